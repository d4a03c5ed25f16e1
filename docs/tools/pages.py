"""Fill the results page's template (``docs/templates/results.md.in``) with numbers and tables.

The words of the page live in the template, in ``docs/``; this module only computes the values of its
``${name}`` placeholders from the typed reports next to the figures (:func:`page_values`) and substitutes
them (:func:`render_results`). The template states a few findings in words; :func:`template_claims` checks
each of them against the reports, and rendering refuses a page whose words the numbers no longer support.

Reports read from the figures folder (``scripts/reproduce.sh`` writes them): ``paper.json`` and
``payload.json`` (required), ``within_xy.json``, ``diagnostic_frozen_p.json``, ``sensitivity.json``,
``tune_xy.json``, ``select_xy.json``, ``own_<kind>.json`` and ``replicates.json``.
"""

from __future__ import annotations

import json
import os
import string
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from docs.tools.claims import restated_checks
from docs.tools.replicates import ReplicateSummary, replicates_markdown
from semiparam_ros.atomic import atomic_write_text
from semiparam_ros.eval.protocol.compare import compare_pair, format_p
from semiparam_ros.eval.protocol.options import Variant
from semiparam_ros.eval.protocol.report import AdaptationReport, ProtocolReport
from semiparam_ros.report.tables import (
    adaptation_table,
    checks_table,
    comparisons_table,
    components_table,
    protocol_table,
)

__all__ = ["PageInputs", "load_inputs", "page_values", "render_results", "template_claims", "write_results"]

_KEYS = ("parametric.lam", "nonparametric.lam", "nonparametric.sigma")


@dataclass(frozen=True)
class PageInputs:
    """The reports the results page is filled from (see the module docstring)."""

    paper: ProtocolReport
    payload: AdaptationReport
    figures: dict[str, str]
    within: ProtocolReport | None = None
    diagnostic: ProtocolReport | None = None
    sensitivity: ProtocolReport | None = None
    tuning: dict[str, Any] | None = None
    selection: dict[str, Any] | None = None
    own: dict[str, ProtocolReport] = field(default_factory=dict)
    replicates: ReplicateSummary | None = None


def _rel(path: Path, start: Path) -> str:
    return os.path.relpath(path, start).replace(os.sep, "/")


def load_inputs(figures: str | Path, page: str | Path) -> PageInputs:
    """Read the reports of a figures folder (``paper.json`` and ``payload.json`` must exist).

    Args:
        figures: The folder with the JSON reports and PNG figures.
        page: Where the page will be written (figure links are relative to it).

    Raises:
        OSError: If a required report cannot be read.
        ValueError: If a report is malformed.
    """
    figures, base = Path(figures), Path(page).parent

    def read(name: str) -> Any:
        path = figures / name
        return json.loads(path.read_text()) if path.is_file() else None

    def protocol(name: str) -> ProtocolReport | None:
        doc = read(name)
        return None if doc is None else ProtocolReport.from_json(doc)

    paper = ProtocolReport.from_json(json.loads((figures / "paper.json").read_text()))
    payload = AdaptationReport.from_json(json.loads((figures / "payload.json").read_text()))
    links = {
        "fig3": _rel(figures / "paper_fig3.png", base),
        "fig3_noise_free": _rel(figures / "paper_fig3_noise_free.png", base),
        "payload": _rel(figures / "payload.png", base),
    }
    own = {k: r for k in ("NP", "SP", "SPJ") if (r := protocol(f"own_{k}.json")) is not None}
    rep = read("replicates.json")
    return PageInputs(
        paper=paper,
        payload=payload,
        figures=links,
        within=protocol("within_xy.json"),
        diagnostic=protocol("diagnostic_frozen_p.json"),
        sensitivity=protocol("sensitivity.json"),
        tuning=read("tune_xy.json"),
        selection=read("select_xy.json"),
        own=own,
        replicates=None if rep is None else ReplicateSummary.from_json(rep),
    )


def _ratio(
    report: ProtocolReport, a: str, b: str, group: str, segment: str = "regime", truth: bool = False
) -> float:
    sa, sb = report.stats(a, truth), report.stats(b, truth)
    if sa is None or sb is None:
        return float("nan")
    return sa.rmse(group, segment) / sb.rmse(group, segment)


def _restated_table(inputs: PageInputs) -> str:
    rows = [("this run's parts", c) for c in restated_checks(inputs.paper)]
    if inputs.replicates is not None:
        rows += [("seeds", c) for c in restated_checks(inputs.replicates)]
    lines = [
        "| model | group | segment | over | ratio to NP | model better in | p (paired t) | holds |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for over, c in rows:
        seg = "at regime" if c.segment == "regime" else f"first {inputs.paper.first_s:g} s"
        lines.append(
            f"| {c.model} | {c.group} | {seg} | {over} | {c.stats.ratio:.4f} | "
            f"{c.stats.wins} of {c.stats.n} | {format_p(c.stats.p_t)} | {'yes' if c.passed else 'no'} |"
        )
    return "\n".join(lines) + "\n"


def _own_table(inputs: PageInputs) -> str:
    if "NP" not in inputs.own:
        return "(no per-learner runs found)\n"
    ref = inputs.own["NP"].models["NP"]
    first_s = inputs.paper.first_s
    lines = [
        "| model | λ_NP | σ | force at regime [N] | torque at regime [N·m] | "
        f"force first {first_s:g} s [N] | torque first {first_s:g} s [N·m] | "
        "force / NP's at regime (paired p) | torque / NP's at regime (paired p) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for kind, rep in inputs.own.items():
        m = rep.models[kind]
        cells = []
        for g in ("force", "torque"):
            if kind == "NP":
                cells.append("1")
                continue
            c = compare_pair(m.groups[g].regime.splits, ref.groups[g].regime.splits)
            cells.append(f"{c.ratio:.4f} ({format_p(c.p_t)})")
        lines.append(
            f"| {kind} | {float(rep.config['nonparametric.lam']):g} | "
            f"{float(rep.config['nonparametric.sigma']):g} | {m.rmse('force'):.4g} | "
            f"{m.rmse('torque'):.4g} | {m.rmse('force', 'first'):.3g} | {m.rmse('torque', 'first'):.3g} | "
            f"{cells[0]} | {cells[1]} |"
        )
    return "\n".join(lines) + "\n"


def _select_table(selection: Mapping[str, Any], kind: str) -> str:
    sel = selection["selections"][kind]
    first = f"{selection.get('first_s', 3.0):g}"
    lines = [
        "| λ_NP | σ | force at regime [N] | torque at regime [N·m] | "
        f"force first {first} s [N] | torque first {first} s [N·m] | score | |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for i, p in enumerate(sel["grid"]):
        lines.append(
            f"| {p['nonparametric.lam']:g} | {p['nonparametric.sigma']:g} | {p['force_rmse']:.4f} | "
            f"{p['torque_rmse']:.5f} | {p['force_rmse_first']:.3f} | {p['torque_rmse_first']:.4f} | "
            f"{p['score']:.4f} | {'selected' if i == 0 else ''} |"
        )
    return "\n".join(lines) + "\n"


def _within_table(within: ProtocolReport | None) -> str:
    if within is None:
        return "(no within-XY run found)\n"
    lines = ["| model | force at regime [N] | torque at regime [N·m] |", "|---|---|---|"]
    for kind, m in within.models.items():
        lines.append(f"| {kind} | {m.rmse('force'):.4g} | {m.rmse('torque'):.4g} |")
    return "\n".join(lines) + "\n"


def page_values(inputs: PageInputs, *, command: str) -> dict[str, str]:
    """Compute every placeholder of the results template.

    Args:
        inputs: The reports.
        command: The command that regenerates the page.

    Returns:
        Placeholder name → text (numbers and tables only).
    """
    paper, payload = inputs.paper, inputs.payload
    m, cfg, proto = paper.models, paper.config, paper.protocol
    kinds = list(m)
    noise = paper.noise or {}
    v: dict[str, str] = {
        "command": command,
        "train_bag": str(proto.get("train_bag")),
        "test_bag": str(proto.get("test_bag")),
        "kinds": ", ".join(kinds[:-1]) + " and " + kinds[-1] if len(kinds) > 1 else kinds[0],
        "samples_train": str(paper.samples_train),
        "splits": str(paper.splits),
        "split_size": str(proto["split_size"]),
        "window_samples": str(proto["window_samples"]),
        "window_s": f"{proto['window_s']:.3g}",
        "rate_hz": f"{1 / proto['sample_period_s']:.3g}",
        "first_s": f"{paper.first_s:g}",
        "config_line": ", ".join(
            f"`{k}` = {cfg[k]}"
            for k in (
                *_KEYS,
                "nonparametric.n_features",
                "nonparametric.standardizer_warmup",
                "acceleration.method",
                "acceleration.window",
            )
            if k in cfg
        ),
        "paper_table": protocol_table(paper),
        "paper_table_noise_free": protocol_table(paper, truth=True),
        "paper_components": components_table(paper),
        "noise_force": f"{noise.get('force', float('nan')):.3g}",
        "noise_torque": f"{noise.get('torque', float('nan')):.3g}",
        "checks_table": checks_table(paper.checks, paper.first_s, tie_margin=0.01),
        "fig3": inputs.figures["fig3"],
        "fig3_noise_free": inputs.figures["fig3_noise_free"],
        "restated_table": _restated_table(inputs),
        "comparisons_table": comparisons_table(paper.comparisons, paper.first_s),
        "p_force": f"{m['P'].rmse('force'):.3g}",
        "p_torque": f"{m['P'].rmse('torque'):.3g}",
        "np_force": f"{m['NP'].rmse('force'):.3g}",
        "np_torque": f"{m['NP'].rmse('torque'):.3g}",
        "sp_force": f"{m['SP'].rmse('force'):.3g}",
        "sp_torque": f"{m['SP'].rmse('torque'):.3g}",
        "within_table": _within_table(inputs.within),
        "own_table": _own_table(inputs),
        "update_times": ", ".join(f"{k} {s['median']:.0f} µs" for k, s in paper.update_us.items()),
    }
    for a in ("SP", "SPJ"):
        for g in ("force", "torque"):
            v[f"{a.lower()}_np_{g}"] = f"{_ratio(paper, a, 'NP', g):.4f}"
            v[f"{a.lower()}_np_{g}_nf"] = f"{_ratio(paper, a, 'NP', g, truth=True):.3f}"
            v[f"{a.lower()}_np_first_{g}"] = f"{_ratio(paper, a, 'NP', g, 'first'):.2f}"
    w = inputs.within
    v.update(
        {
            "within_train": str(w.samples_train) if w else "n/a",
            "within_splits": str(w.splits) if w else "n/a",
            "within_split_size": str(w.protocol["split_size"]) if w else "n/a",
        }
    )
    d = inputs.diagnostic
    for key, kind in (("frozen", "SPfrozenP"), ("frozen_np", "NP"), ("frozen_sp", "SP")):
        for g in ("force", "torque"):
            v[f"{key}_{g}"] = f"{d.models[kind].rmse(g):.4g}" if d and kind in d.models else "n/a"
    s = inputs.sensitivity
    v["sens_lam"] = str(s.config.get("nonparametric.lam")) if s else "n/a"
    v["sens_sigma"] = str(s.config.get("nonparametric.sigma")) if s else "n/a"
    for g in ("force", "torque"):
        v[f"sens_first_{g}"] = f"{_ratio(s, 'SP', 'NP', g, 'first'):.2f}" if s else "n/a"
        v[f"sens_{g}"] = f"{_ratio(s, 'SP', 'NP', g):.3f}" if s else "n/a"
    v["used_values"] = ", ".join(f"`{k}` = {cfg[k]:g}" for k in _KEYS if k in cfg)
    v["n_features"] = str(cfg.get("nonparametric.n_features"))
    v["warmup"] = str(cfg.get("nonparametric.standardizer_warmup"))
    v.update(_tuning_values(inputs.tuning, cfg))
    sel = inputs.selection
    if sel is not None:
        v["select_train"] = str(sel["selections"]["SP"]["n_train"])
        v["select_table"] = _select_table(sel, "SP")
        v["select_others"] = ", ".join(
            f"{k}: λ_NP = {s['best']['nonparametric.lam']:g}, σ = {s['best']['nonparametric.sigma']:g} "
            f"(score {s['best']['score']:.4f})"
            for k, s in sel["selections"].items()
        )
    else:
        v.update(
            {"select_train": "n/a", "select_table": "(no selection runs found)\n", "select_others": "n/a"}
        )
    rep = inputs.replicates
    v["rep_n"] = str(len(rep.seeds)) if rep else "0"
    v["rep_seeds"] = f"{rep.seeds[0]}–{rep.seeds[-1]}" if rep else "n/a"
    v["replicates_tables"] = replicates_markdown(rep) if rep else "(no replicates found)\n"
    pp = payload.protocol
    v.update(
        {
            "payload_bag": str(pp.get("bag")),
            "pickup_s": str(pp.get("pickup_time_s")),
            "forgetting": str(pp.get("forgetting")),
            "pre_s": f"{payload.pre_s:g}",
            "tolerance": f"{payload.tolerance:g}",
            "deadline_s": f"{payload.deadline_s:g}",
            "payload_table": adaptation_table(payload),
            "payload_fig": inputs.figures["payload"],
        }
    )
    return v


def _tuning_values(tuning: Mapping[str, Any] | None, cfg: Mapping[str, Any]) -> dict[str, str]:
    if not tuning:
        return {
            k: "n/a"
            for k in (
                "tune_holdout",
                "tune_best",
                "tune_best_score",
                "tune_used_score",
                "tune_min",
                "tune_max",
            )
        }
    sel = (
        tuning["selections"][tuning["kind"]]
        if "selections" in tuning
        else {"best": tuning["best"], "grid": tuning["grid"], "n_test": tuning["n_holdout"]}
    )
    scores = sorted(row["score"] for row in sel["grid"])
    used = next((r for r in sel["grid"] if all(r[k] == cfg[k] for k in _KEYS)), None)
    return {
        "tune_holdout": str(sel["n_test"]),
        "tune_best": ", ".join(f"`{k}` = {sel['best'][k]:g}" for k in _KEYS),
        "tune_best_score": f"{sel['best']['score']:.4f}",
        "tune_used_score": f"{used['score']:.4f}" if used else "not in the grid",
        "tune_min": f"{scores[0]:.4f}",
        "tune_max": f"{scores[-1]:.4f}",
    }


def template_claims(inputs: PageInputs) -> dict[str, bool]:
    """Return the findings the template states in words, each checked against the reports.

    Returns:
        Claim identifier → whether the reports support it (only claims whose reports are present).
    """
    paper, payload = inputs.paper, inputs.payload
    restated = {(c.model, c.group, c.segment): c.passed for c in restated_checks(paper)}
    claims = {
        "spj_meets_restated": all(v for (k, _, _), v in restated.items() if k == "SPJ"),
        "sp_fails_restated_at_regime": not all(
            v for (k, _, s), v in restated.items() if k == "SP" and s == "regime"
        ),
        "sp_behind_np_at_regime_by_about_1_percent": all(
            1.0 < _ratio(paper, "SP", "NP", g) < 1.03 for g in ("force", "torque")
        ),
    }
    if inputs.within is not None:
        w = inputs.within.models
        claims["cascade_better_within_xy_than_on_xz"] = all(
            w["SP"].rmse(g) < w["SPJ"].rmse(g)
            and paper.models["SP"].rmse(g) > max(paper.models["SPJ"].rmse(g), paper.models["NP"].rmse(g))
            for g in ("force", "torque")
        )
    s = payload.summary
    variants = {Variant.parse(k): v for k, v in s.items()}
    adaptive = {v.kind: x for v, x in variants.items() if v.adaptive}
    frozen = {v.kind: x for v, x in variants.items() if v.adaptive is False}
    if {"SP", "SPJ"} <= set(adaptive) and {"SP", "SPJ"} <= set(frozen):
        claims["payload_both_recover_with_adaptation"] = all(
            r.recovered for k in ("SP", "SPJ") for r in adaptive[k].values()
        )
        claims["payload_spj_larger_bump_and_later"] = all(
            adaptive["SPJ"][g].peak > adaptive["SP"][g].peak
            and (adaptive["SPJ"][g].recovery_time_s or 0.0) > (adaptive["SP"][g].recovery_time_s or 0.0)
            for g in ("force", "torque")
        )
        claims["payload_none_recovers_without_adaptation"] = not any(
            r.recovered for k in ("SP", "SPJ") for r in frozen[k].values()
        )
        claims["payload_spj_further_without_adaptation"] = all(
            frozen["SPJ"][g].post_rmse > frozen["SP"][g].post_rmse for g in ("force", "torque")
        )
    return claims


def render_results(
    template: str,
    inputs: PageInputs,
    *,
    command: str = "bash scripts/reproduce.sh",
    check_claims: bool = True,
) -> str:
    """Fill the template with the reports' numbers.

    Args:
        template: The template text (``string.Template`` syntax, ``${name}``).
        inputs: The reports.
        command: The command that regenerates the page.
        check_claims: Refuse to render when a finding of :func:`template_claims` does not hold (for the
            shipped template; off for other templates).

    Returns:
        The page.

    Raises:
        ValueError: If the template names an unknown placeholder, or states a finding the reports do not
            support (the message names the claim: update the template's words).
    """
    false = sorted(k for k, ok in template_claims(inputs).items() if not ok) if check_claims else []
    if false:
        raise ValueError(
            f"the results template states findings the reports no longer support: {false}; "
            "update docs/templates/results.md.in"
        )
    values = page_values(inputs, command=command)
    try:
        return string.Template(template).substitute(values)
    except KeyError as err:
        raise ValueError(f"the results template names an unknown placeholder {err}") from err


def write_results(
    figures: str | Path, out: str | Path, template: str | Path, *, command: str = "bash scripts/reproduce.sh"
) -> Path:
    """Render the results page from the reports in ``figures`` and write it atomically.

    Args:
        figures: Folder of the JSON reports and figures.
        out: Destination markdown file.
        template: The template file (``docs/templates/results.md.in``).
        command: The command that regenerates the page (printed on it).

    Returns:
        The written path.

    Raises:
        OSError: If a file cannot be read or written.
        ValueError: As :func:`render_results`.
    """
    inputs = load_inputs(figures, out)
    atomic_write_text(out, render_results(Path(template).read_text(), inputs, command=command))
    return Path(out)
