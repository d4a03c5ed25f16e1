"""Contact evaluation: the node's estimator over a log with contact episodes, with the gate on and off.

A log with known contact episodes (the simulator's ``scenario.yaml``: ``contacts.episodes`` and an
optional later ``payload``) is run through :class:`~semiparam_ros.core.estimator.online.OnlineEstimator` — the
node's data path, which measures the sample period itself so ``adaptation.time_constant`` applies — once
with ``gate.enabled`` true and once false, everything else as configured. For each run:

- **detection** (:mod:`semiparam_ros.core.stream.episodes`): a sample is flagged when a component of the
  external estimate ``y − ŷ`` exceeds ``gate.threshold`` published σ; samples before ``gate.warmup`` are not
  scored. Per episode: detected and delay [s]; recall over all episodes and over those with a peak force ≥
  ``strong_force`` [N]; false alarms per minute of contact-free time. Flags within ``pickup_window_s`` of a
  payload pickup are not false alarms (that time is left out like an episode): the new load *is* an external
  force until the gate adopts it after ``gate.max_contact_duration``, and the learners need a moment more to
  absorb it (default window: ``gate.max_contact_duration`` + 2 s);
- **contact immunity**: the RMSE per output group (mean over the group's components of each component's
  RMSE) over ``window_s`` before the first episode (from the end of the warm-up at the earliest) and over
  ``window_s`` after the last episode's end (up to the pickup at the latest); ``ratio = after / before``;
- **payload recovery** (:func:`~semiparam_ros.eval.protocol.prequential.recovery`, the payload scenario's
  definition):
  the first time after the pickup from which the sliding-window RMSE stays within ``tolerance ×`` its level
  over the ``pre_s`` before the pickup; and the *adoption* time: the first time after the peak of the
  sliding-window RMSE at which it has fallen back by ``1 − adopted_fraction`` of the excess it rose above
  the pre-pickup level (default: 80 % of the pickup's error gone), the moment the model has taken the load
  in even if the residual stage keeps settling for a few τ.

Times in the report are seconds from the recording's start (``scenario.yaml``'s ``start_stamp_ns``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.core.stream.episodes import flag_samples, score_episodes
from semiparam_ros.core.stream.messages import JointStateData, WrenchData
from semiparam_ros.core.stream.rate import stream_period_s
from semiparam_ros.eval.bags.replay import Topics, payload_pickup, read_scenario
from semiparam_ros.eval.protocol.metrics import OutputSpec, group_rmse, window_samples, windowed_rmse
from semiparam_ros.eval.protocol.options import DEFAULT_WINDOW_S
from semiparam_ros.eval.protocol.prequential import Recovery, recovery
from semiparam_ros.io.bags import read_messages, topic_info

__all__ = [
    "ContactReport",
    "ContactRun",
    "EpisodeStats",
    "GateStats",
    "GroundTruthEpisodes",
    "contact_report",
    "external_truth",
    "read_episodes",
    "run_contacts",
    "score_run",
]

#: Topics of the true external effect written by the simulator (F/T sensor, joint torques).
EXTERNAL_WRENCH_TOPIC = "/ground_truth/external_wrench"
EXTERNAL_TORQUES_TOPIC = "/ground_truth/external_joint_torques"
_NS = 1e-9


@dataclass(frozen=True)
class GroundTruthEpisodes:
    """The true contacts and payload of a simulated log (``scenario.yaml``).

    Attributes:
        start_stamp_ns: Stamp of the recording's start [ns]; times below count from it.
        episodes: (m, 2) ``[start, end)`` of each contact [s].
        peak_force: (m,) peak force of each contact [N].
        pickup_s: Payload pickup time [s], or ``None``.
    """

    start_stamp_ns: int
    episodes: np.ndarray
    peak_force: np.ndarray
    pickup_s: float | None


def read_episodes(bag: str | Path) -> GroundTruthEpisodes:
    """Read the contact episodes (and payload pickup) from the ``scenario.yaml`` next to a bag.

    Args:
        bag: Bag folder or ``.mcap`` file.

    Returns:
        The ground truth.

    Raises:
        ValueError: If the file is missing, unreadable or records no contact episodes.
    """
    path, doc = read_scenario(bag, "the contact episodes")
    contacts = doc.get("contacts") if doc is not None else None
    episodes = contacts.get("episodes") if isinstance(contacts, Mapping) else None
    if not isinstance(episodes, list) or not isinstance(doc.get("start_stamp_ns"), int):
        raise ValueError(f"{path} records no contact episodes (contacts.episodes, start_stamp_ns); simulate "
                         "the log with --scenario contacts")
    try:
        ep = np.array([[float(e["start_s"]), float(e["end_s"])] for e in episodes]).reshape(-1, 2)
        peak = np.array([float(e["peak_force_N"]) for e in episodes])
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{path}: malformed contact episode: {err}") from err
    pickup_s, _ = payload_pickup(doc)
    return GroundTruthEpisodes(int(doc["start_stamp_ns"]), ep, peak, pickup_s)


@dataclass(frozen=True)
class ContactRun:
    """What the estimator produced over the log with one gate setting (arrays, not serialized).

    Attributes:
        gate: Whether the contact gate was on.
        time_s: (n,) sample times [s from the recording's start].
        y: (n, t) measured outputs [N, N·m].
        predicted: (n, t) a-priori predictions [N, N·m].
        std: (n, t) published predictive σ [N, N·m].
        learned: (n,) whether each sample was learned.
        not_learned: The estimator's not-learned counts by reason.
        forgetting: β the estimator derived from ``adaptation.time_constant`` (``None``: configured β).
    """

    gate: bool
    time_s: np.ndarray
    y: np.ndarray
    predicted: np.ndarray
    std: np.ndarray
    learned: np.ndarray
    not_learned: dict[str, int]
    forgetting: float | None

    @property
    def external(self) -> np.ndarray:
        """(n, t) the external estimate ``y − ŷ`` [N, N·m]."""
        return self.y - self.predicted


def run_estimator(bag: str | Path, config: EstimatorConfig, *, start_stamp_ns: int,
                  topics: Topics | None = None) -> ContactRun:
    """Run the node's estimator over a bag and record every sample's prediction and σ.

    Args:
        bag: Bag folder or ``.mcap`` file.
        config: Configuration (``gate.enabled`` decides the run's gate).
        start_stamp_ns: Stamp of time zero [ns].
        topics: Topics to read (default from the configuration).

    Returns:
        The run.

    Raises:
        ValueError: If the bag cannot be read or yields no sample.
    """
    topics = topics or Topics.from_config(config)
    est = OnlineEstimator(config)
    est.inline_projection = True  # the node's consistent rigid body, on its schedule in the bag's time
    wrench = topics.wrench if config.output_kind == OutputKind.WRENCH else None
    stamps: list[int] = []
    ys: list[np.ndarray] = []
    preds: list[np.ndarray] = []
    stds: list[np.ndarray] = []
    learned: list[bool] = []
    for msg in read_messages(bag, joint_states_topic=topics.joint_states, wrench_topic=wrench):
        results = est.process(msg)
        for r in results:
            stamps.append(r.sample.stamp_ns)
            ys.append(r.sample.y)
            preds.append(r.prediction.total)
            assert r.std is not None  # the estimator always publishes σ
            stds.append(r.std)
            learned.append(r.learned)
    if not stamps:
        raise ValueError(f"{bag}: no usable samples (drops: {est.drops})")
    return ContactRun(gate=bool(config["gate.enabled"]),
                      time_s=(np.array(stamps, dtype=np.int64) - start_stamp_ns) * _NS,
                      y=np.array(ys), predicted=np.array(preds), std=np.array(stds),
                      learned=np.array(learned), not_learned=dict(est.not_learned),
                      forgetting=est.forgetting)


def external_truth(bag: str | Path, run: ContactRun, config: EstimatorConfig, start_stamp_ns: int
                   ) -> np.ndarray | None:
    """Return the simulator's true external effect at each sample of a run, when the bag has it.

    F/T sensor: ``/ground_truth/external_wrench`` at the sample's (wrench) stamp; joint torques:
    ``/ground_truth/external_joint_torques`` (JointState effort) at the sample's stamp, mapped to the
    configured joint order.

    Args:
        bag: The bag.
        run: A run over it.
        config: Its configuration.
        start_stamp_ns: Stamp of time zero [ns].

    Returns:
        (n, t) [N, N·m] (NaN where a sample has no ground-truth message), or ``None`` without the topic.
    """
    wrench = config.output_kind == OutputKind.WRENCH
    topic = EXTERNAL_WRENCH_TOPIC if wrench else EXTERNAL_TORQUES_TOPIC
    if topic not in topic_info(bag):
        return None
    truth: dict[int, np.ndarray] = {}
    joints = list(config["robot.joints"])
    if wrench:
        for m in read_messages(bag, joint_states_topic=None, wrench_topic=topic):
            truth[m.stamp_ns] = cast(WrenchData, m).wrench  # only the wrench topic is read
    else:
        for m in read_messages(bag, joint_states_topic=topic, wrench_topic=None):
            m = cast(JointStateData, m)  # only the JointState topic is read
            index = {n: i for i, n in enumerate(m.names)}
            truth[m.stamp_ns] = np.array([m.effort[index[j]] for j in joints])
    stamps = np.round(run.time_s / _NS).astype(np.int64) + start_stamp_ns
    out = np.full(run.y.shape, np.nan)
    for i, s in enumerate(stamps):
        v = truth.get(int(s))
        if v is not None:
            out[i] = v
    return out


@dataclass(frozen=True)
class EpisodeStats:
    """One true contact and how the run detected it.

    Attributes:
        start_s: Start [s].
        end_s: End [s].
        peak_force: Peak force [N].
        detected: Whether a flagged sample fell in ``[start, end + tolerance]``.
        delay_s: Time from the start to the first such sample [s] (NaN when missed).
    """

    start_s: float
    end_s: float
    peak_force: float
    detected: bool
    delay_s: float


@dataclass(frozen=True)
class GateStats:
    """The numbers of one run (gate on or off).

    Attributes:
        gate: Whether the gate was on.
        episodes: Per true contact.
        recall: Fraction of episodes detected.
        recall_strong: Fraction of the episodes with a peak ≥ ``strong_force`` detected (NaN if none).
        false_alarms: Runs of flagged samples outside every episode.
        false_alarms_per_minute: Per minute of contact-free scored time.
        median_delay_s: Median detection delay of the detected episodes [s] (NaN if none).
        before: RMSE per group over the window before the first contact [N, N·m].
        after: RMSE per group over the window after the last contact [N, N·m].
        recovery: Per group, the payload recovery (``None`` without a pickup).
        adoption_s: Per group, the payload adoption time [s after the pickup] (``None`` inside: never;
            ``None`` overall: no pickup).
        not_learned: The estimator's not-learned counts by reason.
        forgetting: β derived from ``adaptation.time_constant`` (``None``: the configured factors).
    """

    gate: bool
    episodes: tuple[EpisodeStats, ...]
    recall: float
    recall_strong: float
    false_alarms: int
    false_alarms_per_minute: float
    median_delay_s: float
    before: dict[str, float]
    after: dict[str, float]
    recovery: dict[str, Recovery] | None
    adoption_s: dict[str, float | None] | None = None
    not_learned: dict[str, int] = field(default_factory=dict)
    forgetting: float | None = None

    def ratio(self, group: str) -> float:
        """``after / before`` of a group's RMSE."""
        b = self.before[group]
        return self.after[group] / b if b > 0 else math.inf

    def to_json(self) -> dict[str, Any]:
        """Return the JSON document."""
        return {
            "gate": self.gate,
            "episodes": [dict(e.__dict__) for e in self.episodes],
            "recall": self.recall,
            "recall_strong": self.recall_strong,
            "false_alarms": self.false_alarms,
            "false_alarms_per_minute": self.false_alarms_per_minute,
            "median_delay_s": self.median_delay_s,
            "rmse_before_first_contact": self.before,
            "rmse_after_last_contact": self.after,
            "ratio_after_before": {g: self.ratio(g) for g in self.before},
            "recovery": None if self.recovery is None
            else {g: dict(r.__dict__) for g, r in self.recovery.items()},
            "adoption_s": self.adoption_s,
            "not_learned": self.not_learned,
            "forgetting": self.forgetting,
        }

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> GateStats:
        """Read :meth:`to_json` back (``null`` floats become NaN)."""
        rec = doc.get("recovery")
        return cls(
            gate=bool(doc["gate"]),
            episodes=tuple(EpisodeStats(float(e["start_s"]), float(e["end_s"]), float(e["peak_force"]),
                                        bool(e["detected"]), _float(e["delay_s"])) for e in doc["episodes"]),
            recall=_float(doc["recall"]),
            recall_strong=_float(doc["recall_strong"]),
            false_alarms=int(doc["false_alarms"]),
            false_alarms_per_minute=_float(doc["false_alarms_per_minute"]),
            median_delay_s=_float(doc["median_delay_s"]),
            before={g: _float(v) for g, v in doc["rmse_before_first_contact"].items()},
            after={g: _float(v) for g, v in doc["rmse_after_last_contact"].items()},
            recovery=None if rec is None else {g: _recovery_from_json(r) for g, r in rec.items()},
            adoption_s=None if doc.get("adoption_s") is None else {
                g: None if v is None else float(v) for g, v in doc["adoption_s"].items()},
            not_learned={str(k): int(v) for k, v in (doc.get("not_learned") or {}).items()},
            forgetting=None if doc.get("forgetting") is None else float(doc["forgetting"]),
        )


def _float(value: Any) -> float:
    return math.nan if value is None else float(value)


def _recovery_from_json(r: Mapping[str, Any]) -> Recovery:
    rec = r["recovery_time_s"]
    return Recovery(pre_rmse=_float(r["pre_rmse"]), peak=_float(r["peak"]),
                    recovery_time_s=None if rec is None else float(rec),
                    level_at_deadline=_float(r["level_at_deadline"]),
                    ratio_at_deadline=_float(r["ratio_at_deadline"]), post_rmse=_float(r["post_rmse"]),
                    recovered=bool(r["recovered"]))


def score_run(run: ContactRun, truth: GroundTruthEpisodes, output: OutputSpec, *, threshold: float,
              warmup_s: float, strong_force: float = 10.0, window_s: float = 10.0, tolerance_s: float = 0.2,
              recovery_window_s: float = DEFAULT_WINDOW_S, pre_s: float = 10.0,
              recovery_tolerance: float = 1.5, deadline_s: float = 10.0, adopted_fraction: float = 0.2,
              pickup_window_s: float = 5.0) -> GateStats:
    """Score one run against the true episodes (module docstring).

    Args:
        run: The run.
        truth: The true episodes and pickup.
        output: Output groups.
        threshold: Detection threshold in σ (the gate's, ``gate.threshold``).
        warmup_s: Samples before this time from the first sample are not scored [s] (``gate.warmup``).
        strong_force: Episodes with a peak force ≥ this count in ``recall_strong`` [N].
        window_s: Length of the windows before the first and after the last contact [s].
        tolerance_s: Flags up to this long after an episode's end belong to it [s].
        recovery_window_s: Sliding RMSE window of the recovery [s].
        pre_s: Pre-pickup reference segment of the recovery [s].
        recovery_tolerance: Recovered when within this ratio of the pre-pickup level.
        deadline_s: Recovery deadline after the pickup [s].
        adopted_fraction: Adopted once the windowed RMSE's excess over the pre-pickup level is below this
            fraction of its peak excess.
        pickup_window_s: Flags in ``[pickup, pickup + pickup_window_s]`` are not false alarms [s].

    Returns:
        The numbers.

    Raises:
        ValueError: If a window holds no sample (the log is too short for the episodes it records).
    """
    t, e = run.time_s, run.external
    scored = t >= t[0] + warmup_s
    flags = flag_samples(e, run.std, threshold)
    events = truth.episodes
    if truth.pickup_s is not None:  # scored like one more episode, whose detection is not reported
        events = np.vstack([events, [[truth.pickup_s, truth.pickup_s + pickup_window_s]]])
    score = score_episodes(t[scored], flags[scored], events, tolerance_s=tolerance_s)
    n_ep = len(truth.episodes)
    detected, delays_s = score.detected[:n_ep], score.delays_s[:n_ep]
    strong = truth.peak_force >= strong_force
    episodes = tuple(EpisodeStats(float(a), float(b), float(f), bool(d), float(dl))
                     for (a, b), f, d, dl in zip(truth.episodes, truth.peak_force, detected, delays_s,
                                                 strict=True))
    first, last = float(truth.episodes[:, 0].min()), float(truth.episodes[:, 1].max())
    end = last + window_s if truth.pickup_s is None else min(last + window_s, truth.pickup_s)
    windows = {"before": (max(first - window_s, t[0] + warmup_s), first), "after": (last, end)}
    rmse: dict[str, dict[str, float]] = {}
    for name, (a, b) in windows.items():
        m = (t >= a) & (t < b)
        if not m.any():
            raise ValueError(f"no sample in the window {name} the contacts [{a:.3g}, {b:.3g}) s")
        rmse[name] = {g: group_rmse(e[m][:, list(spec.columns)]) for g, spec in output.groups.items()}
    rec = None
    adoption: dict[str, float | None] | None = None
    if truth.pickup_s is not None and t[0] <= truth.pickup_s - pre_s and t[-1] > truth.pickup_s:
        tc = t - truth.pickup_s
        period = stream_period_s(np.round(t * 1e9).astype(np.int64))
        assert period is not None  # t spans the pickup: at least two samples
        window = window_samples(recovery_window_s, period)
        pre = (tc >= -pre_s) & (tc < 0)
        rec, adoption = {}, {}
        for g, spec in output.groups.items():
            err = e[:, list(spec.columns)]
            curve, level = windowed_rmse(err, window), group_rmse(err[pre])
            rec[g] = recovery(tc, curve, err, level, tc >= 0, recovery_tolerance, deadline_s)
            after = np.flatnonzero(tc >= 0)
            peak = after[int(np.argmax(curve[after]))]
            bound = level + adopted_fraction * (curve[peak] - level)
            below = np.flatnonzero(curve[peak:] <= bound)
            adoption[g] = float(tc[peak + below[0]]) if below.size else None
    delays = delays_s[detected]
    return GateStats(
        gate=run.gate, episodes=episodes, recall=float(np.mean(detected)) if n_ep else math.nan,
        recall_strong=float(np.mean(detected[strong])) if strong.any() else math.nan,
        false_alarms=score.false_alarms, false_alarms_per_minute=score.false_alarms_per_minute,
        median_delay_s=float(np.median(delays)) if delays.size else math.nan,
        before=rmse["before"], after=rmse["after"], recovery=rec, adoption_s=adoption,
        not_learned=run.not_learned,
        forgetting=run.forgetting)


@dataclass(frozen=True)
class ContactReport:
    """The contact evaluation of one log: the same numbers with the gate on and off.

    Attributes:
        output: What the outputs are.
        runs: ``{"on": GateStats, "off": GateStats}``.
        threshold: Detection threshold [σ].
        strong_force: Peak force of the episodes in ``recall_strong`` [N].
        window_s: Before/after windows [s].
        pickup_s: Payload pickup [s from the start] or ``None``.
        protocol: Settings of the run (bag, topics, tolerances).
        config: Flat configuration (gate as configured).
    """

    output: OutputSpec
    runs: dict[str, GateStats]
    threshold: float
    strong_force: float
    window_s: float
    pickup_s: float | None
    protocol: dict[str, Any]
    config: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        """Return the JSON document."""
        return {"kind": "contacts", "output": self.output.kind, "components": list(self.output.components),
                "runs": {k: v.to_json() for k, v in self.runs.items()}, "threshold": self.threshold,
                "strong_force": self.strong_force, "window_s": self.window_s, "pickup_s": self.pickup_s,
                "protocol": self.protocol, "config": self.config}

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> ContactReport:
        """Read :meth:`to_json` back.

        Raises:
            ValueError: If a required field is missing.
        """
        try:
            kind = doc["output"]
            comps = tuple(doc["components"])
            output = (OutputSpec.wrench() if OutputKind(kind) == OutputKind.WRENCH
                      else OutputSpec.joint_torques(comps))
            return cls(output=output, runs={k: GateStats.from_json(v) for k, v in doc["runs"].items()},
                       threshold=float(doc["threshold"]), strong_force=float(doc["strong_force"]),
                       window_s=float(doc["window_s"]),
                       pickup_s=None if doc.get("pickup_s") is None else float(doc["pickup_s"]),
                       protocol=dict(doc.get("protocol") or {}), config=dict(doc.get("config") or {}))
        except KeyError as err:
            raise ValueError(f"contact report without the field {err}") from err


def run_contacts(bag: str | Path, config: EstimatorConfig, *, topics: Topics | None = None
                 ) -> tuple[GroundTruthEpisodes, dict[str, ContactRun]]:
    """Run the estimator over a contacts log with the gate on and off.

    Args:
        bag: Bag with ``scenario.yaml`` recording contact episodes.
        config: Configuration (its ``gate.enabled`` is overridden per run).
        topics: Topics to read.

    Returns:
        ``(truth, {"on": run, "off": run})``.

    Raises:
        ValueError: On an unreadable bag or sidecar.
    """
    truth = read_episodes(bag)
    runs = {key: run_estimator(bag, config.with_overrides({"gate.enabled": on}),
                               start_stamp_ns=truth.start_stamp_ns, topics=topics)
            for key, on in (("on", True), ("off", False))}
    return truth, runs


def contact_report(truth: GroundTruthEpisodes, runs: Mapping[str, ContactRun], config: EstimatorConfig, *,
                   strong_force: float = 10.0, window_s: float = 10.0, tolerance_s: float = 0.2,
                   protocol: Mapping[str, Any] | None = None) -> ContactReport:
    """Score the runs of :func:`run_contacts` into the report.

    Args:
        truth: The true episodes.
        runs: ``{"on": ..., "off": ...}``.
        config: The configuration (threshold and warm-up of the gate, output).
        strong_force: Peak force of the episodes in ``recall_strong`` [N].
        window_s: Before/after windows [s].
        tolerance_s: Flags up to this long after an episode's end belong to it [s].
        protocol: Extra settings to record.

    Returns:
        The report.
    """
    output = OutputSpec.from_config(config.to_flat())
    threshold, warmup = float(config["gate.threshold"]), float(config["gate.warmup"])
    pickup_window = float(config["gate.max_contact_duration"]) + 2.0
    stats = {k: score_run(r, truth, output, threshold=threshold, warmup_s=warmup, strong_force=strong_force,
                          window_s=window_s, tolerance_s=tolerance_s, pickup_window_s=pickup_window)
             for k, r in runs.items()}
    return ContactReport(output=output, runs=stats, threshold=threshold, strong_force=strong_force,
                         window_s=window_s, pickup_s=truth.pickup_s,
                         protocol={"tolerance_s": tolerance_s, "warmup_s": warmup,
                                   "pickup_window_s": pickup_window, **dict(protocol or {})},
                         config=config.to_flat())
