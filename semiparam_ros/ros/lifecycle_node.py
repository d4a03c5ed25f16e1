"""The ``estimator`` as a managed (lifecycle) node, for systems that bring nodes up in order.

``estimator --lifecycle`` runs :class:`LifecycleEstimatorNode`: the parameters are declared at start-up
(and can be set while unconfigured), then

* **configure** builds the estimator — reads the URDF (a file, or the description a ``topic:`` source has
  delivered by then) and warm-starts from the checkpoint — and creates the topics, services and threads;
  a failure (invalid parameters, a missing URDF or joint, an incompatible checkpoint) returns FAILURE
  with the reason logged, and the node stays unconfigured;
* **activate** starts learning and publishing;
* **deactivate** stops both: inputs and desired states are not taken, nothing is published; the model,
  σ, the gate and the checkpoint thread are kept;
* **cleanup** writes the final checkpoint and destroys what configure built; **shutdown** does the same
  from any state.

Transitions are the standard ``lifecycle_msgs`` services (``~/change_state``, ``~/get_state``, …), e.g.
``ros2 lifecycle set /estimator configure``.
"""

from __future__ import annotations

from typing import Any

from rclpy.lifecycle import LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from semiparam_ros.core.rigid_body.urdf import TOPIC_SCHEME
from semiparam_ros.errors import StartupError
from semiparam_ros.ros.estimator_node import EstimatorNode

__all__ = ["LifecycleEstimatorNode"]


class LifecycleEstimatorNode(LifecycleNodeMixin, EstimatorNode):
    """:class:`EstimatorNode` under the ROS 2 lifecycle (see the module docstring).

    Args:
        node_name: Node name.
        **kwargs: Passed to :class:`rclpy.node.Node`.

    Raises:
        StartupError: Invalid parameters (declared at construction).
    """

    def __init__(self, node_name: str = "estimator", **kwargs: Any) -> None:
        EstimatorNode.__init__(self, node_name, deferred=True, **kwargs)
        LifecycleNodeMixin.__init__(self)
        self._active = False
        self._built = False
        self._description: str | None = None
        spec = str(self.config["robot.urdf"])
        if spec.startswith(TOPIC_SCHEME):  # listen from the start: configure uses what has arrived
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self.create_subscription(String, spec[len(TOPIC_SCHEME):], self._on_description, qos)

    def _on_description(self, msg: String) -> None:
        self._description = msg.data

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Build the estimator and its entities; FAILURE (logged) leaves the node unconfigured."""
        if str(self.config["robot.urdf"]).startswith(TOPIC_SCHEME) and self._description is None:
            self.get_logger().error(f"configure: no robot description received yet on "
                                    f"{self.config['robot.urdf'][len(TOPIC_SCHEME):]}; configure again "
                                    "once it is published")
            return TransitionCallbackReturn.FAILURE
        before = self._entities()
        try:
            self._build(self._description)
        except StartupError as err:
            self.get_logger().error(f"configure failed: {err}")
            self._stop_threads(save=False)
            self._destroy_since(before)
            return TransitionCallbackReturn.FAILURE
        self._built_entities = self._entities() - before
        self._built = True
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start taking inputs, learning and publishing."""
        self._active = True
        self.get_logger().info("active: learning and publishing")
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop taking inputs and publishing; the model is kept."""
        self._active = False
        self.get_logger().info("inactive: inputs ignored, nothing published; the model is kept")
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Write the final checkpoint and destroy what configure built."""
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """As cleanup, from any state."""
        self._active = False
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    def _teardown(self) -> None:
        if not self._built:
            return
        self.shutdown()  # learns what is queued, writes the final checkpoint, stops the threads
        self._stop_save_service()
        self._destroy_since(self._entities() - self._built_entities)
        self._built = False

    def _entities(self) -> set[Any]:
        return {*self.publishers, *self.subscriptions, *self.services, *self.timers}

    def _destroy_since(self, before: set[Any]) -> None:
        """Destroy the publishers, subscriptions, services and timers created after ``before``."""
        for entity in self._entities() - before:
            if entity in self.timers:
                self.destroy_timer(entity)
            elif entity in self.subscriptions:
                self.destroy_subscription(entity)
            elif entity in self.services:
                self.destroy_service(entity)
            else:
                self.destroy_publisher(entity)

    def shutdown(self) -> None:
        """Learn the queue and write the final checkpoint, if configured (``main`` calls it at exit)."""
        if self._built:
            EstimatorNode.shutdown(self)
