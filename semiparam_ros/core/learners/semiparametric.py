"""The three estimators of Camoriano et al. (ICRA 2016) behind one online interface.

* :class:`ParametricModel` (P) — rigid-body model ``y = Φ(x) π``: recursive ridge regression on the t rows
  of the regressor ``Φ(x)`` (one time step per sample), output ``ŷ = Φ(x) π̂``.
* :class:`NonparametricModel` (NP) — kernel regression with random Fourier features of the standardized
  input: ``ỹ = φ(s(x)) W``.
* :class:`SemiparametricModel` (SP) — the parametric model runs first and alone; the nonparametric stage
  learns the residual ``y − ŷ`` from random features of the standardized ``[x, ŷ]``, where ``ŷ`` is the
  parametric stage's *a-priori* prediction for the sample (the same ``ŷ`` used at prediction time); the
  online warm-up standardizes the ``ŷ`` block with the measured y's statistics (reason in the class).
  Prediction: ``ŷ + Δŷ``.

Common interface (river-style online learning): ``predict_one(x) -> Prediction``, ``learn_one(x, y)``,
``predict_learn_one(x, y) -> Prediction`` (the a-priori prediction, then the update — the hot path, one
pass over each stage's factor through :meth:`RecursiveRLS.predict_update`), ``parameters``,
``n_samples_seen``, ``copy()``, ``reset()``, ``state_dict(prefix)`` / ``load_state_dict(state, prefix)``,
``save(path)`` / ``load(path)``. ``load`` is an instance method: the regressor callable cannot be stored,
so a checkpoint is loaded into a model built with the same regressor.

Predict now, decide, then learn (the contact gate's order): ``predict_ahead(x) -> PredictionContext`` is
``predict_one(x, return_variance=True)`` that also keeps what it computed on the way (the regressor
``Φ(x)``, the parametric prediction, the random features), and ``learn_ahead(context, y)`` learns (x, y)
from exactly those — no second regressor, feature map or parametric prediction. The learned state is
``learn_one(x, y)``'s: bit for bit for P and NP (the same rows), to rounding for SP (the a-priori ŷ that
feeds the residual input comes from the forward substitution instead of the rotations; both are
``Φ(x) π̂`` to ≈ cond(R)·ε relative).

Inputs: ``x = [q, q̇, q̈]`` (rad, rad/s, rad/s², joints in configured order); ``y`` the measured output
(a wrench ``[fx, fy, fz, tx, ty, tz]`` in N and N·m in the sensor frame, or joint torques in N·m).
Bad ``x``/``y`` (shape, NaN/inf) raise :class:`~semiparam_ros.errors.RejectedSampleError` and leave the
model unchanged: every check runs before any state is touched.
"""

from __future__ import annotations

import copy as _copy
import math
import os
from collections.abc import Callable
from typing import Any

import numpy as np

from semiparam_ros.core.checkpoint import atomic_save_npz, load_npz
from semiparam_ros.core.learners._kernels import within
from semiparam_ros.core.learners._step_kernels import standardized_features
from semiparam_ros.core.learners.adaptation import forgetting_factor
from semiparam_ros.core.learners.contract import PeriodSettings, Prediction, PredictionContext
from semiparam_ros.core.learners.features import RandomFourierFeatures, Standardizer
from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.core.stream.rate import samples_in
from semiparam_ros.core.validation import MAX_ABS_INPUT, check_finite_array, check_positive_int
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError

__all__ = [
    "NonparametricModel", "ParametricModel", "SemiparametricModel",
    "checked_rigid", "rigid_body_part",
]

Regressor = Callable[[np.ndarray], np.ndarray]


class _Model:
    """What every learner shares: learning, the sample period, persistence.

    Subclasses define ``_kind``, ``_learn`` (one sample, with or without its a-priori prediction),
    ``_check_x``, ``predict_ahead_checked``, ``learn_ahead_checked``, ``rls_stages`` and the state.
    """

    _kind = ""
    n_outputs: int
    n_samples_seen: int
    #: What :meth:`on_period` converts (set by the builder from the configuration).
    period_settings = PeriodSettings()
    #: The period [s] last announced by :meth:`on_period` (None before).
    sample_period_s: float | None = None
    #: Age [s] of the learned state at the predictions that follow: the sample period times the samples
    #: between the newest learned sample and the predicted one (0 = the previous sample was learned). Set
    #: by whoever knows the stamps (the estimator); a fast correction of recent errors fades with it (the
    #: consistent SP's), the other learners ignore it.
    prediction_age_s: float = 0.0

    def learn_one(self, x: Any, y: Any) -> None:
        """Learn one sample (x, y).

        Raises:
            RejectedSampleError: Bad x, y or regressor output (model unchanged).
        """
        self._learn(x, y, False)

    def predict_learn_one(self, x: Any, y: Any) -> Prediction:
        """Return the a-priori prediction for x, then learn (x, y) (one pass over each stage's factor).

        Raises:
            RejectedSampleError: Bad x, y or regressor output (model unchanged).
        """
        prediction = self._learn(x, y, True)
        assert prediction is not None  # asked for
        return prediction

    def _learn(self, x: Any, y: Any, want_prediction: bool) -> Prediction | None:  # pragma: no cover
        raise NotImplementedError

    def on_period(self, sample_period_s: float) -> float | None:
        """Take the measured sample period T [s] and convert what :attr:`period_settings` gives in seconds.

        The standardizer warm-up given in seconds becomes ``max(1, round(d/T))`` samples (if it is still
        running), and with a time constant τ > 0 every adaptive stage forgets with β = exp(−T/τ).
        Idempotent: the same T again changes nothing.

        Args:
            sample_period_s: T > 0 [s].

        Returns:
            β if the time constant set it, else ``None``.

        Raises:
            ConfigurationError: On a period that is not a finite number > 0.

        Example:
            >>> import numpy as np
            >>> model = NonparametricModel(3, 1, n_features=8)
            >>> model.period_settings = PeriodSettings(time_constant_s=20.0)
            >>> round(model.on_period(0.001), 9) == round(float(np.exp(-0.001 / 20.0)), 9)
            True
        """
        period = float(sample_period_s)
        if not (math.isfinite(period) and period > 0.0):
            raise ConfigurationError(f"sample period must be a finite number > 0 s, got {sample_period_s!r}")
        settings = self.period_settings
        if settings.standardizer_warmup_s is not None:
            self.set_standardizer_warmup(samples_in(settings.standardizer_warmup_s, sample_period_s))
            self.learn_held()  # a shorter warm-up may have ended with samples held
        beta = None
        if settings.time_constant_s > 0.0:
            beta = forgetting_factor(settings.time_constant_s, sample_period_s)
            for rls in self.adaptive_stages():
                rls.set_forgetting(beta)
        self.sample_period_s = period
        return beta

    def set_standardizer_warmup(self, warmup: int) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def learn_held(self) -> None:
        """Learn the warm-up samples held until the residual's standardizer is ready (none by default)."""

    def _take(self, context: PredictionContext) -> PredictionContext:
        """Check that ``context`` was made by this model in its current state.

        A context is used once: learning it advances ``n_samples_seen``, which makes it stale.

        Raises:
            ValueError: If it was made by another model, already used, or the model learned since.
        """
        if context.model is not self or context.seen != self.n_samples_seen:
            raise ValueError("stale prediction context: learn_ahead needs the context of this model's last "
                             "predict_ahead, with nothing learned in between")
        return context

    def predict_ahead(self, x: Any) -> PredictionContext:
        """Predict x with the predictive variance and keep what learning x needs (see the module docstring).

        Args:
            x: The input ``[q, q̇, q̈]`` [rad, rad/s, rad/s²].

        Returns:
            The context; ``context.prediction`` is ``predict_one(x, return_variance=True)`` (warm-up
            variance 0 instead of NaN).

        Raises:
            RejectedSampleError: Bad x or regressor output.
        """
        return self.predict_ahead_checked(self._check_x(x).copy())  # the context must not see x change

    def learn_ahead(self, context: PredictionContext, y: Any) -> None:
        """Learn y for the input of ``context`` (from :meth:`predict_ahead`, nothing learned since).

        Equivalent to ``learn_one(x, y)`` to rounding, without recomputing the regressor, the features or
        the parametric prediction.

        Args:
            context: This model's last context.
            y: The measured output (units of y).

        Raises:
            RejectedSampleError: Bad y (the model and the context are unchanged).
            ValueError: A stale or already used context (a programming error).
        """
        self.learn_ahead_checked(context, check_finite_array("y", y, (self.n_outputs,)))

    def predict_held(self, x: Any) -> Prediction:
        """Predict x cheaply for a sample that will not be learned (a node that falls behind).

        Here the full a-priori prediction with its relative variance (what :meth:`predict_ahead` gives);
        the consistent semiparametric model holds its residual instead (O(p²) instead of O(D²)).

        Raises:
            RejectedSampleError: Bad x or regressor output.
        """
        return self.predict_ahead_checked(self._check_x(x).copy()).prediction

    def rls_stages(self) -> tuple[RecursiveRLS, ...]:  # pragma: no cover - abstract
        """Return the recursive least-squares learners holding this model's state."""
        raise NotImplementedError

    def adaptive_stages(self) -> tuple[RecursiveRLS, ...]:
        """Return the learners whose forgetting ``adaptation.time_constant`` sets (parametric stage first)."""
        return self.rls_stages()

    def has_pending(self) -> bool:
        """Tell whether a learner holds a deferred update (applied by the next prediction or now)."""
        return any(rls.has_pending for rls in self.rls_stages())

    def apply_pending(self) -> bool:
        """Apply the learners' deferred updates now (see :meth:`RecursiveRLS.apply_pending`).

        Returns:
            Whether any update was pending.
        """
        applied = False
        for rls in self.rls_stages():
            applied = rls.apply_pending() or applied
        return applied

    def _check_x(self, x: Any) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def predict_ahead_checked(self, xv: np.ndarray) -> PredictionContext:  # pragma: no cover - abstract
        raise NotImplementedError

    def learn_ahead_checked(self, context: PredictionContext, yv: np.ndarray) -> None:  # pragma: no cover
        raise NotImplementedError

    def copy(self) -> Any:
        """Return a deep copy of the learned state that shares the injected regressor callable."""
        memo: dict[int, Any] = {}
        reg = getattr(self, "regressor", None)
        if reg is not None:
            memo[id(reg)] = reg
        return _copy.deepcopy(self, memo)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the whole learned state to one ``.npz`` file atomically (temp file + rename)."""
        atomic_save_npz(path, self.state_dict())

    def load(self, path: str | os.PathLike[str]) -> Any:
        """Load a checkpoint written by :meth:`save` into this model (in place); returns self.

        Raises:
            CheckpointError: Missing/corrupt file, or a state of another kind or size (model unchanged).
        """
        self.load_state_dict(load_npz(path))
        return self

    def _check_kind(self, state: dict[str, np.ndarray], prefix: str) -> None:
        key = f"{prefix}kind"
        if key not in state:
            raise CheckpointError(f"state is missing key {key!r}")
        kind = str(np.asarray(state[key]))
        if kind != self._kind:
            raise CheckpointError(f"state holds a {kind!r} model, not a {self._kind!r} model")

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:  # pragma: no cover - abstract
        raise NotImplementedError

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:  # pragma: no cover
        raise NotImplementedError


def checked_rigid(rigid: Any, n_params: int) -> np.ndarray | None:
    """Return rigid-body parameters to predict with as a float64 array (None stays None), checked.

    Args:
        rigid: (p,) parameters in the learner's units, or None.
        n_params: p.

    Raises:
        RejectedSampleError: A wrong size or a non-finite value.
    """
    if rigid is None:
        return None
    arr = np.asarray(rigid, dtype=np.float64)
    if arr.shape != (n_params,) or not np.isfinite(arr).all():
        raise RejectedSampleError(f"rigid must be {n_params} finite parameters")
    return arr


class ParametricModel(_Model):
    """Rigid-body (parametric) estimator: recursive ridge regression of y on the rows of ``Φ(x)``.

    Args:
        regressor: Maps x to the (n_outputs, n_params) regressor matrix ``Φ(x)``.
        n_params: Number of (base) parameters.
        n_outputs: t, length of y.
        lam: Ridge regularizer λ > 0 (prior precision of π, units of Φ²).
        forgetting: β ∈ (0, 1] per sample; β < 1 forgets while keeping the prior (see ``core.rrls``).
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
        P, var = self.rls.predict_checked(np.ascontiguousarray(Phi), want_variance)
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
        P, var = self.rls.predict_checked(rows, True)
        assert var is not None  # asked for
        yp = P[:, 0] if not self._has_prior else P[:, 0] + rows @ self.prior
        return yp.reshape(n, t), var.reshape(n, t)

    def predict_update_phi(self, Phi: np.ndarray, y: np.ndarray) -> np.ndarray:
        """A-priori ``Φ(π₀ + δ̂)``, then learn ``y − Φπ₀`` (validated inputs); counters untouched."""
        y0 = self.prior_output(Phi)
        if y0 is None:
            return self.rls.predict_update_checked(Phi, y.reshape(-1, 1))[:, 0]
        return self.rls.predict_update_checked(Phi, (y - y0).reshape(-1, 1))[:, 0] + y0

    def update_phi(self, Phi: np.ndarray, y: np.ndarray) -> None:
        """Learn ``y − Φπ₀`` (validated inputs); counters untouched."""
        y0 = self.prior_output(Phi)
        self.rls.update_checked(Phi, (y if y0 is None else y - y0).reshape(-1, 1))

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

        The prior stored with the state is loaded with it (δ̂ is relative to it); a state without one
        (written before priors existed) had a zero prior.

        Raises:
            CheckpointError: Wrong kind, missing keys, or sizes that do not match this model's regressor.
        """
        self._check_kind(state, prefix)
        rls = RecursiveRLS.from_state_dict(state, f"{prefix}rls.")
        prior = np.asarray(state.get(f"{prefix}prior", np.zeros(rls.n_features)), dtype=np.float64)
        try:
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


class NonparametricModel(_Model):
    """Random-feature kernel ridge regression of y on the standardized input.

    Args:
        n_inputs: Length of x.
        n_outputs: t, length of y.
        n_features: D, number of random Fourier features.
        sigma: Gaussian kernel width σ in standardized input units.
        lam: Ridge regularizer λ > 0.
        forgetting: β ∈ (0, 1] per sample (prior-keeping, see ``core.rrls``).
        seed: Seed of the random features.
        standardizer: A :class:`Standardizer` for x (copied). Default: none (identity) unless
            ``standardizer_warmup > 0``. An unfitted standardizer must have a warm-up.
        standardizer_warmup: If > 0 and no standardizer is given, estimate the statistics online from the
            first N samples; the model predicts a zero residual until then, holds those N samples (bounded
            by N) and learns them, in their order, as soon as the statistics are ready (one
            :meth:`RecursiveRLS.update_steps` call of N rows: O(N·D²) once).
        standardizer_min_scale: Floor of the warm-up's scales (scalar or one value per input, units of x);
            see :class:`Standardizer`.

    Raises:
        ConfigurationError: Invalid sizes or hyperparameters, or a standardizer of the wrong size.

    Example:
        >>> import numpy as np
        >>> model = NonparametricModel(1, 1, n_features=300, sigma=0.5, lam=1e-3, seed=0)
        >>> for x in np.linspace(-1.0, 1.0, 400):
        ...     model.learn_one([x], [np.sin(3.0 * x)])
        >>> bool(abs(model.predict_one([0.3]).total[0] - np.sin(0.9)) < 0.01)
        True
    """

    _kind = "nonparametric"
    #: Hold the warm-up's samples and learn them once the statistics are ready (False: the warm-up's
    #: samples only feed the statistics, as before; no long step when the warm-up ends).
    learn_warmup: bool = True

    def __init__(self, n_inputs: int, n_outputs: int, *, n_features: int = 500, sigma: float = 1.0,
                 lam: float = 1.0, forgetting: float = 1.0, seed: int = 0,
                 standardizer: Standardizer | None = None, standardizer_warmup: int = 0,
                 standardizer_min_scale: Any = 0.0) -> None:
        self.n_inputs = int(n_inputs)
        self.n_outputs = int(n_outputs)
        self.rff = RandomFourierFeatures(n_inputs, n_features, sigma, seed)
        self.rls = RecursiveRLS(self.rff.n_features, n_outputs, lam, forgetting=forgetting)
        self.standardizer = _make_standardizer(self.n_inputs, standardizer, standardizer_warmup,
                                               standardizer_min_scale)
        self._initial_standardizer = self.standardizer.copy()
        self.n_samples_seen = 0
        # (input, target) of the samples the warm-up fed to the standardizer, learned once it is ready
        self._held_x: list[np.ndarray] = []
        self._held_y: list[np.ndarray] = []

    def hold_warmup(self, x_stats: np.ndarray, x_in: np.ndarray, target: np.ndarray) -> None:
        """Feed one warm-up sample to the standardizer and hold its row until the statistics are ready.

        Args:
            x_stats: What the standardizer's statistics take (the input, or another vector of its size).
            x_in: The input the row is learned with (validated, not written to afterwards).
            target: Its target (t,), validated.
        """
        self.standardizer.partial_fit(x_stats)
        if self.learn_warmup:
            self._held_x.append(x_in)
            self._held_y.append(target)

    @property
    def held_rows(self) -> int:
        """Warm-up samples held and not learned yet (0 once learned; at most the warm-up's length)."""
        return len(self._held_x)

    def take_held(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Return the held warm-up rows ``(X, Y)`` once the standardizer is ready, and forget them.

        None while the warm-up runs or when nothing is held.
        """
        if not self._held_x or not self.standardizer.ready:
            return None
        X, Y = np.array(self._held_x), np.array(self._held_y)
        self._held_x, self._held_y = [], []
        return X, Y

    def learn_held(self) -> None:
        """Learn the held warm-up rows in their order, if the standardizer is ready (one compiled call).

        The rows were validated when held; a row the learner refuses (a value above its bound) drops the
        held block with the learner unchanged, as a refused sample would be.
        """
        held = self.take_held()
        if held is None:
            return
        X, Y = held
        F = self.rff.transform(self.standardizer.transform(X))
        try:
            self.rls.update_steps(F, Y)
        except RejectedSampleError:
            pass  # counted as learned by n_samples_seen already; the learner is unchanged

    def features_of(self, x: np.ndarray) -> np.ndarray:
        """φ(s(x)) for a validated 1-D x, as a (1, D) row (finite by construction: cos of finite input).

        One compiled call (:func:`~semiparam_ros.core.learners._step_kernels.standardized_features`); equal to
        ``rff.transform(standardizer.transform(x))`` to rounding.
        """
        std, rff = self.standardizer, self.rff
        return standardized_features(x, std.mean_, std.scale_, rff.omega_, rff.offset_, rff.feature_scale)

    def predict_input(self, xin: np.ndarray, return_variance: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Predict the residual at a checked input: ``(r, relative variance or None)`` (NaN in warm-up)."""
        if not self.standardizer.ready:
            var = np.full(self.n_outputs, np.nan) if return_variance else None
            return np.zeros(self.n_outputs), var
        phi = self.features_of(xin)
        # one forward substitution gives both (fused with a pending update: see RecursiveRLS.predict)
        P, v = self.rls.predict_checked(phi, return_variance)
        var = np.full(self.n_outputs, float(v[0])) if v is not None else None
        return P[0], var

    def learn_input(self, xin: np.ndarray, target: np.ndarray, want_prediction: bool) -> np.ndarray:
        """Warm-up or update with validated inputs; returns the a-priori prediction if asked."""
        if not self.standardizer.ready:
            self.hold_warmup(xin, xin, target.copy())
            self.learn_held()
            return np.zeros(self.n_outputs)
        phi = self.features_of(xin)
        if want_prediction:
            return self.rls.predict_update_checked(phi, target.reshape(1, -1))[0]
        self.rls.update_checked(phi, target.reshape(1, -1))
        return np.zeros(0)

    def rls_stages(self) -> tuple[RecursiveRLS, ...]:
        """Return the recursive least-squares learners holding this model's state (the learner contract)."""
        return (self.rls,)

    def _check_x(self, x: Any) -> np.ndarray:
        return check_finite_array("x", x, (self.n_inputs,))

    def predict_ahead_checked(self, xv: np.ndarray) -> PredictionContext:
        """Do :meth:`predict_ahead` for an input already checked (finite, the model's shape) and copied."""
        t = self.n_outputs
        if not self.standardizer.ready:
            r, var, phi = np.zeros(t), np.zeros(t), None
        else:
            phi = self.features_of(xv)
            P, v = self.rls.predict_checked(phi, True)
            assert v is not None  # asked for
            r, var = P[0], np.full(t, float(v[0]))
        return PredictionContext(Prediction(np.zeros(t), r, r.copy(), var), self, xv, None, phi)

    def learn_ahead_checked(self, context: PredictionContext, yv: np.ndarray) -> None:
        """Do :meth:`learn_ahead` for an output already checked (finite, ``n_outputs`` values)."""
        phi = self._take(context).phi
        if phi is None:
            self.hold_warmup(context.x, context.x, yv.copy())
            self.learn_held()
        else:
            self.rls.update_checked(phi, yv.reshape(1, -1))
        self.n_samples_seen += 1

    def predict_one(self, x: Any, *, return_variance: bool = False) -> Prediction:
        """Predict ``φ(s(x)) W`` (zeros during the warm-up).

        Raises:
            RejectedSampleError: Bad x.
        """
        xv = check_finite_array("x", x, (self.n_inputs,))
        r, var = self.predict_input(xv, return_variance)
        return Prediction(np.zeros(self.n_outputs), r, r.copy(), var)

    def _learn(self, x: Any, y: Any, want_prediction: bool) -> Prediction | None:
        """Learn one sample (warm-up: fed to the standardizer and held); its a-priori prediction."""
        xv = check_finite_array("x", x, (self.n_inputs,))
        yv = check_finite_array("y", y, (self.n_outputs,))
        r = self.learn_input(xv, yv, want_prediction)
        self.n_samples_seen += 1
        return Prediction(np.zeros(self.n_outputs), r, r.copy()) if want_prediction else None

    @property
    def parameters(self) -> None:
        """None: the nonparametric model has no physical parameters."""
        return None

    def set_standardizer_warmup(self, warmup: int) -> None:
        """Set the online warm-up length [samples] if it is still running (else nothing changes).

        For a warm-up given in seconds, once the sample rate is measured; a later :meth:`reset` restarts
        a warm-up of this length. A standardizer that is fitted, given or already warmed up is kept.

        Raises:
            ConfigurationError: If ``warmup`` < 1.
        """
        check_positive_int("warmup", warmup)
        for std in (self.standardizer, self._initial_standardizer):
            if not std.ready:
                std.set_warmup(warmup)

    def reset(self) -> None:
        """Forget the learned weights; the standardizer returns to its initial state (warm-up restarts)."""
        self.rls.reset()
        self.standardizer = self._initial_standardizer.copy()
        self.n_samples_seen = 0
        self._held_x, self._held_y = [], []

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return features, standardizer statistics and weights as arrays."""
        state = {f"{prefix}kind": np.array(self._kind),
                 f"{prefix}n_samples_seen": np.array(self.n_samples_seen)}
        state.update(self.rff.state_dict(f"{prefix}rff."))
        state.update(self.standardizer.state_dict(f"{prefix}standardizer."))
        state.update(self._initial_standardizer.state_dict(f"{prefix}standardizer_initial."))
        state.update(self.rls.state_dict(f"{prefix}rls."))
        k = len(self._held_x)
        state[f"{prefix}held_x"] = np.array(self._held_x) if k else np.zeros((0, self.n_inputs))
        state[f"{prefix}held_y"] = np.array(self._held_y) if k else np.zeros((0, self.n_outputs))
        return state

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Replace the whole state (features included), validated before anything changes.

        Raises:
            CheckpointError: Wrong kind, missing keys or sizes that do not match n_inputs / n_outputs.
        """
        self._check_kind(state, prefix)
        rff = RandomFourierFeatures.from_state_dict(state, f"{prefix}rff.")
        std = Standardizer.from_state_dict(state, f"{prefix}standardizer.")
        std0 = Standardizer.from_state_dict(state, f"{prefix}standardizer_initial.")
        rls = RecursiveRLS.from_state_dict(state, f"{prefix}rls.")
        try:
            n_seen = int(state[f"{prefix}n_samples_seen"])
        except KeyError as err:
            raise CheckpointError(f"state is missing key {err}") from err
        if (rff.n_inputs != self.n_inputs or std.n_inputs != self.n_inputs or std0.n_inputs != self.n_inputs
                or rls.n_features != rff.n_features or rls.n_outputs != self.n_outputs):
            raise CheckpointError(f"state does not fit a model with n_inputs={self.n_inputs}, "
                             f"n_outputs={self.n_outputs}")
        # held warm-up rows (a checkpoint written before they were held has none: nothing to learn)
        held_x = np.asarray(state.get(f"{prefix}held_x", np.zeros((0, self.n_inputs))), dtype=np.float64)
        held_y = np.asarray(state.get(f"{prefix}held_y", np.zeros((0, self.n_outputs))), dtype=np.float64)
        k = held_x.shape[0] if held_x.ndim == 2 else -1
        if (held_x.shape != (k, self.n_inputs) or held_y.shape != (k, self.n_outputs)
                or k > max(std.count_, 0)
                or not (within(held_x, MAX_ABS_INPUT) and within(held_y, MAX_ABS_INPUT))):
            raise CheckpointError("the held warm-up rows have the wrong size or invalid values")
        self.rff, self.standardizer, self.rls, self.n_samples_seen = rff, std, rls, n_seen
        self._initial_standardizer = std0
        self._held_x, self._held_y = list(held_x), list(held_y)


def rigid_body_part(model: object) -> ParametricModel | None:
    """Return a model's rigid-body learner: P itself, the parametric stage of an SP; None for NP.

    >>> rigid_body_part(NonparametricModel(3, 1, n_features=4, standardizer_warmup=0)) is None
    True
    """
    par = model if isinstance(model, ParametricModel) else getattr(model, "parametric", None)
    return par if isinstance(par, ParametricModel) else None


def _make_standardizer(n_inputs: int, standardizer: Standardizer | None, warmup: int,
                       min_scale: Any = 0.0) -> Standardizer:
    if standardizer is not None:
        if not isinstance(standardizer, Standardizer):
            raise ConfigurationError("standardizer must be a Standardizer")
        if standardizer.n_inputs != n_inputs:
            raise ConfigurationError(f"standardizer has {standardizer.n_inputs} inputs, expected {n_inputs}")
        if warmup:
            raise ConfigurationError("give either a standardizer or standardizer_warmup, not both")
        std = standardizer.copy()
        if not std.ready and std.warmup == 0:
            raise ConfigurationError("the standardizer is neither fitted nor configured with a warm-up")
        return std
    warmup = check_positive_int("standardizer_warmup", warmup, minimum=0)
    if warmup == 0:
        return Standardizer.identity(n_inputs)
    return Standardizer(n_inputs, int(warmup), min_scale=min_scale)


class _TwoStageModel(_Model):
    """Plumbing shared by the two semiparametric models (the cascade and the joint fit).

    Both hold a rigid-body learner ``parametric`` (:class:`ParametricModel`) and a random-feature learner
    ``nonparametric`` (:class:`NonparametricModel`); see :mod:`semiparam_ros.core.learners.joint`.
    """

    parametric: ParametricModel
    nonparametric: NonparametricModel
    n_inputs: int
    n_outputs: int
    n_samples_seen: int

    def rls_stages(self) -> tuple[RecursiveRLS, ...]:
        return (self.parametric.rls, self.nonparametric.rls)

    @property
    def regressor(self) -> Regressor:
        """The injected regressor callable (shared by copies)."""
        return self.parametric.regressor

    def _check_x(self, x: Any) -> np.ndarray:
        return check_finite_array("x", x, (self.n_inputs,))

    def _check(self, x: Any, y: Any = None) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        xv = check_finite_array("x", x, (self.n_inputs,))
        yv = None if y is None else check_finite_array("y", y, (self.n_outputs,))
        return xv, yv, self.parametric.phi_cached(xv)

    @property
    def parameters(self) -> np.ndarray:
        """π̂, the rigid-body (base) parameters of the parametric learner (n_params,)."""
        return self.parametric.parameters

    def set_standardizer_warmup(self, warmup: int) -> None:
        """Set the residual stage's online warm-up length [samples] if it is still running.

        Raises:
            ConfigurationError: If ``warmup`` < 1.
        """
        self.nonparametric.set_standardizer_warmup(warmup)

    def learn_held(self) -> None:
        """Learn the residual stage's held warm-up rows once its standardizer is ready (the cascade's)."""
        self.nonparametric.learn_held()

    def reset(self) -> None:
        """Forget both learners (and restart the online standardizer warm-up)."""
        self.parametric.reset()
        self.nonparametric.reset()
        self.n_samples_seen = 0

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return both learners' state as arrays."""
        state = {f"{prefix}kind": np.array(self._kind),
                 f"{prefix}n_samples_seen": np.array(self.n_samples_seen)}
        state.update(self.parametric.state_dict(f"{prefix}parametric."))
        state.update(self.nonparametric.state_dict(f"{prefix}nonparametric."))
        return state

    def _check_loaded(self, parametric: ParametricModel, nonparametric: NonparametricModel) -> None:
        """Extra consistency checks of a loaded pair of learners (raise CheckpointError); none by default."""

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Replace both learners' state (validated completely before anything changes).

        Raises:
            CheckpointError: Wrong kind, missing keys or sizes that do not match this model.
        """
        self._check_kind(state, prefix)
        p = self.parametric.copy()
        npm = self.nonparametric.copy()
        p.load_state_dict(state, f"{prefix}parametric.")
        npm.load_state_dict(state, f"{prefix}nonparametric.")
        self._check_loaded(p, npm)
        try:
            n_seen = int(state[f"{prefix}n_samples_seen"])
        except KeyError as err:
            raise CheckpointError(f"state is missing key {err}") from err
        self.parametric, self.nonparametric, self.n_samples_seen = p, npm, n_seen


class SemiparametricModel(_TwoStageModel):
    """Parametric model first, then a nonparametric model of its residual (Camoriano et al. 2016).

    For a sample (x, y): ``ŷ = Φ(x) π̂`` (a-priori), the parametric stage is updated with y, then the
    nonparametric stage learns ``y − ŷ`` from random features of the standardized ``[x, ŷ]``.
    Prediction ``ŷ + Δŷ`` with ``Δŷ = φ(s([x, ŷ])) W``.

    Args:
        regressor: Maps x to ``Φ(x)`` (n_outputs, n_params).
        n_params: Number of (base) parameters.
        n_inputs: Length of x.
        n_outputs: t, length of y.
        lam_parametric: λ of the parametric stage.
        lam_nonparametric: λ of the residual stage.
        n_features: D random features of the residual stage.
        sigma: Kernel width in standardized units of ``[x, ŷ]``.
        forgetting_parametric: β of the parametric stage (per sample).
        forgetting_nonparametric: β of the residual stage (per sample).
        seed: Seed of the random features.
        standardizer: Optional :class:`Standardizer` for ``[x, ŷ]`` (n_inputs + n_outputs values).
        standardizer_warmup: Online warm-up length of the standardizer if none is given (0 = identity).
        standardizer_min_scale: Floor of the warm-up's scales for ``[x, ŷ]`` (scalar or n_inputs +
            n_outputs values, units of x and y); see :class:`Standardizer`.
        yhat_statistics: What the online warm-up standardizes the ŷ block with: ``"measured"`` (default)
            the statistics of the measured y over the warm-up samples, ``"predicted"`` those of the
            a-priori ŷ itself (the behaviour before this option existed).
        prior: Prior mean π₀ of the parametric stage (see :class:`ParametricModel`); default zero.

    Raises:
        ConfigurationError: Invalid sizes or hyperparameters.

    **Why ŷ is standardized with the measured y's statistics.** ŷ enters the residual stage as an estimate
    of y, so y's own mean and spread are its natural units, and they do not depend on the rigid-body
    stage's state. ŷ's own statistics over the warm-up do: the parametric stage starts from its prior
    (zero in the paper, or the URDF's) and is still converging while the warm-up runs, so its early a-priori
    predictions (zeros, then overshoots) bias the mean and inflate the spread of the ŷ block, and that
    mis-scaling is frozen into the kernel metric for the rest of the model's life, weighting the ŷ
    coordinates arbitrarily against x.
    Once the parametric stage has converged ŷ ≈ y, so the measured statistics are what ŷ's would then be.
    The warm-up sees y anyway (the residual target needs it), so this costs nothing. With an explicit
    ``standardizer`` this does not apply. The ablation behind the default is in ``docs/design-notes.md``.

    **The warm-up's samples are learned too**, once the statistics are ready, as the paper's cascade
    learns every sample: input ``[x, ŷ]`` and target ``y − ŷ`` with the a-priori ŷ each sample had. (Tried
    on the paper-preset iCub bags: the ŷ of the rigid body at the warm-up's end instead gives SP/NP over
    the first 3 s 1.02 / 0.81 (force / torque) against 0.92 / 0.95; neither dominates, and these targets
    are the paper's.)

    Example:
        >>> import numpy as np
        >>> line = lambda x: np.array([[x[0], 1.0]])  # rigid part y = a·x + b
        >>> model = SemiparametricModel(line, 2, 1, 1, lam_parametric=1e-9, lam_nonparametric=1e-3,
        ...                             n_features=300, sigma=1.0)
        >>> for x in np.linspace(-1.0, 1.0, 400):
        ...     _ = model.predict_learn_one([x], [3.0 * x + 1.0 + 0.2 * np.sin(3.0 * x)])
        >>> pred = model.predict_one([0.3])
        >>> bool(np.allclose(pred.total, pred.parametric + pred.residual))
        True
        >>> truth = 1.9 + 0.2 * np.sin(0.9)
        >>> bool(abs(pred.total[0] - truth) < 0.25 * abs(pred.parametric[0] - truth))  # the residual helps
        True
    """

    _kind = "semiparametric"
    _YHAT_STATISTICS = ("measured", "predicted")

    def __init__(self, regressor: Regressor, n_params: int, n_inputs: int, n_outputs: int, *,
                 lam_parametric: float = 1.0, lam_nonparametric: float = 1.0, n_features: int = 500,
                 sigma: float = 1.0, forgetting_parametric: float = 1.0,
                 forgetting_nonparametric: float = 1.0, seed: int = 0,
                 standardizer: Standardizer | None = None, standardizer_warmup: int = 0,
                 standardizer_min_scale: Any = 0.0, yhat_statistics: str = "measured",
                 prior: Any = None) -> None:
        if yhat_statistics not in self._YHAT_STATISTICS:
            raise ConfigurationError(f"yhat_statistics must be one of {self._YHAT_STATISTICS}, "
                             f"got {yhat_statistics!r}")
        self.yhat_statistics = yhat_statistics
        self.parametric = ParametricModel(regressor, n_params, n_outputs, lam=lam_parametric,
                                          forgetting=forgetting_parametric, prior=prior)
        self.nonparametric = NonparametricModel(int(n_inputs) + int(n_outputs), n_outputs,
                                                n_features=n_features, sigma=sigma, lam=lam_nonparametric,
                                                forgetting=forgetting_nonparametric, seed=seed,
                                                standardizer=standardizer,
                                                standardizer_warmup=standardizer_warmup,
                                                standardizer_min_scale=standardizer_min_scale)
        self.n_inputs = int(n_inputs)
        self.n_outputs = int(n_outputs)
        self.n_samples_seen = 0

    def predict_one(self, x: Any, *, return_variance: bool = False) -> Prediction:
        """Predict ``ŷ + Δŷ`` with both parts.

        Raises:
            RejectedSampleError: Bad x or regressor output.
        """
        xv, _, Phi = self._check(x)
        yp, var_p = self.parametric.predict_phi(Phi, return_variance)
        r, var_np = self.nonparametric.predict_input(np.concatenate([xv, yp]), return_variance)
        var = None
        if var_p is not None:
            assert var_np is not None  # _predict computes it when asked
            # NaN while the residual stage warms up (it predicts 0 then): it adds no variance
            var = var_p + var_np if self.nonparametric.standardizer.ready else var_p
        return Prediction(yp, r, yp + r, var)

    def predict_ahead_checked(self, xv: np.ndarray) -> PredictionContext:
        """Do :meth:`predict_ahead` for an input already checked (finite, the model's shape) and copied."""
        par, npm = self.parametric, self.nonparametric
        Phi = par.phi_fresh(xv)
        yp, var = par.predict_phi(Phi, True)
        assert var is not None  # asked for
        if npm.standardizer.ready:
            phi = npm.features_of(np.concatenate([xv, yp]))
            P, v = npm.rls.predict_checked(phi, True)
            assert v is not None  # asked for
            r = P[0]
            var = var + float(v[0])
        else:
            phi, r = None, np.zeros(self.n_outputs)  # the warm-up predicts 0 and adds no variance
        return PredictionContext(Prediction(yp, r, yp + r, var), self, xv, Phi, phi)

    def learn_ahead_checked(self, context: PredictionContext, yv: np.ndarray) -> None:
        """Do :meth:`learn_ahead` for an output already checked (finite, ``n_outputs`` values)."""
        # learn_one's _learn with the regressor, ŷ and features of the prediction; both stages' rows are
        # checked before either learner changes, so a refused value leaves the model as it was
        par, npm = self.parametric, self.nonparametric
        Phi, phi = self._take(context).Phi, context.phi
        assert Phi is not None  # a two-stage context always holds the regressor
        yp = context.prediction.parametric
        y0 = par.prior_output(Phi)
        # Φ (also cached by the parametric stage), φ and the targets below are read-only from here on: owned
        target = yv.copy() if y0 is None else yv - y0
        par_step = par.rls.checked_step(Phi, target.reshape(-1, 1), owned=True)
        if phi is None:
            # warm-up (see _learn and the class docstring for the ŷ block's statistics)
            xv = context.x
            measured = self.yhat_statistics == "measured"
            npm.hold_warmup(np.concatenate([xv, yv if measured else yp]), np.concatenate([xv, yp]), yv - yp)
            par.rls.defer_step(par_step)
            npm.learn_held()
        else:
            np_step = npm.rls.checked_step(phi, (yv - yp).reshape(1, -1), owned=True)
            par.rls.defer_step(par_step)
            npm.rls.defer_step(np_step)
        par.n_samples_seen += 1
        npm.n_samples_seen += 1
        self.n_samples_seen += 1

    def _learn(self, x: Any, y: Any, want_prediction: bool) -> Prediction | None:
        xv, yv, Phi = self._check(x, y)
        assert yv is not None
        yp = self.parametric.predict_update_phi(Phi, yv)
        self.parametric.n_samples_seen += 1
        npm = self.nonparametric
        if not npm.standardizer.ready and self.yhat_statistics == "measured":
            # warm-up: the ŷ block takes the statistics of the measured y (see the class docstring)
            npm.hold_warmup(np.concatenate([xv, yv]), np.concatenate([xv, yp]), yv - yp)
            npm.learn_held()
            r = np.zeros(self.n_outputs)
        else:
            r = npm.learn_input(np.concatenate([xv, yp]), yv - yp, want_prediction)
        self.nonparametric.n_samples_seen += 1
        self.n_samples_seen += 1
        return Prediction(yp, r, yp + r) if want_prediction else None
