"""Bad input never kills the node: it is dropped, counted in /diagnostics, and predictions stay finite."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from helpers.ros import (
    RELIABLE_INPUTS,
    TOPICS,
    NodeProcess,
    TestClient,
    diagnostic_values,
    make_ros_env,
    offline_replay,
    source_bag,
    stamp_ns,
    wrench_array,
)

from semiparam_ros.core.stream.messages import JointStateData, WrenchData
from semiparam_ros.io.bags import BagWriter, read_messages
from semiparam_ros.ros.bag_player import BagPlayer, load_raw

pytestmark = pytest.mark.ros

N_SOURCE = 800


@pytest.fixture
def ros_env(tmp_path, monkeypatch):
    return make_ros_env(tmp_path, monkeypatch)


def write_corrupted_bag(source, path) -> dict[str, int]:
    """Copy the first N_SOURCE messages with faults injected; return the injected count per drop reason."""
    injected = dict.fromkeys(("nonfinite_joint_state", "missing_joint", "joint_state_backwards_stamp",
                              "joint_state_zero_stamp", "nonfinite_wrench", "wrong_frame_id",
                              "wrench_zero_stamp", "wrench_backwards_stamp"), 0)
    js_index = w_index = 0
    previous_js: JointStateData | None = None
    with BagWriter(path) as bag:
        log = 1_000_000_000
        for i, msg in enumerate(read_messages(source)):
            if i >= N_SOURCE:
                break
            log += 1000
            if isinstance(msg, JointStateData):
                js_index += 1
                if js_index % 37 == 5:
                    pos = np.array(msg.position)
                    pos[msg.names.index("r_shoulder_roll")] = np.nan  # a learned joint
                    msg = dataclasses.replace(msg, position=pos)
                    injected["nonfinite_joint_state"] += 1
                elif js_index % 53 == 7:
                    keep = [k for k, n in enumerate(msg.names) if n != "r_elbow"]
                    msg = JointStateData(msg.stamp_ns, tuple(msg.names[k] for k in keep),
                                         np.asarray(msg.position)[keep], np.asarray(msg.velocity)[keep],
                                         np.asarray(msg.effort)[keep] if len(msg.effort) else ())
                    injected["missing_joint"] += 1
                elif js_index % 71 == 11 and previous_js is not None:
                    # a stale message: older than the previous one
                    bag.write_joint_state("/joint_states", dataclasses.replace(
                        previous_js, stamp_ns=previous_js.stamp_ns - 3_000_000), log_time_ns=log)
                    injected["joint_state_backwards_stamp"] += 1
                    log += 1000
                elif js_index == 150:
                    zero = dataclasses.replace(msg, stamp_ns=0)
                    bag.write_joint_state("/joint_states", zero, log_time_ns=log)
                    injected["joint_state_zero_stamp"] += 1
                    log += 1000
                elif js_index == 20:  # an unknown extra joint is ignored, not dropped
                    msg = JointStateData(msg.stamp_ns, (*msg.names, "unknown_joint"),
                                         np.append(msg.position, 1.0), np.append(msg.velocity, 0.0))
                bag.write_joint_state("/joint_states", msg, log_time_ns=log)
                previous_js = msg if np.all(np.isfinite(msg.position)) else previous_js
            else:
                assert isinstance(msg, WrenchData)
                w_index += 1
                if w_index % 41 == 3:
                    force = np.array(msg.force)
                    force[2] = np.inf if w_index % 2 else np.nan
                    msg = dataclasses.replace(msg, force=force)
                    injected["nonfinite_wrench"] += 1
                elif w_index % 61 == 9:
                    msg = dataclasses.replace(msg, frame_id="l_arm_ft_sensor")
                    injected["wrong_frame_id"] += 1
                elif w_index == 200:
                    bag.write_wrench("/wrench", dataclasses.replace(msg, stamp_ns=0), log_time_ns=log)
                    injected["wrench_zero_stamp"] += 1
                    log += 1000
                elif w_index == 250:
                    bag.write_wrench("/wrench", dataclasses.replace(msg, stamp_ns=msg.stamp_ns - 50_000_000),
                                     log_time_ns=log)
                    injected["wrench_backwards_stamp"] += 1
                    log += 1000
                bag.write_wrench("/wrench", msg, log_time_ns=log)
    return injected


def test_corrupted_bag_is_counted_and_survived(ros_env, tmp_path, tmp_path_factory):
    source = source_bag(tmp_path_factory.mktemp("bags"))
    bad_bag = tmp_path / "corrupted"
    injected = write_corrupted_bag(source, bad_bag)
    assert all(v > 0 for v in injected.values()), injected
    messages = load_raw(bad_bag, TOPICS)
    offline = offline_replay(bad_bag, len(messages))
    for reason, count in injected.items():
        assert offline.estimator.drops[reason] == count, (reason, offline.estimator.drops)

    node = NodeProcess(ros_env, [*RELIABLE_INPUTS, "diagnostics.period:=0.25"])
    client = TestClient(ros_env)
    try:
        total = client.collect(WrenchStamped, "/estimator/predicted_wrench")
        diagnostics = client.collect(DiagnosticArray, "/diagnostics")
        player = BagPlayer(client.node, messages)
        assert player.wait_for_subscribers(timeout=60.0), node.output()
        assert client.wait_for_publisher("/estimator/predicted_wrench"), node.output()
        assert diagnostics.wait_for(lambda m: bool(m), timeout=10.0), node.output()
        player.play(hz=500.0)
        expected = len(offline.order)
        assert total.wait_for(lambda m: len(m) >= expected, timeout=60.0), node.output()

        def counted(msgs: list) -> bool:
            return bool(msgs) and diagnostic_values(msgs[-1]).get("samples_learned") == str(expected)

        assert diagnostics.wait_for(counted, timeout=10.0), node.output()
        diag_msgs = diagnostics.snapshot()
        # The node is alive and responsive after all that.
        assert node.alive(), node.output()
        reply = client.trigger("/estimator/save")  # kept by default, under the test's ROS_HOME
        assert reply.success and "semiparam_ros/estimator.npz" in reply.message, reply.message
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()

    diag = diagnostic_values(diag_msgs[-1])
    for reason, count in injected.items():
        assert diag[f"drops.{reason}"] == str(count), (reason, diag)
    assert int(diag["drops_total"]) >= sum(injected.values())
    # Some period saw the drops and said so.
    levels = [m.status[0].level for m in diag_msgs]
    assert DiagnosticStatus.WARN in levels
    assert DiagnosticStatus.ERROR not in levels

    preds = {stamp_ns(m): wrench_array(m) for m in total.snapshot()}
    assert all(np.all(np.isfinite(v)) for v in preds.values())
    assert set(preds) == set(offline.predictions)
    for stamp, pred in offline.predictions.items():
        np.testing.assert_allclose(preds[stamp], pred.total, rtol=1e-9, atol=1e-9)
    out = node.output()
    for reason, count in injected.items():  # every reason reaches the console, each throttled on its own
        if count:
            assert 1 <= out.count(f"input dropped: {reason} (") <= 3, reason
