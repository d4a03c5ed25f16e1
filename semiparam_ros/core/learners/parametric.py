"""The rigid-body learner P of Camoriano et al. (ICRA 2016): ``y = Φ(x) π``.

:class:`ParametricModel` — recursive ridge regression on the t rows of the regressor ``Φ(x)`` (one time
step per sample), output ``ŷ = Φ(x) π̂``, regularized toward a prior π₀ (the URDF's CAD values).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from semiparam_ros.core.learners._kernels import within
from semiparam_ros.core.learners.base import LearnerBase, Regressor, checked_rigid
from semiparam_ros.core.learners.contract import Prediction, PredictionContext
from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.core.validation import MAX_ABS_INPUT, check_finite_array
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError

__all__ = ["ParametricModel"]


class ParametricModel(LearnerBase):
    """Rigid-body (parametric) estimator: recursive ridge regression of y on the rows of ``Φ(x)``.

    Args:
        regressor: Maps x to the (n_outputs, n_params) regressor matrix ``Φ(x)``.
        n_params: Number of (base) parameters.
        n_outputs: t, length of y.
        lam: Ridge regularizer λ > 0 (prior precision of π, units of Φ²).
        forgetting: β ∈ (0, 1] per sample; β < 1 forgets while keeping the prior (see ``core.learners.rrls``).
        prior: Prior mean π₀ (n_params,) the ridge pulls toward, e.g. a URDF's base parameters; default
            zero (the paper: no CAD prior).

    Raises:
        ConfigurationError: Invalid sizes or hyperparameters.

    **Prior mean.** The model solves ``π̂ = argmin Σ β^{n−m}‖y_m − Φ_m π‖² + λ‖π − π₀‖²`` by learning the
    deviation ``δ = π − π₀`` with the recursive ridge of :mod:`semiparam_ros.core.learners.rrls` on the
    targets ``y − Φπ₀``; ``π̂ = π₀ + δ̂`` and ``ŷ = Φ(π₀ + δ̂)``. Before any data ``δ̂ = 0``, so the
    prediction is ``Φπ₀`` exactly; and bounded forgetting, which keeps the regularizer on δ at strength λ
    around 0, keeps it around π₀ — unexcited directions relax toward the prior, never toward zero.

    Example:
        >>> import numpy as np
        >>> line = lambda x: np.array([[x[0], 1.0]])  # Φ(x) of y = a·x + b, π = [a, b]
        >>> model = ParametricModel(line, n_params=2, n_outputs=1, lam=1e-9)
        >>> for x in (0.0, 1.0, 2.0):
        ...     model.learn_one([x], [3.0 * x + 1.0])
        >>> np.round(model.parameters, 6)
        array([3., 1.])
        >>> round(float(model.predict_one([4.0]).total[0]), 6)
        13.0
    """

    _kind = "parametric"

    def __init__(self, regressor: Regressor, n_params: int, n_outputs: int, *, lam: float = 1.0,
                 forgetting: float = 1.0, prior: Any = None) -> None:
        if not callable(regressor):
            raise ConfigurationError("regressor must be callable")
        self.regressor = regressor
        self.rls = RecursiveRLS(n_params, 1, lam, forgetting=forgetting)
        self.n_params = self.rls.n_features
        self.n_outputs = int(n_outputs)
        if self.n_outputs < 1:
            raise ConfigurationError(f"n_outputs must be >= 1, got {n_outputs!r}")
        self._set_prior(np.zeros(self.n_params) if prior is None else prior)
        self.n_samples_seen = 0
        # the last x and its regressor: predicting then learning the same sample (the contact gate's
        # order) evaluates Φ(x) once; the regressor must be a pure function of x
        self._phi_cache: tuple[np.ndarray, np.ndarray] | None = None
        self._rigid: np.ndarray | None = None  # the parameters predicted with (None: the learned π̂)

    def use_rigid(self, rigid: np.ndarray | None) -> None:
        """Predict with these parameters instead of the learned π̂, from now on (None: the learned ones).

        For the physically consistent projection of π̂, re-solved off the sample path: the predictions
        are ``Φ(x)π``; the learner keeps learning π̂ unconstrained (what the projection starts from) and
        the variance stays the learner's. Not part of the saved state; reset and load clear it.

        Args:
            rigid: (p,) parameters in the learner's units, or None.

        Raises:
            RejectedSampleError: A wrong size or a non-finite value (the model is unchanged).

        Example:
            >>> m = ParametricModel(lambda x: np.array([[x[0]]]), n_params=1, n_outputs=1)
            >>> m.use_rigid(np.array([2.0]))
            >>> float(m.predict_one([3.0]).total[0])  # Φ(x)π = 3 · 2
            6.0
        """
        checked = checked_rigid(rigid, self.n_params)
        self._rigid = None if checked is None else checked.copy()

    @property
    def rigid_override(self) -> np.ndarray | None:
        """The parameters set by :meth:`use_rigid` (learner units), or None (the learned ones)."""
        return None if self._rigid is None else self._rigid.copy()

    def _set_prior(self, prior: Any) -> None:
        p = np.asarray(prior, dtype=np.float64)
        if p.shape != (self.n_params,):
            raise ConfigurationError(f"prior must have shape ({self.n_params},), got {p.shape}")
        if not (np.abs(p).max(initial=0.0) <= MAX_ABS_INPUT):
            raise ConfigurationError("prior contains NaN, inf or absurdly large entries")
        self.prior = np.ascontiguousarray(p)
        self.prior.flags.writeable = False
        self._has_prior = bool(np.any(p != 0.0))

    def prior_output(self, Phi: np.ndarray) -> np.ndarray | None:
        """``Φπ₀`` (t,), or None for a zero prior."""
        return Phi @ self.prior if self._has_prior else None

    def predict_phi(
        self, Phi: np.ndarray, want_variance: bool = False
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """``Φ(π₀ + δ̂)`` (t,) for a validated regressor, and ``diag(Φ A⁻¹ Φᵀ)`` when asked (one pass).

        ``Φπ`` instead where :meth:`use_rigid` set π.
        """
        rows = np.ascontiguousarray(Phi)
        P, var = (self.rls.predict(rows, return_variance=True, checked=True) if want_variance
                  else (self.rls.predict(rows, checked=True), None))
        if self._rigid is not None:
            return Phi @ self._rigid, var
        yp = P[:, 0]
        y0 = self.prior_output(Phi)
        return (yp if y0 is None else yp + y0), var

    def predict_many(self, X: Any, rigid: np.ndarray | None = None) -> Prediction:
        """Predict N inputs at once: ``Φ(x)(π₀ + δ̂)`` and the relative variance, arrays of shape (N, t).

        One regressor evaluation per row, then one matrix product and one triangular solve for all
        ``N·t`` regressor rows (BLAS level 3); equal to N calls of :meth:`predict_one` to rounding.

        Args:
            X: (N, n_inputs) inputs ``[q, q̇, q̈]``.
            rigid: Parameters to predict with instead of ``π₀ + δ̂`` (this learner's units, e.g. a
                physically consistent projection); the variance is the learner's either way.

        Returns:
            The prediction (``residual`` zero), ``variance`` = ``diag(Φ A⁻¹ Φᵀ)`` per row.

        Raises:
            RejectedSampleError: Wrong shape, NaN/inf in X, or a bad regressor output.
        """
        X2 = check_finite_array("X", X, (None, None))
        Phi = self.phi_rows(X2)
        yp, var = self.predict_phi_rows(Phi)
        if rigid is not None:
            yp = Phi @ check_finite_array("rigid", rigid, (self.n_params,))
        elif self._rigid is not None:
            yp = Phi @ self._rigid
        return Prediction(yp, np.zeros_like(yp), yp.copy(), var)

    def phi_rows(self, X2: np.ndarray) -> np.ndarray:
        """Stacked regressors (N, t, p) of validated inputs (N, n_inputs).

        A regressor with a ``many`` attribute (the rigid-body regressor's, see
        :func:`~semiparam_ros.core.estimator.build.regressor_function`) maps all rows in one call; any
        other is called row by row.
        """
        many = getattr(self.regressor, "many", None)
        if many is None:
            Phi = np.empty((X2.shape[0], self.n_outputs, self.n_params))
            for i in range(X2.shape[0]):
                Phi[i] = self._phi_uncached(np.ascontiguousarray(X2[i]))
            return Phi
        return self._checked_phi(many(np.ascontiguousarray(X2)), (X2.shape[0], self.n_outputs, self.n_params))

    def predict_phi_rows(self, Phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(Φ(π₀ + δ̂), diag(Φ A⁻¹ Φᵀ))`` of stacked regressors (N, t, p), both (N, t)."""
        n, t, p = Phi.shape
        rows = np.ascontiguousarray(Phi.reshape(n * t, p))
        P, var = self.rls.predict(rows, return_variance=True, checked=True)
        assert var is not None  # asked for
        yp = P[:, 0] if not self._has_prior else P[:, 0] + rows @ self.prior
        return yp.reshape(n, t), var.reshape(n, t)

    def predict_update_phi(self, Phi: np.ndarray, y: np.ndarray) -> np.ndarray:
        """A-priori ``Φ(π₀ + δ̂)``, then learn ``y − Φπ₀`` (validated inputs); counters untouched."""
        y0 = self.prior_output(Phi)
        if y0 is None:
            return self.rls.predict_update(Phi, y.reshape(-1, 1), checked=True)[:, 0]
        return self.rls.predict_update(Phi, (y - y0).reshape(-1, 1), checked=True)[:, 0] + y0

    def update_phi(self, Phi: np.ndarray, y: np.ndarray) -> None:
        """Learn ``y − Φπ₀`` (validated inputs); counters untouched."""
        y0 = self.prior_output(Phi)
        self.rls.update(Phi, (y if y0 is None else y - y0).reshape(-1, 1), checked=True)

    # --- internals shared with SemiparametricModel
    def phi_cached(self, x: np.ndarray) -> np.ndarray:
        """Return the regressor Φ(x) (outputs × parameters), reusing the last one when x is the same."""
        cache = self._phi_cache
        if cache is not None and np.array_equal(cache[0], x):
            return cache[1]
        Phi = self._phi_uncached(x)
        self._phi_cache = (np.array(x, dtype=np.float64), Phi)
        return Phi

    def phi_fresh(self, x: np.ndarray) -> np.ndarray:
        """Φ(x) evaluated now (x is new: no comparison with the cache), then cached for a learn of x."""
        Phi = self._phi_uncached(x)
        self._phi_cache = (x.copy(), Phi)
        return Phi

    def _phi_uncached(self, x: np.ndarray) -> np.ndarray:
        return self._checked_phi(self.regressor(x), (self.n_outputs, self.n_params))

    @staticmethod
    def _checked_phi(value: Any, shape: tuple[int, ...]) -> np.ndarray:
        """Return the regressor's output as a C-contiguous float64 array of ``shape``, values checked.

        Raises:
            ConfigurationError: Another shape (a regressor that does not fit the model).
            RejectedSampleError: NaN, inf or entries beyond ±MAX_ABS_INPUT.
        """
        Phi = np.ascontiguousarray(value, dtype=np.float64)
        if Phi.shape != shape:
            raise ConfigurationError(f"regressor returned shape {Phi.shape}, expected {shape}")
        if not within(Phi.reshape(-1, shape[-1]), MAX_ABS_INPUT):
            raise RejectedSampleError("regressor returned NaN, inf or absurdly large entries")
        return Phi

    def _check(self, x: Any, y: Any = None) -> tuple[np.ndarray, np.ndarray | None]:
        xv = check_finite_array("x", x, (None,))
        yv = None if y is None else check_finite_array("y", y, (self.n_outputs,))
        return xv, yv

    def rls_stages(self) -> tuple[RecursiveRLS, ...]:
        """Return the recursive least-squares learners holding this model's state (the learner contract)."""
        return (self.rls,)

    def _check_x(self, x: Any) -> np.ndarray:
        return check_finite_array("x", x, (None,))

    def predict_ahead_checked(self, xv: np.ndarray) -> PredictionContext:
        """Do :meth:`predict_ahead` for an input already checked (finite, the model's shape) and copied."""
        Phi = self.phi_fresh(xv)
        yp, var = self.predict_phi(Phi, True)
        pred = Prediction(yp, np.zeros(self.n_outputs), yp.copy(), var)
        return PredictionContext(pred, self, xv, Phi, None)

    def learn_ahead_checked(self, context: PredictionContext, yv: np.ndarray) -> None:
        """Do :meth:`learn_ahead` for an output already checked (finite, ``n_outputs`` values)."""
        Phi = self._take(context).Phi
        assert Phi is not None  # a ParametricModel's context always holds the regressor
        self.update_phi(Phi, yv)
        self.n_samples_seen += 1

    # --- interface
    def predict_one(self, x: Any, *, return_variance: bool = False) -> Prediction:
        """Predict ``ŷ = Φ(x) π̂``.

        Args:
            x: The input ``[q, q̇, q̈]``.
            return_variance: Also compute ``diag(Φ A⁻¹ Φᵀ)`` (same triangular solve as the prediction).

        Raises:
            RejectedSampleError: Bad x or regressor output.
        """
        xv, _ = self._check(x)
        Phi = self.phi_cached(xv)
        yp, var = self.predict_phi(Phi, return_variance)
        return Prediction(yp, np.zeros(self.n_outputs), yp.copy(), var)

    def _learn(self, x: Any, y: Any, want_prediction: bool) -> Prediction | None:
        """Update π̂ with one sample (t rows, one time step); the a-priori prediction in the same pass."""
        xv, yv = self._check(x, y)
        assert yv is not None  # _check returns y checked when it is given
        Phi = self.phi_cached(xv)
        if not want_prediction:
            self.update_phi(Phi, yv)
            self.n_samples_seen += 1
            return None
        yp = self.predict_update_phi(Phi, yv)
        if self._rigid is not None:
            yp = Phi @ self._rigid
        self.n_samples_seen += 1
        return Prediction(yp, np.zeros(self.n_outputs), yp.copy())

    @property
    def parameters(self) -> np.ndarray:
        """π̂ = π₀ + δ̂, the current parameter estimate (n_params,)."""
        return self.rls.weights[:, 0] + self.prior

    def set_standardizer_warmup(self, warmup: int) -> None:
        """Do nothing: the rigid-body stage has no standardizer (same interface as NP and SP)."""

    def reset(self) -> None:
        """Forget everything learned (π̂ back to the prior π₀) and any parameters set by :meth:`use_rigid`."""
        self.rls.reset()
        self.n_samples_seen = 0
        self._rigid = None

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the learned state (not the regressor) as arrays."""
        state = {f"{prefix}kind": np.array(self._kind), f"{prefix}n_outputs": np.array(self.n_outputs),
                 f"{prefix}n_samples_seen": np.array(self.n_samples_seen),
                 f"{prefix}prior": self.prior.copy()}
        state.update(self.rls.state_dict(f"{prefix}rls."))
        return state

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Replace the learned state (validated completely before anything changes).

        The prior stored with the state is loaded with it (δ̂ is relative to it).

        Raises:
            CheckpointError: Wrong kind, missing keys, or sizes that do not match this model's regressor.
        """
        self._check_kind(state, prefix)
        rls = RecursiveRLS.from_state_dict(state, f"{prefix}rls.")
        try:
            prior = np.asarray(state[f"{prefix}prior"], dtype=np.float64)
            n_outputs = int(state[f"{prefix}n_outputs"])
            n_seen = int(state[f"{prefix}n_samples_seen"])
        except KeyError as err:
            raise CheckpointError(f"state is missing key {err}") from err
        if rls.n_features != self.n_params or rls.n_outputs != 1 or n_outputs != self.n_outputs:
            raise CheckpointError(f"state is for n_params={rls.n_features}, n_outputs={n_outputs}; "
                                  f"this model has n_params={self.n_params}, n_outputs={self.n_outputs}")
        if prior.shape != (self.n_params,) or not np.isfinite(prior).all():
            raise CheckpointError(f"state has a prior of shape {prior.shape} or non-finite values; expected "
                                  f"({self.n_params},) finite")
        self._set_prior(prior)
        self.rls, self.n_samples_seen = rls, n_seen
        self._rigid = None
