"""Replicates of the protocol over simulator seeds, against statistics computed by hand."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from docs.tools.replicates import ReplicateSummary, replicate_summary, replicates_markdown
from semiparam_ros.eval.protocol.report import ProtocolReport

KINDS = ("P", "NP", "SP", "SPJ")
# per learner: (force at regime, torque at regime, force first 3 s, torque first 3 s) scale
LEVELS = {
    "P": (2.0, 0.4, 2.2, 0.45),
    "NP": (0.31, 0.031, 1.5, 0.15),
    "SP": (0.315, 0.0311, 1.4, 0.13),
    "SPJ": (0.309, 0.0309, 1.1, 0.12),
}


def _model(rng: np.random.Generator, levels: tuple[float, ...], parts: int) -> dict:
    out: dict = {}
    for (group, suffix), level in zip(
        [("force", ""), ("torque", ""), ("force", "_first_3s"), ("torque", "_first_3s")], levels, strict=True
    ):
        splits = level * (1 + 0.01 * rng.standard_normal(parts))
        out[f"{group}_rmse{suffix}"] = float(splits.mean())
        out[f"{group}_rmse{suffix}_splits"] = list(splits)
    return out


def _report(seed: int, parts: int = 4, config: dict | None = None) -> ProtocolReport:
    rng = np.random.default_rng(seed)
    models = {}
    for kind in KINDS:
        m = _model(rng, LEVELS[kind], parts)
        m["ground_truth"] = _model(rng, tuple(v / 3 for v in LEVELS[kind]), parts)
        models[kind] = m
    return ProtocolReport.from_json(
        {
            "models": models,
            "protocol": {"split_size": 1000, "window_samples": 30, "first_s": 3.0},
            "splits": parts,
            "samples_train": 10,
            "samples_test": 1000 * parts,
            "update_us": {k: 1.0 for k in KINDS},
            "config": config or {"nonparametric": {"sigma": 6.0}},
            "noise": {"force_rmse": 0.3, "torque_rmse": 0.03},
        }
    )


def test_criteria_are_counted_over_seeds():
    seeds = [3, 5, 8]
    reports = [_report(s) for s in seeds]
    summary = replicate_summary(reports, seeds)
    c = summary.criterion("SP/NP/force/regime")
    values = [r.models["SP"].rmse("force") / r.models["NP"].rmse("force") for r in reports]
    assert c.values == pytest.approx(values, rel=1e-12)
    # each seed's check passes when SP is no worse or not significantly worse over the parts (paired t)
    assert c.passed == sum(ch.passed for ch in c.checks) and len(c.checks) == 3
    for v, ch in zip(values, c.checks, strict=True):
        assert ch.paired_p is not None and ch.passed == (v <= 1.0 or ch.paired_p >= 0.05)
    strict = summary.criterion("SPJ/NP/torque/first")
    assert strict.passed == sum(
        r.models["SPJ"].rmse("torque", "first") < r.models["NP"].rmse("torque", "first") for r in reports
    )
    assert summary.seeds == tuple(seeds)
    assert summary.per_seed[1]["SP"].ground_truth.rmse("torque") == pytest.approx(
        reports[1].models["SP"].ground_truth.rmse("torque")
    )
    # JSON round trip: the criteria are recomputed from the per-seed means and agree
    back = ReplicateSummary.from_json(json.loads(json.dumps(summary.to_json())))
    assert [x.values for x in back.criteria] == [x.values for x in summary.criteria]
    assert back.comparisons == summary.comparisons


def test_seed_level_and_pooled_comparisons_match_scipy():
    seeds = list(range(6))
    reports = [_report(s) for s in seeds]
    rows = replicate_summary(reports, seeds).comparisons

    def row(level: str, truth: bool):
        (r,) = [
            r
            for r in rows
            if r.a == "SPJ"
            and r.b == "NP"
            and r.group == "torque"
            and r.segment == "regime"
            and r.truth is truth
            and r.level == level
        ]
        return r.stats

    a = np.array([r.models["SPJ"].rmse("torque") for r in reports])
    b = np.array([r.models["NP"].rmse("torque") for r in reports])
    seeds_row = row("seeds", False)
    assert seeds_row.n == 6
    assert seeds_row.p_t == pytest.approx(stats.ttest_rel(a, b).pvalue, rel=1e-9)
    assert seeds_row.ratio == pytest.approx(a.mean() / b.mean(), rel=1e-12)
    ga = np.concatenate([r.models["SPJ"].ground_truth.groups["torque"].regime.splits for r in reports])
    gb = np.concatenate([r.models["NP"].ground_truth.groups["torque"].regime.splits for r in reports])
    pooled = row("pooled", True)
    assert pooled.n == 24
    assert pooled.diff_mean == pytest.approx(float(np.mean(ga - gb)), rel=1e-12)
    assert pooled.diff_sem == pytest.approx(float(np.std(ga - gb, ddof=1) / math.sqrt(24)), rel=1e-12)
    assert pooled.wins == int(np.sum(ga < gb))


def test_inconsistent_inputs_are_refused():
    with pytest.raises(ValueError, match="at least one"):
        replicate_summary([], [])
    with pytest.raises(ValueError, match="seeds"):
        replicate_summary([_report(0)], [0, 1])
    with pytest.raises(ValueError, match="distinct"):
        replicate_summary([_report(0), _report(1)], [2, 2])
    with pytest.raises(ValueError, match="configuration"):
        replicate_summary([_report(0), _report(1, config={"nonparametric": {"sigma": 4.0}})], [0, 1])
    other = _report(1)
    del other.models["SPJ"]
    with pytest.raises(ValueError, match="learners"):
        replicate_summary([_report(0), other], [0, 1])


def test_markdown_lists_every_criterion_and_seed():
    seeds = [1, 2]
    summary = replicate_summary([_report(s) for s in seeds], seeds)
    text = replicates_markdown(summary)
    for c in summary.criteria:
        assert f"| `{c.id}` | {c.passed} of 2 seeds |" in text
    first = summary.per_seed[0]
    ratio = first["SPJ"].rmse("torque") / first["NP"].rmse("torque")
    assert "| 1 | " in text and f"{ratio:.4f}" in text
    # pooled parts only at regime
    assert "| pooled | " in text
    assert not any("first 3 s | pooled" in line for line in text.splitlines())
