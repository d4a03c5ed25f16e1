"""The relative predictive variance v = z A⁻¹ zᵀ against the closed form, and its warm-up convention."""

from __future__ import annotations

import numpy as np
import pytest

from semiparam_ros.core.learners.cascade import SemiparametricModel
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.core.learners.uncertainty import predict_with_variance
from semiparam_ros.errors import RejectedSampleError


def _regressor(x: np.ndarray) -> np.ndarray:
    # a smooth (3 × 5) regressor of a 4-dimensional input
    return np.array([[1.0, x[0], x[1] * x[2], np.sin(x[3]), x[0] ** 2],
                     [x[1], 1.0, np.cos(x[0]), x[2], x[3] * x[0]],
                     [x[2] * x[3], x[0] - x[1], 1.0, x[1] ** 2, np.sin(x[2])]])


PRIOR = np.array([0.5, -1.0, 2.0, 0.0, 3.0])  # a CAD prior π₀ (parametric.prior: urdf)


def _models():
    return {
        "P": ParametricModel(_regressor, 5, 3, lam=0.1, forgetting=0.99),
        "P prior": ParametricModel(_regressor, 5, 3, lam=0.1, forgetting=0.99, prior=PRIOR),
        "NP": NonparametricModel(4, 3, n_features=40, sigma=2.0, lam=0.01, forgetting=0.995,
                                 standardizer_warmup=20),
        "SP": SemiparametricModel(_regressor, 5, 4, 3, lam_parametric=0.1, lam_nonparametric=0.01,
                                  n_features=40, sigma=2.0, forgetting_parametric=0.99,
                                  forgetting_nonparametric=0.995, standardizer_warmup=20),
        "SP prior": SemiparametricModel(_regressor, 5, 4, 3, lam_parametric=0.1, lam_nonparametric=0.01,
                                        n_features=40, sigma=2.0, forgetting_parametric=0.99,
                                        forgetting_nonparametric=0.995, standardizer_warmup=20, prior=PRIOR),
    }


def test_parametric_variance_is_the_closed_form_posterior_variance():
    """v = φ A⁻¹ φᵀ with A = λI + Σ Φᵢᵀ Φᵢ (β = 1), computed by a dense solve, for every output row."""
    rng = np.random.default_rng(3)
    lam = 0.1
    model = ParametricModel(_regressor, 5, 3, lam=lam)
    A = lam * np.eye(5)
    for _ in range(60):
        x = rng.normal(size=4)
        Phi = _regressor(x)
        got = predict_with_variance(model, x)
        ref = np.einsum("ij,ji->i", Phi, np.linalg.solve(A, Phi.T))
        # A is SPD with cond(A) < 1e4 here: a backward-stable solve errs by ≲ κ·ε relative
        assert np.linalg.cond(A) < 1e4
        np.testing.assert_allclose(got.variance, ref, rtol=1e4 * 64 * np.finfo(float).eps, atol=0)
        model.learn_one(x, Phi @ np.arange(1.0, 6.0))
        A += Phi.T @ Phi


@pytest.mark.parametrize("kind", ["P", "NP", "SP", "P prior", "SP prior"])
def test_predict_with_variance_is_predict_one_with_the_warm_up_at_zero(kind):
    rng = np.random.default_rng(3)
    model = _models()[kind]
    X = rng.normal(size=(120, 4))
    Y = np.stack([_regressor(x) @ np.arange(1.0, 6.0) + 0.3 * np.sin(3 * x[0]) for x in X])
    Y += 0.01 * rng.normal(size=Y.shape)
    for k, (x, y) in enumerate(zip(X, Y, strict=True)):
        ref = model.predict_one(x, return_variance=True)
        got = predict_with_variance(model, x)
        # the first call of a pair also applies the deferred update (one fused pass), the second solves with
        # the updated factor: equal in exact arithmetic; cond(R) < 1e4 here keeps rounding far below 1e-9
        scale = 1.0 + np.abs(ref.total).max()
        np.testing.assert_allclose(got.total, ref.total, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(got.variance, np.nan_to_num(ref.variance, nan=0.0), rtol=1e-9, atol=1e-12)
        assert np.isfinite(got.variance).all() and (got.variance >= 0).all()
        if k % 2:
            model.learn_one(x, y)
        else:
            model.predict_learn_one(x, y)
    with pytest.raises(RejectedSampleError):
        predict_with_variance(model, np.full(4, np.nan))
    if not kind.startswith("P"):
        with pytest.raises(RejectedSampleError):
            predict_with_variance(model, np.zeros(3))
