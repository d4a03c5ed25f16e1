"""What the node serves beside the per-sample predictions: feed-forward, gravity, payload, link inertias.

Plain Python (no rclpy): the node (:mod:`semiparam_ros.ros.estimator_node`) calls these from its timers and
callbacks and publishes what they return. The model is served from a copy refreshed at a low rate (a
model that changes at every sample makes the commanded torque jitter: docs/feedforward.md); with
``parametric.consistent`` that copy predicts with the physically consistent parameters a worker process
re-solves every ``parametric.consistent_period``
(:class:`~semiparam_ros.serving.projection.ProjectionWorker`: cvxpy holds the GIL, so never in the
learning thread).

>>> from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
>>> from semiparam_ros.core.estimator.online import OnlineEstimator
>>> from semiparam_ros.serving.learning_loop import LearningLoop
>>> cfg = EstimatorConfig.from_flat({**ICUB_RIGHT_ARM, "robot.output": OutputKind.JOINT_TORQUES,
...                                                  "parametric.consistent": False})
>>> loop = LearningLoop(OnlineEstimator(cfg), queue_size=10, max_delay_s=0.0)
>>> service = ModelService(loop, cfg)
>>> service.feedforward is not None, service.projection is None
(True, True)
>>> service.statistics()["feedforward.ready"]
False
"""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING

import numpy as np

from semiparam_ros.atomic import atomic_write_text
from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.core.rigid_body.identification import ConsistentEstimate, export_urdf
from semiparam_ros.core.rigid_body.payload import PayloadEstimate
from semiparam_ros.errors import RejectedSampleError
from semiparam_ros.serving.feedforward import DesiredState, FeedForward, FeedForwardCommand, TrajectoryEffort
from semiparam_ros.serving.learned_model import LearnedModel
from semiparam_ros.serving.projection import ProjectionWorker

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from semiparam_ros.serving.learning_loop import LearningLoop

__all__ = ["ModelService"]

_EXCITATION_PERIOD_S = 10.0  # the excitation report is recomputed at most this often
_MAX_LATENCIES = 100_000  # feed-forward ages kept per diagnostics period at most


def _limits(urdf_limits: np.ndarray) -> np.ndarray:
    """Return the URDF's ``<limit effort>`` per joint [N·m], ``inf`` where it gives none (read as 0)."""
    limits = np.asarray(urdf_limits, dtype=np.float64).copy()
    limits[~(np.isfinite(limits) & (limits > 0.0))] = np.inf
    return limits


class ModelService:
    """The learned model at any state, for controllers and identification.

    Args:
        loop: The learning loop (its lock guards the estimator; its version says when learning changed it).
        config: The estimator's configuration (``feedforward.*``, ``parametric.consistent*``).

    Raises:
        ConfigurationError: An invalid ``feedforward.joints`` or ``feedforward.max_std``.
    """

    def __init__(self, loop: LearningLoop, config: EstimatorConfig) -> None:
        self.loop = loop
        self.config = config
        est = loop.estimator
        #: The live model (never solves the consistent projection itself).
        self.serving = LearnedModel(est, solve=False)
        self.feedforward: FeedForward | None = None
        self.projection: ProjectionWorker | None = None
        if config.output_kind == OutputKind.JOINT_TORQUES:
            self.feedforward = FeedForward(self.serving, joints=config["feedforward.joints"] or None,
                                           max_std=config["feedforward.max_std"],
                                           exclude=config["feedforward.exclude"],
                                           exclude_source=config["feedforward.exclude_source"],
                                           effort_limits=_limits(est.regressor.effort_limits()))
            if config["parametric.consistent"]:
                self.projection = ProjectionWorker(config.to_flat(), est.regressor.urdf_xml)
        #: Ages of the answered desired states this diagnostics period [ms] (stamp → answer).
        self.latency_ms: list[float] = []
        #: Events of the FollowJointTrajectory proxy: forwarded, rejected_invalid, rejected_no_controller, …
        self.action_counts: dict[str, int] = {
            "forwarded": 0, "rejected_invalid": 0, "rejected_no_controller": 0, "controller_rejected": 0,
            "aborted": 0}
        self._stats_lock = threading.Lock()  # the answers are counted in the feed-forward thread
        self._projection_version = -1
        self._applied = 0  # the worker's solutions the live estimator predicts with (its count)
        self._submitted_learned = 0  # samples the estimator had learned at the last submission
        self._ff_key = (-1, -1)
        self._links_published = 0
        self._payload_key: int | None = None
        self._payload_missing: str | None = None  # of the last payload published (None: none yet)
        self._excitation: tuple[float, int, dict[str, object]] | None = None

    @property
    def solved(self) -> int:
        """Consistent solutions the worker returned so far (0 without one)."""
        return self.projection.solved if self.projection is not None else 0

    def apply_consistent(self) -> bool:
        """Hand the worker's newest solution to the live estimator, whose predictions then use it.

        The node's per-sample predictions use the same consistent rigid body as the feed-forward and
        ``load_model`` (:meth:`OnlineEstimator.use_consistent`), from the first solution of a learned
        state on (the projection of an estimator that learned nothing is its prior, which it predicts
        with anyway), as ``learn`` and offline replay do in line (``OnlineEstimator.inline_projection``).

        Returns:
            Whether a new solution was applied.
        """
        worker = self.projection
        if worker is None:
            return False
        solved = worker.solved  # before latest: a solution arriving in between is applied now or next time
        estimate = worker.latest
        if estimate is None or solved == self._applied or self._submitted_learned == 0:
            return False
        self._applied = solved
        try:
            with self.loop.lock:
                self.loop.estimator.use_consistent(estimate)
        except RejectedSampleError:  # non-finite values from the solver: keep predicting as before
            return False
        return True

    def submit_projection(self) -> None:
        """Send the rigid-body learner's state to the projection worker, if learning changed it."""
        worker = self.projection
        if worker is None:
            return
        self.apply_consistent()
        if self.config["feedforward.refresh_period"] <= 0 and worker.latest is not None:
            self.serving.attach_consistent(worker.latest)  # the live model is served: attach it there
        loop = self.loop
        if self._projection_version == loop.version:
            return
        with loop.lock:
            theta, R, lam = loop.estimator.rigid_body_state()
            version = loop.version
            learned = loop.estimator.n_samples_learned
        if worker.submit(theta, R, loop.estimator.column_scale, lam):
            self._projection_version = version
            self._submitted_learned = learned

    def refresh(self) -> ConsistentEstimate | None:
        """Serve a fresh copy of the model if learning or the projection changed it.

        Returns:
            The newest consistent estimate when its link inertias were not handed out yet (to publish),
            else None.
        """
        ff = self.feedforward
        worker = self.projection
        self.apply_consistent()
        key = (self.loop.version, self.solved)
        if ff is None or key == self._ff_key:
            return None
        with self.loop.lock:
            served = self.serving.snapshot()
            if worker is not None:
                served.attach_consistent(worker.latest)
            ff.model = served
            self._ff_key = (self.loop.version, key[1])
        if worker is not None and worker.latest_links is not None and self._links_published != key[1]:
            self._links_published = key[1]
            return worker.latest_links.estimate
        return None

    def take_desired(self, convert: Callable[[], DesiredState], *, trajectory: bool) -> DesiredState | None:
        """Convert a controller's message; a refused one is counted and None returned.

        Args:
            convert: Builds the desired state from the message (raises
                :class:`~semiparam_ros.errors.RejectedSampleError` on non-finite or malformed content).
            trajectory: Whether it is a trajectory to fill (counted in ``trajectory_counts``) or a
                per-cycle desired state (counted in ``counts``).

        Returns:
            The desired state, or None (see ``feedforward.last_error``).
        """
        ff = self.feedforward
        assert ff is not None, "the feed-forward is served in joint-torque mode only"
        try:
            return convert()
        except RejectedSampleError as err:
            ff.reject(str(err), trajectory=trajectory)
            return None

    def answer(self, desired: DesiredState, now_ns: int) -> FeedForwardCommand | None:
        """Return the feed-forward command at ``desired`` (None: dropped, see ``feedforward.last_error``).

        Served from the copy of the model (:meth:`refresh`) without the learning loop's lock, from any
        one thread: an answer never waits for a learning step. With ``feedforward.refresh_period: 0`` the
        live model answers, under the lock.
        """
        ff = self.feedforward
        assert ff is not None, "the feed-forward is served in joint-torque mode only"
        if ff.model is not self.serving:
            return ff.compute(desired, now_ns)
        with self.loop.lock:
            return ff.compute(desired, now_ns)

    def trajectory(self, desired: DesiredState) -> TrajectoryEffort | None:
        """Return every point's effort of a trajectory (None: dropped, see ``feedforward.last_error``).

        Served as :meth:`answer` is (the copy, without the learning loop's lock).
        """
        ff = self.feedforward
        assert ff is not None, "the feed-forward is served in joint-torque mode only"
        if ff.model is not self.serving:
            return ff.trajectory(desired)
        with self.loop.lock:
            return ff.trajectory(desired)

    def record_age(self, age_ms: float) -> None:
        """Record the age [ms] of an answered desired state (stamp → answer), for this period's statistics."""
        with self._stats_lock:
            if len(self.latency_ms) < _MAX_LATENCIES:
                self.latency_ms.append(age_ms)

    def count_action(self, what: str) -> None:
        """Count an event of the ``FollowJointTrajectory`` proxy (``action.<what>`` in diagnostics)."""
        with self._stats_lock:
            self.action_counts[what] = self.action_counts.get(what, 0) + 1

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """Gravity torques [N·m] of the identified rigid body at ``q`` [rad]."""
        with self.loop.lock:
            return self.serving.gravity(q)

    def tare_payload(self) -> None:
        """Take the model as it is as the payload's reference; the next pickup is the payload."""
        with self.loop.lock:
            self.loop.estimator.tare_payload()
            self._payload_key = None

    def payload(self) -> PayloadEstimate | None:
        """Return the payload when learning changed it since the last call, else None.

        Since a tare: the payload learner's estimate (once a pickup was detected). Without one: beyond
        the URDF (a linear solve on the rigid-body learner's state, about a millisecond), once something
        was learned, for a model with a rigid-body part.
        """
        key = self.loop.version  # neither estimate depends on the consistent projection
        if key == self._payload_key:
            return None
        with self.loop.lock:
            est = self.loop.estimator
            learner = est.payload
            if learner is not None:
                estimate = learner.estimate() if learner.detected else None
            elif est.n_samples_learned > 0 and est.parameters is not None:
                estimate = self.serving.payload()
            else:
                estimate = None
        self._payload_key = key
        if estimate is not None:
            self._payload_missing = estimate.missing
        return estimate

    def excitation_statistics(self) -> dict[str, object]:
        """Return what the data determine (``excitation.*``), recomputed at most every 10 s."""
        now = time.monotonic()
        last = self._excitation
        if last is None or (now - last[0] >= _EXCITATION_PERIOD_S and last[1] != self.loop.version):
            with self.loop.lock:  # an SVD of the p × p factor: well under a ms for a 7-joint arm
                report, version = self.serving.excitation(), self.loop.version
            value, names = report.least_excited[0]
            last = (now, version, {
                "excitation.condition": report.condition,
                "excitation.weakest_eigenvalue": value,
                "excitation.weakest_direction": ", ".join(f"{n} ({w:+.2f})" for n, w in names)})
            self._excitation = last
        return last[2]

    def statistics(self) -> dict[str, object]:
        """Return the feedforward, consistent and payload diagnostics; start a new latency period."""
        ff = self.feedforward
        if ff is None:
            return {}
        stats: dict[str, object] = {f"feedforward.{key}": count for key, count in ff.counts.items()}
        stats.update({f"trajectory.{key}": count for key, count in ff.trajectory_counts.items()})
        stats["feedforward.ready"] = self.serving.ready
        worker = self.projection
        if worker is not None:
            stats["consistent.solutions"] = worker.solved
            stats["consistent.in_use"] = worker.latest is not None
            if worker.latest is not None:
                stats["consistent.solve_ms"] = 1e3 * worker.latest.solve_s
            stats["consistent.error"] = worker.error or ""
        if self._payload_missing is not None:
            stats["payload.determined"] = not self._payload_missing
            stats["payload.missing"] = self._payload_missing
        stats["feedforward.last_error"] = ff.last_error or ""
        with self._stats_lock:
            latency, self.latency_ms = self.latency_ms, []
            stats.update({f"action.{key}": count for key, count in self.action_counts.items()})
        if latency:
            p50, p99 = np.percentile(latency, (50, 99))
            stats["feedforward.age_p50_ms"] = float(p50)
            stats["feedforward.age_p99_ms"] = float(p99)
            stats["feedforward.age_max_ms"] = float(max(latency))
            stats["feedforward.answered_in_period"] = len(latency)
        return stats

    def export_urdf(self, path: Path | None) -> tuple[bool, str]:
        """Write the URDF with the newest consistent parameters to ``path``; returns ``(ok, message)``."""
        worker = self.projection
        links = None if worker is None else worker.latest_links
        if links is None:
            return False, "no consistent estimate yet (the worker solves every parametric.consistent_period)"
        if path is None:
            return False, "checkpoint.enabled is false: the URDF is written next to the checkpoint"
        try:
            atomic_write_text(path, export_urdf(self.loop.estimator.regressor, links.estimate,
                                                links.comments()))
        except OSError as err:
            return False, f"cannot write {path}: {err}"
        warning = links.warning()
        return True, f"wrote {path}" + (f"; {warning}" if warning else "")

    def close(self) -> None:
        """Stop the projection worker (if any)."""
        if self.projection is not None:
            self.projection.close()
            self.projection = None
