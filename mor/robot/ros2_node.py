"""The live controller on a TurtleBot: a ROS 2 node (``mor robot run``). It needs ROS 2's ``rclpy``, which mor does
not install (source your ROS 2 setup in the shell, with the same Python as mor); nothing else in mor, and no test,
imports it.

Subscribes: the top camera (``robot.top_image_topic``) and the first-person camera (``RealTopics.image``), both
sensor_msgs/CompressedImage; the held object, ``/mor/held`` std_msgs/Int32 (-1: none; from the gripper or an
operator). Publishes: ``/cmd_vel`` geometry_msgs/Twist (each segment re-sent at ``CMD_RATE_HZ`` while it lasts,
then a zero Twist), ``/mor/action`` and ``/mor/event`` std_msgs/String.

Each step waits for a frame stamped after the previous command ended (its last segment and ``settle_s``), so the
policy never acts on a pose older than the robot's last motion; without a pose the controller waits, then stops
(``mor.robot.controller``). Ctrl-C, the controller giving up, or ``max_steps`` end the run with a zero Twist.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from mor.data.real import RealTopics, decode_image
from mor.errors import MorError
from mor.robot.actuator import Command
from mor.robot.controller import Controller
from mor.robot.params import RobotParams
from mor.robot.pose import Frame
from mor.robot.recording import EVENT_TOPIC, RunRecorder

logger = logging.getLogger(__name__)
CMD_RATE_HZ = 10.0


def import_ros2() -> tuple[Any, Any, Any, Any, Any]:
    """rclpy and the message classes; a one-line MorError when ROS 2 is not importable."""
    try:
        import rclpy  # noqa: PLC0415
        from geometry_msgs.msg import Twist  # noqa: PLC0415
        from sensor_msgs.msg import CompressedImage  # noqa: PLC0415
        from std_msgs.msg import Int32, String  # noqa: PLC0415
    except ImportError as error:
        raise MorError(f"rclpy (ROS 2) is not importable ({error}); source your ROS 2 setup (e.g. source "
                       "/opt/ros/jazzy/setup.bash) in this shell, with the Python that runs mor, and run "
                       "again") from None
    return rclpy, Twist, CompressedImage, Int32, String


def _stamp_ns(message: Any) -> int:
    return int(message.header.stamp.sec) * 1_000_000_000 + int(message.header.stamp.nanosec)


def run_live(controller: Controller, params: RobotParams, recorder: RunRecorder, max_steps: int) -> int:
    """Drive the robot with ``controller`` (started on its task) until Ctrl-C, giving up or ``max_steps``; every
    step recorded. Returns the steps taken."""
    rclpy, Twist, CompressedImage, Int32, String = import_ros2()
    topics = RealTopics()
    rclpy.init()
    node = rclpy.create_node("mor_controller")
    latest: dict[str, Any] = {"top": None, "first_person": None, "held": -1}
    node.create_subscription(CompressedImage, params.top_image_topic, lambda m: latest.__setitem__("top", m), 1)
    node.create_subscription(CompressedImage, topics.image, lambda m: latest.__setitem__("first_person", m), 1)
    node.create_subscription(Int32, topics.held, lambda m: latest.__setitem__("held", int(m.data)), 10)
    cmd_vel = node.create_publisher(Twist, topics.cmd_vel, 10)
    strings = {topic: node.create_publisher(String, topic, 10) for topic in (topics.action, EVENT_TOPIC)}

    def say(topic: str, text: str) -> None:
        strings[topic].publish(String(data=text))

    def drive(linear: float, angular: float) -> None:
        twist = Twist()
        twist.linear.x, twist.angular.z = float(linear), float(angular)
        cmd_vel.publish(twist)

    def execute(command: Command) -> None:
        for segment in command.segments:
            end = time.monotonic() + segment.duration_s
            while True:
                drive(segment.linear_mps, segment.angular_radps)
                rclpy.spin_once(node, timeout_sec=0.0)
                if time.monotonic() >= end:
                    break
                time.sleep(min(1.0 / CMD_RATE_HZ, end - time.monotonic()))

    def frame_after(ready_ns: int) -> Frame:
        camera = "top" if controller.source.camera == "top_down" else "first_person"
        while latest[camera] is None or _stamp_ns(latest[camera]) < ready_ns:
            rclpy.spin_once(node, timeout_sec=0.1)
        top, first_person = latest["top"], latest["first_person"]
        return Frame(_stamp_ns(latest[camera]), latest["held"],
                     None if top is None else decode_image(top, "sensor_msgs/CompressedImage"),
                     None if first_person is None else decode_image(first_person, "sensor_msgs/CompressedImage"))

    steps, ready_ns = 0, node.get_clock().now().nanoseconds
    try:
        while steps < max_steps and not controller.gave_up:
            step = controller.step(frame_after(ready_ns))
            recorder.add(step)
            say(topics.action, step.command.name)
            for note in (step.command.event, step.note):
                if note:
                    say(EVENT_TOPIC, note)
            execute(step.command)
            ready_ns = node.get_clock().now().nanoseconds
            steps += step.command.action >= 0
    except KeyboardInterrupt:
        logger.warning("interrupted: stopping the robot")
    finally:
        drive(0.0, 0.0)
        node.destroy_node()
        rclpy.shutdown()
    return steps


__all__ = ["CMD_RATE_HZ", "import_ros2", "run_live"]
