"""The consistent SP's compiled step kernels against numpy implementations of their formulas.

Element-wise kernels must agree bit for bit (same IEEE operations in the same order); the residual's sum
over the regressor entries is accumulated in another order than numpy's matrix product, so it agrees to
the rounding bound ``n·ε·Σ|P_e δ_c(e)|`` of a sum of n terms.
"""

from __future__ import annotations

import numpy as np
import pytest

from semiparam_ros.core.learners._consistent_kernels import (
    aged_saving_step,
    fast_total,
    saving_step,
    saving_update,
    scale_step,
    scale_update,
    shrunk_choice,
    significant_saving,
    stage_pending,
    state_weight,
    tracker_step,
    tracker_update,
    weighted_residual,
)

EPS = np.finfo(float).eps


@pytest.mark.parametrize("seed", range(5))
def test_weighted_residual_is_the_residual_with_its_wiener_weight(seed):
    rng = np.random.default_rng(seed)
    t = 6
    raw = rng.normal(size=t)
    s2 = rng.uniform(0.0, 2.0, size=t)
    s2[0] = 0.0  # an output whose rigid body is exact: weight 0
    spread = rng.uniform(0.0, 1.0, size=t)
    spread[1] = 0.0
    s2[1] = 0.0  # 0/0: weight 1
    lam, v = 1e-3, float(rng.uniform(0.0, 2000.0))
    out = np.empty(t)
    weighted_residual(raw, s2, spread, lam, v, out)
    signal = s2 * np.clip(1.0 - lam * v, 0.0, 1.0)
    total = signal + spread * v
    g = np.divide(signal, total, out=np.ones_like(total), where=total > 0.0)
    assert g[0] == 0.0 and g[1] == 1.0
    assert np.array_equal(out, raw * g)  # the weight element-wise: bit for bit


@pytest.mark.parametrize("seed", range(5))
def test_fast_total_is_the_model_plus_the_weighted_corrections(seed):
    rng = np.random.default_rng(seed)
    t = 7
    model, c = rng.normal(size=t), rng.normal(size=t)
    v, noise = rng.uniform(0.0, 0.1, size=t), rng.uniform(0.0, 1.0, size=t)
    c[0] = 0.0
    useful = rng.uniform(size=t) < 0.7
    used = rng.normal(size=t)
    kappa_fast, kappa = rng.uniform(size=t), rng.uniform(size=t)
    applied, fast, total = np.empty(t), np.empty(t), np.empty(t)
    rigid, residual, correction = rng.normal(size=t), np.empty(t), np.empty(t)
    fast_total(model, c, v, noise, kappa_fast, useful, kappa, used, applied, fast, total, rigid, residual,
               correction)
    ref_applied = kappa_fast * c
    nk = 9.0 * noise * v
    c2 = c * c
    w = np.where(c2 > nk, 1.0 - nk / np.where(c2 > 0.0, c2, 1.0), 0.0)
    ref_fast = model + np.where(useful, w, 0.0) * ref_applied
    assert np.array_equal(applied, ref_applied)
    assert np.array_equal(fast, ref_fast)
    assert np.array_equal(total, ref_fast + kappa * used)
    assert np.array_equal(residual, total - rigid) and np.array_equal(correction, total - model)


def test_tracker_update_is_the_smoothers_recursion():
    rng = np.random.default_rng(3)
    gains = np.array([0.0, 0.1, 0.3, 1.0])
    est, err = rng.normal(size=(4, 5)), rng.uniform(size=(4, 5))
    ref_est, ref_err = est.copy(), err.copy()
    for _ in range(20):
        e, w, a = rng.normal(size=5), float(rng.uniform()), float(rng.uniform(0.01, 0.5))
        tracker_update(est, err, gains, e, w, a)
        prior = w * ref_est
        miss = e - prior
        ref_err += a * (miss * miss - ref_err)
        ref_est = prior + gains[:, None] * miss
    assert np.array_equal(est, ref_est) and np.array_equal(err, ref_err)


def test_scale_and_saving_updates_are_their_running_means():
    rng = np.random.default_rng(4)
    t = 6
    scale_model, recent = rng.uniform(size=t), rng.uniform(size=t)
    fast_errors = rng.normal(size=(2, t))
    corr = np.stack([rng.normal(size=t), rng.uniform(size=t)])
    ref_sm, ref_rr, ref_fe, ref_corr = scale_model.copy(), recent.copy(), fast_errors.copy(), corr.copy()
    for _ in range(20):
        y, rigid, raw = rng.normal(size=t), rng.normal(size=t), rng.normal(size=t)
        beta, a, a_corr = float(rng.uniform(0.9, 1.0)), float(rng.uniform(0.01, 0.5)), float(rng.uniform())
        scale_update(scale_model, recent, corr, y, rigid, raw, beta, a, a_corr)
        e_rigid = y - rigid
        e_model = e_rigid - raw
        ref_sm = beta * ref_sm + e_model * e_model
        ref_rr += a * (e_rigid * e_rigid - ref_rr)
        ref_corr[0] += a_corr * (e_model - ref_corr[0])
        ref_corr[1] = beta * ref_corr[1] + ref_corr[0] * ref_corr[0]
        model, cand = rng.normal(size=t), rng.normal(size=t)
        saving_update(fast_errors, y, model, cand, a)
        e0 = y - model
        gain = e0 * e0 - (e0 - cand) ** 2
        ref_fe += a * (np.stack([gain, gain * gain]) - ref_fe)
    assert np.array_equal(scale_model, ref_sm) and np.array_equal(recent, ref_rr)
    assert np.array_equal(fast_errors, ref_fe) and np.array_equal(corr, ref_corr)


@pytest.mark.parametrize("seed", range(5))
def test_shrunk_choice_is_the_smallest_errors_estimate_shrunk_by_its_noise(seed):
    rng = np.random.default_rng(seed)
    gains = np.array([0.0, 0.1, 0.3, 1.0])
    est = rng.normal(scale=0.3, size=(4, 8))
    err = rng.uniform(size=(4, 8))
    err[:, 0] = 0.5  # a tie: the first smoother
    noise = rng.uniform(0.0, 0.1, size=8)
    for ready in (False, True):
        out = np.empty(8)
        shrunk_choice(est, err, gains, noise, 4.0, ready, out)
        chosen = np.argmin(err, axis=0) if ready else np.zeros(8, dtype=np.int64)
        b = est[chosen, np.arange(8)]
        k = gains[chosen]
        nk = 4.0 * noise * k / (2.0 - k)
        b2 = b * b
        ref = np.where(b2 > nk, b * (1.0 - nk / np.where(b2 > 0.0, b2, 1.0)), 0.0)
        assert np.array_equal(out, ref)


def test_significant_saving_is_two_standard_errors():
    rng = np.random.default_rng(5)
    mean = rng.normal(size=9)
    square = mean ** 2 + rng.uniform(-0.1, 1.0, size=9)  # a negative spread (rounding) counts as 0
    fe = np.stack([mean, square])
    for n in (0, 1, 2, 30):
        out = np.empty(9, dtype=np.bool_)
        significant_saving(fe, n, out)
        if n < 2:
            assert not out.any()
            continue
        ref = mean > 2.0 * np.sqrt(np.maximum(square - mean * mean, 0.0) / n)
        assert np.array_equal(out, ref)


def test_scale_step_is_the_update_then_the_weight_scales():
    rng = np.random.default_rng(6)
    t = 5
    sm, rr = rng.uniform(size=t), rng.uniform(size=t)
    corr = np.stack([rng.normal(size=t), rng.uniform(size=t)])
    ref_sm, ref_rr, ref_corr = sm.copy(), rr.copy(), corr.copy()
    y, rigid, raw = rng.normal(size=t), rng.normal(size=t), rng.normal(size=t)
    raw[0] = y[0] - rigid[0]  # an output the residual explains: s² clipped at 0 below
    s2, spread = np.empty(t), np.empty(t)
    scale_step(sm, rr, corr, y, rigid, raw, 0.98, 0.1, 0.05, 3.5, 0.25, s2, spread)
    scale_update(ref_sm, ref_rr, ref_corr, y, rigid, raw, 0.98, 0.1, 0.05)
    assert np.array_equal(sm, ref_sm) and np.array_equal(rr, ref_rr) and np.array_equal(corr, ref_corr)
    noise = ref_sm / 3.5
    assert np.array_equal(s2, np.maximum(ref_rr - noise, 0.0)) and np.array_equal(spread, noise / 0.25)


def test_saving_step_is_the_update_then_its_significance():
    rng = np.random.default_rng(7)
    t = 6
    fe = rng.normal(size=(2, t))
    ref = fe.copy()
    y, model, cand = rng.normal(size=t), rng.normal(size=t), rng.normal(size=t)
    useful = np.empty(t, dtype=np.bool_)
    saving_step(fe, y, model, cand, 0.2, 9, useful)
    saving_update(ref, y, model, cand, 0.2)
    expect = np.empty(t, dtype=np.bool_)
    significant_saving(ref, 9, expect)
    assert np.array_equal(fe, ref) and np.array_equal(useful, expect)


def _aged_reference(errors, y, Phi, theta, phi, W, s2, spread, lam, v, a, window, corr_sq, scale_model,
                    a_corr, min_evidence):
    """``aged_saving_step``'s formulas with numpy: the new means and the decision."""
    keep = min(max(1.0 - lam * v, 0.0), 1.0)
    signal = s2 * keep
    total = signal + spread * v
    g = np.where(total > 0.0, signal / np.where(total > 0.0, total, 1.0), 1.0)
    e = y - Phi @ theta
    gain = e ** 2 - (e - g * (phi @ W)) ** 2
    mean = errors[0] + a * (gain - errors[0])
    square = errors[1] + a * (gain ** 2 - errors[1])
    c = np.maximum(np.where(scale_model > 0.0, corr_sq / np.where(scale_model > 0.0, scale_model, 1.0), 0.0)
                   * (2.0 - a_corr) / a_corr, 1.0)
    n = window / c
    harm = mean < -2.0 * np.sqrt(np.maximum(square - mean ** 2, 0.0) / n)
    return np.stack([mean, square]), np.where(n < min_evidence, True, ~harm)


@pytest.mark.parametrize("seed", range(4))
def test_aged_saving_step_is_the_saving_of_the_weighted_aged_residual_then_the_harm_test(seed):
    """The aged copy's saving e² − (e − g·φW)² (e the aged rigid body's error) enters the running means,
    and an output is dropped only where the mean is negative by more than two standard errors over
    window/c effective samples; outputs with too little evidence keep the residual. The sums over p and D
    are accumulated in another order than numpy's products: agreement to a bound on their rounding."""
    rng = np.random.default_rng(seed)
    t, p, D = 5, 4, 30
    errors = np.stack([rng.normal(0.0, 0.05, t), rng.uniform(0.0, 0.01, t)])
    y, Phi, theta = rng.normal(size=t), rng.normal(size=(t, p)), rng.normal(size=p)
    phi, W = rng.normal(size=D), rng.normal(0.0, 0.3, size=(D, t))
    s2, spread = rng.uniform(0.0, 1.0, t), rng.uniform(0.0, 1.0, t)
    s2[0] = spread[0] = 0.0  # 0/0: weight 1
    corr_sq, scale_model = rng.uniform(0.0, 0.02, t), rng.uniform(0.5, 1.0, t)  # c of 1 to 2
    scale_model[1] = 0.0  # no statistics: c = 1
    corr_sq[2] = 50.0  # long correlation: too little evidence, the residual is kept
    args = (y, Phi, theta, phi, W, s2, spread, 0.1, 0.7, 0.01, 400.0, corr_sq, scale_model, 0.05, 10.0)
    ref_errors, ref_use = _aged_reference(errors, *args)
    use = np.empty(t, dtype=np.bool_)
    got = errors.copy()
    aged_saving_step(got, *args, use)
    e = np.abs(y) + np.abs(Phi) @ np.abs(theta)
    bound = 8 * (D + p) * EPS * (e + np.abs(phi) @ np.abs(W)) ** 2  # the sums' rounding, squared terms
    np.testing.assert_allclose(got[0], ref_errors[0], rtol=0, atol=float(bound.max()))
    np.testing.assert_allclose(got[1], ref_errors[1], rtol=0,
                               atol=float((4 * bound * (e + np.abs(phi) @ np.abs(W)) ** 2).max()))
    assert np.array_equal(use, ref_use)
    assert use[2]  # n = 400 / c < 10
    harmful = np.stack([np.full(t, -0.5), np.full(t, 0.26)])  # mean −0.5 with spread 0.01: harm is clear
    use_h = np.empty(t, dtype=np.bool_)
    aged_saving_step(harmful, *args[:8], 0.0, *args[9:], use_h)  # a = 0: the means stay where they are
    assert not use_h[[0, 1, 3, 4]].any() and use_h[2]


def test_state_weight_is_the_gaussian_of_the_scaled_distance():
    rng = np.random.default_rng(8)
    x, inv, state = rng.normal(size=9), rng.uniform(0.5, 5.0, size=6), rng.normal(size=6)
    d = x[:6] * inv - state
    # a sum of 6 squares: rounding ≤ 6ε relative in the exponent's argument
    assert state_weight(x, inv, state) == pytest.approx(np.exp(-0.5 * np.sum(d * d)), rel=1e-14)


def test_tracker_step_is_the_trackers_recursion():
    """The increments' covariance, the smoothers, the state and r̂, b̂ against their numpy formulas."""
    rng = np.random.default_rng(9)
    t, m, S = 4, 6, 10
    gains = np.array([0.0, 0.1, 0.3, 1.0])
    est, err = np.zeros((4, t)), np.zeros((4, t))
    last_e, last_d, cov = np.zeros(t), np.zeros(t), np.zeros(t)
    state, inv = np.empty(m), rng.uniform(0.5, 5.0, size=m)
    r_est, r_err, r_last_e, r_last_d, r_cov = est.copy(), err.copy(), last_e.copy(), last_d.copy(), cov.copy()
    for n in range(15):
        x, y, model = rng.normal(size=9), rng.normal(size=t), rng.normal(size=t)
        w = float(rng.uniform())
        noise, used = np.empty(t), np.empty(t)
        tracker_step(est, err, gains, last_e, last_d, cov, state, inv, x, y, model, w, n, S, 4.0, noise, used)
        e = y - model
        a = max(1.0 / (n + 1), 1.0 / S)
        if n >= 1:
            d = e - r_last_e
            if n >= 2:
                r_cov += max(1.0 / (n - 1), 1.0 / S) * (d * r_last_d - r_cov)
            r_last_d = d
        tracker_update(r_est, r_err, gains, e, w, a)
        r_last_e = e
        ref_noise = np.maximum(-r_cov, 0.0)
        ref_used = np.empty(t)
        shrunk_choice(r_est, r_err, gains, ref_noise, 4.0, n + 1 >= 2, ref_used)
        assert np.array_equal(est, r_est) and np.array_equal(err, r_err) and np.array_equal(cov, r_cov)
        assert np.array_equal(last_e, r_last_e) and np.array_equal(last_d, r_last_d)
        assert np.array_equal(state, x[:m] * inv)
        assert np.array_equal(noise, ref_noise) and np.array_equal(used, ref_used)


def test_stage_pending_copies_the_row():
    rng = np.random.default_rng(10)
    pphi, pent, pbeta = np.zeros((4, 7)), np.zeros((4, 3)), np.zeros(4)
    phi, Phi = rng.normal(size=7), rng.normal(size=(2, 5))
    entries = np.array([0, 4, 8])
    stage_pending(pphi, pent, pbeta, 2, phi, Phi.reshape(-1), entries, 0.9)
    assert np.array_equal(pphi[2], phi) and np.array_equal(pent[2], Phi.reshape(-1)[entries])
    assert pbeta[2] == 0.9 and not pphi[[0, 1, 3]].any() and not pent[[0, 1, 3]].any()
