"""Learn a model offline from recorded bags, through the node's own pipeline and estimator.

Each bag's joint states (and wrenches, for ``robot.output: wrench``) enter
:class:`~semiparam_ros.core.estimator.online.OnlineEstimator` in log-time order, exactly as the live node
receives them (same pairing, acceleration estimate, contact gate and drop rules), so a bag learned here and
the same bag played to the node give the same model. Between bags the model is kept and the stream-bound state
restarts (:meth:`OnlineEstimator.start_recording`). The result is a self-contained checkpoint that
:func:`semiparam_ros.load_model` and the node (``checkpoint.path`` with ``checkpoint.load_on_start``) read.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.io.bags import absolute_topic, read_messages, recovery_notes, topic_info
from semiparam_ros.serving.fit_summary import FitSummary, SampleReservoir, fit_summary

__all__ = ["LearnProgress", "LearnReport", "learn_bags"]


@dataclass(frozen=True)
class LearnProgress:
    """Where a run is (passed to the progress callback about every 0.25 s of wall time).

    Attributes:
        bag_index: Index of the bag being read (0-based).
        n_bags: Number of bags.
        messages: Messages read from this bag so far.
        total_messages: Messages of the selected topics this bag holds (its metadata; 0 if unknown).
        samples: Samples learned or predicted so far, all bags.
        wall_s: Wall time since the start [s].
        log_s: Recorded time covered so far, all bags [s].
    """

    bag_index: int
    n_bags: int
    messages: int
    total_messages: int
    samples: int
    wall_s: float
    log_s: float


@dataclass
class LearnReport:
    """What a run of :func:`learn_bags` did.

    Attributes:
        bags: The bags, in the order learned.
        messages: Messages read.
        samples: Samples formed (each predicted, then learned unless the gate refused it).
        learned: Samples learned.
        drops: Input dropped, by reason (the node's reasons).
        not_learned: Samples deliberately not learned, by reason (contacts the gate refused).
        wall_s: Wall time of the run [s] (excluding the checkpoint write).
        log_s: Recorded time of the bags [s] (sum over bags of last − first sample stamp).
        recovered: Bags that were truncated or corrupt and read as far as possible (samples were lost).
        checkpoint: Where the checkpoint was written, or None.
        warnings: What the estimator found wrong with the input (e.g. efforts that are not N·m).
        fit: The model's fit on a sample of the logs, beside the URDF's (None without samples).
    """

    bags: list[str]
    messages: int = 0
    samples: int = 0
    learned: int = 0
    drops: dict[str, int] = field(default_factory=dict)
    not_learned: dict[str, int] = field(default_factory=dict)
    wall_s: float = 0.0
    log_s: float = 0.0
    recovered: list[str] = field(default_factory=list)
    checkpoint: str | None = None
    warnings: list[str] = field(default_factory=list)
    fit: FitSummary | None = None

    @property
    def realtime_factor(self) -> float:
        """Recorded time per wall time (> 1: faster than real time)."""
        return self.log_s / self.wall_s if self.wall_s > 0 else float("inf")


def learn_bags(bags: Sequence[str | Path], config: EstimatorConfig, *,
               checkpoint: str | Path | None = None, init: str | Path | None = None,
               joint_states_topic: str | None = None, wrench_topic: str | None = None,
               progress: Callable[[LearnProgress], None] | None = None,
               ) -> tuple[OnlineEstimator, LearnReport]:
    """Learn recorded bags with the node's estimator and write a checkpoint.

    Args:
        bags: Bag folders or ``.mcap`` files, learned in this order.
        config: The configuration (the node's parameter file; ``learning_enabled`` is ignored: learning is
            the point).
        checkpoint: Where to write the checkpoint (atomically), or None.
        init: A checkpoint to continue from (same model structure and robot), or None to start afresh.
        joint_states_topic: JointState topic in the bags (default ``/<topics.joint_states>``).
        wrench_topic: WrenchStamped topic (default ``/<topics.wrench>``; unused for joint torques).
        progress: Called about every 0.25 s with a :class:`LearnProgress`.

    Returns:
        The estimator (its model learned) and the run's report.

    Raises:
        BagError: A missing or unreadable bag, a missing topic or one of another type.
        CheckpointError: ``init`` is missing, corrupt, or of another structure or robot.
        OSError: The checkpoint cannot be written.
        ValueError: ``bags`` is empty.
    """
    if not bags:
        raise ValueError("learn needs at least one bag")
    js_topic = absolute_topic(joint_states_topic or config["topics.joint_states"])
    wr_topic = (absolute_topic(wrench_topic or config["topics.wrench"])
                if config.output_kind == OutputKind.WRENCH else None)
    est = OnlineEstimator(config)
    est.learning_enabled = True
    est.inline_projection = True  # the node's projection schedule, in the bags' time
    if init is not None:
        est.load(init)
    learned_before = est.n_samples_learned
    report = LearnReport(bags=[str(b) for b in bags])
    n_joints = len(config["robot.joints"])
    reservoir = SampleReservoir(3 * n_joints, config.n_outputs)
    start = time.perf_counter()
    next_report = start
    for index, bag in enumerate(bags):
        topics = {js_topic, wr_topic} - {None}
        if index:
            est.start_recording()
        first_ns: int | None = None
        last_ns: int | None = None
        n_msgs = 0
        with recovery_notes() as notes:
            info = topic_info(bag)
            total = sum(info[t].count for t in topics if t in info)
            for msg in read_messages(bag, joint_states_topic=js_topic, wrench_topic=wr_topic):
                n_msgs += 1
                results = est.process(msg)
                if results:
                    for result in results:
                        sample = result.sample
                        reservoir.add(np.concatenate((sample.q, sample.dq, sample.ddq)), sample.y)
                    report.samples += len(results)
                    stamp = results[-1].sample.stamp_ns
                    first_ns = results[0].sample.stamp_ns if first_ns is None else first_ns
                    last_ns = stamp
                if progress is not None and (now := time.perf_counter()) >= next_report:
                    next_report = now + 0.25
                    covered = report.log_s + (0.0 if first_ns is None or last_ns is None
                                              else (last_ns - first_ns) * 1e-9)
                    progress(LearnProgress(index, len(bags), n_msgs, total, report.samples, now - start,
                                           covered))
        if notes:
            report.recovered.append(str(bag))
        report.messages += n_msgs
        if first_ns is not None and last_ns is not None:
            report.log_s += (last_ns - first_ns) * 1e-9
    report.wall_s = time.perf_counter() - start
    report.learned = est.n_samples_learned - learned_before
    report.drops = {k: v for k, v in est.drops.items() if v}
    report.not_learned = {k: v for k, v in est.not_learned.items() if v}
    report.warnings = list(est.warnings)
    report.fit = fit_summary(est, *reservoir.arrays())
    if progress is not None:
        progress(LearnProgress(len(bags) - 1, len(bags), 0, 0, report.samples, report.wall_s, report.log_s))
    if checkpoint is not None:
        est.save(checkpoint)
        report.checkpoint = str(checkpoint)
    return est, report
