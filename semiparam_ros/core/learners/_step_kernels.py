"""Compiled small-vector kernels of the per-sample step: noise scale, predictive σ, sample checks.

At one sample per millisecond the t ≈ 6-vector work of
:class:`~semiparam_ros.core.learners.uncertainty.NoiseScale` (and of the contact gate's test,
:func:`semiparam_ros.core.stream.gate.exceeds`) costs more in numpy's per-call overhead (a dozen ufunc
calls and reductions, each ≈ 0.5–1.5 µs with cold caches after the rotations) than in arithmetic. These
kernels do the same element-wise IEEE operations in the same order (no ``fastmath``), so their results are
bit-identical to the numpy expressions they replace, which stay in the callers as the reference for any
other input type and are what the tests compare against. Only float64 1-D arrays are passed.

:func:`standardized_features` is the exception: it fuses the standardization and the random Fourier
feature map of one input (numpy's version, ``Standardizer.apply_checked`` then
``RandomFourierFeatures.map_checked``, is
six calls and a BLAS product), and sums the phase in its own order, so it agrees with numpy to rounding
(the bound is in its docstring and the test), not bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "joined_within", "noise_std", "noise_update", "standardized_features",
]


@njit(cache=True, nogil=True)
def noise_std(s2: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``sqrt(s2 · (1 + fmax(v, 0)))`` element-wise (a NaN ``v`` counts as 0), a new (t,) array."""
    out = np.empty(s2.shape[0])
    for k in range(s2.shape[0]):
        vk = v[k]
        if not vk >= 0.0:  # negative or NaN: np.fmax(v, 0) gives 0
            vk = 0.0
        out[k] = math.sqrt(s2[k] * (1.0 + vk))
    return out


@njit(cache=True, nogil=True)
def noise_update(s2: np.ndarray, e: np.ndarray, v: np.ndarray, alpha: float) -> tuple[bool, np.ndarray]:
    """``(ok, s2 + alpha · (e² / (1 + fmax(v, 0)) − s2))``; ``ok`` false (s2 copied) if e is not finite."""
    out = s2.copy()
    for k in range(e.shape[0]):
        if not math.isfinite(e[k]):
            return False, out
    for k in range(e.shape[0]):
        vk = v[k]
        if not vk >= 0.0:
            vk = 0.0
        target = e[k] * e[k] / (1.0 + vk)
        out[k] = s2[k] + alpha * (target - s2[k])
    return True, out


@njit(cache=True, nogil=True)
def joined_within(q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, y: np.ndarray,
                  max_abs: float) -> tuple[int, np.ndarray]:
    """``[q, dq, ddq, y]`` in one new array, and which part holds a value beyond ``max_abs`` (or NaN).

    Returns:
        ``(bad, xy)``: ``bad`` 0 if every ``|value| <= max_abs``, 1 if the first offender is in
        ``[q, dq, ddq]``, 2 if it is in ``y``.
    """
    n, t = q.shape[0], y.shape[0]
    xy = np.empty(3 * n + t)
    xy[:n] = q
    xy[n : 2 * n] = dq
    xy[2 * n : 3 * n] = ddq
    xy[3 * n :] = y
    for k in range(3 * n + t):
        if not abs(xy[k]) <= max_abs:
            return (1 if k < 3 * n else 2), xy
    return 0, xy


@njit(cache=True, nogil=True)
def standardized_features(x: np.ndarray, mean: np.ndarray, scale: np.ndarray, omega: np.ndarray,
                          offset: np.ndarray, amplitude: float) -> np.ndarray:
    """Random Fourier features of one standardized input, ``a·cos(((x − m)/s) Ω + b)``, as a (1, D) row.

    Args:
        x: (n,) input, in the units the standardizer was fitted on.
        mean: (n,) m, the standardizer's mean.
        scale: (n,) s > 0, the standardizer's scale.
        omega: (n, D) frequencies Ω (C-contiguous).
        offset: (D,) phases b [rad].
        amplitude: a = √(2/D).

    Returns:
        (1, D) features.

    The phase ``θ_j = Σ_i z_i Ω_ij + b_j`` (z the standardized input) is accumulated row by row of Ω
    (contiguous, vectorised); it differs from numpy's BLAS sum by at most
    ``(n + 1)·ε·(Σ_i |z_i Ω_ij| + |b_j|)`` (ε = 2⁻⁵³), and cos is 1-Lipschitz, so each feature by at most
    ``a`` times that (cos is libm's, as numpy's).
    """
    n, d = omega.shape
    phase = np.zeros(d)
    for i in range(n):
        z = (x[i] - mean[i]) / scale[i]
        row = omega[i]
        for j in range(d):
            phase[j] += z * row[j]
    out = np.empty((1, d))
    for j in range(d):
        out[0, j] = amplitude * math.cos(phase[j] + offset[j])
    return out
