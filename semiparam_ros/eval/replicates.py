"""The paper's protocol replicated over independent simulated logs (simulator seeds).

One run of the protocol (:mod:`semiparam_ros.eval.protocol`) is one pair of logs: its 10 test parts share the
same trained models and the same noise realisation of the training log, so they say how sure we are about
*these* logs, not whether a criterion holds on logs of the same kind in general. Re-simulating the XY and XZ
logs with another seed draws new sensor noise and a new wander of the hand's speed, circle centre and radius
(:mod:`semiparam_ros.sim.scenario`); everything else (robot, non-rigid effects, hyperparameters, protocol) is
unchanged. Each seed is then an independent replicate of the whole experiment, and:

* per criterion of the issue (:func:`~semiparam_ros.eval.report.paper_checks`): on how many seeds it holds,
  and the spread of its value;
* per pair of learners (A vs B), group, segment and target: :func:`~semiparam_ros.eval.compare.compare_pair`
  on the per-seed means (``n`` = seeds; the seeds are independent) and on all parts of all seeds pooled
  (``n`` = seeds × parts; more power, but the parts of one seed share their trained models, so its p-values
  are optimistic).

Only scalars are kept (no curves), so the summary of many seeds is a small JSON file.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from semiparam_ros.eval.compare import DEFAULT_PAIRS, compare_pair, format_p
from semiparam_ros.eval.metrics import GROUP_UNITS
from semiparam_ros.eval.report import first_key, paper_checks

__all__ = ["replicate_summary", "replicates_markdown"]

_GROUPS = ("force", "torque")


def _stats(report: Mapping[str, Any], kind: str, truth: bool) -> Mapping[str, Any] | None:
    model = report["models"].get(kind)
    if model is None:
        return None
    return model.get("ground_truth") if truth else model


def replicate_summary(reports: Sequence[Mapping[str, Any]], seeds: Sequence[int],
                      pairs: Sequence[tuple[str, str]] = DEFAULT_PAIRS) -> dict[str, Any]:
    """Summarize protocol reports of the same experiment on logs simulated with different seeds.

    Args:
        reports: Outputs of :func:`~semiparam_ros.eval.report.protocol_report` (``evaluate --json``), one
            per seed, all with the same learners, protocol and hyperparameters.
        seeds: The simulator seed of each report (same order).
        pairs: ``(A, B)`` learner pairs to compare; a pair with a learner missing is skipped.

    Returns:
        ``{"seeds", "models", "config", "protocol", "per_seed", "criteria", "comparisons"}``:
        ``per_seed`` lists per seed its learners' mean RMSEs (N, N·m; measured and, when present, against
        the noise-free wrench) and its checks; ``criteria`` per check name ``{"check", "model", "limit",
        "passed", "n", "values"}``; ``comparisons`` rows ``{"a", "b", "group", "segment", "truth", "level",
        **compare_pair(...)}`` with ``level`` ``"seeds"`` or ``"parts"``.

    Raises:
        ValueError: No reports, a length mismatch with ``seeds``, repeated seeds, or reports that differ in
            their learners, protocol (split size, window, first seconds) or configuration.
    """
    if not reports:
        raise ValueError("need at least one report")
    if len(reports) != len(seeds):
        raise ValueError(f"{len(reports)} reports but {len(seeds)} seeds")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct, got {list(seeds)}")
    ref = reports[0]
    kinds = list(ref["models"])
    proto_keys = ("split_size", "window_samples", "first_s")
    for seed, rep in zip(seeds, reports, strict=True):
        if list(rep["models"]) != kinds:
            raise ValueError(f"seed {seed}: learners {list(rep['models'])} differ from {kinds}")
        if any(rep["protocol"].get(k) != ref["protocol"].get(k) for k in proto_keys):
            raise ValueError(f"seed {seed}: protocol differs from the first report's")
        if rep.get("config") != ref.get("config"):
            raise ValueError(f"seed {seed}: configuration differs from the first report's")
    first_s = float(ref["protocol"].get("first_s", 3.0))
    segments = (("regime", ""), ("first", f"_{first_key(first_s)}"))

    per_seed: list[dict[str, Any]] = []
    for seed, rep in zip(seeds, reports, strict=True):
        entry: dict[str, Any] = {"seed": int(seed), "models": {}, "checks": paper_checks(rep, first_s)}
        for kind in kinds:
            for truth in (False, True):
                st = _stats(rep, kind, truth)
                if st is None:
                    continue
                scalars = {f"{g}_rmse{suffix}": float(st[f"{g}_rmse{suffix}"])
                           for g in _GROUPS for _, suffix in segments}
                entry["models"].setdefault(kind, {})["ground_truth" if truth else "measured"] = scalars
        if "noise" in rep:
            entry["noise"] = {k: float(v) for k, v in rep["noise"].items()}
        per_seed.append(entry)

    criteria: dict[str, dict[str, Any]] = {}
    for entry in per_seed:
        for chk in entry["checks"]:
            c = criteria.setdefault(chk["check"], {"check": chk["check"], "model": chk["model"],
                                                    "limit": chk["limit"], "passed": 0, "values": []})
            c["passed"] += int(chk["passed"])
            c["values"].append(float(chk["value"]))
    for c in criteria.values():
        c["n"] = len(c["values"])

    comparisons: list[dict[str, Any]] = []
    for a, b in pairs:
        if a not in kinds or b not in kinds:
            continue
        for truth in (False, True):
            sa = [_stats(r, a, truth) for r in reports]
            sb = [_stats(r, b, truth) for r in reports]
            if any(s is None for s in sa + sb):
                continue
            for group in _GROUPS:
                for segment, suffix in segments:
                    key = f"{group}_rmse{suffix}"
                    row = {"a": a, "b": b, "group": group, "segment": segment, "truth": truth}
                    comparisons.append({**row, "level": "seeds",
                                        **compare_pair([s[key] for s in sa], [s[key] for s in sb])})
                    comparisons.append({**row, "level": "parts",
                                        **compare_pair(np.concatenate([s[f"{key}_splits"] for s in sa]),
                                                       np.concatenate([s[f"{key}_splits"] for s in sb]))})
    return {"seeds": [int(s) for s in seeds], "models": kinds, "config": ref.get("config"),
            "protocol": {k: ref["protocol"].get(k) for k in proto_keys}, "per_seed": per_seed,
            "criteria": list(criteria.values()), "comparisons": comparisons}


def replicates_markdown(summary: Mapping[str, Any]) -> str:
    """Tables of a :func:`replicate_summary`: criteria over seeds, per-seed ratios, paired comparisons.

    Args:
        summary: Output of :func:`replicate_summary` (or its JSON).

    Returns:
        Markdown text (three tables; the pooled-parts comparisons only at regime).
    """
    n = len(summary["seeds"])
    first_s = summary["protocol"].get("first_s", 3.0)
    lines = ["| criterion | holds on | min | median | max | limit |", "|---|---|---|---|---|---|"]
    for c in summary["criteria"]:
        v = np.asarray(c["values"])
        lines.append(f"| {c['check']} | {c['passed']} of {c['n']} seeds | {v.min():.4f} | "
                     f"{float(np.median(v)):.4f} | {v.max():.4f} | {c['limit']:g} |")
    lines += ["", "Per seed, ratio to NP's mean RMSE at regime (measured; noise-free in brackets):", ""]
    semis = [k for k in summary["models"] if k not in ("P", "NP")]
    head = " | ".join(f"{k} / NP force | {k} / NP torque" for k in semis)
    lines += [f"| seed | {head} |", "|---" * (1 + 2 * len(semis)) + "|"]
    for entry in summary["per_seed"]:
        m = entry["models"]
        cells = []
        for k in semis:
            for g in _GROUPS:
                key = f"{g}_rmse"
                meas = m[k]["measured"][key] / m["NP"]["measured"][key]
                cell = f"{meas:.4f}"
                if "ground_truth" in m[k] and "ground_truth" in m["NP"]:
                    cell += f" ({m[k]['ground_truth'][key] / m['NP']['ground_truth'][key]:.4f})"
                cells.append(cell)
        lines.append(f"| {entry['seed']} | " + " | ".join(cells) + " |")
    lines += ["", f"Paired comparisons: over the {n} seeds' means (independent replicates) and, at regime, "
              "over all their parts pooled (optimistic p: the parts of one seed share their trained "
              "models):", "",
              "| A vs B | target | group | segment | level | mean ratio | mean A − B ± s.e. | A better in | "
              "p (paired t) | p (sign) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in summary["comparisons"]:
        if r["level"] == "parts" and r["segment"] != "regime":
            continue
        seg = "at regime" if r["segment"] == "regime" else f"first {first_s:g} s"
        sem = "n/a" if r["diff_sem"] is None else f"{r['diff_sem']:.2g}"
        target = "noise-free" if r["truth"] else "measured"
        lines.append(f"| {r['a']} vs {r['b']} | {target} | {r['group']} | {seg} |"
                     f" {r['level']} | {r['ratio']:.4f} | {r['diff_mean']:+.2g} ± {sem} "
                     f"{GROUP_UNITS[r['group']]} | {r['wins']} of {r['n']} | {format_p(r['p_t'])} | "
                     f"{format_p(r['p_sign'])} |")
    return "\n".join(lines) + "\n"
