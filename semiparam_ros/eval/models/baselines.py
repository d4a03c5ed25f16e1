"""Reference models the learners are compared with on recorded joint-torque logs.

Each is an online model of the protocol's interface (``predict_one``, ``predict_learn_one``, ``copy``), so
:func:`~semiparam_ros.eval.protocol.prequential.run_protocol` runs it like P, NP and SP:

- :class:`Persistence` predicts the previous measured output ``y_{k−1}`` (one step ahead; zeros before
  the first sample). It is the floor any one-step-ahead predictor must beat at high rates, and useless
  as a model: its residual ``y_k − y_{k−1}`` hides any external torque that lasts more than one sample.
- :class:`FixedParameters` predicts ``Φ(x) π`` with parameters that never change, e.g. the CAD model
  (:func:`cad_model`: RNEA with the URDF's inertial parameters, no friction, no learning).
- :func:`batch_least_squares` identifies the base parameters (with the friction and offset columns of
  the configuration) by ordinary least squares on a whole training log, as the offline identification
  tools do (FloBaRoID, FIGAROH: base parameters + viscous/Coulomb friction + offset, no prior, no ridge):
  ``π̂ = argmin Σ_m ‖y_m − Φ_m π‖²``. The stacked regressor is reduced block by block to its triangular
  factor (``[R | d]`` with ``RᵀR = ΦᵀΦ``, ``Rᵀd = ΦᵀY``: a tall-skinny QR in O(n·t·b²) time and O(b²)
  memory, never the normal equations), and :func:`least_squares_model` turns the fit into a
  :class:`~semiparam_ros.core.learners.parametric.ParametricModel` that starts from exactly that state.
  Frozen, it is the offline identification; updated online (test-then-train), each new sample extends the
  least squares problem: after k test samples its parameters are the ordinary least-squares solution on the
  training log plus those k samples (the recursive RLS of :mod:`semiparam_ros.core.learners.rrls` with β = 1).

Units: outputs in N·m (joint torques) or N, N·m (wrench), as the regressor gives them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import solve_triangular

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.build import build_regressor, column_scale, regressor_function
from semiparam_ros.core.learners.contract import Prediction
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.core.validation import check_finite_array, check_positive_int
from semiparam_ros.errors import ConfigurationError

__all__ = [
    "FixedParameters",
    "LeastSquaresFit",
    "Persistence",
    "batch_least_squares",
    "cad_model",
    "identification_regressor",
    "least_squares_model",
]

Regressor = Callable[[np.ndarray], np.ndarray]


class Persistence:
    """Predict the previous measured output: ``ŷ_k = y_{k−1}`` (``0`` before the first sample).

    Args:
        n_outputs: t, the length of y.

    Raises:
        ConfigurationError: For t < 1.

    Example:
        >>> import numpy as np
        >>> m = Persistence(2)
        >>> m.predict_learn_one(np.zeros(3), np.array([1.0, 2.0])).total
        array([0., 0.])
        >>> m.predict_learn_one(np.zeros(3), np.array([3.0, 4.0])).total
        array([1., 2.])
    """

    def __init__(self, n_outputs: int) -> None:
        check_positive_int("n_outputs", n_outputs)
        self.n_outputs = int(n_outputs)
        self._last = np.zeros(self.n_outputs)

    def predict_one(self, x: Any) -> Prediction:
        """Return the last measured output (``x`` is ignored; no rigid-body part: ``parametric`` is zero)."""
        y = self._last.copy()
        return Prediction(parametric=np.zeros(self.n_outputs), residual=y, total=y)

    def learn_one(self, x: Any, y: Any) -> None:
        """Remember ``y`` (t,) as the next prediction.

        Raises:
            RejectedSampleError: If ``y`` has the wrong shape or non-finite entries (state unchanged).
        """
        self._last = check_finite_array("y", y, (self.n_outputs,)).copy()

    def predict_learn_one(self, x: Any, y: Any) -> Prediction:
        """Predict, then learn."""
        prediction = self.predict_one(x)
        self.learn_one(x, y)
        return prediction

    def copy(self) -> Persistence:
        """Independent copy."""
        other = Persistence(self.n_outputs)
        other._last = self._last.copy()
        return other


class FixedParameters:
    """Predict ``Φ(x) π`` with fixed parameters; learning is a no-op.

    Args:
        regressor: Maps x to the (t, b) regressor ``Φ(x)``.
        parameters: π (b,), in the units the regressor's columns expect.

    Raises:
        ConfigurationError: If π is not a finite vector.
    """

    def __init__(self, regressor: Regressor, parameters: Any) -> None:
        if not callable(regressor):
            raise ConfigurationError("regressor must be callable")
        p = np.asarray(parameters, dtype=np.float64)
        if p.ndim != 1 or not np.all(np.isfinite(p)):
            raise ConfigurationError(f"parameters must be a finite vector, got shape {p.shape}")
        self.regressor = regressor
        self.parameters = p

    def predict_one(self, x: Any) -> Prediction:
        """Return ``Φ(x) π`` (t,)."""
        y = np.asarray(self.regressor(np.asarray(x, dtype=np.float64)), dtype=np.float64) @ self.parameters
        return Prediction(parametric=y, residual=np.zeros_like(y), total=y)

    def learn_one(self, x: Any, y: Any) -> None:
        """Do nothing: the parameters are fixed."""

    def predict_learn_one(self, x: Any, y: Any) -> Prediction:
        """Predict (nothing is learned)."""
        return self.predict_one(x)

    def copy(self) -> FixedParameters:
        """Return ``self``: the model has no state that learning could change."""
        return self


def cad_model(config: EstimatorConfig) -> FixedParameters:
    """Build the CAD model: RNEA with the URDF's inertial parameters (no friction, no offsets, no learning).

    Args:
        config: Estimator configuration (``robot.*``); its ``parametric.*`` columns are ignored.

    Returns:
        The fixed model, predicting the output of ``robot.output`` [N·m or N, N·m].
    """
    rigid = config.with_overrides({"parametric.friction": False, "parametric.offsets": False,
                                   "parametric.armature": False, "parametric.sensor_offset": False})
    regressor = build_regressor(rigid)
    return FixedParameters(regressor_function(regressor), regressor.to_base(regressor.urdf_parameters()))


def identification_regressor(config: EstimatorConfig) -> tuple[Regressor, np.ndarray]:
    """Return the regressor of batch identification: base parameters plus the configuration's extra columns.

    The columns are scaled as the learners scale them
    (:func:`~semiparam_ros.core.estimator.build.column_scale`), which leaves the least-squares prediction
    unchanged and improves the factor's conditioning.

    Args:
        config: Estimator configuration (``robot.*``, ``parametric.friction/offsets/armature``).

    Returns:
        ``(phi, scale)``: x ↦ ``Φ_b(x) diag(1/c)`` and the column scales c (divide fitted parameters by c
        for the physical base parameters).
    """
    regressor = build_regressor(config)
    scale = column_scale(config, regressor)
    return regressor_function(regressor, scale), scale


@dataclass(frozen=True)
class LeastSquaresFit:
    """Ordinary least squares ``min_π Σ_m ‖y_m − Φ_m π‖²`` over a log, as its triangular factor.

    Attributes:
        R: (b, b) upper triangular with a positive diagonal, ``RᵀR = Σ Φ_mᵀΦ_m``.
        d: (b,) with ``Rᵀd = Σ Φ_mᵀ y_m``.
        residual_ss: Σ ‖y_m − Φ_m π̂‖² at the solution (units of y²).
        n_samples: Samples m (each t rows).
        n_outputs: t.
    """

    R: np.ndarray
    d: np.ndarray
    residual_ss: float
    n_samples: int
    n_outputs: int

    @property
    def parameters(self) -> np.ndarray:
        """``π̂ = R⁻¹d`` (b,), by back substitution."""
        return np.asarray(solve_triangular(self.R, self.d, lower=False, check_finite=False))

    @property
    def rms_residual(self) -> float:
        """RMS of the fit's residual over all rows (units of y)."""
        return float(np.sqrt(self.residual_ss / (self.n_samples * self.n_outputs)))


def batch_least_squares(regressor: Regressor, X: np.ndarray, Y: np.ndarray, *,
                        block: int = 500) -> LeastSquaresFit:
    """Fit ordinary least squares on a whole log by a blocked (tall-skinny) QR of the stacked regressor.

    Each block of samples is stacked under the current ``[R | d]`` and triangularized again (Householder
    QR), so memory is O((block·t + b)·b) whatever the log's length.

    Args:
        regressor: Maps x to the (t, b) regressor ``Φ(x)``.
        X: Inputs ``[q, q̇, q̈]`` (rad, rad/s, rad/s²), shape ``(n, d)``.
        Y: Measured outputs, shape ``(n, t)``.
        block: Samples per block.

    Returns:
        The :class:`LeastSquaresFit`.

    Raises:
        ConfigurationError: If the shapes disagree, the log is empty, or the stacked regressor is
            rank-deficient (a parameter the log does not excite: ordinary least squares has no unique
            solution; use fewer columns or a richer log).
    """
    X = np.asarray(X, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    check_positive_int("block", block)
    if X.ndim != 2 or Y.ndim != 2 or X.shape[0] != Y.shape[0] or X.shape[0] == 0:
        raise ConfigurationError(
            f"X and Y must be non-empty 2-D arrays of equal length, got {X.shape}, {Y.shape}")
    n, t = Y.shape
    top: np.ndarray | None = None  # the augmented factor [R d; 0 ρ] of the blocks so far
    for start in range(0, n, block):
        rows = [np.asarray(regressor(x), dtype=np.float64) for x in X[start : start + block]]
        Phi = np.concatenate(rows)
        if Phi.shape[0] != t * len(rows):
            raise ConfigurationError(f"the regressor returns {rows[0].shape[0]} rows, the outputs have {t}")
        stacked = np.hstack([Phi, Y[start : start + block].reshape(-1, 1)])
        if top is not None:
            stacked = np.vstack([top, stacked])
        # [R d; 0 ρ]: the (b+1)-th diagonal entry ρ of the augmented factor is the residual norm so far
        top = np.asarray(np.linalg.qr(stacked, mode="r"))
    assert top is not None
    b = top.shape[1] - 1
    residual_ss = float(top[b, b] ** 2) if top.shape[0] > b else 0.0
    R, d = top[:b, :b].copy(), top[:b, b].copy()
    sign = np.where(np.diag(R) < 0.0, -1.0, 1.0)
    R *= sign[:, None]
    d *= sign
    diag = np.abs(np.diag(R))
    if R.shape[0] < b or diag.min() <= b * np.finfo(float).eps * diag.max():
        raise ConfigurationError(
            "the stacked regressor is rank-deficient: the log does not excite every identified parameter"
        )
    return LeastSquaresFit(R=R, d=d, residual_ss=residual_ss, n_samples=n, n_outputs=t)


def least_squares_model(regressor: Regressor, fit: LeastSquaresFit) -> ParametricModel:
    """Build a rigid-body learner whose state is the batch fit: ordinary recursive least squares from there.

    The returned :class:`~semiparam_ros.core.learners.parametric.ParametricModel` (zero prior, β = 1)
    predicts ``Φ(x) π̂`` and, updated with new samples, stays the exact least-squares solution over the fit's
    log plus those samples (its factor is the fit's, extended by Givens rotations; no ridge: λ only sets the
    factor of a reset, never used here).

    Args:
        regressor: The regressor the fit was computed with.
        fit: The batch fit.

    Returns:
        The learner (its ``parameters`` are π̂).
    """
    b = fit.R.shape[0]
    model = ParametricModel(regressor, b, fit.n_outputs, lam=1.0)
    state = model.rls.state_dict()
    state["M"] = np.hstack([fit.R, fit.d.reshape(-1, 1)])
    state["n_samples_seen"] = np.array(fit.n_samples * fit.n_outputs)
    state["n_steps"] = np.array(fit.n_samples)
    model.rls = RecursiveRLS.from_state_dict(state)
    model.n_samples_seen = fit.n_samples
    return model
