"""The node's contact-detection outputs over DDS: external wrench/torques and the predictive σ.

``~/external_wrench`` must equal the measured wrench of the bag (decoded independently here) minus the
node's own ``~/predicted_wrench`` at the same stamp, in the input's frame; ``~/predicted_wrench/std`` must
equal the σ offline replay computes; the gate's parameters are refused at run time with their name.
"""

from __future__ import annotations

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from helpers.ros import (
    RELIABLE_INPUTS,
    RELIABLE_JOINT_STATES,
    TOPICS,
    NodeProcess,
    TestClient,
    diagnostic_values,
    make_ros_env,
    source_bag,
    stamp_ns,
    wrench_array,
)
from sensor_msgs.msg import JointState

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.io.bags import read_messages
from semiparam_ros.ros.bag_player import BagPlayer, load_raw

pytestmark = pytest.mark.ros

N_MESSAGES = 800  # 400 joint-state/wrench pairs
PARAMS = [*RELIABLE_INPUTS, "nonparametric.standardizer_warmup:=50", "nonparametric.n_features:=100",
          "diagnostics.period:=0.25"]
OVERRIDES = {"nonparametric.standardizer_warmup": 50, "nonparametric.n_features": 100}


@pytest.fixture
def ros_env(tmp_path, monkeypatch):
    return make_ros_env(tmp_path, monkeypatch)


def _offline_std(bag, overrides, messages) -> dict[int, np.ndarray]:
    from helpers.ros import CONFIG

    est = OnlineEstimator(load_config(CONFIG).with_overrides(overrides))
    out = {}
    for msg in messages:
        results = est.process(msg)
        out.update({r.sample.stamp_ns: r.std for r in results})
    return out


def test_external_wrench_and_std_over_dds_and_gate_parameters(ros_env, tmp_path_factory):
    bag = source_bag(tmp_path_factory.mktemp("bags"))
    messages = load_raw(bag, TOPICS, limit=N_MESSAGES)
    decoded = list(read_messages(bag))[:N_MESSAGES]
    measured = {m.stamp_ns: np.concatenate([m.force, m.torque]) for m in decoded
                if not isinstance(m, JointStateData)}
    offline_std = _offline_std(bag, OVERRIDES, decoded)
    node = NodeProcess(ros_env, PARAMS)
    client = TestClient(ros_env)
    try:
        total = client.collect(WrenchStamped, "/estimator/predicted_wrench")
        external = client.collect(WrenchStamped, "/estimator/external_wrench")
        std = client.collect(WrenchStamped, "/estimator/predicted_wrench/std")
        diagnostics = client.collect(DiagnosticArray, "/diagnostics")
        for topic in ("/estimator/external_wrench", "/estimator/predicted_wrench/std"):
            assert client.wait_for_publisher(topic, timeout=60.0), node.output()

        # run-time refusals name the parameter; valid changes are taken
        for name, value in (("gate.threshold", 0.0), ("gate.max_contact_duration", -1.0),
                            ("gate.warmup", -2.0), ("uncertainty.noise_time_constant", 0.0)):
            reply = client.set_parameters("/estimator", {name: value})[0]
            assert not reply.successful and name in reply.reason, (name, reply.reason)
        assert client.set_parameters("/estimator", {"gate.threshold": 6.0})[0].successful

        player = BagPlayer(client.node, messages)
        assert player.wait_for_subscribers(timeout=60.0), node.output()
        assert diagnostics.wait_for(lambda m: bool(m), timeout=10.0), node.output()
        player.play(hz=400.0)
        expected = len(offline_std)
        assert external.wait_for(lambda m: len(m) >= expected, timeout=60.0), node.output()
        assert total.wait_for(lambda m: len(m) >= expected, timeout=10.0)
        assert std.wait_for(lambda m: len(m) >= expected, timeout=10.0)
        assert client.set_parameters("/estimator", {"gate.enabled": False})[0].successful
        assert diagnostics.wait_for(
            lambda m: diagnostic_values(m[-1]).get("gate_enabled") == "false", timeout=10.0)
        diag = diagnostic_values(diagnostics.snapshot()[-1])
        assert diag["not_learned.gated_contact"] == "0"  # 4 s of clean data: nothing gated
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()

    got_total = {stamp_ns(m): wrench_array(m) for m in total.snapshot()}
    got_ext = {stamp_ns(m): m for m in external.snapshot()}
    got_std = {stamp_ns(m): wrench_array(m) for m in std.snapshot()}
    assert set(got_ext) == set(got_total) == set(got_std) == set(offline_std)
    for stamp, msg in got_ext.items():
        assert msg.header.frame_id == "r_arm_ft_sensor"
        # measured − predicted: one subtraction of doubles carried exactly by CDR
        np.testing.assert_array_equal(wrench_array(msg), measured[stamp] - got_total[stamp])
        # σ as offline replay computes it (same messages, same order; 1e-9 as the node replay test)
        np.testing.assert_allclose(got_std[stamp], offline_std[stamp], rtol=1e-9, atol=0)


def test_external_joint_torques_over_dds(ros_env, tmp_path):
    from helpers.ros import write_torque_bag

    bag = tmp_path / "torques"
    write_torque_bag(bag, 300)
    messages = load_raw(bag, ["/joint_states"])
    decoded = list(read_messages(bag, wrench_topic=None))
    efforts = {m.stamp_ns: np.asarray(m.effort) for m in decoded}
    overrides = {"robot.output": "joint_torques", **OVERRIDES}
    offline_std = _offline_std(bag, overrides, decoded)
    node = NodeProcess(ros_env, [*RELIABLE_JOINT_STATES, "robot.output:=joint_torques",
                                 "nonparametric.standardizer_warmup:=50", "nonparametric.n_features:=100"])
    client = TestClient(ros_env)
    try:
        torques = client.collect(JointState, "/estimator/predicted_joint_torques")
        external = client.collect(JointState, "/estimator/external_joint_torques")
        std = client.collect(JointState, "/estimator/predicted_joint_torques/std")
        assert client.wait_for_publisher("/estimator/external_joint_torques", timeout=60.0), node.output()
        assert client.wait_for_publisher("/estimator/predicted_joint_torques/std", timeout=10.0)
        player = BagPlayer(client.node, messages)
        assert player.wait_for_subscribers(timeout=60.0), node.output()
        player.play(hz=400.0)
        n = len(offline_std)
        assert external.wait_for(lambda m: len(m) >= n, timeout=60.0), node.output()
        assert torques.wait_for(lambda m: len(m) >= n, timeout=10.0)
        assert std.wait_for(lambda m: len(m) >= n, timeout=10.0)
        assert client.node.count_publishers("/estimator/external_wrench") == 0
    finally:
        client.close()
        assert node.stop() == 0, node.output()
    pred = {stamp_ns(m): np.asarray(m.effort) for m in torques.snapshot()}
    got_std = {stamp_ns(m): np.asarray(m.effort) for m in std.snapshot()}
    joints = ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]
    for msg in external.snapshot():
        s = stamp_ns(msg)
        assert list(msg.name) == joints
        np.testing.assert_array_equal(np.asarray(msg.effort), efforts[s] - pred[s])
        np.testing.assert_allclose(got_std[s], offline_std[s], rtol=1e-9, atol=0)
