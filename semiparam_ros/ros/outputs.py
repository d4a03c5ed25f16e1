"""The node's publishers: per-sample predictions and their parts, identification, diagnostics.

Topics and QoS are documented in docs/node.md. A per-sample output is published only while it has a
subscriber (nobody else can tell), as CDR bytes patched per sample
(:class:`~semiparam_ros.ros.conversions.SerializedOutput`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import InertiaStamped, WrenchStamped
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from semiparam_ros.core.estimator.online import StepResult
from semiparam_ros.core.rigid_body.identification import ConsistentEstimate
from semiparam_ros.core.rigid_body.payload import PayloadEstimate
from semiparam_ros.ros import conversions as cv

__all__ = ["PARAMETERS_QOS", "Outputs"]

#: Latched output of the inertial parameters: a late subscriber gets the latest estimate.
PARAMETERS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
_OUTPUT_QOS = 100


class Outputs:
    """Every publisher of the estimator node.

    Args:
        node: The node publishing.
        joints: ``robot.joints``; empty for a wrench model (``robot.output: wrench``).
        n_links: Bodies of the rigid-body model when the consistent projection runs (``~/link_inertias``,
            latched one message per link); 0 without it.
    """

    def __init__(self, node: Node, joints: tuple[str, ...], *, n_links: int) -> None:
        def pub(msg_type: type, topic: str, qos: QoSProfile | int = _OUTPUT_QOS) -> Any:
            # no event handlers: each is one more entity in every executor wait
            return node.create_publisher(msg_type, topic, qos,
                                         event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

        self.wrench = not joints
        base, kind = ("~/predicted_wrench", WrenchStamped) if self.wrench else ("~/predicted_joint_torques",
                                                                               JointState)
        self.total, self.parametric, self.residual, self.model, self.std = (
            pub(kind, base + suffix) for suffix in ("", "/parametric", "/nonparametric", "/model", "/std"))
        self.external = pub(kind, "~/external_wrench" if self.wrench else "~/external_joint_torques")
        self._frame: str | None = None  # the frame of the wrench template
        self._template = None if self.wrench else cv.SerializedOutput(
            lambda stamp, tau: cv.joint_torques_msg(stamp, joints, tau), len(joints))
        if not self.wrench:
            self.gravity = pub(JointState, "~/gravity_torques")
        self.parameters = pub(Float64MultiArray, "~/inertial_parameters", PARAMETERS_QOS)
        self.payload = pub(InertiaStamped, "~/payload", PARAMETERS_QOS)
        self.payload_std = pub(InertiaStamped, "~/payload/std", PARAMETERS_QOS)
        self.diagnostics = pub(DiagnosticArray, "/diagnostics", 10)
        self.links = None if not n_links else pub(InertiaStamped, "~/link_inertias", QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=n_links, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))

    def publish_sample(self, result: StepResult, frame: str,
                       gravity: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        """Publish one sample's outputs (wrench outputs in ``frame``; gravity torques at its posture).

        Each output is computed only when its topic has a subscriber (at 1 kHz every array operation
        counts).
        """
        stamp, pred = result.sample.stamp_ns, result.prediction
        if self.wrench and self._frame != frame:
            self._frame = frame
            self._template = cv.SerializedOutput(lambda ns, w: cv.wrench_stamped_msg(ns, frame, w), 6)
        fill = self._template.fill  # type: ignore[union-attr]
        if self.total.get_subscription_count():
            self.total.publish(fill(stamp, pred.total))
        if self.external.get_subscription_count():
            self.external.publish(fill(stamp, result.sample.y - pred.total))
        if self.model.get_subscription_count():  # the model alone: without the fast correction
            self.model.publish(fill(stamp, pred.total if pred.correction is None
                                    else pred.total - pred.correction))
        if not self.wrench:
            if gravity is not None and self.gravity.get_subscription_count():
                self.gravity.publish(fill(stamp, gravity(result.sample.q)))
        for pub, value in ((self.parametric, pred.parametric), (self.residual, pred.residual),
                           (self.std, result.std)):
            if value is not None and pub.get_subscription_count():
                pub.publish(fill(stamp, value))

    def publish_payload(self, estimate: PayloadEstimate, stamp_ns: int) -> None:
        """Publish the payload and its standard deviations (latched)."""
        value, std = cv.payload_msgs(estimate, stamp_ns)
        self.payload.publish(value)
        self.payload_std.publish(std)

    def publish_links(self, estimate: ConsistentEstimate, stamp_ns: int) -> None:
        """Publish the consistent inertias of every link (latched)."""
        if self.links is not None:
            for msg in cv.link_inertia_msgs(estimate, stamp_ns):
                self.links.publish(msg)

    def publish_parameters(self, names: tuple[str, ...] | list[str], values: np.ndarray) -> None:
        """Publish the inertial parameter estimates (latched)."""
        self.parameters.publish(cv.parameters_msg(names, values))
