"""Joint-acceleration estimators against scipy's Savitzky–Golay filter and closed-form responses."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import scipy.signal as ss

from semiparam_ros.core.stream.acceleration import (
    AccelerationConfig,
    FiniteDifferenceEstimator,
    SavitzkyGolayEstimator,
    _savgol_weights,
    estimate_accelerations,
    make_estimator,
    savgol_weights_reference,
)

T0 = 5 * 10**9  # a non-zero start stamp (ns)


def run(estimator, stamps_ns, dq):
    """Feed every sample; return all decisions, in order."""
    decisions = []
    for stamp, v in zip(stamps_ns, dq, strict=True):
        decisions.extend(estimator.update(int(stamp), np.atleast_1d(v)))
    return decisions


def estimates(decisions):
    """Split decisions into (stamps in s since T0, ddq array) of those with an estimate."""
    kept = [(s, d) for s, d in decisions if d is not None]
    stamps = np.array([(s - T0) * 1e-9 for s, _ in kept])
    return stamps, np.array([d for _, d in kept])


def uniform_stamps(n, dt):
    return T0 + np.arange(n, dtype=np.int64) * round(dt * 1e9)


def jittered_stamps(n, dt, jitter, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt + rng.uniform(-jitter, jitter, n) * dt
    t[0] = 0.0
    return T0 + np.round(t * 1e9).astype(np.int64)


# ---------------------------------------------------------------------------------------------------
# Savitzky–Golay
# ---------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("window", "polyorder"), [(5, 2), (9, 2), (11, 3), (21, 4)])
def test_savgol_matches_scipy_on_uniform_stamps(window, polyorder):
    dt = 0.002
    rng = np.random.default_rng(1)
    n = 300
    dq = np.cumsum(rng.normal(size=(n, 3)), axis=0)  # arbitrary (rough) velocities of 3 joints
    est = make_estimator(3, AccelerationConfig(window=window, polyorder=polyorder))
    stamps = uniform_stamps(n, dt)
    decisions = run(est, stamps, dq)
    ref = ss.savgol_filter(dq, window, polyorder, deriv=1, delta=dt, axis=0)
    half = window // 2
    got_stamps, got = estimates(decisions)
    np.testing.assert_array_equal(got_stamps, (stamps[half : n - half] - T0) * 1e-9)
    np.testing.assert_allclose(got, ref[half : n - half], rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_savgol_decides_every_stamp_once_with_stated_delay():
    window, dt, n = 9, 0.01, 40
    est = make_estimator(2, AccelerationConfig(window=window))
    stamps = uniform_stamps(n, dt)
    seen = []
    for k, stamp in enumerate(stamps):
        out = est.update(int(stamp), np.zeros(2))
        for s, d in out:
            seen.append(s)
            if d is not None:
                # the estimate refers to the middle of the window: window // 2 samples behind
                assert s == stamps[k - window // 2]
    assert seen == list(stamps[: n - window // 2])  # the newest half window is still pending
    assert est.delay_samples == 4
    assert est.delay_s == pytest.approx(4 * dt, rel=1e-9)
    assert est.lag_s == 0.0
    pending = est.reset()
    assert [s for s, _ in pending] == list(stamps[n - window // 2 :])
    assert all(d is None for _, d in pending)


def savgol_relative_error(window, polyorder, dt, omega):
    """Exact relative amplitude error of the centred SG derivative on a sinusoid (uniform stamps).

    For v = cos(ωt) the estimate is Σ c_k v(t + k·dt) = (Σ c_k sin(ω k dt) / ω) · v'(t), with c_k from
    scipy.signal.savgol_coeffs — an independent computation of the estimator's error.
    """
    c = ss.savgol_coeffs(window, polyorder, deriv=1, delta=dt, use="dot")
    k = np.arange(-(window // 2), window // 2 + 1)
    return abs(np.sum(c * np.sin(omega * k * dt)) / omega - 1.0)


def test_savgol_sinusoid_error_is_the_closed_form_bound():
    dt, freq, amp = 0.01, 1.0, 0.7
    omega = 2 * np.pi * freq
    bound = savgol_relative_error(9, 2, dt, omega)  # 0.77 % of the q̈ amplitude
    assert 0.005 < bound < 0.01
    stamps = uniform_stamps(400, dt)
    ts = (stamps - T0) * 1e-9
    dq = amp * omega * np.cos(omega * ts)  # q = amp sin(ωt)
    s, got = estimates(run(make_estimator(1), stamps, dq))
    truth = -amp * omega**2 * np.sin(omega * s)
    err = np.abs(got[:, 0] - truth)
    assert err.max() <= bound * amp * omega**2 * (1 + 1e-6)
    assert err.max() >= 0.9 * bound * amp * omega**2  # the bound is tight (the estimator is that filter)


def test_savgol_uses_true_stamps_when_they_jitter():
    """±30 % stamp jitter: error stays within 1.5× the uniform-stamp bound; ignoring stamps is 5× worse."""
    dt, freq = 0.01, 1.0
    omega = 2 * np.pi * freq
    bound = savgol_relative_error(9, 2, dt, omega)
    for seed in range(3):
        stamps = jittered_stamps(400, dt, 0.3, seed)
        ts = (stamps - T0) * 1e-9
        dq = np.cos(omega * ts)
        s, got = estimates(run(make_estimator(1), stamps, dq))
        err = np.abs(got[:, 0] + omega * np.sin(omega * s)).max() / omega
        assert err < 1.5 * bound
        naive = ss.savgol_filter(dq, 9, 2, deriv=1, delta=dt)  # nominal rate, stamps ignored
        naive_err = np.abs(naive + omega * np.sin(omega * ts))[4:-4].max() / omega
        assert naive_err > 3 * err


@pytest.mark.parametrize("seed", [0, 1])
def test_savgol_exact_for_polynomial_velocity_on_irregular_stamps(seed):
    # velocity a cubic in time, polyorder 3 → the local fit is exact at any stamps
    stamps = jittered_stamps(120, 0.004, 0.45, seed)
    ts = (stamps - T0) * 1e-9
    coeffs = np.array([[0.3, -1.2, 2.0, -0.7], [1.0, 0.5, -3.0, 4.0]])  # per joint: c0 + c1 t + c2 t² + c3 t³
    dq = np.stack([np.polyval(c[::-1], ts) for c in coeffs], axis=1)
    s, got = estimates(run(make_estimator(2, AccelerationConfig(window=7, polyorder=3)), stamps, dq))
    truth = np.stack([np.polyval(np.polyder(c[::-1]), s) for c in coeffs], axis=1)
    np.testing.assert_allclose(got, truth, rtol=0, atol=1e-8)


def irregular_stamps(n, rng):
    """Strongly irregular stamps: intervals spread over two decades (0.1–10 ms), not a jittered grid."""
    return T0 + np.cumsum(np.round(10 ** rng.uniform(5, 7, n)).astype(np.int64))


def exact_weights(stamps, half, order):
    """Least-squares derivative weights in exact rational arithmetic (normal equations, Gauss–Jordan)."""
    t = [Fraction(int(s - stamps[half]), 10**9) for s in stamps]
    p = order + 1
    V = [[ti**j for j in range(p)] for ti in t]
    A = [[sum(row[a] * row[b] for row in V) for b in range(p)] + [Fraction(int(a == 1))] for a in range(p)]
    for c in range(p):  # VᵀV is positive definite for distinct stamps: no pivoting needed
        A[c] = [x / A[c][c] for x in A[c]]
        for r in range(p):
            if r != c:
                A[r] = [x - A[r][c] * y for x, y in zip(A[r], A[c], strict=True)]
    x = [A[c][p] for c in range(p)]
    return np.array([float(sum(v * xj for v, xj in zip(row, x, strict=True))) for row in V])


EPS = np.finfo(float).eps


@pytest.mark.parametrize(("window", "polyorder"), [(3, 1), (3, 2), (5, 2), (9, 2), (9, 4), (11, 3), (21, 4),
                                                   (21, 8), (51, 2), (7, 6)])
def test_compiled_weights_are_the_exact_least_squares_weights_on_irregular_stamps(window, polyorder):
    """Compiled orthogonal-polynomial weights vs exact rational arithmetic, and vs the ``lstsq`` reference.

    Bounds from the conditioning, not from one machine's last bits:
    - Gram–Schmidt applied twice is backward stable: error ≤ c·m·(p+1)·ε·max|w| with a modest c; c = 8
      is ≥ 26× the worst error measured over these cases (0.92·m·ε).
    - ``lstsq`` on the scaled Vandermonde matrix V has a forward error ≤ c·κ₂(V)·ε·max|w|; c = 64 is
      ≥ 20× the worst measured (2.8·κ·ε). κ₂(V) reaches 1e5 for the (7, 6) fits, which is why a fixed
      relative tolerance toward ``lstsq`` held on one CPU and not on another.
    """
    rng = np.random.default_rng(window * 100 + polyorder)
    half = window // 2
    for _ in range(10):
        stamps = irregular_stamps(window, rng)
        got = _savgol_weights(stamps, half, polyorder)
        exact = exact_weights(stamps, half, polyorder)
        scale = np.abs(exact).max()
        compiled_bound = 8 * window * (polyorder + 1) * EPS * scale
        np.testing.assert_allclose(got, exact, rtol=0, atol=compiled_bound)
        tau = (stamps - stamps[half]) * 1e-9
        kappa = np.linalg.cond(np.vander(tau / np.abs(tau[[0, -1]]).max(), polyorder + 1, increasing=True))
        lstsq = savgol_weights_reference(stamps, half, polyorder)
        np.testing.assert_allclose(lstsq, exact, rtol=0, atol=64 * kappa * EPS * scale)
        np.testing.assert_allclose(got, lstsq, rtol=0, atol=compiled_bound + 64 * kappa * EPS * scale)


@pytest.mark.parametrize(("window", "polyorder"), [(5, 2), (9, 2), (15, 4)])
def test_compiled_weights_equal_scipy_coefficients_on_uniform_stamps(window, polyorder):
    dt_ns = 1_000_000
    stamps = T0 + np.arange(window, dtype=np.int64) * dt_ns
    ref = ss.savgol_coeffs(window, polyorder, deriv=1, delta=dt_ns * 1e-9, use="dot")
    got = _savgol_weights(stamps, window // 2, polyorder)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


def test_streaming_savgol_equals_per_window_least_squares_on_irregular_stamps():
    """Ring buffers and the compiled kernel: every estimate = lstsq weights of its own window @ velocities."""
    rng = np.random.default_rng(11)
    window, polyorder, n = 9, 2, 300
    stamps = irregular_stamps(n, rng)
    dq = rng.normal(size=(n, 3)).cumsum(axis=0)
    decisions = run(make_estimator(3, AccelerationConfig(window=window, polyorder=polyorder)), stamps, dq)
    half = window // 2
    got = [(s, d) for s, d in decisions if d is not None]
    assert [s for s, _ in got] == list(stamps[half : n - half])
    for k, (_, ddq) in enumerate(got):
        w = savgol_weights_reference(stamps[k : k + window], half, polyorder)
        ref = w @ dq[k : k + window]
        np.testing.assert_allclose(ddq, ref, rtol=0, atol=1e-12 * np.abs(w).sum() * np.abs(dq).max())


def test_restarting_after_a_dropout_beats_fitting_across_it():
    """Why acceleration.max_gap_s defaults to 0.1 s: at the paper's 100 Hz (window 9 spans 80 ms) a fit
    across a 300 ms hole is several times worse than the hole-free error; restarting keeps the error at
    the hole-free level, at the price of 2·(window // 2) samples."""
    dt, hole = 0.01, (1.0, 1.3)
    amp, omega = np.array([0.4, 0.6]), 2 * np.pi * np.array([0.5, 1.0])
    t = np.arange(0.0, 2.5, dt)
    t = t[(t < hole[0]) | (t >= hole[1])]
    stamps = T0 + np.round(t * 1e9).astype(np.int64)
    dq = amp * omega * np.cos(omega * t[:, None])
    bound = max(savgol_relative_error(9, 2, dt, w) * a * w**2 for a, w in zip(amp, omega, strict=True))
    errors, counts = {}, {}
    for gap in (None, 0.1):
        s, got = estimate_accelerations(stamps, dq, AccelerationConfig(window=9, max_gap_s=gap))
        ts = (s - T0) * 1e-9
        errors[gap] = np.abs(got + amp * omega**2 * np.sin(omega * ts[:, None])).max()
        counts[gap] = len(s)
    assert errors[0.1] <= bound * (1 + 1e-6)
    assert errors[None] > 5 * errors[0.1]
    assert counts[None] - counts[0.1] == 2 * 4


def test_savgol_noise_gain_matches_stated_formula():
    dt, sigma = 0.01, 0.02
    rng = np.random.default_rng(7)
    n = 20000
    stamps = uniform_stamps(n, dt)
    _, got = estimates(run(make_estimator(1), stamps, sigma * rng.normal(size=n)))
    c = ss.savgol_coeffs(9, 2, deriv=1, use="dot")
    stated = sigma * np.linalg.norm(c) / dt  # ≈ 0.13 σ/Δt
    assert np.std(got) == pytest.approx(stated, rel=0.05)


# ---------------------------------------------------------------------------------------------------
# finite difference
# ---------------------------------------------------------------------------------------------------


def fd_response(window, cutoff_hz, dt, omega):
    """Complex gain from v to the estimate: (1 − e^{−iωS})/S · α/(1 − (1 − α)e^{−iωΔt}), S = (w−1)Δt."""
    span = (window - 1) * dt
    alpha = 1 - math.exp(-dt * 2 * math.pi * cutoff_hz)
    return (1 - np.exp(-1j * omega * span)) / span * alpha / (1 - (1 - alpha) * np.exp(-1j * omega * dt))


@pytest.mark.parametrize(("window", "cutoff_hz", "dt"), [(2, 20.0, 0.01), (3, 20.0, 0.001), (5, 5.0, 0.002)])
def test_finite_difference_steady_state_matches_closed_form(window, cutoff_hz, dt):
    omega = 2 * np.pi * 1.3
    est = make_estimator(
        1, AccelerationConfig(method="finite_difference", window=window, cutoff_hz=cutoff_hz)
    )
    assert isinstance(est, FiniteDifferenceEstimator)
    n = int(3.0 / dt)
    stamps = uniform_stamps(n, dt)
    ts = (stamps - T0) * 1e-9
    decisions = run(est, stamps, np.cos(omega * ts))
    # first window − 1 samples: no estimate; afterwards one estimate per sample, for its own stamp
    assert [d is None for _, d in decisions] == [True] * (window - 1) + [False] * (n - window + 1)
    assert [s for s, _ in decisions] == list(stamps)
    s, got = estimates(decisions)
    expected = np.real(fd_response(window, cutoff_hz, dt, omega) * np.exp(1j * omega * s))
    settled = s > 1.0  # the start-up transient decays with τ = 1/(2π f_c) ≤ 32 ms
    np.testing.assert_allclose(got[settled, 0], expected[settled], atol=1e-9)
    # stated lag = low-frequency group delay of that response
    w0 = 1e-3
    group_delay = -np.angle(fd_response(window, cutoff_hz, dt, w0) / (1j * w0)) / w0
    assert est.lag_s == pytest.approx(group_delay, rel=1e-4)
    assert est.delay_s == 0.0
    # and with the lag compensated the estimate is within the amplitude error of the true q̈
    truth_lagged = -omega * np.sin(omega * (s - est.lag_s))
    gain_err = abs(abs(fd_response(window, cutoff_hz, dt, omega)) / omega - 1)
    phase_err = abs(np.angle(fd_response(window, cutoff_hz, dt, omega) / (1j * omega)) + omega * est.lag_s)
    assert np.abs(got[settled, 0] - truth_lagged[settled]).max() <= omega * (gain_err + phase_err) + 1e-9


def test_finite_difference_exact_for_constant_acceleration_on_irregular_stamps():
    stamps = jittered_stamps(200, 0.005, 0.45, 3)
    ts = (stamps - T0) * 1e-9
    acc = np.array([2.5, -0.4])
    dq = np.array([0.1, 1.0]) + ts[:, None] * acc
    s, got = estimates(
        run(make_estimator(2, AccelerationConfig(method="finite_difference", window=4)), stamps, dq)
    )
    assert len(s) == 200 - 3
    np.testing.assert_allclose(got, np.broadcast_to(acc, got.shape), atol=1e-7)


# ---------------------------------------------------------------------------------------------------
# gaps, invalid input, configuration
# ---------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["savgol", "finite_difference"])
def test_gap_restarts_and_every_stamp_is_decided_once(method):
    cfg = AccelerationConfig(method=method, window=5, max_gap_s=0.05)
    est = make_estimator(1, cfg)
    stamps = list(uniform_stamps(20, 0.01)) + list(uniform_stamps(20, 0.01) + 10**9)  # 1 s gap
    decisions = run(est, stamps, np.linspace(0, 1, 40))
    decisions += est.reset()
    assert [s for s, _ in decisions] == stamps
    n_none = sum(d is None for _, d in decisions)
    # per segment: savgol loses 2 at the head (+2 pending at the end), finite difference 4 at the head
    assert n_none == 2 * 4


@pytest.mark.parametrize("method", ["savgol", "finite_difference"])
def test_invalid_updates_raise_and_leave_state_untouched(method):
    cfg = AccelerationConfig(method=method, window=5)
    stamps = uniform_stamps(30, 0.01)
    ts = (stamps - T0) * 1e-9
    clean = make_estimator(1, cfg)
    dirty = make_estimator(1, cfg)
    ref, got = [], []
    for k, stamp in enumerate(stamps):
        v = np.array([np.sin(ts[k])])
        ref += clean.update(int(stamp), v)
        with pytest.raises(ValueError, match="NaN"):
            dirty.update(int(stamp), np.array([np.nan]))
        with pytest.raises(ValueError, match="shape"):
            dirty.update(int(stamp), np.zeros(2))
        got += dirty.update(int(stamp), v)
        with pytest.raises(ValueError, match="increase"):
            dirty.update(int(stamp), v)
        with pytest.raises(ValueError, match="increase"):
            dirty.update(int(stamp) - 1, v)
    assert len(ref) == len(got)
    for (s1, d1), (s2, d2) in zip(ref, got, strict=True):
        assert s1 == s2
        assert (d1 is None and d2 is None) or np.array_equal(d1, d2)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"method": "kalmann"},  # "kalman" is a method now; a misspelt one is not
        {"window": 8},  # even for savgol
        {"window": 1, "method": "finite_difference"},
        {"window": 5, "polyorder": 5},
        {"window": 5, "polyorder": 0},
        {"cutoff_hz": 0.0},
        {"cutoff_hz": float("nan")},
        {"max_gap_s": -1.0},
        {"window": 5.0},
    ],
)
def test_invalid_config_raises(kwargs):
    with pytest.raises(ValueError):
        AccelerationConfig(**kwargs)


def test_defaults_and_factory():
    cfg = AccelerationConfig()
    assert (cfg.method, cfg.window, cfg.polyorder) == ("savgol", 9, 2)
    assert isinstance(make_estimator(4), SavitzkyGolayEstimator)
    est = make_estimator(4, AccelerationConfig(method="finite_difference", cutoff_hz=math.inf, window=2))
    assert math.isnan(est.lag_s)  # no interval seen yet
    run(est, uniform_stamps(3, 0.01), np.zeros((3, 4)))
    assert est.lag_s == pytest.approx(0.005)  # plain backward difference: half a step
    with pytest.raises(ValueError):
        make_estimator(0)


@pytest.mark.parametrize("method", ["savgol", "finite_difference"])
def test_batch_helper_equals_streaming(method):
    cfg = AccelerationConfig(method=method, window=7)
    stamps = jittered_stamps(100, 0.01, 0.2, 4)
    dq = np.sin(np.outer((stamps - T0) * 1e-9, [1.0, 2.0, 3.0]))
    s_ref, d_ref = estimates(run(make_estimator(3, cfg), stamps, dq))
    s_got, d_got = estimate_accelerations(stamps, dq, cfg)
    np.testing.assert_array_equal((s_got - T0) * 1e-9, s_ref)
    np.testing.assert_array_equal(d_got, d_ref)
    _, d1 = estimate_accelerations(stamps, dq[:, 0], cfg)
    np.testing.assert_allclose(d1[:, 0], d_ref[:, 0], rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError):
        estimate_accelerations(stamps[:-1], dq, cfg)
    with pytest.raises(ValueError):
        estimate_accelerations(stamps[::-1], dq, cfg)
