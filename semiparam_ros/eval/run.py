"""What the ``evaluate`` command does, as a library call (the CLI only parses arguments).

:func:`run_evaluate` loads the configuration, reads the bags through the node's pipeline, runs the paper's
protocol or the payload scenario, writes the JSON report, the figure(s) and the markdown table, and
returns the text printed on the terminal.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from semiparam_ros.atomic import atomic_write_text
from semiparam_ros.core.config import EstimatorConfig, load_config, write_config
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.contacts import contact_report, run_contacts
from semiparam_ros.eval.figures import plot_adaptation, plot_contacts, plot_protocol
from semiparam_ros.eval.horizon import horizon_figure, horizon_markdown
from semiparam_ros.eval.options import DEFAULT_WINDOW_S, ProtocolOptions
from semiparam_ros.eval.per_sample import per_sample_figure, write_per_sample
from semiparam_ros.eval.replay import KINDS, Topics, evaluate_adaptation, evaluate_bags, load_samples
from semiparam_ros.eval.report import adaptation_report, protocol_report, write_json
from semiparam_ros.eval.selection import TUNED_KEYS, Selection, grid_table, holdout_search, protocol_search
from semiparam_ros.eval.tables import (
    adaptation_table,
    checks_table,
    comparisons_table,
    components_table,
    contacts_table,
    protocol_table,
)
from semiparam_ros.eval.validation import VALIDATION_HORIZONS, validation_search
from semiparam_ros.io.bags import recovery_notes

__all__ = [
    "ReportPaths", "default_config_path", "evaluate_contacts", "evaluate_paper", "evaluate_payload",
    "evaluation_text", "load_evaluation_config", "run_evaluate", "run_tune",
]


def default_config_path() -> Path | None:
    """Return the shipped ``icub_right_arm.yaml``: the source tree's, else the installed share copy.

    Returns:
        The path, or ``None`` when neither exists (the parameter defaults are then used).
    """
    candidates = [
        Path(__file__).resolve().parents[2] / "config" / "icub_right_arm.yaml",
        Path(sys.prefix) / "share" / "semiparam_ros" / "config" / "icub_right_arm.yaml",
    ]
    return next((c for c in candidates if c.is_file()), None)


def load_evaluation_config(
    path: str | Path | None, overrides: Mapping[str, Any] | None = None
) -> EstimatorConfig:
    """Load a parameter file and apply overrides.

    Args:
        path: ROS 2 parameter file, or ``None`` for the shipped ``icub_right_arm.yaml`` (the parameter
            defaults if it cannot be found).
        overrides: Dotted names to values.

    Returns:
        The validated configuration.

    Raises:
        ValueError: On a bad file, unknown parameter or invalid value.
    """
    if path is None:
        path = default_config_path()
    config = load_config(path) if path is not None else EstimatorConfig.defaults()
    return config.with_overrides(dict(overrides)) if overrides else config


def evaluation_text(report: Any) -> str:
    """Return the tables ``evaluate`` prints for a protocol report.

    Args:
        report: A :class:`~semiparam_ros.eval.report.ProtocolReport`.

    Returns:
        Markdown: the group table (measured and, when known, noise-free), the per-component table (RMSE and
        nMSE per wrench axis or joint), the paper's criteria and the paired comparisons.
    """
    text = protocol_table(report)
    if report.noise is not None:
        text += "\nAgainst the noise-free outputs:\n\n" + protocol_table(report, truth=True)
        text += (
            "\nSensor noise (measured − noise-free): "
            + ", ".join(f"{g} {v:.3g} {report.output.groups[g].unit}" for g, v in report.noise.items())
            + "\n"
        )
    per = "joint" if report.output.kind == "joint_torques" else "axis"
    text += f"\nPer {per}, at regime:\n\n" + components_table(report)
    if report.checks:
        text += "\n" + checks_table(report.checks, report.first_s)
    if report.comparisons:
        text += "\nPaired over the test parts:\n\n" + comparisons_table(report.comparisons, report.first_s)
    return text


@dataclass(frozen=True)
class ReportPaths:
    """Where an evaluation writes (each None: not written).

    Attributes:
        json: The JSON report.
        markdown: The markdown tables (the text printed).
        plot: The figure (PNG).
        plot_truth: Paper protocol, simulated bags: the figure against the noise-free outputs.
        horizon_plot: Paper protocol with horizons: the error by the age of the model.
        per_sample: Paper protocol: every test sample's measured output, predictions and std (CSV).
        per_sample_plot: Paper protocol: measured vs predicted over time, one panel per component.
    """

    json: Path | None = None
    markdown: Path | None = None
    plot: Path | None = None
    plot_truth: Path | None = None
    horizon_plot: Path | None = None
    per_sample: Path | None = None
    per_sample_plot: Path | None = None


def _finish(report: Any, text: str, paths: ReportPaths) -> str:
    if paths.json is not None:
        write_json(report, paths.json)
    if paths.markdown is not None:
        atomic_write_text(paths.markdown, text)
    return text


def evaluate_paper(train: Path, test: Path, config: EstimatorConfig, *, topics: Topics | None = None,
                   models: Sequence[str] | None = None, options: ProtocolOptions | None = None,
                   horizons: Sequence[float | str] | None = None, paths: ReportPaths | None = None,
                   progress: bool = True, jobs: int = 1, cluster: str | None = None) -> str:
    """Run the paper's protocol: learners from zero, trained on ``train``, test-then-train on ``test``.

    Args:
        train: Training bag.
        test: Test bag.
        config: The configuration (:func:`load_evaluation_config`).
        topics: Topics to read (default from the configuration).
        models: Learners (default P, NP, SP; ``SPJ``: the joint fit whatever ``semiparametric.combination``
            says; ``SPC``: the paper's cascade).
        options: The protocol's parts, windows and limits (default :class:`ProtocolOptions`).
        horizons: Also score every model by its age (seconds, 0 = one step, ``"frozen"``;
            :mod:`semiparam_ros.eval.horizon`), written under ``"horizons"`` in the JSON.
        paths: Where to write the report, tables and figures (default: nowhere).
        progress: Show a progress bar (only when stderr is a terminal).
        jobs: Models run in parallel on this machine (the numbers do not depend on it).
        cluster: A Dask scheduler address or ``local:N``: one job per model there.

    Returns:
        The text to print (markdown tables).

    Raises:
        ValueError: On invalid arguments, configuration or bags.
    """
    topics = topics or Topics.from_config(config)
    paths = paths or ReportPaths()
    with recovery_notes() as recovered:
        result, info = evaluate_bags(train, test, config, topics=topics, kinds=models or KINDS,
                                     options=options, horizons=horizons, progress=progress, jobs=jobs,
                                     cluster=cluster)
    if recovered:  # a truncated or damaged bag was read as far as possible: the report says what was lost
        info["recovered_bags"] = recovered
    horizon = info.pop("horizons", None)
    if horizon is not None:
        info["horizons"] = horizon.to_json()
    report = protocol_report(result, config=config.to_flat(), protocol=info)
    text = evaluation_text(report)
    for note in recovered:
        text = f"WARNING: {note}\n\n" + text
    title = f"{Path(train).name} → {Path(test).name}"
    if horizon is not None:
        text += "\n## By the age of the model\n\n" + horizon_markdown(horizon)
        if paths.horizon_plot is not None:
            horizon_figure(horizon, paths.horizon_plot, title=title)
    if paths.plot is not None:
        plot_protocol(report, paths.plot)
    if paths.plot_truth is not None:
        plot_protocol(report, paths.plot_truth, truth=True)
    if paths.per_sample is not None:
        write_per_sample(result, paths.per_sample, config["uncertainty.noise_time_constant"])
    if paths.per_sample_plot is not None:
        per_sample_figure(result, paths.per_sample_plot, title=title)
    return _finish(report, text, paths)


def evaluate_payload(bag: Path, config: EstimatorConfig, *, topics: Topics | None = None,
                     models: Sequence[str] | None = None, forgetting: float = 0.995,
                     forgetting_nonparametric: float | None = None, pickup_time_s: float | None = None,
                     pretrain: Path | None = None, window_s: float = DEFAULT_WINDOW_S,
                     paths: ReportPaths | None = None, progress: bool = True) -> str:
    """Run the payload scenario: each learner with forgetting β and without, around the pickup.

    Args:
        bag: Bag with a payload pickup.
        config: The configuration.
        topics: Topics to read (default from the configuration).
        models: Learners (default SP).
        forgetting: β of the adaptive learners (parametric stage; residual stage too by default).
        forgetting_nonparametric: β of the adaptive learners' residual stage (default: ``forgetting``).
        pickup_time_s: Pickup time [s from the bag's first joint state]; default from its scenario.yaml.
        pretrain: Optional bag every learner is trained on first.
        window_s: Sliding window [s].
        paths: Where to write (``plot``: the recovery figure).
        progress: Show a progress bar.

    Returns:
        The text to print.

    Raises:
        ValueError: On invalid arguments, configuration or bags, or a missing pickup time.
    """
    result, info = evaluate_adaptation(bag, config, forgetting=forgetting,
                                       forgetting_nonparametric=forgetting_nonparametric,
                                       change_s=pickup_time_s, pretrain_path=pretrain, topics=topics,
                                       kinds=models or ("SP",), window_s=window_s, progress=progress)
    paths = paths or ReportPaths()
    stride = max(1, len(result.time_s) // 2000)  # ≤ 2000 curve points in the JSON; summaries use all
    report = adaptation_report(result, config=config.to_flat(), protocol=info, stride=stride)
    if paths.plot is not None:
        plot_adaptation(report, paths.plot)
    return _finish(report, adaptation_table(report), paths)


def evaluate_contacts(bag: Path, config: EstimatorConfig, *, topics: Topics | None = None,
                      paths: ReportPaths | None = None) -> str:
    """Run the node's estimator over a log with contact episodes, with the contact gate on and off.

    Args:
        bag: A log whose scenario.yaml lists its contact episodes (``simulate --scenario contacts``).
        config: The configuration.
        topics: Topics to read (default from the configuration).
        paths: Where to write (``plot``: the episodes and the gate's verdicts).

    Returns:
        The text to print (:mod:`semiparam_ros.eval.contacts`).

    Raises:
        ValueError: On invalid configuration or bag, or a bag without contact episodes.
    """
    topics = topics or Topics.from_config(config)
    paths = paths or ReportPaths()
    truth, runs = run_contacts(bag, config, topics=topics)
    report = contact_report(truth, runs, config, protocol={
        "bag": str(bag), "joint_states_topic": topics.joint_states, "wrench_topic": topics.wrench})
    if paths.plot is not None:
        plot_contacts(report, truth, runs, paths.plot, bag=bag, config=config)
    return _finish(report, contacts_table(report), paths)


def run_evaluate(*, train: Path | None, test: Path | None, payload: Path | None, config: Path | None,
                 contacts: Path | None = None, overrides: Mapping[str, Any] | None = None,
                 joint_states_topic: str | None = None, wrench_topic: str | None = None,
                 models: Sequence[str] | None = None, pickup_time_s: float | None = None,
                 forgetting: float = 0.995, forgetting_nonparametric: float | None = None,
                 horizons: Sequence[float | str] | None = None, progress: bool = True,
                 **options_and_paths: Any) -> str:
    """Run the evaluation chosen by which bag is given (deprecated).

    Call :func:`evaluate_paper`, :func:`evaluate_payload` or :func:`evaluate_contacts` instead.

    The remaining keywords are the fields of :class:`ProtocolOptions` (``splits``, ``window_s``, …) and of
    :class:`ReportPaths` with a ``_path`` suffix (``json_path``, ``plot_path``, …).

    Raises:
        ValueError: On invalid arguments, configuration or bags.
    """
    warnings.warn("run_evaluate is deprecated: use evaluate_paper, evaluate_payload or evaluate_contacts",
                  DeprecationWarning, stacklevel=2)
    opts = {k: v for k, v in options_and_paths.items() if not k.endswith("_path")}
    paths = ReportPaths(**{k[: -len("_path")]: v for k, v in options_and_paths.items()
                           if k.endswith("_path")})
    cfg = load_evaluation_config(config, overrides)
    topics = Topics.from_config(cfg, joint_states_topic, wrench_topic)
    if contacts is not None:
        return evaluate_contacts(contacts, cfg, topics=topics, paths=paths)
    if payload is not None:
        return evaluate_payload(payload, cfg, topics=topics, models=models, forgetting=forgetting,
                                forgetting_nonparametric=forgetting_nonparametric,
                                pickup_time_s=pickup_time_s, pretrain=train,
                                window_s=opts.get("window_s", DEFAULT_WINDOW_S), paths=paths,
                                progress=progress)
    if train is None or test is None:
        raise ValueError("the paper protocol needs --train and --test")
    return evaluate_paper(train, test, cfg, topics=topics, models=models, options=ProtocolOptions(**opts),
                          horizons=horizons, paths=paths, progress=progress)


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
        grid: Values per tuned key (hold-out: :data:`~semiparam_ros.eval.selection.DEFAULT_GRID` for missing
            keys; protocol: the configuration's value for missing keys).
        limit: Use only the first samples of the bag.
        out: Destination of the tuned ROS 2 parameter file (for ``kind``).
        json_path: Destination of the search as JSON (the selection per learner; protocol: the runs' scalars).
        progress: Show a progress bar (only when stderr is a terminal).
        kind: Learner whose selection is written to ``out``: ``"SP"`` (as configured) or ``"SPJ"`` (the joint
            fit; the written file then selects ``semiparametric.combination: joint``).
        method: ``"holdout"`` or ``"protocol"`` (:mod:`semiparam_ros.eval.selection`).
        kinds: Protocol method: learners run at every grid point (default: ``kind`` only).
        train_n: Protocol method: training samples (default: half the stream).
        splits: Protocol method: test parts.
        split_size: Protocol method: samples per part.
        window_s: Protocol method: sliding window [s].
        jobs: Parallel jobs (-1: all cores); the numbers do not depend on it.
        validate: Validation bags: select by held-out motion (:mod:`semiparam_ros.eval.validation`; the
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
    """``tune --train A… --validate B…``: selection by held-out motion (eval/validation.py)."""
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
