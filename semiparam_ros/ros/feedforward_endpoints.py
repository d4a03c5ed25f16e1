"""The node's feed-forward endpoints, answered from the served copy of the model.

Per-cycle desired states, trajectories to fill with efforts and the ``FollowJointTrajectory`` proxy in
front of a controller:

* ``~/desired_state`` (a ``JointTrajectory``; the point at "now") is answered on ``~/feedforward_commands``,
  ``~/feedforward`` and ``~/feedforward/std``;
* ``~/trajectory`` is published on ``~/trajectory_with_effort`` with every point's effort;
* ``~/follow_joint_trajectory`` (``control_msgs/action/FollowJointTrajectory``, what MoveIt sends) forwards
  each goal, every point's effort filled as ``~/trajectory`` fills it, to the controller's action
  (``feedforward.controller_action``), and relays its feedback, result, cancellation and preemption.

The per-cycle topics are the node's own (its executor answers a waiting desired state before the next
queued sample is learned); the action proxy, which awaits the controller, runs on a hidden helper node
(``_<name>_feedforward``, the node's resolved names, no parameter services) spun in a thread of its own.
All read the served copy of the model (:class:`~semiparam_ros.serving.model_service.ModelService`) without
the learning loop's lock. The model and its
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
from semiparam_ros.ros.callbacks import quiet_at_shutdown
from semiparam_ros.ros.inputs import GONE, ThrottledWarnings, take
from semiparam_ros.serving.model_service import ModelService

__all__ = ["FeedForwardEndpoints", "endpoint_names"]

#: Desired states: only the latest matters; best effort accepts reliable and best-effort publishers.
_DESIRED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.VOLATILE)
#: Trajectories to fill with efforts: each one counts (reliable, a few queued).
_TRAJECTORY_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                             reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
_ANSWER_QOS = 10  # the feed-forward answers: reliable (a JointGroupEffortController's ~/commands), shallow
_SPIN_TIMEOUT_S = 0.05


def endpoint_names(node: Node, controller_action: str) -> dict[str, str]:
    """Return the endpoints' names, resolved with the estimator node's name, namespace and remappings.

    Args:
        node: The estimator node.
        controller_action: ``feedforward.controller_action`` (relative names resolve in the node's namespace).

    Returns:
        Resolved names by key (``desired_state``, ``trajectory``, ``feedforward_commands``, ``feedforward``,
        ``feedforward_std``, ``trajectory_with_effort``, ``follow_joint_trajectory``, ``controller_action``),
        and the helper node's name and namespace (``helper``, ``namespace``).
    """
    topics = {"desired_state": "~/desired_state", "trajectory": "~/trajectory",
              "feedforward_commands": "~/feedforward_commands", "feedforward": "~/feedforward",
              "feedforward_std": "~/feedforward/std", "trajectory_with_effort": "~/trajectory_with_effort",
              "follow_joint_trajectory": "~/follow_joint_trajectory", "controller_action": controller_action}
    names = {key: node.resolve_topic_name(topic) for key, topic in topics.items()}
    names.update(helper=f"_{node.get_name()}_feedforward", namespace=node.get_namespace())
    return names


class FeedForwardEndpoints:
    """Feed-forward topics of ``node`` and the trajectory action, served from the served copy of the model.

    The per-cycle topics (``~/desired_state``, ``~/trajectory``) are the node's own subscriptions, taken by
    its executor — a waiting desired state is answered before the next queued sample is learned
    (:meth:`serve_waiting`). The ``FollowJointTrajectory`` proxy awaits the controller's answers: it runs
    on a helper node (``_<name>_feedforward``) spun in a thread of its own.

    Args:
        node: The estimator node (topics, clock, logger).
        names: The endpoints' resolved names (:func:`endpoint_names` of the node).
        service: The model service (``service.feedforward`` is not None: joint-torque output).
        warn: Throttled warnings.
        active: Whether the node takes input now (a lifecycle node: while active).
        join_timeout_s: How long :meth:`close` waits for the thread.
    """

    def __init__(self, node: Node, names: dict[str, str], service: ModelService, warn: ThrottledWarnings,
                 active: Callable[[], bool], *, join_timeout_s: float = 5.0) -> None:
        assert service.feedforward is not None, "the feed-forward is served in joint-torque mode only"
        self._service, self._ff, self._warn, self._active = service, service.feedforward, warn, active
        self._join_timeout_s = join_timeout_s
        self._node = node
        self._logger = node.get_logger()
        self._clock = node.get_clock()

        def pub(msg_type: type, key: str) -> Any:  # no event handlers: each is one more waitable
            return node.create_publisher(msg_type, names[key], _ANSWER_QOS,
                                         event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

        self._commands = pub(Float64MultiArray, "feedforward_commands")
        self._state = pub(JointState, "feedforward")
        self._std = pub(JointState, "feedforward_std")
        self._filled = pub(JointTrajectory, "trajectory_with_effort")
        self.desired = node.create_subscription(JointTrajectory, names["desired_state"],
                                                self.on_desired_state, _DESIRED_QOS)
        self.trajectory = node.create_subscription(JointTrajectory, names["trajectory"], self.on_trajectory,
                                                   _TRAJECTORY_QOS)
        #: The controller's action (resolved) that ``~/follow_joint_trajectory`` forwards to.
        self.controller_action = names["controller_action"]
        helper = Node(names["helper"], namespace=names["namespace"], context=node.context,
                      use_global_arguments=False, start_parameter_services=False, enable_rosout=False)
        self._helper = helper
        self._controller = ActionClient(helper, FollowJointTrajectory, self.controller_action)
        self._goals: dict[bytes, Any] = {}  # our goal id → the controller's goal handle
        self._action = ActionServer(helper, FollowJointTrajectory, names["follow_joint_trajectory"],
                                    execute_callback=self._execute, goal_callback=self._on_goal,
                                    cancel_callback=self._on_cancel)
        self._executor = SingleThreadedExecutor(context=node.context)  # it awaits the proxy's coroutines
        self._executor.add_node(helper)
        self._closed = False
        self._thread = threading.Thread(target=self._spin, name="estimator-trajectory-action", daemon=True)
        self._thread.start()

    @property
    def context(self) -> Any:
        """The rclpy context (callbacks end quietly once it is shut down)."""
        return self._node.context

    def _now_ns(self) -> int:
        return int(self._clock.now().nanoseconds)

    def _spin(self) -> None:
        while not self._closed and self._helper.context.ok():
            try:
                self._executor.spin_once(timeout_sec=_SPIN_TIMEOUT_S)
            except ExternalShutdownException:
                return
            except Exception:  # a publish the shutdown interrupted ends the thread quietly
                if self._helper.context.ok() and not self._closed:
                    raise
                return

    # ------------------------------------------------------------------ per-cycle desired states
    def serve_waiting(self) -> None:
        """Answer a desired state already waiting in DDS (the node calls this before learning a sample)."""
        taken = take(self.desired)
        if taken is not None and taken is not GONE:
            self.on_desired_state(taken)

    @quiet_at_shutdown
    def on_desired_state(self, msg: JointTrajectory) -> None:
        """Answer a desired state at once with the served model's torques."""
        if not self._active():
            return
        service, ff = self._service, self._ff
        desired = service.take_desired(lambda: cv.desired_state_from_msg(msg), trajectory=False)
        command = None if desired is None else service.answer(desired, self._now_ns())
        if desired is None or command is None:
            return self._warn(f"desired state {ff.last_reason}",
                              lambda: f"desired state dropped: {ff.last_error}")
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
            self._warn(f"trajectory {ff.last_reason}", lambda: f"trajectory dropped: {ff.last_error}")
            return None
        if filled.fallback.any():
            n, m = int(filled.fallback.sum()), len(filled.fallback)
            self._warn("trajectory fallback", lambda: f"{n} of {m} trajectory points got the rigid-body part "
                                                      "(model not ready or σ above feedforward.max_std)")
        return cv.fill_trajectory_effort(copy.deepcopy(msg), filled.effort)

    @quiet_at_shutdown
    def on_trajectory(self, msg: JointTrajectory) -> None:
        """Publish the trajectory with every point's effort from the served model."""
        if self._active():
            out = self._filled_trajectory(msg)
            if out is not None:
                self._filled.publish(out)

    # ------------------------------------------------------------------ the FollowJointTrajectory proxy
    def _on_goal(self, goal: FollowJointTrajectory.Goal) -> GoalResponse:
        """Fill an accepted goal's efforts; reject one the model cannot fill, or any without a controller.

        The efforts are written into the goal itself: rclpy hands :meth:`_execute` the same message
        (``goal_handle.request``), so each goal is filled, and counted, once.
        """
        if not self._active():
            self._logger.warning("follow_joint_trajectory goal rejected: the node is not active")
            return GoalResponse.REJECT
        if not self._controller.server_is_ready():
            self._service.count_action("rejected_no_controller")
            self._logger.error(f"follow_joint_trajectory goal rejected: the controller action "
                               f"{self.controller_action} is not available (feedforward.controller_action)")
            return GoalResponse.REJECT
        filled = self._filled_trajectory(goal.trajectory)
        if filled is None:
            self._service.count_action("rejected_invalid")
            self._logger.error(f"follow_joint_trajectory goal rejected: {self._ff.last_error}")
            return GoalResponse.REJECT
        goal.trajectory = filled
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle: ServerGoalHandle) -> CancelResponse:
        """Accept a cancel request and pass it on to the controller's goal."""
        controller_goal = self._goals.get(bytes(goal_handle.goal_id.uuid))
        if controller_goal is not None:
            controller_goal.cancel_goal_async()
        return CancelResponse.ACCEPT

    async def _execute(self, goal_handle: ServerGoalHandle) -> FollowJointTrajectory.Result:
        """Forward the goal (filled at acceptance) to the controller; relay feedback and the result."""
        result = FollowJointTrajectory.Result()
        controller_goal = await self._controller.send_goal_async(
            goal_handle.request, feedback_callback=lambda fb: goal_handle.publish_feedback(fb.feedback))
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
        """Stop the action's thread, then destroy the action server, client and helper node (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._thread.join(timeout=self._join_timeout_s)
        self._executor.shutdown(timeout_sec=1.0)
        self._action.destroy()
        self._controller.destroy()
        self._helper.destroy_node()
