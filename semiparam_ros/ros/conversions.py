"""Conversions between ROS 2 messages and the plain-array types of :mod:`semiparam_ros.core.stream.messages`.

Inputs are converted with the same duck-typed functions the bag reader uses
(:func:`~semiparam_ros.core.stream.messages.joint_state_from_msg`,
:func:`~semiparam_ros.core.stream.messages.wrench_from_msg`), so a message gives identical data live or from a
bag. Outputs are built here: a wrench prediction as ``geometry_msgs/WrenchStamped`` (force first, N; then
torque, N·m; in the sensor frame of the input), joint torques as ``sensor_msgs/JointState`` with only
``effort`` (N·m) filled, and the base inertial parameters as ``std_msgs/Float64MultiArray``.

Layout of ``~/inertial_parameters``: one dimension, ``layout.dim[0].label`` holds the base-parameter names
joined by commas (``size`` = number of parameters, ``stride`` = size); each name is a linear combination of
URDF parameters as given by :attr:`RigidBodyRegressor.base_parameter_names`, in physical units (kg, kg·m,
kg·m²), followed, with ``robot.output: joint_torques``, by the per-joint friction and offset terms named
``<joint>.viscous`` (N·m·s/rad), ``<joint>.coulomb`` (N·m), ``<joint>.offset`` (N·m) and
``<joint>.armature`` (kg·m², when enabled; merged into an inertia combination where not separately
identifiable), or by ``offset_fx … offset_tz`` (N, N·m) for an F/T sensor offset. A name never contains a
comma (commas inside a name are replaced by ``;``), so ``label.split(",")`` recovers them.

The node publishes its per-sample outputs through :class:`SerializedOutput`: the message is serialised
once by rclpy, and each sample only rewrites the stamp and the values in those bytes (publishing bytes
skips rclpy's conversion of the message object, which costs more than the rest of a publish). It
subscribes to serialised messages too and decodes them with :func:`joint_state_from_cdr` and
:func:`wrench_from_cdr` (little-endian CDR read with :mod:`struct`, about 5× cheaper than rclpy building
the message object that :func:`joint_state_from_msg` then reads; any other or unexpected encoding goes
through rclpy's deserialiser and those functions, so the data is the same either way).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import InertiaStamped, WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from semiparam_ros.core.rigid_body.identification import ConsistentEstimate
from semiparam_ros.core.rigid_body.payload import PayloadEstimate
from semiparam_ros.core.stream.messages import (
    JointStateData,
    WrenchData,
    joint_state_from_msg,
    ns_to_stamp,
    stamp_to_ns,
    wrench_from_msg,
)
from semiparam_ros.errors import RejectedSampleError
from semiparam_ros.serving.feedforward import DesiredState, FeedForwardCommand, TrajectoryPoint

__all__ = [
    "SerializedOutput",
    "joint_state_from_cdr",
    "joint_state_from_msg",
    "joint_torques_msg",
    "parameters_msg",
    "payload_msgs",
    "stamp_msg",
    "wrench_from_cdr",
    "wrench_from_msg",
    "wrench_stamped_msg",
]


def stamp_msg(stamp_ns: int) -> Time:
    """Build a ``builtin_interfaces/Time`` from integer nanoseconds.

    Args:
        stamp_ns: Time in nanoseconds (must be ≥ 0 for ROS; negative values are clamped to 0).

    Returns:
        The stamp message.
    """
    sec, nanosec = ns_to_stamp(max(int(stamp_ns), 0))
    return Time(sec=sec, nanosec=nanosec)


def wrench_stamped_msg(stamp_ns: int, frame_id: str, wrench: np.ndarray,
                       out: WrenchStamped | None = None) -> WrenchStamped:
    """Build (or refill) a ``geometry_msgs/WrenchStamped``.

    Args:
        stamp_ns: Header stamp in nanoseconds (the input sample's stamp).
        frame_id: Header frame (the sensor frame of the input).
        wrench: ``[fx, fy, fz, tx, ty, tz]`` in N and N·m, shape ``(6,)``.
        out: A message to overwrite instead of building a new one (publishing serialises at once, so one
            message per publisher can be reused; building the nested message costs more than filling it).

    Returns:
        The message (``out`` when given).

    Raises:
        ValueError: If ``wrench`` does not have 6 entries.
    """
    w = np.asarray(wrench, dtype=np.float64).reshape(-1)
    if w.shape != (6,):
        raise ValueError(f"a wrench has 6 entries [fx, fy, fz, tx, ty, tz], got shape {w.shape}")
    msg = WrenchStamped() if out is None else out
    sec, nanosec = ns_to_stamp(max(int(stamp_ns), 0))
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    msg.header.frame_id = frame_id
    f, t = msg.wrench.force, msg.wrench.torque
    f.x, f.y, f.z, t.x, t.y, t.z = (float(v) for v in w)
    return msg


def joint_torques_msg(stamp_ns: int, joints: Sequence[str], torques: np.ndarray) -> JointState:
    """Build a ``sensor_msgs/JointState`` carrying predicted joint torques in ``effort``.

    Args:
        stamp_ns: Header stamp in nanoseconds (the input sample's stamp).
        joints: Joint names, in the order of ``torques``.
        torques: Joint torques in N·m, shape ``(len(joints),)``.

    Returns:
        The message (``position`` and ``velocity`` left empty).

    Raises:
        ValueError: If the lengths differ.
    """
    tau = np.asarray(torques, dtype=np.float64).reshape(-1)
    if tau.shape != (len(joints),):
        raise ValueError(f"{len(joints)} joints but {tau.size} torques")
    msg = JointState()
    msg.header.stamp = stamp_msg(stamp_ns)
    msg.name = list(joints)
    msg.effort = tau.tolist()
    return msg


def desired_state_from_msg(msg: Any) -> DesiredState:
    """Convert a ``trajectory_msgs/JointTrajectory`` (or any object with its fields) to a desired state.

    Args:
        msg: The trajectory: ``header.stamp``, ``joint_names``, ``points`` with ``positions`` [rad],
            ``velocities`` [rad/s], ``accelerations`` [rad/s²] and ``time_from_start``.

    Returns:
        The plain-array form (values are checked later, by
        :class:`~semiparam_ros.serving.feedforward.FeedForward`).

    Raises:
        RejectedSampleError: A stamp with ``nanosec ≥ 10⁹`` or negative, or non-numeric values.
    """
    stamp = msg.header.stamp
    if not (0 <= stamp.nanosec < 1_000_000_000) or stamp.sec < 0:
        raise RejectedSampleError(f"invalid header stamp {stamp.sec} s {stamp.nanosec} ns")
    points = []
    try:
        for point in msg.points:
            tfs = point.time_from_start
            points.append(TrajectoryPoint(
                int(tfs.sec) * 1_000_000_000 + int(tfs.nanosec),
                np.asarray(point.positions, dtype=np.float64),
                np.asarray(point.velocities, dtype=np.float64),
                np.asarray(point.accelerations, dtype=np.float64)))
    except (TypeError, ValueError) as err:
        raise RejectedSampleError(f"a trajectory point holds non-numeric values: {err}") from err
    return DesiredState(int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec), tuple(msg.joint_names),
                        tuple(points))


def fill_trajectory_effort(msg: Any, effort: np.ndarray) -> Any:
    """Write each point's effort [N·m] into a ``trajectory_msgs/JointTrajectory`` (in place; returned).

    Args:
        msg: The trajectory the efforts were computed for (joint order of ``msg.joint_names``).
        effort: (len(points), len(joint_names)) finite efforts.

    Returns:
        ``msg``, every other field unchanged (the controller interpolates as it would have).
    """
    for point, row in zip(msg.points, effort, strict=True):
        point.effort = row
    return msg


def link_inertia_msgs(estimate: ConsistentEstimate, stamp_ns: int) -> list[InertiaStamped]:
    """One ``geometry_msgs/InertiaStamped`` per identified link (the consistent estimate).

    Args:
        estimate: The physically consistent per-link parameters.
        stamp_ns: Header stamp [ns].

    Returns:
        Per body: ``header.frame_id`` = the link, ``m`` [kg], ``com`` [m] in the link frame, the inertia
        about the centre of mass in the link's axes [kg·m²] — what a URDF's ``<inertial>`` holds.
    """
    return [_inertia_stamped(link, stamp_ns, *estimate.link(i)) for i, link in enumerate(estimate.body_names)]


def _inertia_stamped(frame_id: str, stamp_ns: int, mass: float, com: np.ndarray,
                     inertia: np.ndarray) -> InertiaStamped:
    """One ``InertiaStamped``: mass [kg], centre of mass [m] in ``frame_id``, inertia (3, 3) [kg·m²]."""
    msg = InertiaStamped()
    msg.header.stamp = stamp_msg(stamp_ns)
    msg.header.frame_id = frame_id
    msg.inertia.m = float(mass)
    msg.inertia.com.x, msg.inertia.com.y, msg.inertia.com.z = (float(v) for v in com)
    i_ = msg.inertia
    i_.ixx, i_.ixy, i_.ixz = float(inertia[0, 0]), float(inertia[0, 1]), float(inertia[0, 2])
    i_.iyy, i_.iyz, i_.izz = float(inertia[1, 1]), float(inertia[1, 2]), float(inertia[2, 2])
    return msg


def feedforward_msgs(command: FeedForwardCommand, joints: Sequence[str]
                     ) -> tuple[Float64MultiArray, JointState, JointState]:
    """Build the three feed-forward messages of a command.

    Args:
        command: The feed-forward command (order of ``joints``).
        joints: The output joint names (``feedforward.joints``).

    Returns:
        ``(commands, state, std)``: a ``Float64MultiArray`` of τ_ff [N·m] in the order of a
        ``JointGroupEffortController``'s ``~/commands``; a ``JointState`` (stamp = the evaluated time,
        position/velocity = the desired state used, effort = τ_ff); a ``JointState`` whose effort is σ.
    """
    commands = Float64MultiArray()
    commands.data = command.tau.tolist()
    state = JointState()
    state.header.stamp = stamp_msg(command.stamp_ns)
    state.name = list(joints)
    state.position = command.q.tolist()
    state.velocity = command.dq.tolist()
    state.effort = command.tau.tolist()
    std = joint_torques_msg(command.stamp_ns, joints, command.std)
    return commands, state, std


def parameters_msg(names: Sequence[str], values: np.ndarray) -> Float64MultiArray:
    """Build the ``~/inertial_parameters`` message: the base parameters, each named by a label.

    Layout: ``dim[0]`` is the parameter axis (label ``base_parameters``, size n, stride n); ``dim[1 + i]``
    is a singleton dimension (size 1, stride 1) whose label is the name of ``data[i]``. The layout is a
    valid n × 1 × … × 1 array, and ``{d.label: v for d, v in zip(msg.layout.dim[1:], msg.data)}`` reads
    the named values.

    Args:
        names: Base-parameter names.
        values: Their current estimates (kg, kg·m, kg·m² combinations as the names say; friction N·m·s/rad
            and N·m, offsets N·m).

    Returns:
        The message.

    Raises:
        ValueError: If the lengths differ.
    """
    vals = np.asarray(values, dtype=np.float64).reshape(-1)
    if vals.size != len(names):
        raise ValueError(f"{len(names)} parameter names but {vals.size} values")
    msg = Float64MultiArray()
    axis = MultiArrayDimension()
    axis.label = "base_parameters"
    axis.size = int(vals.size)
    axis.stride = int(vals.size)
    dims = [axis]
    for name in names:
        dim = MultiArrayDimension()
        dim.label = str(name)
        dim.size = 1
        dim.stride = 1
        dims.append(dim)
    msg.layout.dim = dims
    msg.layout.data_offset = 0
    msg.data = vals.tolist()
    return msg


def payload_msgs(estimate: PayloadEstimate, stamp_ns: int) -> tuple[InertiaStamped, InertiaStamped]:
    """Build ``~/payload`` and ``~/payload/std``: the payload and its standard deviations.

    Args:
        estimate: The payload estimate.
        stamp_ns: Header stamp [ns].

    Returns:
        Two ``geometry_msgs/InertiaStamped`` with ``header.frame_id`` = the distal body (the frame of the
        centre of mass): mass [kg], centre of mass [m], inertia about it [kg·m²]; the second holds each
        field's standard deviation in the same place.
    """
    body = estimate.body
    return (_inertia_stamped(body, stamp_ns, estimate.mass, estimate.com, estimate.inertia),
            _inertia_stamped(body, stamp_ns, estimate.mass_std, estimate.com_std, estimate.inertia_std))


#: CDR little-endian encapsulation (``CDR_LE``), what rmw_fastrtps and rmw_cyclonedds write on x86/ARM.
_CDR_LE = b"\x00\x01"
_STAMP = struct.Struct("<iI")  # builtin_interfaces/Time at the start of the CDR payload
_PAYLOAD_START = 4  # after the 2-byte encapsulation id and the 2-byte options


class SerializedOutput:
    """A stamped message serialised once, re-emitted with a new stamp and new trailing ``float64`` values.

    The message's first field must be ``std_msgs/Header`` (its stamp is the first 8 bytes of the CDR
    payload) and the ``n`` values must be stored as ``n`` consecutive ``float64`` (a ``WrenchStamped``'s
    six components, a ``JointState``'s ``effort``). Their byte offset is found by serialising the message
    with distinct sentinel values and searching for them, so no layout is hard-coded. Where that fails (a
    big-endian encapsulation, sentinels not found exactly once) :meth:`fill` falls back to building the
    message object, which publishes the same content.

    Args:
        build: ``build(stamp_ns, values)`` → the message (e.g. :func:`wrench_stamped_msg` with a frame).
        n_values: Number of values per sample.

    Raises:
        ValueError: If ``n_values`` < 1 (raised by ``build`` too for a wrong length).
    """

    def __init__(self, build: Callable[[int, np.ndarray], Any], n_values: int) -> None:
        if n_values < 1:
            raise ValueError(f"n_values must be ≥ 1, got {n_values}")
        self._build = build
        self._n = int(n_values)
        sentinels = np.pi * (1.0 + np.arange(self._n)) + 1e-3  # values no stamp/string byte pattern repeats
        raw = bytes(serialize_message(build(0, sentinels)))
        needle = sentinels.astype("<f8").tobytes()
        offset = raw.find(needle)
        self._buffer: bytearray | None = None
        if raw[:2] == _CDR_LE and offset >= _PAYLOAD_START + _STAMP.size and raw.find(needle, offset + 1) < 0:
            self._buffer = bytearray(raw)
            self._values = np.frombuffer(self._buffer, dtype="<f8", count=self._n, offset=offset)

    @property
    def serialized(self) -> bool:
        """Whether :meth:`fill` returns serialised bytes (else message objects)."""
        return self._buffer is not None

    def fill(self, stamp_ns: int, values: np.ndarray) -> bytes | Any:
        """Return the message for one sample, as CDR bytes ready for ``Publisher.publish``.

        Args:
            stamp_ns: Header stamp in nanoseconds (negative values are clamped to 0, as in :func:`stamp_msg`).
            values: The ``n_values`` values (units of the message: N, N·m).

        Returns:
            Serialised bytes (or the message object in the fallback case).

        Raises:
            ValueError: If ``values`` does not have ``n_values`` entries.
        """
        if self._buffer is None:
            return self._build(stamp_ns, values)
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        if v.shape != (self._n,):
            raise ValueError(f"expected {self._n} values, got shape {v.shape}")
        sec, nanosec = ns_to_stamp(max(int(stamp_ns), 0))
        _STAMP.pack_into(self._buffer, _PAYLOAD_START, sec, nanosec)
        self._values[:] = v
        return bytes(self._buffer)


class _NotFastPathError(Exception):
    """The bytes are not what the fast decoder reads: hand them to rclpy's deserialiser."""


def _cdr_string(raw: bytes, pos: int) -> tuple[str, int]:
    """Read a CDR string (4-aligned ``uint32`` length with the NUL, bytes, NUL) at ``pos``."""
    pos = _align(pos, 4)
    (n,) = _U32.unpack_from(raw, pos)
    end = pos + 4 + n
    if n == 0 or end > len(raw) or raw[end - 1] != 0:
        raise _NotFastPathError
    return raw[pos + 4:end - 1].decode(), end


def _align(pos: int, size: int) -> int:
    """Align a buffer offset to ``size`` relative to the CDR payload (which starts at byte 4)."""
    return pos + (-(pos - _PAYLOAD_START) % size)


def _cdr_doubles(raw: bytes, pos: int) -> tuple[np.ndarray, int]:
    """Read a CDR ``float64[]`` (``uint32`` count, then 8-aligned values; no padding when empty)."""
    pos = _align(pos, 4)
    (n,) = _U32.unpack_from(raw, pos)
    pos += 4
    if n == 0:
        return np.empty(0), pos
    pos = _align(pos, 8)
    end = pos + 8 * n
    if end > len(raw):
        raise _NotFastPathError
    return np.frombuffer(raw, dtype="<f8", count=n, offset=pos), end


_U32 = struct.Struct("<I")
#: A joint name costs at least 8 bytes of CDR (length, one character, terminator, padding) plus 24 for
#: its position, velocity and effort; the header and frame of a sane message fit in 64 kB.
_MIN_BYTES_PER_NAME = 8
_MAX_FIXED_BYTES = 65536


def _names_header(raw: bytes) -> tuple[int, int]:
    """Return ``(number of names, offset of the first name)`` of a little-endian CDR JointState.

    Skips the stamp and the frame id without decoding the names.

    Raises:
        struct.error, UnicodeDecodeError, _NotFastPathError: Bytes the fast reader does not expect.
    """
    _, pos = _cdr_string(raw, _PAYLOAD_START + 8)  # frame_id (not used)
    pos = _align(pos, 4)
    (n_names,) = _U32.unpack_from(raw, pos)
    return int(n_names), pos + 4


def _name_count(raw: bytes) -> int | None:
    """Return the number of names of a little-endian CDR JointState without decoding them (None: unknown)."""
    try:
        return _names_header(raw)[0] if raw[:2] == _CDR_LE else None
    except (struct.error, UnicodeDecodeError, _NotFastPathError):
        return None


#: Frame + names section (bytes from the end of the stamp), its names and end offset, of the last JointState
#: read: a robot sends the same names every time, so one byte comparison replaces decoding them.
_last_names: tuple[bytes, tuple[str, ...], int] = (b"", (), 0)


def joint_state_from_cdr(raw: bytes, max_names: int | None = None) -> JointStateData:
    """Convert a serialised ``sensor_msgs/JointState`` into :class:`JointStateData`.

    Equal to ``joint_state_from_msg(deserialize_message(raw, JointState))``, which is what runs for any
    encapsulation other than little-endian CDR or bytes the fast reader does not expect.

    A message cut short inside its trailing alignment padding still holds every value and is decoded as
    is (correctly: nothing is lost); one cut inside a value is refused by the deserialiser.

    Args:
        raw: The serialised message (CDR with its 4-byte encapsulation header).
        max_names: Refuse a message with more joint names than this before decoding them (a 10⁶-name
            message would otherwise take the node's thread for about a second); None for no bound.

    Returns:
        The plain-array view (content not validated, as :func:`joint_state_from_msg`).

    Raises:
        RejectedSampleError: If the bytes are not a JointState (rclpy cannot deserialise them), the stamp
            is invalid, or there are more than ``max_names`` names.
    """
    global _last_names
    if max_names is not None and len(raw) > _MIN_BYTES_PER_NAME * max_names + _MAX_FIXED_BYTES:
        n_names = _name_count(raw)
        if n_names is None or n_names > max_names:
            raise RejectedSampleError(f"oversized JointState: {len(raw)} bytes"
                                      + ("" if n_names is None else f", {n_names} names")
                                      + f" (at most {max_names} names accepted)")
    try:
        if raw[:2] != _CDR_LE:
            raise _NotFastPathError
        sec, nanosec = _STAMP.unpack_from(raw, _PAYLOAD_START)
        start = _PAYLOAD_START + 8
        key, names, pos = _last_names
        if not key or not raw.startswith(key, start):  # frame and names as in the previous message?
            n_names, pos = _names_header(raw)
            if 4 * n_names > len(raw) - pos:
                raise _NotFastPathError
            decoded = []
            for _ in range(n_names):
                name, pos = _cdr_string(raw, pos)
                decoded.append(name)
            names = tuple(decoded)
            _last_names = (raw[start:pos], names, pos)  # same bytes from `start` parse the same way
        position, pos = _cdr_doubles(raw, pos)
        velocity, pos = _cdr_doubles(raw, pos)
        effort, pos = _cdr_doubles(raw, pos)
    except (_NotFastPathError, struct.error, UnicodeDecodeError):
        return joint_state_from_msg(_deserialize(raw, JointState))
    return JointStateData(stamp_to_ns(sec, nanosec), names, position, velocity, effort)


def wrench_from_cdr(raw: bytes) -> WrenchData:
    """Convert a serialised ``geometry_msgs/WrenchStamped`` into :class:`WrenchData`.

    Equal to ``wrench_from_msg(deserialize_message(raw, WrenchStamped))`` (which runs for any other
    encapsulation or unexpected bytes, as in :func:`joint_state_from_cdr`).

    Args:
        raw: The serialised message.

    Returns:
        The plain-array view: force in N, torque in N·m, in the frame ``header.frame_id``.

    Raises:
        RejectedSampleError: If the bytes are not a WrenchStamped.
    """
    try:
        if raw[:2] != _CDR_LE:
            raise _NotFastPathError
        sec, nanosec = _STAMP.unpack_from(raw, _PAYLOAD_START)
        frame, pos = _cdr_string(raw, _PAYLOAD_START + 8)
        values, _ = _cdr_six(raw, pos)
    except (_NotFastPathError, struct.error, UnicodeDecodeError):
        return wrench_from_msg(_deserialize(raw, WrenchStamped))
    return WrenchData(stamp_to_ns(sec, nanosec), frame, values[:3], values[3:])


def _cdr_six(raw: bytes, pos: int) -> tuple[np.ndarray, int]:
    pos = _align(pos, 8)
    if pos + 48 > len(raw):
        raise _NotFastPathError
    return np.frombuffer(raw, dtype="<f8", count=6, offset=pos), pos + 48


def _deserialize(raw: bytes, msg_type: type) -> Any:
    try:
        return deserialize_message(raw, msg_type)
    except Exception as err:  # rclpy raises several types for bytes that are not this message
        raise RejectedSampleError(f"not a serialised {msg_type.__name__}: {err}") from err
