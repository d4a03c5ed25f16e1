"""Figures of the evaluation (matplotlib, Agg backend; no display needed).

:func:`plot_protocol` draws the paper's Fig. 3: force (top) and torque (bottom) windowed RMSE against the
time from the start of each test split on a log axis, mean over splits as a line and ± one standard
deviation shaded, P green, NP red, SP blue (and SPJ, the joint semiparametric fit, purple, labelled
"SP joint"). :func:`plot_adaptation` draws the payload scenario: windowed
force and torque RMSE against the time from the pickup, one line per model (with and without adaptation),
the pre-pickup level and the recovery tolerance band. :func:`plot_contacts` draws the last contact before
a payload pickup and the pickup on one time axis: the measured output, the predictions with the gate on and
off, and the external estimate (gate on) with its ±2σ band and, for simulated logs, the true external
effect. Groups, units and axis labels come from the report's
output kind (``robot.output``): force and torque for a wrench, joint torque (mean over joints) otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # before pyplot: headless, deterministic PNGs

import matplotlib.pyplot as plt
import numpy as np

from semiparam_ros.atomic import atomic_savefig
from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.eval.bags.contact_detection import (
    ContactReport,
    ContactRun,
    GroundTruthEpisodes,
    external_truth,
)
from semiparam_ros.eval.protocol.options import Variant
from semiparam_ros.eval.protocol.report import AdaptationReport, ProtocolReport

__all__ = ["COLORS", "LABELS", "plot_adaptation", "plot_contacts", "plot_protocol", "plot_served"]

#: The paper's colours: parametric green, nonparametric red, semiparametric blue; the joint semiparametric
#: fit (not in the paper) purple.
COLORS: dict[str, str] = {"P": "tab:green", "NP": "tab:red", "SP": "tab:blue", "SPJ": "tab:purple",
                          "SPC": "tab:cyan"}
#: Legend names of learners that differ from the learner's kind (the rest of a variant's key is kept:
#: ``"SPJ adaptive (β=0.995)"`` → ``"SP joint adaptive (β=0.995)"``).
LABELS: dict[str, str] = {"SPJ": "SP joint", "SPC": "SP cascade (paper)"}
_EXTRA = ("tab:orange", "tab:brown", "tab:gray", "tab:olive", "tab:cyan", "tab:pink")


def _color(kind: str, index: int) -> str:
    """Return the colour of a report key: its learner's (an ``options.Variant``), or a spare."""
    learner = Variant.parse(kind).kind
    return COLORS[learner] if learner in COLORS else _EXTRA[index % len(_EXTRA)]


def _label(kind: str) -> str:
    learner = Variant.parse(kind).kind
    return LABELS[learner] + kind[len(learner):] if learner in LABELS else kind


def _ylabel(report: ProtocolReport | AdaptationReport, group: str) -> str:
    g = report.output.groups[group]
    mean = " (mean over joints)" if report.output.kind == OutputKind.JOINT_TORQUES else ""
    return f"{g.label} RMSE{mean} [{g.unit}]"


def _save(fig: Any, path: str | Path, dpi: int) -> Path:
    try:
        return atomic_savefig(fig, path, dpi=dpi, fmt="png")
    finally:
        plt.close(fig)


def plot_protocol(report: ProtocolReport, path: str | Path, *, truth: bool = False,
                  title: str | None = None, dpi: int = 120) -> Path:
    """Draw the paper's Fig. 3 from a protocol report and write it as PNG (atomically).

    Args:
        report: Output of :func:`~semiparam_ros.eval.protocol.report.protocol_report` (uses ``curves``;
            groups, units and labels from its output kind).
        path: Destination ``.png``.
        truth: Plot the errors against the noise-free outputs (requires them in the report).
        title: Figure title.
        dpi: Resolution.

    Returns:
        The written path.

    Raises:
        ValueError: If the report has no curves (or no ground-truth curves when ``truth``).
    """
    curves = report.curves
    if not curves:
        raise ValueError("the report has no curves")
    time_s = np.asarray(curves["time_s"])
    source = curves.get("ground_truth") if truth else {k: v for k, v in curves.items() if k not in
                                                     ("time_s", "ground_truth")}
    if not source:
        raise ValueError("the report has no ground-truth curves")
    groups = list(report.output.groups.values())
    fig, axes = plt.subplots(len(groups), 1, figsize=(6.4, 2.6 * len(groups) + 0.6), sharex=True,
                             squeeze=False)
    for ax, group in zip(axes[:, 0], groups, strict=True):
        for i, (kind, entry) in enumerate(source.items()):
            mean = np.asarray(entry[f"{group.name}_mean"])
            std = np.asarray(entry[f"{group.name}_std"])
            color = _color(kind, i)
            ax.plot(time_s, mean, color=color, lw=1.4, label=_label(kind))
            ax.fill_between(time_s, mean - std, mean + std, color=color, alpha=0.2, lw=0)
        ax.set_xscale("log")
        ax.set_ylabel(_ylabel(report, group.name))
        ax.grid(True, which="both", alpha=0.3)
        ax.set_ylim(bottom=0)
    axes[0, 0].legend(loc="upper right")
    window = report.protocol.get("window_s", float("nan"))
    axes[-1, 0].set_xlabel("time from split start [s] (log scale)")
    target = report.output.kind.label
    fig.suptitle(title or (f"windowed RMSE ({window:.3g} s window), mean ± std over {report.splits} splits"
                           + (f" — vs noise-free {target}" if truth else "")), fontsize=10)
    fig.tight_layout()
    return _save(fig, path, dpi)


def plot_adaptation(report: AdaptationReport, path: str | Path, *, title: str | None = None,
                    dpi: int = 120, xlim: tuple[float, float] | None = None) -> Path:
    """Draw the payload scenario (error vs time around the change) and write it as PNG (atomically).

    Args:
        report: Output of :func:`~semiparam_ros.eval.protocol.report.adaptation_report`.
        path: Destination ``.png``.
        title: Figure title.
        dpi: Resolution.
        xlim: Time range relative to the change [s]; default all.

    Returns:
        The written path.

    Raises:
        ValueError: If the report has no curves.
    """
    curves = report.curves
    if not curves:
        raise ValueError("the report has no curves")
    time_s = np.asarray(curves["time_s"])
    models = {k: v for k, v in curves.items() if k != "time_s"}
    groups = list(report.output.groups)
    fig, axes = plt.subplots(len(groups), 1, figsize=(6.4, 2.6 * len(groups) + 0.6), sharex=True,
                             squeeze=False)
    tol = report.tolerance
    deadline = report.deadline_s
    styles = ("-", "--", ":", "-.")
    for ax, group in zip(axes[:, 0], groups, strict=True):
        for i, (kind, entry) in enumerate(models.items()):
            color = _color(kind, i)
            # colour = learner, line style = with (solid) or without (dashed) adaptation
            adaptive = Variant.parse(kind).adaptive
            style = styles[i % len(styles)] if adaptive is None else "-" if adaptive else "--"
            ax.plot(time_s, entry[group], color=color, ls=style, lw=1.3, label=_label(kind))
            pre = report.summary[kind][group].pre_rmse
            ax.axhline(tol * pre, color=color, ls=style, lw=0.7, alpha=0.6)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.axvspan(0.0, deadline, color="0.85", alpha=0.5, lw=0)
        ax.set_yscale("log")
        ax.set_ylabel(_ylabel(report, group))
        ax.grid(True, which="both", alpha=0.3)
        if xlim is not None:
            ax.set_xlim(*xlim)
    axes[0, 0].legend(loc="upper left", fontsize=8)
    axes[-1, 0].set_xlabel(f"time from the pickup [s] (shaded: {deadline:g} s; "
                           f"thin lines: {tol:g}× pre-pickup)")
    fig.suptitle(title or "payload pickup: windowed RMSE with and without adaptation", fontsize=10)
    fig.tight_layout()
    return _save(fig, path, dpi)


def plot_contacts(report: ContactReport, truth: GroundTruthEpisodes, runs: Mapping[str, ContactRun],
                  path: str | Path, *, bag: str | Path | None = None, config: EstimatorConfig | None = None,
                  before_s: float = 4.0, after_s: float = 15.0, dpi: int = 130) -> Path:
    """Draw the last contact, the payload pickup and what the estimator made of them, on one time axis.

    The component shown is the one the chosen contact moves most (the largest external estimate of the
    gate-on run during the episode). Top: measured, predicted with the gate on (blue) and off (red, thin).
    Bottom: the external estimate ``y − ŷ`` with the gate on, its ±2σ band (published σ) and, when the bag
    holds it, the simulator's true external effect (black, dashed). Contacts are shaded, the pickup is a
    vertical line.

    Args:
        report: The contact report (units, pickup).
        truth: The true episodes.
        runs: ``{"on": ..., "off": ...}`` of :func:`~semiparam_ros.eval.bags.contact_detection.run_contacts`.
        path: PNG destination.
        bag: The bag, to read the true external effect (optional).
        config: Its configuration (needed with ``bag``).
        before_s: Time shown before the chosen contact [s].
        after_s: Time shown after the pickup (or the contact, without one) [s].
        dpi: Resolution.

    Returns:
        The written path.
    """
    on, off = runs["on"], runs["off"]
    ep = truth.episodes
    # the last contact before the pickup (the last contact without one)
    last = int(np.argmax(ep[:, 1]))
    if truth.pickup_s is not None:
        before = np.flatnonzero(ep[:, 1] <= truth.pickup_s)
        last = int(before[np.argmax(ep[before, 1])]) if before.size else last
    a = ep[last, 0] - before_s
    b = (truth.pickup_s if truth.pickup_s is not None else ep[last, 1]) + after_s
    t = on.time_s
    view = (t >= a) & (t <= b)
    during = (t >= ep[last, 0]) & (t <= ep[last, 1])
    k = int(np.argmax(np.max(np.abs(on.external[during]), axis=0))) if during.any() else 0
    name = report.output.components[k]
    unit = report.output.units[k]
    gt = external_truth(bag, on, config, truth.start_stamp_ns) if bag is not None and config is not None \
        else None
    fig, axes = plt.subplots(2, 1, figsize=(9.0, 5.6), sharex=True, constrained_layout=True)
    top, bottom = axes
    top.plot(t[view], on.y[view, k], color="0.6", lw=0.8, label="measured")
    top.plot(off.time_s[view], off.predicted[view, k], color="tab:red", lw=0.9, label="predicted, gate off")
    top.plot(t[view], on.predicted[view, k], color="tab:blue", lw=1.2, label="predicted, gate on")
    top.set_ylabel(f"{name} [{unit}]")
    ext, band = on.external[view, k], 2.0 * on.std[view, k]
    bottom.fill_between(t[view], -band, band, color="tab:blue", alpha=0.2, lw=0, label="±2σ (published)")
    bottom.plot(t[view], ext, color="tab:blue", lw=0.9, label="external estimate (gate on)")
    if gt is not None:
        bottom.plot(t[view], gt[view, k], color="black", lw=1.0, ls="--", label="true external (simulator)")
    bottom.set_ylabel(f"external {name} [{unit}]")
    bottom.set_xlabel("time from the start of the log [s]")
    for ax in axes:
        for s0, s1 in ep:
            if s1 >= a and s0 <= b:
                ax.axvspan(s0, s1, color="tab:orange", alpha=0.15, lw=0)
        if truth.pickup_s is not None:
            ax.axvline(truth.pickup_s, color="tab:green", lw=1.2, ls=":")
        ax.grid(True, alpha=0.3)
        ax.set_xlim(a, b)
    label = f"contact {ep[last, 1] - ep[last, 0]:.1f} s, {truth.peak_force[last]:.0f} N"
    top.text(ep[last, 0], 1.01, label,
             transform=top.get_xaxis_transform(), fontsize=8, color="tab:orange")
    if truth.pickup_s is not None:
        top.text(truth.pickup_s, 1.01, "payload pickup", transform=top.get_xaxis_transform(), fontsize=8,
                 color="tab:green")
    top.legend(loc="lower left", fontsize=8, ncol=3, framealpha=0.9)
    bottom.legend(loc="lower left", fontsize=8, ncol=3, framealpha=0.9)
    return _save(fig, path, dpi)


def plot_served(trace: Any, path: str | Path, *, title: str = "", seconds: float = 10.0,
                dpi: int = 110) -> Path:
    """Draw the served model (frozen) against the measured torques, per joint, and write it as PNG.

    Args:
        trace: A :class:`~semiparam_ros.report.real_robot.ServedTrace`.
        path: Destination ``.png`` (written atomically).
        title: Figure title.
        seconds: Length of the test log drawn, from its start [s].
        dpi: Resolution.

    Returns:
        The written path.
    """
    keep = trace.time_s <= trace.time_s[0] + seconds
    t = trace.time_s[keep]
    n = len(trace.joints)
    fig, axes = plt.subplots(n, 1, figsize=(7.2, 1.35 * n + 0.8), sharex=True, squeeze=False)
    for j, ax in enumerate(axes[:, 0]):
        served, std = trace.served[keep, j], trace.std[keep, j]
        ax.fill_between(t, served - 2 * std, served + 2 * std, color="tab:blue", alpha=0.2, lw=0,
                        label="served ±2σ")
        ax.plot(t, trace.measured[keep, j], color="black", lw=1.0, label="measured")
        ax.plot(t, served, color="tab:blue", lw=1.0, label="served SP (frozen)")
        ax.plot(t, trace.urdf[keep, j], color="tab:gray", lw=0.9, ls="--", label="URDF")
        ax.set_ylabel(f"{trace.joints[j]}\n[N·m]", fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=4)
    axes[-1, 0].set_xlabel("time on the test log [s]")
    fig.suptitle(title or "the served model, learned on another log, against the measured torques",
                 fontsize=10)
    fig.tight_layout()
    return _save(fig, path, dpi)
