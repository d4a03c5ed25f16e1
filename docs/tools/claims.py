"""The project's restated SP ≤ NP criterion, judged on a report's or a replicate summary's paired comparisons.

Part of the documentation tooling (docs/tools/): the results pages state it; the installed package does not.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from semiparam_ros.eval.protocol.compare import PairStats
from semiparam_ros.eval.protocol.report import CHECKED_SP_KINDS

__all__ = ["RestatedCheck", "restated_checks"]


@dataclass(frozen=True)
class RestatedCheck:
    """The restated SP ≤ NP criterion for one model, group and segment.

    At regime: the model is not significantly worse than NP (paired t-test over the parts or seeds:
    ``p ≥ alpha``, or its mean difference to NP is negative). Over the first seconds: the model is ahead
    of NP (mean ratio < 1).

    Attributes:
        model: ``SP`` or ``SPJ``.
        group: ``force`` or ``torque``.
        segment: ``regime`` or ``first``.
        level: What the pairs run over (``parts`` of one run, or ``seeds``).
        stats: The paired statistics of the model against NP (measured outputs).
        passed: Whether the criterion holds.
    """

    model: str
    group: str
    segment: str
    level: str
    stats: PairStats
    passed: bool

    @property
    def id(self) -> str:
        """Identifier ``model~NP/group/segment/level``."""
        return f"{self.model}~NP/{self.group}/{self.segment}/{self.level}"


def restated_checks(source: Any, alpha: float = 0.05) -> list[RestatedCheck]:
    """Evaluate the restated SP ≤ NP criterion on a report's (or a replicate summary's) paired comparisons.

    Args:
        source: A :class:`ProtocolReport` (pairs over its test parts) or a
            ``replicates.ReplicateSummary`` (pairs over the seeds' means).
        alpha: Significance level of the paired t-test.

    Returns:
        One check per semiparametric model, group and segment present (measured outputs).
    """
    out = []
    for c in source.comparisons:
        if c.b != "NP" or c.a not in CHECKED_SP_KINDS or c.truth or c.level not in ("parts", "seeds"):
            continue
        s = c.stats
        if c.segment == "regime":
            passed = s.p_t is None or s.p_t >= alpha or s.diff_mean < 0
        else:
            passed = s.ratio < 1.0
        out.append(RestatedCheck(c.a, c.group, c.segment, c.level, s, bool(passed)))
    return out
