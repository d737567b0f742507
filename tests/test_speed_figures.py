"""The speed figures the README quotes come from the committed measurements: the default
command's wall times (``wall-time.txt``) and the alternating benchmark rounds
(``results/bench/pixel-speed-alternating.txt``)."""

from __future__ import annotations

import re
import statistics
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text()
WALL_TIME = REPO / "results/runs/pixels/obstacle_loop/default-command-alone/wall-time.txt"
ROUNDS = REPO / "results/bench/pixel-speed-alternating.txt"


def _minutes(text: str) -> list[float]:
    found = re.findall(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\d+):([\d.]+)", text)
    return [int(m) + float(s) / 60 for m, s in found]


def test_the_default_command_times_are_the_committed_ones():
    new, old = _minutes(WALL_TIME.read_text())
    assert "**14.8 min against 25.1**" in README
    assert f"{new:.1f}" == "14.8" and f"{old:.1f}" == "25.1"
    assert f"({old / new:.2f}x" in README


def test_the_pixel_training_row_is_the_committed_rounds():
    rounds: dict[str, list[float]] = {"base": [], "main": []}
    who = None
    for line in ROUNDS.read_text().splitlines():
        if line.startswith("== round"):
            who = line.split()[3]
        elif line.startswith("training, pixels (frames/s)"):
            rounds[who].append(float(line.split()[3]))
    assert len(rounds["base"]) == len(rounds["main"]) == 4
    ratios = [m / b for b, m in zip(rounds["base"], rounds["main"], strict=True)]
    cells = (", ".join(f"{x:.0f}" for x in rounds["base"]),
             ", ".join(f"{x:.0f}" for x in rounds["main"]),
             ", ".join(f"{r:.2f}" for r in ratios), f"{statistics.median(ratios):.2f}")
    assert "| training, pixels (frames/s) | " + " | ".join(cells) + " |" in README
