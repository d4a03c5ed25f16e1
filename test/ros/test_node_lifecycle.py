"""``estimator --lifecycle``: configure builds, activate learns and publishes, deactivate stops both and
keeps the model, cleanup writes the final checkpoint; a configure that cannot succeed leaves the node
unconfigured."""

from __future__ import annotations

import time

import numpy as np
import pytest
from helpers.ros import CONFIG, NodeProcess, TestClient, make_ros_env
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from semiparam_ros.core.config import ICUB_RIGHT_ARM
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.rigid_body.urdf import resolve_urdf

pytestmark = pytest.mark.ros

JOINTS = ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]


def _state(client):
    return client.call(GetState, "/estimator/get_state", GetState.Request()).current_state.label


def _transition(client, transition_id):
    request = ChangeState.Request()
    request.transition = Transition(id=transition_id)
    return client.call(ChangeState, "/estimator/change_state", request).success


def _publish(pub, start, n):
    for k in range(start, start + n):
        msg = JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1000 + k // 100, (k % 100) * 10_000_000
        q = 0.3 * np.sin(0.02 * k + np.arange(4))
        msg.name, msg.position, msg.velocity = JOINTS, q.tolist(), np.cos(q).tolist()
        msg.effort = np.sin(q).tolist()
        pub.publish(msg)
        time.sleep(0.005)


def test_lifecycle_transitions(tmp_path, monkeypatch):
    env = make_ros_env(tmp_path, monkeypatch)
    ckpt = tmp_path / "life.npz"
    params = ["robot.output:=joint_torques", "nonparametric.n_features:=20",
              "robot.urdf:=topic:/robot_description", f"checkpoint.path:={ckpt}", "checkpoint.period:=0.0",
              "diagnostics.period:=0.2"]
    node = NodeProcess(env, params, params_file=CONFIG, node_args=["--lifecycle"], tag="life")
    client = TestClient(env)
    predictions = client.collect(JointState, "/estimator/predicted_joint_torques")
    reliable = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE)
    pub = client.node.create_publisher(JointState, "/joint_states", reliable)
    try:
        getter = client.node.create_client(GetState, "/estimator/get_state")
        assert getter.wait_for_service(60.0), node.output()
        assert _state(client) == "unconfigured"
        assert not client.wait_for_publisher("/estimator/predicted_joint_torques", timeout=0.5)
        # the description has not arrived: configure fails, the node stays unconfigured
        assert not _transition(client, Transition.TRANSITION_CONFIGURE)
        assert _state(client) == "unconfigured"
        latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        desc = client.node.create_publisher(String, "/robot_description", latched)
        desc.publish(String(data=resolve_urdf(ICUB_RIGHT_ARM["robot.urdf"]).read_text()))
        deadline = time.monotonic() + 30
        while not _transition(client, Transition.TRANSITION_CONFIGURE):
            assert time.monotonic() < deadline, node.output()
            time.sleep(0.2)
        assert _state(client) == "inactive"
        assert client.wait_for_publisher("/estimator/predicted_joint_torques", timeout=30.0)
        time.sleep(0.5)
        _publish(pub, 0, 50)  # inactive: not taken
        time.sleep(0.5)
        assert predictions.snapshot() == []
        assert _transition(client, Transition.TRANSITION_ACTIVATE) and _state(client) == "active"
        time.sleep(0.3)
        _publish(pub, 50, 100)
        assert predictions.wait_for(lambda m: len(m) > 50, timeout=20.0), node.output()
        assert _transition(client, Transition.TRANSITION_DEACTIVATE) and _state(client) == "inactive"
        time.sleep(0.3)
        seen = len(predictions.snapshot())
        _publish(pub, 150, 50)
        time.sleep(0.5)
        assert len(predictions.snapshot()) == seen  # nothing published while inactive
        assert _transition(client, Transition.TRANSITION_CLEANUP) and _state(client) == "unconfigured"
        assert ckpt.is_file(), node.output()
        assert not client.wait_for_publisher("/estimator/predicted_joint_torques", timeout=1.0)
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()
    from semiparam_ros.core.config import load_config

    config = load_config(CONFIG).with_overrides({"robot.output": "joint_torques",
                                                 "nonparametric.n_features": 20})
    est = OnlineEstimator(config)
    est.load(ckpt)
    assert 0 < est.n_samples_learned <= 100  # learned only while active
