"""The estimator node, fed a committed synthetic bag over Fast DDS, computes what offline replay computes."""

from __future__ import annotations

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from helpers.ros import (
    LATCHED_QOS,
    RELIABLE_INPUTS,
    RELIABLE_JOINT_STATES,
    TOPICS,
    NodeProcess,
    TestClient,
    diagnostic_values,
    make_ros_env,
    offline_replay,
    parameters_names_from_msg,
    source_bag,
    stamp_ns,
    wait_until,
    wrench_array,
)
from std_msgs.msg import Float64MultiArray

from semiparam_ros.ros.bag_player import BagPlayer, load_raw

pytestmark = pytest.mark.ros

N_MESSAGES = 1200  # 600 joint-state/wrench pairs (6 s of the 100 Hz bag)
OVERRIDES = {"nonparametric.standardizer_warmup": 50}
PARAMS = [*RELIABLE_INPUTS, "nonparametric.standardizer_warmup:=50", "diagnostics.period:=0.25"]


@pytest.fixture
def ros_env(tmp_path, monkeypatch):
    return make_ros_env(tmp_path, monkeypatch)


def _rmse(errors: list[np.ndarray], cols: slice) -> float:
    return float(np.sqrt(np.mean(np.square(np.array(errors)[:, cols]))))


@pytest.mark.parametrize(("combination", "executor"),  # None: the node's default (events)
                         [("cascade", None), ("joint", None), ("cascade", "single_threaded")])
def test_replay_matches_offline_core_and_beats_parametric(ros_env, tmp_path_factory, combination,
                                                          executor):
    """Either executor (``--executor``) gives the offline core's numbers to 1e-9."""
    bag = source_bag(tmp_path_factory.mktemp("bags"))
    messages = load_raw(bag, TOPICS, limit=N_MESSAGES)
    offline = offline_replay(bag, N_MESSAGES, {**OVERRIDES, "semiparametric.combination": combination})
    assert len(offline.order) > 400

    node = NodeProcess(ros_env, [*PARAMS, f"semiparametric.combination:={combination}"], executor=executor)
    client = TestClient(ros_env)
    try:
        total = client.collect(WrenchStamped, "/estimator/predicted_wrench")
        parametric = client.collect(WrenchStamped, "/estimator/predicted_wrench/parametric")
        residual = client.collect(WrenchStamped, "/estimator/predicted_wrench/nonparametric")
        diagnostics = client.collect(DiagnosticArray, "/diagnostics")
        player = BagPlayer(client.node, messages)
        assert player.wait_for_subscribers(timeout=60.0), node.output()
        for topic in ("/estimator/predicted_wrench", "/estimator/predicted_wrench/parametric",
                      "/estimator/predicted_wrench/nonparametric"):
            assert client.wait_for_publisher(topic), node.output()
        assert wait_until(lambda: diagnostics.snapshot() != [], 10.0), node.output()  # outputs matched
        player.play(hz=400.0)
        expected = len(offline.order)
        assert total.wait_for(lambda m: len(m) >= expected, timeout=60.0), node.output()
        assert residual.wait_for(lambda m: len(m) >= expected, timeout=10.0)
        assert node.alive(), node.output()

        # Latched base parameters: a late subscriber gets the estimate after all samples were learned.
        final = offline.estimator.parameters
        late = client.collect(Float64MultiArray, "/estimator/inertial_parameters", LATCHED_QOS)
        assert late.wait_for(
            lambda m: bool(m) and np.allclose(m[-1].data, final, rtol=1e-9, atol=1e-9), timeout=10.0), \
            (late.snapshot()[-1:], final)
        params_msg = late.snapshot()[-1]
        assert parameters_names_from_msg(params_msg) == list(offline.estimator.parameter_names)
        assert params_msg.layout.dim[0].size == len(final) == len(params_msg.data)

        # Diagnostics after the replay: every sample learned, the same drops as offline, no queue drops.
        n = expected

        def settled(msgs: list) -> bool:
            return bool(msgs) and diagnostic_values(msgs[-1]).get("samples_learned") == str(n)

        assert diagnostics.wait_for(settled, timeout=10.0), diagnostic_values(diagnostics.snapshot()[-1])
        diag = diagnostic_values(diagnostics.snapshot()[-1])
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()

    # Same messages in the same order ⇒ the same numbers (1e-9), for every part of the prediction.
    got_total = {stamp_ns(m): wrench_array(m) for m in total.snapshot()}
    got_param = {stamp_ns(m): wrench_array(m) for m in parametric.snapshot()}
    got_resid = {stamp_ns(m): wrench_array(m) for m in residual.snapshot()}
    assert set(got_total) == set(offline.predictions)
    for stamp, pred in offline.predictions.items():
        np.testing.assert_allclose(got_total[stamp], pred.total, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(got_param[stamp], pred.parametric, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(got_resid[stamp], pred.residual, rtol=1e-9, atol=1e-9)
    frames = {m.header.frame_id for m in total.snapshot()}
    assert frames == {"r_arm_ft_sensor"}

    # After the residual has had some data, the semiparametric error is below the rigid-body error.
    late_stamps = offline.order[len(offline.order) // 2:]
    sp_err = [offline.measured[s] - got_total[s] for s in late_stamps]
    p_err = [offline.measured[s] - got_param[s] for s in late_stamps]
    assert _rmse(sp_err, slice(0, 3)) < _rmse(p_err, slice(0, 3))
    assert _rmse(sp_err, slice(3, 6)) < _rmse(p_err, slice(3, 6))

    offline_drops = offline.estimator.drops
    for reason, count in offline_drops.items():
        assert diag[f"drops.{reason}"] == str(count), reason
    assert diag["queue_drops"] == "0"
    assert int(diag["joint_states_received"]) + int(diag["wrench_received"]) == N_MESSAGES
    assert float(diag["rmse_force_N"]) < float(diag["rmse_parametric_force_N"])


def test_joint_torque_output(ros_env, tmp_path):
    from helpers.ros import write_torque_bag
    from sensor_msgs.msg import JointState

    from semiparam_ros.io.bags import read_messages

    bag = tmp_path / "torques"
    write_torque_bag(bag, 300)
    messages = load_raw(bag, ["/joint_states"])
    overrides = {"robot.output": "joint_torques", "nonparametric.standardizer_warmup": 50}
    offline = offline_replay(bag, len(messages), overrides, read_messages(bag, wrench_topic=None))
    assert len(offline.order) > 250
    node = NodeProcess(ros_env, [*RELIABLE_JOINT_STATES, "robot.output:=joint_torques",
                                 "nonparametric.standardizer_warmup:=50"])
    client = TestClient(ros_env)
    try:
        torques = client.collect(JointState, "/estimator/predicted_joint_torques")
        assert client.wait_for_publisher("/estimator/predicted_joint_torques", timeout=60.0), node.output()
        player = BagPlayer(client.node, messages)
        assert player.wait_for_subscribers(timeout=60.0), node.output()
        player.play(hz=400.0)
        assert torques.wait_for(lambda m: len(m) >= len(offline.order), timeout=60.0), node.output()
        assert client.node.count_publishers("/estimator/predicted_wrench") == 0
    finally:
        client.close()
        assert node.stop() == 0, node.output()
    got = {stamp_ns(m): m for m in torques.snapshot()}
    assert set(got) == set(offline.predictions)
    for stamp, pred in offline.predictions.items():
        assert list(got[stamp].name) == ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]
        np.testing.assert_allclose(np.asarray(got[stamp].effort), pred.total, rtol=1e-9, atol=1e-9)
