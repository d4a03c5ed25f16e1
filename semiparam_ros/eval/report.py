"""Reports of the evaluation: JSON documents, markdown tables and the paper's pass/fail checks.

The JSON report of the paper's protocol (:func:`protocol_report`) has the fields::

    {"models": {"P": {"force_rmse": f, "torque_rmse": t, "force_rmse_first_3s": f0,
                      "torque_rmse_first_3s": t0, "force_rmse_std": ..., "force_rmse_splits": [...], ...,
                      "ground_truth": {...same, against the noise-free wrench...}}, "NP": {...}, "SP": {...}},
     "splits": n, "samples_train": n, "samples_test": n,
     "update_us": {"P": x, "NP": x, "SP": x}, "update_us_stats": {...}, "train_s": {...},
     "noise": {"force_rmse": ..., "torque_rmse": ...}, "protocol": {...}, "config": {...},
     "curves": {"time_s": [...], "P": {"force_mean": [...], "force_std": [...], ...}, ...,
                "ground_truth": {"P": {...}, ...}}}

Any learner kind can appear under ``models`` (e.g. ``SPJ``, the joint semiparametric fit, next to the paper's
three). ``evaluate`` adds ``"checks"``: the output of :func:`paper_checks`, one entry per criterion with the
``model`` it judges (SP's and SPJ's criteria are separate entries).

``force_rmse`` is the mean over splits of the component-averaged force RMSE (N) over the second half of
each split ("at regime"), ``torque_rmse`` the same for torques (N·m), the ``_first_3s`` values over the first
3 s of each split; ``update_us`` is the median wall time of one ``predict_learn_one`` (µs); standard
deviations are over splits (population, ``ddof=0``). ``ground_truth`` entries and ``noise`` (the RMSE of the
measured minus the noise-free wrench) appear only when the bag has noise-free outputs, and separate model
error from sensor noise.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from semiparam_ros.eval.metrics import GROUP_UNITS, group_rmse
from semiparam_ros.eval.protocol import AdaptationResult, ProtocolResult

__all__ = [
    "CHECKED_SP_KINDS",
    "adaptation_markdown",
    "adaptation_report",
    "first_key",
    "paper_checks",
    "protocol_markdown",
    "protocol_report",
    "write_json",
]

_SCALAR_LIST = re.compile(r"\[((?:\s*[^\[\]{}\s][^\[\]{}]*?)?)\s*\]")


def first_key(first_s: float) -> str:
    """Return the initial segment's name in report keys: ``"first_3s"`` for 3 s (``force_rmse_first_3s``).

    Args:
        first_s: Length of the initial segment [s].

    Returns:
        The key fragment, without the leading underscore.
    """
    return f"first_{first_s:g}s"


def _segment_stats(result: ProtocolResult, kind: str, first_s: float, truth: bool) -> dict[str, Any]:
    stats: dict[str, Any] = {}
    for group in result.groups:
        for segment, suffix in (("regime", ""), ("first", "_" + first_key(first_s))):
            values = result.segment_rmse(kind, group, segment, truth)
            stats[f"{group}_rmse{suffix}"] = float(np.mean(values))
            stats[f"{group}_rmse{suffix}_std"] = float(np.std(values))
            stats[f"{group}_rmse{suffix}_splits"] = [float(v) for v in values]
    return stats


def _rounded(values: np.ndarray, digits: int = 7) -> list[float]:
    """Curve values to ``digits`` significant digits (compact JSON; far below any plotted resolution)."""
    return [float(f"{v:.{digits}g}") for v in np.asarray(values, dtype=np.float64)]


def _curves(result: ProtocolResult, truth: bool) -> dict[str, Any]:
    curves: dict[str, Any] = {}
    for kind in result.kinds:
        entry: dict[str, list[float]] = {}
        for group in result.groups:
            per_split = result.curves(kind, group, truth)
            entry[f"{group}_mean"] = _rounded(np.mean(per_split, axis=0))
            entry[f"{group}_std"] = _rounded(np.std(per_split, axis=0))
        curves[kind] = entry
    return curves


def protocol_report(result: ProtocolResult, *, config: Mapping[str, Any] | None = None,
                    protocol: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Build the JSON-ready report of the paper's protocol.

    Args:
        result: Output of :func:`~semiparam_ros.eval.protocol.run_protocol`.
        config: Flat configuration (dotted names) the models were built from.
        protocol: Extra protocol settings to record (bags, topics, ...).

    Returns:
        A dict of plain Python types (see the module docstring).
    """
    has_truth = result.targets_true is not None
    first_s = result.first_s
    models: dict[str, Any] = {}
    for kind in result.kinds:
        models[kind] = _segment_stats(result, kind, first_s, truth=False)
        if has_truth:
            models[kind]["ground_truth"] = _segment_stats(result, kind, first_s, truth=True)
    update = {k: result.update_ns[k].ravel() * 1e-3 for k in result.kinds}
    report: dict[str, Any] = {
        "models": models,
        "splits": len(result.bounds),
        "samples_train": int(result.samples_train),
        "samples_test": result.samples_test,
        "update_us": {k: float(np.median(v)) for k, v in update.items()},
        "update_us_stats": {k: {"median": float(np.median(v)), "mean": float(np.mean(v)),
                                "p95": float(np.percentile(v, 95)), "max": float(np.max(v))}
                            for k, v in update.items()},
        "train_s": {k: v * 1e-9 for k, v in result.train_ns.items()},
        "protocol": {
            "split_size": int(result.targets.shape[1]),
            "sample_period_s": result.sample_period_s,
            "window_samples": int(result.window),
            "window_s": result.window * result.sample_period_s,
            "first_samples": int(result.first),
            "first_s": first_s,
            "regime": "second half of each split",
            "std": "population standard deviation over splits (ddof=0)",
            **dict(protocol or {}),
        },
        "config": dict(config or {}),
        "curves": {"time_s": _rounded(result.time_s, 9), **_curves(result, truth=False)},
    }
    if has_truth:
        noise = result.targets - result.targets_true
        report["noise"] = {f"{g}_rmse": float(np.mean([group_rmse(e[:, cols]) for e in noise]))
                           for g, cols in result.groups.items()}
        report["curves"]["ground_truth"] = _curves(result, truth=True)
    return report


#: Semiparametric kinds the criteria are evaluated for, each on its own (the paper's cascade; the joint fit).
CHECKED_SP_KINDS: tuple[str, ...] = ("SP", "SPJ")


def paper_checks(report: Mapping[str, Any], first_s: float = 3.0) -> list[dict[str, Any]]:
    """Evaluate the issue's reproduction criteria on a protocol report.

    At regime: SP and NP force RMSE <= 0.5 × P's, torque RMSE <= 0.4 × P's, SP mean <= NP mean (force and
    torque); over the first seconds SP better than NP (force and torque). The SP criteria are evaluated
    separately, with the same thresholds, for each semiparametric model in the report: ``SP`` (the paper's
    cascade, or whatever the configuration selects) and ``SPJ`` (the joint fit); checks of ``SP`` come first
    and keep their names, those of ``SPJ`` follow, named ``SPJ ...``.

    Args:
        report: Output of :func:`protocol_report` with models ``P``, ``NP`` and ``SP`` and/or ``SPJ`` and a
            wrench output.
        first_s: Length of the initial segment [s].

    Returns:
        A list of ``{"check", "model", "value", "limit", "passed"}``, one per criterion (``model`` is the
        model the criterion judges: ``"SP"``, ``"NP"`` or ``"SPJ"``).

    Raises:
        ValueError: If the report lacks P, NP and a semiparametric model, or the force/torque groups.
    """
    models = report["models"]
    sp_kinds = [k for k in CHECKED_SP_KINDS if k in models]
    if not {"P", "NP"} <= set(models) or not sp_kinds or "force_rmse" not in models["P"]:
        raise ValueError("paper checks need P, NP and SP (or SPJ) models and a wrench output")
    first = "_" + first_key(first_s)
    checks: list[dict[str, Any]] = []

    def add(kind: str, name: str, value: float, limit: float, strict: bool = False) -> None:
        checks.append({"check": name, "model": kind, "value": value, "limit": limit,
                       "passed": bool(value < limit if strict else value <= limit)})

    for sp in sp_kinds:
        for kind in (sp, "NP") if sp == sp_kinds[0] else (sp,):
            for group, factor in (("force", 0.5), ("torque", 0.4)):
                add(kind, f"{kind} {group} RMSE at regime / P's",
                    models[kind][f"{group}_rmse"] / models["P"][f"{group}_rmse"], factor)
        for group in ("force", "torque"):
            add(sp, f"{sp} {group} RMSE at regime / NP's",
                models[sp][f"{group}_rmse"] / models["NP"][f"{group}_rmse"], 1.0)
        for group in ("force", "torque"):
            add(sp, f"{sp} {group} RMSE over the first {first_s:g} s / NP's",
                models[sp][f"{group}_rmse{first}"] / models["NP"][f"{group}_rmse{first}"], 1.0, strict=True)
    return checks


def _fmt(value: float, std: float | None = None) -> str:
    if value is None or not math.isfinite(value):
        return "n/a"
    text = f"{value:.3g}" if abs(value) < 1000 else f"{value:.0f}"
    return text if std is None else f"{text} ± {std:.2g}"


def protocol_markdown(report: Mapping[str, Any], first_s: float = 3.0, truth: bool = False) -> str:
    """Markdown table of a protocol report: mean ± std over splits, per model.

    Args:
        report: Output of :func:`protocol_report`.
        first_s: Length of the initial segment [s].
        truth: Tabulate the errors against the noise-free outputs instead of the measured ones.

    Returns:
        The table (with a trailing newline).
    """
    first = "_" + first_key(first_s)
    groups = [g for g in ("force", "torque") if f"{g}_rmse" in next(iter(report["models"].values()))]
    header = ["model"]
    for g in groups:
        header.append(f"{g} RMSE at regime [{GROUP_UNITS[g]}]")
    for g in groups:
        header.append(f"{g} RMSE first {first_s:g} s [{GROUP_UNITS[g]}]")
    header.append("update [µs]")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for kind, stats in report["models"].items():
        if truth:
            stats = stats.get("ground_truth")
            if stats is None:
                continue
        row = [kind]
        row += [_fmt(stats[f"{g}_rmse"], stats[f"{g}_rmse_std"]) for g in groups]
        row += [_fmt(stats[f"{g}_rmse{first}"], stats[f"{g}_rmse{first}_std"]) for g in groups]
        row.append(_fmt(report["update_us"][kind]))
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def adaptation_report(result: AdaptationResult, *, config: Mapping[str, Any] | None = None,
                      protocol: Mapping[str, Any] | None = None, stride: int = 1) -> dict[str, Any]:
    """Build the JSON-ready report of the adaptation (payload) scenario.

    Args:
        result: Output of :func:`~semiparam_ros.eval.protocol.run_adaptation`.
        config: Flat configuration the models were built from (plus the per-model overrides in
            ``protocol``).
        protocol: Extra settings to record.
        stride: Keep every ``stride``-th curve point (smaller files for long streams).

    Returns:
        A dict of plain Python types: ``summary`` (per model and group, see
        :class:`~semiparam_ros.eval.protocol.AdaptationResult`), settings, and the curves.
    """
    keep = slice(None, None, max(1, int(stride)))
    return {
        "summary": result.summary,
        "change_s": result.change_s,
        "tolerance": result.tolerance,
        "deadline_s": result.deadline_s,
        "pre_s": result.pre_s,
        "window_samples": int(result.window),
        "protocol": dict(protocol or {}),
        "config": dict(config or {}),
        "curves": {"time_s": _rounded(result.time_s[keep], 9),
                   **{k: {g: _rounded(c[keep]) for g, c in v.items()} for k, v in result.curves.items()}},
    }


def adaptation_markdown(report: Mapping[str, Any]) -> str:
    """Markdown table of an adaptation report (force and torque per model).

    Args:
        report: Output of :func:`adaptation_report`.

    Returns:
        The table (with a trailing newline).
    """
    deadline = report["deadline_s"]
    tol = report["tolerance"]
    header = ["model", "group", "pre-change RMSE", "peak", f"at +{deadline:g} s (ratio)",
              f"RMSE after +{deadline:g} s", f"back within {tol:g}× at", f"recovered ≤ {deadline:g} s"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for kind, groups in report["summary"].items():
        for group, s in groups.items():
            rec = s["recovery_time_s"]
            lines.append("| " + " | ".join([
                kind, f"{group} [{GROUP_UNITS.get(group, '')}]", _fmt(s["pre_rmse"]), _fmt(s["peak"]),
                f"{_fmt(s['level_at_deadline'])} ({s['ratio_at_deadline']:.2f}×)", _fmt(s["post_rmse"]),
                "never" if rec is None else f"+{rec:.1f} s", "yes" if s["recovered"] else "no"]) + " |")
    return "\n".join(lines) + "\n"


def _plain(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def write_json(report: Mapping[str, Any], path: str | Path) -> None:
    """Write a report as JSON atomically (temp file in the same directory, then ``os.replace``).

    Non-finite floats are written as ``null`` (JSON has no NaN).

    Args:
        report: The report.
        path: Destination file (parent directories are created).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        text = json.dumps(_plain(report), indent=1)
        # lists of scalars on one line each: readable structure, compact curves
        text = _SCALAR_LIST.sub(lambda m: "[" + re.sub(r"\s*\n\s*", " ", m.group(1)).strip() + "]", text)
        tmp.write_text(text + "\n")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
