"""One-sample glitches of joint states: a suspect is held one joint state, then dropped or accepted.

A joint state ``x = [q, q̇]`` (rad, rad/s) of the configured joints is a **suspect** when an increment
from the last accepted state ``x_ref`` exceeds

    ``ratio · max(s_i, floor_i, res_i)``  on any signal i,

the signals being each joint's position, velocity and **drift** ``q − q_ref − (q̇ + q̇_ref) Δt / 2`` (the
position's departure from its velocity: zero on smooth motion at any speed, so a position spike stands
out at 100 Hz as at 1 kHz); ``s_i`` is the signal's running mean |increment| (memory ``time_constant``
s), ``floor_i`` a constant floor (1e-6 rad, 1e-4 rad/s: exactly still joints) and ``res_i`` the
**resolution**: the position's or velocity's smallest non-zero increment seen so far. Encoders and
loggers quantize positions (e.g. to 1e-4 rad), and a joint at rest toggles by one count; with ``res_i``
in the bound a change of fewer than ``ratio`` counts is never a suspect, whatever the running mean has
decayed to. On a signal that is not quantized ``res_i`` falls towards zero and the rule is the plain
ratio test.

A suspect is not dropped at once: it is **held** until the next joint state ``x_next`` decides. A
one-sample glitch comes back: on every signal that made it a suspect ``x_next`` is closer to ``x_ref``
than to the suspect, and the suspect is dropped — unless its positions moved as its velocities say
(within two counts: a driver's q̇ = Δq/Δt of one encoder count at the start of a slow move comes back
at once and is no glitch). Anything else — a start from rest, the next state of a fast move, a step
that stays — goes on from the suspect, which is then accepted (one joint state late).
Nothing is checked across a dropout (an interval beyond three times the running mean interval): the
reference starts anew there, and a suspect held across one is dropped (nothing can tell). Checking
starts after five accepted increments (the running means settle).

The ratio is dimensionless and the memory in seconds, so the rule means the same at 100 Hz and 1 kHz;
its false-drop rate on clean logs (real, quantized, at rest, point to point) is measured by
``bench/stream/bench_glitch.py`` (docs/reliability.md).

Example:
    >>> import numpy as np
    >>> check = GlitchCheck(1, ratio=50.0, time_constant_s=0.05)
    >>> verdicts = []
    >>> for k in range(12):  # 100 Hz, q̇ = 1 rad/s, one velocity spike at k = 8
    ...     x = np.array([0.01 * k, 99.0 if k == 8 else 1.0])
    ...     verdicts.append(check.offer(10**7 * k, x))
    >>> verdicts[7:10]
    [(None, 'accept'), (None, 'suspect'), ('drop_suspect', 'accept')]
    >>> check = GlitchCheck(1, ratio=50.0, time_constant_s=0.05)
    >>> for k in range(12):  # at rest, then a start at 20 rad/s²: held one state, then accepted
    ...     t = max(0.0, 0.01 * (k - 8))
    ...     verdict = check.offer(10**7 * k, np.array([10.0 * t * t, 20.0 * t]))
    ...     if k == 9 or k == 10:
    ...         print(verdict)
    (None, 'suspect')
    ('accept_suspect', 'accept')
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from semiparam_ros.core.validation import check_range

__all__ = ["ACCEPT", "ACCEPT_SUSPECT", "DROP_SUSPECT", "SUSPECT", "GlitchCheck"]

#: Verdicts of :meth:`GlitchCheck.offer`.
ACCEPT = "accept"  # the offered state is accepted
SUSPECT = "suspect"  # the offered state is held until the next offer decides it
ACCEPT_SUSPECT = "accept_suspect"  # the held suspect went on: a real change, accepted
DROP_SUSPECT = "drop_suspect"  # the held suspect came back: a one-sample glitch, dropped

WARMUP = 5  # accepted increments before the check starts (the running means settle)
FLOOR_Q = 1e-6  # rad: floor of the mean position increment (exactly still joints)
FLOOR_DQ = 1e-4  # rad/s: floor of the mean velocity increment
GAP = 3.0  # an interval this many times the mean one is a dropout: no check across it


@njit(cache=True, nogil=True)
def _known(res: float) -> float:
    """Return a resolution, or 0 while none is known (inf: no non-zero increment seen yet)."""
    if res == np.inf:
        return 0.0
    return res


@njit(cache=True, nogil=True)
def _increment(x: np.ndarray, ref: np.ndarray, dt: float, i: int) -> float:
    """|Increment| of signal i of ``[q, q̇, drift]`` (drift: ``q − q_ref − (q̇ + q̇_ref) Δt / 2``)."""
    n = x.shape[0] // 2
    if i < 2 * n:
        return abs(x[i] - ref[i])
    j = i - 2 * n
    return abs(x[j] - ref[j] - 0.5 * (x[n + j] + ref[n + j]) * dt)


@njit(cache=True, nogil=True)
def _bound(scale: np.ndarray, floor: np.ndarray, res: np.ndarray, ratio: float, i: int) -> float:
    """``ratio · max(scale, floor, resolution)`` of signal i (the drift takes its position's resolution)."""
    n = res.shape[0] // 2
    return ratio * max(scale[i], floor[i], _known(res[i if i < 2 * n else i - 2 * n]))


@njit(cache=True, nogil=True)
def _exceeds(x: np.ndarray, ref: np.ndarray, dt: float, scale: np.ndarray, floor: np.ndarray,
             res: np.ndarray, ratio: float, fired: np.ndarray) -> bool:
    """Mark in ``fired`` (per ``[q, q̇]``) each signal beyond its bound; return whether any is.

    A drift beyond its bound marks its position, unless the joint's position or velocity fired itself
    (a velocity spike makes a drift too: the velocity is the signal that comes back).
    """
    m = x.shape[0]
    n = m // 2
    any_fired = False
    for i in range(m):
        fired[i] = _increment(x, ref, dt, i) > _bound(scale, floor, res, ratio, i)
        any_fired = any_fired or fired[i]
    for j in range(n):
        if not (fired[j] or fired[n + j]) and _increment(x, ref, dt, m + j) > _bound(scale, floor, res, ratio,
                                                                                      m + j):
            fired[j] = True
            any_fired = True
    return any_fired


@njit(cache=True, nogil=True)
def _accept(x: np.ndarray, ref: np.ndarray, dt: float, scale: np.ndarray, floor: np.ndarray,
            res: np.ndarray, ratio: float, alpha: float, clip: bool) -> None:
    """Take ``x`` as the new reference: resolutions, running means (increments clipped to the bound)."""
    m = x.shape[0]
    for i in range(m):
        r = abs(x[i] - ref[i])
        if 0.0 < r < res[i]:
            res[i] = r
    for i in range(scale.shape[0]):
        r = _increment(x, ref, dt, i)
        if clip:
            r = min(r, _bound(scale, floor, res, ratio, i))
        scale[i] += alpha * (r - scale[i])
    for i in range(m):
        ref[i] = x[i]


class GlitchCheck:
    """The glitch rule of the module docstring, for ``n`` joints (``x = [q, q̇]``, length ``2n``).

    Args:
        n_joints: Joints per state.
        ratio: Increment ratio beyond which a state is a suspect (> 0).
        time_constant_s: Memory of the running mean increments [s] (> 0).

    Raises:
        ConfigurationError: A ratio or time constant that is not a positive finite number.
    """

    def __init__(self, n_joints: int, *, ratio: float, time_constant_s: float) -> None:
        self.ratio = check_range("glitch_ratio", ratio, 0.0, lo_inclusive=False)
        self._tau_ns = 1e9 * check_range("glitch_time_constant (s)", time_constant_s, 0.0,
                                         lo_inclusive=False)
        self._floor = np.concatenate([np.full(n_joints, FLOOR_Q), np.full(n_joints, FLOOR_DQ),
                                      np.full(n_joints, FLOOR_Q)])
        self._fired = np.zeros(2 * n_joints, dtype=np.bool_)
        self.reset()

    def reset(self) -> None:
        """Forget the stream (reference, running means, resolutions, a held suspect)."""
        m = self._fired.size
        self._ref: np.ndarray | None = None
        self._ref_stamp = 0
        self._scale = np.zeros(self._floor.size)  # running mean |increment| of q, q̇ and the drift
        self._res = np.full(m, np.inf)
        self._seen = 0
        self._mean_dt = 0.0  # running mean interval between offered states [ns]
        #: The held suspect: ``(stamp, x, alpha, fired)``, or None.
        self._suspect: tuple[int, np.ndarray, float, np.ndarray] | None = None

    @property
    def holding(self) -> bool:
        """Whether a suspect is held (waiting for the next state)."""
        return self._suspect is not None

    @property
    def resolution(self) -> np.ndarray:
        """Smallest non-zero increment seen per signal (``[q…, q̇…]``; inf before any), [rad], [rad/s]."""
        return self._res.copy()

    def _take(self, stamp: int, x: np.ndarray, alpha: float) -> None:
        assert self._ref is not None
        dt = 1e-9 * (stamp - self._ref_stamp)
        _accept(x, self._ref, dt, self._scale, self._floor, self._res, self.ratio, alpha,
                self._seen >= WARMUP)
        self._ref_stamp = stamp
        self._seen += 1

    def _decide(self, stamp: int, x: np.ndarray) -> bool:
        """Decide the held suspect with the next state ``x``; True: it was a real change (accepted)."""
        assert self._suspect is not None and self._ref is not None
        s_stamp, s_x, alpha, fired = self._suspect
        self._suspect = None
        if self._mean_dt and stamp - s_stamp > GAP * self._mean_dt:
            return False  # a dropout after the suspect: nothing tells, it goes
        back = np.abs(x - self._ref) < np.abs(x - s_x)
        if bool(np.all(back[fired])) and not self._consistent(s_stamp, s_x, fired):
            return False
        self._take(s_stamp, s_x, alpha)
        return True

    def _consistent(self, stamp: int, x: np.ndarray, fired: np.ndarray) -> bool:
        """Whether the suspect's positions moved as its velocities say, on every joint that fired.

        A driver that differentiates quantized positions reports q̇ = Δq/Δt: one count at the start of a
        slow move is a velocity that comes back at once, and no glitch. Its position increment agrees
        with its velocity — by the backward difference or the trapezoid, within two counts — where a
        velocity spike s leaves the position behind by at least s·Δt/2.
        """
        assert self._ref is not None
        n = x.size // 2
        joints = fired[:n] | fired[n:]
        dt = 1e-9 * (stamp - self._ref_stamp)
        q, dq, q0, dq0 = x[:n], x[n:], self._ref[:n], self._ref[n:]
        step = q - q0
        mismatch = np.minimum(np.abs(step - dq * dt), np.abs(step - 0.5 * (dq + dq0) * dt))
        res = self._res[:n]
        tol = 2.0 * np.where(np.isinf(res), 0.0, res) + self._floor[:n]
        return bool(np.all(mismatch[joints] <= tol[joints]))

    def offer(self, stamp: int, x: np.ndarray) -> tuple[str | None, str]:
        """Offer the next screened joint state (stamps increasing, ns; ``x = [q, q̇]``).

        Args:
            stamp: Stamp [ns], after every state offered before.
            x: ``[q, q̇]`` of the configured joints (rad, rad/s); not modified, not kept.

        Returns:
            ``(held, offered)``: what became of the suspect held before this offer — :data:`ACCEPT_SUSPECT`,
            :data:`DROP_SUSPECT`, or None when none was held — and of the offered state: :data:`ACCEPT`
            or :data:`SUSPECT` (held: the caller keeps it until the next offer).
        """
        held = None
        if self._suspect is not None:
            held = ACCEPT_SUSPECT if self._decide(stamp, x) else DROP_SUSPECT
        ref = self._ref
        if ref is None:
            self._ref, self._ref_stamp = np.array(x, dtype=np.float64), stamp
            return held, ACCEPT
        dt = stamp - self._ref_stamp
        mean_dt = self._mean_dt
        # the running mean interval, each interval counted at most as a dropout's threshold
        self._mean_dt = float(dt) if mean_dt == 0.0 else mean_dt + 0.1 * (min(dt, GAP * mean_dt) - mean_dt)
        if mean_dt and dt > GAP * mean_dt:  # after a dropout the signals moved on: a new reference
            ref[:] = x
            self._ref_stamp = stamp
            return held, ACCEPT
        alpha = 1.0 if self._seen == 0 else 1.0 - math.exp(-dt / self._tau_ns)
        if self._seen >= WARMUP and _exceeds(x, ref, 1e-9 * dt, self._scale, self._floor, self._res,
                                             self.ratio, self._fired):
            self._suspect = (stamp, np.array(x, dtype=np.float64), alpha, self._fired.copy())
            return held, SUSPECT
        self._take(stamp, x, alpha)
        return held, ACCEPT
