"""Scoring contact detection per episode: recall, false alarms per minute, detection delay.

Pure numerics for the evaluation of the external wrench. A sample is *flagged* when
any component of the external estimate exceeds ``threshold`` predictive standard deviations
(:func:`flag_samples`, the rule the contact gate applies). Against ground-truth episodes ``[start, end)``:

- an episode is *detected* when a flagged sample falls in ``[start, end + tolerance]``; its *delay* is the
  time from ``start`` to the first such sample;
- a *false alarm* is a maximal run of consecutive flagged samples that touches no episode (each window
  extended by ``tolerance``); runs are counted once, not per sample;
- false alarms per minute divide by the time outside the (extended) episodes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from semiparam_ros.core.stream.rate import stream_period_s

__all__ = ["DetectionScore", "flag_samples", "score_episodes"]


@dataclass(frozen=True)
class DetectionScore:
    """Contact detection scored against ground-truth episodes.

    Attributes:
        detected: Per episode, whether it was detected.
        delays_s: Per episode, the detection delay [s] (NaN when missed).
        false_alarms: Runs of flagged samples outside every episode.
        false_alarms_per_minute: ``false_alarms`` per minute of time outside the episodes.
    """

    detected: np.ndarray
    delays_s: np.ndarray
    false_alarms: int
    false_alarms_per_minute: float

    @property
    def recall(self) -> float:
        """Fraction of episodes detected (NaN without episodes)."""
        return float(np.mean(self.detected)) if self.detected.size else float("nan")


def flag_samples(external: np.ndarray, std: np.ndarray, threshold: float) -> np.ndarray:
    """Flag samples whose external estimate exceeds ``threshold`` σ in any component.

    Args:
        external: (n, t) measured − predicted [units of y].
        std: (n, t) predictive σ ≥ 0 [units of y].
        threshold: In σ (> 0).

    Returns:
        (n,) booleans.

    Raises:
        ValueError: On mismatched shapes or a threshold ≤ 0.
    """
    e, s = np.asarray(external, dtype=np.float64), np.asarray(std, dtype=np.float64)
    if e.ndim != 2 or e.shape != s.shape:
        raise ValueError(f"external and std must be (n, t) arrays of one shape, got {e.shape} and {s.shape}")
    if not threshold > 0:
        raise ValueError(f"threshold must be > 0, got {threshold!r}")
    return np.any(np.abs(e) > threshold * s, axis=1)


def score_episodes(t: np.ndarray, flagged: np.ndarray, episodes: np.ndarray, *,
                   tolerance_s: float = 0.0) -> DetectionScore:
    """Score per-sample flags against ground-truth episodes.

    Args:
        t: (n,) sample times [s], increasing.
        flagged: (n,) booleans.
        episodes: (m, 2) ``[start, end)`` times [s] of the true contacts.
        tolerance_s: Flags up to this long after an episode's end still belong to it [s] (≥ 0).

    Returns:
        The score.

    Raises:
        ValueError: On mismatched lengths, decreasing times, malformed episodes or a negative tolerance.
    """
    t = np.asarray(t, dtype=np.float64)
    f = np.asarray(flagged, dtype=bool)
    ep = np.asarray(episodes, dtype=np.float64).reshape(-1, 2)
    if t.ndim != 1 or f.shape != t.shape:
        raise ValueError(f"t and flagged must be (n,) arrays of one length, got {t.shape} and {f.shape}")
    if t.size > 1 and np.any(np.diff(t) < 0):
        raise ValueError("t must be non-decreasing")
    if np.any(ep[:, 1] < ep[:, 0]) or not tolerance_s >= 0:
        raise ValueError("episodes must have end >= start and tolerance_s must be >= 0")
    detected = np.zeros(len(ep), dtype=bool)
    delays = np.full(len(ep), np.nan)
    near = np.zeros(t.shape, dtype=bool)  # within some episode (extended by the tolerance)
    for i, (a, b) in enumerate(ep):
        inside = (t >= a) & (t <= b + tolerance_s)
        near |= inside
        hits = np.flatnonzero(inside & f)
        if hits.size:
            detected[i] = True
            delays[i] = t[hits[0]] - a
    # runs of consecutive flagged samples; a run is a false alarm when none of its samples is near
    false_alarms = 0
    if f.any():
        starts = np.flatnonzero(f & ~np.concatenate([[False], f[:-1]]))
        ends = np.flatnonzero(f & ~np.concatenate([f[1:], [False]]))
        false_alarms = sum(1 for a, b in zip(starts, ends, strict=True) if not near[a : b + 1].any())
    duration = float(t[-1] - t[0]) if t.size > 1 else 0.0
    dt = stream_period_s(np.round(t * 1e9).astype(np.int64)) or 0.0
    outside_min = max(duration - dt * float(near.sum()), 0.0) / 60.0
    rate = false_alarms / outside_min if outside_min > 0 else float("nan")
    return DetectionScore(detected, delays, false_alarms, rate)
