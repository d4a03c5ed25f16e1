"""Wait for the robot description on a topic (``robot.urdf: topic:/robot_description``)."""

from __future__ import annotations

import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from semiparam_ros.errors import DescriptionTimeoutError
from semiparam_ros.ros.diagnostics import diagnostic_array

__all__ = ["wait_for_description"]

_NOTE_PERIOD_S = 5.0


def wait_for_description(node: Node, topic: str, timeout_s: float) -> str:
    """Wait for the URDF text on ``topic`` (robot_state_publisher's transient-local ``std_msgs/String``).

    Logs where it waits, every 5 s until it arrives, and publishes a WARN diagnostic meanwhile.

    Args:
        node: The node that waits (spun here, in a private executor, until the text arrives).
        topic: The topic name (relative names resolve in the node's namespace).
        timeout_s: Seconds to wait at most; ≤ 0 waits forever.

    Returns:
        The URDF text.

    Raises:
        DescriptionTimeoutError: Nothing arrived within ``timeout_s``, or the context shut down.
    """
    received: list[str] = []
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)

    def take(msg: String) -> None:
        received.append(msg.data)

    sub = node.create_subscription(String, topic, take, qos)
    diag = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
    name = node.resolve_topic_name(topic)
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    start = time.monotonic()
    next_note = start
    try:
        while not received:
            now = time.monotonic()
            if timeout_s > 0 and now - start > timeout_s:
                raise DescriptionTimeoutError(
                    f"no robot description on {name} within robot.description_timeout = {timeout_s:g} s "
                    "(is robot_state_publisher running?)")
            if now >= next_note:
                next_note = now + _NOTE_PERIOD_S
                node.get_logger().info(f"waiting for the robot description on {name} (std_msgs/String, "
                                       "transient local, as robot_state_publisher publishes it)")
                diag.publish(diagnostic_array(node.get_clock().now().to_msg(),
                                              f"{node.get_name()}: online learning", "",
                                              {"waiting_for_robot_description": name}, waiting=True))
            executor.spin_once(timeout_sec=0.1)
            if not rclpy.ok(context=node.context):
                raise DescriptionTimeoutError(f"shut down while waiting for the robot description on {name}")
    finally:
        executor.remove_node(node)
        executor.shutdown(timeout_sec=1.0)
        node.destroy_subscription(sub)
        node.destroy_publisher(diag)
    node.get_logger().info(f"robot description received on {name} ({len(received[-1])} characters)")
    return received[-1]
