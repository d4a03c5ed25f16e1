"""From JointState / WrenchStamped messages to learning samples — one path for the node and for replay.

:class:`SamplePipeline` receives messages in arrival order (live callbacks, or a bag in log-time order)
and returns the :class:`~semiparam_ros.core.stream.messages.Sample` objects they complete:

1. **Screening.** Every message is checked before it touches any state; a bad one is dropped and
   counted once, under the first failing reason in this order: stamp (zero/negative, backwards,
   repeated — per stream), structure (array lengths vs names, duplicate names, missing configured
   joints, wrong frame id), values (NaN/inf in the fields that are used), plausibility (a finite value
   beyond the configured bound: ``max_abs_position`` rad, ``max_abs_velocity`` rad/s,
   ``max_abs_output`` N / N·m for the wrench or the learned efforts — e.g. a 1e10 rad/s velocity that
   would poison the q̈ window). Only the configured joints are checked and used: extra joints, in any
   order, are ignored, so a NaN effort of an unused joint (or any effort when learning a wrench) does
   not drop a message. Last, **glitches** (:mod:`semiparam_ros.core.stream.glitch`): a joint state whose
   position or velocity increment (on a configured joint) exceeds ``glitch_ratio`` times that signal's
   running mean increment (memory ``glitch_time_constant`` s) or resolution (its smallest non-zero
   increment: quantized encoders) is held until the next joint state; if that one comes back, the held
   state was a one-sample outlier inside the bounds — a 99 rad/s velocity spike would otherwise enter
   ``window`` q̈ estimates and show as a contact on as many outputs — and is dropped; if it goes on (a
   start from rest, a fast move, a step that stays) the held state is accepted, one joint state late.
   The ratio is dimensionless and rate-independent. Efforts are not checked: a contact changes a torque
   abruptly, which no causal check tells from a glitch.
2. **Acceleration.** Accepted joint velocities feed the estimator of
   :mod:`semiparam_ros.core.stream.acceleration`, which decides each joint-state stamp once: q̈ (rad/s²) or
   none (warm-up). With the default Savitzky–Golay estimator the decision comes ``window // 2`` joint
   states later and refers to the older stamp, so joint states are buffered until decided.
3. **Pairing** (``output=OutputKind.WRENCH``). A wrench waits (bounded) until its pairing is final — every
   joint state within ``sync_tolerance`` of its stamp decided, or a decided one so close that no later
   joint state can be closer — then pairs with the nearest one that has q̈ (the earlier on a tie). The
   sample carries the **wrench** stamp, q and q̇ of that joint state as received, and its q̈. The
   learning rate is thus the wrench rate (e.g. joint states at 100 Hz, wrench at 10 Hz → 10 samples/s).
   With ``output=OutputKind.JOINT_TORQUES`` every decided joint state gives a sample whose output is
   ``JointState.effort`` (N·m) of the configured joints; wrenches are ignored (counted).

Cost: O(1) per message (bounded buffers, an O(window) acceleration estimate); measured by
``bench/stream/bench_pipeline.py`` (``bench/results/bench_pipeline.json``).

Drops never raise. Memory is bounded: joint states are kept for ``buffer_s`` seconds (and at most
``max_buffer`` of them), pending wrenches at most ``max_buffer``.

If one stream's stamps go backwards ``restart_after`` times in a row (a robot restart, ``ros2 bag play
--loop``), the pipeline treats it as a clock restart: those messages stay counted as dropped, the
buffers and the estimator are cleared (counts kept) and ``n_restarts`` is incremented, so the
pipeline recovers instead of dropping everything until the old stamps are passed.
"""

from __future__ import annotations

import math
import sys
from collections import deque
from collections.abc import Sequence

import numpy as np
from numba import njit

from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.core.stream.acceleration import AccelerationConfig, AccelerationEstimator, make_estimator
from semiparam_ros.core.stream.glitch import ACCEPT_SUSPECT, SUSPECT, GlitchCheck
from semiparam_ros.core.stream.messages import InputMessage, JointStateData, Sample, WrenchData
from semiparam_ros.core.validation import check_range
from semiparam_ros.errors import ConfigurationError

__all__ = [
    "DROP_ACCELERATION_WARMUP",
    "DROP_BUFFER_OVERFLOW",
    "DROP_DUPLICATE_JOINT",
    "DROP_GLITCH",
    "DROP_IMPLAUSIBLE_VALUE",
    "DROP_JOINT_STATE_BACKWARDS_STAMP",
    "DROP_JOINT_STATE_REPEATED_STAMP",
    "DROP_JOINT_STATE_ZERO_STAMP",
    "DROP_LENGTH_MISMATCH",
    "DROP_MISSING_JOINT",
    "DROP_NONFINITE_JOINT_STATE",
    "DROP_NONFINITE_WRENCH",
    "DROP_REASONS",
    "DROP_UNPAIRED_WRENCH",
    "DROP_WRENCH_BACKWARDS_STAMP",
    "DROP_WRENCH_IGNORED",
    "DROP_WRENCH_REPEATED_STAMP",
    "DROP_WRENCH_ZERO_STAMP",
    "DROP_WRONG_FRAME_ID",
    "SamplePipeline",
]


# -- drop reasons (stable names: they appear in diagnostics and in evaluation reports) ---------------
DROP_JOINT_STATE_ZERO_STAMP = "joint_state_zero_stamp"
"""JointState with a zero (or negative) header stamp, i.e. never stamped."""
DROP_JOINT_STATE_BACKWARDS_STAMP = "joint_state_backwards_stamp"
"""JointState stamped before the last accepted joint state."""
DROP_JOINT_STATE_REPEATED_STAMP = "joint_state_repeated_stamp"
"""JointState with the same stamp as the last accepted joint state."""
DROP_LENGTH_MISMATCH = "length_mismatch"
"""Arrays whose length differs from the names (position, velocity; effort when learning torques), or a
wrench whose force/torque is not 3 long."""
DROP_DUPLICATE_JOINT = "duplicate_joint"
"""JointState listing a joint name twice."""
DROP_MISSING_JOINT = "missing_joint"
"""JointState without one of the configured joints."""
DROP_NONFINITE_JOINT_STATE = "nonfinite_joint_state"
"""NaN/inf in a used value: position or velocity of a configured joint (or its effort for torques)."""
DROP_WRENCH_ZERO_STAMP = "wrench_zero_stamp"
"""WrenchStamped with a zero (or negative) header stamp."""
DROP_WRENCH_BACKWARDS_STAMP = "wrench_backwards_stamp"
"""WrenchStamped stamped before the last accepted wrench."""
DROP_WRENCH_REPEATED_STAMP = "wrench_repeated_stamp"
"""WrenchStamped with the same stamp as the last accepted wrench."""
DROP_WRONG_FRAME_ID = "wrong_frame_id"
"""WrenchStamped whose frame id is not the configured sensor frame."""
DROP_NONFINITE_WRENCH = "nonfinite_wrench"
"""NaN/inf in force or torque."""
DROP_IMPLAUSIBLE_VALUE = "implausible_value"
"""A finite but physically impossible value in a used field: |q| > ``max_abs_position`` (rad),
|q̇| > ``max_abs_velocity`` (rad/s) of a configured joint, a wrench component (or a learned effort)
beyond ``max_abs_output`` (N, N·m). Either stream."""
DROP_UNPAIRED_WRENCH = "unpaired_wrench"
"""Accepted wrench with no accepted joint state within ``sync_tolerance``."""
DROP_ACCELERATION_WARMUP = "acceleration_warmup"
"""Sample lost because the matching joint state(s) got no q̈ (estimator warm-up after a start, restart
or gap): counts wrenches for a wrench output, joint states for joint torques."""
DROP_BUFFER_OVERFLOW = "buffer_overflow"
"""Pending wrench discarded because ``max_buffer`` wrenches were waiting (joint states stopped)."""
DROP_WRENCH_IGNORED = "wrench_ignored"
"""Wrench received while learning joint torques (not used)."""
DROP_GLITCH = "glitch"
"""JointState whose position or velocity jumped ``glitch_ratio`` times beyond its running mean increment
and resolution, and the next state came back: a one-sample outlier inside the plausibility bounds
(:mod:`semiparam_ros.core.stream.glitch`)."""

DROP_REASONS = (
    DROP_JOINT_STATE_ZERO_STAMP,
    DROP_JOINT_STATE_BACKWARDS_STAMP,
    DROP_JOINT_STATE_REPEATED_STAMP,
    DROP_LENGTH_MISMATCH,
    DROP_DUPLICATE_JOINT,
    DROP_MISSING_JOINT,
    DROP_NONFINITE_JOINT_STATE,
    DROP_WRENCH_ZERO_STAMP,
    DROP_WRENCH_BACKWARDS_STAMP,
    DROP_WRENCH_REPEATED_STAMP,
    DROP_WRONG_FRAME_ID,
    DROP_NONFINITE_WRENCH,
    DROP_IMPLAUSIBLE_VALUE,
    DROP_UNPAIRED_WRENCH,
    DROP_ACCELERATION_WARMUP,
    DROP_BUFFER_OVERFLOW,
    DROP_WRENCH_IGNORED,
    DROP_GLITCH,
)
"""Every key of :attr:`SamplePipeline.drops`, in screening order."""

_NAME_CACHE_SIZE = 16
_NAME_CACHE_BYTES = 1 << 20  # the name cache holds at most about this much name text (bounded memory)
_NO_BOUND = sys.float_info.max  # "no bound": still rejects inf (and NaN) in the one-pass check
@njit(cache=True, nogil=True)
def _within(values: np.ndarray, bound: float) -> bool:
    """Return whether every ``|v| ≤ bound`` (NaN fails, inf fails a finite bound), in one pass."""
    for v in values:
        if not abs(v) <= bound:
            return False
    return True


def _bound(name: str, value: float | None) -> float:
    """Validate a plausibility bound (> 0; ``None`` or ``inf`` = none) and return it as a float."""
    if value is None or value == math.inf:
        return _NO_BOUND
    return check_range(f"{name} (or None for no bound)", value, 0.0, lo_inclusive=False)


class _JointEntry:
    """An accepted joint state of the configured joints, waiting for its q̈ decision / for wrenches."""

    __slots__ = ("ddq", "decided", "dq", "effort", "q", "stamp")

    def __init__(self, stamp: int, q: np.ndarray, dq: np.ndarray, effort: np.ndarray | None) -> None:
        self.stamp = stamp
        self.q = q
        self.dq = dq
        self.effort = effort
        self.ddq: np.ndarray | None = None
        self.decided = False


class SamplePipeline:
    """Turn JointState and WrenchStamped messages into learning samples (see the module docstring).

    Args:
        joints: Configured joint names; samples use this order (``x = [q, q̇, q̈]``).
        output: An :class:`~semiparam_ros.core.kinds.OutputKind` (or its value): the wrench (paired with
            WrenchStamped) or the joint torques (JointState.effort).
        frame_id: Required wrench frame id; ``None`` or ``""`` accepts any.
        sync_tolerance: Largest |wrench stamp − joint-state stamp| for a pair (s, ≥ 0).
        acceleration: q̈ estimator settings (default ``AccelerationConfig()``: Savitzky–Golay, window 9,
            polyorder 2).
        buffer_s: How long accepted joint states are kept for pairing with late wrenches (s, > 0).
        max_buffer: Hard cap on buffered joint states and on pending wrenches (≥ 1).
        restart_after: Consecutive backwards stamps on one stream taken as a clock restart (≥ 1).
        max_abs_position: Largest plausible |q| of a configured joint (rad, > 0); ``None`` = no bound
            (e.g. for unwrapped continuous joints).
        max_abs_velocity: Largest plausible |q̇| of a configured joint (rad/s, > 0); ``None`` = no bound.
        max_abs_output: Largest plausible |component| of the wrench (N, N·m), or of a configured joint's
            effort when learning ``joint_torques`` (N·m); ``None`` = no bound.
        glitch_ratio: Increment ratio beyond which a joint state is a glitch (> 0; ``None`` or 0 = no
            glitch check).
        glitch_time_constant: Memory of the running mean increments (s, > 0).
        effort_scale: N·m per reported effort unit, one per joint of ``joints`` (finite, non-zero),
            multiplying ``JointState.effort`` before anything else reads it (a driver reporting motor
            currents); ``None`` = efforts are N·m.

    Attributes:
        drops: Reason → count, every reason of :data:`DROP_REASONS` present (zeros included).
        n_samples: Samples emitted.
        n_restarts: Clock restarts detected.

    Raises:
        ConfigurationError: Invalid settings.

    Example:
        >>> from semiparam_ros.core.stream.messages import JointStateData
        >>> pipe = SamplePipeline(["elbow"], output=OutputKind.JOINT_TORQUES)
        >>> samples = []
        >>> for k in range(20):  # 100 Hz, q = t²/2 rad: q̇ = t rad/s, q̈ = 1 rad/s²
        ...     t = 0.01 * k
        ...     msg = JointStateData(10**9 + 10**7 * k, ("elbow",), [0.5 * t * t], [t], [2.0])
        ...     samples += pipe.add(msg)
        >>> len(samples), pipe.drops["acceleration_warmup"]  # the rest wait for the centred window
        (12, 4)
        >>> samples[0].ddq, samples[0].y
        (array([1.]), array([2.]))
    """

    def __init__(
        self,
        joints: Sequence[str],
        *,
        output: OutputKind | str = OutputKind.WRENCH,
        frame_id: str | None = None,
        sync_tolerance: float = 0.005,
        acceleration: AccelerationConfig | None = None,
        buffer_s: float = 1.0,
        max_buffer: int = 4096,
        restart_after: int = 50,
        max_abs_position: float | None = 100.0,
        max_abs_velocity: float | None = 100.0,
        max_abs_output: float | None = 1e4,
        glitch_ratio: float | None = 50.0,
        glitch_time_constant: float = 0.05,
        effort_scale: Sequence[float] | None = None,
    ) -> None:
        if isinstance(joints, str):
            raise ConfigurationError("joints must be a sequence of joint names, not a single string")
        joints = tuple(str(j) for j in joints)
        if not joints:
            raise ConfigurationError("joints must name at least one joint")
        if len(set(joints)) != len(joints):
            raise ConfigurationError(f"joints must be unique, got {joints}")
        output = OutputKind.parse(output)
        self._effort_scale: np.ndarray | None = None
        if effort_scale is not None and len(effort_scale):
            scale = np.asarray(effort_scale, dtype=np.float64)
            if scale.shape != (len(joints),) or not np.isfinite(scale).all() or (scale == 0.0).any():
                raise ConfigurationError(f"effort_scale must hold one finite, non-zero value per joint "
                                         f"({len(joints)}), got {list(effort_scale)}")
            self._effort_scale = scale
        check_range("sync_tolerance (s)", sync_tolerance, 0.0)
        check_range("buffer_s (s)", buffer_s, 0.0, lo_inclusive=False)
        if int(max_buffer) < 1:
            raise ConfigurationError(f"max_buffer must be >= 1, got {max_buffer}")
        if int(restart_after) < 1:
            raise ConfigurationError(f"restart_after must be >= 1, got {restart_after}")
        if acceleration is not None and not isinstance(acceleration, AccelerationConfig):
            raise ConfigurationError(f"acceleration must be an AccelerationConfig, got "
                                     f"{type(acceleration).__name__}")
        self.joints: tuple[str, ...] = joints
        self.output = output
        self.frame_id = frame_id or None
        #: Frame of the newest wrench taken (the one its samples are expressed in; "" before any).
        self.last_frame_id = ""
        self.sync_tolerance = float(sync_tolerance)
        self.acceleration = acceleration or AccelerationConfig()
        self.buffer_s = float(buffer_s)
        self.max_buffer = int(max_buffer)
        self.restart_after = int(restart_after)
        self._max_q = _bound("max_abs_position", max_abs_position)
        self._max_dq = _bound("max_abs_velocity", max_abs_velocity)
        self._max_out = _bound("max_abs_output", max_abs_output)
        self._torques = output == OutputKind.JOINT_TORQUES
        check_range("glitch_time_constant (s)", glitch_time_constant, 0.0, lo_inclusive=False)
        self._glitch = None if not glitch_ratio else GlitchCheck(len(joints), ratio=glitch_ratio,
                                                                 time_constant_s=glitch_time_constant)
        frozen = np.zeros(3)
        frozen.flags.writeable = False
        _within(frozen, 1.0)  # compile/load both signatures (messages hold read-only arrays) up front
        _within(np.zeros(3), 1.0)
        self._tol_ns = round(self.sync_tolerance * 1e9)
        self._buffer_ns = round(self.buffer_s * 1e9)
        self._name_cache: dict[tuple[str, ...], np.ndarray | str] = {}
        self._name_cache_bytes = 0  # approximate content size of the cached name lists
        self.drops: dict[str, int] = dict.fromkeys(DROP_REASONS, 0)
        self.n_samples = 0
        self.n_restarts = 0  # clock restarts detected (restart_after backwards stamps in a row)
        self._estimator: AccelerationEstimator = make_estimator(len(joints), self.acceleration)
        self._clear_stream_state()

    # -- public state ----------------------------------------------------------------------------
    @property
    def acceleration_delay_s(self) -> float:
        """How far the q̈ information lags the newest joint state (s): emission delay + estimator lag.

        Savitzky–Golay: ``window // 2`` mean joint-state intervals (zero phase lag); finite
        difference: its low-frequency lag (emitted at once). NaN before two joint states.
        """
        return self._estimator.delay_s + self._estimator.lag_s

    @property
    def estimator(self) -> AccelerationEstimator:
        """The q̈ estimator (read-only use: its ``delay_s``, ``lag_s``, ``mean_dt_s``)."""
        return self._estimator

    @property
    def n_pending_wrenches(self) -> int:
        """Accepted wrenches still waiting for their joint states to be decided."""
        return len(self._wrenches)

    @property
    def n_dropped(self) -> int:
        """Total dropped messages/samples, all reasons."""
        return sum(self.drops.values())

    def reset(self, *, keep_counts: bool = False) -> None:
        """Forget all streaming state (stamps, buffers, estimator).

        Args:
            keep_counts: Keep ``drops``, ``n_samples`` and ``n_restarts`` (default: zero them, as a new
                pipeline).
        """
        self._clear_stream_state()
        if not keep_counts:
            self.drops = dict.fromkeys(DROP_REASONS, 0)
            self.n_samples = 0
            self.n_restarts = 0

    def _clear_stream_state(self) -> None:
        self._estimator.reset()
        self._last_js_stamp: int | None = None
        self._last_wrench_stamp: int | None = None
        self._js_backwards_run = 0
        self._wrench_backwards_run = 0
        self._entries: deque[_JointEntry] = deque()
        self._undecided: deque[_JointEntry] = deque()
        self._decided_until: int | None = None
        self._wrenches: deque[WrenchData] = deque()
        if self._glitch is not None:
            self._glitch.reset()
        #: A joint state the glitch check holds until the next one decides it: (stamp, q, q̇, effort).
        self._held: tuple[int, np.ndarray, np.ndarray, np.ndarray | None] | None = None

    def _drop(self, reason: str) -> list[Sample]:
        self.drops[reason] += 1
        return []

    # -- joint states ----------------------------------------------------------------------------
    def _joint_index(self, names: tuple[str, ...]) -> np.ndarray | str:
        """Map the configured joints to indices in ``names``, or return the drop reason (cached)."""
        cached = self._name_cache.get(names)
        if cached is not None:
            return cached
        position = {}
        result: np.ndarray | str
        for i, name in enumerate(names):
            if name in position:
                result = DROP_DUPLICATE_JOINT
                break
            position[name] = i
        else:
            if all(j in position for j in self.joints):
                result = np.array([position[j] for j in self.joints], dtype=np.intp)
            else:
                result = DROP_MISSING_JOINT
        size = sum(len(n) for n in names) + 8 * len(names)
        if size <= _NAME_CACHE_BYTES // 4:  # a huge name list is answered, not kept
            while self._name_cache and (len(self._name_cache) >= _NAME_CACHE_SIZE
                                        or self._name_cache_bytes + size > _NAME_CACHE_BYTES):
                old = next(iter(self._name_cache))
                self._name_cache_bytes -= sum(len(n) for n in old) + 8 * len(old)
                del self._name_cache[old]
            self._name_cache[names] = result
            self._name_cache_bytes += size
        return result

    def add(self, msg: InputMessage) -> list[Sample]:
        """Take one input message; return the samples it completed (possibly several, usually none or one).

        The one entry for messages: a joint state (q in rad, q̇ in rad/s, effort in N·m; joints in any
        order) or a wrench (force in N, torque in N·m, in the sensor frame). Bad messages are dropped and
        counted in :attr:`drops`, never raised.

        Args:
            msg: A :class:`JointStateData` or a :class:`WrenchData`.

        Returns:
            The samples completed by this message.
        """
        if isinstance(msg, WrenchData):
            return self._add_wrench(msg)
        return self._add_joint_state(msg)

    def _add_joint_state(self, msg: JointStateData) -> list[Sample]:
        """Take one joint state (q in rad, q̇ in rad/s, effort in N·m).

        Args:
            msg: The joint state, joints in any order.

        Returns:
            The samples completed by this message (possibly several, usually none or one).
        """
        stamp = msg.stamp_ns
        if stamp <= 0:
            return self._drop(DROP_JOINT_STATE_ZERO_STAMP)
        last = self._last_js_stamp
        if last is not None and stamp < last:
            self._js_backwards_run += 1
            self._drop(DROP_JOINT_STATE_BACKWARDS_STAMP)
            if self._js_backwards_run >= self.restart_after:
                self._restart()
            return []
        self._js_backwards_run = 0
        if last is not None and stamp == last:
            return self._drop(DROP_JOINT_STATE_REPEATED_STAMP)
        n_names = len(msg.names)
        torques = self._torques
        if (
            msg.position.shape[0] != n_names
            or msg.velocity.shape[0] != n_names
            or (torques and msg.effort.shape[0] != n_names)
        ):
            return self._drop(DROP_LENGTH_MISMATCH)
        index = self._joint_index(msg.names)
        if isinstance(index, str):
            return self._drop(index)
        q = msg.position[index]
        dq = msg.velocity[index]
        effort = msg.effort[index] if torques else None
        if effort is not None and self._effort_scale is not None:
            effort = effort * self._effort_scale  # reported units → N·m
        # one pass per array: NaN, inf and implausible values all fail the bound; sort out which on failure
        if not (
            _within(q, self._max_q)
            and _within(dq, self._max_dq)
            and (effort is None or _within(effort, self._max_out))
        ):
            finite = np.isfinite(q).all() and np.isfinite(dq).all()
            finite = finite and (effort is None or np.isfinite(effort).all())
            return self._drop(DROP_NONFINITE_JOINT_STATE if not finite else DROP_IMPLAUSIBLE_VALUE)
        samples: list[Sample] = []
        if self._glitch is not None:
            held, verdict = self._glitch.offer(stamp, np.concatenate((q, dq)))
            if held is not None:
                assert self._held is not None  # the check holds what the pipeline holds
                if held == ACCEPT_SUSPECT:
                    samples.extend(self._accept_joint_state(*self._held))
                else:
                    self.drops[DROP_GLITCH] += 1
                self._held = None
            if verdict == SUSPECT:
                self._last_js_stamp = stamp  # later messages must still come after it
                self._held = (stamp, q, dq, effort)
                return samples
        samples.extend(self._accept_joint_state(stamp, q, dq, effort))
        return samples

    def _accept_joint_state(self, stamp: int, q: np.ndarray, dq: np.ndarray, effort: np.ndarray | None
                            ) -> list[Sample]:
        """Take a screened joint state: buffer it, feed the q̈ estimator, return the samples it completes."""
        self._last_js_stamp = stamp
        q.flags.writeable = False  # fresh arrays shared by the samples of this joint state
        dq.flags.writeable = False
        entry = _JointEntry(stamp, q, dq, effort)
        self._entries.append(entry)
        self._undecided.append(entry)
        samples: list[Sample] = []
        torques = self._torques
        for ref_stamp, ddq in self._estimator.update_trusted(stamp, dq):
            decided = self._undecided.popleft()
            if decided.stamp != ref_stamp:  # pragma: no cover - estimator contract violated
                raise RuntimeError(f"acceleration estimator decided {ref_stamp}, expected {decided.stamp}")
            decided.ddq = ddq
            decided.decided = True
            self._decided_until = ref_stamp
            if torques:
                samples.extend(self._torque_sample(decided))
        if not torques:
            samples.extend(self._resolve_wrenches())
        self._prune(stamp)
        return samples

    def _torque_sample(self, entry: _JointEntry) -> list[Sample]:
        if entry.ddq is None:
            return self._drop(DROP_ACCELERATION_WARMUP)
        assert entry.effort is not None
        self.n_samples += 1
        return [Sample(entry.stamp, entry.q, entry.dq, entry.ddq, entry.effort)]

    def _prune(self, newest: int) -> None:
        """Drop decided joint states older than ``buffer_s`` (or beyond ``max_buffer``)."""
        entries = self._entries
        horizon = newest - self._buffer_ns
        if self.output == OutputKind.JOINT_TORQUES:
            horizon = newest  # decided entries are never needed again
        while (
            entries and entries[0].decided and (entries[0].stamp < horizon or len(entries) > self.max_buffer)
        ):
            entries.popleft()

    # -- wrenches --------------------------------------------------------------------------------
    def _add_wrench(self, msg: WrenchData) -> list[Sample]:
        """Take one wrench (force in N, torque in N·m, in the sensor frame).

        Args:
            msg: The wrench.

        Returns:
            The samples completed by this message (none while its joint states are pending).
        """
        if self.output == OutputKind.JOINT_TORQUES:
            return self._drop(DROP_WRENCH_IGNORED)
        stamp = msg.stamp_ns
        if stamp <= 0:
            return self._drop(DROP_WRENCH_ZERO_STAMP)
        last = self._last_wrench_stamp
        if last is not None and stamp < last:
            self._wrench_backwards_run += 1
            self._drop(DROP_WRENCH_BACKWARDS_STAMP)
            if self._wrench_backwards_run >= self.restart_after:
                self._restart()
            return []
        self._wrench_backwards_run = 0
        if last is not None and stamp == last:
            return self._drop(DROP_WRENCH_REPEATED_STAMP)
        if self.frame_id is not None and msg.frame_id != self.frame_id:
            return self._drop(DROP_WRONG_FRAME_ID)
        if msg.force.shape != (3,) or msg.torque.shape != (3,):
            return self._drop(DROP_LENGTH_MISMATCH)
        bound = self._max_out
        if not (_within(msg.force, bound) and _within(msg.torque, bound)):
            finite = np.isfinite(msg.force).all() and np.isfinite(msg.torque).all()
            return self._drop(DROP_IMPLAUSIBLE_VALUE if finite else DROP_NONFINITE_WRENCH)
        self._last_wrench_stamp = stamp
        if len(self._wrenches) >= self.max_buffer:
            self._wrenches.popleft()
            self.drops[DROP_BUFFER_OVERFLOW] += 1
        self.last_frame_id = msg.frame_id
        self._wrenches.append(msg)
        return self._resolve_wrenches()

    def _resolve_wrenches(self) -> list[Sample]:
        """Pair the pending wrenches, oldest first, as soon as their pairing can no longer change.

        Joint states arriving later have stamps after ``decided_until`` (the newest decided stamp), so a
        wrench is final when ``decided_until ≥ t_w + tolerance`` (all candidates decided), or earlier
        when a decided candidate with q̈ is at most ``decided_until − t_w`` away (none can be closer).
        """
        samples: list[Sample] = []
        decided_until = self._decided_until
        if decided_until is None:
            return samples
        tol = self._tol_ns
        while self._wrenches:
            wrench = self._wrenches[0]
            tw = wrench.stamp_ns
            if decided_until < tw:
                break
            best, best_dist, any_candidate = self._nearest(tw)
            if tw + tol > decided_until and (best is None or best_dist > decided_until - tw):
                break  # a closer joint state may still be decided
            self._wrenches.popleft()
            if best is None:
                self.drops[DROP_ACCELERATION_WARMUP if any_candidate else DROP_UNPAIRED_WRENCH] += 1
                continue
            assert best.ddq is not None
            self.n_samples += 1
            samples.append(Sample(tw, best.q, best.dq, best.ddq, wrench.wrench, joint_stamp_ns=best.stamp))
        return samples

    def _nearest(self, tw: int) -> tuple[_JointEntry | None, int, bool]:
        """Find the nearest decided joint state with q̈ within tolerance of ``tw``.

        Returns:
            The entry (or None), its distance in ns, and whether any decided joint state is in tolerance.
        """
        tol = self._tol_ns
        best: _JointEntry | None = None
        best_dist = 0
        any_candidate = False
        for entry in reversed(self._entries):
            dist = entry.stamp - tw
            if dist > tol:
                continue
            if dist < -tol:
                break
            if not entry.decided:
                continue
            any_candidate = True
            if entry.ddq is None:
                continue
            dist = abs(dist)
            if best is None or dist <= best_dist:  # scanning backwards: ties go to the earlier one
                best, best_dist = entry, dist
        return best, best_dist, any_candidate

    def _restart(self) -> None:
        """Clock restart on one stream: clear the streaming state, keep the counts."""
        self.n_restarts += 1
        self._clear_stream_state()
