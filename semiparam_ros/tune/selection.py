"""Hyperparameter selection on training data: one API for ``tune``, the reproduction and the tests.

Two ways to score a grid of ``parametric.lam × nonparametric.lam × nonparametric.sigma`` (for a given D),
both on the training stream only:

* **hold-out** (:func:`holdout_search`, ``tune``'s default): the last ``holdout`` fraction of the stream is
  held out; at each grid point a fresh learner (zero parameters, as in the paper) learns the first part one
  sample at a time and predicts the held-out part without learning. Score: normalized RMSE, per output
  component the RMSE over the standard deviation of that component over the hold-out, averaged over
  components (so N and N·m, or joints of different sizes, weigh equally).
* **protocol** (:func:`protocol_search`, ``tune --method protocol``; what ``scripts/reproduce.sh`` uses): the
  paper's protocol run *within* the stream (train on its first ``train_n`` samples, test-then-train on
  parts of the rest) at every grid point with every learner. Score of a grid point for a learner
  (:func:`score_reports`): for each group, its RMSE at regime over the best RMSE any grid point gave that
  learner, summed over groups; lowest wins. GURLS, the paper's library, likewise selects each model's
  regularization for that model.

The configuration's own values are always part of the grid, so the selection is never worse than them on
the score. Grid points are independent jobs: ``jobs`` runs them in parallel with joblib (processes; the
numbers do not depend on ``jobs``). The rigid-body regressor Φ(x) does not depend on the hyperparameters; in
a serial hold-out search it is computed once per sample and reused (:class:`CachedRegressor`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.build import build_model, build_regressor
from semiparam_ros.core.stream.rate import measured_period_s
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.protocol.metrics import OutputSpec, component_rmse
from semiparam_ros.eval.protocol.options import DEFAULT_FIRST_S, DEFAULT_WINDOW_S
from semiparam_ros.eval.protocol.prequential import SampleArrays, progress_enabled
from semiparam_ros.eval.protocol.report import ProtocolReport
from semiparam_ros.jobs.parallel import run_jobs

__all__ = [
    "DEFAULT_GRID",
    "METHODS",
    "TUNED_KEYS",
    "CachedRegressor",
    "GridPoint",
    "Selection",
    "grid_axes",
    "grid_table",
    "holdout_error",
    "holdout_search",
    "learner_config",
    "protocol_search",
    "score_reports",
    "selection_of",
    "split_holdout",
]

#: The parameters the selection chooses.
TUNED_KEYS: tuple[str, ...] = ("parametric.lam", "nonparametric.lam", "nonparametric.sigma")

#: Default grid (the configuration's own values are added to each axis).
DEFAULT_GRID: dict[str, tuple[float, ...]] = {
    "parametric.lam": (1e-4, 1e-2, 1.0),
    "nonparametric.lam": (1e-2, 1e-1, 1.0, 10.0),
    "nonparametric.sigma": (1.0, 2.0, 4.0, 8.0),
}

#: The two scoring methods.
METHODS: tuple[str, ...] = ("holdout", "protocol")


@dataclass(frozen=True)
class GridPoint:
    """One grid point's result for one learner.

    Attributes:
        values: The tuned parameters' values (dotted names).
        score: Lower is better (normalized hold-out RMSE, or the protocol score; dimensionless).
        rmse: Per group, the RMSE (hold-out, or at regime for the protocol) [N or N·m].
        rmse_first: Per group, the RMSE over the first seconds (protocol only) [N or N·m].
    """

    values: dict[str, float]
    score: float
    rmse: dict[str, float]
    rmse_first: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """Return a flat JSON row."""
        return {
            **self.values,
            "score": self.score,
            **{f"{g}_rmse": v for g, v in self.rmse.items()},
            **{f"{g}_rmse_first": v for g, v in self.rmse_first.items()},
        }


@dataclass(frozen=True)
class Selection:
    """The outcome of a search for one learner.

    Attributes:
        kind: The learner (``SP``, ``NP``, ``SPJ``, ``P``).
        method: ``holdout`` or ``protocol``.
        points: Every grid point, best first (ties keep the grid order).
        default: The point with the base configuration's values (``None`` if the grid did not hold it).
        config: The base configuration with the best values.
        n_train: Samples learned at each grid point.
        n_test: Samples scored (held out, or in the test parts).
    """

    kind: str
    method: str
    points: tuple[GridPoint, ...]
    default: GridPoint | None
    config: EstimatorConfig
    n_train: int
    n_test: int

    @property
    def best(self) -> GridPoint:
        """The selected point."""
        return self.points[0]

    def to_json(self) -> dict[str, Any]:
        """Return the JSON document (grid best first, the selection, the configuration)."""
        return {
            "kind": self.kind,
            "method": self.method,
            "best": self.best.to_json(),
            "default": None if self.default is None else self.default.to_json(),
            "grid": [p.to_json() for p in self.points],
            "n_train": self.n_train,
            "n_test": self.n_test,
            "config": self.config.to_flat(),
        }


class CachedRegressor:
    """A rigid-body regressor whose ``base_regressor`` results are memoized by input.

    Φ(q, q̇, q̈) depends only on the state, never on the learners' hyperparameters, so a grid search (or
    several learners replaying the same samples) can compute it once per sample. Every other attribute is
    delegated to the wrapped :class:`~semiparam_ros.core.rigid_body.dynamics.RigidBodyRegressor`.

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

    Raises:
        ValueError: If the fraction is out of (0, 1) or leaves a part with fewer than 2 samples.
    """
    if not 0.0 < holdout < 1.0:
        raise ValueError(f"holdout must be in (0, 1), got {holdout}")
    n_hold = round(len(data) * holdout)
    n_train = len(data) - n_hold
    if n_hold < 2 or n_train < 2:
        raise ValueError(f"{len(data)} samples are too few for a {holdout:g} hold-out")
    return data.slice(0, n_train), data.slice(n_train, len(data))


def grid_axes(
    config: EstimatorConfig, grid: Mapping[str, Sequence[float]] | None, keys: Sequence[str] = TUNED_KEYS
) -> dict[str, list[float]]:
    """Return the sorted values of each tuned key: the given (or default) values plus the configuration's.

    Raises:
        ConfigurationError: On a key that cannot be tuned (a ``ValueError``).
    """
    unknown = set(grid or {}) - set(TUNED_KEYS)
    if unknown:
        raise ConfigurationError(f"cannot tune {sorted(unknown)}; tunable: {list(TUNED_KEYS)}")
    axes: dict[str, list[float]] = {}
    for key in keys:
        values = [*(grid or {}).get(key, DEFAULT_GRID[key]), config[key]]
        axes[key] = sorted({float(v) for v in values})
    return axes


def learner_config(
    config: EstimatorConfig, kind: str, n_features: int | None
) -> tuple[EstimatorConfig, str]:
    """Return the configuration and build kind of a learner: ``SPJ`` is SP with the joint combination.

    Args:
        config: The base configuration.
        kind: ``P``, ``NP``, ``SP`` or ``SPJ``.
        n_features: D, or None for the configuration's.

    Returns:
        ``(configuration, kind to build)``.
    """
    if kind == "SPJ":
        config = config.with_overrides({"semiparametric.combination": "joint"})
        kind = "SP"
    if n_features is not None:
        config = config.with_overrides({"nonparametric.n_features": int(n_features)})
    return config, kind


def holdout_error(
    config: EstimatorConfig,
    train: SampleArrays,
    held_out: SampleArrays,
    *,
    kind: str = "SP",
    regressor: Any = None,
) -> GridPoint:
    """Train a fresh learner on ``train`` (one sample at a time) and score its predictions on ``held_out``.

    Args:
        config: Configuration of the learner (its ``robot.output`` names the groups).
        train: Training samples.
        held_out: Hold-out samples (predicted without learning).
        kind: ``"P"``, ``"NP"`` or ``"SP"``.
        regressor: Rigid-body regressor to share (e.g. a :class:`CachedRegressor`).

    Returns:
        The point: the tuned values, the normalized RMSE (mean over components of RMSE / std over the
        hold-out) and the component-averaged RMSE of each group.
    """
    output = OutputSpec.from_config(config)
    output.check(held_out.n_outputs)
    model = build_model(config, kind, regressor, sample_period_s=measured_period_s(train.stamps_ns))
    for x, y in zip(train.X, train.Y, strict=True):
        model.learn_one(x, y)
    pred = np.stack([np.asarray(model.predict_one(x).total) for x in held_out.X])
    rmse = component_rmse(pred - held_out.Y)
    scale = np.std(held_out.Y, axis=0)
    scale = np.where(scale > 1e-12, scale, 1.0)
    return GridPoint(
        values={k: float(config[k]) for k in TUNED_KEYS},
        score=float(np.mean(rmse / scale)),
        rmse={g: float(np.mean(rmse[list(spec.columns)])) for g, spec in output.groups.items()},
    )


def _holdout_job(
    config: EstimatorConfig, train: SampleArrays, held_out: SampleArrays, kind: str, regressor: Any
) -> GridPoint:
    return holdout_error(config, train, held_out, kind=kind, regressor=regressor)


def _ranked(points: Sequence[GridPoint]) -> tuple[GridPoint, ...]:
    order = sorted(range(len(points)), key=lambda i: (points[i].score, i))
    return tuple(points[i] for i in order)


def holdout_search(
    config: EstimatorConfig,
    data: SampleArrays,
    *,
    kind: str = "SP",
    holdout: float = 0.2,
    n_features: int | None = None,
    grid: Mapping[str, Sequence[float]] | None = None,
    jobs: int = 1,
    progress: bool = False,
    cluster: str | None = None,
) -> Selection:
    """Grid search by hold-out (``tune``).

    Args:
        config: Base configuration (its values of the tuned keys are always part of the grid).
        data: Training stream; its last ``holdout`` fraction is held out.
        kind: Learner to tune (the node runs ``"SP"``); ``"SPJ"`` tunes the joint semiparametric fit, and
            the returned configuration then has ``semiparametric.combination = joint``.
        holdout: Held-out fraction.
        n_features: D of the random features (default: the configuration's).
        grid: Values per tuned key (missing keys: :data:`DEFAULT_GRID`).
        jobs: Parallel jobs (1 = serial, sharing one :class:`CachedRegressor`; -1 = all cores).
        progress: Progress bar on stderr (only when it is a terminal; serial runs).
        cluster: A Dask scheduler address or ``local:N`` instead of ``jobs`` (the same numbers).

    Returns:
        The :class:`Selection`.

    Raises:
        ValueError: On an unknown grid key, an invalid value, too few samples, or ``"SPJ"`` with unequal
            forgetting factors.
    """
    base, build_kind = learner_config(config, kind, n_features)
    axes = grid_axes(base, grid)
    train, held_out = split_holdout(data, holdout)
    configs = [
        base.with_overrides(dict(zip(TUNED_KEYS, values, strict=True)))
        for values in itertools.product(*(axes[k] for k in TUNED_KEYS))
    ]
    serial = jobs == 1 and cluster is None
    regressor = CachedRegressor(build_regressor(base)) if build_kind != "NP" and serial else None
    points = run_jobs(
        _holdout_job,
        [(c, train, held_out, build_kind, regressor) for c in configs],
        jobs=jobs,
        progress=progress_enabled(progress),
        unit="point",
        cluster=cluster,
        labels=[", ".join(f"{k} = {c[k]:g}" for k in TUNED_KEYS) for c in configs],
    )
    return selection_of(kind, "holdout", base, points, len(train), len(held_out))


def selection_of(
    kind: str, method: str, base: EstimatorConfig, points: Sequence[GridPoint], n_train: int, n_test: int
) -> Selection:
    """Rank scored grid points into a :class:`Selection` (the base configuration's own point named)."""
    ranked = _ranked(points)
    default_values = {k: float(base[k]) for k in TUNED_KEYS}
    default = next(
        (
            p
            for p in points
            if all(math.isclose(p.values[k], v) for k, v in default_values.items() if k in p.values)
        ),
        None,
    )
    chosen = base.with_overrides(dict(ranked[0].values))
    return Selection(
        kind=kind,
        method=method,
        points=ranked,
        default=default,
        config=chosen,
        n_train=n_train,
        n_test=n_test,
    )


def score_reports(
    reports: Sequence[ProtocolReport], kind: str, keys: Sequence[str] = TUNED_KEYS
) -> list[GridPoint]:
    """Score protocol runs over a grid for one learner; best first (the protocol method's score).

    Score of a run: ``Σ_groups RMSE at regime / best RMSE at regime of that group over the runs``.

    Args:
        reports: One protocol report per grid point (their ``config`` holds the point's values).
        kind: The learner to score (runs without it are skipped).
        keys: The tuned keys recorded with each point.

    Returns:
        The points, best first (ties keep the reports' order); empty if no report has ``kind``.

    Raises:
        ValueError: If a report's configuration lacks a tuned key.
    """
    runs = [r for r in reports if kind in r.models]
    if not runs:
        return []
    groups = runs[0].groups
    best = {g: min(r.models[kind].rmse(g) for r in runs) for g in groups}
    points = []
    for r in runs:
        try:
            values = {k: float(r.config[k]) for k in keys}
        except KeyError as err:
            raise ValueError(f"selection report without {err} in its configuration") from err
        m = r.models[kind]
        points.append(
            GridPoint(
                values=values,
                score=float(sum(m.rmse(g) / best[g] for g in groups)),
                rmse={g: m.rmse(g) for g in groups},
                rmse_first={g: m.rmse(g, "first") for g in groups},
            )
        )
    return list(_ranked(points))


def _protocol_job(
    config: EstimatorConfig,
    train: SampleArrays,
    test: SampleArrays,
    kinds: Sequence[str],
    options: Mapping[str, Any],
) -> ProtocolReport:
    from semiparam_ros.eval.bags.replay import build_models
    from semiparam_ros.eval.protocol.prequential import run_protocol
    from semiparam_ros.eval.protocol.report import protocol_report

    period = measured_period_s(train.stamps_ns)
    models = build_models(config, kinds, n_train=len(train), sample_period_s=period)
    result = run_protocol(models, train, test, output=OutputSpec.from_config(config), **options)
    return protocol_report(result, config=config.to_flat())


def protocol_search(
    config: EstimatorConfig,
    data: SampleArrays,
    *,
    kinds: Sequence[str] = ("SP",),
    train_n: int,
    splits: int,
    split_size: int | None = None,
    window_s: float = DEFAULT_WINDOW_S,
    first_s: float = DEFAULT_FIRST_S,
    n_features: int | None = None,
    grid: Mapping[str, Sequence[float]] | None = None,
    jobs: int = 1,
    progress: bool = False,
    cluster: str | None = None,
) -> tuple[dict[str, Selection], list[ProtocolReport]]:
    """Grid search by the paper's protocol within one stream, every learner in each run.

    Args:
        config: Base configuration.
        data: The training stream: the first ``train_n`` samples train, the rest is split into test parts.
        kinds: Learners run at every point and selected for (``P``, ``NP``, ``SP``, ``SPJ``).
        train_n: Training samples (the rest is the test stream).
        splits: Number of test parts.
        split_size: Samples per part (``None``: equal parts).
        window_s: Sliding window [s].
        first_s: Initial segment [s].
        n_features: D (default: the configuration's).
        grid: Values per tuned key (missing keys: only the configuration's value — unlike the hold-out).
        jobs: Parallel jobs (-1 = all cores).
        progress: Progress bar over grid points (only on a terminal).
        cluster: A Dask scheduler address or ``local:N`` instead of ``jobs`` (the same numbers).

    Returns:
        ``(selections by kind, the reports of the runs in grid order)``.

    Raises:
        ValueError: On a bad grid key or value, or a stream too short for the split request.
    """
    base = (
        config if n_features is None else config.with_overrides({"nonparametric.n_features": int(n_features)})
    )
    full = {k: (grid or {}).get(k, [base[k]]) for k in TUNED_KEYS}
    axes = grid_axes(base, full)
    if not 2 <= train_n < len(data):
        raise ValueError(f"train_n must leave test samples: 2 <= {train_n} < {len(data)}")
    train, test = data.slice(0, train_n), data.slice(train_n, len(data))
    configs = [
        base.with_overrides(dict(zip(TUNED_KEYS, values, strict=True)))
        for values in itertools.product(*(axes[k] for k in TUNED_KEYS))
    ]
    options = {"splits": splits, "split_size": split_size, "window_s": window_s, "first_s": first_s}
    reports = run_jobs(
        _protocol_job,
        [(c, train, test, tuple(kinds), options) for c in configs],
        jobs=jobs,
        progress=progress_enabled(progress),
        unit="point",
        cluster=cluster,
        labels=[", ".join(f"{k} = {c[k]:g}" for k in TUNED_KEYS) for c in configs],
    )
    n_test = reports[0].samples_test
    selections = {}
    for kind in kinds:
        learner_base, _ = learner_config(base, kind, None)
        selections[kind] = selection_of(
            kind, "protocol", learner_base, score_reports(reports, kind), len(train), n_test
        )
    return selections, reports


def grid_table(selection: Selection, *, first_s: float | None = None) -> str:
    """Markdown table of a search, best first, the selected and the default points marked.

    Args:
        selection: The outcome.
        first_s: With the protocol method, the initial segment's length [s] for the column labels.

    Returns:
        The table with a trailing newline.
    """
    from semiparam_ros.eval.protocol.metrics import GROUP_UNITS

    groups = list(selection.best.rmse)
    where = "hold-out" if selection.method == "holdout" else "at regime"
    header = [
        "λ_P",
        "λ_NP",
        "σ",
        "hold-out nRMSE" if selection.method == "holdout" else "score",
        *(f"{g} RMSE {where} [{GROUP_UNITS.get(g, '')}]" for g in groups),
    ]
    if selection.method == "protocol":
        header += [f"{g} RMSE first {first_s or 3:g} s [{GROUP_UNITS.get(g, '')}]" for g in groups]
    header.append("")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for p in selection.points:
        tags = [t for t, on in (("best", p is selection.best), ("default", p is selection.default)) if on]
        cells = [f"{p.values.get(k, math.nan):g}" for k in TUNED_KEYS] + [f"{p.score:.4f}"]
        cells += [f"{p.rmse[g]:.4g}" for g in groups]
        if selection.method == "protocol":
            cells += [f"{p.rmse_first[g]:.3g}" for g in groups]
        cells.append(", ".join(tags))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"

