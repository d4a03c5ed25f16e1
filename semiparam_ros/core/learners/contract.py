"""The learner contract: what the estimator, adaptation and the semiparametric combinations need of a learner.

Every learner of :mod:`semiparam_ros.core.learners.semiparametric` (P, NP, the cascade SP),
:mod:`~semiparam_ros.core.learners.joint` (SPJ) and :mod:`~semiparam_ros.core.learners.consistent`
(the consistent SP) satisfies :class:`Learner`; the type checker holds them to it
(:data:`semiparam_ros.core.estimator.build.Model`). The stages of a semiparametric model talk to each other
through
the public methods of :class:`~semiparam_ros.core.learners.semiparametric.ParametricModel` (``phi_fresh``,
``predict_phi``, ``prior_output``, …), :class:`~semiparam_ros.core.learners.semiparametric.NonparametricModel`
(``features_of``, ``predict_input``, ``learn_input``) and
:class:`~semiparam_ros.core.learners.rrls.RecursiveRLS`
(``predict_checked``, ``checked_step``, ``defer_step``, …): the ``*_checked`` methods take inputs the
caller already validated (finite, the right shape), so a combination validates once.

Units: ``x = [q, q̇, q̈]`` (rad, rad/s, rad/s²); ``y`` a wrench (N, N·m, sensor frame) or joint torques (N·m).

>>> from semiparam_ros.core.config import EstimatorConfig
>>> from semiparam_ros.core.estimator.online import OnlineEstimator
>>> model = OnlineEstimator(EstimatorConfig.defaults()).model
>>> isinstance(model, Learner), [rls.n_features for rls in model.adaptive_stages()]
(True, [32, 500])
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from semiparam_ros.core.learners.rrls import RecursiveRLS

__all__ = ["Learner"]


@runtime_checkable
class Learner(Protocol):
    """An online learner of ``y = f(x)`` (see the module docstring).

    Attributes:
        n_outputs: Length of y.
        n_samples_seen: Samples learned so far (a prediction context is valid only while it is unchanged).
    """

    n_outputs: int
    n_samples_seen: int

    def predict_one(self, x: Any, *, return_variance: bool = False) -> Any:
        """Predict y at x (a :class:`~semiparam_ros.core.learners.semiparametric.Prediction`)."""
        ...

    def learn_one(self, x: Any, y: Any) -> None:
        """Learn one sample."""
        ...

    def predict_learn_one(self, x: Any, y: Any) -> Any:
        """Predict y at x a priori, then learn (x, y); returns the prediction."""
        ...

    def predict_ahead(self, x: Any) -> Any:
        """Predict x with its variance and keep what learning x needs (a prediction context)."""
        ...

    def learn_ahead(self, context: Any, y: Any) -> None:
        """Learn y for the input of this model's last context."""
        ...

    def predict_held(self, x: Any) -> Any:
        """Predict x cheaply for a sample that will not be learned."""
        ...

    def has_pending(self) -> bool:
        """Tell whether a learner holds a deferred update."""
        ...

    def apply_pending(self) -> bool:
        """Apply deferred updates now; returns whether any was pending."""
        ...

    def rls_stages(self) -> tuple[RecursiveRLS, ...]:
        """Return every recursive least-squares learner holding this model's state."""
        ...

    def adaptive_stages(self) -> tuple[RecursiveRLS, ...]:
        """Return the learners whose forgetting ``adaptation.time_constant`` sets (parametric stage first)."""
        ...

    def reset(self) -> None:
        """Forget everything learned."""
        ...

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the learned state as named arrays (checkpoints)."""
        ...

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Restore the state written by :meth:`state_dict`."""
        ...
