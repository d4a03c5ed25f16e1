"""Plain-array views of the ROS messages the estimator consumes, and the learning sample.

These types carry no ROS dependency: the live node (``semiparam_ros.ros``) and the bag reader
(``semiparam_ros.io.bags``) both convert ``sensor_msgs/JointState`` and ``geometry_msgs/WrenchStamped``
into them, so the same :class:`~semiparam_ros.core.stream.pipeline.SamplePipeline` sees identical data either
way.

Construction normalises types (``int`` stamps, ``tuple[str, ...]`` names, read-only 1-D ``float64``
arrays) but deliberately does **not** reject malformed content: a JointState whose arrays do not match
its names, or a NaN value, must still be representable so that the pipeline can drop it and count the
reason instead of crashing the node.

Stamps are integer nanoseconds (``sec * 10**9 + nanosec`` of ``builtin_interfaces/Time``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from semiparam_ros.errors import RejectedSampleError

__all__ = [
    "InputMessage",
    "JointStateData",
    "Sample",
    "WrenchData",
    "joint_state_from_msg",
    "ns_to_stamp",
    "stamp_to_ns",
    "wrench_from_msg",
]

_NS_PER_S = 1_000_000_000


def stamp_to_ns(sec: int, nanosec: int) -> int:
    """Convert a ``builtin_interfaces/Time`` (``sec``, ``nanosec``) to integer nanoseconds.

    Args:
        sec: Whole seconds (may be negative for pre-epoch times, as in ROS).
        nanosec: Nanoseconds in ``[0, 1e9)``.

    Returns:
        ``sec * 10**9 + nanosec``.

    Raises:
        RejectedSampleError: ``nanosec`` outside ``[0, 1e9)`` (an invalid stamp: ``0xFFFFFFFF`` would
            otherwise read as a time 4.3 s ahead and the samples after it as out of order).
    """
    ns = int(nanosec)
    if not 0 <= ns < _NS_PER_S:
        raise RejectedSampleError(f"invalid stamp: nanosec = {ns} is not in [0, 1e9)")
    return int(sec) * _NS_PER_S + ns


def ns_to_stamp(stamp_ns: int) -> tuple[int, int]:
    """Split integer nanoseconds into ``(sec, nanosec)`` with ``0 <= nanosec < 1e9``.

    Args:
        stamp_ns: Time in nanoseconds.

    Returns:
        ``(sec, nanosec)`` as used by ``builtin_interfaces/Time``.
    """
    sec, nanosec = divmod(int(stamp_ns), _NS_PER_S)
    return sec, nanosec


def _frozen_vector(values: object) -> np.ndarray:
    """Copy ``values`` into a read-only 1-D float64 array (no validation of the content)."""
    arr = np.array(values, dtype=np.float64, copy=True).reshape(-1)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class JointStateData:
    """A ``sensor_msgs/JointState`` as plain arrays.

    Attributes:
        stamp_ns: Header stamp in nanoseconds.
        names: Joint names, in the message's order (not necessarily the configured order).
        position: Joint positions (rad for revolute joints); may be empty or mismatched — the pipeline
            checks.
        velocity: Joint velocities (rad/s); may be empty.
        effort: Joint efforts (N·m for revolute joints); may be empty.
    """

    stamp_ns: int
    names: tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: _frozen_vector(()))
    effort: np.ndarray = field(default_factory=lambda: _frozen_vector(()))

    def __post_init__(self) -> None:
        object.__setattr__(self, "stamp_ns", int(self.stamp_ns))
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        object.__setattr__(self, "position", _frozen_vector(self.position))
        object.__setattr__(self, "velocity", _frozen_vector(self.velocity))
        object.__setattr__(self, "effort", _frozen_vector(self.effort))


@dataclass(frozen=True)
class WrenchData:
    """A ``geometry_msgs/WrenchStamped`` as plain arrays.

    The wrench is expressed in the sensor frame ``frame_id`` and is the wrench that the distal subtree
    exerts on the proximal link (at rest the force is the distal weight).

    Attributes:
        stamp_ns: Header stamp in nanoseconds.
        frame_id: Header frame id (the sensor frame).
        force: ``[fx, fy, fz]`` in N.
        torque: ``[tx, ty, tz]`` in N·m.
    """

    stamp_ns: int
    frame_id: str
    force: np.ndarray
    torque: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "stamp_ns", int(self.stamp_ns))
        object.__setattr__(self, "frame_id", str(self.frame_id))
        object.__setattr__(self, "force", _frozen_vector(self.force))
        object.__setattr__(self, "torque", _frozen_vector(self.torque))

    @property
    def wrench(self) -> np.ndarray:
        """The six-vector ``[fx, fy, fz, tx, ty, tz]`` (N, N·m)."""
        return np.concatenate([self.force, self.torque])


#: An input message of either stream (what ``SamplePipeline.add`` and ``OnlineEstimator.process`` take).
InputMessage = JointStateData | WrenchData


@dataclass(frozen=True)
class Sample:
    """One learning sample: the input state of the configured joints and the measured output.

    Attributes:
        stamp_ns: Stamp the sample refers to (the wrench stamp for ``output=OutputKind.WRENCH``, the joint
            state stamp for ``output=OutputKind.JOINT_TORQUES``), in nanoseconds.
        q: Joint positions in the configured order (rad), shape ``(n,)``.
        dq: Joint velocities (rad/s), shape ``(n,)``.
        ddq: Estimated joint accelerations (rad/s²), shape ``(n,)``.
        y: Measured output: a wrench ``[fx, fy, fz, tx, ty, tz]`` (N, N·m) or joint torques (N·m).
        joint_stamp_ns: Stamp of the joint state that gave q, q̇ and q̈ (ns); differs from ``stamp_ns``
            by at most the pairing tolerance. Defaults to ``stamp_ns``.
    """

    stamp_ns: int
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    y: np.ndarray
    joint_stamp_ns: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "stamp_ns", int(self.stamp_ns))
        js = self.stamp_ns if self.joint_stamp_ns is None else int(self.joint_stamp_ns)
        object.__setattr__(self, "joint_stamp_ns", js)
        for name in ("q", "dq", "ddq", "y"):
            object.__setattr__(self, name, _frozen_vector(getattr(self, name)))

    @property
    def x(self) -> np.ndarray:
        """The learning input ``[q, dq, ddq]`` (length ``3n``)."""
        return np.concatenate([self.q, self.dq, self.ddq])


def joint_state_from_msg(msg: object) -> JointStateData:
    """Convert a ``sensor_msgs/JointState`` message object into :class:`JointStateData`.

    Duck-typed (no ROS import): works for rclpy messages and for the message objects that ``rosbags``
    deserialises, since both expose ``header.stamp.sec``, ``header.stamp.nanosec``, ``name``,
    ``position``, ``velocity`` and ``effort``. The live node and the bag reader both use this, so a
    message gives the same data either way.

    Args:
        msg: The JointState message.

    Returns:
        The plain-array view (arrays copied, content not validated).
    """
    header = msg.header  # type: ignore[attr-defined]
    return JointStateData(
        stamp_ns=stamp_to_ns(header.stamp.sec, header.stamp.nanosec),
        names=tuple(msg.name),  # type: ignore[attr-defined]
        position=np.asarray(msg.position, dtype=np.float64),  # type: ignore[attr-defined]
        velocity=np.asarray(msg.velocity, dtype=np.float64),  # type: ignore[attr-defined]
        effort=np.asarray(msg.effort, dtype=np.float64),  # type: ignore[attr-defined]
    )


def wrench_from_msg(msg: object) -> WrenchData:
    """Convert a ``geometry_msgs/WrenchStamped`` message object into :class:`WrenchData`.

    Duck-typed like :func:`joint_state_from_msg` (rclpy or rosbags message objects).

    Args:
        msg: The WrenchStamped message.

    Returns:
        The plain-array view: force in N, torque in N·m, in the frame ``header.frame_id``.
    """
    header = msg.header  # type: ignore[attr-defined]
    force = msg.wrench.force  # type: ignore[attr-defined]
    torque = msg.wrench.torque  # type: ignore[attr-defined]
    return WrenchData(
        stamp_ns=stamp_to_ns(header.stamp.sec, header.stamp.nanosec),
        frame_id=header.frame_id,
        force=np.array((force.x, force.y, force.z), dtype=np.float64),
        torque=np.array((torque.x, torque.y, torque.z), dtype=np.float64),
    )
