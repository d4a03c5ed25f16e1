"""Random Fourier features and the standardizer against their definitions."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.kernel_approximation import RBFSampler

from semiparam_ros.core.learners.features import RandomFourierFeatures, Standardizer


def test_rff_matches_sklearn_rbfsampler_formulation():
    rng = np.random.default_rng(0)
    sigma, D, n_in = 0.8, 64, 5
    X = rng.standard_normal((10, n_in))
    rff = RandomFourierFeatures(n_in, D, sigma, seed=3)
    sk = RBFSampler(gamma=1.0 / (2 * sigma**2), n_components=D, random_state=0).fit(X)
    sk.random_weights_ = rff.omega_.copy()
    sk.random_offset_ = rff.offset_.copy()
    np.testing.assert_allclose(rff.transform(X), sk.transform(X), rtol=1e-12, atol=1e-14)


def test_rff_distribution_and_shapes():
    sigma = 2.5
    rff = RandomFourierFeatures(4, 20000, sigma, seed=1)
    assert np.isclose(rff.omega_.std(), 1 / sigma, rtol=0.02)
    assert abs(rff.omega_.mean()) < 0.01
    assert rff.offset_.min() >= 0 and rff.offset_.max() < 2 * np.pi
    assert np.isclose(rff.offset_.mean(), np.pi, rtol=0.02)
    small = RandomFourierFeatures(3, 7, 1.0, seed=2)
    X = np.arange(12.0).reshape(4, 3) / 10
    F = small.transform(X)
    assert F.shape == (4, 7)
    assert small.transform(X[1]).shape == (7,)
    np.testing.assert_array_equal(small.transform(X[1]), F[1])
    np.testing.assert_array_equal(RandomFourierFeatures(3, 7, 1.0, seed=2).transform(X), F)
    assert not np.allclose(RandomFourierFeatures(3, 7, 1.0, seed=5).transform(X), F)


def test_rff_kernel_error_shrinks_like_inverse_sqrt_d():
    rng = np.random.default_rng(4)
    n_in, sigma = 6, 1.5
    X = rng.standard_normal((40, n_in))
    Ds = np.array([25, 50, 100, 200, 400, 800, 1600, 3200])
    errs = []
    for D in Ds:
        e = []
        for seed in range(6):
            rff = RandomFourierFeatures(n_in, int(D), sigma, seed=seed)
            F = rff.transform(X)
            e.append(np.sqrt(np.mean((F @ F.T - rff.kernel(X, X)) ** 2)))
        errs.append(np.mean(e))
    slope = np.polyfit(np.log(Ds), np.log(errs), 1)[0]
    assert -0.65 < slope < -0.35, slope
    assert errs[-1] < 0.05


def test_rff_kernel_is_the_gaussian_kernel():
    rff = RandomFourierFeatures(2, 10, 0.5)
    x, y = np.array([0.0, 0.0]), np.array([0.3, 0.4])  # distance 0.5 = σ
    assert np.isclose(rff.kernel(x, y)[0, 0], np.exp(-0.5))


@pytest.mark.parametrize("bad", [np.ones(4), np.ones((2, 4)), np.array([0.0, np.nan, 0.0]),
                                 np.array([[np.inf, 0, 0]]), np.ones((1, 1, 3))])
def test_rff_rejects_bad_input(bad):
    with pytest.raises(ValueError):
        RandomFourierFeatures(3, 5, 1.0).transform(bad)


@pytest.mark.parametrize("kwargs", [dict(sigma=0.0), dict(sigma=-1.0), dict(sigma=np.nan), dict(n_features=0),
                                    dict(n_inputs=0)])
def test_rff_rejects_bad_hyperparameters(kwargs):
    args = dict(n_inputs=3, n_features=5, sigma=1.0) | kwargs
    with pytest.raises(ValueError):
        RandomFourierFeatures(**args)


def test_rff_state_round_trip():
    rff = RandomFourierFeatures(3, 11, 0.7, seed=9)
    back = RandomFourierFeatures.from_state_dict(rff.state_dict("f."), "f.")
    X = np.random.default_rng(0).standard_normal((5, 3))
    np.testing.assert_array_equal(back.transform(X), rff.transform(X))
    with pytest.raises(ValueError, match="missing"):
        RandomFourierFeatures.from_state_dict({}, "f.")


def test_standardizer_fit_and_constant_inputs():
    rng = np.random.default_rng(1)
    X = rng.standard_normal((500, 4)) * [1.0, 10.0, 0.01, 0.0] + [5.0, -3.0, 0.0, 7.0]
    s = Standardizer(4).fit(X)
    assert s.ready
    np.testing.assert_allclose(s.mean_, X.mean(0))
    np.testing.assert_allclose(s.scale_[:3], X.std(0)[:3])
    assert s.scale_[3] == 1.0  # zero variance → scale 1
    Y = s.transform(X)
    np.testing.assert_allclose(Y[:, :3].mean(0), 0, atol=1e-12)
    np.testing.assert_allclose(Y[:, :3].std(0), 1, rtol=1e-12)
    np.testing.assert_allclose(Y[:, 3], 0, atol=1e-12)
    np.testing.assert_allclose(s.transform(X[7]), Y[7])


def test_standardizer_online_warmup_is_welford_then_frozen():
    rng = np.random.default_rng(2)
    X = rng.standard_normal((300, 3)) * [2.0, 0.5, 1.0] + [1e4, 0.0, -2.0]  # large offset: Welford is stable
    s = Standardizer(3, warmup=100)
    with pytest.raises(ValueError, match="not ready"):
        s.transform(X[0])
    for i in range(99):
        assert s.partial_fit(X[i]) is False
    assert not s.ready
    assert s.partial_fit(X[99:150]) is True  # completes the warm-up, the rest is ignored
    s.partial_fit(X[150:])
    assert s.ready and s.count_ == 100
    np.testing.assert_allclose(s.mean_, X[:100].mean(0), rtol=1e-13)
    np.testing.assert_allclose(s.scale_, X[:100].std(0), rtol=1e-10)


def test_standardizer_bad_input_and_state():
    s = Standardizer(2, warmup=10)
    s.partial_fit(np.array([[1.0, 2.0], [3.0, 5.0]]))
    before = s.state_dict()
    for bad in (np.array([np.nan, 1.0]), np.ones(3), np.array([[1.0, 2.0], [np.inf, 0.0]])):
        with pytest.raises(ValueError):
            s.partial_fit(bad)
    after = s.state_dict()
    assert all(np.array_equal(before[k], after[k]) for k in before)
    back = Standardizer.from_state_dict(s.state_dict("s."), "s.")
    for x in ([0.0, 1.0], [2.0, 2.0], [1.0, -1.0], [4.0, 0.5], [0.0, 0.0], [1.0, 1.0], [2.0, 3.0],
              [9.0, 9.0]):
        back.partial_fit(x)
        s.partial_fit(x)
    assert back.ready and s.ready
    np.testing.assert_array_equal(back.transform([1.0, 1.0]), s.transform([1.0, 1.0]))
    with pytest.raises(ValueError):
        Standardizer(2, mean=[0.0, 0.0], scale=[1.0, 0.0])
    with pytest.raises(ValueError):
        Standardizer(2, mean=[0.0, 0.0])
    with pytest.raises(ValueError):
        Standardizer(2).fit(np.zeros((0, 2)))
    ident = Standardizer.identity(2)
    np.testing.assert_array_equal(ident.transform([3.0, -4.0]), [3.0, -4.0])


def test_standardizer_scale_floor_for_a_warmup_at_rest():
    rng = np.random.default_rng(3)
    floor = np.array([0.05, 0.1, 1.0])
    at_rest = np.array([0.3, 0.0, 0.0]) + rng.normal(0.0, 1e-4, (200, 3))  # encoder noise only
    s = Standardizer(3, warmup=200, min_scale=floor)
    assert s.partial_fit(at_rest)
    np.testing.assert_array_equal(s.scale_, floor)  # noise std (1e-4) floored to the operating range
    moving = np.array([1.3, 2.0, 10.0])
    assert np.all(np.abs(s.transform(moving)) <= 20.0)
    # without the floor the same warm-up blows motion up to ~1e4 standardized units
    bare = Standardizer(3, warmup=200)
    bare.partial_fit(at_rest)
    assert np.abs(bare.transform(moving)).max() > 1e3
    # the floor never lowers a measured scale, and survives copies and state round trips
    wide = Standardizer(3, min_scale=floor).fit(rng.normal(0.0, 5.0, (500, 3)))
    assert np.all(wide.scale_ > 4.0)
    restored = Standardizer.from_state_dict(s.state_dict("x."), "x.")
    np.testing.assert_array_equal(restored.min_scale_, floor)
    np.testing.assert_array_equal(s.copy().scale_, s.scale_)
    with pytest.raises(ValueError, match="min_scale"):
        Standardizer(3, warmup=10, min_scale=[-1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="min_scale"):
        Standardizer(3, warmup=10, min_scale=np.nan)
