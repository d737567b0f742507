"""Tiny training runs for tests: two sub-environments, eight steps per iteration."""

from __future__ import annotations

import csv
import subprocess
import sys
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import torch

import crllk  # noqa: F401  (headless GL before torchrl)
from crllk.train import resolve_config
from crllk.training.checkpoints import load_checkpoint
from crllk.training.compose import compose_config
from crllk.training.loop import train

NUM_ENVS, ROLLOUT = 2, 8
FRAMES_PER_ITERATION = NUM_ENVS * ROLLOUT
TINY = [f"num_envs={NUM_ENVS}", f"rollout_steps={ROLLOUT}", "ppo.minibatch_size=8",
        "ppo.epochs=2", "task.horizon=12", "progress=false", "checkpoint_every=1",
        "eval.episodes=4", "eval.num_envs=2", "workers=1"]
"""Overrides of a tiny run; its evaluations play 4 episodes (the default 100 from pixels cost
a test 5–15 s each), and its two simulations step in the test's process (two worker processes
take about 5 s to start; ``tests/test_parallel_collection.py`` tests them)."""


def run_in_process(run_dir: Path, iterations: int, extra: list[str] = (), *,
                   frames_per_iteration: int = FRAMES_PER_ITERATION,
                   on_final_evaluation=None) -> Path:
    """Trains ``iterations`` tiny iterations into ``run_dir`` and returns it (a run of a task
    file, ``task=<file>.yaml``, takes its horizon from the file)."""
    from_file = any(e.startswith(("task=", "task_file=")) and e.endswith((".yaml", ".yml"))
                    for e in extra)
    tiny = [o for o in TINY if not (from_file and o.startswith("task."))]
    cfg = compose_config([*tiny, f"run_dir={run_dir}",
                          f"total_frames={iterations * frames_per_iteration}", *extra])
    return train(resolve_config(cfg), on_final_evaluation=on_final_evaluation)


REPO = Path(__file__).resolve().parents[1]


@contextmanager
def held_by_another_process(lock: str, path: Path) -> Iterator[None]:
    """Another process holds a lock while the block runs: it runs ``held = <lock>`` with
    ``path`` as ``sys.argv[1]`` (e.g. ``lock_run_dir(Path(sys.argv[1]))``; ``lock_run_dir``,
    ``lock_file`` and ``output_lock_path`` are imported), and is killed afterwards."""
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys; from pathlib import Path; "
         "from crllk.training.run_dir import lock_run_dir; "
         "from crllk.files import lock_file, output_lock_path; "
         f"held = {lock}; print('locked', flush=True); sys.stdin.read()", str(path)],
        cwd=REPO, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        yield
    finally:
        holder.kill()
        holder.wait()


def read_rows(path: Path) -> list[dict[str, str]]:
    """A CSV log's rows as strings."""
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


ROUNDING = {"rtol": 1e-4, "atol": 1e-6}
"""How far two runs that differ only in float rounding may drift apart over a few tiny
iterations (:func:`assert_same` with ``close=True``)."""


def assert_same(a, b, path="state", *, close: bool = False) -> None:
    """Equal nested checkpoint contents (tensors, arrays, TensorDicts), NaN equal to NaN;
    with ``close``, floating-point tensors equal up to :data:`ROUNDING`."""
    if isinstance(a, dict):
        assert set(a) == set(b), path
        for key in a:
            assert_same(a[key], b[key], f"{path}.{key}", close=close)
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{path}[{i}]", close=close)
    elif isinstance(a, torch.Tensor) and close and a.is_floating_point():
        torch.testing.assert_close(a, b, **ROUNDING, equal_nan=True, msg=path)
    elif isinstance(a, torch.Tensor):
        assert torch.equal(a, b), path
    elif hasattr(a, "shape") and hasattr(a, "dtype"):  # numpy
        assert (a == b).all(), path
    elif hasattr(a, "to_dict"):  # TensorDict
        assert_same(a.to_dict(), b.to_dict(), path, close=close)
    else:
        assert a == b or (a != a and b != b), path


def comparable(state: dict, ignore: Iterable[str] = ()) -> dict:
    """A checkpoint without what may differ between equal runs: its wall time, and the
    run directory, ``resume`` and the ``ignore`` settings of its configuration."""
    state = dict(state)
    state.pop("elapsed")
    config = dict(state.pop("config"))
    for key in ("run_dir", "resume", *ignore):
        config.pop(key)
    return {**state, "config": config}


def assert_same_runs(a: Path, b: Path, iterations: int, ignore: Iterable[str] = (), *,
                     close: bool = False) -> None:
    """Two run directories trained exactly alike for ``iterations``: equal last checkpoints
    (the ``ignore`` settings aside) and equal ``metrics.csv`` rows but for their timings; with
    ``close``, floating-point values equal up to :data:`ROUNDING`."""
    state_a = load_checkpoint(a / "checkpoints" / "last.pt")
    state_b = load_checkpoint(b / "checkpoints" / "last.pt")
    assert state_a["iteration"] == state_b["iteration"] == iterations
    assert_same(comparable(state_a, ignore), comparable(state_b, ignore), close=close)
    rows_a, rows_b = read_rows(a / "metrics.csv"), read_rows(b / "metrics.csv")
    assert [r["iteration"] for r in rows_b] == [str(i) for i in range(1, iterations + 1)]
    for row_a, row_b in zip(rows_a, rows_b, strict=True):
        for key in ("time_s", "frames_per_s"):
            row_a.pop(key), row_b.pop(key)
        if close:
            assert row_a.keys() == row_b.keys()
            for key in row_a:
                assert _close(row_a[key], row_b[key]), (key, row_a[key], row_b[key])
        else:
            assert row_a == row_b


def _close(a: str, b: str) -> bool:
    try:
        x, y = float(a), float(b)
    except ValueError:
        return a == b
    return (x != x and y != y) or abs(x - y) <= ROUNDING["atol"] + ROUNDING["rtol"] * abs(y)
