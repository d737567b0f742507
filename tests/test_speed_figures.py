"""The speed figures the README and the documentation site quote come from the committed
measurements: the default command's wall times (``wall-time.txt``) and the alternating
benchmark rounds (``results/bench/pixel-speed-alternating.txt``)."""

from __future__ import annotations

import re
import statistics
from pathlib import Path

import pytest
from docs_pages import page, prose

REPO = Path(__file__).resolve().parents[1]
WALL_TIME = REPO / "results/runs/pixels/obstacle_loop/default-command-alone/wall-time.txt"
ROUNDS = REPO / "results/bench/pixel-speed-alternating.txt"
AHEAD_ROUNDS = REPO / "results/bench/collect-ahead-alternating.txt"


def _minutes(text: str) -> list[float]:
    found = re.findall(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\d+):([\d.]+)", text)
    return [int(m) + float(s) / 60 for m, s in found]


@pytest.mark.parametrize("where", ["results/index.md", "benchmarks.md"])
def test_the_default_command_times_are_the_committed_ones(where):
    """Newest first: the current code's time, then earlier ones, the first measured last."""
    times = _minutes(WALL_TIME.read_text())
    newest, first = times[0], times[-1]
    assert len(times) == 3 and f"{first:.1f}" == "25.1"
    assert f"**{newest:.1f} min against {first:.1f}**" in prose(where)
    assert f"({first / newest:.2f}x)" in prose(where)


def test_the_default_command_s_round_figure_is_the_committed_time():
    """The README, the home page, the set-up and In short say "about 10 minutes": the newest
    committed time, rounded."""
    newest = round(_minutes(WALL_TIME.read_text())[0])
    for where in ("README.md", "index.md"):
        assert f"about {newest} min" in prose(where)
        assert f"(the default command: {newest} min on 2 cores)" in prose(where)
    assert f"about {newest} minutes on 2 cores" in prose("getting-started.md")


@pytest.mark.parametrize("row", ["training, pixels (frames/s)", "training, state (frames/s)"])
def test_the_training_rows_are_the_committed_rounds(row):
    rounds: dict[str, list[float]] = {"base": [], "main": [], "prev": []}
    who = None
    for line in ROUNDS.read_text().splitlines():
        if line.startswith("== round"):
            who = line.split()[3]
        elif line.startswith(row):
            rounds[who].append(float(line.split()[3]))
    assert len(rounds["base"]) == len(rounds["main"]) == 8
    ratios = [m / b for b, m in zip(rounds["base"], rounds["main"], strict=True)]
    cells = (", ".join(f"{x:.0f}" for x in rounds["base"]),
             ", ".join(f"{x:.0f}" for x in rounds["main"]),
             ", ".join(f"{r:.2f}" for r in ratios), f"{statistics.median(ratios):.2f}")
    assert f"| {row} | " + " | ".join(cells) + " |" in page("benchmarks.md")


def _rounds(path: Path, row: str) -> dict[str, list[float]]:
    rounds: dict[str, list[float]] = {"base": [], "main": []}
    who = None
    for line in path.read_text().splitlines():
        if line.startswith("== round"):
            who = line.split()[3]
        elif line.startswith(row + " "):
            rounds[who].append(float(line[len(row):].split()[0]))
    return rounds


@pytest.mark.parametrize(("row", "base_row"), [
    ("training, state (frames/s)", "training, state (frames/s)"),
    ("training, state, collect_ahead (frames/s)", "training, state (frames/s)"),
    ("training, pixels (frames/s)", "training, pixels (frames/s)")])
def test_the_collect_ahead_rows_are_the_committed_rounds(row, base_row):
    """The collecting-ahead table: each round's figure of the current code against the same
    round's figure of 864796d (which cannot collect ahead: its sequential state figure)."""
    base, main = _rounds(AHEAD_ROUNDS, base_row)["base"], _rounds(AHEAD_ROUNDS, row)["main"]
    assert len(base) == len(main) == 3
    ratios = [m / b for b, m in zip(base, main, strict=True)]
    cells = (", ".join(f"{x:.0f}" for x in base), ", ".join(f"{x:.0f}" for x in main),
             ", ".join(f"{r:.2f}" for r in ratios), f"{statistics.median(ratios):.2f}")
    assert f"| {row} | " + " | ".join(cells) + " |" in page("benchmarks.md")


def test_the_collect_ahead_prose_is_the_committed_measurements():
    """The medians and ranges the collecting-ahead prose quotes."""
    text = prose("benchmarks.md")

    def median_ratio(row: str) -> float:
        base = _rounds(AHEAD_ROUNDS, "training, state (frames/s)")["base"]
        main = _rounds(AHEAD_ROUNDS, row)["main"]
        return statistics.median(m / b for b, m in zip(base, main, strict=True))

    ahead, default = (median_ratio("training, state, collect_ahead (frames/s)"),
                      median_ratio("training, state (frames/s)"))
    assert f"collecting ahead is {ahead:.1f}x the commit before this work, where the default " \
           f"is {default:.1f}x" in text
    plain = _rounds(AHEAD_ROUNDS, "training, state (frames/s)")["main"]
    collected = _rounds(AHEAD_ROUNDS, "training, state, collect_ahead (frames/s)")["main"]
    same_rounds = ", ".join(f"{a / p:.2f}" for p, a in zip(plain, collected, strict=True))
    assert f"collecting ahead over the default in the same rounds: {same_rounds})" in text
    over_default = statistics.median(a / p for p, a in zip(plain, collected, strict=True))
    assert (f"an option: state training {over_default:.2f}x the default" in
            (REPO / "README.md").read_text())
    over_env = [float(line.split()[-3]) for line in AHEAD_ROUNDS.read_text().splitlines()
                if line.startswith("training, state, collect_ahead")]
    assert f"collecting ahead: {min(over_env):.2f}–{max(over_env):.2f}, still under 0.5" in text
    pixels: dict[str, list[float]] = {}
    for line in (REPO / "results/bench/collect-ahead-pixels.txt").read_text().splitlines():
        if not line.startswith("#"):
            settings, rate = line.split("]")[0].split("[")[1], float(line.split("]")[1].split()[0])
            pixels.setdefault(settings, []).append(rate)
    sequential = pixels["'collect_ahead=false'"]

    def spread(key: str) -> str:
        ratios = [r / p for r, p in zip(pixels[key], sequential, strict=True)]
        low, high = f"{min(ratios):.2f}", f"{max(ratios):.2f}"
        return low if low == high else f"{low}–{high}"

    two, one = spread("'collect_ahead=true'"), spread("'collect_ahead=true', 'threads=1'")
    assert f"{two}x of the sequential loop with the update on two threads" in text
    assert f"and {one}x with it on one" in text


def test_the_default_command_s_training_time_is_the_committed_one():
    """The prose about the timed run quotes its committed training time."""
    training_s = float((WALL_TIME.parent / "eval.csv").read_text().splitlines()[-1].split(",")[2])
    assert f"{training_s / 60:.1f} min of training" in prose("results/index.md")


def test_the_retrained_small_loop_run_meets_what_its_old_run_met():
    """small_loop CRLLK-D seed 0 retrained with the policy in the workers: both constraints
    at every validation evaluation, where the table's run held them at eight of ten."""
    import csv

    runs = REPO / "results/runs/pixels/small_loop"

    def satisfied(run: str) -> list[int]:
        with (runs / run / "eval.csv").open() as handle:
            return [int(row["satisfied"]) for row in csv.DictReader(handle)]

    assert satisfied("retrained-950c9c0") == [1] * 10
    assert sum(satisfied("CRLLK-D-a0.5-seed0")) == 8
    note = (runs / "retrained-950c9c0" / "README.md").read_text()
    assert "at all ten" in note and "at eight of its ten" in note


def test_where_the_time_goes_is_the_committed_measurement():
    """The Benchmarks page's per-iteration times and rates, from the committed bench output:
    1,024 frames per iteration, two workers."""
    rates = {}
    for line in (REPO / "results/bench/where-the-time-goes.txt").read_text().splitlines():
        if ", workers=2 (frames/s)" in line:
            name, value = line.split(" (frames/s)")
            rates[name] = float(value.split()[0])
    text = prose("benchmarks.md")

    def quoted(kind: str) -> str:
        return f"{1024 / rates[kind]:.2f} s ({rates[kind]:,.0f} frames/s"

    assert f"pixel iteration of 1,024 frames takes {quoted('training, pixels, workers=2')})" \
        in text
    assert f"collection alone takes {quoted('collection, pixels, workers=2')}:" in text
    assert f"a state iteration takes {quoted('training, state, workers=2')})" in text
    state = rates["collection, state, workers=2"]
    assert f"{1024 / state:.2f} s of it collecting ({state:,.0f} frames/s)" in text


def test_the_traffic_rounds_are_the_committed_measurements():
    """The range of the traffic figure timed in turns against the code before the last
    speed-up, per commit, and the drift of the rate without movers, from the committed
    rounds."""
    ratios: dict[str, list[float]] = {}
    plain: list[float] = []
    commit = None
    for line in (REPO / "results/bench/traffic-rounds.txt").read_text().splitlines():
        if line.startswith("== round"):
            commit = line.split()[3] if "traffic_loop" in line or len(line.split()) == 5 else None
        elif commit and line.startswith("make_env pixels without movers"):
            plain.append(float(line.split()[-1]))
        elif commit and line.startswith("make_env pixels with traffic"):
            ratios.setdefault(commit, []).append(float(line.split()[-3]))
    (old, new) = ratios
    assert old == "51b15db" and len(ratios[old]) == len(ratios[new]) == 4
    assert min(ratios[new]) >= 0.8  # "the target now holds in every round"
    text = prose("benchmarks.md")
    assert (f"`traffic_loop` {min(ratios[new]):.2f}–{max(ratios[new]):.2f} over four rounds, "
            f"against {min(ratios[old]):.2f}–{max(ratios[old]):.2f} before") in text
    assert f"the code before the last speed-up ({old})" in text
    assert f"between {min(plain):,.0f} and {max(plain):,.0f} steps/s" in text


def test_the_traffic_throughput_is_the_committed_measurement():
    """The Benchmarks page's traffic ratios (the batched pixel env with movers against the same
    task without them), from the committed bench output."""
    ratios, plain, task = {}, {}, None
    for line in (REPO / "results/bench/traffic.txt").read_text().splitlines():
        if line.startswith("task "):
            task = Path(line.split()[1].rstrip(",")).stem
        elif line.startswith("make_env pixels with traffic"):
            ratios[task] = float(line.split()[-3])
        elif line.startswith("make_env pixels without movers"):
            plain[task] = float(line.split()[-1])
    assert set(ratios) == set(plain) == {"traffic_loop", "pedestrian_loop"}
    text = prose("benchmarks.md")
    for task, ratio in ratios.items():
        assert f"`{task}` {ratio:.2f}" in text
    assert (f"its rate without movers was low in that run: {plain['pedestrian_loop']:,.0f} "
            f"steps/s, against {plain['traffic_loop']:,.0f} in `traffic_loop`'s") in text
