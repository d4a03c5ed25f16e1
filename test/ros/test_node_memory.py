"""What the node itself keeps after oversized messages: measured by tracemalloc, not by the process's RSS.

The fault-injection suite sends oversized JointStates over DDS and reads the process RSS, which counts
the middleware's receive buffers (62–70 MB on some runs, nothing the node holds). Here one node runs in
this process and its subscription callback is called with the serialised messages, as the executor
calls it; tracemalloc counts every Python and numpy allocation the node's code keeps. Oversized messages
are refused from their header (counted, never decoded), so 100 of them (≈ 70 MB of names) must leave
what 10 of them left: the bound is a few tens of kB, whatever the allocator, the machine or the CI.
"""

from __future__ import annotations

import gc
import tracemalloc

import numpy as np
import pytest
from helpers.ros import in_process_node
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

pytestmark = pytest.mark.ros

JOINTS = ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]
OVERSIZED_NAMES = 20_000  # ≈ 0.7 MB a message


def _valid(k: int) -> bytes:
    t = k / 200.0
    msg = JointState(name=JOINTS)
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(10**18 + round(t * 1e9), 10**9)
    q = 0.3 * np.sin(2 * np.pi * np.array([0.3, 0.5, 0.4, 0.6]) * t)
    msg.position, msg.velocity, msg.effort = q.tolist(), (0.1 * q).tolist(), (2 * q).tolist()
    return bytes(serialize_message(msg))


def _retained(node, messages: list[bytes]) -> int:
    """Bytes of Python/numpy allocations still held after the node took ``messages`` (one at a time)."""
    gc.collect()
    before = tracemalloc.take_snapshot()
    for raw in messages:
        node._on_input("joint_states", raw)  # what the subscription callback does with a message
    del raw
    gc.collect()
    after = tracemalloc.take_snapshot()
    return sum(stat.size_diff for stat in after.compare_to(before, "filename"))


def test_oversized_messages_leave_nothing_behind_in_the_node(tmp_path, monkeypatch):
    big = JointState(name=[f"joint_{i}" for i in range(OVERSIZED_NAMES)])
    big.position = big.velocity = big.effort = [0.0] * OVERSIZED_NAMES
    oversized = bytes(serialize_message(big))
    assert len(oversized) > 600_000
    # overload.max_delay 0: every valid sample is learned however long the calls took (a loaded machine)
    with in_process_node(tmp_path, monkeypatch, **{"robot.output": "joint_torques", "overload.max_delay": 0.0,
                                                   "nonparametric.n_features": 50}) as node:
        valid = [_valid(k) for k in range(400)]
        tracemalloc.start(1)
        try:
            _retained(node, valid[:200])  # warm: caches, the estimator's buffers, lazily built arrays
            ten = _retained(node, [oversized] * 10 + valid[200:250])
            hundred = _retained(node, [oversized] * 100 + valid[250:300])
        finally:
            tracemalloc.stop()
        drops = node._stats.snapshot()
        assert node.estimator.n_samples_learned > 250  # the valid stream went on between them
    print(f"retained by the node: {ten / 1024:.1f} kB after 10 oversized messages, "
          f"{hundred / 1024:.1f} kB after 100 more")
    assert drops["drops.conversion_error"] == 110, drops
    assert hundred < 64 * 1024 and ten < 64 * 1024  # against ≈ 70 MB of names sent
