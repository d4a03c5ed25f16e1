"""``~/follow_joint_trajectory`` over DDS: MoveIt's path to a ``joint_trajectory_controller`` goes through the
node, which forwards each goal with every point's effort filled.

A fake controller serves ``control_msgs/FollowJointTrajectory`` and records what it receives. The efforts
are compared with :func:`semiparam_ros.load_model` on the checkpoint the node warm-starts from (no joint
states flow, so both hold one model); feedback, result, abort with its error string and cancellation are
relayed; invalid goals and a missing controller are rejected and counted.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest
import rclpy
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from diagnostic_msgs.msg import DiagnosticArray
from helpers.bags import learned_panda_checkpoint
from helpers.ros import REPO, NodeProcess, TestClient, diagnostic_values, make_ros_env, wait_until
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from semiparam_ros import load_model

pytestmark = pytest.mark.ros

PANDA = REPO / "config" / "panda.yaml"
D = 100
CONTROLLER = "/joint_trajectory_controller/follow_joint_trajectory"


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    root = tmp_path_factory.mktemp("action_node")
    return learned_panda_checkpoint(root, "panda_action", seed=1, n_features=D)


class FakeController:
    """A ``FollowJointTrajectory`` server: records goals, sends two feedbacks, then succeeds, aborts with an
    error string, or waits to be cancelled (``mode``)."""

    def __init__(self, domain_id: int) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node("fake_controller", context=self.context)
        self.goals: list[FollowJointTrajectory.Goal] = []
        self.mode = "succeed"
        self.cancelled = threading.Event()
        group = ReentrantCallbackGroup()
        self.server = ActionServer(self.node, FollowJointTrajectory, CONTROLLER,
                                   execute_callback=self._execute,
                                   goal_callback=lambda goal: GoalResponse.ACCEPT,
                                   cancel_callback=lambda handle: CancelResponse.ACCEPT, callback_group=group)
        self.executor = MultiThreadedExecutor(num_threads=3, context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _execute(self, handle):
        self.goals.append(handle.request)
        result = FollowJointTrajectory.Result()
        for k in range(2):
            feedback = FollowJointTrajectory.Feedback()
            feedback.joint_names = list(handle.request.trajectory.joint_names)
            feedback.desired.positions = [float(k)] * len(feedback.joint_names)
            handle.publish_feedback(feedback)
            time.sleep(0.05)
        if self.mode == "cancel":
            deadline = time.monotonic() + 20.0
            while not handle.is_cancel_requested and time.monotonic() < deadline:
                time.sleep(0.01)
            self.cancelled.set()
            handle.canceled()
            return result
        if self.mode == "abort":
            result.error_code = FollowJointTrajectory.Result.PATH_TOLERANCE_VIOLATED
            result.error_string = "joint 3 left its path tolerance"
            handle.abort()
            return result
        handle.succeed()
        return result

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.server.destroy()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _goal(names, q, dq, ddq, dt=0.5):
    goal = FollowJointTrajectory.Goal()
    goal.trajectory = JointTrajectory(joint_names=list(names))
    for k in range(len(q)):
        sec, frac = divmod((k + 1) * dt, 1.0)
        point = JointTrajectoryPoint(positions=[float(v) for v in q[k]], velocities=[float(v) for v in dq[k]],
                                     accelerations=[float(v) for v in ddq[k]],
                                     time_from_start=Duration(sec=int(sec), nanosec=round(frac * 1e9)))
        goal.trajectory.points.append(point)
    return goal


def _wait(future, timeout=30.0):
    deadline = time.monotonic() + timeout
    while not future.done() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert future.done(), "no answer in time"
    return future.result()


def _send(client, goal, feedback=None):
    handle = _wait(client.send_goal_async(goal, feedback_callback=feedback))
    return handle


def test_goals_reach_the_controller_with_the_models_efforts_and_its_answers_come_back(ros_env, checkpoint):
    model = load_model(checkpoint)
    joints = model.joints
    fake = FakeController(ros_env.domain_id)
    node = NodeProcess(ros_env, [f"nonparametric.n_features:={D}", f"checkpoint.path:={checkpoint}",
                                 "checkpoint.period:=0.0", "diagnostics.period:=0.2",
                                 "learning_enabled:=false"], params_file=PANDA, tag="action")
    client = TestClient(ros_env)
    try:
        diagnostics = client.collect(DiagnosticArray, "/diagnostics")
        # the served copy predicts with the consistent projection once the worker's solution is attached
        assert wait_until(lambda: any(diagnostic_values(m).get("consistent.in_use") == "true"
                                      for m in diagnostics.snapshot()), 60.0), node.output()
        time.sleep(2.5)  # the next refresh of the served copy carries the solution
        action = ActionClient(client.node, FollowJointTrajectory, "/estimator/follow_joint_trajectory")
        assert action.wait_for_server(timeout_sec=30.0), node.output()

        rng = np.random.default_rng(4)
        perm = rng.permutation(7)
        names = [joints[i] for i in perm]
        q = rng.uniform(-0.8, 0.8, (3, 7))
        q[:, 3] = rng.uniform(-2.0, -1.0, 3)
        dq, ddq = rng.uniform(-0.5, 0.5, (3, 7)), rng.uniform(-1.0, 1.0, (3, 7))
        goal = _goal(names, q[:, perm], dq[:, perm], ddq[:, perm])
        feedback = []
        handle = _send(action, goal, feedback=feedback.append)
        assert handle.accepted
        response = _wait(handle.get_result_async())
        assert response.status == GoalStatus.STATUS_SUCCEEDED
        assert response.result.error_code == FollowJointTrajectory.Result.SUCCESSFUL
        assert len(feedback) == 2 and list(feedback[0].feedback.joint_names) == names
        sent = fake.goals[-1].trajectory
        assert list(sent.joint_names) == names
        effort = np.array([p.effort for p in sent.points])[:, np.argsort(perm)]
        expected, _ = model.predict(q, dq, ddq)
        np.testing.assert_allclose(effort, expected, rtol=0, atol=1e-6)
        np.testing.assert_array_equal([list(p.positions) for p in sent.points],
                                      [list(p.positions) for p in goal.trajectory.points])

        fake.mode = "abort"
        response = _wait(_send(action, goal).get_result_async())
        assert response.status == GoalStatus.STATUS_ABORTED
        assert response.result.error_code == FollowJointTrajectory.Result.PATH_TOLERANCE_VIOLATED
        assert response.result.error_string == "joint 3 left its path tolerance"

        fake.mode = "cancel"
        handle = _send(action, goal)
        time.sleep(0.3)
        _wait(handle.cancel_goal_async())
        assert fake.cancelled.wait(20.0)
        assert _wait(handle.get_result_async()).status == GoalStatus.STATUS_CANCELED

        fake.mode = "succeed"
        n_before = len(fake.goals)
        bad = []
        unknown = _goal([*names[:6], "elbow_of_another_arm"], q[:, perm], dq[:, perm], ddq[:, perm])
        missing = _goal(names[:6], q[:, perm][:, :6], dq[:, perm][:, :6], ddq[:, perm][:, :6])
        repeated = _goal([*names[:6], names[0]], q[:, perm], dq[:, perm], ddq[:, perm])
        nan = _goal(names, q[:, perm], dq[:, perm], ddq[:, perm])
        nan.trajectory.points[1].positions[2] = math.nan
        unordered = _goal(names, q[:, perm], dq[:, perm], ddq[:, perm])
        unordered.trajectory.points[2].time_from_start = Duration(sec=0, nanosec=1000)
        for goal_bad in (unknown, missing, repeated, nan, unordered):
            bad.append(_send(action, goal_bad).accepted)
        assert bad == [False] * 5 and len(fake.goals) == n_before
        assert wait_until(lambda: diagnostics.snapshot() and int(diagnostic_values(
            diagnostics.snapshot()[-1]).get("action.rejected_invalid", 0)) == 5, 10.0)
        assert "follow_joint_trajectory goal rejected" in node.output()
        action.destroy()
    finally:
        client.close()
        node.stop()
        fake.close()


def test_a_goal_without_its_controller_is_rejected_naming_it(ros_env, checkpoint):
    node = NodeProcess(ros_env, [f"nonparametric.n_features:={D}", f"checkpoint.path:={checkpoint}",
                                 "checkpoint.period:=0.0", "feedforward.controller_action:=nobody/fjt"],
                       params_file=PANDA, tag="no_controller")
    client = TestClient(ros_env)
    try:
        action = ActionClient(client.node, FollowJointTrajectory, "/estimator/follow_joint_trajectory")
        assert action.wait_for_server(timeout_sec=30.0), node.output()
        joints = load_model(checkpoint).joints
        q = np.zeros((2, 7))
        q[:, 3] = -1.5
        handle = _send(action, _goal(joints, q, 0 * q, 0 * q))
        assert not handle.accepted
        assert wait_until(lambda: "/nobody/fjt is not available" in node.output(), 10.0), node.output()
        action.destroy()
    finally:
        client.close()
        node.stop()


@pytest.fixture
def ros_env(tmp_path, monkeypatch):
    return make_ros_env(tmp_path, monkeypatch)
