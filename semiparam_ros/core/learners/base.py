"""What every learner shares: learning one sample, the sample period, persistence.

:class:`LearnerBase` is the base of the rigid-body learner (:mod:`~semiparam_ros.core.learners.parametric`),
the random-feature learner (:mod:`~semiparam_ros.core.learners.nonparametric`) and the semiparametric
combinations (:mod:`~semiparam_ros.core.learners.two_stage`); it implements the checkpoint facet of the
contract (:mod:`~semiparam_ros.core.learners.contract`) once. Common interface (river-style online
learning): ``predict_one(x) -> Prediction``, ``learn_one(x, y)``, ``predict_learn_one(x, y)``,
``n_samples_seen``, ``copy()``, ``reset()``, ``state_dict(prefix)`` / ``load_state_dict(state, prefix)``,
``save(path)`` / ``load(path)`` (an instance method: the regressor callable cannot be stored, so a
checkpoint is loaded into a model built with the same regressor).

Predict now, decide, then learn (the contact gate's order): ``predict_ahead(x) -> PredictionContext`` is
``predict_one(x, return_variance=True)`` that also keeps what it computed on the way, and
``learn_ahead(context, y)`` learns (x, y) from exactly those.

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
from semiparam_ros.core.learners.adaptation import forgetting_factor
from semiparam_ros.core.learners.contract import PeriodSettings, Prediction, PredictionContext
from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.core.stream.rate import samples_in
from semiparam_ros.core.validation import check_finite_array
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError

__all__ = ["LearnerBase", "Regressor", "checked_rigid"]


Regressor = Callable[[np.ndarray], np.ndarray]


class LearnerBase:
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
            >>> from semiparam_ros.core.learners.nonparametric import NonparametricModel
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
        """Set the residual standardizer's warm-up [samples] if it is still running."""
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
        """``predict_ahead`` of an input the caller already validated."""
        raise NotImplementedError

    def learn_ahead_checked(self, context: PredictionContext, yv: np.ndarray) -> None:  # pragma: no cover
        """``learn_ahead`` of an output the caller already validated."""
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
        """Return the learned state as named arrays (checkpoints)."""
        raise NotImplementedError

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:  # pragma: no cover
        """Restore the state written by :meth:`state_dict`."""
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
