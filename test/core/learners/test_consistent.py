"""The consistent semiparametric model against closed-form ridge, and its tracker against Kalman theory."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from semiparam_ros.core.learners.consistent import ConsistentSemiparametricModel, ErrorTracker
from semiparam_ros.core.learners.features import Standardizer
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.errors import CheckpointError, RejectedSampleError


def regressor(x: np.ndarray) -> np.ndarray:
    """Two outputs, three parameters, nonlinear in the state of two joints (x = [q1, q2, dq1, dq2, ...])."""
    q1, q2, dq1 = x[0], x[1], x[2]
    return np.array([[math.sin(q1), dq1, 1.0], [math.cos(q2), q1 * dq1, 0.5]])


def truth(x: np.ndarray) -> np.ndarray:
    """The rigid-body part with π = [2, 0.5, -1] plus an effect it cannot express."""
    rigid = regressor(x) @ np.array([2.0, 0.5, -1.0])
    return rigid + np.array([0.3 * np.tanh(3 * x[3]), 0.2 * x[0] ** 2])


def data(n: int, seed: int, spread: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.uniform(-spread, spread, size=(n, 6))
    Y = np.array([truth(x) for x in X]) + 0.01 * rng.normal(size=(n, 2))
    return X, Y


STD = Standardizer(6, mean=np.zeros(6), scale=np.full(6, 0.6))


def model(**kw) -> ConsistentSemiparametricModel:
    args = dict(lam_parametric=1e-2, lam_nonparametric=1e-1, n_features=80, sigma=1.5, seed=3,
                standardizer=STD, novelty_scale=0.05, tracker=False)
    args.update(kw)
    return ConsistentSemiparametricModel(regressor, 3, 6, 2, **args)


def test_residual_is_the_ridge_fit_of_what_the_final_parameters_leave():
    """At every sample the model predicts with its reference θ_ref (π̂ as it was at the last re-reference:
    after 1, 2, 4, … learned samples, then every 50), and its residual is the closed-form ridge fit, on
    the features, of y − Φθ_ref over *all* the samples before (never of the stale targets it learned with
    other references), times its weight g = s²(1 − ν)/(s²(1 − ν) + σ²v/ν₀) per output (v = φA⁻¹φᵀ,
    ν = λv). σ² and s² are recomputed here from the a-priori errors: σ² the mean of (y − ŷ_P − r)², s² the
    recent mean of (y − ŷ_P)² (memory 1 s at the provisional 100 Hz, i.e. 100 samples) minus σ². After
    learning, the residual of the final π̂ (given explicitly, or made the reference by
    ``use_rigid(None)``) is the ridge fit of y − Φπ̂; used alone (``predict_model``) its weight counts
    the residual's error c times (c by batch means of the same a-priori errors). Every solve is of a
    λ = 0.1 system of condition ≲ 1e3: agreement to 1e-9 relative is far above rounding."""
    m = model()
    assert m._reference_samples == 50  # max(0.5 s / 10 ms, REFERENCE_MIN_SAMPLES)
    X, Y = data(400, 0)
    Z = np.array([m.nonparametric.features_of(x)[0] for x in X])
    noise_sum, recent = np.zeros(2), np.zeros(2)
    smooth, smooth_sum, a_c = np.zeros(2), np.zeros(2), 1.0 - m._corr_beta  # batch means of the errors
    beta = math.exp(-1.0 / 100.0)
    reference, since = np.zeros(3), 0  # the prior
    A0 = 0.1 * np.eye(Z.shape[1])
    for i, (x, y) in enumerate(zip(X, Y, strict=True)):
        rigid = regressor(x) @ reference
        if i:
            targets = Y[:i] - np.array([regressor(xk) @ reference for xk in X[:i]])
            r = Z[i] @ np.linalg.solve(Z[:i].T @ Z[:i] + A0, Z[:i].T @ targets)
            pred = m.predict_one(x, return_variance=True)
            raw = m._raw
            np.testing.assert_allclose(raw, r, rtol=1e-9, atol=1e-12)
        else:
            r = np.zeros(2)
            pred = m.predict_one(x, return_variance=True)
        np.testing.assert_allclose(pred.parametric, rigid, rtol=1e-12, atol=1e-12)
        noise_sum += (y - rigid - r) ** 2
        smooth += a_c * (y - rigid - r - smooth)
        smooth_sum += smooth ** 2
        a = max(1.0 / (i + 1), 1.0 - beta)
        recent += a * ((y - rigid) ** 2 - recent)
        m.learn_one(x, y)
        since += 1
        if since >= min(50, i + 1):  # after 1, 2, 4, … 32 learned samples, then every 50
            reference, since = m.parametric.parameters, 0
    sigma2 = noise_sum / len(X)
    s2 = np.maximum(recent - sigma2, 0.0)
    got_s2, got_sigma2 = m.error_scales()
    np.testing.assert_allclose(got_sigma2, sigma2, rtol=1e-8)
    np.testing.assert_allclose(got_s2, s2, rtol=1e-8)
    pi = m.parametric.parameters
    targets = Y - np.array([regressor(x) @ pi for x in X])
    A = Z.T @ Z + A0
    W = np.linalg.solve(A, Z.T @ targets)
    Xt, _ = data(50, 1)

    # the model used alone weighs the residual's error by c, the samples its errors stay correlated
    c = np.maximum(smooth_sum / noise_sum * (2.0 - a_c) / a_c, 1.0)
    np.testing.assert_allclose(m.correlation_samples(), c, rtol=1e-8)
    assert np.any(c > 1.5)  # (correlated errors on an output: the weights below differ there)

    def want(x: np.ndarray, corr: np.ndarray | float = 1.0) -> np.ndarray:
        z = m.nonparametric.features_of(x)[0]
        v = z @ np.linalg.solve(A, z)
        signal = s2 * max(0.0, 1.0 - 0.1 * v)  # s² times the explained fraction 1 − ν, ν = λv
        return signal / (signal + corr * sigma2 * v / 0.05) * (z @ W)

    explicit = m.predict_model_many(Xt, rigid=pi)
    for k, x in enumerate(Xt):
        np.testing.assert_allclose(m.predict_model(x, rigid=pi).residual, want(x, c), rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(explicit.residual[k], want(x, c), rtol=1e-8, atol=1e-10)
    m.use_rigid(None)  # the reference follows the learned π̂ now
    for x in Xt:
        pred = m.predict_one(x)
        np.testing.assert_allclose(pred.residual, want(x), rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(pred.parametric, regressor(x) @ pi, rtol=1e-12)
        np.testing.assert_allclose(pred.total, pred.parametric + pred.residual, rtol=1e-15)


def test_the_residual_is_trusted_as_far_as_the_rigid_body_part_is_poor():
    """The residual's weight follows the rigid-body part's own error: with an effect the rigid body cannot
    express (poor rigid body) the residual is used at moderately novel states; where the rigid body is
    exact (targets = rigid body + noise), the same states get (almost) none of it."""
    rng = np.random.default_rng(7)
    X = rng.uniform(-0.5, 0.5, size=(600, 6))
    exact = (np.array([regressor(x) @ np.array([2.0, 0.5, -1.0]) for x in X])
             + 0.01 * rng.normal(size=(600, 2)))
    poor = np.array([truth(x) for x in X]) + 0.01 * rng.normal(size=(600, 2))
    weights = {}
    for name, Y in (("exact", exact), ("poor", poor)):
        m = model(novelty_scale=1.0)  # the default
        for x, y in zip(X, Y, strict=True):
            m.learn_one(x, y)
        Xt = rng.uniform(0.6, 0.9, size=(50, 6))  # beside the training box: moderately novel
        npm = m.nonparametric
        v = np.array([npm.rls.predict(npm.features_of(x), return_variance=True, checked=True)[1][0]
                      for x in Xt])
        weights[name] = m.residual_weight(v).mean()
    assert weights["poor"] > 0.3
    assert weights["exact"] < 0.1 * weights["poor"]


def test_parametric_part_is_the_cascade_rigid_body_stage():
    """The rigid-body part is fitted alone: the same π̂ as a ParametricModel on the same samples."""
    m = model()
    p = ParametricModel(regressor, 3, 2, lam=1e-2)
    X, Y = data(300, 2)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
        p.learn_one(x, y)
    np.testing.assert_allclose(m.parameters, p.parameters, rtol=1e-12)


def test_far_from_the_data_the_model_is_its_rigid_body_part_and_helps_inside():
    m = model()
    X, Y = data(600, 3, spread=0.5)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    far = m.predict_one(np.full(6, 8.0))
    assert np.all(np.abs(far.residual) < 1e-3 * np.abs(far.parametric).max())
    # its weight there is a fraction of the weight inside the data (where v is small)
    npm = m.nonparametric
    v_far = npm.rls.predict(npm.features_of(np.full(6, 8.0)), return_variance=True, checked=True)[1][0]
    v_in = npm.rls.predict(npm.features_of(np.zeros(6)), return_variance=True, checked=True)[1][0]
    w_far, w_in = m.residual_weight(v_far), m.residual_weight(v_in)
    assert np.all(w_far <= 0.5 * w_in) and w_in.max() > 0.5
    # inside the training region the residual removes most of what the rigid-body part misses
    Xt, _ = data(200, 4, spread=0.5)
    truth_t = np.array([truth(x) for x in Xt])
    err_sp = np.array([m.predict_one(x).total for x in Xt]) - truth_t
    err_p = np.array([m.predict_one(x).parametric for x in Xt]) - truth_t
    assert np.sqrt(np.mean(err_sp ** 2)) < 0.5 * np.sqrt(np.mean(err_p ** 2))


def test_predict_ahead_then_learn_ahead_is_predict_learn_one():
    a, b = model(tracker=True), model(tracker=True)
    X, Y = data(200, 5)
    for x, y in zip(X, Y, strict=True):
        ctx = a.predict_ahead(x)
        a.learn_ahead(ctx, y)
        pb = b.predict_learn_one(x, y)
        np.testing.assert_array_equal(ctx.prediction.total, pb.total)
        np.testing.assert_array_equal(ctx.prediction.correction, pb.correction)
    np.testing.assert_array_equal(a.predict_one(X[0]).total, b.predict_one(X[0]).total)


def test_a_refused_sample_leaves_the_model_unchanged():
    m = model(tracker=True)
    X, Y = data(50, 6)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    before = m.state_dict()
    with pytest.raises(RejectedSampleError):
        m.learn_one(X[0], [np.nan, 1.0])
    with pytest.raises(RejectedSampleError):
        m.learn_one(np.full(6, np.inf), Y[0])
    after = m.state_dict()
    assert before.keys() == after.keys()
    for k in before:
        np.testing.assert_array_equal(before[k], after[k])


def test_state_dict_round_trip_and_corrupt_tracker_state(tmp_path):
    m = model(tracker=True)
    X, Y = data(120, 7)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    path = tmp_path / "m.npz"
    m.save(path)
    fresh = model(tracker=True).load(path)
    for x in X[:10]:
        np.testing.assert_array_equal(fresh.predict_one(x).total, m.predict_one(x).total)
    state = m.state_dict()
    state["tracker.last_error"] = np.array([np.nan, 0.0])
    other = model(tracker=True)
    with pytest.raises(CheckpointError):
        other.load_state_dict(state)
    assert other.n_samples_seen == 0


def test_the_warm_up_samples_are_learned_once_the_standardizer_is_ready():
    """With an online warm-up of 30 samples the residual predicts zero for 30 samples, then learns all of
    them: after 200 samples its residual of the final π̂ (before its weight) is the closed-form ridge fit,
    on the features of the warm-up's statistics, of y − Φπ̂ over all 200 samples, as without a warm-up.
    λ = 0.1 systems of condition ≲ 1e3: 1e-9 relative is far above rounding."""
    m = model(standardizer=None, standardizer_warmup=30)
    X, Y = data(200, 11)
    for i, (x, y) in enumerate(zip(X, Y, strict=True)):
        pred = m.predict_learn_one(x, y)
        if i < 30:
            assert np.array_equal(pred.residual, np.zeros(2))
        assert m.nonparametric.held_rows == (i + 1 if i < 29 else 0)
    npm = m.nonparametric
    assert npm.rls.n_samples_seen == 200
    np.testing.assert_allclose(npm.standardizer.mean_, X[:30].mean(0), rtol=1e-12)
    Z = npm.rff.transform(npm.standardizer.transform(X))
    pi = m.parametric.parameters
    targets = Y - np.array([regressor(x) @ pi for x in X])
    W = np.linalg.solve(Z.T @ Z + 0.1 * np.eye(Z.shape[1]), Z.T @ targets)
    for x in data(20, 12)[0]:
        m.predict_model(x, rigid=pi)
        z = npm.rff.transform(npm.standardizer.transform(x))
        np.testing.assert_allclose(m._raw, z @ W, rtol=1e-9, atol=1e-12)


def test_a_checkpoint_written_in_the_warm_up_keeps_its_held_samples(tmp_path):
    """A model saved after 12 of its 30 warm-up samples and loaded into a fresh one learns as the model
    that never stopped (same predictions to rounding); held rows of the wrong size or not finite are
    refused with the model unchanged."""
    X, Y = data(150, 13)
    whole, first = model(standardizer=None, standardizer_warmup=30), model(standardizer=None,
                                                                              standardizer_warmup=30)
    for x, y in zip(X[:12], Y[:12], strict=True):
        first.learn_one(x, y)
    first.save(tmp_path / "m.npz")
    resumed = model(standardizer=None, standardizer_warmup=30).load(tmp_path / "m.npz")
    assert resumed.nonparametric.held_rows == 12
    for x, y in zip(X, Y, strict=True):
        whole.learn_one(x, y)
    for x, y in zip(X[12:], Y[12:], strict=True):
        resumed.learn_one(x, y)
    for x in X[:10]:
        np.testing.assert_allclose(resumed.predict_one(x).total, whole.predict_one(x).total, rtol=1e-10)
    state = first.state_dict()
    for key, bad in (("nonparametric.held_x", np.zeros((12, 5))),
                     ("nonparametric.held_y", np.full((12, 2), np.nan)),
                     ("nonparametric.held_x", np.zeros((31, 6)))):
        broken = dict(state, **{key: bad})
        if bad.shape[0] == 31:
            broken["nonparametric.held_y"] = np.zeros((31, 2))
        other = model(standardizer=None, standardizer_warmup=30)
        with pytest.raises(CheckpointError, match="held warm-up rows"):
            other.load_state_dict(broken)
        assert other.n_samples_seen == 0 and other.nonparametric.held_rows == 0


def test_tracker_carries_a_drifting_error_over_and_adds_nothing_to_white_noise():
    """A random walk without noise is best predicted by its last value (K = 1); white noise by nothing
    (K = 0): the tracker chooses so per output from its recent one-step errors. The noise variance of the
    error is −E[d_m d_{m−1}] of its increments: for white noise of variance r that is r (±4·2r/√n)."""
    rng = np.random.default_rng(0)
    tr = ErrorTracker(2, 1, position_scale=1.0, velocity_scale=1.0, stats_samples=2000)
    x = np.zeros(3)
    walk = 0.0
    for _ in range(4000):
        walk += 0.1 * rng.normal()
        tr.update(x, np.array([walk, 0.2 * rng.normal()]), np.zeros(2))
    assert ErrorTracker.GAINS[tr.chosen].tolist() == [1.0, 0.0]
    assert tr.correction(x)[0] == pytest.approx(walk) and tr.correction(x)[1] == 0.0
    r = 0.2 ** 2
    assert tr.noise_variance()[1] == pytest.approx(r, abs=4 * 2 * r / math.sqrt(2000))


def test_tracker_uses_an_estimate_only_where_it_stands_out_from_its_noise():
    """At the noise floor the chosen smoother sometimes carries noise over (a lucky streak makes K > 0 win
    the running comparison): applied raw, that is worse than no correction. Shrunk by its own noise
    (``b̂·max(0, 1 − 4 r̂K/(2 − K)/b̂²)``) it costs less than half as much, and a drifting error, which
    stands far out of its noise, is carried over as before."""
    rng = np.random.default_rng(2)
    tr = ErrorTracker(2, 1, position_scale=1.0, velocity_scale=1.0, stats_samples=50)
    x = np.zeros(3)
    walk = 0.0
    raw, used, none = [], [], []
    for m in range(20000):
        walk += 0.05 * rng.normal()
        e = np.array([walk + 0.02 * rng.normal(), 0.2 * rng.normal()])
        if m > 100:
            raw.append((e - tr.estimate) ** 2)
            used.append((e - tr.used_estimate) ** 2)
            none.append(e ** 2)
            k = ErrorTracker.GAINS[tr.chosen]
            b = tr.estimate
            noise = 4.0 * tr.noise_variance() * k / (2.0 - k)
            expected = np.where(b * b > noise, b * (1.0 - noise / np.where(b != 0.0, b * b, 1.0)), 0.0)
            np.testing.assert_allclose(tr.used_estimate, expected, rtol=1e-12, atol=0.0)
        tr.update(x, e, np.zeros(2))
    rms = {name: np.sqrt(np.mean(v, axis=0)) for name, v in (("raw", raw), ("used", used), ("none", none))}
    assert rms["raw"][1] > rms["none"][1]                                  # the harm at the noise floor
    assert rms["used"][1] - rms["none"][1] < 0.5 * (rms["raw"][1] - rms["none"][1])
    assert rms["used"][0] < 1.01 * rms["raw"][0] < 0.05 * rms["none"][0]   # the drift is still followed


def test_tracker_fades_with_the_state_distance():
    tr = ErrorTracker(1, 2, position_scale=0.1, velocity_scale=1.0)
    tr.update(np.zeros(6), np.array([1.0]), np.zeros(1))
    assert tr.weight(np.zeros(6)) == 1.0
    assert tr.weight(np.array([0.1, 0, 0, 0, 0, 0])) == pytest.approx(math.exp(-0.5))
    assert tr.weight(np.array([0, 0, 0, 2.0, 0, 0])) == pytest.approx(math.exp(-2.0))
    assert tr.weight(np.array([0, 0, 0, 0, 50.0, 50.0])) == 1.0  # accelerations do not count


def sparse_regressor(x: np.ndarray) -> np.ndarray:
    """The regressor above with a structurally zero entry per row (a joint-torque regressor's shape)."""
    q1, dq1 = x[0], x[2]
    return np.array([[math.sin(q1), dq1, 0.0], [0.0, q1 * dq1, 0.5]])


def test_residual_keeps_only_the_regressor_entries_that_are_not_zero(monkeypatch):
    """Learning the identically zero entries of Φ as targets changes nothing but the cost: the model that
    drops them predicts bit for bit what the full regression predicts, on every sample and after."""
    import semiparam_ros.core.learners.consistent as mod

    args = dict(lam_parametric=1e-2, lam_nonparametric=1e-1, n_features=60, sigma=1.5, seed=3,
                standardizer=STD, novelty_scale=0.05, tracker=True)
    reduced = ConsistentSemiparametricModel(sparse_regressor, 3, 6, 2, **args)
    np.testing.assert_array_equal(reduced._phi_entries, [0, 1, 4, 5])
    assert reduced.nonparametric.n_outputs == 2 and reduced._cross.shape == (60, 4)
    monkeypatch.setattr(mod, "structural_entries", lambda reg, n_in, t, p, samples=8: np.arange(t * p))
    full = ConsistentSemiparametricModel(sparse_regressor, 3, 6, 2, **args)
    assert full._cross.shape == (60, 6)
    X, Y = data(300, 5)
    for x, y in zip(X, Y, strict=True):
        a, b = reduced.predict_learn_one(x, y), full.predict_learn_one(x, y)
        np.testing.assert_array_equal(a.total, b.total)
    Xt, _ = data(20, 6)
    np.testing.assert_array_equal(reduced.predict_model_many(Xt).total, full.predict_model_many(Xt).total)
    with pytest.raises(CheckpointError, match="regressor entries"):
        reduced.load_state_dict(full.state_dict())


def test_what_a_served_prediction_keeps_is_recomputed_after_learning():
    """``predict_model`` with other rigid parameters keeps Ω = A⁻¹B_E S and the served scales (s², σ², c)
    between calls; after more samples are learned (or a reset) its answers are those of a copy that never
    kept anything."""
    import copy

    m = model()
    X, Y = data(300, 11)
    for x, y in zip(X[:200], Y[:200], strict=True):
        m.learn_one(x, y)
    m.use_rigid(m.parametric.parameters)  # a fixed reference: only learning changes what is kept
    other = m.parametric.parameters + np.array([0.3, -0.2, 0.1])
    Xt, _ = data(5, 12)

    def uncached(model_):
        fresh = copy.deepcopy(model_)
        fresh._shift_cache = fresh._served_cache = None
        return fresh

    before = [m.predict_model(x, other) for x in Xt]
    for x, y in zip(X[200:], Y[200:], strict=True):  # Ω and the scales change with what is learned
        m.learn_one(x, y)
    after = [m.predict_model(x, other) for x in Xt]
    reference = uncached(m)
    for x, old, new in zip(Xt, before, after, strict=True):
        want = reference.predict_model(x, other)
        np.testing.assert_allclose(new.total, want.total, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(new.variance, want.variance, rtol=1e-12, atol=1e-15)
        assert not np.allclose(old.total, new.total, rtol=1e-9, atol=0.0)
    m.reset()
    for x in Xt:
        np.testing.assert_allclose(m.predict_model(x, other).total, uncached(m).predict_model(x, other).total,
                                   rtol=1e-12, atol=1e-12)


def test_predicting_with_other_rigid_parameters_moves_the_residual_with_them():
    """``rigid`` = the learned parameters gives the learned prediction; other parameters move the
    rigid-body part by Φ(π' − π̂) and the weighted residual by −g·E[Φ](π' − π̂)."""
    m = model()
    X, Y = data(300, 7)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    own = m.parametric.parameters
    other = own + np.array([0.3, -0.2, 0.1])
    Xt, _ = data(10, 8)
    m.use_rigid(None)  # the reference: the learned parameters as they are now
    for x in Xt:
        base = m.predict_model(x)
        same = m.predict_model(x, own)
        np.testing.assert_allclose(same.total, base.total, rtol=1e-12, atol=1e-12)
        moved = m.predict_model(x, other)
        np.testing.assert_allclose(moved.parametric, regressor(x) @ other, rtol=1e-12)
        # the residual's E[Φ] is what it learned of Φ: its change is −g·E[Φ]·(π' − π̂)
        assert not np.allclose(moved.residual, base.residual)
    batch = m.predict_model_many(Xt, other)
    for i, x in enumerate(Xt):
        np.testing.assert_allclose(batch.total[i], m.predict_model(x, other).total, rtol=1e-9, atol=1e-12)
    with pytest.raises(RejectedSampleError):
        m.predict_model(Xt[0], np.array([np.nan, 0.0, 0.0]))


def test_a_rigid_body_set_by_use_rigid_is_the_one_every_prediction_uses():
    """After ``use_rigid(π')`` the model's own predictions (one state, many, held, learn-time a priori)
    equal those with ``rigid=π'`` given explicitly: ŷ_P = Φ(x)π' (independent: the regressor times π'),
    the residual consistent with π'. ``None`` returns to the learned parameters; bad values are refused
    with the model unchanged; reset and a loaded state forget it (it is solved again from the state)."""
    m = model(tracker=True)
    X, Y = data(300, 11)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    m.use_rigid(None)  # the reference: the learned parameters as they are now
    other = m.parametric.parameters + np.array([0.3, -0.2, 0.1])
    Xt, _ = data(6, 12)
    explicit = [m.predict_model(x, other) for x in Xt]
    learned = [m.predict_model(x) for x in Xt]
    m.use_rigid(other)
    np.testing.assert_array_equal(m.rigid_override, other)
    for x, e in zip(Xt, explicit, strict=True):
        own = m.predict_model(x)
        np.testing.assert_allclose(own.parametric, regressor(x) @ other, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(own.total, e.total, rtol=1e-12, atol=1e-12)
        one = m.predict_one(x)  # the online prediction: model(x) plus the fast correction
        np.testing.assert_allclose(one.parametric, regressor(x) @ other, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(one.total - one.correction, e.total, rtol=1e-12, atol=1e-12)
        held = m.predict_held(x)  # the residual held from the last full prediction, with π'
        np.testing.assert_allclose(held.total - held.correction, e.total, rtol=1e-12, atol=1e-12)
    many = m.predict_model_many(Xt)
    np.testing.assert_allclose(many.total, np.array([e.total for e in explicit]), rtol=1e-9, atol=1e-12)
    ctx = m.predict_ahead(Xt[0])
    np.testing.assert_allclose(ctx.prediction.parametric, regressor(Xt[0]) @ other, rtol=1e-12)
    with pytest.raises(RejectedSampleError):
        m.use_rigid(np.array([1.0, np.inf, 0.0]))
    with pytest.raises(RejectedSampleError):
        m.use_rigid(np.ones(4))
    np.testing.assert_array_equal(m.rigid_override, other)  # unchanged by the refusals
    state = m.state_dict()
    assert not any("rigid" in key for key in state)
    m.use_rigid(None)
    for x, ref in zip(Xt, learned, strict=True):
        np.testing.assert_allclose(m.predict_model(x).total, ref.total, rtol=1e-12, atol=1e-12)
    m.use_rigid(other)
    m.load_state_dict(state)  # saved while `other` was set: loaded, it predicts with the learned parameters
    assert m.rigid_override is None
    for x, ref in zip(Xt, learned, strict=True):
        np.testing.assert_allclose(m.predict_model(x).total, ref.total, rtol=1e-9, atol=1e-12)
    m.use_rigid(other)
    m.reset()
    assert m.rigid_override is None


def test_correlation_samples_measure_how_long_the_residuals_errors_stay_correlated():
    """Errors white or AR(1) with ρ = 0.9 (integrated correlation time (1 + ρ)/(1 − ρ) = 19 samples), at
    random states so that the residual cannot learn them: c ≈ 1 for white errors and ≈ 19 for AR(1)
    (batch means over a 1 s window = 1000 samples at 1 kHz, ≫ 19)."""
    rng = np.random.default_rng(11)
    n, rho = 20000, 0.9
    white = 0.1 * rng.normal(size=n)
    ar = np.empty(n)
    ar[0] = white[0]
    for i in range(1, n):  # the same marginal variance: innovations of variance (1 − ρ²)·0.01
        ar[i] = rho * ar[i - 1] + math.sqrt(1.0 - rho ** 2) * white[i]
    X = rng.uniform(-1.0, 1.0, size=(n, 3))
    got = {}
    for name, noise in (("white", white), ("ar", ar)):
        m = ConsistentSemiparametricModel(lambda x: np.array([[1.0]]), 1, 3, 1, lam_parametric=1e-3,
                                          lam_nonparametric=1.0, n_features=20, sigma=1.0, tracker=False,
                                          standardizer=Standardizer(3, mean=np.zeros(3), scale=np.ones(3)))
        m.on_period(1e-3)
        for x, e in zip(X, noise, strict=True):
            m.learn_one(x, [0.5 + e])
        got[name] = float(m.correlation_samples()[0])
    tau = (1 + rho) / (1 - rho)
    assert 1.0 <= got["white"] < 2.0
    assert 0.6 * tau < got["ar"] < 1.5 * tau


def test_the_model_alone_is_as_uncertain_as_its_residual_is_unsure_and_correlated():
    """``predict_model``'s relative variance is the rigid-body part's plus ``model_variance(v)``: the error
    variance of ŷ_P + g r as an estimate of the systematic error, in units of σ² — computed here from the
    model's statistics by the formula, and checked to be far larger away from the data (where the model
    abstains and misses the systematic error) than inside them. The online prediction keeps v."""
    m = model(novelty_scale=1.0)
    X, Y = data(600, 3)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    s2, noise = m.error_scales()
    c = m.correlation_samples()
    assert np.all(noise > 0) and s2[0] > 0.0 and np.all(c >= 1.0)
    npm, lam = m.nonparametric, m.nonparametric.rls.lam
    for x in (np.zeros(6), np.full(6, 1.2), np.full(6, 8.0)):
        v = npm.rls.predict(npm.features_of(x), return_variance=True, checked=True)[1][0]
        var_p = m.parametric.predict_phi(regressor(x), True)[1]
        g, nu = m.residual_weight(v, served=True), min(lam * v, 1.0)
        # the weight of the model used alone: the Wiener weight with the residual's correlated error c σ² v
        signal = s2 * (1 - nu)
        total = signal + c * noise * v
        np.testing.assert_allclose(g, np.where(total > 0, signal / total, 1.0), rtol=1e-12)
        want = ((1 - g) ** 2 * s2 * (1 - nu) + g ** 2 * c * noise * v + s2 * nu) / noise
        # ... which minimises the variance it reports (ν₀ = 1): any other weight (the online one too) is worse
        for other in (m.residual_weight(v), np.clip(g + 0.05, 0, 1), np.clip(g - 0.05, 0, 1)):
            worse = ((1 - other) ** 2 * s2 * (1 - nu) + other ** 2 * c * noise * v + s2 * nu) / noise
            assert np.all(worse >= want - 1e-12 * np.abs(want))
        raw = npm.rls.predict(npm.features_of(x), return_variance=True, checked=True)[0][0]
        np.testing.assert_allclose(m.predict_model(x).residual, g * raw, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(m.predict_model(x).variance, var_p + want, rtol=1e-12)
        np.testing.assert_allclose(m.predict_model_many(x[None]).variance[0], var_p + want, rtol=1e-12)
        np.testing.assert_allclose(m.predict_one(x, return_variance=True).variance, var_p + v, rtol=1e-12)
    def rel_var(x):
        return npm.rls.predict(npm.features_of(x), return_variance=True, checked=True)[1][0]

    far, inside = m.model_variance(rel_var(np.full(6, 8.0))), m.model_variance(rel_var(np.zeros(6)))
    assert inside[0] < 0.2 * far[0]  # the data explain the error inside; far away the model abstains


def through_migration(old_state, **kwargs):
    """A learner state of checkpoint format 1 read through the checkpoint's one migration path."""
    from semiparam_ros.core.estimator.migration import migrate

    v1 = {f"model.{k}": v for k, v in old_state.items()}
    v1.update({"meta.version": np.array(1), "meta.robot": np.array("{}"), "noise.s2": np.zeros(2),
               "gate.warm": np.array(True)})
    fresh = {f"model.{k}": v for k, v in model(**kwargs).state_dict().items()}
    new, notes = migrate(v1, 1, 2, lambda: fresh)
    assert notes and int(new["meta.version"]) == 2
    return {k[len("model."):]: v for k, v in new.items() if k.startswith("model.")}


def test_a_checkpoint_without_correlation_statistics_loads_with_none():
    m = model()
    X, Y = data(200, 5)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    assert np.any(m.correlation_samples() > 1.0)
    state = m.state_dict()
    state["scales"] = state["scales"][:3 + 4 * 2]  # the layout before the correlation statistics
    old = model()
    old.load_state_dict(through_migration(state))
    np.testing.assert_array_equal(old.correlation_samples(), [1.0, 1.0])
    np.testing.assert_array_equal(old.predict_one(X[0]).total, m.predict_one(X[0]).total)
    state["scales"] = np.concatenate([state["scales"], [0.0, 0.0, -1.0, 0.0]])  # a negative Σβm²
    with pytest.raises(CheckpointError):
        model().load_state_dict(state)


def test_a_checkpoint_that_regressed_every_regressor_entry_is_converted_exactly():
    """Before the reference, the residual learner regressed ``[y − Φπ₀, Φ_E]`` (``d = R⁻ᵀ[B_y | B_E]``).
    Such a state (checkpoint format 1), built here from a trained model's factor and cross-products, is
    migrated into today's layout and predicts what the trained model predicts with the learned parameters
    as its reference."""
    from scipy.linalg import solve_triangular


    m = model(tracker=True)
    X, Y = data(300, 13)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    state = m.state_dict()
    R = m.nonparametric.rls.R
    C = m.nonparametric.rls.d
    B_E = m._cross.with_pending()
    change = m._reference - m.parametric.prior
    scatter = np.zeros((B_E.shape[1], 2))
    scatter[np.arange(B_E.shape[1]), m._entry_rows] = change[m._entry_cols]
    d_y = C + solve_triangular(R, B_E @ scatter, trans="T")  # the residual of y − Φπ₀
    d_E = solve_triangular(R, B_E, trans="T")
    old = {k: v for k, v in state.items() if k not in ("entries_rhs", "reference")}
    old["nonparametric.rls.M"] = np.concatenate([R, d_y, d_E], axis=1)
    old["nonparametric.rls.n_outputs"] = np.array(2 + B_E.shape[1])
    loaded = model(tracker=True)
    loaded.load_state_dict(through_migration(old, tracker=True))
    m.use_rigid(None)  # the trained model with the learned parameters as its reference
    Xt, _ = data(10, 14)
    np.testing.assert_allclose(loaded.predict_model_many(Xt).total, m.predict_model_many(Xt).total,
                               rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(loaded._cross.settled(), B_E, rtol=1e-9, atol=1e-12)
    old["nonparametric.rls.M"] = old["nonparametric.rls.M"][:, :-1]  # a damaged one is refused
    with pytest.raises(CheckpointError):
        model(tracker=True).load_state_dict(through_migration(old, tracker=True))


def test_an_old_correction_fades_over_the_time_the_errors_stay_correlated():
    """The fast correction of a model queried a seconds after its last update is weighted exp(−a/τ) per
    output, τ = min(τ_f, ½(1 + c)T): white errors (c ≈ 1, here a random state sequence) leave nothing of it
    0.1 s later, while an offset the model keeps missing (errors correlated over many samples) keeps it
    over about the correction's memory τ_f."""
    period = 0.01
    X, Y = data(600, 21)
    white = model(tracker=True, sample_period_s=period)
    offset = model(tracker=True, sample_period_s=period)
    for k, (x, y) in enumerate(zip(X, Y, strict=True)):
        white.learn_one(x, y)
        offset.learn_one(x, y + (np.array([0.5, -0.3]) if k >= 400 else 0.0))
    c_white, c_offset = white.correlation_samples(), offset.correlation_samples()
    assert np.all(c_white < 3.0) and np.all(c_offset > 30.0)
    tau_f = white.tracker_time_constant
    for m, c in ((white, c_white), (offset, c_offset)):
        m.prediction_age_s = 0.1
        want = np.exp(-0.1 / np.minimum(tau_f, 0.5 * (1.0 + c) * period))
        np.testing.assert_allclose(m.age_fades(), want, rtol=1e-12)
    assert np.all(white.age_fades() < 1e-3)  # white errors: nothing of an old correction is left
    assert np.all(offset.age_fades() > 0.5)  # persistent errors: most of it is kept (τ_f: 0.72)
    x = X[-1] + 0.01
    fresh, old = copy.deepcopy(offset), offset
    fresh.prediction_age_s = 0.0
    assert np.abs(old.predict_one(x).correction).max() < np.abs(fresh.predict_one(x).correction).max()


def _served_formula(m: ConsistentSemiparametricModel, x: np.ndarray, rigid: np.ndarray | None):
    """``predict_model``'s formulas computed here with numpy: (ŷ_P, g·r, variance) and bounds on rounding."""
    npm, lam, eps = m.nonparametric, m.nonparametric.rls.lam, np.finfo(float).eps
    Phi = regressor(x)
    theta = m.reference_parameters if rigid is None else rigid
    yp = Phi @ theta
    var_p = m.parametric.predict_phi(Phi, True)[1]
    phi = npm.features_of(x)
    P, v = npm.rls.predict(phi, return_variance=True, checked=True)
    v = float(v[0])
    change = np.zeros_like(theta) if rigid is None else rigid - m.reference_parameters
    shift = m._rigid_shift(change)  # A⁻¹ B_E S: the residual's share of the change (two solves)
    raw = P[0] - phi[0] @ shift
    s2, noise = m.error_scales()
    c = m.correlation_samples()
    nu = min(max(lam * v, 0.0), 1.0)
    signal = s2 * (1 - nu)
    total = signal + c * noise / m.novelty_scale * v
    g = np.where(total > 0, signal / np.where(total > 0, total, 1.0), 1.0)
    extra = ((1 - g) ** 2 * s2 * (1 - nu) + g ** 2 * c * noise * v + s2 * nu)
    var = var_p + np.where(noise > 0, extra / np.where(noise > 0, noise, 1.0), v)
    d = phi.shape[1]
    # orders of summation differ: n terms sum to within n·ε·Σ|terms| (twice for safety)
    bound_y = 2 * (Phi.shape[1] + 1) * eps * (np.abs(Phi) @ np.abs(theta))
    bound_r = 2 * (d + 1) * eps * (np.abs(phi[0]) @ np.abs(shift)) + 8 * eps * np.abs(g * raw)
    return yp, g * raw, var, bound_y, bound_r


@pytest.mark.parametrize("with_rigid", [False, True])
def test_the_frozen_single_state_call_is_predict_models_formula(with_rigid):
    """``frozen_model_one`` (one compiled call) gives ``predict_model``'s ŷ_P, g·r and variance, computed
    here from the model's statistics by the formulas, within the rounding of its sums; before the residual
    is ready it is the rigid-body part with its variance; it is a copy (later learning does not move it)."""
    fresh = model(standardizer=Standardizer(6, warmup=50))
    x0 = np.array([0.3, -0.2, 0.5, 0.1, 0.0, 0.2])
    yp, r, var = fresh.frozen_model_one()(x0, np.ascontiguousarray(regressor(x0)))
    assert not fresh.nonparametric.standardizer.ready
    np.testing.assert_allclose(yp, fresh.predict_model(x0).parametric, rtol=1e-14)
    assert np.all(r == 0.0)
    np.testing.assert_allclose(var, fresh.parametric.predict_phi(regressor(x0), True)[1], rtol=1e-14)
    m = model(novelty_scale=0.5)
    X, Y = data(400, 11)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    rigid = m.parametric.parameters + np.array([0.2, -0.1, 0.05]) if with_rigid else None
    one = m.frozen_model_one(rigid)
    Xt, _ = data(20, 12, spread=1.5)
    for x in Xt:
        yp, r, var = one(x, np.ascontiguousarray(regressor(x)))
        want_y, want_r, want_var, bound_y, bound_r = _served_formula(m, x, rigid)
        assert np.all(np.abs(yp - want_y) <= bound_y + 1e-300)
        assert np.all(np.abs(r - want_r) <= bound_r + 1e-300)
        np.testing.assert_allclose(var, want_var, rtol=1e-12)
        ref = m.predict_model(x, rigid)
        np.testing.assert_allclose(yp + r, ref.total, rtol=1e-12, atol=float(np.max(bound_y + bound_r)))
    before = one(Xt[0], np.ascontiguousarray(regressor(Xt[0])))
    for x, y in zip(*data(50, 13), strict=True):
        m.learn_one(x, y)
    after = one(Xt[0], np.ascontiguousarray(regressor(Xt[0])))
    for a, b in zip(before, after, strict=True):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(RejectedSampleError):
        m.frozen_model_one(np.array([np.nan, 0.0, 0.0]))


def _smooth_stream(n: int, kind: str, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A smooth two-joint motion at 100 Hz. ``state``: y = truth(x) (an effect of the state the rigid body
    cannot express); ``time``: the rigid body plus ±0.3 switching every 0.2 s whatever the state (what
    belongs to time: a residual fits it from the samples just before, and a copy 0.1–0.2 s old gets it
    wrong about half the time or more)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    X = np.zeros((n, 6))
    w1, w2 = 2 * np.pi * 0.31, 2 * np.pi * 0.23
    X[:, 0], X[:, 1] = np.sin(w1 * t), np.cos(w2 * t)
    X[:, 2], X[:, 3] = w1 * np.cos(w1 * t), -w2 * np.sin(w2 * t)
    if kind == "state":
        Y = np.array([truth(x) for x in X])
    else:
        Y = np.array([regressor(x) @ np.array([2.0, 0.5, -1.0]) for x in X])
        Y += 0.3 * np.sign(np.sin(2 * np.pi * t / 0.4))[:, None]
    return X, Y + 0.01 * rng.normal(size=Y.shape)


def _aged_saving(X: np.ndarray, Y: np.ndarray, copies: list[tuple[int, np.ndarray, np.ndarray]],
                 m: ConsistentSemiparametricModel) -> np.ndarray:
    """Mean saving e² − (e − r)² of copies (k, θ_ref, W) taken while learning, each scored on the samples
    10–19 after it was taken (its residual unweighted, e = y − Φθ_ref), with numpy."""
    gains = []
    for k0, theta, W in copies:
        for k in range(k0 + 10, min(k0 + 20, len(X))):
            e = Y[k] - regressor(X[k]) @ theta
            r = m.nonparametric.features_of(X[k])[0] @ W
            gains.append(e ** 2 - (e - r) ** 2)
    return np.mean(gains, axis=0)


def test_the_residual_is_dropped_where_an_aged_copy_of_it_does_worse_than_its_rigid_body():
    """On errors that belong to the state, a copy of the residual 0.1–0.2 s old still helps, and the residual
    is kept; on errors that belong to time (the same motion, ±0.3 switching every 0.2 s), it fits the last
    samples one step ahead but its aged copy does worse than the rigid body alone — measured here
    independently, copies of (θ_ref, W) taken every 10 samples and scored with numpy — and the online
    prediction drops it: its residual part is then the fast correction alone. The model used alone keeps
    its served weight. The test's state survives a checkpoint, copies included."""
    outcome = {}
    for kind in ("state", "time"):
        m = model(sample_period_s=0.01, tracker=True)
        X, Y = _smooth_stream(3000, kind)
        copies = []
        for k, (x, y) in enumerate(zip(X, Y, strict=True)):
            m.learn_one(x, y)
            if k % 10 == 0 and k >= 1000:
                copies.append((k, m.reference_parameters, m.nonparametric.rls.weights.copy()))
        outcome[kind] = (m, _aged_saving(X, Y, copies, m), X, Y)
    kept, saving_kept, _, _ = outcome["state"]
    dropped, saving_dropped, X, Y = outcome["time"]
    assert np.all(saving_kept > 0.0) and np.all(saving_dropped < 0.0)  # what the test is to find
    assert kept.residual_use().all()
    assert not dropped.residual_use().any()
    x = np.array([0.2, 0.4, 0.5, -0.3, 0.0, 0.0])
    for m, used in ((kept, True), (dropped, False)):
        pred = m.predict_one(x)
        assert bool(np.all(pred.residual - pred.correction != 0.0)) == used
        assert bool(np.all(m.residual_weight(0.01) > 0.0)) == used
        s2, noise = m.error_scales()  # the served weight is its formula, whatever the test found
        signal = s2 * (1.0 - m.nonparametric.rls.lam * 0.01)
        total = signal + m.correlation_samples() * noise / m.novelty_scale * 0.01
        served = np.where(total > 0.0, signal / np.where(total > 0.0, total, 1.0), 1.0)
        np.testing.assert_allclose(m.residual_weight(0.01, served=True), served, rtol=1e-12)
    again = model(sample_period_s=0.01, tracker=True)
    again.load_state_dict(dropped.state_dict())
    assert np.array_equal(again.residual_use(), dropped.residual_use())
    for x, y in zip(X[:300], Y[:300], strict=True):  # the copies too: the test goes on as it would have
        again.learn_one(x, y)
        dropped.learn_one(x, y)
    np.testing.assert_array_equal(again.state_dict()["aged"], dropped.state_dict()["aged"])


@pytest.mark.parametrize("bad", ["short", "nan", "negative_count", "half"])
def test_a_corrupt_aged_test_in_a_checkpoint_is_refused_and_the_model_is_unchanged(bad):
    m = model()
    X, Y = data(100, 5)
    for x, y in zip(X, Y, strict=True):
        m.learn_one(x, y)
    state = m.state_dict()
    aged = np.array(state["aged"], dtype=np.float64)
    broken = {"short": aged[:-1], "nan": np.where(np.arange(aged.size) == 1, np.nan, aged),
              "negative_count": np.concatenate([[-1.0], aged[1:]]),
              "half": np.concatenate([aged[:-1], [0.5]])}[bad]
    other = model()
    with pytest.raises(CheckpointError, match="at an age"):
        other.load_state_dict(dict(state, aged=broken))
    assert other.n_samples_seen == 0
    missing = {k: v for k, v in state.items() if k != "aged"}
    with pytest.raises(CheckpointError, match="at an age"):
        other.load_state_dict(missing)
