"""Run-time statistics of the estimator node and their ``diagnostic_msgs/DiagnosticArray`` form.

:class:`NodeStatistics` is updated by the estimator's processing (one call per sample) and by the
subscription callbacks (one counter increment per message), and read by the diagnostics timer; a lock
makes each read a consistent snapshot (the checkpoint thread records its outcomes too). Memory is
bounded: the RMSE window is a fixed-size ring of squared errors and the latency statistics are reset
every diagnostics period.

Published values (``DiagnosticStatus.values``, all strings as the message requires):

==============================  =================================================================
key                             meaning
==============================  =================================================================
samples_learned                 samples the learner has been updated with (survives warm starts)
samples_predicted               samples predicted since start
learning_skipped                late samples predicted at once without learning (overload.max_delay)
excitation.condition            condition number of the rigid-body information matrix in physical units
excitation.weakest_eigenvalue   its smallest eigenvalue; ``excitation.weakest_direction`` the base
                                parameters that direction weighs most (what the data do not determine)
learning_enabled                ``true`` / ``false``
input_rate_hz                   paired samples per second over the last period
joint_states_rate_hz            JointState messages received per second
wrench_rate_hz                  WrenchStamped messages received per second
joint_states_received, ...      messages received since start (JointState, WrenchStamped)
update_latency_mean_ms / _max   core step (predict + learn) wall time over the last period
pipeline_latency_mean_ms / _max message received → prediction published, over the last period
pipeline_latency_p99_ms          its 99th percentile over the last period (of at most the last 8192 samples)
learning_cpu_percent            CPU time spent in the estimator over the last period (100 = one core)
processed_in_period             queued messages run through the estimator in the last period
acceleration_delay_ms           inherent lag of the acceleration estimate (centred window)
queue_length / queue_size       input queue occupancy and bound
queue_drops                     messages dropped because the queue was full (oldest first), since start
drops.glitch                    joint states whose q or q̇ jumped beyond limits.glitch_ratio × the running
                                increment (one-sample glitches inside the plausibility bounds)
drops.<reason>                  input messages dropped by the pipeline or the node, by reason; the
                                pipeline's reasons count since start or the last ~/reset (which
                                restarts the pipeline), the node's own (queue_full, ...) since start
drops_total                     sum of the drops.* values above, queue drops included
rmse_window                     samples in the RMSE window (≤ diagnostics.rmse_window)
rmse_force_N, rmse_torque_Nm    a-priori RMSE of the semiparametric prediction (wrench output)
rmse_parametric_force_N, ...    same for the rigid-body part alone
rmse_Nm, rmse_parametric_Nm     joint-torque output
model_size                      learned coefficients (parametric + residual weights)
not_learned.gated_contact       samples predicted but not learned: residual beyond gate.threshold σ for
                                less than gate.max_contact_duration (a contact); since start or ~/reset
gate_enabled                    ``true`` / ``false`` (gate.enabled)
gate_in_excursion               ``true`` while the last sample's residual was beyond the gate threshold
gate_novel_samples              outliers learned as motion the model has not seen (relative predictive
                                variance above gate.novelty), not as contacts
feedforward.*                   joint torques: desired states answered (published), fallbacks to the
                                rigid-body part (fallback.not_ready, fallback.std), drops by reason,
                                missing velocities/accelerations, ready, last_error, and the age of the
                                answered desired states (age_p50_ms, age_p99_ms, age_max_ms: node clock
                                at publish − header stamp)
forgetting                      per-sample β from adaptation.time_constant at the measured rate (-1:
                                not measured yet, or adaptation.time_constant = 0)
checkpoint_path                 configured path ('' = disabled)
checkpoint_age_s                seconds since the last successful checkpoint write (-1 = never)
checkpoint_errors               failed checkpoint writes
checkpoint_failed               ``true`` while the last checkpoint write failed (level ERROR)
==============================  =================================================================

Level: ERROR if input is queued but nothing was processed for a whole period (stalled), WARN if messages
were dropped in the last period (bad input or a full queue) or no input arrived, OK otherwise.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Mapping

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from semiparam_ros.core.estimator.build import rmse_window_samples
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.kinds import InputKind, OutputKind
from semiparam_ros.core.stream.gate import Verdict
from semiparam_ros.serving.learning_loop import LearningLoop, Stepped

__all__ = ["NodeStatistics", "diagnostic_array"]

#: Pipeline latencies kept per diagnostics period for the percentile (a ring: memory is bounded).
_E2E_RING = 8192


class _RingRMSE:
    """Root mean square of the last ``window`` error vectors, split into groups of columns."""

    def __init__(self, window: int, width: int) -> None:
        self._sq = np.zeros((max(int(window), 1), width))
        self._next = 0
        self._count = 0

    def add(self, y: np.ndarray, prediction: np.ndarray | float = 0.0) -> None:
        """Record the error ``y - prediction`` (``y`` itself when no prediction is given)."""
        row = self._sq[self._next]
        np.subtract(y, prediction, out=row)
        np.square(row, out=row)
        self._next = (self._next + 1) % self._sq.shape[0]
        self._count = min(self._count + 1, self._sq.shape[0])

    def rmse(self, columns: slice) -> float:
        if self._count == 0:
            return math.nan
        return float(np.sqrt(self._sq[: self._count, columns].mean()))

    @property
    def count(self) -> int:
        return self._count

    @property
    def window(self) -> int:
        return int(self._sq.shape[0])

    def resize(self, window: int) -> None:
        """Change the window length, keeping the most recent ``min(count, window)`` entries."""
        keep = min(self._count, max(int(window), 1))
        order = (self._next - keep + np.arange(keep)) % self._sq.shape[0]
        sq = np.zeros((max(int(window), 1), self._sq.shape[1]))
        sq[:keep] = self._sq[order]
        self._sq, self._count = sq, keep
        self._next = keep % sq.shape[0]

    def clear(self) -> None:
        self._next = 0
        self._count = 0


class NodeStatistics:
    """Thread-safe counters and windows of the estimator node.

    Args:
        output: The output kind: a wrench (6 outputs: force N, torque N·m) or joint torques (n, N·m).
        n_outputs: Number of outputs.
        rmse_window: Samples in the running RMSE window.
        rmse_window_final: Whether that window stays, or is set again once the sample rate is known
            (:meth:`add_step`).
    """

    def __init__(self, output: OutputKind, n_outputs: int, rmse_window: int, *,
                 rmse_window_final: bool = True) -> None:
        self._lock = threading.Lock()
        self._rmse_window_final = rmse_window_final
        self.output = output
        self._rmse_total = _RingRMSE(rmse_window, n_outputs)
        self._rmse_param = _RingRMSE(rmse_window, n_outputs)
        self._period_start = time.monotonic()
        self._e2e_ring = np.empty(_E2E_RING)
        self._reset_period()
        self.samples_predicted = 0
        self.joint_states_received = 0
        self.wrench_received = 0
        self.queue_drops = 0
        self.node_drops: dict[str, int] = {}
        self.last_checkpoint_time: float | None = None
        self.checkpoint_errors = 0
        self.last_checkpoint_failed = False

    def set_rmse_window(self, rmse_window: int) -> None:
        """Change the running RMSE window [samples], keeping the most recent errors (e.g. at a new rate)."""
        with self._lock:
            self._rmse_total.resize(rmse_window)
            self._rmse_param.resize(rmse_window)

    @property
    def rmse_window(self) -> int:
        """Length of the running RMSE window [samples]."""
        return self._rmse_total.window

    def _reset_period(self) -> None:
        self._n_js = 0
        self._n_wrench = 0
        self._n_samples = 0
        self._step_sum = 0.0
        self._step_max = 0.0
        self._e2e_sum = 0.0
        self._e2e_max = 0.0
        self._e2e_count = 0
        self._drops_in_period = 0
        self._learning_cpu = 0.0
        self._processed = 0

    # ---------------------------------------------------------------- updates (hot path, cheap)
    def count_input(self, kind: InputKind) -> None:
        """Count one received input message of a stream."""
        with self._lock:
            if kind == InputKind.JOINT_STATES:
                self._n_js += 1
                self.joint_states_received += 1
            else:
                self._n_wrench += 1
                self.wrench_received += 1

    def count_drop(self, reason: str, n: int = 1) -> None:
        """Count input dropped by the node itself (queue overflow is ``"queue_full"``)."""
        with self._lock:
            if reason == "queue_full":
                self.queue_drops += n
            else:
                self.node_drops[reason] = self.node_drops.get(reason, 0) + n
            self._drops_in_period += n

    def count_pipeline_drops(self, n: int) -> None:
        """Note that the core pipeline dropped ``n`` more messages (totals are read from the core)."""
        if n:
            with self._lock:
                self._drops_in_period += n

    def add_sample(self, step_s: float, e2e_s: float, y: np.ndarray, total: np.ndarray,
                   parametric: np.ndarray) -> None:
        """Record one processed sample.

        Args:
            step_s: Core step (predict + learn) wall time [s].
            e2e_s: Message receipt → prediction published [s].
            y: Measured output.
            total: Semiparametric a-priori prediction.
            parametric: Rigid-body part of the prediction.
        """
        with self._lock:
            self.samples_predicted += 1
            self._n_samples += 1
            self._step_sum += step_s
            self._step_max = max(self._step_max, step_s)
            self._e2e_sum += e2e_s
            self._e2e_max = max(self._e2e_max, e2e_s)
            self._e2e_ring[self._e2e_count % _E2E_RING] = e2e_s
            self._e2e_count += 1
            self._rmse_total.add(y, total)
            self._rmse_param.add(y, parametric)

    def add_step(self, stepped: Stepped, estimator: OnlineEstimator, t_recv: float) -> None:
        """Record what one input produced: the pipeline's new drops and every published sample.

        The first time the estimator knows its sample period, the RMSE window (until then in samples
        of the configured default) becomes ``diagnostics.rmse_window``'s length at that rate.

        Args:
            stepped: What the learning loop returned for the input.
            estimator: The estimator that stepped it (its rate and configuration).
            t_recv: When the input was received (``time.perf_counter()`` [s]).
        """
        self.count_pipeline_drops(stepped.new_drops)
        if not self._rmse_window_final and estimator.sample_period_s is not None:
            self.set_rmse_window(rmse_window_samples(estimator.config, estimator.sample_period_s))
            self._rmse_window_final = True
        for result in stepped.results:
            pred = result.prediction
            self.add_sample(result.latency_s, time.perf_counter() - t_recv, result.sample.y, pred.total,
                            pred.parametric)

    def add_learning_cpu(self, seconds: float, n_messages: int = 1) -> None:
        """Add the CPU time spent running the estimator on ``n_messages`` queued messages [s]."""
        with self._lock:
            self._learning_cpu += seconds
            self._processed += n_messages

    def clear_errors(self) -> None:
        """Forget the RMSE windows (after a model reset)."""
        with self._lock:
            self._rmse_total.clear()
            self._rmse_param.clear()

    # ---------------------------------------------------------------- read-out
    def snapshot(self) -> dict[str, object]:
        """Return this period's statistics and start a new period."""
        with self._lock:
            now = time.monotonic()
            dt = max(now - self._period_start, 1e-9)
            n = self._n_samples
            snap: dict[str, object] = dict(
                input_rate_hz=n / dt,
                joint_states_rate_hz=self._n_js / dt,
                wrench_rate_hz=self._n_wrench / dt,
                update_latency_mean_ms=1e3 * self._step_sum / n if n else math.nan,
                update_latency_max_ms=1e3 * self._step_max if n else math.nan,
                pipeline_latency_mean_ms=1e3 * self._e2e_sum / n if n else math.nan,
                pipeline_latency_max_ms=1e3 * self._e2e_max if n else math.nan,
                pipeline_latency_p99_ms=1e3 * float(np.percentile(
                    self._e2e_ring[: min(self._e2e_count, _E2E_RING)], 99)) if self._e2e_count else math.nan,
                learning_cpu_percent=100.0 * self._learning_cpu / dt,
                processed_in_period=self._processed,
                samples_predicted=self.samples_predicted,
                joint_states_received=self.joint_states_received,
                wrench_received=self.wrench_received,
                queue_drops=self.queue_drops,
                drops_in_period=self._drops_in_period,
                inputs_in_period=self._n_js + self._n_wrench,
                rmse_window=self._rmse_total.count,
                checkpoint_age_s=(now - self.last_checkpoint_time
                                  if self.last_checkpoint_time is not None else -1.0),
                checkpoint_errors=self.checkpoint_errors,
                checkpoint_failed=self.last_checkpoint_failed,
            )
            if self.output == OutputKind.WRENCH:
                snap["rmse_force_N"] = self._rmse_total.rmse(slice(0, 3))
                snap["rmse_torque_Nm"] = self._rmse_total.rmse(slice(3, 6))
                snap["rmse_parametric_force_N"] = self._rmse_param.rmse(slice(0, 3))
                snap["rmse_parametric_torque_Nm"] = self._rmse_param.rmse(slice(3, 6))
            else:
                snap["rmse_Nm"] = self._rmse_total.rmse(slice(None))
                snap["rmse_parametric_Nm"] = self._rmse_param.rmse(slice(None))
            for reason, count in self.node_drops.items():
                snap[f"drops.{reason}"] = count
            self._period_start = now
            self._reset_period()
            return snap

    def mark_checkpoint(self, ok: bool) -> None:
        """Record the outcome of a checkpoint write."""
        with self._lock:
            self.last_checkpoint_failed = not ok
            if ok:
                self.last_checkpoint_time = time.monotonic()
            else:
                self.checkpoint_errors += 1


def _fmt(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def diagnostic_array(
    stamp: object,
    name: str,
    hardware_id: str,
    stats: Mapping[str, object],
    *,
    stalled: bool = False,
    waiting: bool = False,
) -> DiagnosticArray:
    """Build the ``/diagnostics`` message of the estimator.

    Args:
        stamp: ``builtin_interfaces/Time`` of the header (node clock, sim time when enabled).
        name: Status name (``"<node name>: online learning"``).
        hardware_id: Robot / sensor identifier.
        stats: Values to publish (see the module docstring), including ``drops.<reason>`` entries.
        stalled: Input is waiting but none was processed during the period.
        waiting: The node is waiting for its robot description (WARN, nothing learned yet).

    Returns:
        The message with one :class:`DiagnosticStatus`.
    """
    status = DiagnosticStatus()
    status.name = name
    status.hardware_id = hardware_id
    if stats.get("checkpoint_failed") is True:
        status.level, status.message = DiagnosticStatus.ERROR, "the last checkpoint write failed"
    elif waiting:
        status.level, status.message = DiagnosticStatus.WARN, "waiting for the robot description"
    elif stalled:
        status.level, status.message = DiagnosticStatus.ERROR, "stalled: queued input is not processed"
    elif int(stats.get("drops_in_period", 0)) > 0:  # type: ignore[call-overload]
        status.level, status.message = DiagnosticStatus.WARN, "input dropped (see drops.*)"
    elif int(stats.get("inputs_in_period", 0)) == 0:  # type: ignore[call-overload]
        status.level, status.message = DiagnosticStatus.WARN, "no input"
    else:
        status.level, status.message = DiagnosticStatus.OK, "learning" if stats.get(
            "learning_enabled", True) else "predicting (learning disabled)"
    status.values = [KeyValue(key=str(k), value=_fmt(v)) for k, v in stats.items()]
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = [status]
    return msg


def estimator_statistics(node_stats: dict[str, object], loop: LearningLoop) -> dict[str, object]:
    """Add the learner's counters and the queue to a :meth:`NodeStatistics.snapshot` (one period).

    Args:
        node_stats: The node's period statistics (modified and returned).
        loop: The learning loop (its estimator is read under its lock).

    Returns:
        ``node_stats`` with ``samples_learned``, ``learning_skipped``, ``not_learned.*``, ``gate_*``,
        ``forgetting``, ``queue_*``, ``acceleration_delay_ms``, ``drops.*`` (the pipeline's added to the
        node's) and ``drops_total``.
    """
    stats = node_stats
    with loop.lock:
        est = loop.estimator
        drops = est.drops
        stats["samples_learned"] = est.n_samples_learned
        stats["learning_skipped"] = est.n_learning_skipped
        stats["learning_enabled"] = est.learning_enabled
        stats["model_size"] = est.model_size
        for reason, count in est.not_learned.items():
            stats[f"not_learned.{reason}"] = count
        stats["gate_enabled"] = est.gate_enabled
        stats["gate_in_excursion"] = est.gate.in_excursion
        stats["gate_novel_samples"] = est.gate.counts[Verdict.NOVEL]
        stats["forgetting"] = est.forgetting if est.forgetting is not None else -1.0
    stats["queue_length"] = len(loop.queue)
    stats["queue_size"] = loop.queue_size
    stats["acceleration_delay_ms"] = 1e3 * float(getattr(est.pipeline, "acceleration_delay_s", 0.0))
    for reason, count in drops.items():
        key = f"drops.{reason}"
        stats[key] = int(stats.get(key, 0)) + count  # type: ignore[call-overload]
    stats["drops_total"] = int(stats["queue_drops"]) + sum(  # type: ignore[call-overload]
        v for k, v in stats.items() if k.startswith("drops.") and isinstance(v, int))
    return stats
