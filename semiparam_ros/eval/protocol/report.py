"""The typed report of the paper's protocol: built once from the arrays, read by tables, figures, JSON, pages.

:func:`protocol_report` turns a :class:`~semiparam_ros.eval.protocol.prequential.ProtocolResult` into a
:class:`ProtocolReport`: per model and group (force, torque) the RMSE at regime and over the first seconds
(:class:`GroupStats`), per output component (wrench axis or joint) its RMSE and nMSE
(:class:`ComponentStats`), the same against the noise-free outputs when the bag has them, the update
times, the mean curves, the paper's criteria (:class:`Check`, named by identifiers) and the paired
comparisons (:class:`~semiparam_ros.eval.protocol.compare.Comparison`). Nothing downstream recomputes or
parses them.

JSON (:meth:`ProtocolReport.to_json`; :meth:`ProtocolReport.from_json` reads it back) keeps these fields
(stable across releases)::

    {"output": kind, "components": [...],   # kind: a robot.output value (OutputKind)
     "models": {"P": {"force_rmse": f, "torque_rmse": t, "force_rmse_first_3s": f0,
                      "torque_rmse_first_3s": t0, "force_rmse_std": ..., "force_rmse_splits": [...], ...,
                      "components": {"fx": {"rmse": ..., "rmse_first": ..., "nmse": ...}, ...},
                      "rmse_mean": ..., "nmse_mean": ...,          # joint torques only
                      "ground_truth": {...same, against the noise-free outputs...}}, "NP": {...}, ...},
     "splits": n, "samples_train": n, "samples_test": n,
     "update_us": {"P": x, ...}, "update_us_stats": {...}, "train_s": {...},
     "noise": {"force_rmse": ..., "torque_rmse": ...}, "protocol": {...}, "config": {...},
     "curves": {"time_s": [...], "P": {"force_mean": [...], "force_std": [...], ...}, ...,
                "ground_truth": {...}},
     "checks": [{"id": "SP/NP/force/regime", "model": ..., ...}, ...], "comparisons": [...]}

``force_rmse`` is the mean over splits of the component-averaged force RMSE (N) over the second half of
each split ("at regime"), ``torque_rmse`` the same for torques (N·m; for joint torques the mean over
joints), the ``_first_<s>s`` values over the first ``first_s`` seconds of each split (``_first_3s`` for the
paper's 3 s); standard deviations are over splits (population, ``ddof=0``); ``update_us`` is the median wall
time of one ``predict_learn_one`` [µs]. ``nmse`` is the MSE at regime over the variance of the measured
output, pooled over splits.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.eval.protocol.compare import DEFAULT_PAIRS, Comparison, compare_pair
from semiparam_ros.eval.protocol.metrics import OutputSpec, group_rmse
from semiparam_ros.eval.protocol.options import DEFAULT_FIRST_S
from semiparam_ros.eval.protocol.prequential import AdaptationResult, ProtocolResult, Recovery

__all__ = [
    "CHECKED_SP_KINDS",
    "SEGMENTS",
    "AdaptationReport",
    "Check",
    "ComponentStats",
    "GroupStats",
    "ModelStats",
    "ProtocolReport",
    "SegmentStats",
    "adaptation_report",
    "first_key",
    "paired_comparisons",
    "paper_checks",
    "protocol_report",
]

#: The two segments of every split: ``regime`` (its second half) and ``first`` (its first ``first_s``).
SEGMENTS: tuple[str, ...] = ("regime", "first")

#: Semiparametric kinds the criteria are evaluated for, each on its own (the paper's cascade; the joint fit).
CHECKED_SP_KINDS: tuple[str, ...] = ("SP", "SPJ")



def first_key(first_s: float) -> str:
    """Return the initial segment's name in JSON fields: ``"first_3s"`` for 3 s (``force_rmse_first_3s``).

    Args:
        first_s: Length of the initial segment [s].
    """
    return f"first_{first_s:g}s"


def _suffix(segment: str, first_s: float) -> str:
    return "" if segment == "regime" else "_" + first_key(first_s)


# ------------------------------------------------------------------------------------------------ records
@dataclass(frozen=True)
class SegmentStats:
    """Component-averaged RMSE of one group over one segment, per split and summarized (N or N·m).

    Attributes:
        mean: Mean over splits.
        std: Population standard deviation over splits.
        splits: The value of each split, in order (empty when only the summary is known).
    """

    mean: float
    std: float
    splits: tuple[float, ...] = ()

    @classmethod
    def of(cls, values: Sequence[float]) -> SegmentStats:
        """Summarize per-split values."""
        arr = np.asarray(values, dtype=np.float64)
        return cls(float(np.mean(arr)), float(np.std(arr)), tuple(float(v) for v in arr))


@dataclass(frozen=True)
class GroupStats:
    """One group's errors (force or torque) of one model: at regime and over the first seconds."""

    regime: SegmentStats
    first: SegmentStats

    def segment(self, segment: str) -> SegmentStats:
        """Return the stats of ``"regime"`` or ``"first"``."""
        if segment not in SEGMENTS:
            raise ValueError(f"segment must be one of {SEGMENTS}, got {segment!r}")
        return self.regime if segment == "regime" else self.first


@dataclass(frozen=True)
class ComponentStats:
    """One output component's errors (a wrench axis or a joint) of one model.

    Attributes:
        rmse: RMSE at regime, mean over splits (N or N·m).
        rmse_first: RMSE over the first seconds, mean over splits.
        nmse: MSE at regime over the variance of the measured component, pooled over splits.
    """

    rmse: float
    rmse_first: float
    nmse: float


@dataclass(frozen=True)
class ModelStats:
    """Everything the report says about one model against one target (measured or noise-free).

    Attributes:
        groups: Per group name (``force``, ``torque``).
        components: Per component name (``fx`` … ``tz`` or joint names), in output order; empty when read
            from an older report without them.
        ground_truth: The same against the noise-free outputs, when known.
    """

    groups: dict[str, GroupStats]
    components: dict[str, ComponentStats] = field(default_factory=dict)
    ground_truth: ModelStats | None = None

    def rmse(self, group: str, segment: str = "regime") -> float:
        """Mean over splits of the group's component-averaged RMSE over a segment (N or N·m)."""
        return self.groups[group].segment(segment).mean

    @property
    def rmse_mean(self) -> float:
        """Mean over components of the RMSE at regime (meaningful for joint torques: one unit)."""
        return float(np.mean([c.rmse for c in self.components.values()])) if self.components else math.nan

    @property
    def nmse_mean(self) -> float:
        """Mean over components of the nMSE at regime."""
        return float(np.mean([c.nmse for c in self.components.values()])) if self.components else math.nan


@dataclass(frozen=True)
class Check:
    """One reproduction criterion: ``value = model's RMSE / reference's RMSE`` against ``limit``.

    Identified by ``(model, reference, group, segment)`` (:attr:`id`); :meth:`label` is for humans only.

    Attributes:
        model: The model judged (``SP``, ``NP``, ``SPJ``).
        reference: The model it is divided by (``P`` or ``NP``).
        group: ``force`` or ``torque``.
        segment: ``regime`` or ``first``.
        value: The ratio of the segment means.
        limit: The threshold.
        strict: ``value < limit`` is required (else ``value <= limit``).
        passed: Whether it holds.
        paired_p: For a criterion that also passes when the model is not significantly worse: the paired
            t-test's two-sided p over the test parts (it passes when ``value`` is within the limit, or the
            model is not behind at 5 %); ``None`` for a plain ratio criterion.
    """

    model: str
    reference: str
    group: str
    segment: str
    value: float
    limit: float
    strict: bool
    passed: bool
    paired_p: float | None = None

    @property
    def id(self) -> str:
        """Identifier ``model/reference/group/segment``, e.g. ``SP/NP/torque/regime``."""
        return f"{self.model}/{self.reference}/{self.group}/{self.segment}"

    def label(self, first_s: float = DEFAULT_FIRST_S) -> str:
        """Human name, e.g. ``SP force RMSE at regime / NP's``."""
        where = "at regime" if self.segment == "regime" else f"over the first {first_s:g} s"
        return f"{self.model} {self.group} RMSE {where} / {self.reference}'s"


@dataclass(frozen=True)
class ProtocolReport:
    """The report of one run of the paper's protocol (see the module docstring for the JSON form).

    Attributes:
        output: What the outputs are (groups, components, units).
        models: Per model kind, in run order.
        splits: Number of test parts.
        samples_train: Training samples learned.
        samples_test: Test samples used (splits × split size).
        first_s: Length of the initial segment [s].
        protocol: Settings of the run (split size, window, bags, drops, ...), JSON-ready.
        config: Flat configuration (dotted names) the models were built from.
        update_us: Per model, ``{"median", "mean", "p95", "max"}`` of one predict + learn [µs].
        train_s: Per model, training wall time [s].
        noise: Per group, RMSE of measured minus noise-free outputs (N, N·m), when known.
        curves: ``{"time_s": [...], kind: {"<group>_mean": [...], "<group>_std": [...]}, "ground_truth":
            {...}}`` (JSON-ready, 7 significant digits).
        checks: The paper's criteria (:func:`paper_checks`), empty without P, NP and a semiparametric model.
        comparisons: Paired comparisons over the parts (:func:`paired_comparisons`).
    """

    output: OutputSpec
    models: dict[str, ModelStats]
    splits: int
    samples_train: int
    samples_test: int
    first_s: float
    protocol: dict[str, Any]
    config: dict[str, Any]
    update_us: dict[str, dict[str, float]]
    train_s: dict[str, float]
    noise: dict[str, float] | None
    curves: dict[str, Any]
    checks: tuple[Check, ...] = ()
    comparisons: tuple[Comparison, ...] = ()

    @property
    def groups(self) -> tuple[str, ...]:
        """Group names in report order."""
        return tuple(self.output.groups)

    def stats(self, kind: str, truth: bool = False) -> ModelStats | None:
        """Return a model's stats against the measured (or noise-free) outputs; ``None`` if not known."""
        m = self.models.get(kind)
        return None if m is None else (m.ground_truth if truth else m)

    def check(self, model: str, reference: str, group: str, segment: str) -> Check | None:
        """Return the criterion with that identifier, if it was evaluated."""
        return next(
            (
                c
                for c in self.checks
                if (c.model, c.reference, c.group, c.segment) == (model, reference, group, segment)
            ),
            None,
        )

    def comparison(
        self, a: str, b: str, group: str, segment: str = "regime", truth: bool = False
    ) -> Comparison | None:
        """Return the paired comparison of A with B in one group, segment and target, if it was made."""
        return next(
            (
                c
                for c in self.comparisons
                if (c.a, c.b, c.group, c.segment, c.truth) == (a, b, group, segment, truth)
            ),
            None,
        )

    # ------------------------------------------------------------------------------------------ JSON
    def to_json(self) -> dict[str, Any]:
        """Return the JSON document (plain Python types; see the module docstring)."""
        doc: dict[str, Any] = {
            "output": self.output.kind,
            "components": list(self.output.components),
            "models": {k: _model_json(m, self.first_s, self.output) for k, m in self.models.items()},
            "splits": self.splits,
            "samples_train": self.samples_train,
            "samples_test": self.samples_test,
            "update_us": {k: v["median"] for k, v in self.update_us.items()},
            "update_us_stats": self.update_us,
            "train_s": self.train_s,
            "protocol": {**self.protocol, "first_s": self.first_s},
            "config": self.config,
            "curves": self.curves,
            "checks": [
                {
                    "id": c.id,
                    "check": c.label(self.first_s),
                    "model": c.model,
                    "reference": c.reference,
                    "group": c.group,
                    "segment": c.segment,
                    "value": c.value,
                    "limit": c.limit,
                    "strict": c.strict,
                    "passed": c.passed,
                    "paired_p": c.paired_p,
                }
                for c in self.checks
            ],
            "comparisons": [c.to_json() for c in self.comparisons],
        }
        if self.noise is not None:
            doc["noise"] = {f"{g}_rmse": v for g, v in self.noise.items()}
        return doc

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> ProtocolReport:
        """Read a report written by :meth:`to_json` (or by ``evaluate --json`` of earlier versions).

        Checks and comparisons are recomputed from the per-split values (they are derived data).

        Raises:
            ValueError: If a required field is missing.
        """
        try:
            output = _output_of(doc)
            protocol = dict(doc["protocol"])
            first_s = float(protocol.get("first_s", 3.0))
            models = {k: _model_from_json(m, first_s, output) for k, m in doc["models"].items()}
            stats = doc.get("update_us_stats") or {k: {"median": v} for k, v in doc["update_us"].items()}
            noise = doc.get("noise")
            report = cls(
                output=output,
                models=models,
                splits=int(doc["splits"]),
                samples_train=int(doc["samples_train"]),
                samples_test=int(doc["samples_test"]),
                first_s=first_s,
                protocol=protocol,
                config=dict(doc.get("config") or {}),
                update_us={k: dict(v) for k, v in stats.items()},
                train_s=dict(doc.get("train_s") or {}),
                noise=None
                if noise is None
                else {k.removesuffix("_rmse"): float(v) for k, v in noise.items()},
                curves=dict(doc.get("curves") or {}),
            )
        except KeyError as err:
            raise ValueError(f"protocol report without the field {err}") from err
        return report.with_derived()

    def with_derived(self) -> ProtocolReport:
        """Return the report with its checks and paired comparisons computed from its models."""
        return ProtocolReport(
            **{
                **self.__dict__,
                "checks": tuple(paper_checks(self.models, self.groups)),
                "comparisons": tuple(paired_comparisons(self)),
            }
        )


def _output_of(doc: Mapping[str, Any]) -> OutputSpec:
    kind = doc.get("output")
    if kind is None:  # reports written before the output kind was recorded: the paper's wrench
        return OutputSpec.wrench()
    return OutputSpec(kind, tuple(doc["components"]))


def _group_json(g: GroupStats, name: str, first_s: float) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for segment in SEGMENTS:
        s = g.segment(segment)
        key = f"{name}_rmse{_suffix(segment, first_s)}"
        out[key] = s.mean
        out[key + "_std"] = s.std
        out[key + "_splits"] = list(s.splits)
    return out


def _model_json(m: ModelStats, first_s: float, output: OutputSpec) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, g in m.groups.items():
        out.update(_group_json(g, name, first_s))
    if m.components:
        out["components"] = {
            k: {"rmse": c.rmse, "rmse_first": c.rmse_first, "nmse": c.nmse} for k, c in m.components.items()
        }
        if output.kind == OutputKind.JOINT_TORQUES:
            out["rmse_mean"] = m.rmse_mean
            out["nmse_mean"] = m.nmse_mean
    if m.ground_truth is not None:
        out["ground_truth"] = _model_json(m.ground_truth, first_s, output)
    return out


def _model_from_json(doc: Mapping[str, Any], first_s: float, output: OutputSpec) -> ModelStats:
    groups = {}
    for name in output.groups:
        segs = {}
        for segment in SEGMENTS:
            key = f"{name}_rmse{_suffix(segment, first_s)}"
            segs[segment] = SegmentStats(
                float(doc[key]),
                float(doc.get(key + "_std", math.nan)),
                tuple(float(v) for v in doc.get(key + "_splits", ())),
            )
        groups[name] = GroupStats(segs["regime"], segs["first"])
    components = {
        k: ComponentStats(float(c["rmse"]), float(c["rmse_first"]), _float(c["nmse"]))
        for k, c in (doc.get("components") or {}).items()
    }
    truth = doc.get("ground_truth")
    return ModelStats(groups, components, None if truth is None else _model_from_json(truth, first_s, output))


def _float(value: Any) -> float:
    return math.nan if value is None else float(value)


# ------------------------------------------------------------------------------------------ building
def _rounded(values: np.ndarray, digits: int = 7) -> list[float]:
    """Curve values to ``digits`` significant digits (compact JSON; far below any plotted resolution)."""
    return [float(f"{v:.{digits}g}") for v in np.asarray(values, dtype=np.float64)]


def _model_stats(result: ProtocolResult, kind: str, truth: bool) -> ModelStats:
    groups = {
        g: GroupStats(*(SegmentStats.of(result.segment_rmse(kind, g, seg, truth)) for seg in SEGMENTS))
        for g in result.output.groups
    }
    regime = np.mean(result.component_rmse(kind, "regime", truth), axis=0)
    first = np.mean(result.component_rmse(kind, "first", truth), axis=0)
    nmse = result.component_nmse(kind, "regime", truth)
    components = {
        name: ComponentStats(float(regime[i]), float(first[i]), float(nmse[i]))
        for i, name in enumerate(result.output.components)
    }
    return ModelStats(groups, components)


def _curves(result: ProtocolResult, truth: bool) -> dict[str, Any]:
    curves: dict[str, Any] = {}
    for kind in result.kinds:
        entry: dict[str, list[float]] = {}
        for group in result.output.groups:
            per_split = result.curves(kind, group, truth)
            entry[f"{group}_mean"] = _rounded(np.mean(per_split, axis=0))
            entry[f"{group}_std"] = _rounded(np.std(per_split, axis=0))
        curves[kind] = entry
    return curves


def protocol_report(
    result: ProtocolResult,
    *,
    config: Mapping[str, Any] | None = None,
    protocol: Mapping[str, Any] | None = None,
) -> ProtocolReport:
    """Build the typed report of the paper's protocol, with its checks and paired comparisons.

    Args:
        result: Output of :func:`~semiparam_ros.eval.protocol.prequential.run_protocol`.
        config: Flat configuration (dotted names) the models were built from.
        protocol: Extra protocol settings to record (bags, topics, drops, ...).

    Returns:
        The :class:`ProtocolReport`.
    """
    has_truth = result.targets_true is not None
    models: dict[str, ModelStats] = {}
    for kind in result.kinds:
        m = _model_stats(result, kind, truth=False)
        if has_truth:
            m = ModelStats(m.groups, m.components, _model_stats(result, kind, truth=True))
        models[kind] = m
    update = {k: result.update_ns[k].ravel() * 1e-3 for k in result.kinds}
    curves: dict[str, Any] = {"time_s": _rounded(result.time_s, 9), **_curves(result, truth=False)}
    noise = None
    if has_truth:
        err = result.targets - result.targets_true
        noise = {
            g: float(np.mean([group_rmse(e[:, list(spec.columns)]) for e in err]))
            for g, spec in result.output.groups.items()
        }
        curves["ground_truth"] = _curves(result, truth=True)
    settings = {
        "split_size": int(result.targets.shape[1]),
        "sample_period_s": result.sample_period_s,
        "window_samples": int(result.window),
        "window_s": result.window * result.sample_period_s,
        "first_samples": int(result.first),
        "regime": "second half of each split",
        "std": "population standard deviation over splits (ddof=0)",
        **dict(protocol or {}),
    }
    report = ProtocolReport(
        output=result.output,
        models=models,
        splits=len(result.bounds),
        samples_train=int(result.samples_train),
        samples_test=result.samples_test,
        first_s=float(result.first_s),
        protocol=settings,
        config=dict(config or {}),
        update_us={
            k: {
                "median": float(np.median(v)),
                "mean": float(np.mean(v)),
                "p95": float(np.percentile(v, 95)),
                "max": float(np.max(v)),
            }
            for k, v in update.items()
        },
        train_s={k: v * 1e-9 for k, v in result.train_ns.items()},
        noise=noise,
        curves=curves,
    )
    return report.with_derived()


def paper_checks(
    models: Mapping[str, ModelStats], groups: Sequence[str] = ("force", "torque")
) -> list[Check]:
    """Evaluate the paper's reproduction criteria.

    At regime: SP and NP RMSE ≤ 0.5 × P's (force) and ≤ 0.4 × P's (torque), SP ≤ NP or not significantly
    worse (paired t-test over the test parts, p ≥ 0.05, where the parts' values are known: at regime both
    learners are at the noise floor, and a ratio of 1.001 is a tie, not a loss); over the first seconds
    SP < NP. The SP criteria are evaluated separately, with the same thresholds, for each semiparametric
    model present (:data:`CHECKED_SP_KINDS`): those of ``SP`` and NP's come first, then those of ``SPJ``.

    Args:
        models: Model stats by kind (a :class:`ProtocolReport`'s ``models``).
        groups: The output's groups; the criteria need ``force`` and ``torque`` (a wrench).

    Returns:
        The checks; empty if P, NP and a semiparametric model are not all there or the output is not a
        wrench (the paper's thresholds are for force and torque).
    """
    sp_kinds = [k for k in CHECKED_SP_KINDS if k in models]
    if not {"P", "NP"} <= set(models) or not sp_kinds or set(groups) != {"force", "torque"}:
        return []
    checks: list[Check] = []

    def add(kind: str, ref: str, group: str, segment: str, limit: float, strict: bool = False,
            paired: bool = False) -> None:
        value = models[kind].rmse(group, segment) / models[ref].rmse(group, segment)
        passed = bool(value < limit if strict else value <= limit)
        p_value = None
        a = models[kind].groups[group].segment(segment).splits
        b = models[ref].groups[group].segment(segment).splits
        if paired and len(a) == len(b) and len(a) > 1:
            stats = compare_pair(a, b)
            p_value = 1.0 if stats.p_t is None else float(stats.p_t)
            passed = passed or stats.direction() != "behind"
        checks.append(Check(kind, ref, group, segment, value, limit, strict, passed, p_value))

    for sp in sp_kinds:
        for kind in (sp, "NP") if sp == sp_kinds[0] else (sp,):
            for group, factor in (("force", 0.5), ("torque", 0.4)):
                add(kind, "P", group, "regime", factor)
        for group in ("force", "torque"):
            add(sp, "NP", group, "regime", 1.0, paired=True)
        for group in ("force", "torque"):
            add(sp, "NP", group, "first", 1.0, strict=True)
    return checks


def paired_comparisons(
    report: ProtocolReport, pairs: Sequence[tuple[str, str]] = DEFAULT_PAIRS
) -> list[Comparison]:
    """Compare learners pairwise on the per-part RMSEs of a report (both targets, groups and segments).

    Args:
        report: The report (its models need the per-split values).
        pairs: ``(A, B)`` pairs; a pair with a learner missing is skipped.

    Returns:
        One :class:`~semiparam_ros.eval.protocol.compare.Comparison` per pair, target, group and segment.
    """
    out: list[Comparison] = []
    for a, b in pairs:
        for truth in (False, True):
            sa, sb = report.stats(a, truth), report.stats(b, truth)
            if sa is None or sb is None:
                continue
            for group in report.groups:
                for segment in SEGMENTS:
                    xa = sa.groups[group].segment(segment).splits
                    xb = sb.groups[group].segment(segment).splits
                    if not xa or not xb:
                        continue
                    out.append(Comparison(a, b, group, segment, truth, "parts", compare_pair(xa, xb)))
    return out


# ------------------------------------------------------------------------------------------ adaptation
@dataclass(frozen=True)
class AdaptationReport:
    """The report of the payload scenario.

    Attributes:
        output: What the outputs are.
        summary: Per model name and group, the :class:`~semiparam_ros.eval.protocol.prequential.Recovery`.
        change_s: Time of the change from the stream's first sample [s].
        tolerance: Recovery tolerance (ratio to the pre-change level).
        deadline_s: Recovery deadline [s].
        pre_s: Pre-change reference segment [s].
        window_samples: Sliding window [samples].
        protocol: Settings of the run (bag, β, pickup time, drops).
        config: Flat configuration.
        curves: ``{"time_s": [...], name: {group: [...]}}`` (JSON-ready).
    """

    output: OutputSpec
    summary: dict[str, dict[str, Recovery]]
    change_s: float
    tolerance: float
    deadline_s: float
    pre_s: float
    window_samples: int
    protocol: dict[str, Any]
    config: dict[str, Any]
    curves: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        """Return the JSON document."""
        return {
            "output": self.output.kind,
            "components": list(self.output.components),
            "summary": {k: {g: dict(r.__dict__) for g, r in v.items()} for k, v in self.summary.items()},
            "change_s": self.change_s,
            "tolerance": self.tolerance,
            "deadline_s": self.deadline_s,
            "pre_s": self.pre_s,
            "window_samples": self.window_samples,
            "protocol": self.protocol,
            "config": self.config,
            "curves": self.curves,
        }

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> AdaptationReport:
        """Read a report written by :meth:`to_json` (or ``evaluate payload --json``).

        Raises:
            ValueError: If a required field is missing.
        """
        try:
            summary = {
                k: {
                    g: Recovery(
                        **{
                            f: (
                                math.nan if f in ("post_rmse", "level_at_deadline") and r[f] is None else r[f]
                            )
                            for f in Recovery.__dataclass_fields__
                        }
                    )
                    for g, r in v.items()
                }
                for k, v in doc["summary"].items()
            }
            return cls(
                output=_output_of(doc),
                summary=summary,
                change_s=float(doc["change_s"]),
                tolerance=float(doc["tolerance"]),
                deadline_s=float(doc["deadline_s"]),
                pre_s=float(doc["pre_s"]),
                window_samples=int(doc["window_samples"]),
                protocol=dict(doc.get("protocol") or {}),
                config=dict(doc.get("config") or {}),
                curves=dict(doc.get("curves") or {}),
            )
        except KeyError as err:
            raise ValueError(f"adaptation report without the field {err}") from err


def adaptation_report(
    result: AdaptationResult,
    *,
    config: Mapping[str, Any] | None = None,
    protocol: Mapping[str, Any] | None = None,
    stride: int = 1,
) -> AdaptationReport:
    """Build the report of the adaptation (payload) scenario.

    Args:
        result: Output of :func:`~semiparam_ros.eval.protocol.prequential.run_adaptation`.
        config: Flat configuration the models were built from.
        protocol: Extra settings to record.
        stride: Keep every ``stride``-th curve point (smaller files for long streams).

    Returns:
        The :class:`AdaptationReport`.
    """
    keep = slice(None, None, max(1, int(stride)))
    return AdaptationReport(
        output=result.output,
        summary=result.summary,
        change_s=result.change_s,
        tolerance=result.tolerance,
        deadline_s=result.deadline_s,
        pre_s=result.pre_s,
        window_samples=int(result.window),
        protocol=dict(protocol or {}),
        config=dict(config or {}),
        curves={
            "time_s": _rounded(result.time_s[keep], 9),
            **{k: {g: _rounded(c[keep]) for g, c in v.items()} for k, v in result.curves.items()},
        },
    )
