"""Fault injection: every class of hostile input against one running node, a valid stream flowing.

One estimator node (a subprocess, joint torques of the iCub arm, default overload and glitch settings)
receives a valid 200 Hz JointState stream from this process; in between, each fault class of
docs/reliability.md is injected over the same topic. After each, and at the end, the suite asserts what
the table promises: the node is alive, the fault is counted under its reason (and no counter jumps by
more than the messages sent), every published prediction is finite, the velocity glitch leaves no
external torque beyond 3× the median (at least 0.05 N·m; a leak is 100+ N·m), and the oversized
messages are refused and counted. What the node keeps after them is measured exactly in
ros/test_node_memory.py (tracemalloc): the process RSS printed here also counts the middleware's receive
buffers (62–70 MB on some runs), so it is reported, not bounded.
Under ``CI`` the oversized case sends 20 messages instead of 100.
"""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import psutil
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from helpers.ros import NodeProcess, TestClient, diagnostic_values, make_ros_env, stamp_ns
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

pytestmark = [pytest.mark.ros, pytest.mark.slow]

JOINTS = ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]
PARAMS = ["robot.output:=joint_torques", "nonparametric.n_features:=50", "diagnostics.period:=0.2",
          "qos_overrides./joint_states.subscription.reliability:=reliable",
          "qos_overrides./joint_states.subscription.depth:=1000"]
HZ = 200.0
N_OVERSIZED = 20 if os.environ.get("CI") else 100
OVERSIZED_NAMES = 20_000  # ≈ 0.7 MB each: refused from the header (bound max(1024, 16 × 4 joints))


class Stream:
    """A valid JointState stream (multi-sine motion, torques of a smooth function of it) and injections."""

    def __init__(self, publisher) -> None:
        self.pub = publisher
        self.k = 0
        self.lock = threading.Lock()
        self.sent = 0
        self.stop = threading.Event()

    def state(self, k: int) -> JointState:
        t = k / HZ
        w = np.array([0.3, 0.5, 0.4, 0.6]) * 2 * np.pi
        q = np.array([-0.5, 0.5, 0.2, 0.9]) + 0.3 * np.sin(w * t)
        dq = 0.3 * w * np.cos(w * t)
        msg = JointState()
        stamp = 1_000_000_000_000_000_000 + round(k * 1e9 / HZ)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 10**9)
        msg.name = JOINTS
        msg.position, msg.velocity = q.tolist(), dq.tolist()
        msg.effort = (2.0 * np.sin(q) + 0.5 * dq).tolist()
        return msg

    def publish(self, msg: JointState | bytes) -> None:
        with self.lock:
            self.pub.publish(msg)
            self.sent += 1

    def next_valid(self) -> JointState:
        with self.lock:
            k = self.k
            self.k += 1
        return self.state(k)

    def run(self) -> None:
        start = time.perf_counter()
        n = 0
        while not self.stop.is_set():
            self.publish(self.next_valid())
            n += 1
            delay = start + n / HZ - time.perf_counter()
            if delay > 0:
                time.sleep(delay)


def test_every_fault_class_is_survived_counted_and_bounded(tmp_path, monkeypatch):
    ros_env = make_ros_env(tmp_path, monkeypatch)
    node = NodeProcess(ros_env, PARAMS, tag="faults")
    client = TestClient(ros_env)
    try:
        pub = client.node.create_publisher(JointState, "/joint_states",
                                           QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        predictions = client.collect(JointState, "/estimator/predicted_joint_torques")
        external = client.collect(JointState, "/estimator/external_joint_torques")
        diags = client.collect(DiagnosticArray, "/diagnostics")
        assert client.wait_for_publisher("/estimator/predicted_joint_torques", 60.0), node.output()
        deadline = time.monotonic() + 30.0
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        stream = Stream(pub)
        thread = threading.Thread(target=stream.run, daemon=True)
        thread.start()
        proc = psutil.Process(node.proc.pid)

        def drops() -> dict[str, int]:
            snap = diags.snapshot()
            assert snap, "no diagnostics"
            values = diagnostic_values(snap[-1])
            return {k: int(v) for k, v in values.items() if k.startswith("drops") or k == "queue_drops"}

        def settle() -> dict[str, int]:
            time.sleep(0.6)  # three diagnostics periods
            assert node.alive(), node.output()
            return drops()

        assert predictions.wait_for(lambda m: len(m) > 200, 60.0), node.output()  # learning, predicting
        before = settle()

        def inject(reason: str, messages: list, expected: int | None = None) -> None:
            nonlocal before
            for m in messages:
                stream.publish(m)
            after = settle()
            got = after.get(f"drops.{reason}", 0) - before.get(f"drops.{reason}", 0)
            assert got == (len(messages) if expected is None else expected), (reason, got, after)
            jump = after["drops_total"] - before["drops_total"]
            assert 0 <= jump <= stream.sent, (reason, jump)  # no counter jumps beyond what was sent
            before = after

        def faulty(**change) -> JointState:
            msg = stream.next_valid()
            for field, (joint, value) in change.items():
                values = list(getattr(msg, field))
                values[joint] = value
                setattr(msg, field, values)
            return msg

        inject("nonfinite_joint_state",
               [faulty(position=(1, float("nan"))), faulty(velocity=(2, float("inf")))])
        missing = stream.next_valid()
        missing.name, missing.position, missing.velocity, missing.effort = (
            JOINTS[:3], missing.position[:3], missing.velocity[:3], missing.effort[:3])
        inject("missing_joint", [missing])
        short = stream.next_valid()
        short.velocity = short.velocity[:2]
        inject("length_mismatch", [short])
        old = stream.state(max(stream.k - 50, 0))  # a stamp 0.25 s in the past
        inject("joint_state_backwards_stamp", [old])
        bad_stamp = stream.next_valid()
        bad_stamp.header.stamp.nanosec = 0xFFFFFFFF
        raw = bytes(serialize_message(stream.next_valid()))
        inject("conversion_error", [bad_stamp, raw[: len(raw) // 2]])  # invalid stamp; cut inside a value
        implausible = faulty(velocity=(0, 1e6))
        inject("implausible_value", [implausible])

        # the velocity glitch inside the bound: dropped as a glitch, it does not reach the outputs. Measured
        # here with the check off (limits.glitch_ratio 0), a leaked glitch shows 104–145 N·m of external
        # torque; dropped, at most 0.015 N·m. On this noise-free stream the median is ≈ 0.0015 N·m and the
        # transients the faults before it leave (0.005–0.034 N·m) can reach 3× it around the glitch (2 of 5
        # fresh-clone runs, with either glitch rule; 0.062 N·m once in a full-suite run on a loaded
        # machine): the bound is 3× the median but never below 0.2 N·m, still 500× under a leak
        glitch = faulty(velocity=(3, 99.0))
        inject("glitch", [glitch])
        glitch_ns = stamp_ns(glitch)
        time.sleep(0.3)
        ext = {stamp_ns(m): np.abs(np.asarray(m.effort)).max() for m in external.snapshot()}
        stamps = np.array(sorted(ext))
        recent = stamps[stamps > glitch_ns - 3 * 10**9]
        median = np.median([ext[s] for s in recent])
        near = [ext[s] for s in recent if abs(s - glitch_ns) <= 10**8]  # ±20 samples
        print(f"external torque around the glitch: max {max(near):.4f} N·m, median {median:.4f} N·m")
        assert len(near) > 10 and max(near) <= max(3.0 * median, 0.2), (max(near), median)

        # oversized messages: refused from the header, memory bounded
        big = JointState()
        big.name = [f"joint_{i}" for i in range(OVERSIZED_NAMES)]
        big.position = big.velocity = big.effort = [0.0] * OVERSIZED_NAMES
        rss_before = proc.memory_info().rss
        inject("conversion_error", [big] * N_OVERSIZED)
        rss_growth_mb = (proc.memory_info().rss - rss_before) / 2**20
        # reported only: the RSS counts the middleware's buffers (the node's own: ros/test_node_memory.py)
        print(f"RSS growth after {N_OVERSIZED} oversized JointStates: {rss_growth_mb:.1f} MB")

        stream.stop.set()
        thread.join(timeout=5.0)
        time.sleep(0.5)
        preds = predictions.snapshot()
        assert len(preds) > 1000
        assert all(np.isfinite(np.asarray(m.effort)).all() for m in preds)  # no NaN or inf published
        assert node.alive(), node.output()
        assert node.stop() == 0, node.output()  # and a clean shutdown after all of it
    finally:
        client.close()
        if node.alive():
            node.kill()
