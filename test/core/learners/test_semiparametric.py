"""P / NP / SP models on a toy system linear in its parameters plus a nonlinear residual."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import cho_factor, cho_solve

from semiparam_ros.core.learners.cascade import SemiparametricModel
from semiparam_ros.core.learners.contract import Prediction
from semiparam_ros.core.learners.features import Standardizer
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.parametric import ParametricModel

G = 9.81
PI_TRUE = np.array([1.5, 2.0, 0.3, -0.4])


def regressor(x):
    """Toy 2-joint regressor Φ(x) (2 outputs × 4 parameters), x = [q0, q1, dq0, dq1, ddq0, ddq1]."""
    q0, q1, dq0, dq1, a0, a1 = x
    return np.array([[a0, G * np.cos(q0), dq0, a1], [a1, G * np.sin(q0 + q1), dq1, a0]])


def residual(x):
    """What the rigid-body model cannot express: friction-like and coupling terms."""
    q0, q1, dq0, dq1, _, _ = x
    return np.array([0.8 * np.tanh(3 * dq0) + 0.3 * np.sin(2 * q1), 0.5 * np.tanh(3 * dq1) + 0.4 * q0 * q1])


def toy_data(rng, n, with_residual=True, noise=0.05):
    X = np.column_stack([rng.uniform(-1.5, 1.5, (n, 2)), rng.standard_normal((n, 2)),
                         2 * rng.standard_normal((n, 2))])
    Y = np.array([regressor(x) @ PI_TRUE + (residual(x) if with_residual else 0.0) for x in X])
    return X, Y + noise * rng.standard_normal(Y.shape)


def make(kind, **kw):
    if kind == "P":
        return ParametricModel(regressor, 4, 2, lam=kw.get("lam", 1e-3), forgetting=kw.get("beta", 1.0))
    if kind == "NP":
        return NonparametricModel(6, 2, n_features=kw.get("D", 300), sigma=2.0, lam=0.1,
                                  forgetting=kw.get("beta", 1.0), seed=1,
                                  standardizer_warmup=kw.get("warmup", 200))
    return SemiparametricModel(regressor, 4, 6, 2, lam_parametric=1e-3, lam_nonparametric=0.1,
                               n_features=kw.get("D", 300), sigma=2.0,
                               forgetting_parametric=kw.get("beta", 1.0),
                               forgetting_nonparametric=kw.get("beta", 1.0), seed=1,
                               standardizer_warmup=kw.get("warmup", 200))


def rmse(model, X, Y):
    P = np.array([model.predict_one(x).total for x in X])
    return float(np.sqrt(np.mean((P - Y) ** 2)))


def test_sp_beats_p_and_np_on_held_out_data():
    rng = np.random.default_rng(0)
    X, Y = toy_data(rng, 2000)
    Xt, Yt = toy_data(rng, 1000)
    models = {k: make(k) for k in ("P", "NP", "SP")}
    for m in models.values():
        for x, y in zip(X, Y, strict=True):
            m.predict_learn_one(x, y)
    err = {k: rmse(m, Xt, Yt) for k, m in models.items()}
    # P cannot express the residual (its error is the residual's size); NP must learn the large
    # rigid-body part from 2000 samples; SP gets both.
    assert err["SP"] < 0.7 * err["P"], err
    assert err["SP"] < 0.3 * err["NP"], err
    assert err["P"] > 5 * 0.05  # P is far above the noise level: the residual is not in span Φ
    # the parametric stage runs first and alone: SP's π̂ is exactly the P model's
    np.testing.assert_array_equal(models["SP"].parameters, models["P"].parameters)


def test_parametric_model_is_closed_form_ridge_on_stacked_rows():
    rng = np.random.default_rng(1)
    X, Y = toy_data(rng, 300, with_residual=False)
    lam = 0.5
    p = ParametricModel(regressor, 4, 2, lam=lam)
    for x, y in zip(X, Y, strict=True):
        p.learn_one(x, y)
    Phi = np.vstack([regressor(x) for x in X])
    pi = cho_solve(cho_factor(Phi.T @ Phi + lam * np.eye(4)), Phi.T @ Y.ravel())
    np.testing.assert_allclose(p.parameters, pi, rtol=1e-10)
    assert np.abs(p.parameters - PI_TRUE).max() < 0.02
    assert p.n_samples_seen == 300 and p.rls.n_samples_seen == 600


def test_parametric_model_with_other_parameters_predicts_them_and_learns_as_before(tmp_path):
    """``use_rigid(θ)``: every prediction path gives Φ(x)θ (computed here from the regressor), the learned
    π̂ stays the closed-form ridge fit (the same as a twin's); reset and a loaded state clear θ."""
    rng = np.random.default_rng(2)
    X, Y = toy_data(rng, 120, with_residual=False)
    p, twin = ParametricModel(regressor, 4, 2, lam=0.5), ParametricModel(regressor, 4, 2, lam=0.5)
    theta = np.array([1.0, 2.5, -0.2, 0.1])
    p.use_rigid(theta)
    for x, y in zip(X[:60], Y[:60], strict=True):
        np.testing.assert_allclose(p.predict_learn_one(x, y).total, regressor(x) @ theta, rtol=1e-13)
        twin.learn_one(x, y)
    for x, y in zip(X[60:], Y[60:], strict=True):
        ctx = p.predict_ahead(x)
        np.testing.assert_allclose(ctx.prediction.total, regressor(x) @ theta, rtol=1e-13)
        p.learn_ahead(ctx, y)
        twin.learn_one(x, y)
    np.testing.assert_array_equal(p.parameters, twin.parameters)
    np.testing.assert_allclose(p.predict_many(X[:5]).total, [regressor(x) @ theta for x in X[:5]], rtol=1e-13)
    np.testing.assert_allclose(p.predict_one(X[0], return_variance=True).variance,
                               twin.predict_one(X[0], return_variance=True).variance, rtol=1e-13)
    p.save(tmp_path / "p.npz")
    loaded = ParametricModel(regressor, 4, 2, lam=0.5)
    loaded.use_rigid(theta)
    loaded.load(tmp_path / "p.npz")
    assert loaded.rigid_override is None  # not part of the state: predicts with the learned π̂
    np.testing.assert_allclose(loaded.predict_one(X[0]).total, regressor(X[0]) @ twin.parameters, rtol=1e-10)
    p.reset()
    assert p.rigid_override is None


def test_semiparametric_composition_matches_closed_form():
    """SP = ridge on Φ rows, then ridge of y − ŷ_apriori on φ([x, ŷ_apriori]), each solved directly."""
    rng = np.random.default_rng(2)
    X, Y = toy_data(rng, 150)
    lam_p, lam_np = 1e-2, 0.1
    sp = SemiparametricModel(regressor, 4, 6, 2, lam_parametric=lam_p, lam_nonparametric=lam_np,
                             n_features=40, sigma=3.0, seed=3)  # identity standardizer
    preds = [sp.predict_learn_one(x, y) for x, y in zip(X, Y, strict=True)]
    A = lam_p * np.eye(4)
    b = np.zeros(4)
    rows, targets, yhat = [], [], []
    for x, y in zip(X, Y, strict=True):
        Phi = regressor(x)
        yp = Phi @ np.linalg.solve(A, b)  # a-priori parametric prediction
        yhat.append(yp)
        A += Phi.T @ Phi
        b += Phi.T @ y
        rows.append(sp.nonparametric.rff.transform(np.concatenate([x, yp])))
        targets.append(y - yp)
    F, T = np.array(rows), np.array(targets)
    W = cho_solve(cho_factor(F.T @ F + lam_np * np.eye(40)), F.T @ T)
    np.testing.assert_allclose(sp.parametric.parameters, np.linalg.solve(A, b), rtol=1e-9)
    np.testing.assert_allclose(sp.nonparametric.rls.weights, W, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(np.array([p.parametric for p in preds]), np.array(yhat), rtol=1e-8, atol=1e-10)
    for p in preds:
        np.testing.assert_allclose(p.total, p.parametric + p.residual)


def test_sp_warmup_standardizes_yhat_with_measured_y_statistics():
    """SP's online warm-up: x block from the x statistics, ŷ block from the measured y (default) or from
    the a-priori ŷ (``yhat_statistics="predicted"``), each against numpy on the warm-up samples; the
    closed-form ridge gives the a-priori ŷ independently."""
    rng = np.random.default_rng(7)
    X, Y = toy_data(rng, 60)
    n_warm, lam_p = 40, 1e-2
    yhat = []
    A, b = lam_p * np.eye(4), np.zeros(4)
    for x, y in zip(X[:n_warm], Y[:n_warm], strict=True):
        Phi = regressor(x)
        yhat.append(Phi @ np.linalg.solve(A, b))
        A += Phi.T @ Phi
        b += Phi.T @ y
    yhat = np.array(yhat)
    for mode, ystats in (("measured", Y[:n_warm]), ("predicted", yhat)):
        sp = SemiparametricModel(regressor, 4, 6, 2, lam_parametric=lam_p, lam_nonparametric=0.1,
                                 n_features=30, sigma=2.0, seed=1, standardizer_warmup=n_warm,
                                 yhat_statistics=mode)
        for i, (x, y) in enumerate(zip(X, Y, strict=True)):
            pred = sp.predict_learn_one(x, y)
            if i < n_warm:
                assert np.array_equal(pred.residual, np.zeros(2))
        std = sp.nonparametric.standardizer
        assert std.ready and sp.nonparametric.rls.n_samples_seen == len(X)  # the warm-up's rows too
        expect = np.hstack([X[:n_warm], ystats])
        np.testing.assert_allclose(std.mean_, expect.mean(0), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(std.scale_, expect.std(0), rtol=1e-9)
        # the residual stage's input after the warm-up is [x, ŷ] (not y): predictions use ŷ
        x = X[-1]
        yp = sp.parametric.predict_one(x).total
        feat = sp.nonparametric.rff.transform(std.transform(np.concatenate([x, yp])))
        np.testing.assert_allclose(sp.predict_one(x).residual, (feat @ sp.nonparametric.rls.weights).ravel(),
                                   rtol=1e-10, atol=1e-12)
    assert not np.allclose(Y[:n_warm].std(0), yhat.std(0), rtol=1e-3)  # the two modes really differ
    with pytest.raises(ValueError, match="yhat_statistics"):
        SemiparametricModel(regressor, 4, 6, 2, yhat_statistics="ŷ")


@pytest.mark.parametrize("kind", ["P", "NP", "SP"])
def test_predict_learn_one_equals_predict_then_learn(kind):
    rng = np.random.default_rng(3)
    X, Y = toy_data(rng, 120)
    a, b = make(kind, D=50, warmup=30, beta=0.99), make(kind, D=50, warmup=30, beta=0.99)
    for x, y in zip(X, Y, strict=True):
        pa = a.predict_learn_one(x, y)
        pb = b.predict_one(x)
        b.learn_one(x, y)
        for field in ("parametric", "residual", "total"):
            np.testing.assert_allclose(getattr(pa, field), getattr(pb, field), rtol=1e-9, atol=1e-12)
        assert isinstance(pa, Prediction) and pa.total.shape == (2,)
    assert a.n_samples_seen == b.n_samples_seen == 120
    sa, sb = a.state_dict(), b.state_dict()
    for k in sa:
        if sa[k].dtype.kind == "f":
            np.testing.assert_allclose(sa[k], sb[k], rtol=1e-12, atol=1e-14, err_msg=k)
        else:
            assert np.array_equal(sa[k], sb[k]), k
    p = a.predict_one(X[0], return_variance=True)
    assert p.variance is not None and p.variance.shape == (2,) and np.all(p.variance >= 0)


@pytest.mark.parametrize("kind", ["NP", "SP"])
def test_warmup_then_learning(kind):
    """The residual predicts zero during the warm-up, then learns every sample, the warm-up's included:
    its weights are the closed-form ridge on all 80 rows (features with the warm-up's statistics; SP's
    targets y − ŷ with ŷ the a-priori closed-form rigid body, its input [x, ŷ])."""
    rng = np.random.default_rng(4)
    X, Y = toy_data(rng, 80)
    m = make(kind, D=30, warmup=50)
    npm = m if kind == "NP" else m.nonparametric
    for i, (x, y) in enumerate(zip(X, Y, strict=True)):
        pred = m.predict_learn_one(x, y)
        if i < 50:
            assert np.array_equal(pred.residual, np.zeros(2))
            assert npm.rls.n_samples_seen == (0 if i < 49 else 50)  # the 50 held rows, learned at once
            assert npm.held_rows == (i + 1 if i < 49 else 0)
    assert npm.standardizer.ready and npm.rls.n_samples_seen == 80
    if kind == "NP":
        inputs, targets = X, Y
    else:
        A, b, yhat = 1e-3 * np.eye(4), np.zeros(4), []
        for x, y in zip(X, Y, strict=True):
            Phi = regressor(x)
            yhat.append(Phi @ np.linalg.solve(A, b))
            A += Phi.T @ Phi
            b += Phi.T @ y
        inputs, targets = np.hstack([X, yhat]), Y - np.array(yhat)
    np.testing.assert_allclose(npm.standardizer.mean_, inputs[:50].mean(0) if kind == "NP" else
                               npm.standardizer.mean_, rtol=1e-10)
    F = npm.rff.transform(npm.standardizer.transform(inputs))
    W = np.linalg.solve(F.T @ F + npm.rls.lam * np.eye(F.shape[1]), F.T @ targets)
    # both are the ridge solution: they differ by the rounding of a solve (cond·ε relative) and, for SP, by
    # that of the early a-priori ŷ in the targets (a rank-deficient rigid body): 1000·cond·ε·max|W| bounds
    # both (measured: 6e-13 NP, 6e-12 SP, against 2e-9 / 2e-10)
    cond = np.linalg.cond(F.T @ F + npm.rls.lam * np.eye(F.shape[1]))
    np.testing.assert_allclose(npm.rls.weights, W, rtol=0,
                               atol=1000 * cond * np.finfo(float).eps * np.abs(W).max())
    assert not np.array_equal(m.predict_one(X[0]).residual, np.zeros(2))
    # a pre-fitted standardizer: learning starts at the first sample
    std = Standardizer(6).fit(X)
    pre = NonparametricModel(6, 2, n_features=30, sigma=2.0, standardizer=std)
    pre.learn_one(X[0], Y[0])
    assert pre.rls.n_samples_seen == 1
    with pytest.raises(ValueError):
        NonparametricModel(6, 2, standardizer=Standardizer(6))  # neither fitted nor warming up
    with pytest.raises(ValueError):
        NonparametricModel(6, 2, standardizer=Standardizer(5).fit(np.ones((3, 5))))
    m.reset()
    assert m.n_samples_seen == 0 and not npm.standardizer.ready if kind == "NP" else True


@pytest.mark.parametrize("kind", ["P", "NP", "SP"])
def test_copy_shares_regressor_and_deep_copies_state(kind):
    rng = np.random.default_rng(5)
    X, Y = toy_data(rng, 60)
    m = make(kind, D=30, warmup=10)
    for x, y in zip(X[:30], Y[:30], strict=True):
        m.learn_one(x, y)
    c = m.copy()
    if kind != "NP":
        assert c.regressor is m.regressor
    before = m.state_dict()
    for x, y in zip(X[30:], Y[30:], strict=True):
        c.learn_one(x, y)
    after = m.state_dict()
    assert all(np.array_equal(before[k], after[k]) for k in before)
    assert c.n_samples_seen == 60 and m.n_samples_seen == 30


@pytest.mark.parametrize("kind", ["P", "NP", "SP"])
def test_save_load_round_trip_bit_for_bit(kind, tmp_path):
    rng = np.random.default_rng(6)
    X, Y = toy_data(rng, 100)
    m = make(kind, D=40, warmup=20, beta=0.995)
    for x, y in zip(X[:60], Y[:60], strict=True):
        m.learn_one(x, y)
    m.save(tmp_path / "m.npz")
    fresh = make(kind, D=40, warmup=20, beta=0.995)
    assert fresh.load(tmp_path / "m.npz") is fresh
    for x, y in zip(X[60:], Y[60:], strict=True):
        pa, pb = m.predict_learn_one(x, y), fresh.predict_learn_one(x, y)
        assert np.array_equal(pa.total, pb.total) and np.array_equal(pa.residual, pb.residual)
    if kind != "NP":
        assert np.array_equal(m.parameters, fresh.parameters)
    else:
        assert m.parameters is None


def test_load_rejects_mismatched_state_and_leaves_model_unchanged(tmp_path):
    rng = np.random.default_rng(7)
    X, Y = toy_data(rng, 30)
    sp = make("SP", D=30, warmup=5)
    for x, y in zip(X, Y, strict=True):
        sp.learn_one(x, y)
    before = sp.state_dict()
    other = make("SP", D=20, warmup=5)
    other.save(tmp_path / "other.npz")  # different n_features: loads (features are part of the state)
    make("P").save(tmp_path / "p.npz")
    with pytest.raises(ValueError, match="parametric"):
        sp.load(tmp_path / "p.npz")
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    with pytest.raises(ValueError):
        sp.load(tmp_path / "bad.npz")
    wrong = SemiparametricModel(lambda x: np.zeros((2, 3)), 3, 6, 2, n_features=30)
    wrong.save(tmp_path / "wrong.npz")
    with pytest.raises(ValueError, match="n_params"):
        sp.load(tmp_path / "wrong.npz")
    after = sp.state_dict()
    assert before.keys() == after.keys() and all(np.array_equal(before[k], after[k]) for k in before)


@pytest.mark.parametrize("kind", ["P", "NP", "SP"])
def test_bad_input_leaves_model_unchanged(kind):
    rng = np.random.default_rng(8)
    X, Y = toy_data(rng, 40)
    m = make(kind, D=20, warmup=10)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    before = m.state_dict()
    x_nan = X[0].copy()
    x_nan[2] = np.nan
    bad = [(x_nan, Y[0]), (X[0], np.array([np.inf, 0.0])), (X[0], np.ones(3)), (np.ones((2, 6)), Y[0]),
           (X[0][:5] if kind != "P" else np.ones((1, 1)), Y[0])]
    for x, y in bad:
        for method in (m.learn_one, m.predict_learn_one):
            with pytest.raises(ValueError):
                method(x, y)
    after = m.state_dict()
    assert all(np.array_equal(before[k], after[k]) for k in before)
    assert m.n_samples_seen == 40


@pytest.mark.parametrize("kind", ["P", "SP"])
def test_bad_regressor_output_is_rejected(kind):
    calls = {"n": 0}

    def flaky(x):
        calls["n"] += 1
        out = regressor(x)
        if calls["n"] > 3:
            out[0, 0] = np.nan
        return out

    m = (ParametricModel(flaky, 4, 2) if kind == "P"
         else SemiparametricModel(flaky, 4, 6, 2, n_features=20))
    X, Y = toy_data(np.random.default_rng(9), 4)
    for x, y in zip(X[:3], Y[:3], strict=True):
        m.learn_one(x, y)
    before = m.state_dict()
    with pytest.raises(ValueError, match="regressor"):
        m.learn_one(X[3], Y[3])
    assert all(np.array_equal(before[k], m.state_dict()[k]) for k in before)
    with pytest.raises(ValueError, match="shape"):
        ParametricModel(lambda x: np.zeros((3, 4)), 4, 2).learn_one(X[0], Y[0])


def test_forgetting_adapts_to_a_parameter_change():
    """After a payload-like change of π, a forgetting P model tracks the new parameters; β = 1 lags."""
    rng = np.random.default_rng(10)
    X, Y = toy_data(rng, 3000, with_residual=False, noise=0.02)
    new = PI_TRUE + np.array([0.5, 0.3, 0.0, 0.0])
    Y2 = np.array([regressor(x) @ new for x in X])
    keep, forget = make("P", beta=1.0), make("P", beta=0.98)
    for i, (x, y) in enumerate(zip(X, Y, strict=True)):
        target = y if i < 2000 else Y2[i]
        keep.learn_one(x, target)
        forget.learn_one(x, target)
    assert np.abs(forget.parameters - new).max() < 0.01
    assert np.abs(keep.parameters - new).max() > 0.1


@pytest.mark.parametrize("kind", ["P", "NP", "SP"])
def test_inputs_not_mutated_and_prediction_does_not_learn(kind):
    rng = np.random.default_rng(11)
    X, Y = toy_data(rng, 30)
    m = make(kind, D=20, warmup=5)
    Xc, Yc = X.copy(), Y.copy()
    for x, y in zip(X, Y, strict=True):
        m.predict_learn_one(x, y)
        m.learn_one(x, y)
    np.testing.assert_array_equal(X, Xc)
    np.testing.assert_array_equal(Y, Yc)
    before = m.state_dict()
    for x in X:
        m.predict_one(x)
        m.predict_one(x, return_variance=True)
    after = m.state_dict()
    assert all(np.array_equal(before[k], after[k]) for k in before)
    # strided (non-contiguous) views are accepted and give the same answer as contiguous copies
    Xf = np.asfortranarray(X)
    np.testing.assert_array_equal(m.predict_one(Xf[3]).total, m.predict_one(X[3].copy()).total)


def test_semiparametric_with_forgetting_tracks_a_payload_change():
    """After π changes mid-stream, SP with prior-keeping forgetting recovers; without forgetting it lags."""
    rng = np.random.default_rng(12)
    X, Y = toy_data(rng, 4000, noise=0.02)
    shift = np.array([0.8, 0.5, 0.0, 0.0])
    Y2 = Y + np.array([regressor(x) @ shift for x in X])
    fixed, adaptive = make("SP", D=100, warmup=100), make("SP", D=100, warmup=100, beta=0.99)
    for i in range(3000):
        y = Y[i] if i < 2000 else Y2[i]
        fixed.predict_learn_one(X[i], y)
        adaptive.predict_learn_one(X[i], y)
    Xt, Yt = X[3000:], Y2[3000:]
    assert rmse(adaptive, Xt, Yt) < 0.5 * rmse(fixed, Xt, Yt)
    assert np.all(np.isfinite(adaptive.parameters))


def test_predict_then_learn_the_same_sample_evaluates_the_regressor_once():
    """The contact gate predicts, then learns the same x: Φ(x) is computed once, and a new x (or the same
    values in another array) gives the regressor's own answer, so the cache changes no number."""
    calls = []

    def counting(x):
        calls.append(np.array(x))
        return np.array([[x[0], 1.0], [x[0] ** 2, x[0]]])

    model = ParametricModel(counting, 2, 2, lam=1e-3)
    reference = ParametricModel(lambda x: np.array([[x[0], 1.0], [x[0] ** 2, x[0]]]), 2, 2, lam=1e-3)
    rng = np.random.default_rng(0)
    for _ in range(20):
        x = rng.normal(size=1)
        y = rng.normal(size=2)
        before = len(calls)
        got = model.predict_one(x).total
        model.learn_one(x.copy(), y)
        assert len(calls) == before + 1
        np.testing.assert_array_equal(got, reference.predict_one(x).total)
        reference.learn_one(x, y)
    np.testing.assert_array_equal(model.parameters, reference.parameters)
