"""Names of the Duckiebot's MJCF elements and its physical constants (SI units)."""

from __future__ import annotations

ROBOT_PREFIX = "duckiebot/"
ROOT_JOINT = ROBOT_PREFIX + "root"
FOOTPRINT_GEOM = ROBOT_PREFIX + "footprint"
LEFT_WHEEL_JOINT = ROBOT_PREFIX + "left_wheel"
RIGHT_WHEEL_JOINT = ROBOT_PREFIX + "right_wheel"
FORWARD_ACTUATOR = ROBOT_PREFIX + "forward"
TURN_ACTUATOR = ROBOT_PREFIX + "turn"
CAMERA = ROBOT_PREFIX + "camera"
CHASE_CAMERA = ROBOT_PREFIX + "chase"
OVERHEAD_CAMERA = "overhead"
OBSTACLE_PREFIX = "obstacle/"
DISTRACTOR_PREFIX = "distractor/"
"""Names of the flat distractor patches a randomised scene scatters beside the road."""
VEHICLE_PREFIX = "vehicle/"
"""Other Duckiebots driving along the lanes: bodies ``vehicle/<k>/chassis``."""
PEDESTRIAN_PREFIX = "pedestrian/"
"""Duckies crossing the road: bodies ``pedestrian/<k>``."""
MOVER_FOOTPRINT = "footprint"
"""Name (after a mover's prefix) of each mover's collision box."""

WHEEL_RADIUS = 0.0318
"""Kinematic wheel radius (m)."""
WHEEL_DISTANCE = 0.102
"""Distance between the wheel contact points (m)."""
FOOTPRINT_LENGTH = 0.18
FOOTPRINT_WIDTH = 0.15
FOOTPRINT_CENTRE_BEHIND_AXLE = 0.024
"""The collision footprint's centre lies this far behind the axle (m)."""

PHYSICS_TIMESTEP = 1.0 / 240.0
"""Physics step (s): eight substeps per 30 Hz control step."""

FORWARD_SERVO_GAIN = 0.1
"""Velocity servo gain of the forward tendon actuator (N m s / rad)."""
TURN_SERVO_GAIN = 0.05
"""Velocity servo gain of the turn tendon actuator (N m s / rad)."""

CAMERA_AHEAD = 0.066
"""Camera position ahead of the wheel axle (m)."""
CAMERA_HEIGHT = 0.108
"""Camera height above the floor (m)."""
CAMERA_PITCH = 0.33423
"""Camera pitch below the horizontal (rad; 19.15 degrees)."""
CAMERA_FOVY = 75.0
"""Camera vertical field of view (degrees)."""
