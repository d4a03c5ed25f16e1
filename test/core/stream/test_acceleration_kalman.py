"""Constant-jerk Kalman q̈ estimator against independent computations.

References: the exact discretisation by Van Loan's matrix exponential (scipy.linalg.expm), the filtered
state as the last state of a dense batch weighted least-squares (MAP) problem over the whole sequence, the
steady-state gain from scipy.linalg.solve_discrete_are and its frequency response, the continuous
Kalman–Bucy filter's error transfer, and exact tracking of a constant-jerk signal.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.signal as ss

from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
from semiparam_ros.core.estimator.build import build_pipeline
from semiparam_ros.core.stream.acceleration import (
    KALMAN_PRIOR_VARIANCE,
    KALMAN_SETTLE,
    KALMAN_STATES,
    AccelerationConfig,
    KalmanEstimator,
    _kalman_step,
    estimate_accelerations,
    kalman_matrices,
    kalman_step_reference,
    make_estimator,
)
from semiparam_ros.errors import ConfigurationError, RejectedSampleError

EPS = np.finfo(float).eps
T0 = 5 * 10**9  # a non-zero start stamp (ns)


def kalman(bandwidth_hz: float = 8.0, kalman_model: str = "jerk", **kw) -> AccelerationConfig:
    return AccelerationConfig(method="kalman", bandwidth_hz=bandwidth_hz, kalman_model=kalman_model, **kw)


def jittered_stamps(n: int, dt: float, jitter: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt + rng.uniform(-jitter, jitter, n) * dt
    t[0] = 0.0
    return T0 + np.round(t * 1e9).astype(np.int64)


def feed(est, stamps, dq):
    out = []
    for s, v in zip(stamps.tolist(), dq, strict=True):
        out.extend(est.update(int(s), np.atleast_1d(v)))
    return out


@pytest.mark.parametrize("m", [3, 4])
@pytest.mark.parametrize("h", [1e-3, 0.05, 0.6, 2.0])
def test_discretisation_is_van_loans_exact_one(h, m):
    """F = exp(A h), Q = ∫ exp(As) G Gᵀ exp(Aᵀs) ds from one matrix exponential (Van Loan 1978)."""
    A = np.diag(np.ones(m - 1), 1)
    G = np.zeros((m, 1))
    G[-1, 0] = 1.0
    M = np.zeros((2 * m, 2 * m))
    M[:m, :m] = -A
    M[:m, m:] = G @ G.T
    M[m:, m:] = A.T
    E = sla.expm(M * h)
    F_ref = E[m:, m:].T
    Q_ref = F_ref @ E[:m, m:]
    F, Q, R = kalman_matrices(h, m)
    # expm is accurate to a few ε relative to ‖exp(M h)‖ ≤ exp(2h)-ish; Q's entries span h⁵..h, so
    # compare each entry relative to its own size (measured agreement ≤ 1e-13, margin ≥ 100×)
    np.testing.assert_allclose(F, F_ref, rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(Q, Q_ref, rtol=1e-9, atol=1e-14 * h)
    assert R == 1.0 / h


@pytest.mark.parametrize("m", [3, 4])
@pytest.mark.parametrize("h", [0.01, 0.3, 1.5])
def test_compiled_step_equals_numpy_reference(h, m):
    rng = np.random.default_rng(3)
    x = rng.normal(size=(m, 5))
    L = rng.normal(size=(m, m))
    P = L @ L.T + np.eye(m)
    z = rng.normal(size=5)
    x_ref, P_ref = kalman_step_reference(x, P, h, z)
    x2, P2 = x.copy(), P.copy()
    _kalman_step(x2, P2, h, z)
    # a few dozen flops per entry on O(‖P‖ + 1/h) numbers: 64 ε of that scale bounds the rounding gap
    scale = np.abs(P).max() + 1.0 / h + np.abs(x).max() + np.abs(z).max()
    np.testing.assert_allclose(x2, x_ref, rtol=0, atol=64 * EPS * scale)
    np.testing.assert_allclose(P2, P_ref, rtol=0, atol=64 * EPS * scale)
    np.testing.assert_array_equal(P2, P2.T)


def batch_map_last_state(stamps_ns, z, omega, m=3):
    """Dense weighted least squares over all states x_0..x_N (scaled units): prior on q̈/ω and jerk/ω²
    only (velocity diffuse), measurement of x_0's velocity with the first interval's variance, dynamics
    residuals whitened by the Cholesky factor of Q_i, measurements by √h_i. Returns (x_N, cond)."""
    n = len(stamps_ns)
    h = omega * np.diff(stamps_ns) * 1e-9
    rows, rhs = [], []
    nv = m * n

    def row():
        return np.zeros(nv)

    for c in range(1, m):  # prior, mean 0, variance KALMAN_PRIOR_VARIANCE
        r = row()
        r[c] = 1.0 / math.sqrt(KALMAN_PRIOR_VARIANCE)
        rows.append(r)
        rhs.append(0.0)
    for i in range(n):
        hi = h[0] if i == 0 else h[i - 1]
        r = row()
        r[m * i] = math.sqrt(hi)
        rows.append(r)
        rhs.append(math.sqrt(hi) * z[i])
        if i == 0:
            continue
        F, Q, _ = kalman_matrices(h[i - 1], m)
        L = np.linalg.cholesky(Q)
        block = np.zeros((m, nv))
        block[:, m * i : m * i + m] = np.eye(m)
        block[:, m * (i - 1) : m * i] = -F
        white = sla.solve_triangular(L, block, lower=True)
        rows.extend(white)
        rhs.extend([0.0] * m)
    A = np.array(rows)
    b = np.array(rhs)
    sol = np.linalg.lstsq(A, b, rcond=None)[0]
    return sol[-m:], np.linalg.cond(A)


@pytest.mark.parametrize("model", ["jerk", "snap"])
def test_filtered_estimate_equals_batch_least_squares_on_irregular_stamps(model):
    """The streaming q̈ at each stamp equals ω·(q̈/ω) of the last state of the batch MAP problem using the
    samples up to that stamp (the Kalman filter is the recursive solution of that problem)."""
    bw = 10.0
    omega = 2 * math.pi * bw
    stamps = jittered_stamps(24, 0.01, 0.3, seed=4)
    rng = np.random.default_rng(5)
    t = (stamps - T0) * 1e-9
    z = np.sin(3.0 * t) + 0.01 * rng.normal(size=t.size)
    est = make_estimator(1, kalman(bw, kalman_model=model))
    decided = feed(est, stamps, z[:, None])
    assert [s for s, _ in decided] == stamps.tolist()
    checked = 0
    for k, (stamp, ddq) in enumerate(decided):
        if ddq is None:
            assert (stamp - T0) * 1e-9 < KALMAN_SETTLE[model] / omega
            continue
        assert (stamp - T0) * 1e-9 >= KALMAN_SETTLE[model] / omega - 1e-12
        x_last, cond = batch_map_last_state(stamps[: k + 1], z[: k + 1], omega, KALMAN_STATES[model])
        ref = omega * x_last[1]
        # backward-stable lstsq: relative error ≤ cond·ε·(a small factor); 100× margin on top
        assert abs(ddq[0] - ref) <= 100 * cond * EPS * max(1.0, abs(ref) * 1.0) * omega, (k, ddq, ref, cond)
        checked += 1
    assert checked >= 12


def steady_state_gain(h, m=3):
    F, Q, R = kalman_matrices(h, m)
    H = np.zeros((1, m))
    H[0, 0] = 1.0
    P_pred = sla.solve_discrete_are(F.T, H.T, Q, np.array([[R]]))
    K = P_pred[:, 0] / (P_pred[0, 0] + R)
    return F, K


@pytest.mark.parametrize("model", ["jerk", "snap"])
@pytest.mark.parametrize("rate_hz", [100.0, 1000.0])
def test_steady_state_response_to_a_sinusoid_is_the_dare_filters(rate_hz, model):
    """After the transient, q̈̂ of q̇ = sin(2πft) equals the frequency response of the LTI filter with the
    DARE steady-state gain: x_k = (I − K H) F x_{k−1} + K z_k."""
    bw, f = 8.0, 1.3
    m = KALMAN_STATES[model]
    omega = 2 * math.pi * bw
    dt = 1.0 / rate_hz
    n = int(3.0 * rate_hz)
    stamps = T0 + np.arange(n, dtype=np.int64) * round(dt * 1e9)
    t = (stamps - T0) * 1e-9
    z = np.sin(2 * math.pi * f * t)
    est_stamps, ddq = estimate_accelerations(stamps, z, kalman(bw, kalman_model=model))
    F, K = steady_state_gain(omega * dt, m)
    H = np.zeros((1, m))
    H[0, 0] = 1.0
    Acl = (np.eye(m) - np.outer(K, H)) @ F
    zeta = np.exp(1j * 2 * math.pi * f * dt)
    G = np.linalg.solve(zeta * np.eye(m) - Acl, zeta * K)  # X(ζ) = G Z(ζ)
    resp = omega * G[1]  # q̈̂ per unit complex exponential of q̇
    tail = (est_stamps - T0) * 1e-9 > 2.0  # slowest pole ≥ 0.38 ω: transient < e^-38 of its start
    tt = (est_stamps[tail] - T0) * 1e-9
    expected = np.imag(resp * np.exp(1j * 2 * math.pi * f * tt))
    # the steady state is reached to rounding: tolerance 1e-9 of the signal scale (ω·|G| ≤ ~10 ω)
    np.testing.assert_allclose(ddq[tail, 0], expected, rtol=0, atol=1e-9 * 2 * math.pi * f)
    # and the continuous-time claim of the docstring: q̈̂/(s q̇) = 1 − (s^m + k₁ s^(m−1))/B(s) with B the
    # Butterworth polynomial at ω (scipy.signal.butter, analog); the sampled filter differs by O(h),
    # h = ω·dt (0.05 at 1 kHz, 0.5 at 100 Hz): bound h relative to the continuous error
    x = f / bw
    a = ss.butter(m, 1.0, analog=True)[1]  # [1, k₁/ω, k₂/ω², …]
    sx = 1j * x
    cont_err = -(sx**m + a[1] * sx ** (m - 1)) / np.polyval(a, sx)
    disc_err = resp / (1j * 2 * math.pi * f) - 1.0
    assert abs(disc_err - cont_err) <= omega * dt * abs(cont_err), (disc_err, cont_err)
    if model == "jerk":  # |q̈̂/q̈| = √((1 + 4x²)/(1 + x⁶)) ≈ 1 + 2x²
        amplitude = math.sqrt((1 + 4 * x**2) / (1 + x**6))
        assert abs(1 + cont_err) == pytest.approx(amplitude, rel=1e-12)
        assert amplitude - 1 == pytest.approx(2 * x**2, rel=2 * x**2)
    else:  # relative error ≈ k₁/ω · x³ = 2.613 x³ (the next term is O(x⁴))
        assert abs(cont_err) == pytest.approx(a[1] * x**3, rel=2 * x)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("model", ["jerk", "snap"])
def test_constant_jerk_velocity_is_tracked_without_lag_on_irregular_stamps(seed, model):
    """q̇ quadratic in t lies in the model's noise-free subspace: once settled the estimate equals the
    exact q̈ up to the diffuse prior's pull (≤ P_post/KALMAN_PRIOR_VARIANCE ≈ 1e-7 of the state, then
    decaying) and rounding; no delay, no lag."""
    stamps = jittered_stamps(600, 0.001, 0.4, seed)
    t = (stamps - T0) * 1e-9
    c = np.array([[0.3, -1.2, 2.0], [-0.5, 0.7, -4.0]])  # v = c0 + c1 t + c2 t² per joint
    dq = c[:, 0] + t[:, None] * c[:, 1] + t[:, None] ** 2 * c[:, 2]
    ddq_true = c[:, 1] + 2 * t[:, None] * c[:, 2]
    est = make_estimator(2, kalman(8.0, kalman_model=model))
    out = feed(est, stamps, dq)
    got = [(k, d) for k, (_, d) in enumerate(out) if d is not None]
    assert got
    k = np.array([g[0] for g in got])
    d = np.array([g[1] for g in got])
    np.testing.assert_allclose(d, ddq_true[k], rtol=0, atol=1e-6 * np.abs(ddq_true).max())
    assert est.delay_s == 0.0 and est.lag_s == 0.0


def test_warm_up_gaps_and_every_stamp_decided_once():
    bw = 8.0
    settle = KALMAN_SETTLE["jerk"] / (2 * math.pi * bw)
    dt = 0.001
    t = np.concatenate([np.arange(0.0, 0.3, dt), 0.5 + np.arange(0.0, 0.3, dt)])  # a 0.2 s hole
    stamps = T0 + np.round(t * 1e9).astype(np.int64)
    est = make_estimator(3, kalman(bw, max_gap_s=0.05))
    assert isinstance(est, KalmanEstimator)
    assert est.settle_s == pytest.approx(settle)
    out = []
    for s in stamps.tolist():
        dec = est.update(s, np.ones(3))
        assert [d[0] for d in dec] == [s]  # decided at once, for its own stamp
        out.extend(dec)
    none = np.array([d is None for _, d in out])
    since_start = np.where(t < 0.5, t, t - 0.5)
    np.testing.assert_array_equal(none, since_start < settle - 1e-12)
    ddq = np.array([d for _, d in out if d is not None])
    np.testing.assert_allclose(ddq, 0.0, atol=1e-9)  # constant velocity: q̈ = 0
    assert est.delay_s == 0.0 and est.lag_s == 0.0
    assert est.mean_dt_s == pytest.approx(dt, rel=1e-6)
    assert est.reset() == []  # nothing is ever pending


def test_invalid_updates_raise_and_leave_state_untouched():
    est = make_estimator(2, kalman())
    stamps = T0 + np.arange(200, dtype=np.int64) * 10**6
    for s in stamps[:100].tolist():
        est.update(s, np.array([0.1, 0.2]))
    twin = make_estimator(2, kalman())
    for s in stamps[:100].tolist():
        twin.update(s, np.array([0.1, 0.2]))
    for bad in [(int(stamps[99]), np.zeros(2)), (int(stamps[100]), np.zeros(3)),
                (int(stamps[100]), np.array([np.nan, 0.0]))]:
        with pytest.raises(RejectedSampleError):
            est.update(*bad)
    for s in stamps[100:].tolist():
        a = est.update(s, np.array([0.1, 0.3]))
        b = twin.update(s, np.array([0.1, 0.3]))
        assert a[0][0] == b[0][0]
        np.testing.assert_array_equal(a[0][1], b[0][1])


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, True, "8"])
def test_invalid_bandwidth_is_a_configuration_error(bad):
    with pytest.raises(ConfigurationError, match="bandwidth_hz"):
        AccelerationConfig(method="kalman", bandwidth_hz=bad)


def test_invalid_kalman_model_is_a_configuration_error():
    with pytest.raises(ConfigurationError, match="kalman_model"):
        AccelerationConfig(method="kalman", kalman_model="crackle")


def test_parameter_table_builds_the_kalman_pipeline():
    cfg = EstimatorConfig.from_flat({**ICUB_RIGHT_ARM, "acceleration.method": "kalman",
                                                     "acceleration.bandwidth_hz": 12.0})
    pipe = build_pipeline(cfg)
    assert pipe.acceleration.method == "kalman" and pipe.acceleration.bandwidth_hz == 12.0
    assert pipe.acceleration_delay_s == 0.0
    for bad in (0.0, -3.0, "x"):
        with pytest.raises(ConfigurationError, match=r"acceleration\.bandwidth_hz"):
            cfg.with_overrides({"acceleration.bandwidth_hz": bad})
    with pytest.raises(ConfigurationError, match=r"acceleration\.method"):
        cfg.with_overrides({"acceleration.method": "kalmann"})


def steady_state_noise_gain(bw, dt, n_terms=20000):
    """√Σ_k (ω e₂ᵀ A_clᵏ K)²: std of q̈̂ per unit std of white velocity noise, from the DARE gain."""
    omega = 2 * math.pi * bw
    F, K = steady_state_gain(omega * dt)
    Acl = (np.eye(3) - np.outer(K, [1.0, 0.0, 0.0])) @ F
    total, g = 0.0, K.copy()
    for _ in range(n_terms):
        total += (omega * g[1]) ** 2
        g = Acl @ g
    return math.sqrt(total)


def test_white_noise_gain_is_the_steady_state_filters_and_grows_like_bandwidth_to_1_5():
    bw, dt, sigma = 8.0, 0.001, 0.01
    rng = np.random.default_rng(11)
    n, joints = 60000, 8
    stamps = T0 + np.arange(n, dtype=np.int64) * 10**6
    _, ddq = estimate_accelerations(stamps, sigma * rng.standard_normal((n, joints)), kalman(bw))
    measured = ddq[5000:].std()  # transient (ω t > 250) gone
    expected = sigma * steady_state_noise_gain(bw, dt)
    # 55k samples × 8 independent joints, output correlation ≈ 1/(ω dt) ≈ 20 samples: the std of the
    # estimated std is ≈ √(20 / (2 · 440k)) ≈ 0.5 %; 3 % is 6 of those
    assert measured == pytest.approx(expected, rel=0.03)
    # continuous-time scaling: the q̈ noise std ∝ ω^{3/2} (white-noise density fixed); O(h) corrections
    ratio = steady_state_noise_gain(16.0, dt) / steady_state_noise_gain(8.0, dt)
    assert ratio == pytest.approx(2**1.5, rel=2 * math.pi * 16.0 * dt)


def test_pipeline_emits_each_joint_torque_sample_with_its_own_joint_state():
    """Through the SamplePipeline (joint-torque output): no sample waits for later joint states, the warm-up
    is counted as 'acceleration_warmup', and q̈ equals the standalone estimator's."""
    from semiparam_ros.core.stream.messages import JointStateData
    from semiparam_ros.core.stream.pipeline import DROP_ACCELERATION_WARMUP

    cfg = EstimatorConfig.from_flat({**ICUB_RIGHT_ARM,
        "robot.output": "joint_torques", "acceleration.method": "kalman", "acceleration.bandwidth_hz": 8.0,
        "acceleration.kalman_model": "jerk"})
    pipe = build_pipeline(cfg)
    joints = tuple(cfg["robot.joints"])
    n = len(joints)
    stamps = jittered_stamps(300, 0.001, 0.2, seed=8)
    t = (stamps - T0) * 1e-9
    dq = np.cos(np.outer(t, np.arange(1, n + 1)))
    twin = make_estimator(n, kalman(8.0, max_gap_s=cfg["acceleration.max_gap_s"]))
    n_samples = 0
    for k, s in enumerate(stamps.tolist()):
        msg = JointStateData(s, joints, np.zeros(n), dq[k], np.full(n, 0.5))
        out = pipe.add(msg)
        ((ref_stamp, expected),) = twin.update(s, dq[k])
        assert ref_stamp == s
        if expected is None:
            assert out == []
            continue
        assert len(out) == 1 and out[0].stamp_ns == s
        np.testing.assert_array_equal(out[0].ddq, expected)
        n_samples += 1
    settle = KALMAN_SETTLE["jerk"] / (2 * math.pi * 8.0)
    n_warm = int(np.sum(t < settle - 1e-12))
    assert pipe.drops[DROP_ACCELERATION_WARMUP] == n_warm
    assert n_samples == len(stamps) - n_warm


def test_parameter_table_selects_the_kalman_model():
    cfg = EstimatorConfig.from_flat({**ICUB_RIGHT_ARM, "acceleration.method": "kalman",
                                                     "acceleration.kalman_model": "jerk"})
    pipe = build_pipeline(cfg)
    assert pipe.acceleration.kalman_model == "jerk"
    assert pipe.estimator.settle_s == pytest.approx(KALMAN_SETTLE["jerk"] / (2 * math.pi * 6.0))
    defaults = build_pipeline(EstimatorConfig.from_flat({**ICUB_RIGHT_ARM, "acceleration.method": "kalman"}))
    assert defaults.acceleration.kalman_model == "snap" and defaults.acceleration.bandwidth_hz == 6.0
    with pytest.raises(ConfigurationError, match=r"acceleration\.kalman_model"):
        cfg.with_overrides({"acceleration.kalman_model": "crackle"})
