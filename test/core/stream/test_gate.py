"""Contact gate, noise-scale estimate and rate-independent forgetting: each against a hand computation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from semiparam_ros.core.learners.adaptation import forgetting_factor
from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.core.learners.uncertainty import NoiseScale
from semiparam_ros.core.stream.gate import ContactGate, GateConfig, Verdict

T0 = 1_700_000_000 * 10**9
DT = 10_000_000  # 100 Hz


def test_gate_rule_warmup_contact_and_adoption():
    gate = ContactGate(GateConfig(threshold=3.0, max_contact_duration_s=0.5, warmup_s=1.0))
    std = np.array([1.0, 2.0])
    verdicts = []
    # 0–1 s warm-up: learned even when far out; then 1 s inside; a 0.3 s excursion (gated); inside again;
    # then an excursion that lasts 1 s: gated for its first 0.5 s, adopted after
    for k in range(400):
        t = k * 0.01
        big = (0.2 <= t < 0.4) or (2.0 <= t < 2.3) or (3.0 <= t < 4.0)
        err = np.array([0.0, 7.0 if big else 5.9])  # 7 > 3·2, 5.9 < 3·2: only component 2 decides
        verdicts.append(gate.decide(T0 + k * DT, err, std))
    expected = []
    for k in range(400):
        t = round(k * 0.01, 6)
        if t < 1.0:
            expected.append(Verdict.WARMUP)
        elif 2.0 <= t < 2.3:
            expected.append(Verdict.GATED)
        elif 3.0 <= t < 4.0:
            expected.append(Verdict.GATED if t - 3.0 <= 0.5 + 1e-9 else Verdict.ADOPTED)
        else:
            expected.append(Verdict.INLIER)
    assert verdicts == expected
    assert gate.counts[Verdict.GATED] == 30 + 51 and gate.counts[Verdict.ADOPTED] == 49
    assert [v.learn for v in (Verdict.WARMUP, Verdict.INLIER, Verdict.GATED, Verdict.ADOPTED)] == \
        [True, True, False, True]
    gate.reset()
    assert gate.decide(T0, np.array([0.0, 100.0]), std) is Verdict.WARMUP


def test_gate_infinite_std_accepts_and_zero_std_flags():
    gate = ContactGate(GateConfig(threshold=1.0, max_contact_duration_s=1.0, warmup_s=0.0))
    assert gate.decide(T0, np.array([1e9]), np.array([np.inf])) is Verdict.INLIER
    assert gate.decide(T0 + DT, np.array([1e-12]), np.array([0.0])) is Verdict.GATED


@pytest.mark.parametrize(("name", "kwargs"), [
    ("gate.threshold", dict(threshold=0.0)),
    ("gate.threshold", dict(threshold=math.nan)),
    ("gate.max_contact_duration", dict(max_contact_duration_s=-1.0)),
    ("gate.warmup", dict(warmup_s=math.inf)),
])
def test_gate_config_refuses_bad_values_naming_them(name, kwargs):
    with pytest.raises(ValueError, match=name):
        GateConfig(**kwargs)


def test_noise_scale_is_the_exponentially_weighted_mean_in_time():
    rng = np.random.default_rng(0)
    tau, n = 0.5, 200
    err = rng.normal(size=(n, 2)) * [1.0, 3.0]
    v = rng.uniform(0, 0.5, size=n)
    ns = NoiseScale(2, tau)
    assert np.all(np.isinf(ns.std(0.0)))
    for k in range(n):
        ns.update(T0 + k * DT, err[k], v[k])
    # closed form: weights (1−α)^(n−1) for the first target, α(1−α)^(n−m) for target m ≥ 2
    alpha = 1.0 - math.exp(-0.01 / tau)
    target = err**2 / (1.0 + v[:, None])
    w = alpha * (1.0 - alpha) ** (n - 1 - np.arange(n))
    w[0] = (1.0 - alpha) ** (n - 1)
    expected = w @ target
    np.testing.assert_allclose(ns.s2, expected, rtol=1e-12)  # n·ε accumulation, n = 200
    np.testing.assert_allclose(ns.std(0.3), np.sqrt(expected * 1.3), rtol=1e-12)
    # a skipped (gated) sample does not count and its time step weighs nothing
    before = ns.s2.copy()
    ns.skip(T0 + n * DT)
    ns.update(T0 + (n + 1) * DT, np.array([1.0, 1.0]), 0.0)
    np.testing.assert_allclose(ns.s2, before + alpha * (1.0 - before), rtol=1e-12)
    with pytest.raises(ValueError):
        ns.update(T0 + (n + 2) * DT, np.array([np.nan, 1.0]), 0.0)


def test_forgetting_time_constant_is_rate_independent():
    tau = 20.0
    for hz in (10.0, 100.0, 200.0):
        beta = forgetting_factor(tau, 1.0 / hz)
        # a sample tau seconds old weighs e⁻¹ whatever the rate
        assert beta ** (tau * hz) == pytest.approx(math.exp(-1.0), rel=1e-12)
    with pytest.raises(ValueError):
        forgetting_factor(0.0, 0.01)
    with pytest.raises(ValueError):
        forgetting_factor(1.0, -0.01)


def test_set_forgetting_continues_the_closed_form_recursion():
    rng = np.random.default_rng(1)
    b, t, lam, k, n, beta = 5, 2, 0.3, 7, 40, 0.9
    Z, U = rng.normal(size=(n, b)), rng.normal(size=(n, t))
    rls = RecursiveRLS(b, t, lam)
    for m in range(n):
        if m == k:
            rls.set_forgetting(beta)
        rls.update(Z[m], U[m])
    # A_n = β^{n−k}(λI + Σ_{m≤k} z zᵀ) + Σ_{m>k} β^{n−m}(z zᵀ + c e_j e_jᵀ), j = (m − 1) mod b, 1-based m
    c = b * (1.0 - beta) * lam
    A, B = lam * np.eye(b), np.zeros((b, t))
    for m in range(1, n + 1):
        z, u = Z[m - 1], U[m - 1]
        if m <= k:
            A += np.outer(z, z)
            B += np.outer(z, u)
        else:
            A = beta * A + np.outer(z, z)
            A[(m - 1) % b, (m - 1) % b] += c
            B = beta * B + np.outer(z, u)
    W = np.linalg.solve(A, B)
    # κ(A)·ε-level agreement: cond(A) < 1e3 here, so 1e-10 leaves a margin > 100×
    assert np.linalg.cond(A) < 1e3
    np.testing.assert_allclose(rls.weights, W, rtol=0, atol=1e-10 * np.abs(W).max())
    with pytest.raises(ValueError):
        rls.set_forgetting(1.5)
    assert rls.forgetting == beta


def test_gate_and_noise_state_survive_a_checkpoint(tmp_path):
    """After a restart from a checkpoint the gate is engaged at once and σ is the saved one: an outlier
    right after the warm start is a contact (gated), not a warm-up sample learned."""
    from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
    from semiparam_ros.core.estimator.online import OnlineEstimator
    from semiparam_ros.core.stream.messages import JointStateData

    config = EstimatorConfig.from_flat(ICUB_RIGHT_ARM).with_overrides({
        "robot.output": "joint_torques", "nonparametric.n_features": 20, "gate.warmup": 1.0})
    est = OnlineEstimator(config)
    joints = tuple(config["robot.joints"])
    rng = np.random.default_rng(0)
    for k in range(300):  # 3 s at 100 Hz of smooth motion, torques a smooth function of the state
        q = 0.3 * np.sin(0.5 * k * 0.01 + np.arange(4))
        est.process(JointStateData(T0 + k * DT, joints, q, np.cos(q), np.sin(q) + 0.01 *
                                               rng.standard_normal(4)))
    assert est.gate.counts[Verdict.INLIER] > 0
    est.save(tmp_path / "c.npz")
    fresh = OnlineEstimator(config)
    fresh.load(tmp_path / "c.npz")
    np.testing.assert_array_equal(fresh.noise.s2, est.noise.s2)
    assert fresh.gate.counts == est.gate.counts
    std = fresh.noise.std(np.zeros(4))
    assert fresh.gate.decide(T0 + 10**12, 100 * std, std) is Verdict.GATED  # engaged: no new warm-up
    cold = OnlineEstimator(config)
    assert cold.gate.decide(T0, np.full(4, 1e6), np.ones(4)) is Verdict.WARMUP


def test_an_outlier_where_the_model_does_not_know_the_state_is_novel_motion_not_a_contact():
    gate = ContactGate(GateConfig(threshold=3.0, max_contact_duration_s=0.5, warmup_s=0.0, novelty=1.0))
    std, big = np.ones(2), np.array([10.0, 0.0])
    assert gate.decide(T0, big, std, novelty=0.5) is Verdict.GATED       # a known state: a contact
    assert gate.in_excursion
    v = gate.decide(T0 + DT, big, std, novelty=5.0)                      # the model is uncertain there
    assert v is Verdict.NOVEL and v.learn and not gate.in_excursion
    assert gate.decide(T0 + 2 * DT, big, std, novelty=1.0) is Verdict.GATED   # not above: a contact again
    assert gate.decide(T0 + 3 * DT, np.zeros(2), std, novelty=9.0) is Verdict.INLIER
    off = ContactGate(GateConfig(threshold=3.0, warmup_s=0.0, novelty=0.0))
    assert off.decide(T0, big, std, novelty=1e9) is Verdict.GATED
    with pytest.raises(ValueError, match=r"gate\.novelty"):
        GateConfig(novelty=-1.0)
