"""The node's feed-forward endpoints, served from a thread of their own.

Per-cycle desired states, trajectories to fill with efforts and the ``FollowJointTrajectory`` proxy in
front of a controller:

* ``~/desired_state`` (a ``JointTrajectory``; the point at "now") is answered on ``~/feedforward_commands``,
  ``~/feedforward`` and ``~/feedforward/std``;
* ``~/trajectory`` is published on ``~/trajectory_with_effort`` with every point's effort;
* ``~/follow_joint_trajectory`` (``control_msgs/action/FollowJointTrajectory``, what MoveIt sends) forwards
  each goal, every point's effort filled as ``~/trajectory`` fills it, to the controller's action
  (``feedforward.controller_action``), and relays its feedback, result, cancellation and preemption.

These run on a hidden helper node (``_<name>_feedforward``, the main node's resolved names, no parameter
services) spun by an executor in a thread of their own, so an answer never waits behind a learning step
and learning is not starved by answers; they read the served copy of the model
(:class:`~semiparam_ros.serving.model_service.ModelService`), not the live learner. The model and its
bookkeeping live in the service; this module converts, hands on and publishes. Topics and QoS:
docs/node.md; how to wire a controller: docs/controllers.md.
"""

from __future__ import annotations

import copy
import threading
from collections.abc import Callable
from typing import Any

from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from semiparam_ros.ros import conversions as cv
from semiparam_ros.ros.inputs import ThrottledWarnings
from semiparam_ros.serving.model_service import ModelService

__all__ = ["FeedForwardEndpoints"]

#: Desired states: only the latest matters; best effort accepts reliable and best-effort publishers.
_DESIRED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.VOLATILE)
#: Trajectories to fill with efforts: each one counts (reliable, a few queued).
_TRAJECTORY_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                             reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
_ANSWER_QOS = 10  # the feed-forward answers: reliable (a JointGroupEffortController's ~/commands), shallow
_SPIN_TIMEOUT_S = 0.05


class FeedForwardEndpoints:
    """Feed-forward topics and the trajectory action of ``node``, served by a helper node in its own thread.

    Args:
        node: The estimator node (its name, namespace, context, clock and remappings).
        service: The model service (``service.feedforward`` is not None: joint-torque output).
        warn: Throttled warnings of the node.
        active: Whether the node takes input now (a lifecycle node: while active).
        controller_action: ``feedforward.controller_action`` (relative names resolve in the node's namespace).
        join_timeout_s: How long :meth:`close` waits for the thread.
    """

    def __init__(self, node: Node, service: ModelService, warn: ThrottledWarnings, active: Callable[[], bool],
                 *, controller_action: str, join_timeout_s: float = 5.0) -> None:
        assert service.feedforward is not None, "the feed-forward is served in joint-torque mode only"
        self._service, self._ff, self._warn, self._active = service, service.feedforward, warn, active
        self._join_timeout_s = join_timeout_s
        self._logger = node.get_logger()
        self._clock = node.get_clock()
        helper = Node(f"_{node.get_name()}_feedforward", namespace=node.get_namespace(), context=node.context,
                      use_global_arguments=False, start_parameter_services=False, enable_rosout=False)
        self._helper = helper
        name = node.resolve_topic_name

        def pub(msg_type: type, topic: str) -> Any:  # no event handlers: each is one more waitable
            return helper.create_publisher(msg_type, name(topic), _ANSWER_QOS,
                                           event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

        self._commands = pub(Float64MultiArray, "~/feedforward_commands")
        self._state = pub(JointState, "~/feedforward")
        self._std = pub(JointState, "~/feedforward/std")
        self._filled = pub(JointTrajectory, "~/trajectory_with_effort")
        self.desired = helper.create_subscription(JointTrajectory, name("~/desired_state"),
                                                  self.on_desired_state, _DESIRED_QOS)
        self.trajectory = helper.create_subscription(JointTrajectory, name("~/trajectory"),
                                                     self.on_trajectory, _TRAJECTORY_QOS)
        #: The controller's action (resolved) that ``~/follow_joint_trajectory`` forwards to.
        self.controller_action = name(controller_action)
        self._controller = ActionClient(helper, FollowJointTrajectory, self.controller_action)
        self._goals: dict[bytes, Any] = {}  # our goal id → the controller's goal handle
        self._action = ActionServer(helper, FollowJointTrajectory, name("~/follow_joint_trajectory"),
                                    execute_callback=self._execute, goal_callback=self._on_goal,
                                    cancel_callback=self._on_cancel)
        self._executor: SingleThreadedExecutor | None = SingleThreadedExecutor(context=node.context)
        self._executor.add_node(helper)
        self._thread = threading.Thread(target=self._spin, name="estimator-feedforward", daemon=True)
        self._thread.start()

    @property
    def context(self) -> Any:
        """The rclpy context (callbacks end quietly once it is shut down)."""
        return self._helper.context

    def _now_ns(self) -> int:
        return int(self._clock.now().nanoseconds)

    def _spin(self) -> None:
        executor = self._executor
        while executor is not None and self._helper.context.ok():
            try:
                executor.spin_once(timeout_sec=_SPIN_TIMEOUT_S)
            except ExternalShutdownException:
                return
            except Exception:  # a publish the shutdown interrupted ends the thread quietly
                if self._helper.context.ok():
                    raise
                return
            executor = self._executor

    # ------------------------------------------------------------------ per-cycle desired states
    def on_desired_state(self, msg: JointTrajectory) -> None:
        """Answer a desired state at once with the served model's torques."""
        if not self._active():
            return
        service, ff = self._service, self._ff
        desired = service.take_desired(lambda: cv.desired_state_from_msg(msg), trajectory=False)
        command = None if desired is None else service.answer(desired, self._now_ns())
        if desired is None or command is None:
            return self._warn("desired state", lambda: f"desired state dropped: {ff.last_error}")
        commands, state, std = cv.feedforward_msgs(command, ff.joints)
        for publisher, out in ((self._commands, commands), (self._state, state), (self._std, std)):
            if publisher.get_subscription_count():
                publisher.publish(out)
        if desired.stamp_ns > 0:  # stamped by the controller: its age when answered
            service.record_age(1e-6 * (self._now_ns() - desired.stamp_ns))
        if command.reason is not None:
            self._warn(f"feedforward {command.reason}", lambda: ff.fallback_message(command.reason))

    # ------------------------------------------------------------------ trajectories
    def _filled_trajectory(self, msg: JointTrajectory) -> JointTrajectory | None:
        """Return the trajectory with every point's effort from the served model (None: dropped, counted)."""
        service, ff = self._service, self._ff
        desired = service.take_desired(lambda: cv.desired_state_from_msg(msg), trajectory=True)
        filled = None if desired is None else service.trajectory(desired)
        if filled is None:
            self._warn(f"trajectory {ff.last_error}", lambda: f"trajectory dropped: {ff.last_error}")
            return None
        if filled.fallback.any():
            n, m = int(filled.fallback.sum()), len(filled.fallback)
            self._warn("trajectory fallback", lambda: f"{n} of {m} trajectory points got the rigid-body part "
                                                      "(model not ready or σ above feedforward.max_std)")
        return cv.fill_trajectory_effort(copy.deepcopy(msg), filled.effort)

    def on_trajectory(self, msg: JointTrajectory) -> None:
        """Publish the trajectory with every point's effort from the served model."""
        if self._active():
            out = self._filled_trajectory(msg)
            if out is not None:
                self._filled.publish(out)

    # ------------------------------------------------------------------ the FollowJointTrajectory proxy
    def _on_goal(self, goal: FollowJointTrajectory.Goal) -> GoalResponse:
        """Reject a goal the model cannot fill (its reason logged and counted) or with no controller."""
        if not self._active():
            self._logger.warning("follow_joint_trajectory goal rejected: the node is not active")
            return GoalResponse.REJECT
        if not self._controller.server_is_ready():
            self._service.count_action("rejected_no_controller")
            self._logger.error(f"follow_joint_trajectory goal rejected: the controller action "
                               f"{self.controller_action} is not available (feedforward.controller_action)")
            return GoalResponse.REJECT
        if self._filled_trajectory(goal.trajectory) is None:  # validated here; filled again when executed
            self._service.count_action("rejected_invalid")
            self._logger.error(f"follow_joint_trajectory goal rejected: {self._ff.last_error}")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle: ServerGoalHandle) -> CancelResponse:
        """Accept a cancel request and pass it on to the controller's goal."""
        controller_goal = self._goals.get(bytes(goal_handle.goal_id.uuid))
        if controller_goal is not None:
            controller_goal.cancel_goal_async()
        return CancelResponse.ACCEPT

    async def _execute(self, goal_handle: ServerGoalHandle) -> FollowJointTrajectory.Result:
        """Forward the goal with its efforts to the controller; relay feedback and the final result."""
        goal = copy.deepcopy(goal_handle.request)
        filled = self._filled_trajectory(goal.trajectory)
        result = FollowJointTrajectory.Result()
        if filled is None:  # the model changed between acceptance and execution and refused a point
            result.error_code, result.error_string = FollowJointTrajectory.Result.INVALID_GOAL, str(
                self._ff.last_error)
            goal_handle.abort()
            return result
        goal.trajectory = filled
        controller_goal = await self._controller.send_goal_async(
            goal, feedback_callback=lambda fb: goal_handle.publish_feedback(fb.feedback))
        if controller_goal is None or not controller_goal.accepted:
            self._service.count_action("controller_rejected")
            result.error_code = FollowJointTrajectory.Result.INVALID_GOAL
            result.error_string = f"the controller action {self.controller_action} rejected the goal"
            goal_handle.abort()
            return result
        key = bytes(goal_handle.goal_id.uuid)
        self._goals[key] = controller_goal
        self._service.count_action("forwarded")
        if goal_handle.is_cancel_requested:  # cancelled while it was being sent
            controller_goal.cancel_goal_async()
        try:
            response = await controller_goal.get_result_async()
        finally:
            self._goals.pop(key, None)
        result = response.result
        if response.status == GoalStatus.STATUS_SUCCEEDED:
            goal_handle.succeed()
        elif response.status == GoalStatus.STATUS_CANCELED and goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:  # aborted, or cancelled by the controller itself (a newer goal preempted it)
            self._service.count_action("aborted")
            goal_handle.abort()
        return result

    def close(self) -> None:
        """Stop the thread, then destroy the action server, client and helper node (idempotent)."""
        executor, self._executor = self._executor, None
        if executor is None:
            return
        self._thread.join(timeout=self._join_timeout_s)
        executor.shutdown(timeout_sec=1.0)
        self._action.destroy()
        self._controller.destroy()
        self._helper.destroy_node()
