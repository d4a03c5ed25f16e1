"""The model a user is served, as an evaluation's frozen row: learned by the node's estimator, saved, loaded.

An evaluation that trains its own learners and scores their ``predict_model`` scores another model than
the one a user gets: the node and ``learn`` run every sample through :class:`OnlineEstimator` (the contact
gate, σ, the rate meter, the learners' memory converted at the measured period), write a checkpoint, and
``load_model(...).predict`` serves it with the physically consistent rigid body where
``parametric.consistent`` is on. :func:`learn_served` does exactly that from a stream of samples (the
samples the node's pipeline made from a bag: :func:`~semiparam_ros.eval.bags.replay.load_samples`), and
:class:`ServedModel` presents the loaded model to the protocol and the horizon table as a frozen model,
so that a frozen row *is* ``learn`` → checkpoint → ``load_model(...).predict`` on the test states.

Units: x = [q, q̇, q̈] (rad, rad/s, rad/s²); predictions in the units of y (N·m for joint torques, N and
N·m for a wrench).
"""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.learners.contract import Prediction
from semiparam_ros.core.learners.stick import StickState, with_held
from semiparam_ros.core.stream.messages import Sample
from semiparam_ros.errors import RejectedSampleError
from semiparam_ros.eval.protocol.options import CASCADE_SP, JOINT_SP
from semiparam_ros.eval.protocol.prequential import SampleArrays
from semiparam_ros.serving.learned_model import LearnedModel, load_model

__all__ = ["SERVED_COMBINATIONS", "NodeLearner", "ServedModel", "learn_served", "node_learner", "serve",
           "served_model"]

#: The evaluation's model names served by the node's learner kinds: ``(kind, semiparametric.combination or
#: None for the configuration's)``; the paper's cascade ``SPC`` and the joint fit ``SPJ`` are SP learners.
SERVED_COMBINATIONS: dict[str, tuple[str, str | None]] = {
    "P": ("P", None), "NP": ("NP", None), "SP": ("SP", None),
    CASCADE_SP: ("SP", "cascade"), JOINT_SP: ("SP", "joint"),
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
    node = NodeLearner(OnlineEstimator(config, kind=kind))  # type: ignore[arg-type]  # checked by build
    for stamp, x, y in zip(train.stamps_ns, train.X, train.Y, strict=True):
        try:
            node.learn_one(x, y, stamp_ns=int(stamp))
        except RejectedSampleError:
            continue
    return serve(node.estimator)


def serve(estimator: OnlineEstimator) -> LearnedModel:
    """Write the estimator's checkpoint and load it back with ``load_model``, as a user would.

    Args:
        estimator: A learned estimator (e.g. a trained :class:`NodeLearner`'s).

    Returns:
        The served model.
    """
    with tempfile.TemporaryDirectory(prefix="semiparam-served-") as folder:
        path = Path(folder) / "model.npz"
        estimator.save(path)
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
    config, kind = _with_combination(config, name)
    return ServedModel(learn_served(config, train, kind=kind))


class ServedModel:
    """A loaded model presented as a frozen model: ``predict_model(x)`` is ``served.predict`` at x.

    It never learns (``learn_one`` raises): put it in the protocol's ``frozen`` and ``trained`` names and
    in the horizon table's frozen column only. Consecutive ``predict_model`` calls are one path (a test
    stream, one sample at a time): friction that remembers carries its stick state from one to the next,
    from where the training path left it; ``predict_many`` is a path of its own from there.

    Args:
        served: The model, e.g. from :func:`learn_served` or
            :func:`~semiparam_ros.serving.learned_model.load_model`.

    """

    def __init__(self, served: LearnedModel) -> None:
        self.served = served
        self._n = len(served.joints)
        self._history = served.stick_state()

    def predict_model(self, x: Any) -> np.ndarray:
        """Return the served model at one state x = [q, q̇, q̈] (t,)."""
        xv = np.asarray(x, dtype=np.float64)
        n = self._n
        return self.served.predict_parts(xv[:n], xv[n:2 * n], xv[2 * n:], history=self._history).total

    predict_one = predict_model

    def predict_many(self, X: Any) -> np.ndarray:
        """Return the served model at N states (N, 3n) → (N, t), in one call."""
        X2 = np.asarray(X, dtype=np.float64)
        n = self._n
        return self.served.predict(X2[:, :n], X2[:, n:2 * n], X2[:, 2 * n:])[0]

    def coverage(self, X: Any, Y: Any, k: float = 2.0) -> np.ndarray:
        """Fraction of the errors within ±kσ of the served prediction, per output (σ as served).

        Args:
            X: (N, 3n) states ``[q, q̇, q̈]`` [rad, rad/s, rad/s²].
            Y: (N, t) measured outputs (units of y).
            k: Width in standard deviations.

        Returns:
            (t,) fractions in [0, 1].
        """
        X2 = np.asarray(X, dtype=np.float64)
        n = self._n
        total, std = self.served.predict(X2[:, :n], X2[:, n:2 * n], X2[:, 2 * n:])
        return np.asarray(np.mean(np.abs(np.asarray(Y, dtype=np.float64) - total) <= k * std, axis=0))

    def learn_one(self, x: Any, y: Any) -> None:
        """Refuse: a served model is frozen."""
        raise TypeError("a served model does not learn: evaluate it frozen")

    predict_learn_one = learn_one

    def copy(self) -> ServedModel:
        """Return itself (it never changes)."""
        return self


def _with_combination(config: EstimatorConfig, name: str) -> tuple[EstimatorConfig, str]:
    kind, combination = SERVED_COMBINATIONS[name]
    if combination is not None:
        config = config.with_overrides({"semiparametric.combination": combination})
    return config, kind


def node_learner(config: EstimatorConfig, name: str) -> NodeLearner | None:
    """Build a fresh :class:`NodeLearner` of an evaluation's model name, or ``None`` for another name.

    Args:
        config: The estimator's configuration.
        name: ``P``, ``NP``, ``SP``, ``SPC`` or ``SPJ``.

    Returns:
        The learner, or ``None`` for another name.

    Raises:
        ConfigurationError: A configuration the combination does not allow.
    """
    if name not in SERVED_COMBINATIONS:
        return None
    config, kind = _with_combination(config, name)
    return NodeLearner(OnlineEstimator(config, kind=kind))  # type: ignore[arg-type]  # checked by build


_FIRST_STAMP_NS = 1_000_000_000  # the stamp of a first sample given without one [ns]
_NOMINAL_STEP_NS = 1_000_000  # the step between samples given without stamps [ns]


class NodeLearner:
    """The node's per-sample step as an evaluation's online learner: what the node would have published.

    ``predict_learn_one(x, y, stamp_ns=…)`` is :meth:`OnlineEstimator.step` on the sample: the a-priori
    prediction with the contact gate, the noise estimate and the rate meter exactly as in the node (a
    sample the gate refuses is predicted, not learned), and the consistent projection of the rigid body
    solved on the node's schedule in the samples' time (:attr:`OnlineEstimator.inline_projection`).
    ``predict_one`` is the learned model at x (the delay line of the horizon table); ``copy`` is an
    independent estimator (the regressor and the configuration, both read-only, are shared) for another
    stream: its first sample, like a stamp not after the previous one, begins another recording
    (:meth:`OnlineEstimator.start_recording`), as ``learn`` does between bags.

    Args:
        estimator: The estimator (learning is switched on).
    """

    #: The protocol and the horizon table pass the samples' stamps.
    needs_stamps = True

    def __init__(self, estimator: OnlineEstimator) -> None:
        self.estimator = estimator
        estimator.learning_enabled = True
        estimator.inline_projection = True  # the node's consistent rigid body, on its schedule in stamp time
        self._last_ns: int | None = None
        self._restart = False  # the next sample begins another recording
        self._n = len(estimator.config["robot.joints"])
        self._path: StickState | None = None  # the path of predict_one's states (friction that remembers)

    def _sample(self, x: Any, y: Any, stamp_ns: int | None) -> Sample:
        if stamp_ns is None:  # no stamp given: one nominal period after the previous sample
            stamp_ns = _FIRST_STAMP_NS if self._last_ns is None else self._last_ns + _NOMINAL_STEP_NS
        if self._restart or (self._last_ns is not None and stamp_ns <= self._last_ns):
            self.estimator.start_recording()
            self._restart = False
        self._last_ns = int(stamp_ns)
        xv = np.asarray(x, dtype=np.float64)
        n = self._n
        return Sample(int(stamp_ns), xv[:n], xv[n:2 * n], xv[2 * n:], np.asarray(y, dtype=np.float64))

    def predict_learn_one(self, x: Any, y: Any, *, stamp_ns: int | None = None) -> Prediction:
        """Predict the sample a priori, then learn it as the node does (unless the gate refuses it).

        ``stamp_ns`` is the sample's stamp [ns]; None: 1 ms after the previous sample (the protocol and
        the horizon table always pass the samples' own stamps).

        Raises:
            RejectedSampleError: A sample the learner refuses (nothing changed).
        """
        return self.estimator.step(self._sample(x, y, stamp_ns)).prediction

    def learn_one(self, x: Any, y: Any, *, stamp_ns: int | None = None) -> None:
        """Learn the sample as the node does (the a-priori prediction is made and dropped)."""
        self.estimator.step(self._sample(x, y, stamp_ns))

    def predict_one(self, x: Any, *, stamp_ns: int | None = None) -> Prediction:
        """Return the learned model's prediction at x (rigid-body part, residual, corrections).

        With friction that remembers, consecutive calls are one path (the delay line's samples, in order):
        the torque the joints' stick state holds is carried along them from where the learned stream left
        it, as the node's step adds it.

        Args:
            x: The state ``[q, q̇, q̈]``.
            stamp_ns: The predicted sample's stamp [ns]: the model's fast correction fades with the age of
                its newest learned sample at it (:meth:`OnlineEstimator.age_at`); None = the age of the
                last step's prediction.
        """
        model = self.estimator.model
        if stamp_ns is not None:
            model.prediction_age_s = self.estimator.age_at(int(stamp_ns))
        prediction = model.predict_one(x)
        stick = self.estimator.stick
        if stick is None:
            return prediction
        if self._path is None:
            self._path = stick.state.copy()
        xv, n = np.asarray(x, dtype=np.float64), self._n
        return with_held(prediction, stick.held(xv[None, :n], xv[None, n:2 * n], self._path)[0])

    def copy(self) -> NodeLearner:
        """Return an independent copy (the estimator's learned and time-based state)."""
        est = self.estimator
        memo = {id(est.regressor): est.regressor, id(est.config): est.config}
        twin = NodeLearner.__new__(NodeLearner)
        twin.estimator = copy.deepcopy(est, memo)
        twin._last_ns, twin._n, twin._restart = self._last_ns, self._n, True
        twin._path = None
        return twin
