"""Paired comparison of two learners over the test parts of the paper's protocol.

Every part is an independent replicate (its own stretch of the test log, its own copy of each trained
model), and both learners see the same samples, so the fair test of "A is better than B" is paired: per
part, the difference of their RMSEs. Reported per group (force, torque) and segment (at regime, first
seconds), against the measured outputs and, when the bag has it, against the noise-free ones:

* ``ratio`` — mean RMSE of A over mean RMSE of B (the issue's criteria use this);
* ``diff_mean`` / ``diff_sem`` — mean of the per-part differences A − B and its standard error
  (``std(ddof=1)/√n``), in N or N·m;
* ``wins`` — parts where A's RMSE is below B's;
* ``p_t`` — two-sided p-value of the paired t-test (differences normal; n − 1 degrees of freedom);
* ``p_sign`` — two-sided exact sign test on the wins (no distributional assumption; ties dropped).

With 10 parts a p-value above 0.05 means the data do not separate the two learners; it is not evidence that
they are equal.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy import stats

from semiparam_ros.eval.metrics import GROUP_UNITS
from semiparam_ros.eval.report import first_key

__all__ = ["DEFAULT_PAIRS", "compare_pair", "comparison_markdown", "format_p", "paired_comparisons"]

#: Pairs compared by default when both learners are in a report: each semiparametric model against NP.
DEFAULT_PAIRS: tuple[tuple[str, str], ...] = (("SP", "NP"), ("SPJ", "NP"), ("SPJ", "SP"))


def compare_pair(a: Sequence[float], b: Sequence[float]) -> dict[str, Any]:
    """Paired statistics of per-part RMSEs ``a`` and ``b`` (same parts, same order).

    Args:
        a: RMSE of learner A per part.
        b: RMSE of learner B per part.

    Returns:
        ``{"n", "ratio", "diff_mean", "diff_sem", "wins", "ties", "p_t", "p_sign"}``; ``diff_sem`` is None
        with one part, ``p_t`` None with one part or when all differences are equal (JSON has no NaN).

    Raises:
        ValueError: Different lengths, no parts, or non-finite values.
    """
    av = np.asarray(a, dtype=np.float64)
    bv = np.asarray(b, dtype=np.float64)
    if av.shape != bv.shape or av.ndim != 1 or av.size == 0:
        raise ValueError(f"need two equally long non-empty sequences, got shapes {av.shape} and {bv.shape}")
    if not (np.isfinite(av).all() and np.isfinite(bv).all()):
        raise ValueError("per-part RMSEs must be finite")
    d = av - bv
    n = d.size
    sem = float(np.std(d, ddof=1) / math.sqrt(n)) if n > 1 else None
    p_t = None
    if sem is not None and sem > 0:
        p_t = float(2.0 * stats.t.sf(abs(float(np.mean(d)) / sem), df=n - 1))
    wins = int(np.sum(d < 0))
    ties = int(np.sum(d == 0))
    decided = n - ties
    p_sign = float(stats.binomtest(wins, decided, 0.5).pvalue) if decided else 1.0
    return {"n": n, "ratio": float(np.mean(av) / np.mean(bv)), "diff_mean": float(np.mean(d)),
            "diff_sem": sem, "wins": wins, "ties": ties, "p_t": p_t, "p_sign": p_sign}


def paired_comparisons(report: Mapping[str, Any], pairs: Sequence[tuple[str, str]] = DEFAULT_PAIRS,
                       first_s: float | None = None) -> list[dict[str, Any]]:
    """Compare learners pairwise on the per-part RMSEs stored in a protocol report.

    Args:
        report: Output of :func:`~semiparam_ros.eval.report.protocol_report` (needs the ``*_splits`` lists).
        pairs: ``(A, B)`` pairs; a pair with a learner missing from the report is skipped.
        first_s: Length of the initial segment [s]; default: the report's.

    Returns:
        One dict per pair, group, segment and target: ``{"a", "b", "group", "segment", "truth", **stats}``
        with ``segment`` ``"regime"`` or ``"first"`` and ``truth`` whether against the noise-free outputs.
    """
    models = report["models"]
    first_s = report["protocol"].get("first_s", 3.0) if first_s is None else first_s
    first = f"_{first_key(first_s)}"
    out: list[dict[str, Any]] = []
    for a, b in pairs:
        if a not in models or b not in models:
            continue
        for truth in (False, True):
            sa = models[a].get("ground_truth") if truth else models[a]
            sb = models[b].get("ground_truth") if truth else models[b]
            if sa is None or sb is None:
                continue
            for group in ("force", "torque"):
                for segment, suffix in (("regime", ""), ("first", first)):
                    key = f"{group}_rmse{suffix}_splits"
                    if key not in sa or key not in sb:
                        continue
                    out.append({"a": a, "b": b, "group": group, "segment": segment, "truth": truth,
                                **compare_pair(sa[key], sb[key])})
    return out


def format_p(value: float | None) -> str:
    """Format a p-value for a table: two significant digits, ``< 0.001`` below that, ``n/a`` for None."""
    return "n/a" if value is None else (f"{value:.2g}" if value >= 0.001 else "< 0.001")


def _p_or(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2g}"


def comparison_markdown(rows: Sequence[Mapping[str, Any]], first_s: float = 3.0) -> str:
    """Markdown table of :func:`paired_comparisons` rows.

    Args:
        rows: The comparisons.
        first_s: Length of the initial segment [s] (for the labels).

    Returns:
        The table with a trailing newline (empty string for no rows).
    """
    if not rows:
        return ""
    lines = ["| A vs B | target | group | segment | mean ratio | mean A − B ± s.e. | A better in "
             "| p (paired t) | p (sign) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        seg = "at regime" if r["segment"] == "regime" else f"first {first_s:g} s"
        unit = GROUP_UNITS.get(r["group"], "")
        lines.append(
            f"| {r['a']} vs {r['b']} | {'noise-free' if r['truth'] else 'measured'} | {r['group']} | {seg} "
            f"| {r['ratio']:.4f} | {r['diff_mean']:+.2g} ± {_p_or(r['diff_sem'])} {unit} "
            f"| {r['wins']} of {r['n']} | {format_p(r['p_t'])} | {format_p(r['p_sign'])} |")
    return "\n".join(lines) + "\n"
