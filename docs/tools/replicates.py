"""The paper's protocol replicated over independent simulated logs (simulator seeds).

One run of the protocol (:mod:`semiparam_ros.eval.protocol.prequential`) is one pair of logs: its 10 test
parts share the
same trained models and the same noise realisation of the training log, so they say how sure we are about
*these* logs, not whether a criterion holds on logs of the same kind in general. Re-simulating the XY and XZ
logs with another seed draws new sensor noise and a new wander of the hand's speed, circle centre and radius
(:mod:`semiparam_ros.sim.scenario`); everything else (robot, non-rigid effects, hyperparameters, protocol) is
unchanged. Each seed is then an independent replicate of the whole experiment, and:

* per criterion of the issue (:func:`~semiparam_ros.eval.protocol.report.paper_checks`): on how many seeds it
  holds,
  and the spread of its value;
* per pair of learners (A vs B), group, segment and target:
  :func:`~semiparam_ros.eval.protocol.compare.compare_pair`
  on the per-seed means (``n`` = seeds; the seeds are independent) and on all parts of all seeds pooled
  (``n`` = seeds × parts; more power, but the parts of one seed share their trained models, so its p-values
  are optimistic).

Only scalars are kept (no curves), so the summary of many seeds is a small JSON file.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from semiparam_ros.eval.protocol.compare import DEFAULT_PAIRS, Comparison, compare_pair
from semiparam_ros.eval.protocol.report import (
    SEGMENTS,
    Check,
    GroupStats,
    ModelStats,
    ProtocolReport,
    SegmentStats,
    first_key,
    paper_checks,
)
from semiparam_ros.report.tables import comparisons_table

__all__ = ["Criterion", "ReplicateSummary", "replicate_summary", "replicates_markdown"]

_PROTOCOL_KEYS = ("split_size", "window_samples")


@dataclass(frozen=True)
class Criterion:
    """One criterion of :func:`~semiparam_ros.eval.protocol.report.paper_checks` over the seeds.

    Attributes:
        checks: The check on each seed (same identifier), in seed order.
    """

    checks: tuple[Check, ...]

    @property
    def id(self) -> str:
        """The check's identifier."""
        return self.checks[0].id

    @property
    def passed(self) -> int:
        """On how many seeds it holds."""
        return sum(c.passed for c in self.checks)

    @property
    def values(self) -> list[float]:
        """Its value on each seed."""
        return [c.value for c in self.checks]


@dataclass(frozen=True)
class ReplicateSummary:
    """The protocol over independent simulated log pairs (see the module docstring).

    Attributes:
        seeds: Simulator seed of each replicate.
        kinds: Learners, in report order.
        first_s: Initial segment [s].
        groups: Output groups.
        protocol: Split size and window of every replicate.
        config: The common configuration.
        per_seed: Per seed and learner, the mean RMSEs (measured; noise-free as ``ground_truth``).
        noise: Per seed, the sensor noise per group (when known).
        criteria: Per criterion identifier, its checks over the seeds.
        comparisons: Paired comparisons over the seed means (``level="seeds"``) and over all parts pooled
            (``level="pooled"``; optimistic p-values).
    """

    seeds: tuple[int, ...]
    kinds: tuple[str, ...]
    first_s: float
    groups: tuple[str, ...]
    protocol: dict[str, Any]
    config: dict[str, Any]
    per_seed: tuple[dict[str, ModelStats], ...]
    noise: tuple[dict[str, float] | None, ...]
    criteria: tuple[Criterion, ...]
    comparisons: tuple[Comparison, ...]

    def criterion(self, check_id: str) -> Criterion | None:
        """Return the criterion with that identifier (``model/reference/group/segment``)."""
        return next((c for c in self.criteria if c.id == check_id), None)

    def to_json(self) -> dict[str, Any]:
        """Return the JSON document (scalars only)."""

        def means(m: ModelStats) -> dict[str, float]:
            return {
                f"{g}_rmse{'' if seg == 'regime' else '_' + first_key(self.first_s)}": m.groups[g]
                .segment(seg)
                .mean
                for g in self.groups
                for seg in SEGMENTS
            }

        per_seed = []
        for seed, models, noise in zip(self.seeds, self.per_seed, self.noise, strict=True):
            entry: dict[str, Any] = {"seed": seed, "models": {}}
            for kind, m in models.items():
                entry["models"][kind] = {"measured": means(m)}
                if m.ground_truth is not None:
                    entry["models"][kind]["ground_truth"] = means(m.ground_truth)
            if noise is not None:
                entry["noise"] = {f"{g}_rmse": v for g, v in noise.items()}
            per_seed.append(entry)
        return {
            "seeds": list(self.seeds),
            "models": list(self.kinds),
            "groups": list(self.groups),
            "config": self.config,
            "protocol": {**self.protocol, "first_s": self.first_s},
            "per_seed": per_seed,
            "criteria": [
                {
                    "id": c.id,
                    "check": c.checks[0].label(self.first_s),
                    "model": c.checks[0].model,
                    "limit": c.checks[0].limit,
                    "strict": c.checks[0].strict,
                    "passed": c.passed,
                    "n": len(c.checks),
                    "values": c.values,
                }
                for c in self.criteria
            ],
            "comparisons": [c.to_json() for c in self.comparisons],
        }

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> ReplicateSummary:
        """Read a summary written by :meth:`to_json`; criteria are recomputed from the per-seed means.

        Raises:
            ValueError: If a required field is missing.
        """
        try:
            first_s = float(doc["protocol"].get("first_s", 3.0))
            groups = tuple(doc.get("groups") or ("force", "torque"))
            suffix = {"regime": "", "first": "_" + first_key(first_s)}

            def stats(d: Mapping[str, Any]) -> ModelStats:
                return ModelStats(
                    {
                        g: GroupStats(
                            *(SegmentStats(float(d[f"{g}_rmse{suffix[s]}"]), float("nan")) for s in SEGMENTS)
                        )
                        for g in groups
                    }
                )

            per_seed, noise = [], []
            for entry in doc["per_seed"]:
                models = {}
                for kind, m in entry["models"].items():
                    truth = m.get("ground_truth")
                    measured = stats(m["measured"])
                    models[kind] = ModelStats(measured.groups, {}, None if truth is None else stats(truth))
                per_seed.append(models)
                n = entry.get("noise")
                noise.append(None if n is None else {k.removesuffix("_rmse"): float(v) for k, v in n.items()})
            comparisons = []
            for row in doc["comparisons"]:
                c = Comparison.from_json(row)
                if c.level == "parts":  # summaries written before the level was named "pooled"
                    c = Comparison(c.a, c.b, c.group, c.segment, c.truth, "pooled", c.stats)
                comparisons.append(c)
            return cls(
                seeds=tuple(int(s) for s in doc["seeds"]),
                kinds=tuple(doc["models"]),
                first_s=first_s,
                groups=groups,
                protocol={k: doc["protocol"].get(k) for k in _PROTOCOL_KEYS},
                config=dict(doc.get("config") or {}),
                per_seed=tuple(per_seed),
                noise=tuple(noise),
                criteria=_criteria(per_seed, groups),
                comparisons=tuple(comparisons),
            )
        except KeyError as err:
            raise ValueError(f"replicate summary without the field {err}") from err


def _criteria(per_seed: Sequence[Mapping[str, ModelStats]], groups: Sequence[str]) -> tuple[Criterion, ...]:
    by_id: dict[str, list[Check]] = {}
    for models in per_seed:
        for check in paper_checks(models, groups):
            by_id.setdefault(check.id, []).append(check)
    return tuple(Criterion(tuple(checks)) for checks in by_id.values())


def replicate_summary(
    reports: Sequence[ProtocolReport], seeds: Sequence[int], pairs: Sequence[tuple[str, str]] = DEFAULT_PAIRS
) -> ReplicateSummary:
    """Summarize protocol reports of the same experiment on logs simulated with different seeds.

    Args:
        reports: One protocol report per seed, all with the same learners, protocol and hyperparameters.
        seeds: The simulator seed of each report (same order).
        pairs: ``(A, B)`` learner pairs to compare; a pair with a learner missing is skipped.

    Returns:
        The :class:`ReplicateSummary`.

    Raises:
        ValueError: No reports, a length mismatch with ``seeds``, repeated seeds, or reports that differ in
            their learners, output, protocol (split size, window, first seconds) or configuration.
    """
    if not reports:
        raise ValueError("need at least one report")
    if len(reports) != len(seeds):
        raise ValueError(f"{len(reports)} reports but {len(seeds)} seeds")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct, got {list(seeds)}")
    ref = reports[0]
    kinds = tuple(ref.models)
    for seed, rep in zip(seeds, reports, strict=True):
        if tuple(rep.models) != kinds:
            raise ValueError(f"seed {seed}: learners {list(rep.models)} differ from {list(kinds)}")
        if (
            rep.output != ref.output
            or rep.first_s != ref.first_s
            or any(rep.protocol.get(k) != ref.protocol.get(k) for k in _PROTOCOL_KEYS)
        ):
            raise ValueError(f"seed {seed}: output or protocol differs from the first report's")
        if rep.config != ref.config:
            raise ValueError(f"seed {seed}: configuration differs from the first report's")
    comparisons: list[Comparison] = []
    for a, b in pairs:
        if a not in kinds or b not in kinds:
            continue
        for truth in (False, True):
            sa = [r.stats(a, truth) for r in reports]
            sb = [r.stats(b, truth) for r in reports]
            if any(s is None for s in sa + sb):
                continue
            for group in ref.groups:
                for segment in SEGMENTS:
                    xa = [s.groups[group].segment(segment) for s in sa if s is not None]
                    xb = [s.groups[group].segment(segment) for s in sb if s is not None]
                    comparisons.append(
                        Comparison(
                            a,
                            b,
                            group,
                            segment,
                            truth,
                            "seeds",
                            compare_pair([x.mean for x in xa], [x.mean for x in xb]),
                        )
                    )
                    comparisons.append(
                        Comparison(
                            a,
                            b,
                            group,
                            segment,
                            truth,
                            "pooled",
                            compare_pair(
                                np.concatenate([x.splits for x in xa]), np.concatenate([x.splits for x in xb])
                            ),
                        )
                    )
    per_seed = tuple(dict(r.models) for r in reports)
    return ReplicateSummary(
        seeds=tuple(int(s) for s in seeds),
        kinds=kinds,
        first_s=ref.first_s,
        groups=ref.groups,
        protocol={k: ref.protocol.get(k) for k in _PROTOCOL_KEYS},
        config=dict(ref.config),
        per_seed=per_seed,
        noise=tuple(r.noise for r in reports),
        criteria=_criteria(per_seed, ref.groups),
        comparisons=tuple(comparisons),
    )


def replicates_markdown(summary: ReplicateSummary) -> str:
    """Tables of a summary: criteria over seeds, per-seed ratios to NP, paired comparisons.

    Args:
        summary: The summary.

    Returns:
        Markdown text (three tables; the pooled comparisons only at regime).
    """
    lines = ["| criterion | id | holds on | min | median | max | limit |", "|---|---|---|---|---|---|---|"]
    for c in summary.criteria:
        v = np.asarray(c.values)
        first = c.checks[0]
        lines.append(
            f"| {first.label(summary.first_s)} | `{c.id}` | {c.passed} of {len(c.checks)} seeds | "
            f"{v.min():.4f} | {float(np.median(v)):.4f} | {v.max():.4f} | {first.limit:g} |"
        )
    semis = [k for k in summary.kinds if k not in ("P", "NP")]
    if "NP" in summary.kinds and semis:
        lines += ["", "Per seed, ratio to NP's mean RMSE at regime (measured; noise-free in brackets):", ""]
        head = " | ".join(f"{k} / NP {g}" for k in semis for g in summary.groups)
        lines += [f"| seed | {head} |", "|---" * (1 + len(semis) * len(summary.groups)) + "|"]
        for seed, models in zip(summary.seeds, summary.per_seed, strict=True):
            cells = []
            for k in semis:
                for g in summary.groups:
                    cell = f"{models[k].rmse(g) / models['NP'].rmse(g):.4f}"
                    gk, gn = models[k].ground_truth, models["NP"].ground_truth
                    if gk is not None and gn is not None:
                        cell += f" ({gk.rmse(g) / gn.rmse(g):.4f})"
                    cells.append(cell)
            lines.append(f"| {seed} | " + " | ".join(cells) + " |")
    rows = [r for r in summary.comparisons if r.level == "seeds" or r.segment == "regime"]
    lines += ["", comparisons_table(rows, summary.first_s, level=True).rstrip()]
    return "\n".join(lines) + "\n"
