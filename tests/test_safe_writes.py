"""Writing into run directories others may write in too: a planted symbolic link is never
written through, concurrent writers never lose each other's results, a write that cannot
succeed is refused before any work (or named with its cause when the disk fills meanwhile), a
row cut short by a kill never survives a resume, and settings are never silently dropped."""

from __future__ import annotations

import errno
import itertools
import json
import os
import shutil
import subprocess
import sys
import time
from functools import partial
from pathlib import Path

import pytest
import torch
from tiny_runs import (
    FRAMES_PER_ITERATION,
    REPO,
    TINY,
    held_by_another_process,
    read_rows,
    run_in_process,
)

from crllk import convert, evaluate, export
from crllk.cli import exit_status, one_line
from crllk.errors import ConfigError, MapError
from crllk.evaluation.runs import evaluate_run, record_run
from crllk.files import (
    WriteError,
    atomic_write,
    atomic_write_text,
    output_lock,
    output_lock_path,
    read_csv_rows,
)
from crllk.train import resolve_config
from crllk.training.compose import compose_config
from crllk.training.logs import CsvLog
from crllk.training.loop import train
from crllk.training.run_dir import EVAL_RECORDING, RUN_LOCK, lock_run_dir
from crllk.yaml_files import read_yaml

PRECIOUS = "precious: must stay as it is\n"
SMALL_LOOP = REPO / "tasks" / "small_loop.yaml"


def _victim(tmp_path: Path, name: str = "victim.txt") -> Path:
    victim = tmp_path / "elsewhere" / name
    victim.parent.mkdir(parents=True, exist_ok=True)
    victim.write_text(PRECIOUS)
    return victim


def _plant(link: Path, target: Path) -> Path:
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(target)
    return link


def _one_line_error(capsys, status: int) -> str:
    err = capsys.readouterr().err.strip()
    assert status == 2, err
    assert err.startswith("error: ") and len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


def _command(module: str, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", module, *args], cwd=REPO, capture_output=True,
                          text=True, timeout=timeout)


def _train(run_dir: Path, *overrides: str, iterations: int = 1) -> int:
    return exit_status(lambda: train(resolve_config(compose_config(
        [*TINY, "obs=state", "eval.final=false", f"run_dir={run_dir}",
         f"total_frames={iterations * FRAMES_PER_ITERATION}", *overrides]))))


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> Path:
    return run_in_process(tmp_path_factory.mktemp("safe_writes") / "run", 1,
                          ["obs=state", "eval.final=false"])


# ----- planted links -------------------------------------------------------------------------
def test_the_run_lock_never_follows_a_planted_link(tmp_path):
    victim = _victim(tmp_path)
    run_dir = tmp_path / "run"
    _plant(run_dir / RUN_LOCK, victim)
    with pytest.raises(ConfigError, match="symbolic link") as caught:
        lock_run_dir(run_dir)
    assert str(run_dir / RUN_LOCK) in str(caught.value) and len(str(caught.value)) < 300
    assert victim.read_text() == PRECIOUS
    (run_dir / RUN_LOCK).unlink()
    _plant(run_dir / RUN_LOCK, tmp_path / "created-through-a-link")  # a dangling link
    with pytest.raises(ConfigError, match="symbolic link"):
        lock_run_dir(run_dir)
    assert not (tmp_path / "created-through-a-link").exists()


def test_the_run_lock_is_not_truncated(tmp_path):
    (tmp_path / RUN_LOCK).write_text("kept")
    lock_run_dir(tmp_path).close()
    assert (tmp_path / RUN_LOCK).read_text() == "kept"


def test_csv_logs_never_follow_a_planted_link(tmp_path):
    victim = _victim(tmp_path)
    log = CsvLog(_plant(tmp_path / "metrics.csv", victim), ["iteration", "J_R"])
    for act in (lambda: log.append({"iteration": 1, "J_R": 0.5}), lambda: log.truncate_after(1)):
        with pytest.raises(WriteError) as caught:
            act()
        assert one_line(caught.value).startswith(f"{log.path}: is a symbolic link")
    assert victim.read_text() == PRECIOUS


def test_atomic_writes_replace_a_planted_link_and_locks_refuse_one(tmp_path):
    victim = _victim(tmp_path)
    target = _plant(tmp_path / "eval.json", victim)
    atomic_write_text(target, "{}\n")
    assert not target.is_symlink() and target.read_text() == "{}\n"
    _plant(output_lock_path(target), victim)
    with pytest.raises(WriteError, match="symbolic link"), output_lock(target):
        pass
    assert victim.read_text() == PRECIOUS


def test_training_writes_through_no_planted_link(tmp_path, capsys):
    """Checkpoint, kept policy, config and recordings replace links planted at their paths;
    links planted as a log or the lock end the run with one line naming them."""
    run_dir = tmp_path / "run"
    planted = {name: _plant(run_dir / name, _victim(tmp_path, name.replace("/", "_")))
               for name in ("checkpoints/last.pt", "policy.pt", "config.yaml",
                            "recordings/iteration_000001.rrd")}
    assert _train(run_dir, "record_every=1") == 0
    for name, link in planted.items():
        assert not link.is_symlink() and link.stat().st_size > 0, name
        assert (tmp_path / "elsewhere" / name.replace("/", "_")).read_text() == PRECIOUS

    for name, extra in ((RUN_LOCK, []), ("eval.csv", ["eval.every=1"])):
        other = tmp_path / f"other-{name}"
        victim = _victim(tmp_path, f"other-{name}")
        _plant(other / name, victim)
        err = _one_line_error(capsys, _train(other, *extra))
        assert f"{other / name}: is a symbolic link" in err
        assert victim.read_text() == PRECIOUS

    victim = _victim(tmp_path, "metrics")
    (run_dir / "metrics.csv").unlink()
    _plant(run_dir / "metrics.csv", victim)
    err = _one_line_error(capsys, _train(run_dir, "resume=true", iterations=2))
    assert f"{run_dir / 'metrics.csv'}: is a symbolic link" in err
    assert victim.read_text() == PRECIOUS


def test_evaluation_and_recording_write_through_no_planted_link(tiny_run, tmp_path):
    victims = {name: _victim(tmp_path, name) for name in ("json", "rrd")}
    result = tiny_run / "planted.json"
    _plant(result, victims["json"])
    _plant(tiny_run / EVAL_RECORDING, victims["rrd"])
    evaluate_run(tiny_run, episodes=2, num_envs=2, name="planted")
    record_run(tiny_run, episodes=1)
    assert json.loads(result.read_text())["evaluation"]["episodes"] == 2
    assert not (tiny_run / EVAL_RECORDING).is_symlink()
    assert all(v.read_text() == PRECIOUS for v in victims.values())


def test_export_writes_through_no_planted_link(tiny_run, tmp_path):
    victim = _victim(tmp_path)
    out = _plant(tmp_path / "out" / "policy.onnx", victim)
    assert exit_status(lambda: export.main([f"run={tiny_run}", f"out={out}"])) == 0
    assert not out.is_symlink() and out.stat().st_size > 1000
    assert victim.read_text() == PRECIOUS


# ----- concurrent writers --------------------------------------------------------------------
def test_a_live_writers_temporary_file_is_left_alone(tmp_path):
    """A write of a file that starts and ends while another write of it is under way (another
    process, here nested) no longer removes the other's temporary file."""
    target = tmp_path / "eval.json"

    def outer(handle):
        handle.write(b'{"outer": 1}\n')
        atomic_write_text(target, '{"inner": 1}\n')

    atomic_write(target, outer)
    assert json.loads(target.read_text()) == {"outer": 1}
    assert not list(tmp_path.glob(".*.tmp"))


def test_two_evaluations_of_one_run_both_finish(tiny_run):
    """Two ``crllk.evaluate`` processes into the same file: the second waits for the first;
    both succeed and the result is whole."""
    argv = [sys.executable, "-m", "crllk.evaluate", f"run={tiny_run}", "episodes=2",
            "num_envs=2", "name=twice"]
    both = [subprocess.Popen(argv, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True) for _ in range(2)]
    outputs = [p.communicate(timeout=300) for p in both]
    for process, (stdout, stderr) in zip(both, outputs, strict=True):
        assert process.returncode == 0, stderr
        assert "J_R" in stdout
    assert json.loads((tiny_run / "twice.json").read_text())["evaluation"]["episodes"] == 2
    assert not list(tiny_run.glob(".*.tmp"))


def test_an_evaluation_waits_for_the_writer_of_its_file(tiny_run):
    result = tiny_run / "waited.json"
    with held_by_another_process("lock_file(output_lock_path(sys.argv[1]), wait=False)",
                                 result):
        waiting = subprocess.Popen(
            [sys.executable, "-m", "crllk.evaluate", f"run={tiny_run}", "episodes=2",
             "num_envs=2", "name=waited"], cwd=REPO, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True)
        said = f"waiting for another process writing {result}"
        assert any(line.startswith(said) for line in _lines_until(waiting.stderr, said))
        time.sleep(1)
        assert waiting.poll() is None and not result.exists()
    _, stderr = waiting.communicate(timeout=300)
    assert waiting.returncode == 0, stderr
    assert json.loads(result.read_text())["evaluation"]["episodes"] == 2


def _lines_until(stream, start: str, most: int = 20) -> list[str]:
    """Lines of ``stream`` up to the first that begins with ``start`` (at most ``most``)."""
    lines = []
    while len(lines) < most:
        line = stream.readline()
        lines.append(line)
        if not line or line.startswith(start):
            break
    return lines


# ----- failing writes ------------------------------------------------------------------------
def _read_only_runner() -> list[str] | None:
    """A command prefix that runs its command with the folder given first mounted read-only
    (a user and mount namespace: also for root, whom permissions do not stop), or None."""
    script = 'mount --bind "$0" "$0" && mount -o remount,bind,ro "$0" && shift && exec "$@"'
    prefix = ["unshare", "-Urm", "sh", "-c", script]
    if shutil.which("unshare") is None:
        return None
    probe = subprocess.run([*prefix, "/tmp", "_", "true"], capture_output=True)
    return prefix if probe.returncode == 0 else None


def _run_read_only(folder: Path, module: str, *args: str) -> subprocess.CompletedProcess:
    prefix = _read_only_runner()
    if prefix is None:
        pytest.skip("needs unshare with user namespaces to mount a folder read-only")
    return subprocess.run([*prefix, str(folder), "_", sys.executable, "-m", module, *args],
                          cwd=REPO, capture_output=True, text=True, timeout=300)


def _assert_refused(result: subprocess.CompletedProcess, *words: str) -> None:
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for word in words:
        assert word in lines[0], lines[0]


def test_commands_refuse_a_read_only_folder_before_any_work(tiny_run, tmp_path):
    copy = tmp_path / "run"
    shutil.copytree(tiny_run, copy)
    result = _run_read_only(copy, "crllk.evaluate", f"run={copy}", "episodes=50")
    _assert_refused(result, str(copy), "Read-only file system")
    assert "episodes" not in result.stdout
    out = tmp_path / "out"
    out.mkdir()
    _assert_refused(_run_read_only(out, "crllk.export", f"run={tiny_run}",
                                   f"out={out}/p.onnx"), str(out), "Read-only file system")
    _assert_refused(_run_read_only(out, "crllk.record", "--task", "small_loop", "--out",
                                   f"{out}/r.rrd"), str(out), "Read-only file system")


def test_a_full_disk_names_the_file_and_the_cause(tmp_path):
    target = tmp_path / "checkpoints" / "last.pt"

    def full(handle):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(WriteError) as caught:
        atomic_write(target, full)
    assert one_line(caught.value) == f"{target}: No space left on device"
    assert not target.exists() and not list(target.parent.glob(".*.tmp"))


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_torch_save_on_a_full_disk_names_the_file(tmp_path):
    """``torch.save`` reports a full disk as ``RuntimeError: [enforce fail at
    inline_container.cc...]``; the write names the checkpoint and the cause instead."""
    target = tmp_path / "last.pt"

    def save(handle):
        with open("/dev/full", "wb") as full:
            torch.save({"weights": torch.zeros(100_000)}, full)

    with pytest.raises(WriteError) as caught:
        atomic_write(target, save)
    assert one_line(caught.value) == f"{target}: No space left on device"


def test_training_on_a_full_disk_ends_with_one_line(tmp_path):
    """A file system of 128 kB: the config and logs fit, the checkpoint does not."""
    if _read_only_runner() is None:
        pytest.skip("needs unshare with user namespaces to mount a small file system")
    disk = tmp_path / "disk"
    disk.mkdir()
    script = 'mount -t tmpfs -o size=128k tmpfs "$0" && shift && exec "$@"'
    result = subprocess.run(
        ["unshare", "-Urm", "sh", "-c", script, str(disk), "_", sys.executable, "-m",
         "crllk.train", *TINY, "obs=state", "eval.final=false", f"run_dir={disk}/run",
         "total_frames=16"], cwd=REPO, capture_output=True, text=True, timeout=300)
    _assert_refused(result, f"{disk}/run/checkpoints/last.pt: No space left on device")


# ----- torn rows -----------------------------------------------------------------------------
def test_a_row_cut_short_is_not_read(tmp_path):
    log = tmp_path / "metrics.csv"
    log.write_text("iteration,J_R\r\n1,0.5\r\n2,0.7\r\n3,0.\r\n4")
    assert read_csv_rows(log) == (["iteration", "J_R"], [{"iteration": "1", "J_R": "0.5"},
                                                          {"iteration": "2", "J_R": "0.7"},
                                                          {"iteration": "3", "J_R": "0."}])
    log.write_text("iteration,J_R\r\n1,0.5\r\n2\r\n")
    assert read_csv_rows(log)[1] == [{"iteration": "1", "J_R": "0.5"}]


def test_resume_drops_a_row_cut_short(tmp_path):
    """A kill while ``metrics.csv`` was appended leaves part of a row (here ``1`` of an
    iteration 1x): the resumed run's logs hold whole rows, one per iteration."""
    run_dir = tmp_path / "run"
    assert _train(run_dir, iterations=2) == 0
    with (run_dir / "metrics.csv").open("a") as handle:
        handle.write("1")
    assert _train(run_dir, "resume=true", iterations=3) == 0
    rows = read_rows(run_dir / "metrics.csv")
    assert [r["iteration"] for r in rows] == ["1", "2", "3"]
    assert all(None not in r.values() and r["J_R"] != "" for r in rows)


# ----- settings ------------------------------------------------------------------------------
def test_evaluation_overrides_apply_to_a_task_file_run(tmp_path, capsys):
    """A run trained from ``task=<file>.yaml`` keeps its settings in the file; an evaluation's
    ``overrides.*`` change them all the same, and a bad one is one line before any episode."""
    task = tmp_path / "short_loop.yaml"
    task.write_text(SMALL_LOOP.read_text().replace("horizon: 512", "horizon: 12"))
    run = run_in_process(tmp_path / "file-task", 1, ["obs=state", "eval.final=false",
                                                     f"task={task}"])
    document = evaluate_run(run, episodes=2, num_envs=2, overrides={"horizon": 5},
                            name="short")
    assert document["summary"]["episode_length"] <= 5
    assert document["evaluation"]["task_overrides"] == {"horizon": 5}
    err = _one_line_error(capsys, evaluate.main([f"run={run}", "overrides.horizon=abc"]))
    assert f"{run}: overrides.horizon: expected a whole number" in err
    err = _one_line_error(capsys, evaluate.main([f"run={run}", "overrides.map=zigzag"]))
    assert "overrides.map: cannot be changed" in err
    assert not (run / "eval.json").exists()


def test_the_follower_takes_the_overrides_too(capsys):
    err = _one_line_error(capsys, evaluate.main(["follower=true", "overrides.horizon=-3"]))
    assert "evaluate: overrides.horizon: must be positive" in err


def test_an_alias_bomb_is_refused_in_one_short_line(tmp_path, capsys):
    """Nested anchors of 340 bytes expand to 5 million nodes; an error message printing the
    value ran to 39 MB."""
    parts = ["&a [lol,lol,lol,lol,lol,lol,lol,lol,lol]"]
    parts += [f"&{b} [" + ",".join([f"*{a}"] * 9) + "]" for a, b in zip("abcdef", "bcdefg",
                                                                        strict=True)]
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("map: {tile_size: 0.585, tiles: [[curve_left/W, curve_left/N], "
                    "[curve_left/S, curve_left/E]]}\nhorizon: [" + ", ".join(parts) + "]\n")
    with pytest.raises(MapError, match="aliases expand"):
        read_yaml(bomb)
    err = _one_line_error(capsys, evaluate.main(["follower=true", f"task={bomb}"]))
    assert len(err) < 300


def test_export_wants_an_onnx_file(tiny_run, tmp_path, capsys):
    err = _one_line_error(capsys, exit_status(lambda: export.main(
        [f"run={tiny_run}", f"out={tmp_path / 'policy.txt'}"])))
    assert "export: out: must end in .onnx" in err
    assert not (tmp_path / "policy.txt").exists()


# ----- planted folders, run configurations, damaged logs -------------------------------------
def _bomb(depth: int = 7) -> str:
    """Nested anchors of a few hundred bytes that expand to millions of nodes."""
    parts = ["a: &a [lol,lol,lol,lol,lol,lol,lol,lol,lol]"]
    names = "abcdefgh"[:depth]
    parts += [f"{b}: &{b} [" + ",".join([f"*{a}"] * 9) + "]"
              for a, b in itertools.pairwise(names)]
    return "\n".join(parts) + "\n"


def test_a_run_configuration_is_read_with_the_task_files_limits(tiny_run, tmp_path, capsys):
    """A run's ``config.yaml`` with an alias bomb is refused in one line (OmegaConf alone ran
    for minutes), and a bad key in it is named with the file, not as an override."""
    run = tmp_path / "bombed"
    shutil.copytree(tiny_run, run)
    config = run / "config.yaml"
    saved = config.read_text()
    config.write_text(_bomb() + saved)
    for main, extra in ((evaluate.main, ["episodes=1"]), (export.main, [])):
        err = _one_line_error(capsys, exit_status(partial(main, [f"run={run}", *extra])))
        assert f"{config}: <file>: its aliases expand to" in err and len(err) < 300
    config.write_text(saved + "no_such_setting: 1\n")
    err = _one_line_error(capsys, evaluate.main([f"run={run}", "episodes=1"]))
    assert err == f"error: {config}: no_such_setting: no such setting"


def test_planted_run_folders_are_refused_not_followed(tiny_run, tmp_path, capsys):
    """``checkpoints/`` or ``recordings/`` planted as a link to a folder elsewhere: every
    command that writes there refuses the run in one line, and nothing lands in the folder."""
    for name in ("checkpoints", "recordings"):
        run = tmp_path / f"planted-{name}"
        shutil.copytree(tiny_run, run, ignore=shutil.ignore_patterns(name))
        target = tmp_path / f"elsewhere-{name}"
        target.mkdir()
        _plant(run / name, target)
        expected = f"{run / name}: <folder>: is a symbolic link, which is not followed"
        err = _one_line_error(capsys, evaluate.main([f"run={run}", "episodes=1", "record=true"]))
        assert expected in err
        err = _one_line_error(capsys, _train(run, "resume=true", iterations=2))
        assert expected in err
        assert list(target.iterdir()) == []
    err = _one_line_error(capsys, exit_status(
        lambda: convert.main([f"path={tmp_path / 'planted-checkpoints'}"])))
    assert "checkpoints is a symbolic link, which is not followed" in err


def test_a_log_whose_header_is_not_the_run_s_is_named_not_emptied(tmp_path, capsys):
    """Resuming with a damaged ``metrics.csv`` header used to drop every row it could not
    read, or fail with a bare ValueError for an extra column."""
    run_dir = tmp_path / "run"
    assert _train(run_dir, iterations=2) == 0
    log = run_dir / "metrics.csv"
    rows = log.read_text()
    for header in (rows.replace("iteration,", "iterat0n,", 1),
                   rows.replace("\n", ",zz\n", 1)):
        log.write_text(header)
        err = _one_line_error(capsys, _train(run_dir, "resume=true", iterations=3))
        assert f"{log}: <header>: not this run's log" in err
        assert log.read_text() == header


def test_a_file_torch_did_not_write_is_named_as_such(tiny_run, tmp_path, capsys):
    run = tmp_path / "text"
    shutil.copytree(tiny_run, run)
    (run / "checkpoints" / "last.pt").write_text("hello\n")
    err = _one_line_error(capsys, evaluate.main([f"run={run}", "episodes=1"]))
    assert err == (f"error: {run / 'checkpoints' / 'last.pt'}: <file>: not a checkpoint: "
                   "neither the zip archive torch.save writes nor a pickle")


@pytest.mark.parametrize(("argument", "problem"), [
    ("seed=999999999999999999999", "seed: must be at most 4294967295 (2**32 - 1)"),
    ("episodes=99999999999999999999999", "episodes: must be at most 1000000"),
    ("num_envs=99999999999", "num_envs: must be at most 1024"),
    ("overrides={a: 1", "overrides: while parsing a flow mapping"),
])
def test_evaluate_bounds_its_numbers_and_names_an_unreadable_value(tiny_run, capsys, argument,
                                                                  problem):
    err = _one_line_error(capsys, evaluate.main([f"run={tiny_run}", argument]))
    assert err.startswith(f"error: evaluate: {problem}")


def test_a_seed_too_large_is_refused_before_training(tmp_path, capsys):
    err = _one_line_error(capsys, _train(tmp_path / "run", "eval.seed=99999999999999999999"))
    assert "eval.seed: must be at most 4294967295" in err
    assert not (tmp_path / "run").exists()
