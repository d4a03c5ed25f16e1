"""What the ``tune`` command does, as a library call (the CLI only parses arguments).

:func:`run_tune` selects the learners' hyperparameters on training bags — by a hold-out grid, by the
paper's protocol or by held-out motion (``validate``) — writes the chosen configuration and the search as
JSON, and returns the text printed on the terminal.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from semiparam_ros.core.config import EstimatorConfig, load_evaluation_config, write_config
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.bags.replay import Topics, load_samples
from semiparam_ros.eval.protocol.options import DEFAULT_WINDOW_S
from semiparam_ros.plain_json import write_json
from semiparam_ros.tune.held_out import VALIDATION_HORIZONS, validation_search
from semiparam_ros.tune.selection import TUNED_KEYS, Selection, grid_table, holdout_search, protocol_search

__all__ = ["run_tune"]


def run_tune(
    *,
    train: Path | Sequence[Path],
    config: Path | None,
    overrides: Mapping[str, Any] | None = None,
    joint_states_topic: str | None = None,
    wrench_topic: str | None = None,
    n_features: int | None = None,
    holdout: float = 0.2,
    grid: Mapping[str, Sequence[float]] | None = None,
    limit: int | None = None,
    out: Path | None = None,
    json_path: Path | None = None,
    progress: bool = True,
    kind: str = "SP",
    method: str = "holdout",
    kinds: Sequence[str] | None = None,
    train_n: int | None = None,
    splits: int = 5,
    split_size: int | None = None,
    window_s: float = DEFAULT_WINDOW_S,
    jobs: int = 1,
    validate: Sequence[Path] | None = None,
    cluster: str | None = None,
) -> str:
    """Select hyperparameters on a training bag and write the tuned parameter file.

    Args:
        train: Training bag (several with ``validate``: learned in this order).
        config: Parameter file (``None``: the shipped one).
        overrides: Parameter overrides applied before tuning.
        joint_states_topic: JointState topic (default from the configuration).
        wrench_topic: WrenchStamped topic (default from the configuration).
        n_features: D (default: the configuration's).
        holdout: Held-out fraction (hold-out method).
        grid: Values per tuned key (hold-out: :data:`~semiparam_ros.tune.selection.DEFAULT_GRID` for missing
            keys; protocol: the configuration's value for missing keys).
        limit: Use only the first samples of the bag.
        out: Destination of the tuned ROS 2 parameter file (for ``kind``).
        json_path: Destination of the search as JSON (the selection per learner; protocol: the runs' scalars).
        progress: Show a progress bar (only when stderr is a terminal).
        kind: Learner whose selection is written to ``out``: ``"SP"`` (as configured) or ``"SPJ"`` (the joint
            fit; the written file then selects ``semiparametric.combination: joint``).
        method: ``"holdout"`` or ``"protocol"`` (:mod:`semiparam_ros.tune.selection`).
        kinds: Protocol method: learners run at every grid point (default: ``kind`` only).
        train_n: Protocol method: training samples (default: half the stream).
        splits: Protocol method: test parts.
        split_size: Protocol method: samples per part.
        window_s: Protocol method: sliding window [s].
        jobs: Parallel jobs (-1: all cores); the numbers do not depend on it.
        validate: Validation bags: select by held-out motion (:mod:`semiparam_ros.tune.held_out`; the
            method is then ``"validate"``) instead of ``method``.
        cluster: A Dask scheduler address or ``local:N`` that runs the grid points instead of ``jobs``.

    Returns:
        The text to print (the grid and the selection).

    Raises:
        ValueError: On invalid arguments, configuration or bag.
    """
    cfg = load_evaluation_config(config, overrides)
    topics = Topics.from_config(cfg, joint_states_topic, wrench_topic)
    trains = [Path(train)] if isinstance(train, str | Path) else [Path(t) for t in train]
    if validate:
        return _run_validation(cfg, trains, list(validate), topics, kind=kind, n_features=n_features,
                               grid=grid, jobs=jobs, cluster=cluster, progress=progress, out=out,
                               json_path=json_path)
    if len(trains) != 1:
        raise ConfigurationError(f"{method} selection takes one training bag (several need --validate)")
    train = trains[0]
    data, drops = load_samples(train, cfg, topics, limit=limit)
    if method == "holdout":
        selections = {
            kind: holdout_search(
                cfg,
                data,
                kind=kind,
                holdout=holdout,
                n_features=n_features,
                grid=grid,
                jobs=jobs,
                progress=progress,
                cluster=cluster,
            )
        }
        doc: dict[str, Any] = {}
    elif method == "protocol":
        run_kinds = list(dict.fromkeys([*(kinds or ()), kind])) if kinds else [kind]
        selections, reports = protocol_search(
            cfg,
            data,
            kinds=run_kinds,
            train_n=len(data) // 2 if train_n is None else train_n,
            splits=splits,
            split_size=split_size,
            window_s=window_s,
            n_features=n_features,
            grid=grid,
            jobs=jobs,
            progress=progress,
            cluster=cluster,
        )
        doc = {
            "first_s": reports[0].first_s,
            "runs": [
                {
                    "config": {k: r.config[k] for k in TUNED_KEYS},
                    "models": {k: {g: m.rmse(g) for g in r.groups} for k, m in r.models.items()},
                }
                for r in reports
            ]
        }
    else:
        raise ConfigurationError(f"method must be 'holdout' or 'protocol', got {method!r}")
    text = "".join(
        f"{method} search of {k} on {train}: {sel.n_train} samples learned, {sel.n_test} scored, "
        f"D = {sel.config['nonparametric.n_features']}\n\n" + grid_table(sel) + "\n"
        for k, sel in selections.items())
    return text + _write_selection(selections, kind, method, str(train), out, json_path, {
        "drops": drops, "holdout": holdout if method == "holdout" else None, **doc})


def _write_selection(selections: Mapping[str, Selection], kind: str, method: str, source: str,
                     out: Path | None, json_path: Path | None, extra: Mapping[str, Any]) -> str:
    """Say what was selected for ``kind``; write the tuned parameter file and the JSON when asked."""
    chosen = selections[kind]
    values = ", ".join(f"{k} = {chosen.best.values[k]:g}" for k in TUNED_KEYS)
    base = "n/a" if chosen.default is None else f"{chosen.default.score:.4f}"
    text = (f"selected for {kind}: {values} (score {chosen.best.score:.4f}; the configuration's values: "
            f"{base})\n")
    if out is not None:
        write_config(chosen.config, out, header=(
            f"semiparam_ros estimator parameters tuned by `tune --method {method}` ({kind}) on {source}\n"
            f"score {chosen.best.score:.4f} (base configuration {base})"))
        text += f"wrote {out}\n"
    if json_path is not None:
        write_json({"method": method, "kind": kind, **extra,
                    "selections": {k: s.to_json() for k, s in selections.items()}}, json_path)
    return text


def _run_validation(cfg: EstimatorConfig, train: list[Path], validate: list[Path], topics: Topics, *,
                    kind: str, n_features: int | None, grid: Mapping[str, Sequence[float]] | None, jobs: int,
                    cluster: str | None, progress: bool, out: Path | None, json_path: Path | None) -> str:
    """``tune --train A… --validate B…``: selection by held-out motion (tune/held_out.py)."""
    selection = validation_search(cfg, train, validate, topics=topics, kind=kind, n_features=n_features,
                                  grid=grid, jobs=jobs, cluster=cluster, progress=progress)
    source = f"{', '.join(map(str, train))} (validated on {', '.join(map(str, validate))})"
    d = selection.config["nonparametric.n_features"]
    text = (f"validate search of {kind}: learned {source}, D = {d}; "
            f"score = normalized RMSE over the horizons {', '.join(f'{h:g} s' for h in VALIDATION_HORIZONS)} "
            f"and frozen as served\n\n" + grid_table(selection) + "\n")
    return text + _write_selection({kind: selection}, kind, "validate", source, out, json_path, {
        "train": [str(t) for t in train], "validate": [str(v) for v in validate],
        "horizons": [*VALIDATION_HORIZONS, "frozen"]})
