"""The floor of a Python rclpy answer on this machine: a node that answers each desired state at once.

It subscribes to ``/joint_states`` (taken and discarded, as a node learning nothing would) and to
``/estimator/desired_state`` (the estimator's QoS), and answers each desired state with a ``JointState`` on
``/estimator/feedforward`` carrying its stamp and zero efforts: no model, only the transport, the executor
and the publish, with the estimator's default executor (``EventsExecutor``). ``bench_feedforward.py`` runs it
after the estimator's runs, on the same machine and stream.

    .venv/bin/python bench/node/echo_node.py   # ROS_DOMAIN_ID from the environment; Ctrl-C ends it
"""

from __future__ import annotations

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory


def main() -> None:
    rclpy.init()
    node = Node("estimator")
    publisher = node.create_publisher(JointState, "/estimator/feedforward", 10)

    def answer(msg: JointTrajectory) -> None:
        out = JointState()
        out.header.stamp = msg.header.stamp
        out.name = list(msg.joint_names)
        out.position = list(msg.points[0].positions)
        out.effort = [0.0] * len(out.name)
        publisher.publish(out)

    node.create_subscription(JointState, "/joint_states", lambda msg: None,
                             QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
    node.create_subscription(JointTrajectory, "/estimator/desired_state", answer,
                             QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                                        reliability=ReliabilityPolicy.BEST_EFFORT,
                                        durability=DurabilityPolicy.VOLATILE))
    executor = EventsExecutor()  # the estimator's default executor, driven as its main() drives it
    executor.add_node(node)
    try:
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
