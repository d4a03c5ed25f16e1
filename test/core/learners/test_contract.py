"""The learner contract, run over every learner the builder makes (P, NP, and SP as cascade, joint fit and
consistent model): inputs are not mutated, a checkpoint round trip predicts and learns on identically,
the seed fixes the random features, ``on_period`` converts seconds as the formulas say and is idempotent,
``learn_one`` and ``predict_learn_one`` leave the same state, and a restored learner takes the period
again through ``on_period`` (the fast correction's memory and the warm-up included)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
from semiparam_ros.core.estimator.build import build_model, build_regressor, learner_variants, traits_of
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.learners.contract import Learner, PeriodSettings
from semiparam_ros.core.stream.messages import Sample

LEARNERS = list(learner_variants())  # every learner the builder makes
TAU_S, WARMUP_S = 5.0, 0.3


def config(combination: str, **overrides: object) -> EstimatorConfig:
    base = {"semiparametric.combination": combination, "nonparametric.n_features": 16,
            "adaptation.time_constant": TAU_S, "nonparametric.standardizer_warmup_s": WARMUP_S,
            "nonparametric.standardizer_warmup": 0, "gate.enabled": False}
    if combination == "joint":  # the joint fit needs one forgetting factor for both stages
        base["nonparametric.forgetting"] = EstimatorConfig.from_flat(ICUB_RIGHT_ARM)["parametric.forgetting"]
    return EstimatorConfig.from_flat(ICUB_RIGHT_ARM).with_overrides({**base, **overrides})


@pytest.fixture(scope="module")
def regressor():
    return build_regressor(EstimatorConfig.from_flat(ICUB_RIGHT_ARM))


def stream(n: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    n_joints = len(EstimatorConfig.from_flat(ICUB_RIGHT_ARM)["robot.joints"])
    return [(rng.uniform(-1, 1, 3 * n_joints), rng.normal(0, 2, 6)) for _ in range(n)]


def states_equal(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize(("kind", "combination"), LEARNERS)
def test_inputs_are_not_mutated_and_learn_one_equals_predict_learn_one(kind, combination, regressor):
    cfg = config(combination)
    a, b, c = (build_model(cfg, kind, regressor) for _ in range(3))
    assert isinstance(a, Learner)
    traits = traits_of(a)
    assert traits.kind == kind and traits.combination in (combination if kind == "SP" else None,)
    for x, y in stream(60, 1):
        x0, y0 = x.copy(), y.copy()
        a.learn_one(x, y)
        b.predict_learn_one(x, y)
        c.predict_one(x, return_variance=True)
        c.learn_ahead(c.predict_ahead(x), y)
        c.predict_held(x)
        assert np.array_equal(x, x0) and np.array_equal(y, y0)
    assert a.n_samples_seen == b.n_samples_seen == 60
    a.apply_pending()
    b.apply_pending()
    assert states_equal(a.state_dict(), b.state_dict())


@pytest.mark.parametrize(("kind", "combination"), LEARNERS)
def test_a_checkpoint_round_trip_predicts_and_learns_on_identically(kind, combination, regressor):
    cfg = config(combination)
    model = build_model(cfg, kind, regressor, sample_period_s=0.01)
    for x, y in stream(80, 2):
        model.learn_one(x, y)
    restored = build_model(cfg, kind, regressor, sample_period_s=0.01)
    restored.load_state_dict({k: v.copy() for k, v in model.state_dict().items()})
    for x, y in stream(30, 3):
        got, want = restored.predict_learn_one(x, y), model.predict_learn_one(x, y)
        assert np.array_equal(got.total, want.total)


@pytest.mark.parametrize(("kind", "combination"), [k for k in LEARNERS if k[0] != "P"])
def test_the_seed_fixes_the_random_features(kind, combination, regressor):
    preds = {}
    for seed in (0, 0, 1):
        model = build_model(config(combination, **{"nonparametric.seed": seed}), kind, regressor)
        for x, y in stream(120, 4):
            out = model.predict_learn_one(x, y)
        # the prediction and every learned weight (the consistent SP may weight its residual by 0 here)
        weights = np.concatenate([stage.weights.ravel() for stage in model.rls_stages()])
        preds.setdefault(seed, []).append(np.concatenate([out.total, weights]))
    assert np.array_equal(preds[0][0], preds[0][1])
    assert not np.array_equal(preds[0][0], preds[1][0])


@pytest.mark.parametrize(("kind", "combination"), LEARNERS)
def test_on_period_converts_seconds_and_is_idempotent(kind, combination, regressor):
    cfg = config(combination)
    once = build_model(cfg, kind, regressor)
    assert once.period_settings == PeriodSettings(TAU_S, WARMUP_S)
    twice = once.copy()
    period = 0.002
    beta = once.on_period(period)
    assert beta == twice.on_period(period) == twice.on_period(period)
    assert beta == pytest.approx(math.exp(-period / TAU_S), rel=1e-15)
    assert all(rls.forgetting == beta for rls in once.adaptive_stages())
    assert once.sample_period_s == twice.sample_period_s == period
    if kind != "P":  # the standardizer warm-up in seconds became samples at T
        npm = getattr(once, "nonparametric", once)
        assert npm.standardizer.warmup == round(WARMUP_S / period)
    assert states_equal(once.state_dict(), twice.state_dict())
    with pytest.raises(ValueError, match="sample period"):
        once.on_period(0.0)


def test_a_restored_consistent_model_takes_the_streams_period_in_every_part():
    """The estimator announces the measured period to a learner loaded from a checkpoint: the adaptive
    stages' β, the fast correction's memory and the warm-up equal those of a learner built at that period,
    although the checkpoint was written before its writer had measured any (provisional 100 Hz values)."""
    cfg = config("consistent")
    early = OnlineEstimator(cfg)
    for i, (x, y) in enumerate(stream(5, 5)):  # fewer stamps than the rate needs
        early.step(Sample(10**9 + i * 2_000_000, x[:4], x[4:8], x[8:], y))
    assert early.sample_period_s is None
    state = early.checkpoint_state()
    loader = OnlineEstimator(cfg)
    for i, (x, y) in enumerate(stream(12, 6)):  # the loader measures the same period first
        loader.step(Sample(10**9 + i * 2_000_000, x[:4], x[4:8], x[8:], y))
    loader.load_state(state)
    fresh = build_model(cfg, "SP", loader.regressor, sample_period_s=0.002)
    provisional = build_model(cfg, "SP", loader.regressor)
    assert loader.model.fast.forgetting == fresh.fast.forgetting != provisional.fast.forgetting
    assert [r.forgetting for r in loader.model.adaptive_stages()] == \
        [r.forgetting for r in fresh.adaptive_stages()]
    assert loader.model.nonparametric.standardizer.warmup == fresh.nonparametric.standardizer.warmup


# ----------------------------------------------------------------------------- the narrow contract
# Every model of the project — the builder's learners and the evaluation's reference models — is an
# OnlineModel: predict, learn, copy. The same checks run over all of them.

def _eval_models(regressor):
    """name → a fresh model of each kind the evaluation runs (built anew per call)."""
    from semiparam_ros.eval.models.baselines import (
        FixedParameters,
        Persistence,
        batch_least_squares,
        least_squares_model,
    )
    from semiparam_ros.eval.models.frozen import FrozenParametricSP
    from semiparam_ros.eval.models.served import node_learner

    cfg = config("cascade")
    rng = np.random.default_rng(7)
    b = 4

    def linear(x):  # a fixed regressor Φ(x) (6, b), smooth in x
        x = np.asarray(x)
        return np.outer(np.tanh(x[:6]), np.ones(b)) + np.outer(np.ones(6), np.cos(x[:b]))

    X = rng.uniform(-1, 1, (60, 3 * len(cfg["robot.joints"])))
    Y = np.array([linear(x) @ np.arange(1.0, b + 1) for x in X]) + rng.normal(0, 0.01, (60, 6))
    return {
        "Persistence": lambda: Persistence(6),
        "FixedParameters": lambda: FixedParameters(linear, np.arange(1.0, b + 1)),
        "LeastSquaresFit": lambda: least_squares_model(linear, batch_least_squares(linear, X, Y)),
        "FrozenParametricSP": lambda: FrozenParametricSP(build_model(cfg, "SP", regressor), 20),
        "NodeLearner": lambda: node_learner(config("consistent"), "SP"),
        **{f"{k}/{c}": (lambda k=k, c=c: build_model(config(c), k, regressor)) for k, c in LEARNERS},
    }


EVAL_MODELS = ["Persistence", "FixedParameters", "LeastSquaresFit", "FrozenParametricSP", "NodeLearner",
               *(f"{k}/{c}" for k, c in LEARNERS)]


def _total(prediction) -> np.ndarray:
    return np.asarray(getattr(prediction, "total", prediction))


@pytest.mark.parametrize("name", EVAL_MODELS)
def test_every_model_is_an_online_model_that_does_not_mutate_its_inputs(name, regressor):
    from semiparam_ros.core.learners.contract import OnlineModel

    model = _eval_models(regressor)[name]()
    assert isinstance(model, OnlineModel)
    for x, y in stream(40, 11):
        x0, y0 = x.copy(), y.copy()
        model.predict_one(x)
        model.predict_learn_one(x, y)
        model.learn_one(x, y)
        assert np.array_equal(x, x0) and np.array_equal(y, y0)
        assert np.all(np.isfinite(_total(model.predict_one(x))))


@pytest.mark.parametrize("name", EVAL_MODELS)
def test_predict_learn_one_is_learn_one_after_the_a_priori_prediction(name, regressor):
    """predict_learn_one returns what the model predicted before learning, and learns what learn_one learns
    (the next predictions of the two agree: bit for bit, or to the rounding of the fused update)."""
    make = _eval_models(regressor)[name]
    a, b = make(), make()
    data = stream(50, 12)
    for x, y in data:
        a.learn_one(x, y)
        b.predict_learn_one(x, y)
    for x, _ in stream(10, 13):
        np.testing.assert_allclose(_total(a.predict_one(x)), _total(b.predict_one(x)), rtol=1e-9, atol=1e-9)
    c = make()
    for x, y in data[:30]:
        c.learn_one(x, y)
    x, y = data[30]
    before = _total(c.copy().predict_one(x))
    np.testing.assert_allclose(_total(c.predict_learn_one(x, y)), before, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", EVAL_MODELS)
def test_a_copy_is_independent(name, regressor):
    model = _eval_models(regressor)[name]()
    for x, y in stream(30, 14):
        model.learn_one(x, y)
    probe = [x for x, _ in stream(5, 15)]
    twin = model.copy()
    twin.predict_one(probe[0])  # a deferred update is applied by the first prediction (rounding path)
    want = [_total(twin.predict_one(x)).copy() for x in probe]
    for x, y in stream(30, 16):
        model.learn_one(x, y * 3.0 + 1.0)
    for x, w in zip(probe, want, strict=True):
        assert np.array_equal(_total(twin.predict_one(x)), w)
