"""Hyperparameter selection by hold-out: λ of each stage and the kernel width σ, for a given D.

The last ``holdout`` fraction of a training stream is held out; for every point of the grid
``parametric.lam × nonparametric.lam × nonparametric.sigma`` a fresh semiparametric learner (zero
parameters, as in the paper) learns the first part one sample at a time and then predicts the held-out
part without learning. The score is the normalized RMSE: per output component the RMSE divided by the
standard deviation of that component over the hold-out part, averaged over the components — so forces
(N) and torques (N·m) weigh equally. The configuration's own values are always evaluated too, so the
selected point is never worse than the defaults on the hold-out.

The rigid-body regressor Φ(x) does not depend on the hyperparameters; it is computed once per sample and
reused by every grid point (:class:`CachedRegressor`).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator import build_model, build_regressor
from semiparam_ros.eval.metrics import component_rmse, groups_for
from semiparam_ros.eval.protocol import SampleArrays

__all__ = [
    "DEFAULT_GRID",
    "TUNED_KEYS",
    "CachedRegressor",
    "TuneResult",
    "grid_markdown",
    "holdout_error",
    "split_holdout",
    "tune",
]

#: The parameters the grid search selects.
TUNED_KEYS: tuple[str, ...] = ("parametric.lam", "nonparametric.lam", "nonparametric.sigma")

#: Default grid (the configuration's own values are added to each axis).
DEFAULT_GRID: dict[str, tuple[float, ...]] = {
    "parametric.lam": (1e-4, 1e-2, 1.0),
    "nonparametric.lam": (1e-2, 1e-1, 1.0, 10.0),
    "nonparametric.sigma": (1.0, 2.0, 4.0, 8.0),
}


class CachedRegressor:
    """A rigid-body regressor whose ``base_regressor`` results are memoized by input.

    Φ(q, q̇, q̈) depends only on the state, never on the learners' hyperparameters, so a grid search (or
    several learners replaying the same samples) can compute it once per sample. Every other attribute is
    delegated to the wrapped :class:`~semiparam_ros.core.dynamics.RigidBodyRegressor`.

    Args:
        regressor: The regressor to wrap.
    """

    def __init__(self, regressor: Any) -> None:
        self._regressor = regressor
        self._cache: dict[bytes, np.ndarray] = {}

    def __getattr__(self, name: str) -> Any:
        return getattr(self._regressor, name)

    def base_regressor(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
        """Return the base regressor (t × n_base) at a state, computed once per distinct state."""
        key = np.concatenate([np.asarray(q, float), np.asarray(dq, float), np.asarray(ddq, float)]).tobytes()
        value = self._cache.get(key)
        if value is None:
            value = np.array(self._regressor.base_regressor(q, dq, ddq), dtype=np.float64)
            value.setflags(write=False)
            self._cache[key] = value
        return value


def split_holdout(data: SampleArrays, holdout: float) -> tuple[SampleArrays, SampleArrays]:
    """Split a stream into its first part (training) and its last ``holdout`` fraction.

    Args:
        data: The stream.
        holdout: Fraction in (0, 1) held out at the end.

    Returns:
        ``(train, held_out)``.

    Raises:
        ValueError: If the fraction is out of range or leaves a part with fewer than 2 samples.
    """
    if not 0.0 < holdout < 1.0:
        raise ValueError(f"holdout must be in (0, 1), got {holdout}")
    n_hold = round(len(data) * holdout)
    n_train = len(data) - n_hold
    if n_hold < 2 or n_train < 2:
        raise ValueError(f"{len(data)} samples are too few for a {holdout:g} hold-out")
    return data.slice(0, n_train), data.slice(n_train, len(data))


def holdout_error(config: EstimatorConfig, train: SampleArrays, held_out: SampleArrays, *,
                  kind: str = "SP", regressor: Any = None) -> dict[str, float]:
    """Train a fresh learner on ``train`` (one sample at a time) and score its predictions on ``held_out``.

    Args:
        config: Configuration of the learner.
        train: Training samples.
        held_out: Hold-out samples (predicted without learning).
        kind: ``"P"``, ``"NP"`` or ``"SP"``.
        regressor: Rigid-body regressor to share (e.g. a :class:`CachedRegressor`).

    Returns:
        ``{"score": normalized RMSE (mean over components of RMSE / std), "force_rmse": N,
        "torque_rmse": N·m}`` (component-averaged RMSEs; only ``torque_rmse`` for joint torques).
    """
    model = build_model(config, kind, regressor)
    for x, y in zip(train.X, train.Y, strict=True):
        model.learn_one(x, y)
    pred = np.stack([np.asarray(model.predict_one(x).total) for x in held_out.X])
    err = pred - held_out.Y
    rmse = component_rmse(err)
    scale = np.std(held_out.Y, axis=0)
    scale = np.where(scale > 1e-12, scale, 1.0)
    out = {"score": float(np.mean(rmse / scale))}
    for group, cols in groups_for(held_out.n_outputs).items():
        out[f"{group}_rmse"] = float(np.mean(rmse[cols]))
    return out


@dataclass
class TuneResult:
    """Outcome of :func:`tune`.

    Attributes:
        grid: One row per grid point: the tuned parameters' values, ``score``, and the RMSEs.
        best: The row with the lowest score.
        default: The row of the configuration's own values.
        config: The configuration with the best values.
        n_train: Samples learned at each grid point.
        n_holdout: Held-out samples.
    """

    grid: list[dict[str, Any]]
    best: dict[str, Any]
    default: dict[str, Any]
    config: EstimatorConfig
    n_train: int
    n_holdout: int


def tune(config: EstimatorConfig, data: SampleArrays, *, holdout: float = 0.2, n_features: int | None = None,
         grid: Mapping[str, Sequence[float]] | None = None, kind: str = "SP",
         progress: bool = False) -> TuneResult:
    """Grid search of ``parametric.lam``, ``nonparametric.lam`` and ``nonparametric.sigma`` by hold-out.

    Args:
        config: Base configuration (its values of the tuned keys are always part of the grid).
        data: Training stream; its last ``holdout`` fraction is held out.
        holdout: Held-out fraction.
        n_features: D of the random features (default: the configuration's).
        grid: Values per tuned key (missing keys: :data:`DEFAULT_GRID`).
        kind: Learner to tune (the node runs ``"SP"``); ``"SPJ"`` tunes the joint semiparametric fit, and the
            returned configuration then has ``semiparametric.combination = joint``.
        progress: Show a tqdm bar.

    Returns:
        The :class:`TuneResult`.

    Raises:
        ValueError: On an unknown grid key, an invalid value, too few samples, or ``"SPJ"`` with unequal
            forgetting factors.
    """
    if kind == "SPJ":
        config = config.with_overrides({"semiparametric.combination": "joint"})
        kind = "SP"
    if n_features is not None:
        config = config.with_overrides({"nonparametric.n_features": int(n_features)})
    axes: dict[str, list[float]] = {}
    for key in TUNED_KEYS:
        values = list((grid or {}).get(key, DEFAULT_GRID[key]))
        values.append(config[key])
        axes[key] = sorted({float(v) for v in values})
    unknown = set(grid or {}) - set(TUNED_KEYS)
    if unknown:
        raise ValueError(f"cannot tune {sorted(unknown)}; tunable: {list(TUNED_KEYS)}")
    train, held_out = split_holdout(data, holdout)
    regressor = CachedRegressor(build_regressor(config)) if kind != "NP" else None
    points = list(itertools.product(*(axes[k] for k in TUNED_KEYS)))
    if progress:
        from tqdm import tqdm

        points_iter = tqdm(points, unit="point")
    else:
        points_iter = points
    rows = []
    for values in points_iter:
        overrides = dict(zip(TUNED_KEYS, values, strict=True))
        scores = holdout_error(config.with_overrides(overrides), train, held_out, kind=kind,
                               regressor=regressor)
        rows.append({**overrides, **scores})
    default_values = {k: float(config[k]) for k in TUNED_KEYS}
    default = next(r for r in rows if all(r[k] == v for k, v in default_values.items()))
    best = min(rows, key=lambda r: r["score"])
    tuned = config.with_overrides({k: best[k] for k in TUNED_KEYS})
    return TuneResult(grid=rows, best=best, default=default, config=tuned, n_train=len(train),
                      n_holdout=len(held_out))


def grid_markdown(result: TuneResult) -> str:
    """Markdown table of a grid search, best first, the default marked.

    Args:
        result: Output of :func:`tune`.

    Returns:
        The table with a trailing newline.
    """
    extra = [k for k in ("force_rmse", "torque_rmse") if k in result.grid[0]]
    units = {"force_rmse": "force RMSE [N]", "torque_rmse": "torque RMSE [N·m]"}
    header = ["λ_P", "λ_NP", "σ", "hold-out nRMSE", *(units[k] for k in extra), ""]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in sorted(result.grid, key=lambda r: r["score"]):
        tags = []
        if row is result.best:
            tags.append("best")
        if row is result.default:
            tags.append("default")
        cells = [f"{row[k]:g}" for k in TUNED_KEYS] + [f"{row['score']:.4f}"]
        cells += [f"{row[k]:.4g}" for k in extra] + [", ".join(tags)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
