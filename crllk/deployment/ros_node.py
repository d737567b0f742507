"""A ROS 2 node that drives a Duckiebot with a :class:`~crllk.deployment.pilot.Pilot`.

On the robot (ROS 2 with ``duckietown_msgs`` built)::

    python -m crllk.deployment.ros_node --policy policy.onnx --vehicle <robot name>

It subscribes to ``/<vehicle>/camera_node/image/compressed`` (``sensor_msgs/CompressedImage``,
JPEG) and publishes ``duckietown_msgs/WheelsCmdStamped`` on
``/<vehicle>/wheels_driver_node/wheels_cmd``. A camera callback only keeps the newest frame; a
timer at the control rate (30 Hz, the rate the policy was trained at) steps the pilot on it, so
a slow step drops frames instead of queueing them.

It fails safe (:class:`DriveLoop`): when no frame has come for ``--frame-timeout`` seconds
(:data:`FRAME_TIMEOUT_S`) the timer publishes a stop at every tick until frames come again, and
the next frame starts a new drive; a frame that cannot be read (not a JPEG, too large) is
answered with a stop and a warning, and the node goes on; so are state features or outputs that
are not finite (:class:`~crllk.deployment.pilot.Pilot`). Stops are counted and logged the first
time and every :data:`~crllk.deployment.pilot.WARN_EVERY` times after. On shutdown, or any other
error, it sends a stop. The decisions are plain Python, tested without ROS; the ROS part only
moves messages, and imports rclpy only when it runs.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence

from crllk.cli import Parser, fail, one_line, positive_float, run
from crllk.deployment.pilot import STOP, Pilot, WheelCommand
from crllk.errors import ConfigError

CONTROL_RATE_HZ = 30.0
"""Steps per second: the policies' control rate."""
FRAME_TIMEOUT_S = 0.5
"""Seconds without a camera frame after which the node stops the wheels: 15 frames of the
camera's 30 Hz, long past its jitter; at the policies' fastest mean duty (0.6, about 0.5 m/s)
the robot drives about a quarter of a metre blind before it stops."""
BAD_FRAME = "unreadable camera frame"
NO_FRAME = "no camera frame"


class DriveLoop:
    """What the node does, without ROS: :meth:`on_frame` (the camera callback) keeps the newest
    frame, :meth:`on_tick` (the timer) steps the pilot on it and publishes the command.

    ``publish`` sends a :class:`WheelCommand`; ``clock`` gives seconds (monotonic). A tick
    publishes a stop instead when the frame cannot be read, and at every tick once no frame
    has come for ``frame_timeout_s`` (the watchdog, counting each stall once). Without a new
    frame before that, a tick publishes nothing: the last command holds.
    """

    def __init__(self, pilot: Pilot, publish: Callable[[WheelCommand], object],
                 clock: Callable[[], float] = time.monotonic,
                 frame_timeout_s: float = FRAME_TIMEOUT_S):
        if not frame_timeout_s > 0:
            raise ValueError(f"frame_timeout_s must be above 0, got {frame_timeout_s}")
        self.pilot = pilot
        self.publish = publish
        self.clock = clock
        self.frame_timeout_s = frame_timeout_s
        self.faults = pilot.faults
        """The pilot's counted stops, the node's own (:data:`BAD_FRAME`, :data:`NO_FRAME`)
        among them."""
        self.stalled = False
        """Whether the watchdog is stopping the wheels."""
        self._lock = threading.Lock()
        self._newest: bytes | None = None
        self._last_frame = clock()  # no frame yet: the watchdog counts from the start

    def on_frame(self, data: bytes) -> None:
        """A camera frame (JPEG bytes) has arrived."""
        with self._lock:
            self._newest, self._last_frame = data, self.clock()

    def on_tick(self) -> None:
        """One control step: the command for the newest frame, or a stop."""
        with self._lock:
            frame, self._newest = self._newest, None
            waited = self.clock() - self._last_frame
        if frame is None:
            if waited > self.frame_timeout_s:
                if not self.stalled:
                    self.stalled = True
                    self.faults.record(NO_FRAME, f"none for {self.frame_timeout_s:g} s")
                    self.pilot.reset()  # the images it remembers are stale
                self.publish(STOP)
            return
        self.stalled = False
        try:
            command = self.pilot.step(frame, "camera")
        except ConfigError as err:
            self.faults.record(BAD_FRAME, one_line(err))
            command = STOP
        self.publish(command)


def main(argv: Sequence[str] | None = None) -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", required=True, help="an exported policy (.onnx)")
    parser.add_argument("--vehicle", required=True, help="the robot's name (topic prefix)")
    parser.add_argument("--rate", type=positive_float, default=CONTROL_RATE_HZ,
                        help="steps per second")
    parser.add_argument("--frame-timeout", type=positive_float, default=FRAME_TIMEOUT_S,
                        help="seconds without a camera frame after which the wheels stop")
    args = parser.parse_args(argv)
    if args.frame_timeout <= 1.0 / args.rate:
        parser.error(f"--frame-timeout: must be longer than one step (1/--rate = "
                     f"{1.0 / args.rate:.3g} s), got {args.frame_timeout:g}")
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
            self.wheels = self.create_publisher(
                WheelsCmdStamped, f"/{args.vehicle}/wheels_driver_node/wheels_cmd", 1)
            pilot.faults.warn = self.get_logger().warning
            self.loop = DriveLoop(pilot, self.send, frame_timeout_s=args.frame_timeout)
            self.create_subscription(CompressedImage,
                                     f"/{args.vehicle}/camera_node/image/compressed",
                                     lambda message: self.loop.on_frame(bytes(message.data)), 1)
            self.create_timer(1.0 / args.rate, self.loop.on_tick)

        def send(self, command: WheelCommand) -> None:
            message = WheelsCmdStamped()
            message.header.stamp = self.get_clock().now().to_msg()
            message.vel_left, message.vel_right = command.vel_left, command.vel_right
            self.wheels.publish(message)

    rclpy.init()
    node = PilotNode()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.send(STOP)
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    run(main)
