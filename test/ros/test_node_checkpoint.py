"""Checkpoints: ~/save, kill -9, warm restart gives the same prediction; periodic and shutdown saves."""

from __future__ import annotations

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from helpers.ros import (
    CONFIG,
    RELIABLE_INPUTS,
    TOPICS,
    NodeProcess,
    TestClient,
    diagnostic_values,
    make_ros_env,
    offline_replay,
    source_bag,
    stamp_ns,
    wait_quiet,
    wait_until,
    wrench_array,
)
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from semiparam_ros.core.checkpoint import load_npz
from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.ros.bag_player import BagPlayer, RawMessage, load_raw
from semiparam_ros.ros.conversions import stamp_msg

pytestmark = pytest.mark.ros

N_MESSAGES = 600
JOINTS = ("r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow")


@pytest.fixture
def ros_env(tmp_path, monkeypatch):
    return make_ros_env(tmp_path, monkeypatch)


def static_probe(start_ns: int, q: np.ndarray, wrench: np.ndarray, n: int) -> list[RawMessage]:
    """n joint-state/wrench pairs at 100 Hz holding the arm still at q (dq = 0, so q̈ = 0 once warm)."""
    out = []
    for k in range(n):
        stamp = start_ns + k * 10_000_000
        js = JointState(name=list(JOINTS), position=[float(v) for v in q], velocity=[0.0] * 4)
        js.header.stamp = stamp_msg(stamp)
        w = WrenchStamped()
        w.header.stamp, w.header.frame_id = stamp_msg(stamp), "r_arm_ft_sensor"
        f, t = w.wrench.force, w.wrench.torque
        f.x, f.y, f.z, t.x, t.y, t.z = (float(v) for v in wrench)
        out.append(RawMessage("/joint_states", "sensor_msgs/msg/JointState", stamp, serialize_message(js)))
        out.append(RawMessage("/wrench", "geometry_msgs/msg/WrenchStamped", stamp, serialize_message(w)))
    return out


def checkpoint_samples(path) -> int:
    return int(load_npz(path)["meta.n_samples_learned"])


def play(client: TestClient, node: NodeProcess, messages: list[RawMessage], hz: float = 400.0) -> None:
    player = BagPlayer(client.node, messages)
    assert player.wait_for_subscribers(timeout=60.0), node.output()
    player.play(hz=hz)


def learn_and_save(client: TestClient, node: NodeProcess, messages: list[RawMessage], n_samples: int,
                   ckpt, timeout: float = 30.0):
    """Play ``messages``, wait for their ``n_samples`` predictions, call ``~/save`` and check the file holds
    every one of them; return the predictions collector."""
    preds = client.collect(WrenchStamped, "/estimator/predicted_wrench")
    assert client.wait_for_publisher("/estimator/predicted_wrench"), node.output()
    play(client, node, messages)
    assert preds.wait_for(lambda m: len(m) >= n_samples, timeout=60.0), node.output()
    reply = client.trigger("/estimator/save", timeout=timeout)
    assert reply.success, reply.message
    assert checkpoint_samples(ckpt) == n_samples
    return preds


def test_save_kill_restart_gives_the_same_prediction(ros_env, tmp_path, tmp_path_factory):
    bag = source_bag(tmp_path_factory.mktemp("bags"))
    messages = load_raw(bag, TOPICS, limit=N_MESSAGES)
    offline = offline_replay(bag, N_MESSAGES, {"nonparametric.standardizer_warmup": 50})
    last = offline.order[-1]
    ckpt = tmp_path / "ckpt" / "estimator.npz"
    params = [*RELIABLE_INPUTS, f"checkpoint.path:={ckpt}", "nonparametric.standardizer_warmup:=50",
              "diagnostics.period:=0.25"]
    probe = static_probe(last + 1_000_000_000, np.array([-0.3, 0.4, 0.1, 1.0]), offline.measured[last], 15)
    probe_stamps = [m.log_time_ns for m in probe if m.topic == "/wrench"]

    # --- first run: learn, save, predict (learning off), then die without any shutdown handler
    node = NodeProcess(ros_env, [*params, "checkpoint.period:=0.0"], tag="first")
    client = TestClient(ros_env)
    try:
        preds = learn_and_save(client, node, messages, len(offline.order), ckpt)
        results = client.set_parameters("/estimator", {"learning_enabled": False})
        assert results[0].successful, results[0].reason
        play(client, node, probe)
        # the last window // 2 probe wrenches stay pending: q̈ of their joint states needs later ones
        assert wait_quiet(preds, lambda m: stamp_ns(m[-1]) in probe_stamps[-6:], timeout=30.0), node.output()
        before = [(stamp_ns(m), wrench_array(m)) for m in preds.snapshot()]
        node.kill()
    finally:
        client.close()
        node.kill()
    # the saved model's prediction for the resting arm (the last probe samples are all the same input)
    assert before[-2][0] in probe_stamps
    p_before = before[-1][1]
    np.testing.assert_allclose(before[-2][1], p_before, rtol=1e-12, atol=1e-12)
    assert np.all(np.isfinite(p_before))
    assert np.linalg.norm(p_before[:3]) > 1.0  # a learned model (a fresh one predicts 0 N)

    # --- second run: warm start from the checkpoint; the first prediction equals the one before the kill
    node = NodeProcess(ros_env, [*params, "checkpoint.period:=0.5"], tag="second")
    client = TestClient(ros_env)
    try:
        preds = client.collect(WrenchStamped, "/estimator/predicted_wrench")
        diagnostics = client.collect(DiagnosticArray, "/diagnostics")
        assert client.wait_for_publisher("/estimator/predicted_wrench"), node.output()
        assert diagnostics.wait_for(lambda m: bool(m), timeout=30.0), node.output()
        assert diagnostic_values(diagnostics.snapshot()[-1])["samples_learned"] == str(len(offline.order))
        play(client, node, probe)
        assert wait_quiet(preds, lambda m: stamp_ns(m[-1]) in probe_stamps[-6:], timeout=30.0), node.output()
        after = preds.snapshot()
        np.testing.assert_allclose(wrench_array(after[0]), p_before, rtol=1e-9, atol=1e-9)
        assert "warm start from" in node.output()

        # periodic checkpoint (0.5 s) picks up the probe samples learned by this run, no ~/save needed
        learned = len(offline.order) + len(after)
        assert wait_until(lambda: checkpoint_samples(ckpt) == learned, timeout=10.0), checkpoint_samples(ckpt)

        # with periodic checkpoints off, only the clean shutdown can save the next samples
        assert client.set_parameters("/estimator", {"checkpoint.period": 0.0})[0].successful
        more = static_probe(probe_stamps[-1] + 1_000_000_000, np.array([-0.2, 0.5, 0.0, 0.8]),
                            offline.measured[last], 12)
        play(client, node, more)
        more_stamps = [m.log_time_ns for m in more]
        assert wait_quiet(preds, lambda m: stamp_ns(m[-1]) in more_stamps, timeout=30.0), node.output()
        learned_total = len(offline.order) + len(preds.snapshot())
        assert checkpoint_samples(ckpt) == learned
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()
    assert checkpoint_samples(ckpt) == learned_total

    # the checkpoint is a valid, compatible estimator state
    est = OnlineEstimator(load_config(CONFIG).with_overrides({"nonparametric.standardizer_warmup": 50}))
    est.load(ckpt)
    assert est.n_samples_learned == learned_total
    assert not list(ckpt.parent.glob("*.tmp"))  # atomic writes leave no temp files behind


@pytest.mark.parametrize("executor", ["events", "single_threaded"])
def test_save_answers_under_either_executor(ros_env, tmp_path, tmp_path_factory, executor):
    """~/save (served by the helper node's own thread) replies with the file written, under both executors,
    and the samples played before it are all in the checkpoint."""
    bag = source_bag(tmp_path_factory.mktemp("bags"))
    messages = load_raw(bag, TOPICS, limit=200)
    offline = offline_replay(bag, 200, {"nonparametric.standardizer_warmup": 50})
    ckpt = tmp_path / "ckpt.npz"
    node = NodeProcess(ros_env, [*RELIABLE_INPUTS, f"checkpoint.path:={ckpt}", "checkpoint.period:=0.0",
                                 "nonparametric.standardizer_warmup:=50"], executor=executor)
    client = TestClient(ros_env)
    try:
        learn_and_save(client, node, messages, len(offline.order), ckpt)
    finally:
        client.close()
        node.stop()


def test_learning_is_kept_by_default_under_ros_home(ros_env, tmp_path, tmp_path_factory):
    """No checkpoint.path: ~/save succeeds, the file lies under $ROS_HOME (one per fully qualified node name)
    after SIGINT, and the next start warm-starts from it."""
    bag = source_bag(tmp_path_factory.mktemp("bags"))
    messages = load_raw(bag, TOPICS, limit=200)
    offline = offline_replay(bag, 200, {"nonparametric.standardizer_warmup": 50})
    home = tmp_path / "ros_home"
    ckpt = home / "semiparam_ros" / "estimator.npz"
    params = [*RELIABLE_INPUTS, "checkpoint.period:=0.0", "nonparametric.standardizer_warmup:=50"]
    node = NodeProcess(ros_env, params, tag="default")
    client = TestClient(ros_env)
    try:
        learn_and_save(client, node, messages, len(offline.order), ckpt)
    finally:
        client.close()
    assert node.stop() == 0, node.output()
    assert checkpoint_samples(ckpt) == len(offline.order)
    again = NodeProcess(ros_env, params, tag="again")
    try:
        assert wait_until(lambda: "warm start from" in again.output(), 60.0), again.output()
        assert str(ckpt) in again.output()
    finally:
        again.stop()
