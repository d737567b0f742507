"""Reading a run never runs code: checkpoints and kept policies load with ``weights_only``, a
crafted or older file is refused on one line under every command, ``python -m crllk.convert``
converts a trusted one only with ``trust=true``, and every committed file loads."""

from __future__ import annotations

import os
import pathlib
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_runs import assert_same_runs, run_in_process

from crllk import convert, evaluate
from crllk.cli import exit_status
from crllk.rl.plain import tensordict_from_plain, tensordict_to_plain
from crllk.training.checkpoints import (
    CHECKPOINT_FORMAT,
    CONVERTED_FORMATS,
    UnsafeFileError,
    load_checkpoint,
    read_state,
    write_state,
)
from crllk.training.runs import CHECKPOINT_FILE, POLICY_FILE

REPO = Path(__file__).resolve().parents[1]


class TouchPayload:
    """Unpickled, creates ``marker`` (``Path.touch``)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return pathlib.Path.touch, (self.marker,)


class ShellPayload(TouchPayload):
    """Unpickled, creates ``marker`` through the shell (``os.system``)."""

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    """A tiny run of two iterations: config, checkpoint and kept policy."""
    return run_in_process(tmp_path_factory.mktemp("trained") / "run", 2,
                          ["obs=state", "eval.final=false"])


def crafted(path: Path, marker: Path, payload: type[TouchPayload] = TouchPayload) -> Path:
    """Rewrites ``path`` (a real checkpoint or policy) with a payload among its entries."""
    state = torch.load(path, weights_only=True)
    torch.save({**state, "iteration": payload(marker)}, path)
    return path


def as_format_3(path: Path) -> Path:
    """Rewrites a checkpoint as format 3 stored it: the carry a TensorDict, the running
    episode sums numpy arrays."""
    state = torch.load(path, weights_only=True)
    episodes = state["episodes"]
    state.update(format=3, carry=tensordict_from_plain(state["carry"]), episodes={
        "distance": episodes["distance"].numpy(), "length": episodes["length"].numpy(),
        "costs": {name: sums.numpy() for name, sums in episodes["costs"].items()}})
    torch.save(state, path)
    return path


def command(module: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", module, *args], cwd=REPO, capture_output=True,
                          text=True, timeout=300)


def assert_refused(result: subprocess.CompletedProcess, path: Path) -> str:
    """Exit status 2 and one line naming ``path``, no traceback."""
    err = result.stderr.strip()
    assert result.returncode == 2, result.stderr[-2000:]
    assert len(err.splitlines()) == 1 and err.startswith(f"error: {path}: <file>: "), err
    assert "Traceback" not in err
    return err


# ----- what is committed -----------------------------------------------------------------------
def test_every_committed_file_loads_without_running_code():
    files = sorted(REPO.glob("results/**/*.pt"))
    assert len(files) >= 100
    for path in files:
        assert isinstance(torch.load(path, map_location="cpu", weights_only=True), dict), path
        load_checkpoint(path)


# ----- the format ------------------------------------------------------------------------------
def test_a_checkpoint_holds_tensors_and_plain_containers_only(trained):
    for name in (CHECKPOINT_FILE, POLICY_FILE):
        state = torch.load(trained / name, weights_only=True)
        assert state["format"] == CHECKPOINT_FORMAT


def test_a_tensordict_is_kept_as_a_dict_exactly():
    from tensordict import TensorDict

    td = TensorDict({"b": torch.arange(4.0).reshape(2, 2), "a": torch.ones(2, 1, dtype=torch.bool),
                     "next": TensorDict({"x": torch.zeros(2, 3, dtype=torch.uint8)}, [2, 3])},
                    batch_size=[2], device="cpu")
    back = tensordict_from_plain(tensordict_to_plain(td))
    assert list(back.keys(include_nested=True)) == list(td.keys(include_nested=True))
    assert back.batch_size == td.batch_size and back["next"].batch_size == (2, 3)
    assert (back == td).all()


def test_only_plain_values_are_written(tmp_path):
    with pytest.raises(TypeError, match=r"state\.episodes\.distance: numpy\.ndarray"):
        write_state(tmp_path / "x.pt", {"format": 4, "episodes": {"distance": np.zeros(2)}})
    with pytest.raises(TypeError, match=r"state\.value: numpy\.float64"):  # a float subclass
        write_state(tmp_path / "x.pt", {"format": 4, "value": np.float64(1.0)})
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("payload", [TouchPayload, ShellPayload])
def test_a_payload_runs_only_when_the_file_is_trusted(tmp_path, trained, payload):
    """The crafted files are real threats: a full unpickling (``trust``) runs the payload;
    reading without it does not."""
    marker = tmp_path / "marker"
    path = crafted(shutil.copy(trained / POLICY_FILE, tmp_path / "policy.pt"), marker, payload)
    with pytest.raises(UnsafeFileError, match="may execute code: refused"):
        load_checkpoint(path)
    assert not marker.exists()
    read_state(path, trust=True)
    assert marker.exists()


# ----- every command refuses a crafted file ----------------------------------------------------
@pytest.mark.parametrize(("module", "name"), [
    ("crllk.evaluate", POLICY_FILE), ("crllk.evaluate", CHECKPOINT_FILE),
    ("crllk.export", POLICY_FILE), ("crllk.export", CHECKPOINT_FILE),
    ("crllk.analysis.cost_critics", CHECKPOINT_FILE),
    ("crllk.analysis.endings", POLICY_FILE), ("crllk.analysis.endings", CHECKPOINT_FILE)])
def test_reading_a_crafted_run_is_refused(tmp_path, trained, module, name):
    run_dir = shutil.copytree(trained, tmp_path / "run")
    if name == POLICY_FILE:  # the kept policy is read where the checkpoints are gone
        shutil.rmtree(run_dir / CHECKPOINT_FILE.parent)
    marker = tmp_path / "marker"
    path = crafted(run_dir / name, marker)
    arguments = {"crllk.evaluate": [f"run={run_dir}", "episodes=1", "num_envs=1"],
                 "crllk.export": [f"run={run_dir}"],
                 "crllk.analysis.cost_critics": [str(run_dir), "--batches", "1"],
                 "crllk.analysis.endings": [str(run_dir), "--episodes", "1"]}[module]
    err = assert_refused(command(module, *arguments), path)
    assert "may execute code: refused" in err and "crllk.convert" in err
    assert not marker.exists()
    assert not (run_dir / "eval.json").exists() and not (run_dir / "policy.onnx").exists()
    assert not (run_dir / "endings.json").exists()


def test_resuming_a_crafted_checkpoint_is_refused(tmp_path, trained):
    run_dir = shutil.copytree(trained, tmp_path / "run")
    marker = tmp_path / "marker"
    path = crafted(run_dir / CHECKPOINT_FILE, marker)
    before = path.read_bytes()
    err = assert_refused(command("crllk.train", f"run_dir={run_dir}", "resume=true",
                                 "total_frames=64"), path)
    assert "may execute code: refused" in err
    assert not marker.exists() and path.read_bytes() == before


def test_an_older_checkpoint_is_refused_with_the_conversion(tmp_path, trained):
    run_dir = shutil.copytree(trained, tmp_path / "run")
    path = as_format_3(run_dir / CHECKPOINT_FILE)
    err = assert_refused(command("crllk.export", f"run={run_dir}"), path)
    assert f"python -m crllk.convert path={path} trust=true" in err


# ----- python -m crllk.convert -----------------------------------------------------------------
def test_convert_refuses_without_the_opt_in(tmp_path, trained):
    run_dir = shutil.copytree(trained, tmp_path / "run")
    marker = tmp_path / "marker"
    for path in (as_format_3(run_dir / CHECKPOINT_FILE), crafted(run_dir / POLICY_FILE, marker)):
        before = path.read_bytes()
        result = command("crllk.convert", f"path={path}")
        err = result.stderr.strip()
        assert result.returncode == 2 and len(err.splitlines()) == 1, err
        assert err.startswith(f"error: convert: trust: {path} ") and "trust=true" in err
        assert path.read_bytes() == before and not marker.exists()


def test_convert_with_the_opt_in_converts_a_run_that_then_evaluates(tmp_path, trained, capsys):
    run_dir = shutil.copytree(trained, tmp_path / "run")
    path = as_format_3(run_dir / CHECKPOINT_FILE)
    policy = (run_dir / POLICY_FILE).read_bytes()
    assert exit_status(lambda: convert.main([f"path={run_dir}", "trust=true"])) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"{run_dir / POLICY_FILE}: loads without running code, left as it is",
        f"{path}: converted from format 3 to {CONVERTED_FORMATS[3]}"]
    assert (run_dir / POLICY_FILE).read_bytes() == policy
    state = torch.load(path, weights_only=True)
    assert state["format"] == CONVERTED_FORMATS[3] and isinstance(state["carry"], dict)
    assert exit_status(lambda: evaluate.main([f"run={run_dir}", "episodes=2",
                                              "num_envs=2"])) == 0
    assert (run_dir / "eval.json").exists()


def test_convert_help_documents_the_opt_in(capsys):
    assert convert.main(["--help"]) == 0
    assert "trust=true" in capsys.readouterr().out


def test_a_converted_checkpoint_resumes_exactly(tmp_path):
    """Two iterations, the checkpoint rewritten as format 3 and converted, then a third
    iteration on resume: equal to three straight."""
    extra = ["obs=state", "task.randomize=default", "ppo.anneal_lr=false", "eval.final=false"]
    straight = run_in_process(tmp_path / "straight", 3, extra)
    resumed = run_in_process(tmp_path / "resumed", 2, extra)
    convert.convert_file(as_format_3(resumed / CHECKPOINT_FILE), trust=True)
    run_in_process(resumed, 3, [*extra, "resume=true"])
    assert_same_runs(straight, resumed, 3)
