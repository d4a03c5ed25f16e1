"""The one-pass gated step: ``predict_ahead`` / ``learn_ahead`` against ``predict_one`` / ``learn_one`` and
the closed-form ridge, and the compiled small-vector kernels against their numpy expressions.

``learn_ahead`` learns from the regressor, the features and the a-priori ŷ that ``predict_ahead`` computed.
For P, NP and the joint SP model those are exactly what ``learn_one`` computes again, so the states are
bit-identical. The cascade's residual input ``[x, ŷ]`` takes ŷ from the forward substitution instead of
the rotations: equal to rounding, so its state is compared with a bound (and both stages with the closed
form).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.learners import _step_kernels as kernels
from semiparam_ros.core.learners.cascade import SemiparametricModel
from semiparam_ros.core.learners.features import RandomFourierFeatures, Standardizer
from semiparam_ros.core.learners.joint import JointSemiparametricModel
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.core.learners.uncertainty import predict_with_variance
from semiparam_ros.core.stream.gate import exceeds
from semiparam_ros.core.stream.messages import Sample
from semiparam_ros.errors import RejectedSampleError

EPS = np.finfo(float).eps
N_IN, N_OUT, N_PAR = 4, 3, 5
PRIOR = np.array([0.5, -1.0, 2.0, 0.0, 3.0])
TRUE = np.array([1.0, -2.0, 0.5, 3.0, -1.5])


def _regressor(x: np.ndarray) -> np.ndarray:
    # a smooth (3 × 5) regressor of a 4-dimensional input
    return np.array([[1.0, x[0], x[1] * x[2], np.sin(x[3]), x[0] ** 2],
                     [x[1], 1.0, np.cos(x[0]), x[2], x[3] * x[0]],
                     [x[2] * x[3], x[0] - x[1], 1.0, x[1] ** 2, np.sin(x[2])]])


def _make(kind: str, forgetting: float = 0.995):
    common = dict(n_features=60, sigma=2.0, standardizer_warmup=20)
    if kind == "P":
        return ParametricModel(_regressor, N_PAR, N_OUT, lam=0.1, forgetting=forgetting, prior=PRIOR)
    if kind == "NP":
        return NonparametricModel(N_IN, N_OUT, lam=0.01, forgetting=forgetting, **common)
    if kind == "SPJ":
        return JointSemiparametricModel(_regressor, N_PAR, N_IN, N_OUT, lam_parametric=0.1,
                                        lam_nonparametric=0.01, forgetting=forgetting, prior=PRIOR, **common)
    return SemiparametricModel(_regressor, N_PAR, N_IN, N_OUT, lam_parametric=0.1, lam_nonparametric=0.01,
                               forgetting_parametric=forgetting, forgetting_nonparametric=forgetting,
                               prior=PRIOR, yhat_statistics="measured" if kind == "SP" else "predicted",
                               **common)


def _data(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, N_IN))
    Y = np.array([_regressor(x) @ TRUE + 0.3 * np.sin(2.0 * x[:3]) for x in X])
    return X, Y + 0.01 * rng.normal(size=Y.shape)


def _states_equal(a, b) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(np.array_equal(sa[k], sb[k]) for k in sa)


@pytest.mark.parametrize("kind", ["P", "NP", "SPJ"])
def test_learn_ahead_is_learn_one_bit_for_bit(kind):
    """P, NP and the joint model learn from the very regressor and features learn_one recomputes."""
    X, Y = _data(150)  # through the standardizer warm-up (20 samples) and well beyond
    a, b = _make(kind), _make(kind)
    for x, y in zip(X, Y, strict=True):
        context = b.predict_ahead(x)
        ref = a.predict_one(x, return_variance=True)
        # the context's prediction is predict_one's (the state is bit-identical so far), v ≥ 0 in warm-up
        for part in ("parametric", "residual", "total"):
            assert np.array_equal(getattr(context.prediction, part), getattr(ref, part)), part
        assert np.array_equal(context.prediction.variance, np.fmax(ref.variance, 0.0))
        a.learn_one(x, y)
        b.learn_ahead(context, y)
    assert _states_equal(a, b)
    assert a.n_samples_seen == b.n_samples_seen == len(X)


@pytest.mark.parametrize("kind", ["SP", "SP predicted"])
def test_cascade_learn_ahead_equals_learn_one_to_rounding(kind):
    """The cascade's residual input takes ŷ from the forward substitution, learn_one's from the rotations.

    Both are Φ(x) π̂ with a relative error ≲ cond(R)·ε (cond(R) ≤ 1e3 here, so ≲ 1e-13); that perturbs the
    residual stage's inputs and targets by as much, and its ridge solution by ≲ cond(A)·that. Measured
    difference of every prediction: < 2e-15 relative; the bound asserted, 1e-9 (the issue's), leaves a
    margin > 1e5.
    """
    X, Y = _data(300)
    a, b = _make(kind), _make(kind)
    for x, y in zip(X, Y, strict=True):
        context = b.predict_ahead(x)
        a.learn_one(x, y)
        b.learn_ahead(context, y)
    assert a.parametric.rls.condition_number() < 1e3
    # the rigid-body stage sees identical rows: bit-identical
    assert _states_equal(a.parametric, b.parametric)
    Xt, _ = _data(50, seed=1)
    for x in Xt:
        pa, pb = a.predict_one(x, return_variance=True), b.predict_one(x, return_variance=True)
        scale = np.abs(pa.total).max()
        np.testing.assert_allclose(pb.total, pa.total, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(pb.variance, pa.variance, rtol=1e-9, atol=0)


def test_cascade_learn_ahead_is_the_closed_form_ridge_of_both_stages():
    """β = 1, zero prior: θ̂ = (λI + ΣΦᵀΦ)⁻¹ΣΦᵀy, and the residual weights the ridge solution on the numpy
    features of [x, ŷ] (ŷ the a-priori predictions the contexts carried, standardized with the warm-up's
    measured statistics) with targets y − ŷ, over every sample: the warm-up's rows are held and learned
    when its statistics are ready. Dense solves are backward stable: relative error ≲ κ(A)·ε;
    the tolerance is 100·κ·ε."""
    X, Y = _data(400)
    model = SemiparametricModel(_regressor, N_PAR, N_IN, N_OUT, lam_parametric=0.1, lam_nonparametric=0.05,
                                n_features=60, sigma=2.0, standardizer_warmup=20)
    yhat, inputs = [], []
    for x, y in zip(X, Y, strict=True):
        context = model.predict_ahead(x)
        yhat.append(context.prediction.parametric)
        model.learn_ahead(context, y)
    Phi = np.concatenate([_regressor(x) for x in X])
    A = 0.1 * np.eye(N_PAR) + Phi.T @ Phi
    theta = np.linalg.solve(A, Phi.T @ Y.reshape(-1))
    np.testing.assert_allclose(model.parameters, theta, rtol=0,
                               atol=100 * np.linalg.cond(A) * EPS * np.abs(theta).max())

    yhat = np.array(yhat)
    std = Standardizer(N_IN + N_OUT).fit(np.hstack([X[:20], Y[:20]]))  # the ŷ block: measured y's stats
    npm = model.nonparametric
    np.testing.assert_allclose(npm.standardizer.mean_, std.mean_, rtol=1e-12)
    inputs = np.hstack([X, yhat])
    F = npm.rff.transform(npm.standardizer.transform(inputs))  # the numpy reference map
    A = 0.05 * np.eye(F.shape[1]) + F.T @ F
    W = np.linalg.solve(A, F.T @ (Y - yhat))
    np.testing.assert_allclose(npm.rls.weights, W, rtol=0,
                               atol=100 * np.linalg.cond(A) * EPS * np.abs(W).max())


@pytest.mark.parametrize("kind", ["P", "NP", "SP", "SPJ"])
def test_a_stale_context_is_a_programming_error(kind):
    X, Y = _data(40)
    model, other = _make(kind), _make(kind)
    for x, y in zip(X[:30], Y[:30], strict=True):
        model.learn_one(x, y)
    context = model.predict_ahead(X[30])
    with pytest.raises(ValueError, match="stale") as err:
        other.learn_ahead(context, Y[30])  # another model's context
    assert not isinstance(err.value, RejectedSampleError)
    model.learn_ahead(context, Y[30])
    with pytest.raises(ValueError, match="stale"):
        model.learn_ahead(context, Y[30])  # used twice
    context = model.predict_ahead(X[31])
    model.learn_one(X[32], Y[32])
    with pytest.raises(ValueError, match="stale"):
        model.learn_ahead(context, Y[31])  # the model learned in between


@pytest.mark.parametrize("kind", ["P", "NP", "SP", "SPJ"])
def test_a_rejected_label_leaves_model_and_context_usable(kind):
    X, Y = _data(40)
    model = _make(kind)
    for x, y in zip(X[:30], Y[:30], strict=True):
        model.learn_one(x, y)
    before = model.state_dict()
    context = model.predict_ahead(X[30])
    for bad in (np.array([np.nan, 0.0, 0.0]), np.full(3, 1e200), np.zeros(4)):
        with pytest.raises(RejectedSampleError):
            model.learn_ahead(context, bad)
    after = model.state_dict()
    assert all(np.array_equal(before[k], after[k]) for k in before)
    model.learn_ahead(context, Y[30])  # still valid: nothing was learned
    with pytest.raises(RejectedSampleError):
        model.predict_ahead(np.array([0.0, np.inf, 0.0, 0.0]))


def test_cascade_checks_both_stages_before_changing_either(monkeypatch):
    """A refusal of the residual stage's rows leaves the rigid-body stage unchanged too."""
    X, Y = _data(40)
    model = _make("SP")
    for x, y in zip(X[:30], Y[:30], strict=True):
        model.learn_one(x, y)
    before = model.state_dict()
    context = model.predict_ahead(X[30])

    def refuse(Z, U, owned=False):
        raise RejectedSampleError("refused")

    monkeypatch.setattr(model.nonparametric.rls, "checked_step", refuse)
    with pytest.raises(RejectedSampleError, match="refused"):
        model.learn_ahead(context, Y[30])
    after = model.state_dict()
    assert all(np.array_equal(before[k], after[k]) for k in before)


@pytest.mark.parametrize("kind", ["SP", "SPJ", "P", "NP"])
def test_gated_estimator_step_equals_predict_then_learn_one(kind):
    """The estimator's gate-on path (the node's) against the two-pass loop it replaces: predict_one with
    variance, the noise scale and gate by hand, learn_one; every verdict, prediction and σ bit-identical.
    The consistent SP's reference predicts and learns through one context (predict_ahead / learn_ahead,
    whose equality to learn_one is tested above): its fast correction and tracker take discrete decisions
    (a significance mask, a chosen estimate) that the rounding of a second, unfused prediction can flip
    hundreds of samples later, so only the same arithmetic can be compared bit for bit."""
    overrides = {"nonparametric.n_features": 80, "nonparametric.standardizer_warmup": 50, "gate.warmup": 0.5,
                 "adaptation.time_constant": 0.0}
    if kind == "SPJ":
        overrides.update({"semiparametric.combination": "joint", "nonparametric.forgetting": 1.0,
                          "parametric.forgetting": 1.0})
    cfg = EstimatorConfig.from_flat(ICUB_RIGHT_ARM).with_overrides(overrides)
    model_kind = "SP" if kind == "SPJ" else kind
    est = OnlineEstimator(cfg, kind=model_kind)
    ref = OnlineEstimator(cfg, regressor=est.regressor, kind=model_kind)
    rng = np.random.default_rng(5)
    n = len(cfg["robot.joints"])
    ref_pi = est.regressor.to_base(est.regressor.urdf_parameters())
    verdicts = set()
    last_learned = None
    for i in range(600):
        q, dq, ddq = rng.uniform(-0.5, 0.5, n), rng.normal(0, 0.5, n), rng.normal(0, 2.0, n)
        y = est.regressor.base_regressor(q, dq, ddq) @ ref_pi + 0.2 * np.sin(q[:1]) + rng.normal(0, 0.05, 6)
        if 300 <= i < 330:
            y = y + 30.0  # a contact: gated
        s = Sample(10**9 + i * 10_000_000, q, dq, ddq, y)
        got = est.step(s)
        # reference: the former two-pass step
        # the age the fast correction fades with: samples since the last learned one, times the period
        missed = i - last_learned - 1 if last_learned is not None else 0
        period = est.sample_period_s
        ref.model.prediction_age_s = missed * period if missed > 0 and period is not None else 0.0
        context = ref.model.predict_ahead(s.x) if kind == "SP" else None
        ahead = context.prediction if context is not None else predict_with_variance(ref.model, s.x)
        std = ref.noise.std(ahead.variance)
        verdict = ref.gate.decide(s.stamp_ns, s.y - ahead.total, std, float(np.max(ahead.variance)))
        if verdict.learn:
            last_learned = i
            if context is not None:
                ref.model.learn_ahead(context, s.y)
            else:
                ref.model.learn_one(s.x, s.y)
            # the noise scale of the model's errors (a consistent SP's fast correction left out)
            model_error = s.y - ahead.total + (0.0 if ahead.correction is None else ahead.correction)
            ref.noise.update(s.stamp_ns, model_error, ahead.variance)
        else:
            ref.noise.skip(s.stamp_ns)
        assert got.verdict == verdict and got.learned == verdict.learn
        verdicts.add(verdict.value)
        assert np.array_equal(got.prediction.total, ahead.total) and np.array_equal(got.std, std)
    assert {"warmup", "inlier", "gated"} <= verdicts  # "novel" too where the random states are new
    assert est.n_samples_learned == ref.model.n_samples_seen


# ----------------------------------------------------------------------------- compiled kernels
def test_standardized_features_match_the_numpy_map_within_the_rounding_bound():
    rng = np.random.default_rng(2)
    rff = RandomFourierFeatures(7, 1000, sigma=1.5, seed=3)
    std = Standardizer(7, mean=rng.normal(size=7), scale=rng.uniform(0.01, 3.0, 7))
    for _ in range(50):
        x = rng.normal(0.0, 5.0, 7)
        got = kernels.standardized_features(x, std.mean_, std.scale_, rff.omega_, rff.offset_,
                                            rff.feature_scale)
        z = std.transform(x)
        ref = rff.transform(z)
        # phase error ≤ (n + 1)·ε·(Σ|z_i Ω_ij| + |b_j|) each side, cos 1-Lipschitz, plus each cos's own
        # error (the kernel calls libm's cos, numpy its own SIMD one: ≤ 1 ulp ≤ 2ε near 1 each, < 3ε
        # apart in practice, as ε·|cos| ≤ ε below 0.5)
        phase = np.abs(z) @ np.abs(rff.omega_) + np.abs(rff.offset_)
        bound = rff.feature_scale * (2 * (7 + 1) * EPS * phase + 3 * EPS)
        assert got.shape == (1, 1000)
        assert np.all(np.abs(got[0] - ref) <= bound)


def test_noise_and_gate_kernels_are_the_numpy_expressions_bit_for_bit():
    rng = np.random.default_rng(4)
    for _ in range(200):
        t = 6
        s2 = rng.uniform(0.0, 3.0, t)
        v = rng.uniform(-0.1, 2.0, t)
        v[rng.random(t) < 0.2] = np.nan
        e = rng.normal(0.0, 2.0, t)
        alpha = -math.expm1(-rng.uniform(0.0, 0.1))
        vv = np.fmax(v, 0.0)
        assert np.array_equal(kernels.noise_std(s2, v), np.sqrt(s2 * (1.0 + vv)))
        ok, got = kernels.noise_update(s2, e, v, alpha)
        assert ok and np.array_equal(got, s2 + alpha * (e * e / (1.0 + vv) - s2))
        s = np.abs(rng.normal(0.0, 1.0, t))
        s[rng.random(t) < 0.2] = 0.0
        s[rng.random(t) < 0.1] = np.inf
        e[rng.random(t) < 0.1] = np.nan
        for threshold in (0.5, 2.0, 5.0):
            assert exceeds(e, s, threshold) == bool(np.any(np.abs(e) > threshold * s))
    ok, got = kernels.noise_update(s2, np.array([0.0, np.inf, 0, 0, 0, 0]), v, 0.5)
    assert not ok and np.array_equal(got, s2)
