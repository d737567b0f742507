"""Held-out perturbations for robustness evaluations: one axis at a time, and all together.

Each condition is a change of task settings for an evaluation (``crllk.evaluate
overrides.*``, :func:`crllk.evaluation.runs.evaluate_run`'s ``overrides``). Its ranges lie
beyond those the ``default`` randomisation preset trains with (both sides where a side exists),
so a policy trained with randomisation meets none of them in training; ``deployment`` takes
every image through the robot's camera path (640×480, JPEG, the pilot's preparation).
"""

from __future__ import annotations

from typing import Any

NOMINAL = "nominal"
HELD_OUT: dict[str, dict[str, Any]] = {
    "lighting": {"light_intensity": [0.5, 0.7], "ambient": [0.5, 0.7], "headlight": [0.5, 0.7],
                 "light_tilt": [0.6, 0.8]},
    "colours": {"floor_color": [1.25, 1.4], "horizon_color": [1.3, 1.5],
                "object_color": [0.5, 0.7]},
    "camera pose": {"camera_height": [1.08, 1.15], "camera_pitch": [1.2, 1.3],
                    "camera_fov": [0.7, 0.8], "camera_position_noise": 0.008},
    "motor gain": {"max_speed": [0.8, 0.9], "yaw_rate": [0.8, 0.9]},
    "trim": {"trim": 0.05},
    "delay": {"delay": [1 / 30, 2 / 30]},
    "distractors": {"distractors": 12},
}
"""Randomisation ranges per perturbed axis (fields of ``randomize``), beyond the default
preset's: darker and lower sun, brighter floor and darker objects, a higher camera pitched
further down with a narrower view, weaker motors, a larger left/right asymmetry (std 0.05
against 0.02), one to two control steps more delay, a dozen coloured patches beside the road
(the preset scatters none)."""
DEPLOYMENT = "deployment"


def conditions() -> dict[str, dict[str, Any]]:
    """Task-setting overrides by condition: nominal, each held-out axis, the deployment path
    and everything together (``combined``)."""
    combined_ranges: dict[str, Any] = {}
    for ranges in HELD_OUT.values():
        combined_ranges.update(ranges)
    table: dict[str, dict[str, Any]] = {NOMINAL: {}}
    table.update({name: {"randomize": dict(ranges)} for name, ranges in HELD_OUT.items()})
    table[DEPLOYMENT] = {"camera": {"robot_frames": True}}
    table["combined"] = {"randomize": combined_ranges, "camera": {"robot_frames": True}}
    return table


def result_name(condition: str) -> str:
    """The evaluation's file name in the run directory (without ``.json``)."""
    return "robust-" + condition.replace(" ", "-")


__all__ = ["DEPLOYMENT", "HELD_OUT", "NOMINAL", "conditions", "result_name"]
