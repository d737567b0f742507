"""A ROS 2 node that drives a Duckiebot with a :class:`~crllk.deployment.pilot.Pilot`.

On the robot (ROS 2 with ``duckietown_msgs`` built)::

    python -m crllk.deployment.ros_node --policy policy.onnx --vehicle <robot name>

It subscribes to ``/<vehicle>/camera_node/image/compressed`` (``sensor_msgs/CompressedImage``,
JPEG) and publishes ``duckietown_msgs/WheelsCmdStamped`` on
``/<vehicle>/wheels_driver_node/wheels_cmd``. A camera callback only keeps the newest frame; a
timer at the control rate (30 Hz, the rate the policy was trained at) steps the pilot on it, so
a slow step drops frames instead of queueing them. On shutdown it sends a stop. All decisions
are the pilot's, tested in simulation; this file only moves messages, and imports rclpy only
when it runs.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

from crllk.cli import Parser, fail, positive_float, run
from crllk.deployment.pilot import Pilot

CONTROL_RATE_HZ = 30.0
"""Steps per second: the policies' control rate."""


def main(argv: Sequence[str] | None = None) -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", required=True, help="an exported policy (.onnx)")
    parser.add_argument("--vehicle", required=True, help="the robot's name (topic prefix)")
    parser.add_argument("--rate", type=positive_float, default=CONTROL_RATE_HZ,
                        help="steps per second")
    args = parser.parse_args(argv)
    pilot = Pilot.from_onnx(args.policy)

    try:  # only on the robot
        import rclpy
        from duckietown_msgs.msg import WheelsCmdStamped
        from rclpy.node import Node
        from sensor_msgs.msg import CompressedImage
    except ImportError as err:
        fail(f"ros_node: cannot import {err.name}: run the node on the robot, with ROS 2 and "
             "duckietown_msgs sourced")

    class PilotNode(Node):
        def __init__(self) -> None:
            super().__init__("crllk_pilot")
            self.newest: bytes | None = None
            self.lock = threading.Lock()
            self.wheels = self.create_publisher(
                WheelsCmdStamped, f"/{args.vehicle}/wheels_driver_node/wheels_cmd", 1)
            self.create_subscription(CompressedImage,
                                     f"/{args.vehicle}/camera_node/image/compressed",
                                     self.on_frame, 1)
            self.create_timer(1.0 / args.rate, self.on_tick)

        def on_frame(self, message: CompressedImage) -> None:
            with self.lock:
                self.newest = bytes(message.data)

        def on_tick(self) -> None:
            with self.lock:
                frame, self.newest = self.newest, None
            if frame is not None:
                command = pilot.step(frame)
                self.send(command.vel_left, command.vel_right)

        def send(self, left: float, right: float) -> None:
            message = WheelsCmdStamped()
            message.header.stamp = self.get_clock().now().to_msg()
            message.vel_left, message.vel_right = float(left), float(right)
            self.wheels.publish(message)

    rclpy.init()
    node = PilotNode()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.send(0.0, 0.0)
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    run(main)
