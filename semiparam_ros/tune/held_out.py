"""Selection by held-out motion: learn some bags, score on others (``tune --train A… --validate B…``).

The hold-out of :mod:`semiparam_ros.tune.selection` scores the end of the training bag: the same motion,
a little later. A default that must hold on a robot's next task is chosen on *other* motion — other bags,
other robots of a fleet. Here each grid point is a job that

1. learns the training bags with the node's estimator
   (:func:`~semiparam_ros.serving.bag_learning.learn_bags`: the
   same pipeline, contact gate and adaptation as ``learn`` and the node), and
2. scores the learned model on every validation bag at the ages of the evaluation
   (:mod:`semiparam_ros.eval.protocol.horizon`): one step, 0.1 s, 1 s and 10 s through the delay line, and
   **frozen** as served — ``LearnedModel.predict`` at the validation states, what ``load_model`` gives.

Score of a grid point: the normalized RMSE (per output component the RMSE over the component's standard
deviation in that bag, averaged over components) averaged over the horizons and the validation bags;
lower is better. Each job reads its bags itself, so on a cluster the bags must be where the workers look
(a shared filesystem or the same paths; a missing one fails that job, naming the bag and the worker).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.eval.bags.replay import Topics, load_samples
from semiparam_ros.eval.protocol.horizon import evaluate_horizons
from semiparam_ros.eval.protocol.metrics import OutputSpec, component_rmse
from semiparam_ros.eval.protocol.prequential import SampleArrays, progress_enabled
from semiparam_ros.jobs.parallel import run_jobs
from semiparam_ros.serving.bag_learning import learn_bags
from semiparam_ros.serving.learned_model import LearnedModel
from semiparam_ros.tune.selection import (
    TUNED_KEYS,
    GridPoint,
    Selection,
    grid_axes,
    learner_config,
    selection_of,
)

__all__ = ["VALIDATION_HORIZONS", "served_error", "validation_error", "validation_search"]

#: The ages of the model scored by the delay line [s] (0: one step); the frozen model is scored as served.
VALIDATION_HORIZONS: tuple[float, ...] = (0.0, 0.1, 1.0, 10.0)


def served_error(model: LearnedModel, data: SampleArrays) -> np.ndarray:
    """Return the frozen model's errors as served (``LearnedModel.predict``) at a stream's states, (N, t).

    Args:
        model: The learned model.
        data: The stream (``X = [q, q̇, q̈]`` in the model's joint order, ``Y`` measured).

    Returns:
        Predicted − measured [N·m, or N and N·m].
    """
    n = len(model.joints)
    tau, _ = model.predict(data.X[:, :n], data.X[:, n:2 * n], data.X[:, 2 * n:])
    return np.asarray(tau) - data.Y


def _normalized(err: np.ndarray, Y: np.ndarray) -> float:
    scale = np.std(Y, axis=0)
    return float(np.mean(component_rmse(err) / np.where(scale > 1e-12, scale, 1.0)))


def validation_error(config: EstimatorConfig, train: Sequence[str | Path], validate: Sequence[str | Path],
                     topics: Topics) -> GridPoint:
    """Learn ``train`` with the node's estimator, score the model on each ``validate`` bag (one grid point).

    Args:
        config: The learner's configuration.
        train: Training bags, learned in this order.
        validate: Validation bags.
        topics: Topics of the bags.

    Returns:
        The point: the tuned values, the score (module docstring) and per group the frozen RMSE [N or
        N·m] averaged over the validation bags.

    Raises:
        BagError: A bag that cannot be read (named).
    """
    est, _ = learn_bags(train, config, joint_states_topic=topics.joint_states, wrench_topic=topics.wrench)
    served = LearnedModel(est)
    output = OutputSpec.from_config(config)
    scores: list[float] = []
    frozen: dict[str, list[float]] = {g: [] for g in output.groups}
    for bag in validate:
        data, _ = load_samples(bag, config, topics)
        err = served_error(served, data)
        scores.append(_normalized(err, data.Y))
        rmse = component_rmse(err)
        for g, spec in output.groups.items():
            frozen[g].append(float(np.mean(rmse[list(spec.columns)])))
        # the delay line (the training range split is not used here: the bag stands for itself)
        report = evaluate_horizons({"model": est.model}, data, data, horizons=VALIDATION_HORIZONS)
        scale = np.std(data.Y, axis=0)
        for h in report.horizons:
            per_component = np.asarray(report.rmse["model"][h.label])
            scores.append(float(np.mean(per_component / np.where(scale > 1e-12, scale, 1.0))))
    return GridPoint(values={k: float(config[k]) for k in TUNED_KEYS}, score=float(np.mean(scores)),
                     rmse={g: float(np.mean(v)) for g, v in frozen.items()})


def validation_search(config: EstimatorConfig, train: Sequence[str | Path], validate: Sequence[str | Path], *,
                      topics: Topics | None = None, kind: str = "SP", n_features: int | None = None,
                      grid: Mapping[str, Sequence[float]] | None = None, jobs: int = 1,
                      cluster: str | None = None, progress: bool = False) -> Selection:
    """Grid search by held-out motion: every grid point learns ``train`` and is scored on ``validate``.

    Args:
        config: Base configuration (its values are always part of the grid).
        train: Training bags.
        validate: Validation bags (other motion: other logs, other robots).
        topics: Topics of the bags (default from the configuration).
        kind: ``"SP"`` (as configured) or ``"SPJ"`` (the joint fit).
        n_features: D (default: the configuration's).
        grid: Values per tuned key (missing keys: the default grid of the hold-out).
        jobs: Parallel jobs on this machine (-1: all cores).
        cluster: A Dask scheduler address or ``local:N`` instead of ``jobs``.
        progress: Progress on stderr.

    Returns:
        The :class:`~semiparam_ros.tune.selection.Selection` (method ``"validate"``).

    Raises:
        ValueError: No training or validation bag, a bad grid, or an unreadable bag.
    """
    if not train or not validate:
        raise ValueError("selection by held-out motion needs --train and --validate bags")
    base, _ = learner_config(config, kind, n_features)
    topics = topics or Topics.from_config(base)
    axes = grid_axes(base, grid)
    configs = [base.with_overrides(dict(zip(TUNED_KEYS, values, strict=True)))
               for values in itertools.product(*(axes[k] for k in TUNED_KEYS))]
    train, validate = [str(b) for b in train], [str(b) for b in validate]
    labels = [", ".join(f"{k} = {c[k]:g}" for k in TUNED_KEYS) for c in configs]
    points: list[Any] = run_jobs(validation_error, [(c, train, validate, topics) for c in configs], jobs=jobs,
                                 cluster=cluster, labels=labels, unit="point",
                                 progress=progress if cluster else progress_enabled(progress))
    return selection_of(kind, "validate", base, points, len(train), len(validate))
