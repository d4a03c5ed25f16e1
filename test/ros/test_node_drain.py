"""The node's ``InputStreams.drain`` takes queued messages through ``sub.handle.take_message`` (not public
rclpy API; kept for the measured reason in its docstring). These tests fail if that call changes shape."""

from __future__ import annotations

import time

import pytest
import rclpy
from helpers.ros import in_process_node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

from semiparam_ros.ros.inputs import MAX_DRAIN as _MAX_DRAIN

pytestmark = pytest.mark.ros


@pytest.fixture
def node_and_publisher(tmp_path, monkeypatch):
    with in_process_node(tmp_path, monkeypatch) as node:
        source = rclpy.create_node("source", context=node.context)
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        pub = source.create_publisher(JointState, node.config["topics.joint_states"], qos)
        try:
            yield node, pub
        finally:
            source.destroy_node()


def _publish(pub, n):
    for k in range(n):
        msg = JointState(name=["a"], position=[0.0], velocity=[0.0], effort=[0.0])
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1, k
        pub.publish(msg)


def _wait_matched(pub, timeout=10.0):
    deadline = time.monotonic() + timeout
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert pub.get_subscription_count() > 0


def test_take_message_returns_message_and_info_then_none(node_and_publisher):
    node, pub = node_and_publisher
    _wait_matched(pub)
    _publish(pub, 1)
    sub = node.inputs.subscriptions["joint_states"]
    deadline, taken = time.monotonic() + 5.0, None
    while taken is None and time.monotonic() < deadline:
        with sub.handle:
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
        time.sleep(0.01)
    assert isinstance(taken, tuple) and isinstance(taken[0], bytes)  # the node subscribes serialised
    msg = deserialize_message(taken[0], JointState)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1, 0)
    with sub.handle:
        assert sub.handle.take_message(sub.msg_type, sub.raw) is None  # the history is empty now


def test_drain_takes_every_queued_message_in_order(node_and_publisher):
    node, pub = node_and_publisher
    _wait_matched(pub)
    n = _MAX_DRAIN + 10
    _publish(pub, n)
    time.sleep(0.5)  # let DDS deliver into the subscription's history (depth 100 > n)
    node.inputs.drain("joint_states")
    assert len(node.loop.queue) == _MAX_DRAIN  # bounded per callback
    node.inputs.drain("joint_states")
    stamps = [item.stamp_ns for _, item, _ in node.loop.queue]
    assert stamps == [1_000_000_000 + k for k in range(n)]


def test_drain_alternates_the_two_subscriptions(node_and_publisher):
    """Both streams queued: taken one of each in turn (the other kind first), so neither runs ahead."""
    from geometry_msgs.msg import WrenchStamped

    node, pub = node_and_publisher
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    source = rclpy.create_node("source_wrench", context=node.context)
    try:
        wpub = source.create_publisher(WrenchStamped, node.config["topics.wrench"], qos)
        _wait_matched(pub)
        _wait_matched(wpub)
        n_js, n_w = 30, 20
        _publish(pub, n_js)
        for k in range(n_w):
            w = WrenchStamped()
            w.header.stamp.sec, w.header.stamp.nanosec = 2, k
            wpub.publish(w)
        time.sleep(0.5)
        node.inputs.drain("joint_states")
        kinds = [kind for kind, _, _ in node.loop.queue]
        assert kinds == ["wrench", "joint_states"] * n_w + ["joint_states"] * (n_js - n_w)
        assert [item.stamp_ns for kind, item, _ in node.loop.queue if kind == "wrench"] == [
            2_000_000_000 + k for k in range(n_w)]
    finally:
        source.destroy_node()
