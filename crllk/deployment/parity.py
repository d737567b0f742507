"""How often the pilot on camera frames acts as the policy did in simulation.

The scripted lane follower drives a task; at every step the simulator renders the robot camera
twice: the policy's own 30×40 observation, and a 640×480 frame as the Duckiebot camera takes
it, JPEG-encoded as the camera publishes it. The pilot steps on the JPEG; the policy reads the
observation (each with its own memory of images, for a policy with a frame history). Their
wheel commands agree when no duty differs by more than :data:`SAME_DUTY` (a discrete policy's
expected duties, and a continuous one's, move with its probabilities; the argmax alone would
flip between its three pairs). The simulator renders the policy's images as its training did
(the supersampling the export records).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crllk.deployment.pilot import Pilot
from crllk.tasks.follower import LaneFollower
from crllk.tasks.frames import JPEG_QUALITY, robot_camera_image
from crllk.tasks.lane_keeping import load

SAME_DUTY = 0.01
"""Largest difference of a wheel duty (of 1) between two commands that count as the same: a
hundredth of full duty, 0.6 cm/s of wheel speed under the DB18 motor model."""


@dataclass(frozen=True)
class Parity:
    """Frames compared and how many gave the same command."""

    frames: int
    same: int
    mean_pixel_difference: float
    """Mean absolute difference of the two 30×40 images, in 0-255 levels."""

    @property
    def agreement(self) -> float:
        return self.same / self.frames


def pilot_parity(pilot: Pilot, task: str, frames: int = 900, seed: int = 0,
                 quality: int = JPEG_QUALITY) -> Parity:
    """Compares the pilot on JPEG camera frames with the policy on the simulator's images."""
    overrides = {"camera": {"supersample": pilot.supersample}} if pilot.supersample else None
    env = load(task, observation="pixels", action="duty", seed=seed, overrides=overrides)
    follower = LaneFollower(env.task.map, env.task.config.motor)
    simulated = Pilot(pilot.session, pilot.metadata, pilot.source)  # its own image memory
    step = env.reset()
    same, differences = 0, []
    for _ in range(frames):
        if step.first():
            pilot.reset()
            simulated.reset()
        observation = step.observation["pixels"]
        prepared = robot_camera_image(env.physics.render_camera, pilot.observation_shape[:2],
                                      quality)
        difference = np.abs(pilot.duty(pilot.remember(prepared))
                            - simulated.duty(simulated.remember(observation)))
        same += int(difference.max() <= SAME_DUTY)
        differences.append(np.abs(prepared.astype(np.int16) - observation).mean())
        step = env.reset() if step.last() else env.step(follower.duty(env.physics))
    env.physics.free_renderers()
    return Parity(frames, same, float(np.mean(differences)))
