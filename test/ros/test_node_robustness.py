"""What a robot computer does to a node: stale temporaries, a disk that refuses the checkpoint, a planted
absurd value, invalid stamps, a middleware counter glitch — each a clear message or a counted drop."""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from helpers.ros import CONFIG, NodeProcess, TestClient, in_process_node, make_ros_env
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from semiparam_ros.core.checkpoint import atomic_save_npz, load_npz
from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.messages import stamp_to_ns
from semiparam_ros.errors import CheckpointError, RejectedSampleError
from semiparam_ros.ros.conversions import joint_state_from_cdr

pytestmark = pytest.mark.ros

JOINTS = ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]
TORQUES = ["robot.output:=joint_torques", "nonparametric.n_features:=20", "diagnostics.period:=0.2"]


def _joint_state(k, nanosec=None):
    msg = JointState()
    msg.header.stamp.sec = 100 + k // 100
    msg.header.stamp.nanosec = (k % 100) * 10_000_000 if nanosec is None else nanosec
    q = 0.3 * np.sin(0.02 * k + np.arange(4))
    msg.name, msg.position = JOINTS, q.tolist()
    msg.velocity, msg.effort = np.cos(q).tolist(), np.sin(q).tolist()
    return msg


def test_invalid_nanosec_is_refused_by_both_decoders():
    with pytest.raises(RejectedSampleError, match="nanosec"):
        stamp_to_ns(1, 10**9)
    raw = serialize_message(_joint_state(0, nanosec=0xFFFFFFFF))
    with pytest.raises(RejectedSampleError, match="nanosec"):
        joint_state_from_cdr(raw)
    assert joint_state_from_cdr(serialize_message(_joint_state(3))).stamp_ns == 100 * 10**9 + 30_000_000


def test_a_middleware_lost_count_glitch_is_not_added(tmp_path, monkeypatch):
    with in_process_node(tmp_path, monkeypatch) as node:
        count = node.inputs.lost_counter("joint_states")
        count(SimpleNamespace(total_count=5, total_count_change=5))
        count(SimpleNamespace(total_count=5 + 2**31, total_count_change=2**31))  # a wrapped counter
        count(SimpleNamespace(total_count=5 + 2**31 + 2, total_count_change=2))
        assert node._stats.snapshot()["drops.dds_message_lost"] == 5 + 1 + 2


def test_planted_absurd_value_in_a_checkpoint_is_refused(tmp_path):
    config = load_config(CONFIG).with_overrides({"nonparametric.n_features": 20})
    est = OnlineEstimator(config)
    est.save(tmp_path / "ok.npz")
    state = load_npz(tmp_path / "ok.npz")
    key = "model.nonparametric.rls.M"  # the residual's factor: finite but absurd loads, then refuses samples
    state[key] = state[key].copy()
    state[key].flat[-1] = 1e300
    atomic_save_npz(tmp_path / "bad.npz", state)
    with pytest.raises(CheckpointError, match=key.replace(".", r"\.")):
        OnlineEstimator(config).load(tmp_path / "bad.npz")


def test_stale_temporaries_cold_start_and_a_disk_that_refuses_the_checkpoint(tmp_path, monkeypatch):
    env = make_ros_env(tmp_path, monkeypatch)
    good = tmp_path / "ckpt"
    good.mkdir()
    stale = good / ".model.npz.0123456789abcdef.tmp"
    stale.write_bytes(b"half a checkpoint")
    keep = good / "notes.tmp"
    keep.write_text("not ours")
    node = NodeProcess(env, [*TORQUES, f"checkpoint.path:={good / 'model.npz'}"], tag="stale")
    client = TestClient(env)
    try:
        assert client.wait_for_publisher("/estimator/predicted_joint_torques", timeout=60.0), node.output()
    finally:
        client.close()
        assert node.stop() == 0
    out = node.output()
    assert not stale.exists() and keep.exists()
    assert f"removed {stale}" in out and "cold start: no checkpoint at" in out, out

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    node = NodeProcess(env, [*TORQUES, f"checkpoint.path:={blocker / 'model.npz'}", "checkpoint.period:=0.0"],
                       tag="refused")
    client = TestClient(env)
    diagnostics = client.collect(DiagnosticArray, "/diagnostics")
    try:
        pub = client.node.create_publisher(JointState, "/joint_states",
                                           QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        assert client.wait_for_publisher("/estimator/predicted_joint_torques", timeout=60.0), node.output()
        time.sleep(0.5)
        for k in range(60):
            pub.publish(_joint_state(k))
            time.sleep(0.005)
        time.sleep(0.5)
        reply = client.trigger("/estimator/save")
        assert not reply.success and "checkpoint failed" in reply.message
        assert diagnostics.wait_for(lambda m: m and m[-1].status[0].level == DiagnosticStatus.ERROR, 10.0)
        assert "checkpoint write failed" in diagnostics.snapshot()[-1].status[0].message
    finally:
        client.close()
        code = node.stop()
    assert code == 1, node.output()  # the final checkpoint could not be written either
    assert "the final checkpoint could not be written" in node.output()


def test_oversized_joint_states_are_refused_cheaply_and_the_name_cache_is_bounded():
    from semiparam_ros.core.estimator.build import build_pipeline
    from semiparam_ros.core.stream.messages import JointStateData

    big = JointState()
    n = 200_000
    big.name = [f"joint_{i}" for i in range(n)]
    big.position = big.velocity = big.effort = [0.0] * n
    raw = bytes(serialize_message(big))
    start = time.perf_counter()
    with pytest.raises(RejectedSampleError, match="oversized JointState"):
        joint_state_from_cdr(raw, max_names=1024)
    assert time.perf_counter() - start < 0.05  # refused from its header, its names never decoded
    assert len(joint_state_from_cdr(raw).names) == n  # without a bound it decodes (the offline readers)
    # distinct large name lists: the pipeline's cache keeps a bounded amount of name text
    pipeline = build_pipeline(load_config(CONFIG))
    for k in range(40):
        names = tuple(f"k{k}_{i:06d}" for i in range(20_000)) + tuple(JOINTS)
        pipeline.add(JointStateData(10**9 + k * 10**7, names, np.zeros(len(names)),
                                                np.zeros(len(names)), np.zeros(len(names))))
    assert pipeline._name_cache_bytes <= 1 << 20
    assert sum(sum(len(s) for s in key) for key in pipeline._name_cache) <= 1 << 20


def test_a_diagnostics_timer_that_fell_behind_does_not_publish_an_empty_period(tmp_path, monkeypatch):
    """Measured in the soak: a timer catching up fired twice at once, and every second period published
    was a few µs long with no samples (NaN latencies, a spurious 'no input' warning)."""
    with in_process_node(tmp_path, monkeypatch, **{"diagnostics.period": 0.2}) as node:
        published = []
        monkeypatch.setattr(node.outputs.diagnostics, "publish", published.append)
        node._on_diagnostics_timer()
        node._on_diagnostics_timer()  # the catch-up call: merged into the next period
        assert len(published) == 1
        time.sleep(0.12)
        node._on_diagnostics_timer()  # more than half a period later: a period of its own
        assert len(published) == 2
