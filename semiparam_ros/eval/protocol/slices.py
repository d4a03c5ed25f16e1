"""Errors by motion state: at rest, around reversals, slow and fast, beside the totals.

A real arm's logs are full of rests and reversals, where friction holds whatever its history left and a
static model of (q, q̇, q̈) knows least; a total over a log hides them. Each test sample is put, **per
joint**, in the slices its own velocity q̇_j says (joint torques: output j is joint j; for a wrench every
output is judged by the fastest joint, and a reversal of any joint):

* ``at rest``: |q̇| < :data:`REST_VELOCITY` (0.01 rad/s);
* ``reversals``: within ±:data:`REVERSAL_WINDOW_S` (0.2 s) of a sign change of q̇ (overlaps the others);
* ``slow``: :data:`REST_VELOCITY` ≤ |q̇| < :data:`SLOW_VELOCITY` (0.2 rad/s);
* ``fast``: |q̇| ≥ :data:`SLOW_VELOCITY`.

A slice's RMSE is the mean over the outputs that have at least :data:`MIN_SAMPLES` samples in it (NaN when
none has); its share is the fraction of (sample, output) pairs in it.

>>> dq = np.concatenate([np.zeros(50), np.linspace(0.1, 1.0, 50)])[:, None]
>>> masks = motion_slices(np.hstack([0 * dq, dq, 0 * dq]), 1, 1, 0.01)
>>> [int(masks[k].sum()) for k in SLICES]
[50, 0, 6, 44]
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = ["MIN_SAMPLES", "REST_VELOCITY", "REVERSAL_WINDOW_S", "SLICES", "SLOW_VELOCITY", "motion_slices",
           "slice_coverage", "slice_rmse", "slice_shares"]

#: The slices, in the order tables show them.
SLICES = ("at rest", "reversals", "slow", "fast")
#: A joint slower than this is at rest [rad/s].
REST_VELOCITY = 0.01
#: A joint slower than this (and not at rest) is slow [rad/s].
SLOW_VELOCITY = 0.2
#: Half-width of the window around a velocity sign change [s].
REVERSAL_WINDOW_S = 0.2
#: Samples an output needs in a slice for its RMSE to count there.
MIN_SAMPLES = 20


def motion_slices(X: np.ndarray, n_joints: int, n_outputs: int, period_s: float) -> dict[str, np.ndarray]:
    """Return each slice's (N, t) mask of the samples of ``X = [q, q̇, q̈]``.

    Args:
        X: (N, 3n) states [rad, rad/s, rad/s²].
        n_joints: n.
        n_outputs: t: one per joint (joint torques, t = n), or any other width (a wrench: every output
            judged by the fastest joint).
        period_s: Sample period [s] (for the reversal window).

    Returns:
        Slice name → boolean mask (N, t).
    """
    dq = np.asarray(X, dtype=np.float64)[:, n_joints:2 * n_joints]
    sign = np.sign(dq)
    flips = (sign[1:] * sign[:-1]) < 0  # (N−1, n): q̇_j changed sign between two samples
    half = max(1, round(REVERSAL_WINDOW_S / period_s)) if period_s > 0 and math.isfinite(period_s) else 1
    near = np.zeros(dq.shape, dtype=bool)
    for i, j in zip(*np.nonzero(flips), strict=True):
        near[max(0, i + 1 - half): i + 1 + half, j] = True
    speed = np.abs(dq)
    if n_outputs != n_joints:  # one judgement per sample: the fastest joint, any joint's reversal
        speed, near = speed.max(axis=1, keepdims=True), near.any(axis=1, keepdims=True)
    masks = {"at rest": speed < REST_VELOCITY, "reversals": near,
             "slow": (speed >= REST_VELOCITY) & (speed < SLOW_VELOCITY), "fast": speed >= SLOW_VELOCITY}
    if n_outputs != n_joints:
        masks = {k: np.repeat(m, n_outputs, axis=1) for k, m in masks.items()}
    return masks


def _per_slice(values: np.ndarray, masks: dict[str, np.ndarray], reduce: Callable[[np.ndarray], float]
               ) -> dict[str, float]:
    """Mean over the outputs (with enough samples in the slice) of ``reduce`` of each output's values."""
    out = {}
    for name in SLICES:
        mask = masks[name]
        per_output = [reduce(values[mask[:, k], k]) for k in range(values.shape[1])
                      if int(mask[:, k].sum()) >= MIN_SAMPLES]
        out[name] = float(np.mean(per_output)) if per_output else float("nan")
    return out


def slice_rmse(errors: np.ndarray, masks: dict[str, np.ndarray]) -> dict[str, float]:
    """Mean over the outputs (with enough samples) of each slice's RMSE of ``errors`` (N, t)."""
    return _per_slice(errors, masks, lambda e: math.sqrt(float(np.mean(e**2))))


def slice_coverage(inside: np.ndarray, masks: dict[str, np.ndarray]) -> dict[str, float]:
    """Return each slice's share of ``inside`` (N, t), the errors within ±2σ: coverage by motion state.

    The mean over the outputs with enough samples in the slice, as :func:`slice_rmse`; under ``all`` the
    share over every sample and output.
    """
    return {"all": float(np.mean(inside)), **_per_slice(inside, masks, lambda b: float(np.mean(b)))}


def slice_shares(masks: dict[str, np.ndarray]) -> dict[str, float]:
    """Fraction of the (sample, output) pairs in each slice."""
    return {name: float(np.mean(masks[name])) for name in SLICES}
