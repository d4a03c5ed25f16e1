"""Paired comparison of two learners over the test parts of the paper's protocol.

Every part is an independent replicate (its own stretch of the test log, its own copy of each trained
model), and both learners see the same samples, so the fair test of "A is better than B" is paired: per
part, the difference of their RMSEs. Reported per group (force, torque) and segment (at regime, first
seconds), against the measured outputs and, when the bag has it, against the noise-free ones:

* ``ratio`` — mean RMSE of A over mean RMSE of B (the paper's criteria use this);
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
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

__all__ = ["DEFAULT_PAIRS", "Comparison", "PairStats", "compare_pair", "format_p"]

#: Pairs compared by default when both learners are in a report: each semiparametric model against NP.
DEFAULT_PAIRS: tuple[tuple[str, str], ...] = (("SP", "NP"), ("SPJ", "NP"), ("SPJ", "SP"))


@dataclass(frozen=True)
class PairStats:
    """Paired statistics of per-part (or per-seed) RMSEs of learners A and B (N or N·m).

    Attributes:
        n: Number of pairs.
        ratio: ``mean(A) / mean(B)``.
        diff_mean: Mean of ``A − B``.
        diff_sem: Its standard error ``std(ddof=1)/√n``; ``None`` with one pair.
        wins: Pairs where A is below B.
        ties: Pairs where A equals B.
        p_t: Two-sided paired t-test p-value; ``None`` with one pair or all differences equal.
        p_sign: Two-sided exact sign test p-value (ties dropped).
    """

    n: int
    ratio: float
    diff_mean: float
    diff_sem: float | None
    wins: int
    ties: int
    p_t: float | None
    p_sign: float

    def direction(self, alpha: float = 0.05) -> str:
        """Return ``"ahead"`` (A significantly lower, paired t), ``"behind"`` or ``"tie"``."""
        if self.p_t is not None and self.p_t < alpha:
            return "ahead" if self.diff_mean < 0 else "behind"
        return "tie"


@dataclass(frozen=True)
class Comparison:
    """One paired comparison of learner A with learner B.

    Attributes:
        a: Learner A.
        b: Learner B.
        group: ``force`` or ``torque``.
        segment: ``regime`` or ``first``.
        truth: Against the noise-free outputs (else the measured ones).
        level: ``parts`` (the test parts of one run), ``seeds`` (per-seed means of replicates) or
            ``pooled`` (all parts of all replicates).
        stats: The statistics.
    """

    a: str
    b: str
    group: str
    segment: str
    truth: bool
    level: str
    stats: PairStats

    def to_json(self) -> dict[str, Any]:
        """Return the flat JSON row (``a``, ``b``, ``group``, ``segment``, ``truth``, ``level``, stats)."""
        return {"a": self.a, "b": self.b, "group": self.group, "segment": self.segment, "truth": self.truth,
                "level": self.level, **self.stats.__dict__}

    @classmethod
    def from_json(cls, row: dict[str, Any]) -> Comparison:
        """Read a row written by :meth:`to_json`."""
        fields = PairStats.__dataclass_fields__
        return cls(row["a"], row["b"], row["group"], row["segment"], bool(row["truth"]),
                   row.get("level", "parts"), PairStats(**{k: row[k] for k in fields}))


def compare_pair(a: Sequence[float], b: Sequence[float]) -> PairStats:
    """Paired statistics of per-part RMSEs ``a`` and ``b`` (same parts, same order).

    Args:
        a: RMSE of learner A per part.
        b: RMSE of learner B per part.

    Returns:
        The :class:`PairStats`.

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
    return PairStats(n=n, ratio=float(np.mean(av) / np.mean(bv)), diff_mean=float(np.mean(d)), diff_sem=sem,
                     wins=wins, ties=ties, p_t=p_t, p_sign=p_sign)


def format_p(value: float | None) -> str:
    """Format a p-value for a table: two significant digits, ``< 0.001`` below that, ``n/a`` for None."""
    return "n/a" if value is None else (f"{value:.2g}" if value >= 0.001 else "< 0.001")
