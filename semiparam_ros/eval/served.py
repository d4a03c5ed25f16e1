"""The model a user is served, as an evaluation's frozen row: learned by the node's estimator, saved, loaded.

An evaluation that trains its own learners and scores their ``predict_model`` scores another model than
the one a user gets: the node and ``learn`` run every sample through :class:`OnlineEstimator` (the contact
gate, σ, the rate meter, the learners' memory converted at the measured period), write a checkpoint, and
``load_model(...).predict`` serves it with the physically consistent rigid body where
``parametric.consistent`` is on. :func:`learn_served` does exactly that from a stream of samples (the
samples the node's pipeline made from a bag: :func:`~semiparam_ros.eval.replay.load_samples`), and
:class:`ServedModel` presents the loaded model to the protocol and the horizon table as a frozen model,
so that a frozen row *is* ``learn`` → checkpoint → ``load_model(...).predict`` on the test states.

Units: x = [q, q̇, q̈] (rad, rad/s, rad/s²); predictions in the units of y (N·m for joint torques, N and
N·m for a wrench).
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.learners.contract import Prediction
from semiparam_ros.core.stream.messages import Sample
from semiparam_ros.errors import RejectedSampleError
from semiparam_ros.eval.protocol import SampleArrays
from semiparam_ros.service.serving import LearnedModel, load_model

__all__ = ["SERVED_COMBINATIONS", "ServedModel", "learn_served", "served_model"]

#: The evaluation's model names served by the node's learner kinds: ``(kind, semiparametric.combination or
#: None for the configuration's)``; the paper's cascade ``SPC`` and the joint fit ``SPJ`` are SP learners.
SERVED_COMBINATIONS: dict[str, tuple[str, str | None]] = {
    "P": ("P", None), "NP": ("NP", None), "SP": ("SP", None),
    "SPC": ("SP", "cascade"), "SPJ": ("SP", "joint"),
}


def learn_served(config: EstimatorConfig, train: SampleArrays, *, kind: str = "SP") -> LearnedModel:
    """Learn a stream as the node does, write the checkpoint and load it back as a user would.

    Every sample goes through :meth:`OnlineEstimator.step` with learning on (the gate, the noise estimate
    and the rate meter as configured); a sample the learner rejects is skipped, as the node counts it.

    Args:
        config: The estimator's configuration.
        train: The samples, in stream order (stamps in ns).
        kind: ``"P"``, ``"NP"`` or ``"SP"``.

    Returns:
        ``load_model`` of the checkpoint the estimator wrote.

    Raises:
        ConfigurationError: An invalid configuration.
    """
    est = OnlineEstimator(config, kind=kind)  # type: ignore[arg-type]  # checked by build_model
    est.learning_enabled = True
    n = train.X.shape[1] // 3
    for stamp, x, y in zip(train.stamps_ns, train.X, train.Y, strict=True):
        try:
            est.step(Sample(int(stamp), x[:n], x[n:2 * n], x[2 * n:], y))
        except RejectedSampleError:
            continue
    with tempfile.TemporaryDirectory(prefix="semiparam-served-") as folder:
        path = Path(folder) / "model.npz"
        est.save(path)
        return load_model(path)


def served_model(config: EstimatorConfig, name: str, train: SampleArrays) -> ServedModel | None:
    """Learn the served model of an evaluation's model name (:data:`SERVED_COMBINATIONS`), or ``None``.

    Args:
        config: The estimator's configuration.
        name: ``P``, ``NP``, ``SP``, ``SPC`` or ``SPJ`` (other names, e.g. diagnostics, have none).
        train: The training stream.

    Returns:
        :class:`ServedModel` of :func:`learn_served`, or ``None``.

    Raises:
        ConfigurationError: A configuration the combination does not allow (e.g. ``SPJ`` with two
            different forgetting factors).
    """
    if name not in SERVED_COMBINATIONS:
        return None
    kind, combination = SERVED_COMBINATIONS[name]
    if combination is not None:
        config = config.with_overrides({"semiparametric.combination": combination})
    return ServedModel(learn_served(config, train, kind=kind))


class ServedModel:
    """A loaded model presented as a frozen model: ``predict_model(x)`` is ``served.predict`` at x.

    It never learns (``learn_one`` raises): put it in the protocol's ``frozen`` and ``trained`` names and
    in the horizon table's frozen column only.

    Args:
        served: The model, e.g. from :func:`learn_served` or
            :func:`~semiparam_ros.service.serving.load_model`.

    """

    def __init__(self, served: LearnedModel) -> None:
        self.served = served
        self._n = len(served.joints)

    def predict_model(self, x: Any) -> np.ndarray:
        """Return the served model at one state x = [q, q̇, q̈] (t,)."""
        xv = np.asarray(x, dtype=np.float64)
        n = self._n
        return self.served.predict(xv[:n], xv[n:2 * n], xv[2 * n:])[0]

    predict_one = predict_model

    def predict_parts(self, x: Any) -> Prediction:
        """Return the served model's parts at x (total, rigid-body part, residual; no variance)."""
        xv = np.asarray(x, dtype=np.float64)
        n = self._n
        parts = self.served.predict_parts(xv[:n], xv[n:2 * n], xv[2 * n:])
        return Prediction(parts.rigid_body, parts.residual, parts.total, None)

    def predict_many(self, X: Any) -> np.ndarray:
        """Return the served model at N states (N, 3n) → (N, t), in one call."""
        X2 = np.asarray(X, dtype=np.float64)
        n = self._n
        return self.served.predict(X2[:, :n], X2[:, n:2 * n], X2[:, 2 * n:])[0]

    def learn_one(self, x: Any, y: Any) -> None:
        """Refuse: a served model is frozen."""
        raise TypeError("a served model does not learn: evaluate it frozen")

    predict_learn_one = learn_one

    def copy(self) -> ServedModel:
        """Return itself (it never changes)."""
        return self
