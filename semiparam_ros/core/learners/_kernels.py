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
``M[i, j]`` with ``j`` from ``i+1``; checked in the generated assembly: AVX2 ``vmulpd``/``vfmadd`` on
``ymm`` registers). The rotation kernel is compiled with ``fastmath={"contract"}`` and nothing else: each
``a·b + c`` may become one fused multiply-add (one rounding instead of two, so each operation is at least
as accurate as before; no reassociation, no finite-math or reciprocal approximations). The same expression
is contracted the same way in every loop, so an update gives the same bits whether or not a query row is
fused into its sweep (tested). Only float64 C-contiguous arrays are used (one compiled signature).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "back_substitute", "checked_copies", "predict_row", "predict_row_pending", "qr_rls_steps",
    "solve_predict", "stage_row", "values_within", "within",
]


@njit(cache=True, nogil=True, inline="always")
def _angle(a: float, w0: float) -> tuple[float, float, float]:
    """Givens angle zeroing w0 against a: (r, c, s) with r = √(a² + w0²) ≥ 0, c = a/r, s = w0/r."""
    rr = math.sqrt(a * a + w0 * w0)
    if not (rr < math.inf and rr > 0.0):
        rr = math.hypot(a, w0)  # only when a² + w0² over- or underflows
    inv = 1.0 / rr
    return rr, a * inv, w0 * inv


@njit(cache=True, nogil=True, fastmath={"contract"})
def _rotate_in(
    M: np.ndarray,
    W: np.ndarray,
    scale: float,
    scratch: np.ndarray,
    ext: int,
    coef: np.ndarray,
    act: np.ndarray,
    QV: np.ndarray,
    QP: np.ndarray,
    Qvar: np.ndarray,
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

    Query rows (``QV`` (kq, b+t) as made by :func:`_start_queries`, ``QP`` (kq, t), ``Qvar`` (kq,); kq may
    be 0) are predicted with the *new* factor during the same sweep: each row of ``M`` is final as soon as
    its column is rotated, and the forward substitution of :func:`solve_predict` needs the rows in that
    same order, so it advances over the row(s) just finished while they are still in cache. A single query
    row is fused into the pair sweep (one data row) and into the two-active-row sweep (data row plus the
    regularizer row, β < 1): its remainder is loaded and stored once per sweep instead of in a second pass
    over the row. The result equals :func:`solve_predict` on the updated ``M`` to rounding (blocks of one
    or two rows instead of four, reciprocals of the finished diagonal in the pair sweep, FMA); the
    rotations themselves, and so the state, are the same whether or not a query rides along.
    """
    qv = np.empty(2)
    kq = QV.shape[0]
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
                if kq == 1:
                    # one query row: its substitution over rows i, i+1 rides in the rotation loop
                    # (same operations, in the same order, as _forward_block with m = 2)
                    Vq = QV[0]
                    inv_i = 1.0 / M[i, i]
                    inv_k = 1.0 / M[i + 1, i + 1]
                    vi = Vq[i] * inv_i
                    vk = (Vq[i + 1] - vi * M[i, i + 1]) * inv_k
                    # V is b+t wide: one loop over the whole row, the last t entries of V are scratch
                    Vv = Vq[i + 2 : bt]
                    for j in range(Mi.shape[0]):
                        x = Mi[j]
                        y = Wv[j]
                        z = Mk[j]
                        xn = cs1 * x + s1 * y
                        y1 = c1 * y - ss1 * x
                        zn = cs2 * z + s2 * y1
                        Mi[j] = xn
                        Mk[j] = zn
                        Wv[j] = c2 * y1 - ss2 * z
                        Vv[j] -= vi * xn + vk * zn
                    Qvar[0] += vi * vi + vk * vk
                    Pq = QP[0]
                    di = M[i, b:bt]
                    dk = M[i + 1, b:bt]
                    for q in range(bt - b):
                        Pq[q] += vi * di[q] + vk * dk[q]
                else:
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
                if kq > 1:
                    _forward_block(M, i, 2, QV, QP, Qvar, qv)
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
        fused = False
        if n_act == 0:
            if sc != 1.0:
                for j in range(n):
                    Mi[j] *= sc
            if kq > 0:
                _forward_block(M, i, 1, QV, QP, Qvar, qv)
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
            if kq == 1:
                # one query row: its substitution over row i rides in the rotation loop (as for a pair)
                fused = True
                Vq = QV[0]
                vi = Vq[i] / M[i, i]
                Vv = Vq[i + 1 : bt]  # b+t wide, as in the pair sweep
                for j in range(n):
                    x = Mi[j]
                    y1 = W1[j]
                    y2 = W2[j]
                    x1 = cs1 * x + s1 * y1
                    W1[j] = c1 * y1 - ss1 * x
                    xn = c2 * x1 + s2 * y2
                    Mi[j] = xn
                    W2[j] = c2 * y2 - s2 * x1
                    Vv[j] -= vi * xn
                Qvar[0] += vi * vi
                Pq = QP[0]
                di = M[i, b:bt]
                for q in range(bt - b):
                    Pq[q] += vi * di[q]
            else:
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
        if kq > 0 and not fused:
            _forward_block(M, i, 1, QV, QP, Qvar, qv)
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
    Q: np.ndarray,
    QP: np.ndarray,
    Qvar: np.ndarray,
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
        Q: ``(kq, b)`` query rows predicted with the factor *after* the last step, in the last step's
            sweep (see :func:`_rotate_in`), or a ``(0, b)`` array for none.
        QP: ``(kq, t)`` output, ``Q W_new``.
        Qvar: ``(kq,)`` output, ``diag(Q A_new⁻¹ Qᵀ)``.

    Returns:
        The coordinate of the regularizer row of the next step, or −1 if the input was rejected.
    """
    b = M.shape[0]
    bt = M.shape[1]
    if not values_within(Z, U, max_abs):
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
    QV = _start_queries(Q, QP, Qvar, bt)
    QV0 = QV[:0]
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
        last = step == n_steps - 1
        _rotate_in(M, W, scale, scratch, ext, coef, act, QV if last else QV0, QP, Qvar)
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




@njit(cache=True, nogil=True)
def _forward_block(M: np.ndarray, i0: int, m: int, V: np.ndarray, P: np.ndarray, var: np.ndarray,
                   v: np.ndarray) -> None:
    """Advance the forward substitution ``Rᵀ vᵣ = zᵣᵀ`` of every query row r over rows ``i0 … i0+m−1``.

    ``V[r, i0:]`` holds what is left of query row r after the rows above ``i0`` were eliminated; the
    rows ``i0 … i0+m−1`` of ``M = [R | d]`` must be final. The m×m diagonal block is solved first
    (``v``, length ≥ m, is scratch), ``P[r] += Σ v_p d[i0+p]`` and ``var[r] += Σ v_p²`` accumulate, then
    ``V[r, i0+m:] −= Σ_p v_p R[i0+p, i0+m:]`` in one pass (fused loops for m = 1, 2, 4).
    """
    b = M.shape[0]
    bt = M.shape[1]
    t = bt - b
    for r in range(V.shape[0]):
        Vr = V[r]
        for p in range(m):
            i = i0 + p
            acc = Vr[i]
            for s in range(p):
                acc -= v[s] * M[i0 + s, i]
            v[p] = acc / M[i, i]
        Pr = P[r]
        for p in range(m):
            vp = v[p]
            var[r] += vp * vp
            dp = M[i0 + p, b:bt]
            for q in range(t):
                Pr[q] += vp * dp[q]
        W = Vr[i0 + m : b]
        n = W.shape[0]
        if m == 4:
            v0 = v[0]
            v1 = v[1]
            v2 = v[2]
            v3 = v[3]
            M0 = M[i0, i0 + 4 : b]
            M1 = M[i0 + 1, i0 + 4 : b]
            M2 = M[i0 + 2, i0 + 4 : b]
            M3 = M[i0 + 3, i0 + 4 : b]
            for j in range(n):
                W[j] -= v0 * M0[j] + v1 * M1[j] + v2 * M2[j] + v3 * M3[j]
        elif m == 2:
            v0 = v[0]
            v1 = v[1]
            M0 = M[i0, i0 + 2 : b]
            M1 = M[i0 + 1, i0 + 2 : b]
            for j in range(n):
                W[j] -= v0 * M0[j] + v1 * M1[j]
        else:
            for p in range(m):
                vp = v[p]
                Mp = M[i0 + p, i0 + m : b]
                for j in range(n):
                    W[j] -= vp * Mp[j]


@njit(cache=True, nogil=True)
def _start_queries(Z: np.ndarray, P: np.ndarray, var: np.ndarray, width: int) -> np.ndarray:
    """Working copy of the query rows, ``width ≥ b`` wide (zeros right of b); zero the outputs.

    The rotation sweeps make it ``b + t`` wide so that a fused query runs over the whole row of ``M``
    in one loop (its last t entries are scratch that is never read).
    """
    V = np.empty((Z.shape[0], width))
    for r in range(Z.shape[0]):
        Vr = V[r]
        Zr = Z[r]
        for j in range(Z.shape[1]):
            Vr[j] = Zr[j]
        for j in range(Z.shape[1], width):
            Vr[j] = 0.0
        for q in range(P.shape[1]):
            P[r, q] = 0.0
        var[r] = 0.0
    return V


@njit(cache=True, nogil=True)
def solve_predict(M: np.ndarray, Z: np.ndarray, P: np.ndarray, var: np.ndarray) -> None:
    """Prediction ``Z W = (Z R⁻¹) d`` and ``diag(Z A⁻¹ Zᵀ) = ‖R⁻ᵀ Zᵀ‖²`` in one read-only sweep of ``R``.

    For each query row z the forward substitution ``Rᵀ v = zᵀ`` runs down the rows of ``R`` in the
    "axpy" order: once ``v_i = z_i / R_ii`` is known, ``v_i · R[i, i+1:]`` is subtracted from the rest of
    z. Rows of ``R`` are taken four at a time, so each entry of ``R`` is read once, contiguously, and the
    working row is loaded and stored once per four rows of ``R``; ``R`` is never written.
    ``P += v_i · d[i]`` and ``var += v_i²`` accumulate on the way. Cost ``k·b²`` flops, against
    ``t·b²`` for the weights ``W = R⁻¹d`` (t outputs) plus ``k·b·t`` for ``Z W``.

    Args:
        M: ``(b, b+t)`` float64 C-contiguous ``[R | d]``, ``R`` upper triangular with a nonzero diagonal.
        Z: ``(k, b)`` float64 query rows (read only).
        P: ``(k, t)`` output, ``Z W``.
        var: ``(k,)`` output, ``z A⁻¹ zᵀ`` per row (≥ 0).
    """
    b = M.shape[0]
    V = _start_queries(Z, P, var, Z.shape[1])
    v = np.empty(4)
    i0 = 0
    while i0 < b:
        m = min(4, b - i0)
        _forward_block(M, i0, m, V, P, var, v)
        i0 += m


@njit(cache=True, nogil=True)
def within(A: np.ndarray, max_abs: float) -> bool:
    """Whether every entry of the 2-d float64 ``A`` satisfies ``|v| ≤ max_abs`` (false for NaN)."""
    for r in range(A.shape[0]):
        for q in range(A.shape[1]):
            if not (abs(A[r, q]) <= max_abs):
                return False
    return True


@njit(cache=True, nogil=True)
def values_within(Z: np.ndarray, U: np.ndarray, max_abs: float) -> bool:
    """Whether every entry of ``Z`` and ``U`` (2-d float64) satisfies ``|v| ≤ max_abs`` (false for NaN)."""
    return within(Z, max_abs) and within(U, max_abs)


def checked_copies(Z: np.ndarray, U: np.ndarray, max_abs: float) -> tuple[bool, np.ndarray, np.ndarray]:
    """``(ok, Z.copy(), U.copy())`` with ``ok`` as :func:`values_within` (the check of a deferred update).

    Not compiled as a whole: handing two new arrays back from a numba function costs more than numpy's
    own copies (≈ 3 µs against ≈ 1.8 µs for one row at b = 1000), so only the check is compiled.
    """
    return values_within(Z, U, max_abs), Z.copy(), U.copy()


@njit(cache=True, nogil=True)
def stage_row(z: np.ndarray, u: np.ndarray, Z: np.ndarray, U: np.ndarray, max_abs: float) -> bool:
    """Check one row ``z`` (b,), ``u`` (t,) and copy it into ``Z`` (1, b), ``U`` (1, t) — the deferred update.

    One compiled call instead of a check plus two numpy copies (the learner's preallocated buffers).

    Returns:
        Whether every entry satisfies ``|v| ≤ max_abs`` (false for NaN); on false nothing is written.
    """
    if not values_within(z.reshape(1, z.shape[0]), u.reshape(1, u.shape[0]), max_abs):
        return False
    Zr = Z[0]
    Ur = U[0]
    for q in range(z.shape[0]):
        Zr[q] = z[q]
    for q in range(u.shape[0]):
        Ur[q] = u[q]
    return True


@njit(cache=True, nogil=True)
def predict_row(M: np.ndarray, z: np.ndarray, p: np.ndarray, max_abs: float) -> float:
    """:func:`solve_predict` for one query row ``z`` (b,) into ``p`` (t,), with the value check.

    Returns:
        ``z A⁻¹ zᵀ`` (≥ 0), or −1 if an entry of ``z`` has ``|v| > max_abs`` or is NaN (``p`` unwritten).
    """
    if not within(z.reshape(1, z.shape[0]), max_abs):
        return -1.0
    var = np.empty(1)
    solve_predict(M, z.reshape(1, z.shape[0]), p.reshape(1, p.shape[0]), var)
    return var[0]


@njit(cache=True, nogil=True)
def predict_row_pending(M: np.ndarray, Z: np.ndarray, U: np.ndarray, scale: float, reg: float, j0: int,
                        z: np.ndarray, p: np.ndarray, max_abs: float) -> tuple[int, float]:
    """One time step ``(Z, U)`` (as :func:`qr_rls_steps`, one step) with the query row ``z`` (b,) fused.

    The query is checked first: if an entry has ``|v| > max_abs`` or is NaN, ``M`` is untouched and
    ``(−2, −1)`` is returned. Otherwise ``p`` (t,) receives ``z W_new`` and the result is
    ``(j, z A_new⁻¹ zᵀ)`` with ``j`` the next regularizer coordinate (−1 if ``Z``/``U`` were rejected,
    ``M`` again untouched). Same operations as :func:`qr_rls_steps` with ``Q = z``: the same bits.
    """
    if not within(z.reshape(1, z.shape[0]), max_abs):
        return -2, -1.0
    t = M.shape[1] - M.shape[0]
    none = np.empty((0, t))
    var = np.empty(1)
    j = qr_rls_steps(M, Z, U, Z.shape[0], scale, reg, j0, none, max_abs, none, z.reshape(1, z.shape[0]),
                     p.reshape(1, t), var)
    return j, var[0]
