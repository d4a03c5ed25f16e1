"""JointSemiparametricModel against the closed-form solution of the joint ridge problem, summed directly."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import cho_factor, cho_solve

from semiparam_ros.core.learners.cascade import SemiparametricModel
from semiparam_ros.core.learners.features import Standardizer
from semiparam_ros.core.learners.joint import JointSemiparametricModel
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.parametric import ParametricModel

T, P, D, N_IN = 3, 4, 12, 2


def make_regressor(seed: int = 1):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((T, P, N_IN))
    c = rng.uniform(0, 2 * np.pi, (T, P))

    def regressor(x: np.ndarray) -> np.ndarray:
        return np.sin(a @ x + c) + 0.5

    return regressor


def features(model: JointSemiparametricModel, x: np.ndarray) -> np.ndarray:
    """φ(s(x)) recomputed from the model's (frozen) standardizer and random features."""
    npm = model.nonparametric
    s = (x - npm.standardizer.mean_) / npm.standardizer.scale_
    return np.sqrt(2.0 / D) * np.cos(s @ npm.rff.omega_ + npm.rff.offset_)


def joint_rows(Phi: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Rows of the stacked problem in θ = [π, vec(W)] (W[j, k] at p + j·t + k), one per output."""
    rows = np.zeros((T, P + D * T))
    rows[:, :P] = Phi
    for k in range(T):
        rows[k, P + np.arange(D) * T + k] = phi
    return rows


def closed_form(samples, regressor, feats, lam_p, lam_np, beta):
    """θ and the precision H of the joint ridge problem with the documented prior-keeping forgetting."""
    nth = P + D * T
    H = np.zeros((nth, nth))
    g = np.zeros(nth)
    prior = np.concatenate([np.full(P, lam_p), np.full(D * T, lam_np)])
    c_p = P * (1 - beta) * lam_p if beta < 1 else 0.0
    c_np = D * (1 - beta) * lam_np if beta < 1 else 0.0
    for m, ((x, y), phi) in enumerate(zip(samples, feats, strict=True)):
        H *= beta
        g *= beta
        prior *= beta
        prior[m % P] += c_p
        prior[P + (m % D) * T + np.arange(T)] += c_np
        Z = joint_rows(regressor(x), phi)
        H += Z.T @ Z
        g += Z.T @ y
    Hp = H + np.diag(prior)
    return cho_solve(cho_factor(Hp), g), Hp


def stream(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    reg = make_regressor()
    pi_true = rng.standard_normal(P)
    out = []
    for _ in range(n):
        x = rng.uniform(-1.5, 1.5, N_IN)
        y = reg(x) @ pi_true + 0.3 * np.sin(2 * x[0]) * np.cos(x[1]) + 0.01 * rng.standard_normal(T)
        out.append((x, y))
    return out


def new_model(beta: float = 1.0, warmup: int = 0, lam_p: float = 0.1, lam_np: float = 0.05):
    std = None if warmup else Standardizer(N_IN).fit(np.random.default_rng(5).uniform(-1.5, 1.5, (50, N_IN)))
    return JointSemiparametricModel(make_regressor(), P, N_IN, T, lam_parametric=lam_p,
                                    lam_nonparametric=lam_np, n_features=D, sigma=1.3, forgetting=beta,
                                    seed=3, standardizer=std, standardizer_warmup=warmup)


@pytest.mark.parametrize("beta", [1.0, 0.97])
def test_every_a_priori_prediction_and_pi_equal_the_closed_form(beta):
    data = stream(60)
    model = new_model(beta)
    reg = make_regressor()
    feats = [features(model, x) for x, _ in data]
    for n, (x, y) in enumerate(data):
        theta = closed_form(data[:n], reg, feats[:n], 0.1, 0.05, beta)[0] if n else np.zeros(P + D * T)
        expect = joint_rows(reg(x), feats[n]) @ theta
        pred = model.predict_learn_one(x, y)
        np.testing.assert_allclose(pred.total, expect, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(pred.parametric, reg(x) @ theta[:P], rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(pred.parametric + pred.residual, pred.total, rtol=0, atol=1e-12)
    theta, _ = closed_form(data, reg, feats, 0.1, 0.05, beta)
    np.testing.assert_allclose(model.parameters, theta[:P], rtol=1e-9, atol=1e-11)


def test_predict_one_and_variance_equal_the_closed_form():
    data = stream(40)
    model = new_model()
    for x, y in data:
        model.learn_one(x, y)
    reg = make_regressor()
    theta, H = closed_form(data, reg, [features(model, x) for x, _ in data], 0.1, 0.05, 1.0)
    x = np.array([0.3, -0.7])
    rows = joint_rows(reg(x), features(model, x))
    out = model.predict_one(x, return_variance=True)
    np.testing.assert_allclose(out.total, rows @ theta, rtol=1e-9)
    np.testing.assert_allclose(out.variance, np.einsum("ij,ji->i", rows, cho_solve(cho_factor(H), rows.T)),
                               rtol=1e-8)


@pytest.mark.parametrize("beta", [1.0, 0.97])
def test_warm_up_learns_the_rigid_body_term_alone_then_the_joint_problem_over_every_sample(beta):
    """During the warm-up the rigid-body term alone predicts and learns (a ParametricModel beside it); once
    the statistics are ready every a-priori prediction is the closed-form joint ridge over *all* the
    samples before, the warm-up's with their features (as if the statistics had been known from the
    first sample), with the documented prior-keeping forgetting."""
    data = stream(30)
    model = new_model(beta, warmup=8)
    reg = make_regressor()
    alone = ParametricModel(reg, P, T, lam=0.1, forgetting=beta)
    for n, (x, y) in enumerate(data[:8]):
        np.testing.assert_allclose(model.predict_learn_one(x, y).total, alone.predict_learn_one(x, y).total,
                                   rtol=1e-10, atol=1e-12)
        assert model.nonparametric.held_rows == (n + 1 if n < 7 else 0)
    assert model.nonparametric.standardizer.ready
    assert model.n_samples_seen == model.parametric.n_samples_seen == model.nonparametric.n_samples_seen == 8
    feats = [features(model, x) for x, _ in data]
    for n in range(8, 30):
        theta, _ = closed_form(data[:n], reg, feats[:n], 0.1, 0.05, beta)
        x, y = data[n]
        np.testing.assert_allclose(model.predict_learn_one(x, y).total, joint_rows(reg(x), feats[n]) @ theta,
                                   rtol=1e-9, atol=1e-10)


def snapshot(model):
    return {k: np.array(v, copy=True) for k, v in model.state_dict().items()}


def test_rejected_input_leaves_the_model_unchanged():
    data = stream(20)
    calls = {"bad": False}
    reg = make_regressor()

    def flaky(x):
        return np.full((T, P), np.nan) if calls["bad"] else reg(x)

    model = JointSemiparametricModel(flaky, P, N_IN, T, lam_parametric=0.1, lam_nonparametric=0.05,
                                     n_features=D, sigma=1.3, seed=3, standardizer_warmup=5)
    for x, y in data:
        model.learn_one(x, y)
    before = snapshot(model)
    x, y = data[0]
    for bad_x, bad_y in [([np.nan, 0.0], y), (x, y[:2]), (x, [np.inf, 0, 0]), (np.zeros(3), y)]:
        with pytest.raises(ValueError):
            model.predict_learn_one(bad_x, bad_y)
    calls["bad"] = True
    with pytest.raises(ValueError, match="regressor"):
        model.learn_one(x, y)
    after = snapshot(model)
    assert before.keys() == after.keys()
    for key in before:
        np.testing.assert_array_equal(before[key], after[key])


def test_save_load_copy_reset(tmp_path):
    data = stream(30)
    model = new_model(beta=0.99, warmup=5)
    for x, y in data[:20]:
        model.learn_one(x, y)
    path = tmp_path / "joint.npz"
    model.save(path)
    twin = new_model(beta=0.99, warmup=5).load(path)
    clone = model.copy()
    for x, y in data[20:]:
        a, b, c = model.predict_learn_one(x, y), twin.predict_learn_one(x, y), clone.predict_learn_one(x, y)
        np.testing.assert_array_equal(a.total, b.total)
        np.testing.assert_array_equal(a.total, c.total)
    clone.learn_one(*data[0])
    assert clone.n_samples_seen == model.n_samples_seen + 1
    assert not np.array_equal(clone.parameters, model.parameters)
    # another kind, another size, another forgetting: refused, model unchanged
    cascade = SemiparametricModel(make_regressor(), P, N_IN, T, n_features=D, standardizer_warmup=5)
    before = snapshot(model)
    with pytest.raises(ValueError, match="semiparametric"):
        model.load_state_dict(cascade.state_dict())
    for n_params, n_inputs in [(P, N_IN + 1), (P + 1, N_IN)]:
        other = JointSemiparametricModel(make_regressor(), n_params, n_inputs, T, n_features=D,
                                         standardizer_warmup=5)
        with pytest.raises(ValueError):
            other.load(path)
    mixed = model.state_dict()
    mixed.update(new_model(beta=1.0, warmup=5).parametric.state_dict("parametric."))
    with pytest.raises(ValueError):
        model.load_state_dict(mixed)
    for key, value in snapshot(model).items():
        np.testing.assert_array_equal(value, before[key])
    model.reset()
    assert model.n_samples_seen == 0 and not model.nonparametric.standardizer.ready
    np.testing.assert_array_equal(model.parameters, np.zeros(P))


def test_extrapolates_with_the_rigid_body_term_where_the_kernel_has_no_data():
    """Trained on x₀ < 0 only: on x₀ > 0.8 the kernel predicts ~0, the joint model keeps Φπ̂.

    NP has nothing there; the joint model's error stays near the size of the residual it cannot know.
    """
    rng = np.random.default_rng(7)
    reg = make_regressor()
    pi_true = np.array([1.0, -2.0, 0.5, 1.5])

    def truth(x):
        return reg(x) @ pi_true + 0.2 * np.cos(3 * x[1])

    kw = dict(n_features=200, sigma=0.5, seed=0, standardizer_warmup=50)
    joint = JointSemiparametricModel(reg, P, N_IN, T, lam_parametric=1e-3, lam_nonparametric=1e-3, **kw)
    nonpar = NonparametricModel(N_IN, T, lam=1e-3, **kw)
    for _ in range(1500):
        x = np.array([rng.uniform(-1.5, 0.0), rng.uniform(-1.5, 1.5)])
        y = truth(x) + 0.01 * rng.standard_normal(T)
        joint.learn_one(x, y)
        nonpar.learn_one(x, y)
    test = [np.array([rng.uniform(0.8, 1.5), rng.uniform(-1.5, 1.5)]) for _ in range(200)]
    err_joint = np.sqrt(np.mean([(joint.predict_one(x).total - truth(x)) ** 2 for x in test]))
    err_np = np.sqrt(np.mean([(nonpar.predict_one(x).total - truth(x)) ** 2 for x in test]))
    scale = np.sqrt(np.mean([truth(x) ** 2 for x in test]))
    assert err_joint < 0.25 * err_np, (err_joint, err_np)
    assert err_joint < 0.2 * scale, (err_joint, scale)


def test_invalid_hyperparameters():
    with pytest.raises(ValueError):
        JointSemiparametricModel(make_regressor(), P, N_IN, T, forgetting=1.5)
    with pytest.raises(ValueError):
        JointSemiparametricModel(make_regressor(), P, N_IN, T, lam_parametric=0.0)
    with pytest.raises(ValueError):
        JointSemiparametricModel("not callable", P, N_IN, T)  # type: ignore[arg-type]
