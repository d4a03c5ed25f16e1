"""The random-feature learner NP of Camoriano et al. (ICRA 2016): ``ỹ = φ(s(x)) W``.

:class:`NonparametricModel` — kernel regression with random Fourier features of the standardized input
(the standardizer's warm-up held and learned once its statistics are ready).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from semiparam_ros.core.learners._kernels import within
from semiparam_ros.core.learners._step_kernels import standardized_features
from semiparam_ros.core.learners.base import LearnerBase
from semiparam_ros.core.learners.contract import Prediction, PredictionContext
from semiparam_ros.core.learners.features import RandomFourierFeatures, Standardizer
from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.core.validation import MAX_ABS_INPUT, check_finite_array, check_positive_int
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError

__all__ = ["NonparametricModel", "make_standardizer"]


class NonparametricModel(LearnerBase):
    """Random-feature kernel ridge regression of y on the standardized input.

    Args:
        n_inputs: Length of x.
        n_outputs: t, length of y.
        n_features: D, number of random Fourier features.
        sigma: Gaussian kernel width σ in standardized input units.
        lam: Ridge regularizer λ > 0.
        forgetting: β ∈ (0, 1] per sample (prior-keeping, see ``core.learners.rrls``).
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
        self.standardizer = make_standardizer(self.n_inputs, standardizer, standardizer_warmup,
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
        P, v = (self.rls.predict(phi, return_variance=True, checked=True) if return_variance
                else (self.rls.predict(phi, checked=True), None))
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
            return self.rls.predict_update(phi, target.reshape(1, -1), checked=True)[0]
        self.rls.update(phi, target.reshape(1, -1), checked=True)
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
            P, v = self.rls.predict(phi, return_variance=True, checked=True)
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
            self.rls.update(phi, yv.reshape(1, -1), checked=True)
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
        try:  # the held warm-up rows
            held_x = np.asarray(state[f"{prefix}held_x"], dtype=np.float64)
            held_y = np.asarray(state[f"{prefix}held_y"], dtype=np.float64)
        except KeyError as err:
            raise CheckpointError(f"state is missing key {err}") from err
        k = held_x.shape[0] if held_x.ndim == 2 else -1
        if (held_x.shape != (k, self.n_inputs) or held_y.shape != (k, self.n_outputs)
                or k > max(std.count_, 0)
                or not (within(held_x, MAX_ABS_INPUT) and within(held_y, MAX_ABS_INPUT))):
            raise CheckpointError("the held warm-up rows have the wrong size or invalid values")
        self.rff, self.standardizer, self.rls, self.n_samples_seen = rff, std, rls, n_seen
        self._initial_standardizer = std0
        self._held_x, self._held_y = list(held_x), list(held_y)


def make_standardizer(n_inputs: int, standardizer: Standardizer | None, warmup: int,
                       min_scale: Any = 0.0) -> Standardizer:
    """Return the given input standardizer (checked against ``n_inputs``) or a new one with ``warmup``."""
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
