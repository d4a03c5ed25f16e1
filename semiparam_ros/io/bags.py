"""Read and write rosbag2 bags (MCAP storage) without a ROS installation.

Reading goes through :class:`rosbags.highlevel.AnyReader`, which accepts a bag folder (with
``metadata.yaml``; MCAP or SQLite3 storage) or a bare ``.mcap`` file and streams messages in log-time
order chunk by chunk, so a bag is never loaded whole. Messages are deserialised with the type
definitions embedded in the bag and converted with the same duck-typed functions the live node uses
(:func:`~semiparam_ros.core.stream.messages.joint_state_from_msg`,
:func:`~semiparam_ros.core.stream.messages.wrench_from_msg`).

Writing goes through :class:`rosbags.rosbag2.Writer` (rosbag2 version 9, MCAP storage) with the ROS 2
Jazzy typestore, which gives ``<folder>/<folder>.mcap`` plus ``metadata.yaml`` — the layout ``ros2 bag``
produces, readable by ``ros2 bag play`` on a ROS machine.

A truncated MCAP file (no footer: the recorder was killed or the robot powered off) or one with a corrupt
chunk is not refused: it is read by a sequential scan (:mod:`semiparam_ros.io.mcap_scan`) that recovers
every message complete before the cut and skips chunks that do not decode, and a
:class:`BagRecoveryWarning` says how many messages and how much log time were recovered.

Every other failure to read or write a bag raises :class:`~semiparam_ros.errors.BagError` (a
``ValueError``) whose message names the path and, where relevant, the topic.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from semiparam_ros.core.kinds import WRENCH_WIDTH, InputKind, OutputKind
from semiparam_ros.core.stream.messages import (
    JointStateData,
    Sample,
    WrenchData,
    joint_state_from_msg,
    ns_to_stamp,
    stamp_to_ns,
    wrench_from_msg,
)
from semiparam_ros.errors import BagError, RejectedSampleError
from semiparam_ros.io.mcap_scan import McapScan, ScannedChannel

if TYPE_CHECKING:
    from rosbags.interfaces import Connection

    from semiparam_ros.core.stream.pipeline import SamplePipeline

__all__ = [
    "JOINT_STATE_TYPE",
    "JOINT_TRAJECTORY_TYPE",
    "WRENCH_STAMPED_TYPE",
    "BagError",
    "BagRecoveryWarning",
    "BagWriter",
    "TopicArrays",
    "TopicInfo",
    "absolute_topic",
    "iter_raw",
    "iter_samples",
    "read_messages",
    "read_topic_arrays",
    "recovery_notes",
    "topic_info",
]

JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
WRENCH_STAMPED_TYPE = "geometry_msgs/msg/WrenchStamped"
JOINT_TRAJECTORY_TYPE = "trajectory_msgs/msg/JointTrajectory"

_DEFAULT_WRENCH_TOPIC = "/wrench"
_AUTO: Any = object()  # sentinel: "choose the wrench topic from the pipeline's output"

_TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


# --------------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TopicInfo:
    """Summary of one topic of a bag.

    Attributes:
        msgtype: Message type, e.g. ``"sensor_msgs/msg/JointState"``.
        count: Number of messages.
    """

    msgtype: str
    count: int


def _resolve(path: Path) -> Path:
    """Return what AnyReader should open: the folder, or a folder's only ``.mcap`` if it has no metadata."""
    if path.is_dir() and not (path / "metadata.yaml").exists():
        mcaps = sorted(path.glob("*.mcap"))
        if len(mcaps) == 1:
            return mcaps[0]  # e.g. a recording copied without its metadata.yaml
        raise BagError(
            f"bag folder {str(path)!r} has no metadata.yaml and {len(mcaps)} .mcap files (expected exactly 1)"
        )
    return path


def _open_reader(path: Path) -> AnyReader:
    """Open ``path`` with AnyReader, translating every failure into :class:`BagError`."""
    if not path.exists():
        raise BagError(f"bag {str(path)!r} does not exist")
    path = _resolve(path)
    if path.is_file() and path.suffix not in {".mcap", ".db3", ".bag"}:
        raise BagError(f"bag {str(path)!r} is a file but not an .mcap (or .db3/.bag) file")
    try:
        reader = AnyReader([path], default_typestore=_TYPESTORE)
        reader.open()
    except BagError:
        raise
    except Exception as err:  # rosbags raises several unrelated types (reader, typesys, OS, struct)
        raise BagError(f"cannot open bag {str(path)!r}: {err}") from err
    return reader


def _mcap_file(path: Path) -> Path | None:
    """Return the MCAP file behind a bag path (a bare ``.mcap``, or a folder's only one), else None."""
    if path.is_file():
        return path if path.suffix == ".mcap" else None
    mcaps = sorted(path.glob("*.mcap")) if path.is_dir() else []
    return mcaps[0] if len(mcaps) == 1 else None


def _scan_or_raise(path: Path, err: BagError) -> McapScan:
    """Start a recovery scan of a bag that AnyReader cannot read, or re-raise ``err`` if none is possible."""
    mcap = _mcap_file(path)
    if mcap is None:
        raise err
    try:
        return McapScan(mcap)
    except (OSError, ValueError):
        raise err from err.__cause__


def _connections_for(connections: Sequence[Any], path: Path, topics: dict[str, str | None]) -> list[Any]:
    """Select the connections of the requested topics, checking presence and message type.

    Args:
        connections: The bag's connections (objects with ``topic`` and ``msgtype``).
        path: The bag path (for messages).
        topics: Topic name -> required message type (``None``: any type).

    Raises:
        BagError: A topic is missing or carries another type.
    """
    available = {c.topic: c.msgtype for c in connections}
    selected = []
    for topic, msgtype in topics.items():
        conns = [c for c in connections if c.topic == topic]
        if not conns:
            listing = ", ".join(f"{t} [{m}]" for t, m in sorted(available.items())) or "none"
            raise BagError(f"bag {str(path)!r} has no topic {topic!r} (topics: {listing})")
        for conn in conns:
            if msgtype is not None and conn.msgtype != msgtype:
                raise BagError(
                    f"bag {str(path)!r}: topic {topic!r} carries {conn.msgtype!r}, expected {msgtype!r}"
                )
        selected.extend(conns)
    return selected


Decoder = Callable[[bytes, str], Any]
"""Deserialises CDR bytes of a message type (rosbags form, e.g. ``"sensor_msgs/msg/JointState"``)."""


def _stream(path: Path, topics: dict[str, str | None]) -> Iterator[tuple[Decoder, Any, int, bytes]]:
    """Yield ``(decode, connection, log_time_ns, raw)`` for the topics, in log-time order.

    Opens the bag when iteration starts and closes it when the generator finishes or is closed. An MCAP
    file that cannot be read whole — no footer (truncated), or a corrupt chunk met while reading — is
    read by a sequential scan instead (:mod:`semiparam_ros.io.mcap_scan`), with a
    :class:`BagRecoveryWarning` saying what was recovered. Other read errors become :class:`BagError`.
    """
    try:
        reader = _open_reader(path)
    except BagError as err:
        scan = _scan_or_raise(path, err)
        yield from _recover(scan, path, topics, resume=None, cause=err)
        return
    last_time, n_at_last = -1, 0  # where the reader got to: a recovery scan resumes after it
    try:
        conns = _connections_for(reader.connections, path, topics)
        messages = reader.messages(connections=conns)
        while True:
            try:
                conn, log_time, raw = next(messages)
            except StopIteration:
                return
            except Exception as err:
                failure = BagError(f"cannot read bag {str(path)!r}: {err}")
                failure.__cause__ = err
                scan = _scan_or_raise(path, failure)
                yield from _recover(scan, path, topics, resume=(last_time, n_at_last), cause=failure)
                return
            n_at_last = n_at_last + 1 if log_time == last_time else 1
            last_time = log_time
            yield reader.deserialize, conn, log_time, raw
    finally:
        reader.close()


class BagRecoveryWarning(UserWarning):
    """A bag was read in part: the MCAP file is truncated (no footer) or has chunks that do not decode."""


@contextlib.contextmanager
def recovery_notes() -> Iterator[list[str]]:
    """Collect the :class:`BagRecoveryWarning` texts raised inside the block, once each, into a list.

    For tools that report recovered bags in their own output instead of as warnings; every other warning
    is passed on unchanged when the block ends.

    Yields:
        The list the notes are appended to (filled when the block ends).
    """
    notes: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", BagRecoveryWarning)
        yield notes
    for w in caught:
        if issubclass(w.category, BagRecoveryWarning):
            if str(w.message) not in notes:
                notes.append(str(w.message))
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def absolute_topic(topic: str) -> str:
    """Return a topic name as recorded in a bag: a relative name (the node's ``topics.*``) gets a ``/``."""
    return topic if topic.startswith("/") else "/" + topic


def _recover(scan: McapScan, path: Path, topics: dict[str, str | None], *, resume: tuple[int, int] | None,
             cause: BagError) -> Iterator[tuple[Decoder, Any, int, bytes]]:
    """Yield the messages a recovery scan finds on ``topics``.

    ``resume = (t, k)``: the messages up to log time ``t`` (the first ``k`` at ``t``) were read already
    (by AnyReader, in log-time order, before it met a damaged chunk); only later ones are yielded.

    Raises:
        BagError: ``cause`` if the scan recovers no message at all; a missing topic or wrong type.
    """
    store = get_typestore(Stores.ROS2_JAZZY)  # own store: schemas of the file may be registered into it
    wanted = set(topics)
    checked: set[int] = set()
    last_time, n_at_last = resume if resume is not None else (-1, 0)
    for channel, log_time, raw in scan.messages(wanted):
        if channel.id not in checked:
            _connections_for([channel], path, {channel.topic: topics[channel.topic]})
            _register_schema(store, channel)
            checked.add(channel.id)
        if log_time < last_time:
            continue
        if log_time == last_time and n_at_last > 0:
            n_at_last -= 1
            continue
        yield store.deserialize_cdr, channel, log_time, raw
    rep = scan.report
    if not scan.channels and not rep.n_messages:
        raise cause
    if resume is None:
        # a topic never seen in the recovered part: the standard missing-topic message
        _connections_for(list(scan.channels.values()), path, topics)
    _warn_recovered(scan, path, sorted(wanted), cause)


def _warn_recovered(scan: McapScan, path: Path, topics: list[str], cause: BagError) -> None:
    """Issue the :class:`BagRecoveryWarning` that says what a scan recovered and what it lost."""
    rep = scan.report
    lost = "; ".join(f"at byte {off}: {why}" for off, why in rep.skipped[:5])
    more = f" (+{len(rep.skipped) - 5} more)" if len(rep.skipped) > 5 else ""
    if not rep.complete:
        state = (f"is truncated or damaged ({rep.stop_reason}: record at byte {rep.stop_offset}, file of "
                 f"{rep.file_size} bytes)")
    elif rep.skipped:
        state = "has damaged chunks"
    else:
        state = "has a damaged summary or footer (every data record was read)"
    warnings.warn(
        f"bag {str(path)!r} {state}: recovered {rep.n_messages} messages on {topics} spanning "
        f"{rep.span_s:.3f} s of log time; skipped: {lost or 'nothing'}{more}. Cause: {cause}",
        BagRecoveryWarning, stacklevel=4)


def _register_schema(store: Any, channel: ScannedChannel) -> None:
    """Add a type the Jazzy store lacks from the file's own definition (``ros2msg`` schemas)."""
    if channel.msgtype in store.types or channel.schema_encoding != "ros2msg":
        return
    try:
        store.register(get_types_from_msg(channel.schema_data, channel.msgtype))
    except Exception:
        pass


def _validate_now(path: Path, topics: dict[str, str | None]) -> None:
    """Open the bag and check the topics eagerly (cheap: reads the MCAP summary only).

    A bag AnyReader cannot open is scanned instead (a whole pass; only damaged files take this path).
    """
    try:
        reader = _open_reader(path)
    except BagError as err:
        scan = _scan_or_raise(path, err)
        for _ in scan.messages(set()):
            pass
        if not scan.channels:
            raise err from err.__cause__
        _connections_for(list(scan.channels.values()), path, topics)
        return
    try:
        _connections_for(reader.connections, path, topics)
    finally:
        reader.close()


def _deserialize(decode: Decoder, raw: bytes, conn: Any, path: Path) -> Any:
    try:
        return decode(raw, conn.msgtype)
    except Exception as err:
        raise BagError(
            f"bag {str(path)!r}: cannot decode a {conn.msgtype!r} message on {conn.topic!r}: {err}"
        ) from err


def topic_info(path: str | Path) -> dict[str, TopicInfo]:
    """List the topics of a bag with their message type and count.

    Args:
        path: Bag folder or bare ``.mcap`` file.

    Returns:
        Topic name -> :class:`TopicInfo` (for a truncated MCAP file, the counts of the recoverable
        messages).

    Raises:
        BagError: The bag cannot be opened (nor scanned).
    """
    path = Path(path)
    try:
        reader = _open_reader(path)
    except BagError as err:
        scan = _scan_or_raise(path, err)
        counts: dict[int, int] = {}
        for channel, _, _ in scan.messages():
            counts[channel.id] = counts.get(channel.id, 0) + 1
        if not scan.channels:
            raise err from err.__cause__
        _warn_recovered(scan, path, sorted({c.topic for c in scan.channels.values()}), err)
        out: dict[str, TopicInfo] = {}
        for cid, channel in scan.channels.items():
            prev = out.get(channel.topic)
            out[channel.topic] = TopicInfo(channel.msgtype, counts.get(cid, 0) + (prev.count if prev else 0))
        return out
    try:
        return {
            name: TopicInfo(msgtype=info.msgtype or "", count=int(info.msgcount))
            for name, info in reader.topics.items()
        }
    finally:
        reader.close()


def read_messages(
    path: str | Path,
    *,
    joint_states_topic: str | None = "/joint_states",
    wrench_topic: str | None = _DEFAULT_WRENCH_TOPIC,
) -> Iterator[JointStateData | WrenchData]:
    """Stream the joint states and wrenches of a bag in log-time order.

    The bag and the topics are checked when this function is called; messages are then read lazily,
    one MCAP chunk (≈1 MB) at a time, and the file is closed when the iterator is exhausted or closed.

    Args:
        path: Bag folder (with ``metadata.yaml``) or bare ``.mcap`` file.
        joint_states_topic: ``sensor_msgs/msg/JointState`` topic, or ``None`` to skip joint states.
        wrench_topic: ``geometry_msgs/msg/WrenchStamped`` topic, or ``None`` to skip wrenches
            (e.g. for joint-torque learning from ``JointState.effort``).

    Returns:
        An iterator of :class:`JointStateData` and :class:`WrenchData` (header stamps in ns).

    Raises:
        BagError: Missing or unreadable bag (one that yields no message even by a scan), a missing topic,
            or a topic with another message type (at call time).

    Warns:
        BagRecoveryWarning: At the end of iteration, if the file was truncated or had corrupt chunks.
    """
    path = Path(path)
    topics: dict[str, str | None] = {}
    if joint_states_topic is not None:
        topics[joint_states_topic] = JOINT_STATE_TYPE
    if wrench_topic is not None:
        if wrench_topic in topics:
            raise BagError(f"joint_states_topic and wrench_topic are both {wrench_topic!r}")
        topics[wrench_topic] = WRENCH_STAMPED_TYPE
    if not topics:
        raise BagError("read_messages needs at least one of joint_states_topic and wrench_topic")
    _validate_now(path, topics)
    return _read_messages(path, topics)


def _read_messages(path: Path, topics: dict[str, str | None]) -> Iterator[JointStateData | WrenchData]:
    invalid = 0
    for decode, conn, _log_time, raw in _stream(path, topics):
        msg = _deserialize(decode, raw, conn, path)
        try:
            yield joint_state_from_msg(msg) if conn.msgtype == JOINT_STATE_TYPE else wrench_from_msg(msg)
        except RejectedSampleError:  # an invalid stamp: the node drops such a message too
            invalid += 1
    if invalid:
        warnings.warn(f"bag {str(path)!r}: {invalid} messages with an invalid stamp (nanosec >= 1e9) were "
                      "skipped", BagRecoveryWarning, stacklevel=3)


def iter_samples(
    path: str | Path,
    pipeline: SamplePipeline,
    *,
    joint_states_topic: str = "/joint_states",
    wrench_topic: str | None = _AUTO,
) -> Iterator[Sample]:
    """Feed a bag through a :class:`~semiparam_ros.core.stream.pipeline.SamplePipeline` and yield its samples.

    Messages enter the pipeline in log-time order, exactly as a live subscriber would receive them;
    drops are counted in ``pipeline.drops``.

    Args:
        path: Bag folder or bare ``.mcap`` file.
        pipeline: The pipeline (its state carries over; call ``pipeline.reset()`` to start afresh).
        joint_states_topic: ``sensor_msgs/msg/JointState`` topic.
        wrench_topic: ``geometry_msgs/msg/WrenchStamped`` topic. Default: ``"/wrench"`` when the
            pipeline learns a wrench, none when it learns joint torques.

    Returns:
        An iterator of :class:`~semiparam_ros.core.stream.messages.Sample`.

    Raises:
        BagError: As :func:`read_messages`.
    """
    if wrench_topic is _AUTO:
        wrench_topic = None if pipeline.output == OutputKind.JOINT_TORQUES else _DEFAULT_WRENCH_TOPIC
    messages = read_messages(path, joint_states_topic=joint_states_topic, wrench_topic=wrench_topic)
    return _iter_samples(messages, pipeline)


def _iter_samples(
    messages: Iterator[JointStateData | WrenchData], pipeline: SamplePipeline
) -> Iterator[Sample]:
    for msg in messages:
        yield from pipeline.add(msg)


def iter_raw(path: str | Path, topics: Iterable[str]) -> Iterator[tuple[str, str, int, bytes]]:
    """Stream the serialised messages of some topics, for replay over DDS.

    Args:
        path: Bag folder or bare ``.mcap`` file.
        topics: Topic names (any message type).

    Returns:
        An iterator of ``(topic, msgtype, log_time_ns, cdr_bytes)`` in log-time order; ``msgtype`` is
        the rosbags form, e.g. ``"sensor_msgs/msg/JointState"``. The bytes can be published as they are
        with ``publisher.publish(raw)``.

    Raises:
        BagError: As :func:`read_messages`.
    """
    path = Path(path)
    wanted: dict[str, str | None] = dict.fromkeys(topics)
    if not wanted:
        raise BagError("iter_raw needs at least one topic")
    _validate_now(path, wanted)
    return _iter_raw(path, wanted)


def _iter_raw(path: Path, topics: dict[str, str | None]) -> Iterator[tuple[str, str, int, bytes]]:
    for _decode, conn, log_time, raw in _stream(path, topics):
        yield conn.topic, conn.msgtype, int(log_time), bytes(raw)


@dataclass(frozen=True)
class TopicArrays:
    """A whole topic as stacked arrays (for ground-truth and evaluation topics, not for replay).

    Attributes:
        topic: The topic name.
        msgtype: Its message type.
        stamp_ns: Header stamps, shape ``(N,)`` int64.
        log_time_ns: Log times, shape ``(N,)`` int64.
        names: Joint names of the columns (empty for wrenches).
        frame_id: Header frame id of the first message (``""`` if none).
        fields: Field name -> array ``(N, k)``. JointState: ``position``, ``velocity``, ``effort``
            (absent when empty in the messages); WrenchStamped: ``wrench`` ``(N, 6)`` = ``[f, τ]``
            (N, N·m); JointTrajectory (the first point of each message): ``positions``,
            ``velocities``, ``accelerations``, ``effort``.
    """

    topic: str
    msgtype: str
    stamp_ns: np.ndarray
    log_time_ns: np.ndarray
    names: tuple[str, ...] = ()
    frame_id: str = ""
    fields: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.stamp_ns.shape[0])


_ARRAY_TYPES = {
    JOINT_STATE_TYPE: ("position", "velocity", "effort"),
    WRENCH_STAMPED_TYPE: (InputKind.WRENCH,),
    JOINT_TRAJECTORY_TYPE: ("positions", "velocities", "accelerations", "effort"),
}


def read_topic_arrays(path: str | Path, topic: str, *, joints: Sequence[str] | None = None) -> TopicArrays:
    """Read one topic whole into arrays, e.g. ``/ground_truth/joint_accelerations``.

    Supported types: ``sensor_msgs/msg/JointState``, ``geometry_msgs/msg/WrenchStamped`` and
    ``trajectory_msgs/msg/JointTrajectory`` (first point of each message). Memory grows with the
    topic: use it for evaluation topics, and :func:`read_messages` for long recordings.

    Args:
        path: Bag folder or bare ``.mcap`` file.
        topic: The topic.
        joints: For joint topics, the columns to return in this order (default: the names of the
            first message). Messages may list joints in any order; each is reordered by name.

    Returns:
        A :class:`TopicArrays`.

    Raises:
        BagError: Unreadable bag, missing topic, unsupported type, a requested joint missing from a
            message, or arrays whose length does not match the names.
    """
    path = Path(path)
    info = topic_info(path)
    if topic not in info:
        _validate_now(path, {topic: None})  # raises the standard missing-topic message
    msgtype = info[topic].msgtype
    if msgtype not in _ARRAY_TYPES:
        raise BagError(
            f"bag {str(path)!r}: topic {topic!r} has type {msgtype!r}; read_topic_arrays supports "
            f"{sorted(_ARRAY_TYPES)}"
        )
    stamps: list[int] = []
    log_times: list[int] = []
    columns: dict[str, list[np.ndarray]] = {k: [] for k in _ARRAY_TYPES[msgtype]}
    names: tuple[str, ...] | None = tuple(joints) if joints is not None else None
    frame_id = ""
    for decode, conn, log_time, raw in _stream(path, {topic: msgtype}):
        msg = _deserialize(decode, raw, conn, path)
        if not stamps:
            frame_id = str(msg.header.frame_id)
        stamps.append(stamp_to_ns(msg.header.stamp.sec, msg.header.stamp.nanosec))
        log_times.append(int(log_time))
        if msgtype == WRENCH_STAMPED_TYPE:
            f, t = msg.wrench.force, msg.wrench.torque
            columns[InputKind.WRENCH].append(np.array([f.x, f.y, f.z, t.x, t.y, t.z]))
            continue
        if msgtype == JOINT_STATE_TYPE:
            msg_names = tuple(msg.name)
            values = {k: np.asarray(getattr(msg, k), dtype=np.float64) for k in columns}
        else:
            if not msg.points:
                raise BagError(f"bag {str(path)!r}: a message on {topic!r} has no trajectory point")
            msg_names = tuple(msg.joint_names)
            point = msg.points[0]
            values = {k: np.asarray(getattr(point, k), dtype=np.float64) for k in columns}
        if names is None:
            names = msg_names
        index = {n: i for i, n in enumerate(msg_names)}
        missing = [n for n in names if n not in index]
        if missing:
            raise BagError(f"bag {str(path)!r}: a message on {topic!r} lacks joints {missing}")
        order = np.array([index[n] for n in names], dtype=np.intp)
        for key, val in values.items():
            if val.size == 0:
                columns[key].append(np.full(len(names), np.nan))
                continue
            if val.shape[0] != len(msg_names):
                raise BagError(
                    f"bag {str(path)!r}: field {key!r} on {topic!r} has {val.shape[0]} values for "
                    f"{len(msg_names)} names"
                )
            columns[key].append(val[order])
    width = WRENCH_WIDTH if msgtype == WRENCH_STAMPED_TYPE else len(names or ())
    stacked = {k: (np.stack(v) if v else np.empty((0, width))) for k, v in columns.items()}
    # drop fields that were empty in every message (e.g. a JointState without effort)
    stacked = {k: v for k, v in stacked.items() if v.shape[0] == 0 or not np.all(np.isnan(v))}
    return TopicArrays(
        topic=topic,
        msgtype=msgtype,
        stamp_ns=np.asarray(stamps, dtype=np.int64),
        log_time_ns=np.asarray(log_times, dtype=np.int64),
        names=tuple(names or ()) if msgtype != WRENCH_STAMPED_TYPE else (),
        frame_id=frame_id,
        fields=stacked,
    )


# --------------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------------


def _is_bag_folder(path: Path) -> bool:
    """Tell whether ``path`` holds nothing but rosbag2 files (safe to delete on overwrite)."""
    return path.is_dir() and all(
        child.is_file() and (child.name == "metadata.yaml" or child.suffix in {".mcap", ".db3"})
        for child in path.iterdir()
    )


def _float_array(values: object, what: str) -> np.ndarray:
    arr = np.asarray(values if values is not None else (), dtype=np.float64).reshape(-1)
    if arr.ndim != 1:
        raise ValueError(f"{what} must be a 1-D array")
    return np.ascontiguousarray(arr)


class BagWriter:
    """Write a rosbag2 bag (version 9, MCAP storage, ROS 2 Jazzy message definitions embedded).

    Use as a context manager; the bag is complete (MCAP index + ``metadata.yaml``) when the block
    exits normally. It is written in a hidden folder beside ``path`` and renamed into place when finished,
    so ``path`` holds either the previous bag or the whole new one, never a partial bag: if the block
    raises, the writer is aborted, the hidden folder removed and ``path`` left as it was.

    Example::

        with BagWriter("bags/demo") as bag:
            bag.write_joint_state("/joint_states", js)
            bag.write_wrench("/wrench", w)

    Args:
        path: Output folder; it gets ``<name>.mcap`` and ``metadata.yaml``. Must not exist, unless
            ``overwrite`` is true and it is a previous bag folder (only bag files inside).
        overwrite: Replace an existing bag folder.
        compress: zstd-compress MCAP chunks (smaller files; every MCAP reader supports it).

    Raises:
        BagError: The folder exists (and may not be overwritten) or cannot be created.
    """

    def __init__(self, path: str | Path, *, overwrite: bool = False, compress: bool = False) -> None:
        self.path = Path(path)
        self._overwrite = overwrite
        self._compress = compress
        self._writer: Writer | None = None
        self._staging: Path | None = None  # the hidden parent folder the bag is written in
        self._connections: dict[str, Connection] = {}
        self.counts: dict[str, int] = {}

    @property
    def typestore(self) -> Any:
        """The ROS 2 Jazzy typestore; build messages for :meth:`write_message` from ``typestore.types``."""
        return _TYPESTORE

    # -- lifecycle -------------------------------------------------------------------------------
    def open(self) -> BagWriter:
        """Create the folder and start the MCAP file (called by ``__enter__``).

        Returns:
            ``self``.

        Raises:
            BagError: The folder exists or cannot be created.
        """
        if self._writer is not None:
            raise BagError(f"bag writer for {str(self.path)!r} is already open")
        if self.path.exists():
            if not self._overwrite:
                raise BagError(f"bag {str(self.path)!r} exists already (pass overwrite=True to replace it)")
            if not _is_bag_folder(self.path):
                raise BagError(
                    f"refusing to overwrite {str(self.path)!r}: not a bag folder (only metadata.yaml and "
                    ".mcap/.db3 files may be inside)"
                )
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._staging = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.partial-", dir=self.path.parent))
            writer = Writer(self._staging / self.path.name, version=9, storage_plugin=StoragePlugin.MCAP)
            if self._compress:
                from rosbags.rosbag2 import CompressionFormat, CompressionMode

                writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            writer.open()
        except Exception as err:
            self._remove_staging()
            raise BagError(f"cannot create bag {str(self.path)!r}: {err}") from err
        self._writer = writer
        return self

    def close(self) -> None:
        """Finish the bag: write the MCAP summary and ``metadata.yaml``.

        Raises:
            BagError: Writing the summary failed.
        """
        writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            writer.close()
            assert self._staging is not None  # set by open
            previous = None
            if self.path.exists():  # a previous bag folder (checked by open): set aside only now
                previous = self._staging / ".previous"
                os.replace(self.path, previous)
            try:
                os.replace(self._staging / self.path.name, self.path)
            except OSError:
                if previous is not None:  # put the previous bag back
                    os.replace(previous, self.path)
                raise
        except Exception as err:
            raise BagError(f"cannot finish bag {str(self.path)!r}: {err}") from err
        finally:
            self._remove_staging()

    def abort(self) -> None:
        """Stop writing without finishing the bag (no index, no ``metadata.yaml``)."""
        writer, self._writer = self._writer, None
        try:
            if writer is not None:
                writer.abort()
        finally:
            self._remove_staging()

    def _remove_staging(self) -> None:
        staging, self._staging = self._staging, None
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)

    def __enter__(self) -> BagWriter:
        return self.open()

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # -- writing ---------------------------------------------------------------------------------
    def _connection(self, topic: str, msgtype: str) -> Connection:
        if self._writer is None:
            raise BagError(f"bag writer for {str(self.path)!r} is not open (use it as a context manager)")
        conn = self._connections.get(topic)
        if conn is None:
            try:
                conn = self._writer.add_connection(topic, msgtype, typestore=_TYPESTORE)
            except Exception as err:
                raise BagError(
                    f"bag {str(self.path)!r}: cannot add topic {topic!r} ({msgtype}): {err}"
                ) from err
            self._connections[topic] = conn
            self.counts[topic] = 0
        elif conn.msgtype != msgtype:
            raise BagError(
                f"bag {str(self.path)!r}: topic {topic!r} already carries {conn.msgtype!r}, not {msgtype!r}"
            )
        return conn

    def write_message(self, topic: str, msgtype: str, msg: Any, *, log_time_ns: int) -> None:
        """Serialise and write any message of the Jazzy typestore.

        Args:
            topic: Topic name.
            msgtype: rosbags type name, e.g. ``"std_msgs/msg/Float64MultiArray"``.
            msg: A message object from ``self.typestore.types[msgtype]`` (``float64[]`` fields as
                numpy arrays).
            log_time_ns: Log (receive) time in ns, ≥ 0.

        Raises:
            BagError: Writer not open, or the topic already carries another type.
            ValueError: Negative log time or a message that cannot be serialised.
        """
        if int(log_time_ns) < 0:
            raise ValueError(f"log_time_ns must be >= 0, got {log_time_ns}")
        conn = self._connection(topic, msgtype)
        try:
            raw = _TYPESTORE.serialize_cdr(msg, msgtype)
        except Exception as err:
            raise ValueError(f"cannot serialise a {msgtype!r} message for {topic!r}: {err}") from err
        assert self._writer is not None
        self._writer.write(conn, int(log_time_ns), raw)
        self.counts[topic] += 1

    @staticmethod
    def _header(stamp_ns: int, frame_id: str = "") -> Any:
        types = _TYPESTORE.types
        sec, nanosec = ns_to_stamp(stamp_ns)
        return types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame_id
        )

    def write_joint_state(self, topic: str, msg: JointStateData, *, log_time_ns: int | None = None) -> None:
        """Write a ``sensor_msgs/msg/JointState``.

        The content is written as given (mismatched lengths and NaN included), so that test bags can
        hold the faults a real robot may publish.

        Args:
            topic: Topic name, e.g. ``"/joint_states"``.
            msg: The joint state (rad, rad/s, N·m).
            log_time_ns: Log time in ns (default: the header stamp).
        """
        ros_msg = _TYPESTORE.types[JOINT_STATE_TYPE](
            header=self._header(msg.stamp_ns),
            name=list(msg.names),
            position=_float_array(msg.position, "position"),
            velocity=_float_array(msg.velocity, "velocity"),
            effort=_float_array(msg.effort, "effort"),
        )
        self.write_message(
            topic, JOINT_STATE_TYPE, ros_msg, log_time_ns=msg.stamp_ns if log_time_ns is None else log_time_ns
        )

    def write_wrench(self, topic: str, msg: WrenchData, *, log_time_ns: int | None = None) -> None:
        """Write a ``geometry_msgs/msg/WrenchStamped``.

        Args:
            topic: Topic name, e.g. ``"/wrench"``.
            msg: The wrench (N, N·m) in frame ``msg.frame_id``.
            log_time_ns: Log time in ns (default: the header stamp).

        Raises:
            ValueError: Force or torque is not of length 3.
        """
        types = _TYPESTORE.types
        force, torque = _float_array(msg.force, "force"), _float_array(msg.torque, "torque")
        if force.shape != (3,) or torque.shape != (3,):
            raise ValueError(f"force and torque must have 3 components, got {force.shape} and {torque.shape}")
        vec = types["geometry_msgs/msg/Vector3"]
        ros_msg = types[WRENCH_STAMPED_TYPE](
            header=self._header(msg.stamp_ns, msg.frame_id),
            wrench=types["geometry_msgs/msg/Wrench"](
                force=vec(x=float(force[0]), y=float(force[1]), z=float(force[2])),
                torque=vec(x=float(torque[0]), y=float(torque[1]), z=float(torque[2])),
            ),
        )
        self.write_message(
            topic,
            WRENCH_STAMPED_TYPE,
            ros_msg,
            log_time_ns=msg.stamp_ns if log_time_ns is None else log_time_ns,
        )

    def write_joint_trajectory_point(
        self,
        topic: str,
        stamp_ns: int,
        names: Sequence[str],
        positions: object,
        velocities: object,
        accelerations: object,
        effort: object = None,
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """Write a ``trajectory_msgs/msg/JointTrajectory`` with a single point.

        Used for ground truth that ``JointState`` cannot carry, e.g. ``/ground_truth/joint_accelerations``
        (positions in rad, velocities in rad/s, accelerations in rad/s², effort in N·m). The point's
        ``time_from_start`` is zero; the header stamp is ``stamp_ns``.

        Args:
            topic: Topic name.
            stamp_ns: Header stamp in ns.
            names: Joint names.
            positions: Joint positions (rad) or empty.
            velocities: Joint velocities (rad/s) or empty.
            accelerations: Joint accelerations (rad/s²) or empty.
            effort: Joint efforts (N·m), optional.
            log_time_ns: Log time in ns (default: ``stamp_ns``).
        """
        types = _TYPESTORE.types
        point = types["trajectory_msgs/msg/JointTrajectoryPoint"](
            positions=_float_array(positions, "positions"),
            velocities=_float_array(velocities, "velocities"),
            accelerations=_float_array(accelerations, "accelerations"),
            effort=_float_array(effort, "effort"),
            time_from_start=types["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
        )
        ros_msg = types[JOINT_TRAJECTORY_TYPE](
            header=self._header(stamp_ns), joint_names=[str(n) for n in names], points=[point]
        )
        self.write_message(
            topic,
            JOINT_TRAJECTORY_TYPE,
            ros_msg,
            log_time_ns=stamp_ns if log_time_ns is None else log_time_ns,
        )
