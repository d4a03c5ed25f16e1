"""The one-solve predictive variance equals the learners' own two-solve ``predict_one(return_variance)``."""

from __future__ import annotations

import numpy as np
import pytest

from semiparam_ros.core.semiparametric import NonparametricModel, ParametricModel, SemiparametricModel
from semiparam_ros.core.uncertainty import predict_with_variance


def _regressor(x: np.ndarray) -> np.ndarray:
    # a smooth (3 × 5) regressor of a 4-dimensional input
    return np.array([[1.0, x[0], x[1] * x[2], np.sin(x[3]), x[0] ** 2],
                     [x[1], 1.0, np.cos(x[0]), x[2], x[3] * x[0]],
                     [x[2] * x[3], x[0] - x[1], 1.0, x[1] ** 2, np.sin(x[2])]])


def _models():
    return {
        "P": ParametricModel(_regressor, 5, 3, lam=0.1, forgetting=0.99),
        "NP": NonparametricModel(4, 3, n_features=40, sigma=2.0, lam=0.01, forgetting=0.995,
                                 standardizer_warmup=20),
        "SP": SemiparametricModel(_regressor, 5, 4, 3, lam_parametric=0.1, lam_nonparametric=0.01,
                                  n_features=40, sigma=2.0, forgetting_parametric=0.99,
                                  forgetting_nonparametric=0.995, standardizer_warmup=20),
    }


@pytest.mark.parametrize("kind", ["P", "NP", "SP"])
def test_predict_with_variance_matches_predict_one(kind):
    rng = np.random.default_rng(3)
    model = _models()[kind]
    X = rng.normal(size=(120, 4))
    Y = np.stack([_regressor(x) @ np.arange(1.0, 6.0) + 0.3 * np.sin(3 * x[0]) for x in X])
    Y += 0.01 * rng.normal(size=Y.shape)
    for k, (x, y) in enumerate(zip(X, Y, strict=True)):
        ref = model.predict_one(x, return_variance=True)
        got = predict_with_variance(model, x)
        # both are exact in exact arithmetic; the factors here have cond(R) < 1e4, so rounding stays far
        # below 1e-9 (relative to the output scale)
        scale = 1.0 + np.abs(ref.total).max()
        np.testing.assert_allclose(got.total, ref.total, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(got.parametric, ref.parametric, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(got.variance, np.nan_to_num(ref.variance, nan=0.0), rtol=1e-9, atol=1e-12)
        if k % 2:
            model.learn_one(x, y)
        else:
            model.predict_learn_one(x, y)
    with pytest.raises(ValueError):
        predict_with_variance(model, np.full(4, np.nan))
    if kind != "P":
        with pytest.raises(ValueError):
            predict_with_variance(model, np.zeros(3))
