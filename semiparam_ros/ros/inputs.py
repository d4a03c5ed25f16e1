"""The node's inputs: serialised subscriptions, their conversion into the learning loop, counted losses.

Sensor-data QoS (best effort, volatile) with a history of 100, overridable with the standard QoS overrides
(``-p qos_overrides./joint_states.subscription.reliability:=reliable``). Messages are taken serialised and
read by :func:`~semiparam_ros.ros.conversions.joint_state_from_cdr` / ``wrench_from_cdr``; a message the
conversion refuses, a full queue and messages lost inside DDS are counted drops, logged at most every 5 s.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from typing import Any

from geometry_msgs.msg import WrenchStamped
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState

from semiparam_ros.core.kinds import InputKind
from semiparam_ros.core.stream.pipeline import DROP_ACCELERATION_WARMUP
from semiparam_ros.errors import RejectedSampleError
from semiparam_ros.ros import conversions as cv
from semiparam_ros.ros.diagnostics import NodeStatistics
from semiparam_ros.serving.learning_loop import LearningLoop

__all__ = ["EXPECTED_DROPS", "GONE", "INPUT_QOS", "MAX_DRAIN", "SILENCE_S", "DropReporter", "InputStreams",
           "ThrottledWarnings", "take"]

#: The ROS message type of each input stream.
_MESSAGE_TYPES: dict[InputKind, Any] = {InputKind.JOINT_STATES: JointState, InputKind.WRENCH: WrenchStamped}

#: Sensor-data QoS of the inputs (best effort, volatile), with a deeper history than the default 5.
INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE)
MAX_DRAIN = 64  # messages taken per subscription callback at most (bounds the executor's time away)
_MIN_NAME_BOUND = 1024
_MAX_LOST_PER_EVENT = 100_000  # a larger lost-message count in one event is a middleware counter glitch
#: An input stream silent this long [s] (since start-up or its last message) is named on the console.
SILENCE_S = 3.0
#: What :func:`take` returns for a subscription being destroyed.
GONE: Any = object()


class ThrottledWarnings:
    """Log a warning at most every ``period_s`` per key; the text is built only when logged.

    rclpy's own ``throttle_duration_sec`` inspects the caller's frame on every call, logged or not
    (≈ 0.35 ms): at 1 kHz of bad input that alone would stall the node.
    """

    def __init__(self, logger: Any, period_s: float = 5.0) -> None:
        self._logger = logger
        self._period_s = period_s
        self._last: dict[str, float] = {}

    def __call__(self, key: str, text: str | Callable[[], str], *, once: bool = False) -> None:
        """Warn under ``key`` unless it was logged less than a period ago (``once``: ever before)."""
        now = time.monotonic()
        last = self._last.get(key, -math.inf)
        if now - last < self._period_s or (once and last > -math.inf):
            return
        self._last[key] = now
        self._logger.warning(text() if callable(text) else text)


#: Drops that every start, restart or gap of the stream brings (logged once, at INFO).
EXPECTED_DROPS = frozenset({DROP_ACCELERATION_WARMUP})


class DropReporter:
    """Say on the console why input is dropped: every reason at least once, each throttled on its own.

    Args:
        logger: The node's logger (INFO for the expected drops).
        warn: Throttled warnings (one key per reason).
    """

    def __init__(self, logger: Any, warn: ThrottledWarnings) -> None:
        self._logger, self._warn = logger, warn
        self._seen: dict[str, int] = {}

    def report(self, drops: Mapping[str, int]) -> list[str]:
        """Log the reasons whose counts grew since the last call; return them (for tests)."""
        grown = []
        for reason, count in drops.items():
            seen = self._seen.get(reason, 0)
            self._seen[reason] = count  # a reset zeroes the counts: they grow again from there
            if count <= seen:
                continue
            grown.append(reason)
            if reason in EXPECTED_DROPS:
                if seen == 0:
                    self._logger.info(f"{count} joint states waited for the acceleration estimate's window "
                                      "(expected at start-up and after a gap: drops.acceleration_warmup)")
                continue
            nonzero = ", ".join(f"{k} {v}" for k, v in drops.items() if v)
            self._warn(f"drop {reason}", f"input dropped: {reason} ({count} so far; /diagnostics "
                                         f"drops.{reason}); every non-zero count: {nonzero}")
        return grown


def take(sub: Any) -> Any:
    """Take one waiting message of a subscription as the executor does.

    Returns:
        The message, None when none waits, :data:`GONE` when the subscription is being destroyed. Not
        public rclpy API (see :meth:`InputStreams.drain`).
    """
    try:
        with sub.handle:
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
    except Exception:
        return GONE
    return None if taken is None else taken[0]


class InputStreams:
    """Subscribe to the input streams and feed them, converted, to a :class:`LearningLoop`.

    Args:
        node: The node subscribing.
        topics: Topic per input kind subscribed to (joint states, and wrenches for an F/T sensor).
        callbacks: The subscription callback per kind (the node's: it decides when to run the loop).
        loop: The learning loop the converted inputs are queued in.
        stats: Counts inputs and drops.
        warn: Throttled warnings.
        n_joints: Joints of the robot (a JointState listing far more names is refused undecoded).
    """

    def __init__(self, node: Node, topics: dict[InputKind, str],
                 callbacks: dict[InputKind, Callable[[bytes], None]], *,
                 loop: LearningLoop, stats: NodeStatistics, warn: ThrottledWarnings, n_joints: int) -> None:
        self._node, self._loop, self._stats, self._warn = node, loop, stats, warn
        self._max_names = max(_MIN_NAME_BOUND, 16 * n_joints)
        overrides = QoSOverridingOptions.with_default_policies()
        self.subscriptions: dict[InputKind, Any] = {}
        for kind, topic in topics.items():
            msg_type = _MESSAGE_TYPES[kind]
            events = SubscriptionEventCallbacks(incompatible_qos=self._incompatible_qos_logger(topic),
                                                message_lost=self.lost_counter(topic),
                                                use_default_callbacks=False)
            self.subscriptions[kind] = node.create_subscription(
                msg_type, topic, callbacks[kind], INPUT_QOS, qos_overriding_options=overrides,
                event_callbacks=events, raw=True)
        #: Messages received per stream at the last :meth:`check_silence`, and when that count last changed.
        self._heard = {kind: (0, time.monotonic()) for kind in self.subscriptions}
        self._silent: set[InputKind] = set()  # streams named silent since their last message
        # the other stream first: the callback just took one of its own kind (see drain)
        subs = self.subscriptions
        self._order = {own: (*((k, subs[k]) for k in subs if k != own), (own, subs[own])) for own in subs}

    def check_silence(self, received: dict[InputKind, int], now: float | None = None) -> list[str]:
        """Warn once per silence about a stream that received nothing for :data:`SILENCE_S` seconds.

        The warning names the topic as resolved and the topics of that message type the graph knows of
        (the usual cause: the robot publishes elsewhere, e.g. ``/robot/joint_states``); a stream that
        speaks again is watched afresh.

        Args:
            received: Messages received so far per stream (the node's statistics).
            now: Monotonic time [s] (default: now).

        Returns:
            The warnings logged (for tests; empty when every stream speaks).
        """
        now = time.monotonic() if now is None else now
        logged = []
        for kind in self.subscriptions:
            count = received.get(kind, 0)
            last_count, since = self._heard[kind]
            if count != last_count:
                self._heard[kind] = (count, now)
                self._silent.discard(kind)
                continue
            if kind in self._silent or now - since < SILENCE_S:
                continue
            self._silent.add(kind)
            text = self.silence_message(kind, now - since, count)
            self._node.get_logger().warning(text)
            logged.append(text)
        return logged

    def silence_message(self, kind: InputKind, silent_s: float, count: int) -> str:
        """Say that a stream is silent, and which topics of its type exist (the graph, now)."""
        topic = self._node.resolve_topic_name(self.subscriptions[kind].topic_name)
        msg_type = _MESSAGE_TYPES[kind]  # as the graph names it: sensor_msgs/msg/JointState
        type_name = f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"
        own, graph = self._node.get_name(), self._node
        others = sorted(name for name, types in graph.get_topic_names_and_types()
                        if type_name in types and name != topic  # the node's own outputs are no candidates
                        and any(info.node_name != own for info in graph.get_publishers_info_by_topic(name)))
        where = (f"topics of that type with publishers: {', '.join(others)}" if others
                 else "no other topic of that type has a publisher")
        since = "since start-up" if count == 0 else "since the last one"
        return (f"no {type_name} on {topic} for {silent_s:.0f} s ({since}); {where}; set "
                f"{kind.topic_parameter} (or remap) to the robot's topic")

    def intake(self, kind: InputKind, msg: bytes | Any) -> None:
        """Convert one input (serialised, as the subscriptions deliver it, or a message object); queue it."""
        self._stats.count_input(kind)
        try:
            if isinstance(msg, bytes):
                data = (cv.joint_state_from_cdr(msg, self._max_names) if kind == InputKind.JOINT_STATES
                        else cv.wrench_from_cdr(msg))
            else:
                data = (cv.joint_state_from_msg(msg) if kind == InputKind.JOINT_STATES
                        else cv.wrench_from_msg(msg))
        except RejectedSampleError as err:  # a message the conversion refuses: a counted drop
            self._stats.count_drop("conversion_error")
            text = str(err)
            self._warn(f"convert {kind}", lambda: f"cannot convert a {kind} message: {text}")
            return
        if self._loop.enqueue(kind, data):
            self._stats.count_drop("queue_full")
            self._warn("queue_full",
                       "input queue full: dropping the oldest message (learning cannot keep up)")

    def drain(self, kind: InputKind) -> None:
        """Take the messages already waiting on both subscriptions without another executor wait.

        The executor takes one message per subscription per wait, and building its wait set costs far more
        than taking a message. The two subscriptions are taken alternately (the other one first: the
        callback just took one of ``kind``), at most :data:`MAX_DRAIN` rounds, so neither stream runs
        ahead of the other by more than one message (a joint-state stream far ahead would outrun the
        pipeline's pairing buffer). Not public rclpy API: Jazzy has no public take, so this makes the call
        the executor makes; measured ≈ 8× cheaper per queued message than an executor wait each
        (bench/node/bench_drain.py); test/ros/test_node_drain.py fails if the call changes.
        """
        order = self._order[kind]
        for _ in range(MAX_DRAIN):
            took = False
            for sub_kind, sub in order:
                taken = take(sub)
                if taken is GONE:
                    return
                if taken is not None:
                    took = True
                    self.intake(sub_kind, taken)
            if not took:
                return

    def _incompatible_qos_logger(self, topic: str) -> Callable[[Any], None]:
        def warn(event: Any) -> None:
            self._node.get_logger().warning(
                f"a publisher on {self._node.resolve_topic_name(topic)} offers an incompatible QoS "
                f"({event.last_policy_kind}); its messages will not be received")

        return warn

    def lost_counter(self, topic: str) -> Callable[[Any], None]:
        """Return the message-lost event handler of ``topic``: counts (``dds_message_lost``) and warns."""
        last = [0]  # the middleware's running total at the last event

        def count(event: Any) -> None:
            # a running total, taken as a delta and checked (one oversized message made Fast DDS report a
            # change of 2**31, a wrapped 32-bit counter): a loss can never exceed the messages sent
            total = int(event.total_count)
            delta, last[0] = total - last[0], max(last[0], total)
            name = self._node.resolve_topic_name(topic)
            if not 0 <= delta <= _MAX_LOST_PER_EVENT:
                self._warn(f"lost count {topic}", lambda: (
                    f"the middleware reported an implausible lost-message count on {name} (total {total}, "
                    f"change {delta}): counted as 1"))
                delta = 1
            self._stats.count_drop("dds_message_lost", delta)
            self._warn(f"lost {topic}", lambda: (
                f"{delta} messages on {name} were lost in the middleware (history overflow: the node is not "
                "taking them fast enough)"))

        return count
