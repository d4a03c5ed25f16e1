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

from semiparam_ros.core.config import EstimatorConfig, load_config, write_config
from semiparam_ros.eval.compare import comparison_markdown, paired_comparisons
from semiparam_ros.eval.figures import plot_adaptation, plot_protocol
from semiparam_ros.eval.replay import KINDS, Topics, evaluate_adaptation, evaluate_bags, load_samples
from semiparam_ros.eval.report import (
    CHECKED_SP_KINDS,
    adaptation_markdown,
    adaptation_report,
    paper_checks,
    protocol_markdown,
    protocol_report,
    write_json,
)
from semiparam_ros.eval.tuning import TUNED_KEYS, grid_markdown, tune

__all__ = ["checks_markdown", "default_config_path", "load_evaluation_config", "run_evaluate", "run_tune"]


def default_config_path() -> Path | None:
    """Return the shipped ``icub_right_arm.yaml``: the source tree's, else the installed share copy.

    Returns:
        The path, or ``None`` when neither exists (the parameter defaults are then used).
    """
    candidates = [Path(__file__).resolve().parents[2] / "config" / "icub_right_arm.yaml",
                  Path(sys.prefix) / "share" / "semiparam_ros" / "config" / "icub_right_arm.yaml"]
    return next((c for c in candidates if c.is_file()), None)


def load_evaluation_config(path: str | Path | None, overrides: Mapping[str, Any] | None = None
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


def checks_markdown(checks: Sequence[Mapping[str, Any]]) -> str:
    """Markdown table of :func:`~semiparam_ros.eval.report.paper_checks` results.

    One row per criterion; the criteria of SP and of SPJ (the joint fit) are separate rows named by their
    model.
    """
    lines = ["| criterion | value | limit | |", "|---|---|---|---|"]
    for c in checks:
        op = "<" if "first" in c["check"] else "≤"
        lines.append(f"| {c['check']} | {c['value']:.3f} | {op} {c['limit']:g} | "
                     f"{'pass' if c['passed'] else 'FAIL'} |")
    return "\n".join(lines) + "\n"


def run_evaluate(*, train: Path | None, test: Path | None, payload: Path | None, config: Path | None,
                 overrides: Mapping[str, Any] | None = None, joint_states_topic: str | None = None,
                 wrench_topic: str | None = None, models: Sequence[str] | None = None, splits: int = 10,
                 split_size: int | None = None, window_s: float = 3.0, train_limit: int | None = None,
                 test_limit: int | None = None, test_skip: int = 0, pickup_time_s: float | None = None,
                 forgetting: float = 0.995,
                 forgetting_nonparametric: float | None = None,
                 json_path: Path | None = None, plot_path: Path | None = None,
                 plot_truth_path: Path | None = None, markdown_path: Path | None = None,
                 progress: bool = True) -> str:
    """Run an evaluation and write its outputs.

    Args:
        train: Training bag (paper protocol) or optional pre-training bag (payload scenario).
        test: Test bag (paper protocol).
        payload: Payload bag (adaptation scenario); exclusive with ``test``.
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
        progress: Show a progress bar.

    Returns:
        The text to print (markdown tables).

    Raises:
        ValueError: On invalid arguments, configuration or bags.
    """
    cfg = load_evaluation_config(config, overrides)
    topics = Topics.from_config(cfg, joint_states_topic, wrench_topic)
    if payload is not None:
        result, info = evaluate_adaptation(payload, cfg, forgetting=forgetting,
                                           forgetting_nonparametric=forgetting_nonparametric,
                                           change_s=pickup_time_s,
                                           pretrain_path=train, topics=topics, kinds=models or ("SP",),
                                           window_s=window_s, progress=progress)
        stride = max(1, len(result.time_s) // 2000)  # ≤ 2000 curve points in the JSON; summaries use all
        report = adaptation_report(result, config=cfg.to_flat(), protocol=info, stride=stride)
        text = adaptation_markdown(report)
        if plot_path is not None:
            plot_adaptation(report, plot_path)
    else:
        if train is None or test is None:
            raise ValueError("the paper protocol needs --train and --test")
        result, info = evaluate_bags(train, test, cfg, topics=topics, kinds=models or KINDS, splits=splits,
                                     split_size=split_size, window_s=window_s, train_limit=train_limit,
                                     test_limit=test_limit, test_skip=test_skip, progress=progress)
        report = protocol_report(result, config=cfg.to_flat(), protocol=info)
        text = protocol_markdown(report)
        if "ground_truth" in next(iter(report["models"].values())):
            text += "\nAgainst the noise-free wrench:\n\n" + protocol_markdown(report, truth=True)
            text += (f"\nSensor noise (measured − noise-free): force {report['noise']['force_rmse']:.3g} N, "
                     f"torque {report['noise']['torque_rmse']:.3g} N·m\n")
        names = set(report["models"])
        if ({"P", "NP"} <= names and names & set(CHECKED_SP_KINDS)
                and "force_rmse" in report["models"]["P"]):
            report["checks"] = paper_checks(report)
            text += "\n" + checks_markdown(report["checks"])
        report["comparisons"] = paired_comparisons(report)
        if report["comparisons"]:
            text += "\nPaired over the test parts:\n\n" + comparison_markdown(report["comparisons"])
        if plot_path is not None:
            plot_protocol(report, plot_path)
        if plot_truth_path is not None:
            plot_protocol(report, plot_truth_path, truth=True)
    if json_path is not None:
        write_json(report, json_path)
    if markdown_path is not None:
        markdown_path.parent.mkdir(parents=True, exist_ok=True)
        markdown_path.write_text(text)
    return text


def run_tune(*, train: Path, config: Path | None, overrides: Mapping[str, Any] | None = None,
             joint_states_topic: str | None = None, wrench_topic: str | None = None,
             n_features: int | None = None, holdout: float = 0.2,
             grid: Mapping[str, Sequence[float]] | None = None, limit: int | None = None,
             out: Path | None = None,
             json_path: Path | None = None, progress: bool = True, kind: str = "SP") -> str:
    """Run the hold-out grid search on a bag and write the tuned parameter file.

    Args:
        train: Training bag (its last ``holdout`` fraction is held out).
        config: Parameter file (``None``: the shipped one).
        overrides: Parameter overrides applied before tuning.
        joint_states_topic: JointState topic (default from the configuration).
        wrench_topic: WrenchStamped topic (default from the configuration).
        n_features: D (default: the configuration's).
        holdout: Held-out fraction.
        grid: Values per tuned key (default: :data:`~semiparam_ros.eval.tuning.DEFAULT_GRID`).
        limit: Use only the first samples of the bag.
        out: Destination of the tuned ROS 2 parameter file.
        json_path: Destination of the grid as JSON.
        progress: Show a progress bar.
        kind: Learner to tune: ``"SP"`` (as configured) or ``"SPJ"`` (the joint fit; the written file then
            selects ``semiparametric.combination: joint``).

    Returns:
        The text to print (the grid and the selection).

    Raises:
        ValueError: On invalid arguments, configuration or bag.
    """
    cfg = load_evaluation_config(config, overrides)
    topics = Topics.from_config(cfg, joint_states_topic, wrench_topic)
    data, drops = load_samples(train, cfg, topics, limit=limit)
    result = tune(cfg, data, holdout=holdout, n_features=n_features, grid=grid, kind=kind,
                  progress=progress)
    chosen = ", ".join(f"{k} = {result.best[k]:g}" for k in TUNED_KEYS)
    text = (f"hold-out grid search of {kind} on {train}: {result.n_train} samples learned, "
            f"{result.n_holdout} held out, "
            f"D = {result.config['nonparametric.n_features']}\n\n" + grid_markdown(result)
            + f"\nselected: {chosen} (hold-out nRMSE {result.best['score']:.4f}; "
            f"the configuration's values: {result.default['score']:.4f})\n")
    if out is not None:
        write_config(result.config, out, header=(
            f"semiparam_ros estimator parameters tuned by `tune` ({kind}) on {train}\n"
            f"hold-out {holdout:g} ({result.n_holdout} samples): nRMSE {result.best['score']:.4f} "
            f"(base configuration {result.default['score']:.4f})"))
        text += f"wrote {out}\n"
    if json_path is not None:
        write_json({"grid": result.grid, "best": result.best, "default": result.default,
                    "n_train": result.n_train, "n_holdout": result.n_holdout, "drops": drops, "kind": kind,
                    "config": result.config.to_flat()}, json_path)
    return text
