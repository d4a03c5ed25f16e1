"""What the ``evaluate`` command does, as library calls (the CLI only parses arguments).

:func:`evaluate_paper`, :func:`evaluate_payload` and :func:`evaluate_contacts` read the bags through the
node's pipeline, run the paper's protocol, the payload scenario or the contact test, write the JSON report,
the figure(s) and the markdown table, and return the text printed on the terminal.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from semiparam_ros.atomic import atomic_write_text
from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.eval.bags.contact_detection import contact_report, run_contacts
from semiparam_ros.eval.bags.replay import KINDS, Topics, evaluate_adaptation, evaluate_bags
from semiparam_ros.eval.protocol.horizon import (
    HEADLINE_HORIZONS,
    horizon_figure,
    horizon_markdown,
)
from semiparam_ros.eval.protocol.options import DEFAULT_WINDOW_S, ProtocolOptions
from semiparam_ros.eval.protocol.report import adaptation_report, protocol_report
from semiparam_ros.io.bags import recovery_notes
from semiparam_ros.plain_json import write_json
from semiparam_ros.report.figures import plot_adaptation, plot_contacts, plot_protocol
from semiparam_ros.report.per_sample import per_sample_figure, write_per_sample
from semiparam_ros.report.tables import (
    adaptation_table,
    checks_table,
    comparisons_table,
    components_table,
    contacts_table,
    controller_section,
    protocol_table,
)

__all__ = [
    "ReportPaths", "evaluate_contacts", "evaluate_paper", "evaluate_payload", "evaluation_text",
]


def evaluation_text(report: Any) -> str:
    """Return the tables ``evaluate`` prints for a protocol report.

    Args:
        report: A :class:`~semiparam_ros.eval.protocol.report.ProtocolReport`.

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
    per = "joint" if report.output.kind == OutputKind.JOINT_TORQUES else "axis"
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
            :mod:`semiparam_ros.eval.protocol.horizon`), written under ``"horizons"`` in the JSON and
            tabled. ``None``: joint torques are scored frozen and one step ahead (the headline table, what
            a controller gets, printed first); a wrench (the paper's set-up) is not.
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
    torques = config.output_kind == OutputKind.JOINT_TORQUES
    asked = horizons is not None
    if torques and horizons is None:  # lead with what a controller gets: frozen, beside one step ahead
        horizons = HEADLINE_HORIZONS
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
    text = "## One step ahead (test-then-train, the paper's protocol)\n\n" + evaluation_text(report)
    text = controller_section(horizon, report.output.kind.unit) + text
    for note in recovered:
        text = f"WARNING: {note}\n\n" + text
    title = f"{Path(train).name} → {Path(test).name}"
    if horizon is not None and asked:
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
        The text to print (:mod:`semiparam_ros.eval.bags.contact_detection`).

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
