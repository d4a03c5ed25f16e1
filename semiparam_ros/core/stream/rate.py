"""The one owner of the sample rate: how a stream's period is measured and how seconds become samples.

Every length the configuration gives in seconds (acceleration window, standardizer warm-up, memory τ,
diagnostics and evaluation windows) is converted here, at a period measured here, by the same rule online
(the node, one stamp at a time: :class:`RateMeter`) and offline (replay, evaluation, selection: the same
meter fed a recorded stream's stamps, :func:`measured_period_s`), so a bag gives the same numbers either way.

**The rule.** The period is the median of the positive intervals between the first :data:`RATE_SAMPLES`
stamps, leaving out intervals longer than ``max_gap_s`` when given (a dropout is not the rate). The median
ignores a few jittered or repeated stamps. If no interval qualifies, measuring starts again from the newest
stamp. A duration ``d`` [s] spans :func:`samples_in` ``= max(1, round(d / T))`` samples.

Units: stamps in integer ns, periods and durations in s.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from semiparam_ros.errors import ConfigurationError

__all__ = ["RATE_SAMPLES", "RateMeter", "measured_period_s", "samples_in", "stream_period_s"]

#: Stamps whose intervals measure a stream's period (9 intervals).
RATE_SAMPLES = 10


class RateMeter:
    """Measure a stream's sample period from its first stamps, one stamp at a time.

    Args:
        max_gap_s: Intervals longer than this [s] are not the rate (``None``: no bound).
        n_stamps: Stamps to collect before deciding (default :data:`RATE_SAMPLES`, ≥ 2).

    Example:
        >>> meter = RateMeter()
        >>> periods = [meter.add(k * 5_000_000) for k in range(RATE_SAMPLES)]  # 200 Hz
        >>> periods[-2] is None, periods[-1]
        (True, 0.005)
        >>> meter.period_s
        0.005
    """

    def __init__(self, max_gap_s: float | None = None, n_stamps: int = RATE_SAMPLES) -> None:
        if max_gap_s is not None and not (math.isfinite(max_gap_s) and max_gap_s > 0):
            raise ConfigurationError(f"max_gap_s must be a positive number or None, got {max_gap_s!r}")
        if int(n_stamps) < 2:
            raise ConfigurationError(f"n_stamps must be >= 2, got {n_stamps!r}")
        self.max_gap_s = max_gap_s
        self.n_stamps = int(n_stamps)
        self._stamps: list[int] = []
        #: The measured period [s], or None until it is known.
        self.period_s: float | None = None

    def add(self, stamp_ns: int) -> float | None:
        """Take one stamp [ns]; return the period [s] once it is measured (then always the same value)."""
        if self.period_s is not None:
            return self.period_s
        self._stamps.append(int(stamp_ns))
        if len(self._stamps) < self.n_stamps:
            return None
        dts: np.ndarray = np.diff(np.asarray(self._stamps, dtype=np.int64)).astype(np.float64) * 1e-9
        dts = dts[dts > 0]
        if self.max_gap_s is not None:
            dts = dts[dts <= self.max_gap_s]
        if dts.size == 0:
            self._stamps = self._stamps[-1:]  # nothing usable: measure again from the newest stamp
            return None
        self.period_s = float(np.median(dts))
        self._stamps = []
        return self.period_s


def measured_period_s(stamps_ns: Iterable[int], max_gap_s: float | None = None) -> float | None:
    """Return the period [s] the node would measure on a recorded stream (:class:`RateMeter` on its stamps).

    Args:
        stamps_ns: The stream's stamps [ns], in order.
        max_gap_s: Intervals longer than this [s] are left out (``None``: no bound).

    Returns:
        The period, or ``None`` if the stream never gives :data:`RATE_SAMPLES` stamps with a usable
        interval.

    Example:
        >>> measured_period_s(range(0, 10**9, 10**7))  # 100 Hz
        0.01
    """
    meter = RateMeter(max_gap_s)
    for s in stamps_ns:
        if meter.add(int(s)) is not None:
            break
    return meter.period_s


def stream_period_s(stamps_ns: np.ndarray) -> float | None:
    """Return a recorded stream's period [s], by the node's rule where the stream is long enough.

    :func:`measured_period_s`, or for a stream too short for it the median of its stamp differences
    (``None`` with fewer than two stamps).

    Args:
        stamps_ns: The stream's stamps [ns], in order.

    Example:
        >>> stream_period_s(np.array([0, 10**7, 2 * 10**7]))  # 3 stamps: too few to measure, the median
        0.01
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    period = measured_period_s(stamps)
    if period is not None:
        return period
    if len(stamps) < 2:
        return None
    return float(np.median(np.diff(stamps))) * 1e-9


def samples_in(duration_s: float, sample_period_s: float) -> int:
    """Return the number of samples spanning a duration: ``max(1, round(duration_s / sample_period_s))``.

    Args:
        duration_s: Duration [s], > 0.
        sample_period_s: Sample period [s], > 0.

    Raises:
        ConfigurationError: If either is not a finite positive number.

    Example:
        >>> samples_in(2.0, 0.005), samples_in(2.0, 0.001), samples_in(0.0001, 0.01)
        (400, 2000, 1)
    """
    try:
        d, t = float(duration_s), float(sample_period_s)
    except (TypeError, ValueError):
        d = t = math.nan
    if not (math.isfinite(d) and d > 0 and math.isfinite(t) and t > 0):
        raise ConfigurationError(f"need a positive duration and period, got {duration_s!r} s, "
                                 f"{sample_period_s!r} s")
    return max(1, round(d / t))
