"""Paired comparison of learners over the protocol's test parts, against hand-computed statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from semiparam_ros.eval.compare import compare_pair, comparison_markdown, paired_comparisons


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
    assert out["n"] == 10
    assert out["ratio"] == pytest.approx(a.mean() / b.mean(), rel=1e-12)
    assert out["diff_mean"] == pytest.approx(d.mean(), rel=1e-12)
    assert out["diff_sem"] == pytest.approx(d.std(ddof=1) / math.sqrt(10), rel=1e-12)
    assert out["p_t"] == pytest.approx(stats.ttest_rel(a, b).pvalue, rel=1e-9)
    assert out["p_t"] == pytest.approx(2 * stats.t.sf(abs(t), 9), rel=1e-9)
    assert out["wins"] == int(np.sum(a < b))
    assert out["p_sign"] == pytest.approx(sign_test_p(out["wins"], 10), rel=1e-12)


def test_ties_single_part_and_identical_learners():
    out = compare_pair([1.0, 2.0, 3.0], [1.0, 2.5, 2.0])
    assert out["ties"] == 1 and out["wins"] == 1
    assert out["p_sign"] == pytest.approx(sign_test_p(1, 2))
    same = compare_pair([0.3, 0.4], [0.3, 0.4])
    assert same["p_t"] is None and same["p_sign"] == 1.0 and same["ratio"] == 1.0
    one = compare_pair([0.3], [0.2])
    assert one["diff_sem"] is None and one["p_t"] is None


@pytest.mark.parametrize(("a", "b"), [([1.0, 2.0], [1.0]), ([], []), ([1.0, np.nan], [1.0, 2.0]),
                                      ([[1.0]], [[1.0]])])
def test_bad_input_is_refused(a, b):
    with pytest.raises(ValueError):
        compare_pair(a, b)


def test_comparisons_from_a_report_skip_missing_learners():
    def stats_of(values):
        v = np.asarray(values)
        return {"force_rmse_splits": list(v), "torque_rmse_splits": list(v / 10),
                "force_rmse_first_3s_splits": list(2 * v), "torque_rmse_first_3s_splits": list(v / 5)}

    report = {"protocol": {"first_s": 3.0}, "models": {
        "NP": {**stats_of([0.31, 0.32, 0.30]), "ground_truth": stats_of([0.09, 0.1, 0.08])},
        "SP": {**stats_of([0.32, 0.33, 0.31]), "ground_truth": stats_of([0.1, 0.11, 0.09])},
    }}
    rows = paired_comparisons(report)
    assert {(r["a"], r["b"]) for r in rows} == {("SP", "NP")}  # no SPJ in the report
    assert len(rows) == 8  # 2 targets × 2 groups × 2 segments
    regime = next(r for r in rows if (r["group"], r["segment"], r["truth"]) == ("force", "regime", False))
    assert regime["wins"] == 0 and regime["diff_mean"] == pytest.approx(0.01)
    table = comparison_markdown(rows)
    assert table.count("\n") == 2 + len(rows) and "| SP vs NP | noise-free | torque | first 3 s |" in table
    assert comparison_markdown([]) == ""
