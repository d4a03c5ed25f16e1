"""Replay a rosbag2/MCAP bag over DDS: the stored CDR bytes, in log-time order, at a chosen pace.

A small stand-in for ``ros2 bag play`` (not available without a ROS installation), used by the node
tests and the benchmark. Messages are read with :func:`semiparam_ros.io.bags.iter_raw` and published as
they are stored (``publisher.publish(bytes)``: no deserialisation), so what the node receives is
byte-for-byte what the bag holds.

Pace: by default the recorded pace (differences of log times), scaled by ``rate``; or, with ``hz``, one
log-time group (all messages recorded at the same log time, e.g. a joint state and a wrench) every
``1/hz`` seconds. A publisher that falls behind publishes at once (no catching-up sleep is skipped twice).
With ``publish_clock`` a ``rosgraph_msgs/Clock`` carrying the log time is published on ``/clock`` before
each group, for nodes running with ``use_sim_time``.

Publishers are reliable with a deep history, so a subscriber that asks for reliable delivery gets every
message; a best-effort subscriber (the estimator's default) is matched too.

Command line::

    python -m semiparam_ros.ros.bag_player BAG [--rate 1.0 | --hz 1000] [--clock] [--remap /a:=/b]
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from semiparam_ros.core.stream.messages import ns_to_stamp
from semiparam_ros.errors import BagError, ConfigurationError
from semiparam_ros.io.bags import iter_raw, topic_info

__all__ = ["PLAYER_QOS", "BagPlayer", "PlaybackReport", "RawMessage", "load_raw", "main", "message_class"]

#: Reliable, volatile, deep history: nothing is lost for a reliable subscriber that keeps up.
PLAYER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


@dataclass(frozen=True)
class RawMessage:
    """One stored message.

    Attributes:
        topic: Topic name in the bag.
        msgtype: Type name, e.g. ``sensor_msgs/msg/JointState``.
        log_time_ns: Log (record) time [ns].
        data: CDR bytes as stored.
    """

    topic: str
    msgtype: str
    log_time_ns: int
    data: bytes


@dataclass
class PlaybackReport:
    """What a playback did.

    Attributes:
        published: Messages published.
        wall_s: Wall time from the first to the last publish [s].
        publish_times: ``time.perf_counter()`` at each publish, in order (for latency measurements).
        late_s: Largest delay of a publish behind its schedule [s].
    """

    published: int = 0
    wall_s: float = 0.0
    publish_times: list[float] = field(default_factory=list)
    late_s: float = 0.0


def message_class(msgtype: str) -> type:
    """Return the rclpy message class of a type name.

    Args:
        msgtype: ``pkg/msg/Name`` (or ``pkg/Name``).

    Returns:
        The generated Python class.

    Raises:
        BagError: If the type name is malformed or its package is not installed.
    """
    parts = msgtype.split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts):
        raise BagError(f"malformed message type {msgtype!r}, expected pkg/msg/Name")
    try:
        return getattr(importlib.import_module(f"{parts[0]}.{parts[1]}"), parts[2])
    except (ImportError, AttributeError) as err:
        raise BagError(f"message type {msgtype!r} is not available: {err}") from err


def load_raw(path: str | Path, topics: Iterable[str] | None = None, *, limit: int | None = None,
             start_ns: int | None = None, end_ns: int | None = None) -> list[RawMessage]:
    """Read a bag's serialised messages into memory (so reading never disturbs the playback pace).

    Args:
        path: Bag folder or ``.mcap`` file.
        topics: Topics to read; all topics when None.
        limit: Keep at most this many messages (a prefix in log-time order).
        start_ns: Skip messages logged before this time [ns].
        end_ns: Stop at messages logged at or after this time [ns].

    Returns:
        The messages in log-time order.

    Raises:
        BagError: If the bag cannot be read or a topic is missing.
    """
    wanted = list(topics) if topics is not None else sorted(topic_info(path))
    out: list[RawMessage] = []
    for topic, msgtype, log_time, raw in iter_raw(path, wanted):
        if start_ns is not None and log_time < start_ns:
            continue
        if end_ns is not None and log_time >= end_ns:
            break
        out.append(RawMessage(topic, msgtype, log_time, raw))
        if limit is not None and len(out) >= limit:
            break
    return out


class BagPlayer:
    """Publish stored messages with an existing node.

    Args:
        node: Node that owns the publishers.
        messages: Messages to play, in log-time order.
        remap: Bag topic → published topic (unlisted topics keep their name).
        qos: QoS of the publishers.
        publish_clock: Also publish the log time on ``/clock``.
    """

    def __init__(self, node: Node, messages: Sequence[RawMessage], *, remap: Mapping[str, str] | None = None,
                 qos: QoSProfile = PLAYER_QOS, publish_clock: bool = False) -> None:
        self.node = node
        self.messages = list(messages)
        remap = dict(remap or {})
        self._publishers: dict[str, Publisher] = {}
        for msg in self.messages:
            if msg.topic not in self._publishers:
                self._publishers[msg.topic] = node.create_publisher(
                    message_class(msg.msgtype), remap.get(msg.topic, msg.topic), qos)
        self._clock_pub = node.create_publisher(Clock, "/clock", 10) if publish_clock else None

    @property
    def publishers(self) -> dict[str, Publisher]:
        """Bag topic → publisher."""
        return dict(self._publishers)

    def wait_for_subscribers(self, timeout: float = 10.0, count: int = 1,
                             spin: Callable[[], None] | None = None) -> bool:
        """Wait until every publisher is matched by at least ``count`` subscriptions.

        Args:
            timeout: Seconds to wait.
            count: Required subscription count per topic.
            spin: Called while waiting (e.g. to spin an executor); sleeps 10 ms otherwise.

        Returns:
            Whether all publishers were matched in time.
        """
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if all(p.get_subscription_count() >= count for p in self._publishers.values()):
                return True
            if spin is not None:
                spin()
            time.sleep(0.01)
        return False

    def _groups(self) -> list[list[RawMessage]]:
        groups: list[list[RawMessage]] = []
        for msg in self.messages:
            if groups and groups[-1][0].log_time_ns == msg.log_time_ns:
                groups[-1].append(msg)
            else:
                groups.append([msg])
        return groups

    def play(self, *, rate: float = 1.0, hz: float | None = None,
             should_stop: Callable[[], bool] | None = None) -> PlaybackReport:
        """Publish every message at the recorded pace (times ``rate``) or one log-time group per ``1/hz``.

        Args:
            rate: Speed factor on the recorded pace (2 = twice as fast); ignored when ``hz`` is given.
            hz: Groups per second, regardless of the recorded pace.
            should_stop: Polled between groups; playback stops when it returns true.

        Returns:
            Counts and timing of the playback.

        Raises:
            ConfigurationError: If ``rate`` or ``hz`` is not positive.
        """
        if hz is not None and not hz > 0:
            raise ConfigurationError(f"hz must be > 0, got {hz}")
        if not rate > 0:
            raise ConfigurationError(f"rate must be > 0, got {rate}")
        report = PlaybackReport()
        groups = self._groups()
        if not groups:
            return report
        t0_log = groups[0][0].log_time_ns
        start = time.perf_counter()
        for index, group in enumerate(groups):
            if should_stop is not None and should_stop():
                break
            offset = index / hz if hz is not None else (group[0].log_time_ns - t0_log) * 1e-9 / rate
            target = start + offset
            delay = target - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            else:
                report.late_s = max(report.late_s, -delay)
            if self._clock_pub is not None:
                sec, nanosec = ns_to_stamp(group[0].log_time_ns)
                clock = Clock()
                clock.clock.sec, clock.clock.nanosec = sec, nanosec
                self._clock_pub.publish(clock)
            for msg in group:
                self._publishers[msg.topic].publish(msg.data)
                report.publish_times.append(time.perf_counter())
                report.published += 1
        report.wall_s = report.publish_times[-1] - report.publish_times[0] if report.publish_times else 0.0
        return report


def _parse(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="bag_player", description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", type=Path, help="bag folder or .mcap file")
    parser.add_argument("--topics", nargs="*", default=None, help="topics to play (default: all)")
    parser.add_argument("--rate", type=float, default=1.0, help="speed factor on the recorded pace")
    parser.add_argument("--hz", type=float, default=None, help="play log-time groups at this rate instead")
    parser.add_argument("--clock", action="store_true", help="publish the log time on /clock")
    parser.add_argument("--remap", nargs="*", default=[], metavar="FROM:=TO", help="rename topics")
    parser.add_argument("--wait", type=float, default=10.0, help="seconds to wait for subscribers")
    return parser.parse_args(argv)


def main(args: list[str] | None = None) -> int:
    """Play a bag from the command line (ROS arguments after ``--ros-args`` are passed to rclpy).

    Args:
        args: Command line; ``sys.argv`` when None.

    Returns:
        Exit code (0 on success, 1 if no subscriber matched in time, 2 on a bad bag or argument).
    """
    argv = list(sys.argv if args is None else args)
    plain = rclpy.utilities.remove_ros_args(argv)[1:]
    ns = _parse(plain)
    remap = {}
    for item in ns.remap:
        if ":=" not in item:
            print(f"bag_player: --remap expects FROM:=TO, got {item!r}", file=sys.stderr)
            return 2
        src, dst = item.split(":=", 1)
        remap[src] = dst
    try:
        messages = load_raw(ns.bag, ns.topics)
    except BagError as err:
        print(f"bag_player: {err}", file=sys.stderr)
        return 2
    rclpy.init(args=argv)
    node = Node("bag_player")
    code = 0
    try:
        player = BagPlayer(node, messages, remap=remap, publish_clock=ns.clock)
        if not player.wait_for_subscribers(ns.wait):
            node.get_logger().warning("not every topic has a subscriber; playing anyway")
            code = 1
        report = player.play(rate=ns.rate, hz=ns.hz)
        node.get_logger().info(f"published {report.published} messages in {report.wall_s:.3f} s "
                               f"(largest lag {1e3 * report.late_s:.1f} ms)")
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
