"""Compiled small-vector kernels of the consistent SP's per-sample step.

Besides its two factor sweeps, a step of
:class:`~semiparam_ros.core.learners.consistent.ConsistentSemiparametricModel` is a few dozen operations
on t-vectors (t ≈ 6 outputs): the residual's weight, the fast correction's weight, the tracker's
smoothers. In numpy each is a ufunc call of about a microsecond; these kernels do the same arithmetic in
one call each. Element-wise operations are done in the same order as the numpy expressions of the
formulas (no ``fastmath``). The tests compare every kernel with a numpy implementation of its formula.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from semiparam_ros.core.learners._kernels import solve_predict
from semiparam_ros.core.learners._step_kernels import standardized_features

__all__ = [
    "fast_total", "model_alone_one", "saving_step", "saving_update", "scale_step", "scale_update",
    "shrunk_choice", "significant_saving", "stage_pending", "state_weight", "tracker_step", "tracker_update",
    "weighted_residual",
]


@njit(cache=True, nogil=True)
def weighted_residual(raw: np.ndarray, s2: np.ndarray, spread: np.ndarray, lam: float, v: float,
                      out: np.ndarray) -> None:
    """Write the residual r weighted per output into ``out`` (t,): ``out_k = g_k r_k``.

    ``g_k = S_k / (S_k + spread_k v)``, ``S_k = s2_k · clip(1 − λv, 0, 1)`` (1 where the denominator is 0).

    Args:
        raw: (t,) the residual r before its weight.
        s2: (t,) the rigid-body part's recent systematic error variance.
        spread: (t,) the residual's noise variance over the novelty scale.
        lam: λ of the residual learner.
        v: The residual's relative predictive variance at x (≥ 0).
        out: (t,) output, the weighted residual.
    """
    keep = 1.0 - lam * v
    if keep < 0.0:
        keep = 0.0
    elif keep > 1.0:
        keep = 1.0
    for k in range(raw.shape[0]):
        signal = s2[k] * keep
        total = signal + spread[k] * v
        g = signal / total if total > 0.0 else 1.0
        out[k] = raw[k] * g


@njit(cache=True, nogil=True)
def fast_total(model_total: np.ndarray, c: np.ndarray, v: np.ndarray, noise: np.ndarray,
               kappa_fast: np.ndarray, useful: np.ndarray, kappa: np.ndarray, used: np.ndarray,
               applied: np.ndarray, fast: np.ndarray, total: np.ndarray, rigid: np.ndarray,
               residual: np.ndarray, correction: np.ndarray) -> None:
    """Write the model plus its fast corrections into ``applied``, ``fast`` and ``total`` (t,), and the parts.

    ``applied = κ_f c``; ``fast = model + [useful] w·applied`` with ``w = max(0, 1 − 9 r̂ v / c²)`` (0 where
    ``c² ≤ 9 r̂ v``); ``total = fast + κ b̂``; ``residual = total − ŷ_P``, ``correction = total − model``.

    Args:
        model_total: (t,) model(x).
        c: (t,) the fast rigid-body correction Φδ_f at x.
        v: (t,) its relative predictive variance.
        noise: (t,) r̂, the white-noise variance of the model's error.
        kappa_fast: (t,) κ_f, the fast correction's fade at x, per output.
        useful: (t,) bool, where the fast correction is used.
        kappa: (t,) κ, the local tracker's fade at x, per output.
        used: (t,) b̂, the local tracker's estimate.
        applied: (t,) output.
        fast: (t,) output.
        total: (t,) output.
        rigid: (t,) ŷ_P, the rigid-body part.
        residual: (t,) output, everything but the rigid-body part.
        correction: (t,) output, the fast corrections.
    """
    for k in range(model_total.shape[0]):
        a = kappa_fast[k] * c[k]
        applied[k] = a
        w = 0.0
        if useful[k]:
            nk = 9.0 * noise[k] * v[k]
            c2 = c[k] * c[k]
            if c2 > nk:
                w = 1.0 - nk / c2
        fast[k] = model_total[k] + w * a
        total[k] = fast[k] + kappa[k] * used[k]
        residual[k] = total[k] - rigid[k]
        correction[k] = total[k] - model_total[k]


@njit(cache=True, nogil=True)
def tracker_update(estimates: np.ndarray, errors: np.ndarray, gains: np.ndarray, e: np.ndarray, weight: float,
                   a: float) -> None:
    """Absorb one learned error e into the bank of smoothers, in place.

    ``miss = e − weight·b_K``; ``errors ← errors + a(miss² − errors)``; ``b_K ← weight·b_K + K·miss``.

    Args:
        estimates: (k, t) the smoothers' estimates b_K.
        errors: (k, t) their running a-priori squared errors.
        gains: (k,) the gains K.
        e: (t,) the error.
        weight: κ at the sample's state.
        a: The running mean's weight.
    """
    for i in range(estimates.shape[0]):
        gain = gains[i]
        for k in range(estimates.shape[1]):
            prior = weight * estimates[i, k]
            miss = e[k] - prior
            errors[i, k] += a * (miss * miss - errors[i, k])
            estimates[i, k] = prior + gain * miss


@njit(cache=True, nogil=True)
def scale_update(scale_model: np.ndarray, recent_rigid: np.ndarray, corr: np.ndarray, y: np.ndarray,
                 rigid: np.ndarray, raw: np.ndarray, beta: float, a: float, a_corr: float) -> None:
    """Update the error statistics of the residual's weight and of the model's variance, in place.

    ``e_P = y − ŷ_P``, ``e = e_P − r``: ``scale_model ← β·scale_model + e²``,
    ``recent_rigid ← recent_rigid + a(e_P² − recent_rigid)``, and the correlation statistics
    ``m ← m + a_c(e − m)`` (``corr[0]``, the smoothed error), ``corr[1] ← β·corr[1] + m²``.

    Args:
        scale_model: (t,) Σ β^{n−m} e_m², the residual's noise variance times its weight.
        recent_rigid: (t,) the recent mean of e_P².
        corr: (2, t) the smoothed error m and Σ β^{n−m} m_m².
        y: (t,) the measurement.
        rigid: (t,) ŷ_P, the rigid-body part's a-priori prediction.
        raw: (t,) r, the residual's a-priori value before its weight.
        beta: The residual learner's forgetting factor β.
        a: The recent mean's weight.
        a_corr: The smoothed error's weight a_c.
    """
    for k in range(y.shape[0]):
        e_rigid = y[k] - rigid[k]
        e_model = e_rigid - raw[k]
        scale_model[k] = beta * scale_model[k] + e_model * e_model
        recent_rigid[k] += a * (e_rigid * e_rigid - recent_rigid[k])
        corr[0, k] += a_corr * (e_model - corr[0, k])
        corr[1, k] = beta * corr[1, k] + corr[0, k] * corr[0, k]


@njit(cache=True, nogil=True)
def saving_update(fast_errors: np.ndarray, y: np.ndarray, model: np.ndarray, candidate: np.ndarray,
                  a: float) -> None:
    """Update the running mean and mean square of what the fast correction saved, in place.

    ``e = y − model``, ``s = e² − (e − candidate)²``: ``fast_errors[0] += a(s − fast_errors[0])``,
    ``fast_errors[1] += a(s² − fast_errors[1])``.

    Args:
        fast_errors: (2, t) the running mean of s and of s².
        y: (t,) the measurement.
        model: (t,) model(x), the a-priori prediction without corrections.
        candidate: (t,) the full fast correction κ_f Φδ_f at the sample.
        a: The running mean's weight.
    """
    for k in range(y.shape[0]):
        e0 = y[k] - model[k]
        miss = e0 - candidate[k]
        gain = e0 * e0 - miss * miss
        fast_errors[0, k] += a * (gain - fast_errors[0, k])
        fast_errors[1, k] += a * (gain * gain - fast_errors[1, k])


@njit(cache=True, nogil=True)
def aged_saving_step(errors: np.ndarray, y: np.ndarray, Phi: np.ndarray, theta: np.ndarray, phi: np.ndarray,
                     W: np.ndarray, s2: np.ndarray, spread: np.ndarray, lam: float, v: float, a: float,
                     window: float, corr_sq: np.ndarray, scale_model: np.ndarray, a_corr: float,
                     min_evidence: float, use: np.ndarray) -> None:
    """Score an aged copy of the residual on one learned sample, then decide per output whether to use it.

    The copy is ``(θ, W)``: the reference and the residual's weights as they were a while ago. At the
    sample, with e = y − Φθ (the aged rigid body's error) and the weighted aged residual
    ``ρ = g(v)·φW`` (``g = S/(S + spread·v)``, ``S = s²·clip(1 − λv, 0, 1)``, 1 where that is 0: the
    online weight at the sample's v), the saving ``d = e² − (e − ρ)²`` enters running means of d and d²
    with weight a: ``errors[0] += a(d − errors[0])``, ``errors[1] += a(d² − errors[1])``.

    Then ``use_k`` is false only where the mean saving m is negative by more than two standard errors:
    ``m < −2·sqrt(max(errors[1] − m², 0)/n)`` with ``n = window/c`` effective samples, c the samples over
    which the residual's errors stay correlated (``max((corr_sq/scale_model)(2 − a_corr)/a_corr, 1)``, as
    ``correlation_samples``); true while n < ``min_evidence``.

    Args:
        errors: (2, t) running mean of d and of d², updated in place.
        y: (t,) the measurement.
        Phi: (t, p) the regressor at the sample.
        theta: (p,) the aged copy's reference parameters.
        phi: (D,) the random features at the sample.
        W: (D, t) the aged copy's residual weights.
        s2: (t,) the rigid-body part's systematic error variance s² (now).
        spread: (t,) σ²/ν₀ of the online weight (now).
        lam: λ of the residual learner.
        v: The residual's relative predictive variance at the sample (now).
        a: The running means' weight.
        window: The samples the running means average over.
        corr_sq: (t,) the smoothed residual error's Σβ m² (the correlation statistics).
        scale_model: (t,) Σβ (y − ŷ_P − r)².
        a_corr: 1 − β of the correlation statistics.
        min_evidence: Effective samples below which the residual is used.
        use: (t,) bool output.
    """
    t, p = Phi.shape
    rigid, raw, candidate = np.empty(t), np.empty(t), np.empty(t)
    for k in range(t):
        acc = 0.0
        for j in range(p):
            acc += Phi[k, j] * theta[j]
        rigid[k] = acc
        acc = 0.0
        for j in range(phi.shape[0]):
            acc += phi[j] * W[j, k]
        raw[k] = acc
    weighted_residual(raw, s2, spread, lam, v, candidate)  # ρ = g(v)·φW, the online weight
    saving_update(errors, y, rigid, candidate, a)  # d = e² − (e − ρ)²
    for k in range(t):
        ratio = corr_sq[k] / scale_model[k] if scale_model[k] > 0.0 else 0.0
        c = ratio * (2.0 - a_corr) / a_corr
        if c < 1.0:
            c = 1.0
        n = window / c
        if n < min_evidence:
            use[k] = True
            continue
        use[k] = not (errors[0, k] < -two_standard_errors(errors, k, n))


@njit(cache=True, nogil=True)
def shrunk_choice(estimates: np.ndarray, errors: np.ndarray, gains: np.ndarray, noise: np.ndarray,
                  z2: float, ready: bool, out: np.ndarray) -> None:
    """Write the chosen smoother's estimate, shrunk by the noise it carries, into ``out`` (t,).

    Per output k: the smoother ``i`` with the smallest running error (the first of equals; ``i = 0`` when
    not ``ready``), ``b = estimates[i, k]``, ``n = z2·noise_k·K_i/(2 − K_i)``, ``out_k = b(1 − n/b²)`` where
    ``b² > n``, else 0.

    Args:
        estimates: (k, t) the smoothers' estimates.
        errors: (k, t) their running a-priori squared errors.
        gains: (k,) the gains K (< 2).
        noise: (t,) r̂, the white-noise variance of the error.
        z2: z², the squared number of standard deviations.
        ready: Whether enough errors were seen to choose.
        out: (t,) output.
    """
    for k in range(estimates.shape[1]):
        best = 0
        if ready:
            for i in range(1, estimates.shape[0]):
                if errors[i, k] < errors[best, k]:
                    best = i
        b = estimates[best, k]
        gain = gains[best]
        nk = z2 * noise[k] * gain / (2.0 - gain)
        b2 = b * b
        out[k] = b * (1.0 - nk / b2) if b2 > nk else 0.0


@njit(cache=True, nogil=True)
def two_standard_errors(stats: np.ndarray, k: int, n: float) -> float:
    """``2·sqrt(max(s − m², 0)/n)``: two standard errors of the running mean m of column k over n samples.

    Args:
        stats: (2, t) the running mean m and mean square s.
        k: The column (output).
        n: The (effective) samples averaged, > 0.
    """
    mean = stats[0, k]
    spread = stats[1, k] - mean * mean
    if spread < 0.0:
        spread = 0.0
    return 2.0 * np.sqrt(spread / n)


@njit(cache=True, nogil=True)
def significant_saving(fast_errors: np.ndarray, n: int, out: np.ndarray) -> None:
    """Write whether each output's mean saving exceeds two standard errors into ``out`` (t,) bool.

    ``out_k = m_k > 2·sqrt(max(s_k − m_k², 0)/n)``, m and s the running mean of the saving and of its
    square (``fast_errors[0]``, ``fast_errors[1]``), over n samples (all false for n < 2).

    Args:
        fast_errors: (2, t) the running mean and mean square.
        n: The samples they average over.
        out: (t,) bool output.
    """
    for k in range(fast_errors.shape[1]):
        if n < 2:
            out[k] = False
            continue
        out[k] = fast_errors[0, k] > two_standard_errors(fast_errors, k, n)


@njit(cache=True, nogil=True)
def scale_step(scale_model: np.ndarray, recent_rigid: np.ndarray, corr: np.ndarray, y: np.ndarray,
               rigid: np.ndarray, raw: np.ndarray, beta: float, a: float, a_corr: float, weight: float,
               novelty_scale: float, s2: np.ndarray, spread: np.ndarray) -> None:
    """:func:`scale_update`, then the residual weight's scales it gives, into ``s2`` and ``spread`` (t,).

    With σ² = ``scale_model / weight`` (weight = Σ β^{n−m} > 0, after this sample):
    ``s2 = max(recent_rigid − σ², 0)``, ``spread = σ² / novelty_scale``.

    Args:
        scale_model: As :func:`scale_update`.
        recent_rigid: As :func:`scale_update`.
        corr: As :func:`scale_update`.
        y: As :func:`scale_update`.
        rigid: As :func:`scale_update`.
        raw: As :func:`scale_update`.
        beta: As :func:`scale_update`.
        a: As :func:`scale_update`.
        a_corr: As :func:`scale_update`.
        weight: Σ β^{n−m} over the learned samples, including this one (> 0).
        novelty_scale: ν₀ > 0.
        s2: (t,) output, the rigid-body part's systematic error variance.
        spread: (t,) output, the residual's noise variance over ν₀.
    """
    scale_update(scale_model, recent_rigid, corr, y, rigid, raw, beta, a, a_corr)
    for k in range(y.shape[0]):
        noise = scale_model[k] / weight
        diff = recent_rigid[k] - noise
        s2[k] = diff if diff > 0.0 else 0.0
        spread[k] = noise / novelty_scale


@njit(cache=True, nogil=True)
def saving_step(fast_errors: np.ndarray, y: np.ndarray, model: np.ndarray, candidate: np.ndarray, a: float,
                n: int, useful: np.ndarray) -> None:
    """:func:`saving_update`, then :func:`significant_saving` of the new means over n samples into ``useful``.

    Args:
        fast_errors: As :func:`saving_update`.
        y: As :func:`saving_update`.
        model: As :func:`saving_update`.
        candidate: As :func:`saving_update`.
        a: As :func:`saving_update`.
        n: The samples the means average over.
        useful: (t,) bool output.
    """
    saving_update(fast_errors, y, model, candidate, a)
    significant_saving(fast_errors, n, useful)


@njit(cache=True, nogil=True)
def state_weight(x: np.ndarray, inv_scale: np.ndarray, state: np.ndarray) -> float:
    """``κ = exp(−½ Σ_i (x_i s_i − state_i)²)`` over the first ``len(state)`` coordinates of x.

    Args:
        x: The input; its first m entries are used.
        inv_scale: (m,) the inverse length scales s.
        state: (m,) the scaled state of the last learned sample.

    Returns:
        κ ∈ [0, 1].
    """
    acc = 0.0
    for i in range(state.shape[0]):
        d = x[i] * inv_scale[i] - state[i]
        acc += d * d
    return np.exp(-0.5 * acc)


@njit(cache=True, nogil=True)
def tracker_step(estimates: np.ndarray, errors: np.ndarray, gains: np.ndarray, last_error: np.ndarray,
                 last_increment: np.ndarray, cov_increment: np.ndarray, state: np.ndarray,
                 inv_scale: np.ndarray, x: np.ndarray, y: np.ndarray, model: np.ndarray, weight: float,
                 n_errors: int, stats_samples: int, z2: float, noise: np.ndarray, used: np.ndarray) -> None:
    """Absorb one learned sample into the error tracker, in place, and write its noise and used estimate.

    With ``e = y − model`` and n = ``n_errors`` (before this sample), S = ``stats_samples``: the increment
    ``d = e − last_error`` (n ≥ 1) updates ``cov_increment ← cov + b(d·last_increment − cov)``,
    ``b = max(1/(n − 1), 1/S)`` (n ≥ 2) and becomes ``last_increment``; :func:`tracker_update` with
    ``a = max(1/(n + 1), 1/S)``; ``state = x[:m]·inv_scale``; ``last_error = e``; then
    ``noise = max(−cov_increment, 0)`` and ``used`` = :func:`shrunk_choice` (ready once n + 1 ≥ 2).

    Args:
        estimates: (k, t) the smoothers' estimates.
        errors: (k, t) their running a-priori squared errors.
        gains: (k,) the gains K.
        last_error: (t,) the previous sample's error, replaced by e.
        last_increment: (t,) its increment, replaced by d (n ≥ 1).
        cov_increment: (t,) the running E[d_m d_{m−1}].
        state: (m,) output, the scaled state of this sample.
        inv_scale: (m,) the inverse length scales.
        x: The input (its first m entries are the state).
        y: (t,) the measurement.
        model: (t,) the prediction the error is relative to.
        weight: κ at the sample's state (before this update).
        n_errors: Learned samples before this one.
        stats_samples: S.
        z2: z² of the shrinkage.
        noise: (t,) output, the white-noise variance r̂.
        used: (t,) output, the used estimate.
    """
    t = y.shape[0]
    e = np.empty(t)
    for k in range(t):
        e[k] = y[k] - model[k]
    a = max(1.0 / (n_errors + 1), 1.0 / stats_samples)
    if n_errors >= 1:
        b = max(1.0 / (n_errors - 1), 1.0 / stats_samples) if n_errors >= 2 else 0.0
        for k in range(t):
            d = e[k] - last_error[k]
            if n_errors >= 2:
                cov_increment[k] += b * (d * last_increment[k] - cov_increment[k])
            last_increment[k] = d
    tracker_update(estimates, errors, gains, e, weight, a)
    for i in range(state.shape[0]):
        state[i] = x[i] * inv_scale[i]
    for k in range(t):
        last_error[k] = e[k]
        noise[k] = max(-cov_increment[k], 0.0)
    shrunk_choice(estimates, errors, gains, noise, z2, n_errors + 1 >= 2, used)


@njit(cache=True, nogil=True)
def stage_pending(pending_phi: np.ndarray, pending_entries: np.ndarray, pending_beta: np.ndarray, k: int,
                  phi: np.ndarray, Phi_flat: np.ndarray, entries: np.ndarray, beta: float) -> None:
    """Copy one learned sample's features, regressor entries and β into row k of the pending buffers.

    Args:
        pending_phi: (K, D) buffer; row k ← phi.
        pending_entries: (K, E) buffer; row k ← Phi_flat[entries].
        pending_beta: (K,) buffer; entry k ← beta.
        k: The row.
        phi: (D,) the features.
        Phi_flat: The regressor, flattened.
        entries: (E,) indices of its learned entries.
        beta: The step's forgetting factor.
    """
    for i in range(phi.shape[0]):
        pending_phi[k, i] = phi[i]
    for i in range(entries.shape[0]):
        pending_entries[k, i] = Phi_flat[entries[i]]
    pending_beta[k] = beta


@njit(cache=True, nogil=True)
def model_alone_one(x: np.ndarray, Phi: np.ndarray, rigid: np.ndarray, Mp: np.ndarray, Mn: np.ndarray,
                    mean: np.ndarray, scale: np.ndarray, omega: np.ndarray, offset: np.ndarray,
                    amplitude: float, shift: np.ndarray, s2: np.ndarray, spread: np.ndarray,
                    noise: np.ndarray, c: np.ndarray, lam: float, ready: bool, yp: np.ndarray,
                    r: np.ndarray, var: np.ndarray) -> None:
    """Write the consistent SP's model used alone at one state into ``yp``, ``r`` and ``var``, in one call.

    The formulas of ``predict_model`` (the served weight g and ``model_variance``), for a model with no
    pending update:

    * ``ŷ_P = Φπ``; ``var = diag(Φ A_P⁻¹ Φᵀ) + m(v)`` (``‖R_P⁻ᵀ Φ_kᵀ‖²`` per output row k);
    * ``φ = a cos(((x − μ)/s) Ω + b)`` (``standardized_features``, as the learner's own features);
      ``p = φ R⁻¹ d`` and ``v = ‖R⁻ᵀ φᵀ‖²`` (one forward sweep);
      ``raw = p − φ·shift`` (``shift`` (D, t) the rigid-body change's share, or (0, t): none);
    * ``S = s² clip(1 − λv, 0, 1)``, ``g = S / (S + spread·v)`` (1 where that is 0), ``r = g·raw``;
    * ``m(v) = [(1 − g)² S + g² c σ² v + s² ν] / σ²`` (ν = clip(λv, 0, 1); v itself where σ² = 0).

    Not ready (the residual's standardizer in warm-up): ``r = 0`` and ``var = diag(Φ A_P⁻¹ Φᵀ)``.

    Args:
        x: (3n,) the state ``[q, q̇, q̈]``.
        Phi: (t, p) the regressor at x (learner units).
        rigid: (p,) the rigid-body parameters π.
        Mp: (p, p + 1) ``[R_P | d_P]`` of the rigid-body learner (only R_P is read for the variance).
        Mn: (D, D + t) ``[R | d]`` of the residual learner.
        mean: (3n,) the standardizer's μ.
        scale: (3n,) the standardizer's s.
        omega: (3n, D) the frequencies Ω.
        offset: (D,) the phases b [rad].
        amplitude: a = √(2/D).
        shift: (D, t), or (0, t) for none.
        s2: (t,) the rigid-body part's systematic error variance s².
        spread: (t,) the served weight's c σ²/ν₀.
        noise: (t,) the residual's noise variance σ².
        c: (t,) the samples over which the residual's errors stay correlated.
        lam: λ of the residual learner.
        ready: Whether the residual is active.
        yp: (t,) output ŷ_P.
        r: (t,) output g·r.
        var: (t,) output, the relative variance.
    """
    t, p = Phi.shape
    for k in range(t):
        acc = 0.0
        for j in range(p):
            acc += Phi[k, j] * rigid[j]
        yp[k] = acc
    tmp = np.empty((t, Mp.shape[1] - Mp.shape[0]))
    solve_predict(Mp, Phi, tmp, var)
    if not ready:
        for k in range(t):
            r[k] = 0.0
        return
    d = omega.shape[1]
    phi = standardized_features(x, mean, scale, omega, offset, amplitude)
    P = np.empty((1, t))
    vv = np.empty(1)
    solve_predict(Mn, phi, P, vv)
    v = vv[0]
    nu = lam * v
    if nu < 0.0:
        nu = 0.0
    elif nu > 1.0:
        nu = 1.0
    keep = 1.0 - nu  # clip(1 − λv, 0, 1): the same value as clipping 1 − λv itself
    has_shift = shift.shape[0] == d
    for k in range(t):
        raw = P[0, k]
        if has_shift:
            acc = 0.0
            for j in range(d):
                acc += phi[0, j] * shift[j, k]
            raw -= acc
        signal = s2[k] * keep
        total = signal + spread[k] * v
        g = signal / total if total > 0.0 else 1.0
        r[k] = raw * g
        if noise[k] > 0.0:
            extra = ((1.0 - g) ** 2 * s2[k] * keep + g * g * c[k] * noise[k] * v + s2[k] * nu)
            var[k] += extra / noise[k]
        else:
            var[k] += v
