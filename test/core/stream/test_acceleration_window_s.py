"""acceleration.window_s: a window in seconds, sized at the measured joint-state rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.build import build_pipeline
from semiparam_ros.core.stream.acceleration import (
    RATE_SAMPLES,
    AccelerationConfig,
    RateAdaptiveEstimator,
    estimate_accelerations,
    make_estimator,
    samples_for_window,
)

T0 = 7 * 10**9
WINDOW_S = 0.08  # 9 samples at 100 Hz: the window of the iCub file (the paper's protocol)
DEFAULT_WINDOW_S, DEFAULT_POLYORDER = 0.12, 3  # the node's defaults (acceleration.window_s, .polyorder)
# v(t) = Σ a_k sin(ω_k t + φ_k): smooth joint velocities [rad/s] with content up to 1.5 Hz (excitation band)
AMPS = np.array([0.4, 0.25, 0.15])
FREQS = np.array([0.3, 0.8, 1.5])  # Hz
PHASES = np.array([0.1, 1.3, 2.0])


def velocity(t: np.ndarray, deriv: int = 0) -> np.ndarray:
    w = 2 * np.pi * FREQS
    return (AMPS * w**deriv * np.sin(w * t[:, None] + PHASES + deriv * np.pi / 2)).sum(axis=1)


@pytest.mark.parametrize(("rate_hz", "expected"), [(100.0, 9), (200.0, 17), (1000.0, 81)])
def test_window_s_gives_the_stated_sample_count_and_delay(rate_hz, expected):
    dt = 1.0 / rate_hz
    assert samples_for_window(WINDOW_S, dt) == expected
    est = make_estimator(1, AccelerationConfig(window_s=WINDOW_S))
    assert isinstance(est, RateAdaptiveEstimator) and est.window == 0
    stamps = T0 + np.arange(RATE_SAMPLES + 5) * round(dt * 1e9)
    for s in stamps:
        est.update(int(s), np.zeros(1))
    assert est.window == expected
    assert est.delay_s == pytest.approx(expected // 2 * dt, rel=1e-9)  # ≈ window_s / 2 = 40 ms


@pytest.mark.parametrize("rate_hz", [100.0, 1000.0])
def test_window_s_estimates_a_smooth_signal_within_the_derived_bias(rate_hz):
    """Noise-free: the centred degree-2 fit's derivative is the least-squares slope Σtᵢvᵢ/Σtᵢ² (the even
    terms drop out by symmetry), so by Taylor's theorem its error is at most
    |v'''|max·Σt⁴/(6Σt²) + |v⁽⁵⁾|max·Σt⁶/(120Σt²) (t = offsets in the window). That bound is computed here
    from the window the estimator chose, and it is itself below 1 % of max|q̈| at both rates."""
    dt = 1.0 / rate_hz
    t = np.arange(0, 10.0, dt)
    stamps = T0 + np.round(t * 1e9).astype(np.int64)
    got_t, got = estimate_accelerations(stamps, velocity(t), AccelerationConfig(window_s=WINDOW_S))
    m = samples_for_window(WINDOW_S, dt)
    assert len(got_t) == len(t) - 2 * (m // 2)  # every sample but the two half windows
    offs = (np.arange(m) - m // 2) * dt
    s2, s4, s6 = (offs**2).sum(), (offs**4).sum(), (offs**6).sum()
    w = 2 * np.pi * FREQS
    bound = (AMPS * w**3).sum() * s4 / (6 * s2) + (AMPS * w**5).sum() * s6 / (120 * s2)
    truth = velocity((got_t - T0) * 1e-9, deriv=1)
    err = np.abs(got[:, 0] - truth).max()
    assert err <= bound * (1 + 1e-6) + 1e-9
    assert bound < 0.01 * np.abs(truth).max()


@pytest.mark.parametrize("rate_hz", [100.0, 1000.0])
def test_the_default_cubic_fit_has_no_gain_bias_where_the_quadratic_has_one(rate_hz):
    """Noise-free, at the node's defaults. The degree-3 fit's slope at the centre is exact for velocities
    of degree ≤ 4 (the odd weights of a symmetric window), so by Taylor's theorem its error is at most
    max|v⁽⁵⁾| Σ|wᵢ||tᵢ|⁵/120, wᵢ its derivative weights (computed here by an independent least squares,
    ``numpy.linalg.lstsq`` of the Vandermonde matrix). The degree-2 fit of the same window instead
    attenuates each component by the gain G(ωh) = Σ tᵢ sin(ωtᵢ) / (ω Σ tᵢ²), whose error 1 − G ≈ (ωh)²/10
    is systematic; the cubic's bound is below a tenth of that error."""
    dt = 1.0 / rate_hz
    t = np.arange(0, 10.0, dt)
    stamps = T0 + np.round(t * 1e9).astype(np.int64)
    cubic = AccelerationConfig(window_s=DEFAULT_WINDOW_S, polyorder=DEFAULT_POLYORDER)
    got_t, got = estimate_accelerations(stamps, velocity(t), cubic)
    m = samples_for_window(DEFAULT_WINDOW_S, dt, "savgol", DEFAULT_POLYORDER)
    offs = (np.arange(m) - m // 2) * dt
    vander = np.vander(offs, DEFAULT_POLYORDER + 1, increasing=True)
    weights = np.linalg.lstsq(vander, np.eye(m), rcond=None)[0][1]  # the fitted slope at t = 0
    w = 2 * np.pi * FREQS
    bound = (AMPS * w**5).sum() * (np.abs(weights) * np.abs(offs) ** 5).sum() / 120
    truth = velocity((got_t - T0) * 1e-9, deriv=1)
    assert np.abs(got[:, 0] - truth).max() <= bound * (1 + 1e-6) + 1e-9
    # the quadratic of the same window: its error is the gain's, component by component
    q_t, quad = estimate_accelerations(stamps, velocity(t), AccelerationConfig(window=m, polyorder=2))
    gain = np.array([(offs * np.sin(wk * offs)).sum() / (wk * (offs**2).sum()) for wk in w])
    arg = w * ((q_t - T0) * 1e-9)[:, None] + PHASES + np.pi / 2
    expected = (AMPS * w * gain * np.sin(arg)).sum(axis=1)
    np.testing.assert_allclose(quad[:, 0], expected, rtol=0, atol=1e-9 * np.abs(expected).max() + 1e-12)
    quad_error = np.abs(quad[:, 0] - velocity((q_t - T0) * 1e-9, deriv=1)).max()
    assert bound < 0.1 * quad_error


def test_window_s_equals_the_fixed_sample_window_at_the_measured_rate():
    """Same decisions (stamps and values, bit for bit) as a fixed window of the sample count it chose,
    with a jittered 1 kHz stream: the held samples are replayed into that estimator."""
    rng = np.random.default_rng(4)
    n = 400
    stamps = T0 + np.cumsum(rng.integers(900_000, 1_100_000, size=n))  # 1 kHz ± 10 %
    dq = rng.normal(size=(n, 3))
    s_a, a = estimate_accelerations(stamps, dq, AccelerationConfig(window_s=WINDOW_S))
    dts = np.diff(stamps[:RATE_SAMPLES]) * 1e-9
    m = samples_for_window(WINDOW_S, float(np.median(dts)))
    s_b, b = estimate_accelerations(stamps, dq, AccelerationConfig(window=m))
    np.testing.assert_array_equal(s_a, s_b)
    np.testing.assert_array_equal(a, b)


def test_rate_measurement_ignores_dropouts_and_keeps_every_stamp_decided_once():
    cfg = AccelerationConfig(window_s=WINDOW_S, max_gap_s=0.1)
    est = make_estimator(1, cfg)
    stamps = list(T0 + np.arange(10) * 10_000_000)  # 100 Hz
    stamps += list(stamps[-1] + 500_000_000 + np.arange(40) * 10_000_000)  # a 0.5 s dropout, then 100 Hz
    decided = []
    for s in stamps:
        decided += [d for d, _ in est.update(int(s), np.zeros(1))]
    decided += [d for d, _ in est.reset()]
    assert est.window == 9  # the dropout is not the rate
    assert sorted(decided) == decided == [int(s) for s in stamps]


def test_config_window_in_samples_still_overrides_window_s():
    """Old files with acceleration.window (samples) keep working: a non-zero value wins; 0 uses window_s."""
    joints = ["a", "b"]
    base = {"robot.joints": joints, "robot.output": "joint_torques", "robot.ft_sensor": ""}
    fixed = build_pipeline(EstimatorConfig.from_flat({**base, "acceleration.window": 11}))
    assert fixed.acceleration.window_s is None and fixed.acceleration.window == 11
    adaptive = build_pipeline(EstimatorConfig.from_flat(base))
    assert adaptive.acceleration.window_s == DEFAULT_WINDOW_S
    assert adaptive.acceleration.polyorder == DEFAULT_POLYORDER
    with pytest.raises(ValueError, match=r"acceleration\.window"):
        EstimatorConfig.from_flat({**base, "acceleration.window": 2})
    with pytest.raises(ValueError, match=r"acceleration\.window_s"):
        EstimatorConfig.from_flat({**base, "acceleration.window_s": 0.0})
    with pytest.raises(ValueError, match="window_s"):
        AccelerationConfig(window_s=math.nan)
    with pytest.raises(ValueError, match="cutoff_hz"):  # the other settings are still checked
        AccelerationConfig(window_s=0.08, method="finite_difference", cutoff_hz=-1.0)
    with pytest.raises(ValueError, match="max_gap_s"):
        AccelerationConfig(window_s=0.08, max_gap_s=math.inf)
