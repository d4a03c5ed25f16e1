"""Paired comparison of learners over the protocol's test parts, against hand-computed statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from semiparam_ros.eval.protocol.compare import compare_pair
from semiparam_ros.eval.protocol.metrics import OutputSpec
from semiparam_ros.eval.protocol.report import (
    GroupStats,
    ModelStats,
    ProtocolReport,
    SegmentStats,
    paired_comparisons,
)
from semiparam_ros.report.tables import comparisons_table


def sign_test_p(wins: int, n: int) -> float:
    """Two-sided exact sign test by direct summation of the binomial(n, 1/2) tails."""
    k = min(wins, n - wins)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2**n
    return min(1.0, 2 * tail)


def test_pair_statistics_equal_the_textbook_formulas():
    rng = np.random.default_rng(3)
    b = rng.uniform(0.3, 0.4, 10)
    a = b + rng.normal(-0.002, 0.003, 10)
    out = compare_pair(a, b)
    d = a - b
    t = d.mean() / (d.std(ddof=1) / math.sqrt(10))
    assert out.n == 10
    assert out.ratio == pytest.approx(a.mean() / b.mean(), rel=1e-12)
    assert out.diff_mean == pytest.approx(d.mean(), rel=1e-12)
    assert out.diff_sem == pytest.approx(d.std(ddof=1) / math.sqrt(10), rel=1e-12)
    assert out.p_t == pytest.approx(stats.ttest_rel(a, b).pvalue, rel=1e-9)
    assert out.p_t == pytest.approx(2 * stats.t.sf(abs(t), 9), rel=1e-9)
    assert out.wins == int(np.sum(a < b))
    assert out.p_sign == pytest.approx(sign_test_p(out.wins, 10), rel=1e-12)


def test_ties_single_part_and_identical_learners():
    out = compare_pair([1.0, 2.0, 3.0], [1.0, 2.5, 2.0])
    assert out.ties == 1 and out.wins == 1
    assert out.p_sign == pytest.approx(sign_test_p(1, 2))
    same = compare_pair([0.3, 0.4], [0.3, 0.4])
    assert same.p_t is None and same.p_sign == 1.0 and same.ratio == 1.0
    one = compare_pair([0.3], [0.2])
    assert one.diff_sem is None and one.p_t is None


@pytest.mark.parametrize(
    ("a", "b"), [([1.0, 2.0], [1.0]), ([], []), ([1.0, np.nan], [1.0, 2.0]), ([[1.0]], [[1.0]])]
)
def test_bad_input_is_refused(a, b):
    with pytest.raises(ValueError):
        compare_pair(a, b)


def test_comparisons_from_a_report_skip_missing_learners():
    def stats_of(values, truth=None):
        v = np.asarray(values, dtype=float)
        groups = {
            "force": GroupStats(SegmentStats.of(v), SegmentStats.of(2 * v)),
            "torque": GroupStats(SegmentStats.of(v / 10), SegmentStats.of(v / 5)),
        }
        return ModelStats(groups, {}, truth)

    models = {
        "NP": stats_of([0.31, 0.32, 0.30], stats_of([0.09, 0.1, 0.08])),
        "SP": stats_of([0.32, 0.33, 0.31], stats_of([0.1, 0.11, 0.09])),
    }
    report = ProtocolReport(
        output=OutputSpec.wrench(),
        models=models,
        splits=3,
        samples_train=1,
        samples_test=3,
        first_s=3.0,
        protocol={},
        config={},
        update_us={},
        train_s={},
        noise=None,
        curves={},
    )
    rows = paired_comparisons(report)
    assert {(r.a, r.b) for r in rows} == {("SP", "NP")}  # no SPJ in the report
    assert len(rows) == 8  # 2 targets × 2 groups × 2 segments
    regime = next(r for r in rows if (r.group, r.segment, r.truth) == ("force", "regime", False))
    assert regime.stats.wins == 0 and regime.stats.diff_mean == pytest.approx(0.01)
    table = comparisons_table(rows)
    assert table.count("\n") == 2 + len(rows) and "| SP vs NP | noise-free | torque | first 3 s |" in table
    assert comparisons_table([]) == ""


def test_direction_is_the_paired_t_verdict_at_5_percent():
    b = np.array([0.30, 0.32, 0.31, 0.33, 0.29])
    behind = compare_pair(b + np.array([0.010, 0.012, 0.011, 0.009, 0.010]), b)
    assert behind.p_t < 0.05 and behind.direction() == "behind"
    assert compare_pair(b - np.array([0.010, 0.012, 0.011, 0.009, 0.010]), b).direction() == "ahead"
    mixed = compare_pair(b + np.array([0.01, -0.01, 0.012, -0.011, 0.0]), b)
    assert mixed.p_t > 0.05 and mixed.direction() == "tie"
