"""The learner contract: what the estimator, adaptation and the semiparametric combinations need of a learner.

The narrow contract is :class:`OnlineModel`: predict, learn, copy. Every model of the project satisfies
it — the learners (:mod:`~semiparam_ros.core.learners.parametric` P,
:mod:`~semiparam_ros.core.learners.nonparametric` NP, and the SP combinations
:mod:`~semiparam_ros.core.learners.cascade`, :mod:`~semiparam_ros.core.learners.joint` and
:mod:`~semiparam_ros.core.learners.consistent`) and the evaluation's reference models — and
``test/core/learners/test_contract.py`` runs the same behavioural checks over all of them. On top, a
learner the estimator runs has three facets: :class:`StreamingModel` (predict now, decide, then learn:
``predict_ahead`` keeps a :class:`PredictionContext` that ``learn_ahead`` consumes), :class:`AdaptiveModel`
(the sample period and forgetting) and :class:`CheckpointModel` (its state as named arrays);
:class:`Learner` is the three together. :class:`RigidBodyUser` is the facet of the models that predict
with one rigid body a consistent projection can replace.

**The sample period.** A learner is told the measured sample period once, by :meth:`Learner.on_period`,
and converts there what its configuration gives in seconds (:class:`PeriodSettings`): the forgetting of
its adaptive stages (β = exp(−T/τ)), the standardizer warm-up and, for the consistent model, the fast
correction's memory. Until then it runs with its per-sample factors. ``on_period`` is idempotent: telling
the same period again changes nothing, and a restored checkpoint is told the current one.

The stages of a semiparametric model talk to each other through the public methods of
:class:`~semiparam_ros.core.learners.parametric.ParametricModel` (``phi_fresh``, ``predict_phi``,
``prior_output``, …), :class:`~semiparam_ros.core.learners.nonparametric.NonparametricModel`
(``features_of``, ``predict_input``, ``learn_input``) and
:class:`~semiparam_ros.core.learners.rrls.RecursiveRLS` (``predict(..., checked=True)``,
``checked_step``, ``defer_step``, …): ``checked=True`` and the ``*_checked`` methods take inputs the
caller already validated (finite, the right shape), so a combination validates once.

Units: ``x = [q, q̇, q̈]`` (rad, rad/s, rad/s²); ``y`` a wrench (N, N·m, sensor frame) or joint torques (N·m).

>>> from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
>>> from semiparam_ros.core.estimator.online import OnlineEstimator
>>> model = OnlineEstimator(EstimatorConfig.from_flat(ICUB_RIGHT_ARM)).model
>>> isinstance(model, Learner), [rls.n_features for rls in model.adaptive_stages()]
(True, [17, 500])
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from semiparam_ros.core.learners.rrls import RecursiveRLS

__all__ = [
    "AdaptiveModel",
    "CheckpointModel",
    "Learner",
    "OnlineModel",
    "PeriodSettings",
    "Prediction",
    "PredictionContext",
    "RigidBodyUser",
    "StreamingModel",
]


@dataclass(frozen=True)
class Prediction:
    """One prediction, split into its parts (each (t,), units of y).

    Attributes:
        parametric: Rigid-body part ``ŷ = Φ(x) π̂`` (zeros for the NP model).
        residual: Learned residual ``Δŷ`` (zeros for the P model, and for NP/SP during the warm-up).
        total: ``ŷ + Δŷ``.
        variance: Optional relative predictive variance per output, ``z A⁻¹ zᵀ`` summed over the stages
            (multiply by the noise variance of y in its units²); None unless requested.
        correction: The fast error tracker's part of ``residual`` (units of y), for a model that has one
            (:mod:`semiparam_ros.core.learners.consistent`): ``total − correction`` is the model's
            prediction from the state alone. None for the others.
    """

    parametric: np.ndarray
    residual: np.ndarray
    total: np.ndarray
    variance: np.ndarray | None = None
    correction: np.ndarray | None = None


class PredictionContext:
    """An a-priori prediction together with what learning the same sample needs.

    Made by a model's ``predict_ahead(x)`` and consumed by the same model's ``learn_ahead(context, y)``;
    it is only valid while the model has learned nothing else (checked: a stale or consumed context is
    a programming error, :class:`ValueError`).

    Attributes:
        prediction: The prediction of ``predict_one(x, return_variance=True)``, its ``variance`` the
            relative predictive variance ``v ≥ 0`` per output (a residual stage still in its standardizer
            warm-up counts 0, as in :func:`~semiparam_ros.core.learners.uncertainty.predict_with_variance`).
    """

    __slots__ = ("Phi", "model", "phi", "prediction", "seen", "x")

    def __init__(self, prediction: Prediction, model: Any, x: np.ndarray, Phi: np.ndarray | None,
                 phi: np.ndarray | None) -> None:
        self.prediction = prediction
        self.model: object | None = model  # the learner that made it (None once consumed)
        self.seen = model.n_samples_seen
        self.x = x  # validated input (of the model)
        self.Phi = Phi  # rigid-body regressor rows (t, p), or None (NP)
        self.phi = phi  # random features (1, D), or None (P, or a residual stage in its warm-up)


@dataclass(frozen=True)
class PeriodSettings:
    """What a learner converts at the measured sample period (:meth:`Learner.on_period`).

    Attributes:
        time_constant_s: τ [s] of the adaptive stages' forgetting, β = exp(−T/τ); 0 keeps the per-sample
            factors the learner was built with.
        standardizer_warmup_s: The residual standardizer's warm-up [s] (converted to samples, if the
            warm-up is still running); ``None`` when it is given in samples.
    """

    time_constant_s: float = 0.0
    standardizer_warmup_s: float | None = None


@runtime_checkable
class OnlineModel(Protocol):
    """The narrow contract: predict, learn, copy (every learner and every evaluation model).

    The evaluation protocol, the horizon table and the reference models of ``semiparam_ros.eval`` need
    no more of a model; ``test/core/learners/test_contract.py`` runs the same checks over all of them.
    """

    def predict_one(self, x: Any) -> Prediction:
        """Predict y at x (units of y)."""
        ...

    def learn_one(self, x: Any, y: Any) -> None:
        """Learn one sample (x, y)."""
        ...

    def predict_learn_one(self, x: Any, y: Any) -> Prediction:
        """Predict y at x a priori, then learn (x, y); returns the prediction."""
        ...

    def copy(self) -> Any:
        """Return an independent copy: learning one changes nothing in the other."""
        ...


@runtime_checkable
class StreamingModel(OnlineModel, Protocol):
    """The facet the estimator's per-sample step uses: predict now, decide (the contact gate), then learn.

    Attributes:
        n_outputs: Length of y.
        n_samples_seen: Samples learned so far (a prediction context is valid only while it is unchanged).
        prediction_age_s: Age [s] of the learned state at the predictions that follow, beyond one sample
            period (0 = the previous sample was learned; set by the estimator from the stamps).
    """

    n_outputs: int
    n_samples_seen: int
    prediction_age_s: float

    def predict_one(self, x: Any, *, return_variance: bool = False) -> Prediction:
        """Predict y at x; with ``return_variance`` the relative predictive variance per output."""
        ...

    def predict_ahead(self, x: Any) -> PredictionContext:
        """Predict x with its variance and keep what learning x needs (a prediction context)."""
        ...

    def learn_ahead(self, context: PredictionContext, y: Any) -> None:
        """Learn y for the input of this model's last context."""
        ...

    def predict_held(self, x: Any) -> Prediction:
        """Predict x cheaply for a sample that will not be learned."""
        ...

    def has_pending(self) -> bool:
        """Tell whether a learner holds a deferred update."""
        ...

    def apply_pending(self) -> bool:
        """Apply deferred updates now; returns whether any was pending."""
        ...


@runtime_checkable
class AdaptiveModel(Protocol):
    """The facet of the sample period and forgetting (see the module docstring).

    Attributes:
        period_settings: What :meth:`on_period` converts.
        sample_period_s: The period [s] last announced by :meth:`on_period` (None before).
    """

    period_settings: PeriodSettings
    sample_period_s: float | None

    def on_period(self, sample_period_s: float) -> float | None:
        """Take the measured sample period T [s]; returns the adaptive stages' β if τ set it."""
        ...

    def rls_stages(self) -> tuple[RecursiveRLS, ...]:
        """Return every recursive least-squares learner holding this model's state."""
        ...

    def adaptive_stages(self) -> tuple[RecursiveRLS, ...]:
        """Return the learners whose forgetting ``adaptation.time_constant`` sets (parametric stage first)."""
        ...

    def set_standardizer_warmup(self, warmup: int) -> None:
        """Set the residual standardizer's warm-up [samples] if it is still running."""
        ...


@runtime_checkable
class CheckpointModel(Protocol):
    """The facet of persistence: the learned state as named arrays, and forgetting it."""

    def reset(self) -> None:
        """Forget everything learned."""
        ...

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the learned state as named arrays (checkpoints)."""
        ...

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Restore the state written by :meth:`state_dict`."""
        ...

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the learned state to one ``.npz`` file atomically."""
        ...


@runtime_checkable
class Learner(StreamingModel, AdaptiveModel, CheckpointModel, Protocol):
    """A learner the estimator runs: the narrow contract with its streaming, adaptive and checkpoint facets.

    Every learner :func:`~semiparam_ros.core.estimator.build.build_model` makes satisfies it (the type
    checker holds them to it through :data:`semiparam_ros.core.estimator.build.Model`).
    """


@runtime_checkable
class RigidBodyUser(Protocol):
    """The facet of a learner that predicts with one rigid body a consistent projection can replace.

    P and the consistent SP (``ModelTraits.takes_rigid``): ``use_rigid(θ)`` makes the predictions use θ
    (learner units) instead of the learned π̂ until ``use_rigid(None)``.
    """

    def use_rigid(self, rigid: np.ndarray | None) -> None:
        """Predict with ``rigid`` (learner units) from now on; None: the learned parameters again."""
        ...

    @property
    def rigid_override(self) -> np.ndarray | None:
        """The rigid body set by :meth:`use_rigid`, or None."""
        ...
