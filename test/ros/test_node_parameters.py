"""Parameters: invalid values refused at start-up and at run time; learning switch, reset, remap, sim time."""

from __future__ import annotations

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from helpers.ros import (
    CONFIG,
    LATCHED_QOS,
    REPO,
    TOPICS,
    NodeProcess,
    TestClient,
    diagnostic_values,
    make_ros_env,
    source_bag,
    wait_quiet,
    wait_until,
)
from std_msgs.msg import Float64MultiArray

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.ros.bag_player import BagPlayer, load_raw

pytestmark = pytest.mark.ros


@pytest.fixture
def ros_env(tmp_path, monkeypatch):
    return make_ros_env(tmp_path, monkeypatch)


def test_invalid_startup_values_exit_with_a_clear_message(ros_env, tmp_path):
    incompatible = tmp_path / "d100.npz"
    OnlineEstimator(load_config(CONFIG).with_overrides({"nonparametric.n_features": 100})).save(incompatible)
    cases = {
        "n_features": (["nonparametric.n_features:=0"], ["nonparametric.n_features", ">= 1"]),
        "lam": (["parametric.lam:=-1.0"], ["parametric.lam", "> 0"]),
        "choice": (["robot.output:=torque"], ["robot.output", "'joint_torques'"]),
        "type": (["checkpoint.period:=abc"], ["checkpoint.period", "double"]),
        "odd_window": (["acceleration.window:=10"], ["acceleration.window", "odd"]),
        "joint": (["robot.joints:=[r_shoulder_pitch, no_such_joint]"], ["no_such_joint"]),
        # the joint semiparametric fit has one data weighting: both forgetting factors are named
        "joint_fit_forgetting": (["semiparametric.combination:=joint", "parametric.forgetting:=0.99"],
                                 ["parametric.forgetting", "nonparametric.forgetting", "joint"]),
        "checkpoint": ([f"checkpoint.path:={incompatible}"], ["d100.npz", "load_on_start"]),
        # the contact gate's parameters (core/stream/gate.py)
        "gate_threshold": (["gate.threshold:=0.0"], ["gate.threshold", "> 0"]),
        "gate_duration": (["gate.max_contact_duration:=-3.0"], ["gate.max_contact_duration", ">= 0"]),
        # a misspelt name is refused with the closest known one (rclpy would keep it silently)
        "misspelt": (["adaptaton.time_constant:=5.0"], ["unknown parameter 'adaptaton.time_constant'",
                                                        "did you mean 'adaptation.time_constant'"]),
    }
    procs = {name: NodeProcess(ros_env, params, tag=name) for name, (params, _) in cases.items()}
    for name, (_, needles) in cases.items():
        proc = procs[name]
        code = proc.wait(timeout=120)
        out = proc.output()
        assert code == 2, (name, out)
        assert "FATAL" in out, (name, out)
        for needle in needles:
            assert needle in out, (name, needle, out)
        assert "Traceback" not in out, (name, out)
        proc.stop()


def test_runtime_parameters_learning_switch_reset_remap_and_sim_time(ros_env, tmp_path_factory):
    bag = source_bag(tmp_path_factory.mktemp("bags"))
    messages = load_raw(bag, TOPICS, limit=300)
    # overload.max_delay 0: every sample is learned however late (on a loaded machine the default predicts
    # late samples without learning them, and the count below would depend on the load)
    params = ["use_sim_time:=true", "diagnostics.period:=0.2", "learning_enabled:=false",
              "overload.max_delay:=0.0",
              "qos_overrides./robot/joint_states.subscription.reliability:=reliable",
              "qos_overrides./robot/joint_states.subscription.depth:=1000",
              "qos_overrides./robot/wrench.subscription.reliability:=reliable",
              "qos_overrides./robot/wrench.subscription.depth:=1000"]
    node = NodeProcess(ros_env, params, extra_args=["-r", "joint_states:=/robot/joint_states",
                                                     "-r", "wrench:=/robot/wrench"])
    client = TestClient(ros_env)
    try:
        preds = client.collect(WrenchStamped, "/estimator/predicted_wrench")
        diagnostics = client.collect(DiagnosticArray, "/diagnostics")
        inertial = client.collect(Float64MultiArray, "/estimator/inertial_parameters", LATCHED_QOS)
        assert client.wait_for_publisher("/estimator/predicted_wrench", timeout=60.0), node.output()

        # run-time refusals: out of range, read-only, wrong type
        refused = client.set_parameters("/estimator", {"checkpoint.period": -1.0})[0]
        assert not refused.successful and "checkpoint.period" in refused.reason and "range" in refused.reason
        refused = client.set_parameters("/estimator", {"nonparametric.n_features": 10})[0]
        assert not refused.successful and "read-only" in refused.reason
        refused = client.set_parameters("/estimator", {"learning_enabled": "yes"})[0]
        assert not refused.successful

        # predict only: the remapped inputs are used, nothing is learned
        player = BagPlayer(client.node, messages, remap={t: "/robot" + t for t in TOPICS}, publish_clock=True)
        assert player.wait_for_subscribers(timeout=60.0), node.output()
        player.play(hz=500.0)
        assert wait_quiet(preds, lambda m: len(m) > 100, timeout=30.0), node.output()
        assert diagnostics.wait_for(lambda m: int(diagnostic_values(m[-1])["samples_predicted"]) > 100,
                          timeout=10.0)
        diag_msg = diagnostics.snapshot()[-1]
        diag = diagnostic_values(diag_msg)
        assert diag["samples_learned"] == "0" and diag["learning_enabled"] == "false"
        assert all(np.all(np.asarray(m.data) == 0.0) for m in inertial.snapshot())
        # use_sim_time: diagnostics are stamped with the bag's /clock, not the wall clock
        stamp = diag_msg.header.stamp.sec * 10**9 + diag_msg.header.stamp.nanosec
        assert messages[0].log_time_ns <= stamp <= messages[-1].log_time_ns

        # learning on: the same input is now learned
        assert client.set_parameters("/estimator", {"learning_enabled": True})[0].successful
        later = load_raw(bag, TOPICS, start_ns=messages[-1].log_time_ns + 1, end_ns=None, limit=300)
        remap = {t: "/robot" + t for t in TOPICS}
        BagPlayer(client.node, later, remap=remap, publish_clock=True).play(hz=500.0)
        assert diagnostics.wait_for(lambda m: int(diagnostic_values(m[-1])["samples_learned"]) > 100,
                          timeout=30.0), node.output()
        assert inertial.wait_for(lambda m: bool(m) and np.any(np.asarray(m[-1].data) != 0.0), timeout=10.0)

        # ~/reset forgets it all
        reply = client.trigger("/estimator/reset")
        assert reply.success, reply.message
        assert diagnostics.wait_for(lambda m: diagnostic_values(m[-1])["samples_learned"] == "0",
                          timeout=10.0)
        assert inertial.wait_for(lambda m: np.all(np.asarray(m[-1].data) == 0.0), timeout=10.0)
        assert node.alive(), node.output()
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()


def test_misspelt_name_in_a_parameter_file_and_print_defaults(ros_env, tmp_path):
    import subprocess
    import sys

    from semiparam_ros.core.config import PARAMETERS

    params = tmp_path / "typo.yaml"
    params.write_text("estimator:\n  ros__parameters:\n    use_sim_time: false\n"
                      "    gate:\n      treshold: 4.0\n")
    proc = NodeProcess(ros_env, params_file=params, tag="typo")
    assert proc.wait(timeout=120) == 2
    out = proc.output()
    proc.stop()
    assert "unknown parameter 'gate.treshold'" in out and "did you mean 'gate.threshold'" in out, out
    assert "Traceback" not in out
    listing = subprocess.run([sys.executable, "-m", "semiparam_ros.ros.main", "--print-defaults"],
                             capture_output=True, text=True, timeout=120, env=ros_env.env, check=True).stdout
    header = [line for line in listing.splitlines() if line.startswith("#")]
    lines = [line for line in listing.splitlines() if not line.startswith("#")]
    assert "robot.urdf and robot.joints" in " ".join(header)  # what the node needs, before the table
    assert [line.split(" (")[0] for line in lines] == [p.name for p in PARAMETERS]
    assert any(line.startswith("gate.threshold (double, > 0 and <= 1e+06, default 5.0, settable at run time)")
               for line in lines), lines


def test_missing_or_unparseable_parameter_file_is_one_line_and_exit_2(ros_env, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("estimator:\n  ros__parameters:\n    gate: [1, 2\n")
    for name, path in (("missing", tmp_path / "nope.yaml"), ("unparseable", bad)):
        proc = NodeProcess(ros_env, params_file=path, tag=name)
        assert proc.wait(timeout=120) == 2, (name, proc.output())
        out = proc.output()
        proc.stop()
        lines = [line for line in out.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("[estimator] FATAL:") and str(path) in lines[0], out


def test_a_shipped_parameter_file_applies_under_a_namespace_and_another_name(ros_env, tmp_path):
    """The shipped files are keyed '/**': a node '/arm/kuka_estimator' reads them (read back over ROS);
    a file keyed 'estimator:' does not reach it, and the node says so instead of starting on the defaults;
    without robot.urdf it does not start either."""
    shipped = REPO / "config" / "panda.yaml"
    assert shipped.read_text().count("\n/**:\n") == 1
    node = NodeProcess(ros_env, ["checkpoint.path:=''"], params_file=shipped, tag="ns",
                       extra_args=["-r", "__ns:=/arm", "-r", "__node:=kuka_estimator"])
    client = TestClient(ros_env)
    try:
        wanted = load_config(shipped)
        names = ["robot.urdf", "robot.joints", "robot.output", "nonparametric.n_features"]
        assert wait_until(lambda: client.node.count_subscribers("/arm/kuka_estimator/desired_state") > 0
                          or not node.alive(), timeout=120), node.output()
        got = client.get_parameters("/arm/kuka_estimator", names)
        assert got["robot.urdf"] == wanted["robot.urdf"]
        assert list(got["robot.joints"]) == wanted["robot.joints"]
        assert got["robot.output"] == "joint_torques" and got["nonparametric.n_features"] == 500
    finally:
        client.close()
        assert node.stop() == 0, node.output()

    old_style = tmp_path / "my_kuka.yaml"
    old_style.write_text(shipped.read_text().replace("\n/**:\n", "\nestimator:\n"))
    no_urdf = tmp_path / "no_urdf.yaml"
    no_urdf.write_text(shipped.read_text().replace('urdf: "example-robot-data://', 'frame_id: "'))
    assert "urdf:" not in no_urdf.read_text().split("robot:")[1].split("\n    topics")[0]
    cases = {
        "mismatch": (old_style, ["-r", "__ns:=/arm"],
                     ["no parameter file applies to this node, /arm/estimator", str(old_style), "'estimator'",
                      "'/**:'"]),
        "no_urdf": (no_urdf, [], ["robot.urdf is not set"]),
    }
    procs = {name: NodeProcess(ros_env, params_file=path, extra_args=args, tag=name)
             for name, (path, args, _) in cases.items()}
    for name, (_, _, needles) in cases.items():
        proc = procs[name]
        code = proc.wait(timeout=120)
        out = proc.output()
        proc.stop()
        assert code == 2, (name, out)
        assert all(n in out for n in needles), (name, out)
        assert "Traceback" not in out, out
