"""What the ``evaluate`` command does, as a library call (the CLI only parses arguments).

:func:`run_evaluate` loads the configuration, reads the bags through the node's pipeline, runs the paper's
protocol or the payload scenario, writes the JSON report, the figure(s) and the markdown table, and
returns the text printed on the terminal.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from semiparam_ros.atomic import atomic_write_text
from semiparam_ros.core.config import EstimatorConfig, load_config, write_config
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.contacts import contact_report, run_contacts
from semiparam_ros.eval.figures import plot_adaptation, plot_contacts, plot_protocol
from semiparam_ros.eval.horizon import horizon_figure, horizon_markdown
from semiparam_ros.eval.per_sample import per_sample_figure, write_per_sample
from semiparam_ros.eval.replay import KINDS, Topics, evaluate_adaptation, evaluate_bags, load_samples
from semiparam_ros.eval.report import adaptation_report, protocol_report, write_json
from semiparam_ros.eval.selection import TUNED_KEYS, grid_table, holdout_search, protocol_search
from semiparam_ros.eval.tables import (
    adaptation_table,
    checks_table,
    comparisons_table,
    components_table,
    contacts_table,
    protocol_table,
)
from semiparam_ros.io.bags import recovery_notes

__all__ = ["default_config_path", "evaluation_text", "load_evaluation_config", "run_evaluate", "run_tune"]


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


def run_evaluate(
    *,
    train: Path | None,
    test: Path | None,
    payload: Path | None,
    config: Path | None,
    contacts: Path | None = None,
    overrides: Mapping[str, Any] | None = None,
    joint_states_topic: str | None = None,
    wrench_topic: str | None = None,
    models: Sequence[str] | None = None,
    splits: int = 10,
    split_size: int | None = None,
    window_s: float = 3.0,
    first_s: float = 3.0,
    train_limit: int | None = None,
    test_limit: int | None = None,
    test_skip: int = 0,
    pickup_time_s: float | None = None,
    forgetting: float = 0.995,
    forgetting_nonparametric: float | None = None,
    json_path: Path | None = None,
    plot_path: Path | None = None,
    plot_truth_path: Path | None = None,
    markdown_path: Path | None = None,
    horizons: Sequence[float | str] | None = None,
    horizon_plot_path: Path | None = None,
    per_sample_path: Path | None = None,
    per_sample_plot_path: Path | None = None,
    progress: bool = True,
) -> str:
    """Run an evaluation and write its outputs.

    Args:
        train: Training bag (paper protocol) or optional pre-training bag (payload scenario).
        test: Test bag (paper protocol).
        payload: Payload bag (adaptation scenario); exclusive with ``test``.
        contacts: Bag with contact episodes (contact evaluation: the estimator with the gate on and off,
            :mod:`semiparam_ros.eval.contacts`); exclusive with ``test`` and ``payload``.
        config: Parameter file (``None``: the shipped one).
        overrides: Parameter overrides.
        joint_states_topic: JointState topic (default from the configuration).
        wrench_topic: WrenchStamped topic (default from the configuration).
        models: Learners (default P, NP, SP; SP for the payload scenario); ``SPJ`` is the joint
            semiparametric fit whatever ``semiparametric.combination`` says (its criteria are checked
            separately from SP's).
        splits: Number of test parts.
        split_size: Samples per part (``None``: equal parts).
        window_s: Sliding window [s].
        first_s: Initial segment reported separately [s].
        train_limit: Use only the first training samples.
        test_limit: Use only the first test samples.
        test_skip: Drop this many samples at the start of the test bag.
        pickup_time_s: Payload pickup time [s]; default from the bag's ``scenario.yaml``.
        forgetting: β of the adaptive learners (parametric stage; residual stage too by default).
        forgetting_nonparametric: β of the adaptive learners' residual stage (default: ``forgetting``).
        json_path: JSON report destination.
        plot_path: Figure destination.
        plot_truth_path: Figure against the noise-free wrench (paper protocol, simulated bags).
        markdown_path: Markdown table destination.
        horizons: Paper protocol: also score every model by its age (seconds, 0 = one step, ``"frozen"``;
            :mod:`semiparam_ros.eval.horizon`), written under ``"horizons"`` in the JSON.
        horizon_plot_path: Figure of the error by the age of the model (with ``horizons``).
        per_sample_path: Paper protocol: every test sample's measured output and each model's prediction
            and std, as CSV (:mod:`semiparam_ros.eval.per_sample`).
        per_sample_plot_path: Paper protocol: measured vs predicted over time, one panel per component.
        progress: Show a progress bar (only when stderr is a terminal).

    Returns:
        The text to print (markdown tables).

    Raises:
        ValueError: On invalid arguments, configuration or bags.
    """
    cfg = load_evaluation_config(config, overrides)
    topics = Topics.from_config(cfg, joint_states_topic, wrench_topic)
    if contacts is not None:
        truth, runs = run_contacts(contacts, cfg, topics=topics)
        report_c = contact_report(truth, runs, cfg, protocol={
            "bag": str(contacts), "joint_states_topic": topics.joint_states, "wrench_topic": topics.wrench})
        text = contacts_table(report_c)
        if plot_path is not None:
            plot_contacts(report_c, truth, runs, plot_path, bag=contacts, config=cfg)
        report: Any = report_c
    elif payload is not None:
        result, info = evaluate_adaptation(
            payload,
            cfg,
            forgetting=forgetting,
            forgetting_nonparametric=forgetting_nonparametric,
            change_s=pickup_time_s,
            pretrain_path=train,
            topics=topics,
            kinds=models or ("SP",),
            window_s=window_s,
            progress=progress,
        )
        stride = max(1, len(result.time_s) // 2000)  # ≤ 2000 curve points in the JSON; summaries use all
        adaptation = adaptation_report(result, config=cfg.to_flat(), protocol=info, stride=stride)
        text = adaptation_table(adaptation)
        if plot_path is not None:
            plot_adaptation(adaptation, plot_path)
        report = adaptation
    else:
        if train is None or test is None:
            raise ValueError("the paper protocol needs --train and --test")
        with recovery_notes() as recovered:
            result, info = evaluate_bags(
                train,
                test,
                cfg,
                topics=topics,
                kinds=models or KINDS,
                splits=splits,
                split_size=split_size,
                window_s=window_s,
                first_s=first_s,
                train_limit=train_limit,
                test_limit=test_limit,
                test_skip=test_skip,
                horizons=horizons,
                progress=progress,
            )
        if recovered:
            # a truncated or damaged bag was read as far as possible: the report says so, with what was lost
            info["recovered_bags"] = recovered
        horizon = info.pop("horizons", None)
        if horizon is not None:
            info["horizons"] = horizon.to_json()
        report = protocol_report(result, config=cfg.to_flat(), protocol=info)
        text = evaluation_text(report)
        for note in recovered:
            text = f"WARNING: {note}\n\n" + text
        if horizon is not None:
            text += "\n## By the age of the model\n\n" + horizon_markdown(horizon)
            if horizon_plot_path is not None:
                horizon_figure(horizon, horizon_plot_path, title=f"{Path(train).name} → {Path(test).name}")
        if plot_path is not None:
            plot_protocol(report, plot_path)
        if plot_truth_path is not None:
            plot_protocol(report, plot_truth_path, truth=True)
        if per_sample_path is not None:
            write_per_sample(result, per_sample_path, cfg["uncertainty.noise_time_constant"])
        if per_sample_plot_path is not None:
            per_sample_figure(result, per_sample_plot_path, title=f"{Path(train).name} → {Path(test).name}")
    if json_path is not None:
        write_json(report, json_path)
    if markdown_path is not None:
        atomic_write_text(markdown_path, text)
    return text


def run_tune(
    *,
    train: Path,
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
    window_s: float = 3.0,
    jobs: int = 1,
) -> str:
    """Select hyperparameters on a training bag and write the tuned parameter file.

    Args:
        train: Training bag.
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

    Returns:
        The text to print (the grid and the selection).

    Raises:
        ValueError: On invalid arguments, configuration or bag.
    """
    cfg = load_evaluation_config(config, overrides)
    topics = Topics.from_config(cfg, joint_states_topic, wrench_topic)
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
    chosen = selections[kind]
    text = ""
    for k, sel in selections.items():
        text += (
            f"{method} search of {k} on {train}: {sel.n_train} samples learned, {sel.n_test} scored, "
            f"D = {sel.config['nonparametric.n_features']}\n\n" + grid_table(sel) + "\n"
        )
    values = ", ".join(f"{k} = {chosen.best.values[k]:g}" for k in TUNED_KEYS)
    base = "n/a" if chosen.default is None else f"{chosen.default.score:.4f}"
    text += (
        f"selected for {kind}: {values} (score {chosen.best.score:.4f}; the configuration's values: {base})\n"
    )
    if out is not None:
        write_config(
            chosen.config,
            out,
            header=(
                f"semiparam_ros estimator parameters tuned by `tune --method {method}` ({kind}) on {train}\n"
                f"score {chosen.best.score:.4f} (base configuration {base})"
            ),
        )
        text += f"wrote {out}\n"
    if json_path is not None:
        write_json(
            {
                "method": method,
                "kind": kind,
                "drops": drops,
                "holdout": holdout if method == "holdout" else None,
                "selections": {k: s.to_json() for k, s in selections.items()},
                **doc,
            },
            json_path,
        )
    return text
