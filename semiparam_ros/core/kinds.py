"""What the estimator learns and what it reads: the output kind and the input kind, as types.

An :class:`OutputKind` is what a model predicts — the six-axis reading of a force/torque sensor or the
torques of the moving joints — and decides the width of the output, the rigid-body columns that apply
(friction, offsets and armature are joint-torque columns) and the input topics the node subscribes to.
An :class:`InputKind` is the message stream an input came from. Both are string enums: a value read from a
parameter file (``robot.output: joint_torques``) compares equal to its member, and
``OutputKind(text)`` turns it into one (``ValueError`` for anything else).

>>> OutputKind("joint_torques") is OutputKind.JOINT_TORQUES
True
>>> OutputKind.WRENCH.n_outputs(7), OutputKind.JOINT_TORQUES.n_outputs(7)
(6, 7)
"""

from __future__ import annotations

import enum

from semiparam_ros.errors import ConfigurationError

__all__ = ["WRENCH_WIDTH", "InputKind", "OutputKind"]

#: Components of a wrench: ``[fx, fy, fz, tx, ty, tz]`` (N, N·m).
WRENCH_WIDTH = 6


class InputKind(enum.StrEnum):
    """A stream of input messages: ``sensor_msgs/JointState`` or ``geometry_msgs/WrenchStamped``."""

    JOINT_STATES = "joint_states"
    WRENCH = "wrench"

    @property
    def topic_parameter(self) -> str:
        """The parameter that names this stream's topic (``topics.joint_states``, ``topics.wrench``)."""
        return f"topics.{self.value}"


class OutputKind(enum.StrEnum):
    """What a model predicts: a six-axis F/T sensor's wrench (N, N·m) or the joints' torques (N·m)."""

    WRENCH = "wrench"
    JOINT_TORQUES = "joint_torques"

    @classmethod
    def parse(cls, value: object, what: str = "output") -> OutputKind:
        """Return the kind a value names.

        Raises:
            ConfigurationError: If ``value`` names no output kind.
        """
        try:
            return cls(str(value)) if isinstance(value, str) else cls(value)  # type: ignore[arg-type]
        except ValueError:
            raise ConfigurationError(f"{what} must be one of {tuple(k.value for k in cls)}, "
                                     f"got {value!r}") from None

    def n_outputs(self, n_joints: int) -> int:
        """Width of the output: 6 for a wrench, one per joint for joint torques."""
        return WRENCH_WIDTH if self is OutputKind.WRENCH else int(n_joints)

    @property
    def inputs(self) -> tuple[InputKind, ...]:
        """The input streams this output needs: joint states, and the sensor's wrenches for a wrench.

        >>> [k.value for k in OutputKind.JOINT_TORQUES.inputs]
        ['joint_states']
        """
        if self is OutputKind.WRENCH:
            return (InputKind.JOINT_STATES, InputKind.WRENCH)
        return (InputKind.JOINT_STATES,)

    @property
    def label(self) -> str:
        """Human name for titles: ``wrench`` or ``joint torques``."""
        return self.value.replace("_", " ")

    @property
    def unit(self) -> str:
        """Units of the components, for tables and axes."""
        return "N, N·m" if self is OutputKind.WRENCH else "N·m"
