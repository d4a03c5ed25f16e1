"""A clean shutdown learns the messages still queued before the final checkpoint (in-process node)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.ros import CONFIG, TOPICS, make_ros_env, offline_replay, source_bag

from semiparam_ros.core.checkpoint import load_npz
from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.ros.bag_player import load_raw

pytestmark = pytest.mark.ros

N_MESSAGES = 600  # 300 joint-state/wrench pairs of the committed 100 Hz bag


@pytest.fixture
def ros_env(tmp_path, monkeypatch):
    return make_ros_env(tmp_path, monkeypatch)


def test_queued_messages_are_learned_before_the_final_checkpoint(ros_env, tmp_path, tmp_path_factory):
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    from semiparam_ros.ros.estimator_node import EstimatorNode

    bag = source_bag(tmp_path_factory.mktemp("bags"))
    messages = load_raw(bag, TOPICS, limit=N_MESSAGES)
    overrides = {"nonparametric.standardizer_warmup": 50}
    offline = offline_replay(bag, N_MESSAGES, overrides)
    assert len(offline.order) > 250
    ckpt = tmp_path / "estimator.npz"
    context = rclpy.Context()
    rclpy.init(args=["--ros-args", "--params-file", str(CONFIG), "-p", f"checkpoint.path:={ckpt}",
                     "-p", "checkpoint.period:=0.0", "-p", "nonparametric.standardizer_warmup:=50"],
               context=context)
    try:
        node = EstimatorNode(context=context)
        # queue the messages as the callbacks do (without running the estimator, which they do next)
        for m in messages:
            if m.topic == "/joint_states":
                node.inputs.intake("joint_states", deserialize_message(m.data, JointState))
            else:
                node.inputs.intake("wrench", deserialize_message(m.data, WrenchStamped))
        assert node.estimator.n_samples_learned == 0
        node.shutdown()  # what main() does after Ctrl-C: learn the queue, then the final checkpoint
        assert node.estimator.n_samples_learned == len(offline.order)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)

    state = load_npz(ckpt)
    assert int(state["meta.n_samples_learned"]) == len(offline.order)
    restored = OnlineEstimator(load_config(CONFIG).with_overrides(overrides))
    restored.load(ckpt)
    np.testing.assert_allclose(restored.parameters, offline.estimator.parameters, rtol=1e-12, atol=1e-12)
