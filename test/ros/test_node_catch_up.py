"""A backlog larger than one batch is worked off by the catch-up timer, under either executor."""

from __future__ import annotations

import time

import pytest
from helpers.ros import CONFIG, TOPICS, make_ros_env, offline_replay, source_bag, wait_until

from semiparam_ros.ros.bag_player import load_raw

pytestmark = pytest.mark.ros

N_MESSAGES = 400  # 200 joint-state/wrench pairs: four batches


@pytest.fixture
def ros_env(tmp_path, monkeypatch):
    return make_ros_env(tmp_path, monkeypatch)


@pytest.mark.parametrize("executor_name", ["single_threaded", "events"])
def test_backlog_beyond_a_batch_is_learned_by_the_catch_up_timer(ros_env, tmp_path_factory, executor_name):
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    from semiparam_ros.ros import estimator_node
    from semiparam_ros.ros.estimator_node import EstimatorNode
    from semiparam_ros.ros.main import EXECUTORS

    bag = source_bag(tmp_path_factory.mktemp("bags"))
    messages = load_raw(bag, TOPICS, limit=N_MESSAGES)
    offline = offline_replay(bag, N_MESSAGES)
    context = rclpy.Context()
    # learn every sample however late (the default predicts a backlog without learning it: tested below)
    rclpy.init(args=["--ros-args", "--params-file", str(CONFIG), "-p", "overload.max_delay:=0.0"],
               context=context)
    try:
        node = EstimatorNode(context=context)
        for m in messages:  # queue everything, as the callbacks do before they run the estimator
            kind, msg_type = ("joint_states", JointState) if m.topic == "/joint_states" else ("wrench",
                                                                                             WrenchStamped)
            node.inputs.intake(kind, deserialize_message(m.data, msg_type))
        assert len(node.loop.queue) == N_MESSAGES
        node._process_queued()  # what a subscription callback does: one batch, then arm the timer
        assert len(node.loop.queue) == N_MESSAGES - estimator_node._BATCH
        assert not node._catch_up.is_canceled()
        executor = EXECUTORS[executor_name](context=context)
        executor.add_node(node)
        assert wait_until(lambda: (executor.spin_once(timeout_sec=0.05), not node.loop.queue)[1], 30.0)
        assert wait_until(lambda: (executor.spin_once(timeout_sec=0.05), node._catch_up.is_canceled())[1],
                          5.0)  # disarmed once the queue is empty
        # the same samples learned as when the core is fed the messages directly
        assert node.estimator.n_samples_learned == offline.estimator.n_samples_learned > 150
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_a_late_backlog_is_predicted_at_once_and_not_learned(ros_env, tmp_path_factory):
    """Default ``overload.max_delay``: every queued sample is predicted, none that waited too long learned.

    A backlog is what a node that falls behind holds: each sample is predicted (published and counted),
    with the rigid-body part of the full model, and the learner only takes the samples that arrive on
    time afterwards — the learned state is that of a core fed only those samples.
    """
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    from semiparam_ros.ros.estimator_node import EstimatorNode

    bag = source_bag(tmp_path_factory.mktemp("bags"))
    messages = load_raw(bag, TOPICS, limit=N_MESSAGES)
    offline = offline_replay(bag, N_MESSAGES)
    context = rclpy.Context()
    rclpy.init(args=["--ros-args", "--params-file", str(CONFIG)], context=context)
    try:
        node = EstimatorNode(context=context)
        assert node.loop.max_delay_s == 0.001  # the default
        decoded = [(("joint_states", JointState) if m.topic == "/joint_states" else ("wrench", WrenchStamped),
                    m.data) for m in messages]
        for (kind, msg_type), data in decoded:
            node.inputs.intake(kind, deserialize_message(data, msg_type))
        time.sleep(0.01)  # every queued message is now older than the 1 ms budget
        while node.loop.queue:
            node._process_queued()
        est = node.estimator
        samples = offline.estimator.n_samples_learned
        assert est.n_samples_learned == 0
        assert est.n_learning_skipped == samples > 150
        assert node._stats.samples_predicted == samples  # every sample predicted and published
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
