"""Markdown tables of the typed reports: what ``evaluate``/``tune`` print and the results page embeds.

Each function renders one record type into a table (numbers and short labels only); the words around the
tables live in ``docs/`` (``docs/tools/pages.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.eval.bags.contact_detection import ContactReport
from semiparam_ros.eval.protocol.compare import Comparison, format_p
from semiparam_ros.eval.protocol.horizon import FROZEN, HorizonReport
from semiparam_ros.eval.protocol.metrics import GROUP_UNITS
from semiparam_ros.eval.protocol.options import DEFAULT_FIRST_S
from semiparam_ros.eval.protocol.report import AdaptationReport, Check, ProtocolReport

__all__ = [
    "adaptation_table",
    "checks_table",
    "comparisons_table",
    "components_table",
    "contacts_table",
    "controller_section",
    "fmt",
    "headline_markdown",
    "protocol_table",
    "slices_markdown",
]

_DIRECTION = {"ahead": "A ahead", "behind": "A behind", "tie": "not separable"}


def fmt(value: float | None, std: float | None = None) -> str:
    """Three significant digits (``n/a`` for None/NaN), with ``± std`` to two when given."""
    if value is None or not math.isfinite(value):
        return "n/a"
    text = f"{value:.3g}" if abs(value) < 1000 else f"{value:.0f}"
    return text if std is None or not math.isfinite(std) else f"{text} ± {std:.2g}"


def _label(report: ProtocolReport, group: str) -> tuple[str, str]:
    g = report.output.groups[group]
    extra = " (mean over joints)" if report.output.kind == OutputKind.JOINT_TORQUES else ""
    return f"{g.label} RMSE{extra}", g.unit


def protocol_table(report: ProtocolReport, truth: bool = False) -> str:
    """Per model: each group's RMSE at regime and over the first seconds (mean ± std over splits).

    Args:
        report: The protocol report.
        truth: Against the noise-free outputs instead of the measured ones.

    Returns:
        The table with a trailing newline.
    """
    header = ["model"]
    for segment in ("regime", "first"):
        where = "at regime" if segment == "regime" else f"first {report.first_s:g} s"
        for group in report.groups:
            name, unit = _label(report, group)
            header.append(f"{name} {where} [{unit}]")
    header.append("update [µs]")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for kind in report.models:
        stats = report.stats(kind, truth)
        if stats is None:
            continue
        row = [kind]
        for segment in ("regime", "first"):
            for group in report.groups:
                s = stats.groups[group].segment(segment)
                row.append(fmt(s.mean, s.std))
        row.append(fmt(report.update_us[kind]["median"]))
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def components_table(report: ProtocolReport, truth: bool = False) -> str:
    """Per model and output component (wrench axis or joint): RMSE at regime [unit] and nMSE.

    For joint torques the last columns are the means over joints. Empty string when the report has no
    per-component values.
    """
    names = report.output.components
    units = report.output.units
    rows = [(k, report.stats(k, truth)) for k in report.models]
    rows = [(k, s) for k, s in rows if s is not None and s.components]
    if not rows:
        return ""
    header = [
        "model",
        *(f"{n} RMSE [{u}]" for n, u in zip(names, units, strict=True)),
        *(f"{n} nMSE" for n in names),
    ]
    joints = report.output.kind == OutputKind.JOINT_TORQUES
    if joints:
        header += ["mean RMSE [N·m]", "mean nMSE"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for kind, s in rows:
        cells = [
            kind,
            *(fmt(s.components[n].rmse) for n in names),
            *(fmt(s.components[n].nmse) for n in names),
        ]
        if joints:
            cells += [fmt(s.rmse_mean), fmt(s.nmse_mean)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def checks_table(checks: Sequence[Check], first_s: float = DEFAULT_FIRST_S, *,
                 tie_margin: float | None = None) -> str:
    """One row per criterion: its name, value, limit and pass/FAIL.

    Args:
        checks: The criteria.
        first_s: Length of the initial segment [s] (for the names).
        tie_margin: If given, a passed criterion within this fraction of its limit is marked as a tie.

    Returns:
        The table with a trailing newline.
    """
    lines = ["| criterion | id | value | limit | |", "|---|---|---|---|---|"]
    for c in checks:
        verdict = "pass" if c.passed else "FAIL"
        if c.passed and tie_margin is not None and c.value > (1 - tie_margin) * c.limit:
            verdict = f"pass, but a tie (within {100 * tie_margin:g} % of the limit)"
        op = "<" if c.strict else "≤"
        limit = f"{op} {c.limit:g}"
        if c.paired_p is not None:
            limit += f" or not behind (paired p = {c.paired_p:.2g})"
        lines.append(f"| {c.label(first_s)} | `{c.id}` | {c.value:.3f} | {limit} | {verdict} |")
    return "\n".join(lines) + "\n"


def comparisons_table(rows: Sequence[Comparison], first_s: float = DEFAULT_FIRST_S, *,
                      level: bool = False) -> str:
    """Paired comparisons: ratio, mean difference ± s.e., wins, p-values and the verdict at 5 %.

    Args:
        rows: The comparisons.
        first_s: Length of the initial segment [s] (for the labels).
        level: Add the column saying over what the pairs run (parts, seeds, pooled parts).

    Returns:
        The table with a trailing newline (empty string for no rows).
    """
    if not rows:
        return ""
    head = [
        "A vs B",
        "target",
        "group",
        "segment",
        *(["level"] if level else []),
        "mean ratio",
        "mean A − B ± s.e.",
        "A better in",
        "p (paired t)",
        "p (sign)",
        "at 5 %",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        s = r.stats
        seg = "at regime" if r.segment == "regime" else f"first {first_s:g} s"
        sem = "n/a" if s.diff_sem is None else f"{s.diff_sem:.2g}"
        cells = [
            f"{r.a} vs {r.b}",
            "noise-free" if r.truth else "measured",
            r.group,
            seg,
            *([r.level] if level else []),
            f"{s.ratio:.4f}",
            f"{s.diff_mean:+.2g} ± {sem} {GROUP_UNITS.get(r.group, '')}",
            f"{s.wins} of {s.n}",
            format_p(s.p_t),
            format_p(s.p_sign),
            _DIRECTION[s.direction()],
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def adaptation_table(report: AdaptationReport) -> str:
    """Per model and group: pre-change level, peak, level at the deadline, recovery time."""
    deadline, tol = report.deadline_s, report.tolerance
    header = [
        "model",
        "group",
        "pre-change RMSE",
        "peak",
        f"at +{deadline:g} s (ratio)",
        f"RMSE after +{deadline:g} s",
        f"back within {tol:g}× at",
        f"recovered ≤ {deadline:g} s",
    ]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for kind, groups in report.summary.items():
        for group, s in groups.items():
            rec = s.recovery_time_s
            unit = report.output.groups[group].unit
            lines.append(
                "| "
                + " | ".join(
                    [
                        kind,
                        f"{group} [{unit}]",
                        fmt(s.pre_rmse),
                        fmt(s.peak),
                        f"{fmt(s.level_at_deadline)} ({s.ratio_at_deadline:.2f}×)",
                        fmt(s.post_rmse),
                        "never" if rec is None else f"+{rec:.1f} s",
                        "yes" if s.recovered else "no",
                    ]
                )
                + " |"
            )
    return "\n".join(lines) + "\n"


def contacts_table(report: ContactReport) -> str:
    """Gate on and off: detection per episode summarized, error after vs before the contacts, payload.

    Args:
        report: A :class:`~semiparam_ros.eval.bags.contact_detection.ContactReport`.

    Returns:
        Markdown: one summary table (a row per gate setting) and one row per episode.
    """
    groups = list(report.output.groups)
    first = groups[0]
    header = ["gate", "recall", f"recall ≥ {report.strong_force:g} N", "false alarms / min",
              "median delay [s]"]
    for g in groups:
        u = report.output.groups[g].unit
        header += [f"{g} before [{u}]", f"{g} after [{u}]", f"{g} after/before"]
    header += [f"{first} adopted [s]", f"{first} back within tolerance [s]"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for key, r in report.runs.items():
        row = [key, f"{r.recall:.2f}", f"{r.recall_strong:.2f}", f"{r.false_alarms_per_minute:.2f}",
               f"{r.median_delay_s:.3f}"]
        for g in groups:
            row += [fmt(r.before[g]), fmt(r.after[g]), f"{r.ratio(g):.3f}"]
        adopt = None if r.adoption_s is None else r.adoption_s[first]
        rec = None if r.recovery is None else r.recovery[first].recovery_time_s
        row += ["n/a" if r.adoption_s is None else ("never" if adopt is None else f"{adopt:.1f}"),
                "n/a" if r.recovery is None else ("never" if rec is None else f"{rec:.1f}")]
        lines.append("| " + " | ".join(row) + " |")
    text = "\n".join(lines) + "\n"
    keys = list(report.runs)
    ep_header = ["episode", "start [s]", "duration [s]", "peak [N]"] + [f"delay, gate {k} [s]" for k in keys]
    lines = ["| " + " | ".join(ep_header) + " |", "|" + "---|" * len(ep_header)]
    for i, e in enumerate(report.runs[keys[0]].episodes):
        row = [str(i + 1), f"{e.start_s:.2f}", f"{e.end_s - e.start_s:.2f}", f"{e.peak_force:.1f}"]
        for k in keys:
            ek = report.runs[k].episodes[i]
            row.append(f"{ek.delay_s:.3f}" if ek.detected else "missed")
        lines.append("| " + " | ".join(row) + " |")
    return text + "\nPer episode:\n\n" + "\n".join(lines) + "\n"


def headline_markdown(report: HorizonReport, unit: str) -> str:
    """Render what a controller gets: each model frozen (served) beside one step ahead, persistence too.

    The frozen column is the model learned on the training log and nothing after — what ``load_model``
    and the node's feed-forward serve on motion they have not seen; one step ahead is the paper's
    test-then-train, where the previous measured output (persistence) is the baseline any learning must
    beat. Needs the ``"1 step"`` and ``"frozen"`` horizons
    (:data:`~semiparam_ros.eval.protocol.horizon.HEADLINE_HORIZONS`).

    Args:
        report: A :class:`~semiparam_ros.eval.protocol.horizon.HorizonReport` with both horizons.
        unit: Unit of the outputs (for the title).

    Returns:
        Markdown ('' when a horizon is missing).
    """
    labels = {h.label for h in report.horizons}
    if not {"1 step", FROZEN} <= labels:
        return ""
    rows = []
    for model in report.rmse:
        if model == "persistence":
            frozen = "—"
            name = "persistence (the previous measured output)"
        else:
            frozen = f"{report.mean(model, FROZEN):.3f}"
            name = "CAD (the URDF, never learns)" if model == "CAD" else model
        rows.append(f"| {name} | {frozen} | {report.mean(model, '1 step'):.3f} |\n")
    return (f"Mean RMSE over the outputs [{unit}] on the test log:\n\n"
            "| model | frozen: served, as a feed-forward uses it | one step ahead: test-then-train |\n"
            "|---|---|---|\n" + "".join(rows)
            + "\nFrozen: learned on the training log only, predicts the test log from the state "
            "(`load_model(...).predict`, the node's feed-forward). One step ahead: learned every test sample "
            "up to the previous one (the paper's protocol); there the previous measured output is "
            "already accurate, so compare with persistence.\n")


def slices_markdown(report: HorizonReport, unit: str, horizon: str = FROZEN,
                    coverage: dict[str, dict[str, float]] | None = None) -> str:
    """Render each model's mean RMSE by motion state at one horizon (frozen: what a controller gets).

    Args:
        report: A :class:`~semiparam_ros.eval.protocol.horizon.HorizonReport` with slices.
        unit: Unit of the outputs.
        horizon: The horizon's label (``"frozen"`` or ``"1 step"``).
        coverage: Per model, the ±2σ coverage by slice of its served model, or None.

    Returns:
        Markdown ('' when the report has no slices at that horizon).
    """
    from semiparam_ros.eval.protocol.slices import SLICES

    rows = [(m, v[horizon]) for m, v in report.slices.items() if horizon in v and m != "persistence"]
    if not rows:
        return ""
    share = report.slice_share
    head = ("| model | " + " | ".join(f"{s} ({100 * share.get(s, 0.0):.0f} %)" for s in SLICES) + " | all |\n"
            + "|---" * (len(SLICES) + 2) + "|\n")
    body = "".join(f"| {m} | " + " | ".join(f"{v[s]:.3f}" for s in SLICES)
                   + f" | {report.mean(m, horizon):.3f} |\n" for m, v in rows)
    text = (f"By motion state, {horizon} [{unit}] (per joint by its own velocity: at rest < 0.01 rad/s, "
            "reversals ± 0.2 s of a sign change, slow < 0.2 rad/s, fast; share of the samples in "
            "brackets):\n\n" + head + body)
    if coverage:
        text += ("\n±2σ coverage of the served model by motion state:\n\n| model | "
                 + " | ".join(SLICES) + " | all |\n" + "|---" * (len(SLICES) + 2) + "|\n"
                 + "".join(f"| {m} | " + " | ".join(f"{c[s]:.3f}" for s in SLICES) + f" | {c['all']:.3f} |\n"
                           for m, c in coverage.items()))
    return text


def controller_section(report: HorizonReport | None, unit: str,
                       coverage: dict[str, dict[str, float]] | None = None) -> str:
    """Return the section that leads a joint-torque report: what a controller gets, by motion state too.

    Args:
        report: The horizon report (frozen and one step ahead), or None.
        unit: Unit of the outputs.
        coverage: Per model, the served model's ±2σ coverage by slice, or None.

    Returns:
        Markdown ending with a blank line ('' without the two horizons).
    """
    headline = "" if report is None else headline_markdown(report, unit)
    if not headline:
        return ""
    assert report is not None
    sliced = slices_markdown(report, unit, coverage=coverage)
    return "## What a controller gets\n\n" + headline + "\n" + sliced + "\n"
