"""Diagnostic learner variants, used to explain results (not models a robot should run).

:class:`FrozenParametricSP` is the semiparametric learner whose rigid-body stage stops learning after a
given number of samples (the training stream), while its residual stage keeps learning. Comparing it with
the plain SP learner on the paper's protocol isolates the effect of the parametric stage's drift during the
test parts: SP's residual learns ``y − ŷ`` against a ŷ that keeps changing while the rigid-body stage keeps
learning, whereas the residual of the frozen variant has a stationary target, like NP's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from semiparam_ros.core.estimator.build import traits_of
from semiparam_ros.core.learners.cascade import SemiparametricModel
from semiparam_ros.core.learners.contract import Prediction

__all__ = ["FrozenParametricSP"]


class FrozenParametricSP:
    """A semiparametric learner whose rigid-body stage learns only its first ``learn_parametric_for`` samples.

    Wraps a :class:`~semiparam_ros.core.learners.cascade.SemiparametricModel`. Before the limit it
    behaves exactly like the wrapped model (``predict_learn_one`` of both stages). Afterwards the rigid-body
    stage only predicts ``ŷ = Φ(x) π̂`` and the residual stage predicts and learns ``y − ŷ`` from ``[x, ŷ]``
    as in the wrapped model.

    Args:
        model: The semiparametric learner (owned by the wrapper).
        learn_parametric_for: Number of samples the rigid-body stage learns (e.g. the training stream).

    Raises:
        ValueError: If ``model`` is not semiparametric or the count is negative.
    """

    def __init__(self, model: SemiparametricModel, learn_parametric_for: int) -> None:
        if traits_of(model).combination != "cascade":
            raise ValueError("FrozenParametricSP wraps a SemiparametricModel (the cascade)")
        if learn_parametric_for < 0:
            raise ValueError(f"learn_parametric_for must be >= 0, got {learn_parametric_for}")
        self.model = model
        self.learn_parametric_for = int(learn_parametric_for)
        self.n_samples_seen = 0

    def predict_learn_one(self, x: Any, y: Any) -> Prediction:
        """A-priori prediction of both stages, then learn (the rigid-body stage only while not frozen).

        Args:
            x: Input ``[q, dq, ddq]`` (rad, rad/s, rad/s²).
            y: Measured output (N, N·m).

        Returns:
            The a-priori prediction.
        """
        if self.n_samples_seen < self.learn_parametric_for:
            out = self.model.predict_learn_one(x, y)
        else:
            xv = np.asarray(x, dtype=np.float64)
            yv = np.asarray(y, dtype=np.float64)
            yp = self.model.parametric.predict_one(xv).total
            residual = self.model.nonparametric.predict_learn_one(np.concatenate([xv, yp]), yv - yp).total
            out = Prediction(yp, residual, yp + residual)
        self.n_samples_seen += 1
        return out

    def predict_one(self, x: Any) -> Prediction:
        """Predict both stages at x (the rigid-body stage as it is now, frozen or not)."""
        return self.model.predict_one(x)

    def learn_one(self, x: Any, y: Any) -> None:
        """Learn (x, y) as :meth:`predict_learn_one` does, dropping the prediction."""
        self.predict_learn_one(x, y)

    def copy(self) -> FrozenParametricSP:
        """Independent deep copy (same freezing point and sample count)."""
        clone = FrozenParametricSP(self.model.copy(), self.learn_parametric_for)
        clone.n_samples_seen = self.n_samples_seen
        return clone
