"""``python -m crllk.screenshots``: bad input is one line on stderr and a non-zero exit, before
any viewer starts (the screenshots themselves: tests/test_viewer.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from crllk import screenshots
from crllk.cli import exit_status
from crllk.recording import headless

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def no_viewer(monkeypatch):
    """Fail the test if a viewer would be started."""
    def refuse(*args, **kwargs):
        raise AssertionError("a viewer was started for bad input")

    monkeypatch.setattr(headless, "start_viewer", refuse)


def run_main(argv: list[str], capsys) -> tuple[int | str | None, str]:
    try:
        code = exit_status(lambda: screenshots.main(argv))
    except SystemExit as exit_info:  # argument errors
        code = exit_info.code
    return code, capsys.readouterr().err


@pytest.mark.parametrize(("argv", "message"), [
    (["{missing}", "--out", "{out}"], "cannot read"),
    (["{not_rrd}", "--out", "{out}"], "recording: not a rerun recording"),
    (["{rrd}", "--out", "{file}"], "cannot write pictures"),
    (["{rrd}", "--out", "{out}", "--times", "abc"], "expected a number"),
    (["{rrd}", "--out", "{out}", "--times", "-1"], "must be finite and >= 0"),
    (["{rrd}", "--out", "{out}", "--times", "nan"], "must be finite and >= 0"),
    (["{rrd}", "--out", "{out}", "--size", "big"], "WIDTHxHEIGHT"),
    (["{rrd}", "--out", "{out}", "--size", "10x10"], "must lie in"),
    (["--out", "{out}"], "either a recording or --train"),
    (["{rrd}", "--out", "{out}", "--train", "task=zigzag"], "either a recording or --train"),
    (["{rrd}"], "--out"),
])
def test_bad_input_is_one_line(argv, message, tmp_path, capsys, no_viewer):
    paths = {"missing": tmp_path / "missing.rrd", "not_rrd": tmp_path / "notes.txt",
             "rrd": tmp_path / "x.rrd", "out": tmp_path / "out", "file": tmp_path / "a_file"}
    paths["not_rrd"].write_text("not a recording")
    paths["rrd"].write_bytes(b"RRF2" + bytes(60))
    paths["file"].write_text("a file where the folder should be")
    code, err = run_main([a.format(**paths) for a in argv], capsys)
    assert code not in (0, None)
    assert err.startswith("error:") and message in err
    assert len(err.strip().splitlines()) == 1, err


def test_command_line_fails_without_a_traceback(tmp_path):
    result = subprocess.run([sys.executable, "-m", "crllk.screenshots", str(tmp_path / "no.rrd"),
                             "--out", str(tmp_path)], cwd=REPO, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 2
    assert result.stderr.startswith("error: ") and "recording: cannot read" in result.stderr
    assert "Traceback" not in result.stderr
