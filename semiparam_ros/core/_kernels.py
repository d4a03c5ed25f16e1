"""Compiled Givens-rotation kernels of the QR-RLS update (numba, ``cache=True``).

The learner state is the augmented upper-trapezoidal matrix ``M = [R | d]`` (``b × (b+t)``, C-contiguous
float64) with ``RᵀR = A`` and ``d = R⁻ᵀB``, so the weights are ``W = R⁻¹d``. One *time step* appends
rows to ``M`` and re-triangularises it::

    Q · [ s·R   s·d ]   =   [ R'  d' ]
        [  Z     U  ]       [  0   E ]

where ``s = √β`` is the forgetting scale (folded into the first rotation of each row, so forgetting costs
no extra pass over memory), ``Z`` are the k data rows plus (optionally) one regularizer row ``√c·e_j`` with
zero target. Rotations are applied column by column: row i of ``R`` is loaded once and rotated against all
k rows while it is in cache, so a block of k rows costs one sweep of ``R`` (memory-bound at large b).

A-priori prediction as a by-product: from ``Q21·s·R + Q22·Z = 0`` and ``E = Q21·s·d + Q22·U`` follows
``E = Q22 (U − Z W_old)``. The kernel tracks ``Q22`` by appending an identity block to the new rows (and
a k-long scratch for the ``R`` row being rotated, which is discarded once that row is finished). With the
column ordering ``Q22`` is lower triangular with the products of the cosines on its diagonal, so the
a-priori errors ``U − Z W_old`` follow by a k×k forward substitution. Data rows come first, so the
regularizer row never enters the data rows' errors.

Loops run over row slices with ranges starting at 0 so LLVM vectorises them (2–4× faster than indexing
``M[i, j]`` with ``j`` from ``i+1``). Only float64 C-contiguous arrays are used (one compiled signature).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["back_substitute", "qr_rls_steps"]


@njit(cache=True, nogil=True, inline="always")
def _angle(a: float, w0: float) -> tuple[float, float, float]:
    """Givens angle zeroing w0 against a: (r, c, s) with r = √(a² + w0²) ≥ 0, c = a/r, s = w0/r."""
    rr = math.sqrt(a * a + w0 * w0)
    if not (rr < math.inf and rr > 0.0):
        rr = math.hypot(a, w0)  # only when a² + w0² over- or underflows
    inv = 1.0 / rr
    return rr, a * inv, w0 * inv


@njit(cache=True, nogil=True)
def _rotate_in(
    M: np.ndarray,
    W: np.ndarray,
    scale: float,
    scratch: np.ndarray,
    ext: int,
    coef: np.ndarray,
    act: np.ndarray,
) -> None:
    """Rotate the rows of ``W`` into ``M = [R | d]`` (in place), scaling ``M`` by ``scale``.

    ``W`` is ``(kk, b+t+ext)``: the new rows ``[z | u]`` followed, if ``ext > 0``, by the ``ext`` columns
    of the ``Q22`` tracker. On return ``W[:, :b]`` is zero, ``W[:, b:b+t]`` holds ``E`` and
    ``W[:, b+t:]`` holds ``Q22``. ``coef`` (kk, 4) and ``act`` (kk,) are work arrays.

    At column i the rotation of row r only touches ``M[i, i:]`` and ``W[r, i:]``, so all rotation angles
    of the column follow from the diagonal recurrence first; two active rows (one data row plus the
    regularizer row) are then applied in one fused sweep over the row of ``M``. When a single row is
    active at columns i and i+1 (the rank-1 hot path), both rotations are applied in one sweep over rows
    i and i+1 of ``M`` (the new row is loaded and stored once for two rotations: 1.3× faster at b = 1000,
    2× at b = 2000 where ``M`` no longer fits in cache).
    """
    b = M.shape[0]
    bt = M.shape[1]
    kk = W.shape[0]
    i = 0
    while i < b:
        sc = scale
        if i + 1 < b:
            n_act = 0
            r1 = -1
            for r in range(kk):
                if W[r, i] != 0.0:
                    n_act += 1
                    r1 = r
            pair = n_act == 1
            if pair:
                for r in range(kk):
                    if r != r1 and W[r, i + 1] != 0.0:
                        pair = False
            if pair:
                Wr = W[r1]
                rr, c1, s1 = _angle(sc * M[i, i], Wr[i])
                cs1 = c1 * sc
                ss1 = s1 * sc
                M[i, i] = rr
                Wr[i] = 0.0
                x = M[i, i + 1]
                y = Wr[i + 1]
                M[i, i + 1] = cs1 * x + s1 * y
                w1 = c1 * y - ss1 * x
                if w1 != 0.0:
                    rr2, c2, s2 = _angle(sc * M[i + 1, i + 1], w1)
                    cs2 = c2 * sc
                    ss2 = s2 * sc
                else:
                    rr2, c2, s2 = sc * M[i + 1, i + 1], 1.0, 0.0
                    cs2 = sc
                    ss2 = 0.0
                M[i + 1, i + 1] = rr2
                Wr[i + 1] = 0.0
                Mi = M[i, i + 2 :]
                Mk = M[i + 1, i + 2 :]
                Wv = Wr[i + 2 : bt]
                for j in range(Mi.shape[0]):
                    x = Mi[j]
                    y = Wv[j]
                    z = Mk[j]
                    Mi[j] = cs1 * x + s1 * y
                    y1 = c1 * y - ss1 * x
                    Mk[j] = cs2 * z + s2 * y1
                    Wv[j] = c2 * y1 - ss2 * z
                # tracker: the finished rows' extra columns start at zero, so a lone rotation scales by c
                c12 = c1 * c2
                for q in range(ext):
                    Wr[bt + q] *= c12
                i += 2
                continue
        n_act = 0
        diag = M[i, i]
        for r in range(kk):
            w0 = W[r, i]
            if w0 == 0.0:
                continue  # exact: c = 1, s = 0 (regularizer rows are zero left of their coordinate)
            rr, c, s = _angle(sc * diag, w0)
            coef[n_act, 0] = c
            coef[n_act, 1] = s
            coef[n_act, 2] = c * sc
            coef[n_act, 3] = s * sc
            act[n_act] = r
            n_act += 1
            diag = rr
            W[r, i] = 0.0
            sc = 1.0
        M[i, i] = diag * sc
        Mi = M[i, i + 1 :]
        n = Mi.shape[0]
        if n_act == 0:
            if sc != 1.0:
                for j in range(n):
                    Mi[j] *= sc
            i += 1
            continue
        if n_act == 1:
            c = coef[0, 0]
            s = coef[0, 1]
            cs = coef[0, 2]
            ss = coef[0, 3]
            Wr = W[act[0], i + 1 : bt]
            for j in range(n):
                x = Mi[j]
                y = Wr[j]
                Mi[j] = cs * x + s * y
                Wr[j] = c * y - ss * x
        elif n_act == 2:
            c1 = coef[0, 0]
            s1 = coef[0, 1]
            cs1 = coef[0, 2]
            ss1 = coef[0, 3]
            c2 = coef[1, 0]
            s2 = coef[1, 1]
            W1 = W[act[0], i + 1 : bt]
            W2 = W[act[1], i + 1 : bt]
            for j in range(n):
                x = Mi[j]
                y1 = W1[j]
                y2 = W2[j]
                x1 = cs1 * x + s1 * y1
                W1[j] = c1 * y1 - ss1 * x
                Mi[j] = c2 * x1 + s2 * y2
                W2[j] = c2 * y2 - s2 * x1
        else:
            for p in range(n_act):
                c = coef[p, 0]
                s = coef[p, 1]
                cs = coef[p, 2]
                ss = coef[p, 3]
                Wr = W[act[p], i + 1 : bt]
                for j in range(n):
                    x = Mi[j]
                    y = Wr[j]
                    Mi[j] = cs * x + s * y
                    Wr[j] = c * y - ss * x
        if ext > 0:
            for q in range(ext):
                scratch[q] = 0.0
            for p in range(n_act):
                c = coef[p, 0]
                s = coef[p, 1]
                r = act[p]
                for q in range(ext):
                    x = scratch[q]
                    y = W[r, bt + q]
                    scratch[q] = c * x + s * y
                    W[r, bt + q] = c * y - s * x
        i += 1


@njit(cache=True, nogil=True)
def qr_rls_steps(
    M: np.ndarray,
    Z: np.ndarray,
    U: np.ndarray,
    rows_per_step: int,
    scale: float,
    reg: float,
    j0: int,
    P: np.ndarray,
    max_abs: float,
    L: np.ndarray,
) -> int:
    """Apply ``len(Z) // rows_per_step`` consecutive time steps to ``M = [R | d]`` in place.

    Every entry of ``Z`` and ``U`` is checked first (``|v| ≤ max_abs``, which also rejects NaN and inf);
    on failure nothing is modified and −1 is returned.

    Step m uses rows ``Z[m·k:(m+1)·k]``, targets ``U[m·k:(m+1)·k]``: ``A ← β·A + ZᵀZ + c·e_j e_jᵀ``,
    ``B ← β·B + ZᵀU`` with ``scale = √β``, ``reg = c`` (no regularizer row if ``reg == 0``) and the
    coordinate ``j`` cycling from ``j0`` through ``0 … b−1``.

    Args:
        M: ``(b, b+t)`` float64 C-contiguous, updated in place.
        Z: ``(n, b)`` float64 C-contiguous data rows.
        U: ``(n, t)`` float64 C-contiguous targets.
        rows_per_step: k ≥ 1; ``n`` must be a multiple of it.
        scale: √β ∈ (0, 1].
        reg: c ≥ 0, weight of the regularizer row of each step.
        j0: coordinate of the first step's regularizer row.
        P: ``(n, t)`` output for the a-priori predictions ``Z W_old`` of every row (W before its step),
            or a ``(0, t)`` array to skip them.
        max_abs: Largest accepted magnitude of an entry of Z and U.
        L: ``(n_steps·kk, t)`` output for the rotated-out rows ``E`` of every step (``kk`` = k, plus one
            when ``reg > 0``: the regularizer row's comes last), or a ``(0, t)`` array to skip them. Since
            the rotations are orthogonal, ``EᵀE`` is the step's increment of the weighted residual matrix
            ``S = Σ β^{n−m} U_mᵀU_m − dᵀd`` (the minimum of the ridge cost, per pair of output columns):
            ``S ← β·S + EᵀE``.

    Returns:
        The coordinate of the regularizer row of the next step, or −1 if the input was rejected.
    """
    b = M.shape[0]
    bt = M.shape[1]
    for r in range(Z.shape[0]):
        for q in range(Z.shape[1]):
            if not (abs(Z[r, q]) <= max_abs):
                return -1
        for q in range(U.shape[1]):
            if not (abs(U[r, q]) <= max_abs):
                return -1
    k = rows_per_step
    n_steps = Z.shape[0] // k
    track = P.shape[0] > 0
    keep = L.shape[0] > 0
    kk = k + 1 if reg > 0.0 else k
    ext = kk if track else 0
    W = np.empty((kk, bt + ext))
    scratch = np.zeros(max(ext, 1))
    coef = np.empty((kk, 4))
    act = np.empty(kk, dtype=np.int64)
    sqrt_reg = math.sqrt(reg)
    e = np.empty(bt - b)
    j = j0
    for step in range(n_steps):
        base = step * k
        for r in range(k):
            Wr = W[r]
            Zr = Z[base + r]
            Ur = U[base + r]
            for q in range(b):
                Wr[q] = Zr[q]
            for q in range(bt - b):
                Wr[b + q] = Ur[q]
        if kk > k:
            Wr = W[k]
            for q in range(bt):
                Wr[q] = 0.0
            Wr[j] = sqrt_reg
        if track:
            for r in range(kk):
                for q in range(ext):
                    W[r, bt + q] = 0.0
                W[r, bt + r] = 1.0
        _rotate_in(M, W, scale, scratch, ext, coef, act)
        if track:
            # E = Q22 (U − Z W_old), Q22 lower triangular: forward substitution for the data rows.
            for r in range(k):
                for q in range(bt - b):
                    acc = W[r, b + q]
                    for p in range(r):
                        acc -= W[r, bt + p] * (U[base + p, q] - P[base + p, q])
                    e[q] = acc / W[r, bt + r]
                for q in range(bt - b):
                    P[base + r, q] = U[base + r, q] - e[q]
        if keep:
            for r in range(kk):
                for q in range(bt - b):
                    L[step * kk + r, q] = W[r, b + q]
        j += 1
        if j == b:
            j = 0
    return j


@njit(cache=True, nogil=True)
def back_substitute(M: np.ndarray) -> np.ndarray:
    """``W = R⁻¹d`` for ``M = [R | d]`` (``R`` upper triangular with a nonzero diagonal), by rows.

    Used for small factors, where a LAPACK call through scipy costs more in call overhead than the
    O(b²·t) arithmetic (b = 17 parameters: ≈1 µs here, ≈15 µs through ``scipy.linalg.solve_triangular``).

    Args:
        M: ``(b, b+t)`` float64 C-contiguous.

    Returns:
        ``(b, t)`` weights.
    """
    b = M.shape[0]
    t = M.shape[1] - b
    W = np.empty((b, t))
    for i in range(b - 1, -1, -1):
        inv = 1.0 / M[i, i]
        for q in range(t):
            acc = M[i, b + q]
            for j in range(i + 1, b):
                acc -= M[i, j] * W[j, q]
            W[i, q] = acc * inv
    return W
