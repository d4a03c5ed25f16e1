"""The node's feed-forward endpoints: per-cycle desired states and trajectories to fill with efforts.

A controller's ``~/desired_state`` (a ``JointTrajectory``; the point at "now") is answered on
``~/feedforward_commands``, ``~/feedforward`` and ``~/feedforward/std``; a trajectory on ``~/trajectory`` is
published on ``~/trajectory_with_effort`` with every point's effort. The model and its bookkeeping live in
:class:`~semiparam_ros.serving.model_service.ModelService`; this module converts, hands on and publishes.
Topics and QoS: docs/node.md; the ways to wire a controller: docs/feedforward.md.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from trajectory_msgs.msg import JointTrajectory

from semiparam_ros.ros import conversions as cv
from semiparam_ros.ros.callbacks import quiet_at_shutdown
from semiparam_ros.ros.inputs import GONE, ThrottledWarnings, take
from semiparam_ros.ros.outputs import Outputs
from semiparam_ros.serving.model_service import ModelService

__all__ = ["FeedForwardEndpoints"]

#: Desired states: only the latest matters; best effort accepts reliable and best-effort publishers.
_DESIRED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.VOLATILE)
#: Trajectories to fill with efforts: each one counts (reliable, a few queued).
_TRAJECTORY_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                             reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


class FeedForwardEndpoints:
    """Subscriptions that answer controllers from the served model (joint-torque mode only).

    Args:
        node: The node subscribing (its clock stamps the answers).
        service: The model service (``service.feedforward`` is not None).
        outputs: The node's publishers (the feed-forward topics).
        warn: Throttled warnings of the node.
        active: Whether the node takes input now (a lifecycle node: while active).
    """

    def __init__(self, node: Node, service: ModelService, outputs: Outputs, warn: ThrottledWarnings,
                 active: Callable[[], bool]) -> None:
        assert service.feedforward is not None, "the feed-forward is served in joint-torque mode only"
        self._node, self._service, self._ff, self._outputs = node, service, service.feedforward, outputs
        self._warn, self._active = warn, active
        self.desired = node.create_subscription(JointTrajectory, "~/desired_state", self.on_desired_state,
                                                _DESIRED_QOS)
        self.trajectory = node.create_subscription(JointTrajectory, "~/trajectory", self.on_trajectory,
                                                   _TRAJECTORY_QOS)

    @property
    def context(self) -> Any:
        """The node's rclpy context (callbacks end quietly once it is shut down)."""
        return self._node.context

    def _now_ns(self) -> int:
        return int(self._node.get_clock().now().nanoseconds)

    def serve_waiting(self) -> None:
        """Answer a desired state already waiting in DDS (the node calls this before learning a sample)."""
        taken = take(self.desired)
        if taken is not None and taken is not GONE:
            self.on_desired_state(taken)

    @quiet_at_shutdown
    def on_desired_state(self, msg: JointTrajectory) -> None:
        """Answer a desired state at once with the model's torques."""
        if not self._active():
            return
        service, ff = self._service, self._ff
        desired = service.take_desired(lambda: cv.desired_state_from_msg(msg), trajectory=False)
        command = None if desired is None else service.answer(desired, self._now_ns())
        if desired is None or command is None:
            return self._warn("desired state", lambda: f"desired state dropped: {ff.last_error}")
        self._outputs.publish_feedforward(command, ff.joints)
        if desired.stamp_ns > 0:  # stamped by the controller: its age when answered
            service.record_age(1e-6 * (self._now_ns() - desired.stamp_ns))
        if command.reason is not None:
            self._warn(f"feedforward {command.reason}", lambda: ff.fallback_message(command.reason))

    @quiet_at_shutdown
    def on_trajectory(self, msg: JointTrajectory) -> None:
        """Publish the trajectory with every point's effort from the served model."""
        if not self._active():
            return
        service, ff = self._service, self._ff
        desired = service.take_desired(lambda: cv.desired_state_from_msg(msg), trajectory=True)
        filled = None if desired is None else service.trajectory(desired)
        if filled is None:
            return self._warn("trajectory", lambda: f"trajectory dropped: {ff.last_error}")
        self._outputs.trajectory.publish(cv.fill_trajectory_effort(msg, filled.effort))
        if filled.fallback.any():
            n, m = int(filled.fallback.sum()), len(filled.fallback)
            self._warn("trajectory fallback", lambda: f"{n} of {m} trajectory points got the rigid-body part "
                                                      "(model not ready or σ above feedforward.max_std)")
