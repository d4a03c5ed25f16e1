"""Where the URDF comes from: a path, ``package://`` and ``example-robot-data://`` through the ament index
then the pip prefix, and the ``/robot_description`` topic that robot_state_publisher latches."""

from __future__ import annotations

import time

import pytest
from helpers.ros import REPO, NodeProcess, TestClient, make_ros_env
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from semiparam_ros.core.config import ICUB_RIGHT_ARM
from semiparam_ros.core.rigid_body.urdf import example_robot_data_path, resolve_urdf
from semiparam_ros.errors import ConfigurationError

PANDA_REL = "robots/panda_description/urdf/panda.urdf"


def _ament_prefix(root, package, relative, text):
    (root / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (root / "share" / "ament_index" / "resource_index" / "packages" / package).write_text("")
    path = root / "share" / package / relative
    path.parent.mkdir(parents=True)
    path.write_text(text)
    return path


def test_package_uris_use_the_ament_index_then_the_pip_prefix(tmp_path, monkeypatch):
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    wheel = example_robot_data_path(PANDA_REL)
    # no ROS environment: the wheel's copy, by either scheme
    assert resolve_urdf(f"example-robot-data://{PANDA_REL}") == wheel
    assert resolve_urdf(f"package://example-robot-data/{PANDA_REL}") == wheel
    # a sourced ROS install (an ament prefix) wins
    mine = _ament_prefix(tmp_path / "install", "my_robot_description", "urdf/arm.urdf", "<robot name='a'/>")
    erd = _ament_prefix(tmp_path / "ros", "example-robot-data", PANDA_REL, wheel.read_text())
    monkeypatch.setenv("AMENT_PREFIX_PATH", f"{tmp_path / 'install'}:{tmp_path / 'ros'}")
    assert resolve_urdf("package://my_robot_description/urdf/arm.urdf") == mine.resolve()
    assert resolve_urdf(f"example-robot-data://{PANDA_REL}") == erd.resolve()
    with pytest.raises(FileNotFoundError, match=r"package://nope/x\.urdf not found; tried the ament index"):
        resolve_urdf("package://nope/x.urdf")
    with pytest.raises(ConfigurationError, match="names a topic"):
        resolve_urdf("topic:/robot_description")


def _latch(client, text):
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    pub = client.node.create_publisher(String, "/robot_description", qos)
    pub.publish(String(data=text))
    return pub


def test_node_waits_for_the_robot_description_topic(tmp_path, monkeypatch):
    env = make_ros_env(tmp_path, monkeypatch)
    params = ["robot.urdf:=topic:/robot_description", "nonparametric.n_features:=20"]
    node = NodeProcess(env, params, params_file=REPO / "config" / "panda.yaml", tag="wait")
    client = TestClient(env)
    try:
        deadline = time.monotonic() + 60
        while "waiting for the robot description on /robot_description" not in node.output():
            assert time.monotonic() < deadline and node.alive(), node.output()
            time.sleep(0.1)
        assert not client.wait_for_publisher("/estimator/feedforward", timeout=1.0)  # not up yet
        _latch(client, resolve_urdf(f"example-robot-data://{PANDA_REL}").read_text())
        assert client.wait_for_publisher("/estimator/feedforward", timeout=60.0), node.output()
        assert "robot description received on /robot_description" in node.output()
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()


def test_description_without_the_joints_or_none_at_all_stops_the_node(tmp_path, monkeypatch):
    env = make_ros_env(tmp_path, monkeypatch)
    client = TestClient(env)
    try:
        _latch(client, resolve_urdf(ICUB_RIGHT_ARM["robot.urdf"]).read_text())  # the iCub: no panda joints
        node = NodeProcess(env, ["robot.urdf:=topic:/robot_description"],
                           params_file=REPO / "config" / "panda.yaml", tag="wrong")
        assert node.wait(timeout=120) == 2
        out = node.output()
        node.stop()
        assert "unknown joint 'panda_joint1'" in out and "published on topic:/robot_description" in out, out
        assert "its moving joints" in out and "Traceback" not in out
        late = NodeProcess(env, ["robot.urdf:=topic:/nobody_publishes", "robot.description_timeout:=1.0"],
                           params_file=REPO / "config" / "panda.yaml", tag="none")
        assert late.wait(timeout=120) == 2
        out = late.output()
        late.stop()
        assert "no robot description on /nobody_publishes within robot.description_timeout = 1 s" in out, out
    finally:
        client.close()
