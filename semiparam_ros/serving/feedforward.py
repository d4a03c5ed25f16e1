"""Feed-forward torques at desired states: the node's controller-facing service, without ROS.

A controller sends a desired state — one or several trajectory points (``trajectory_msgs/JointTrajectory``
converted to :class:`DesiredState`) — and gets ``τ_ff = τ̂(q_d, q̇_d, q̈_d)`` back with its σ, in the joint
order of its effort interface (``feedforward.joints``), from the learned model alone (no correction of the
last measured error: it is evaluated ahead of the measurement; :class:`~semiparam_ros.serving.learned_model.
LearnedModel`).

Point selection: one point is used as is; with several, the point at ``now`` — linear interpolation of
positions, velocities and accelerations between the two points around ``stamp + time_from_start = now``,
the first point before it, the last after it (a header stamp of 0 means "start now": the first point).

Fallback: while the model is not ready (its residual still in warm-up) or where its σ exceeds
``max_std`` on any joint, the rigid-body part is sent instead (the CAD model before any data, with
``parametric.prior: urdf``), and the reason is counted.

Bad input — unknown or missing joints, lengths that differ from the names, NaN/inf, no point — is a
counted drop with a message (:attr:`FeedForward.last_error`); nothing non-finite is ever returned.
Missing velocities or accelerations (empty arrays) count as zero with a counted warning.

Example:
    >>> import numpy as np
    >>> from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
    >>> from semiparam_ros.core.estimator.online import OnlineEstimator
    >>> from semiparam_ros.serving.learned_model import LearnedModel
    >>> cfg = EstimatorConfig.from_flat({**ICUB_RIGHT_ARM, "robot.output": OutputKind.JOINT_TORQUES})
    >>> est = OnlineEstimator(cfg)
    >>> ff = FeedForward(LearnedModel(est))
    >>> names = ff.joints[::-1]  # any order: the names say which value is which
    >>> cmd = ff.compute(DesiredState(0, names, (TrajectoryPoint(0, np.zeros(4)),)), now_ns=0)
    >>> cmd.source, cmd.tau.shape   # nothing learned yet: the rigid-body part (the URDF's CAD model)
    ('rigid_body', (4,))
    >>> ff.compute(DesiredState(0, ("nope",), (TrajectoryPoint(0, np.zeros(1)),)), now_ns=0) is None
    True
    >>> ff.last_error.split(" (")[0]
    "unknown joint(s) ['nope']"
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.core.learners.stick import StickState
from semiparam_ros.core.validation import MAX_ABS_INPUT
from semiparam_ros.errors import ConfigurationError, RejectedSampleError
from semiparam_ros.serving.learned_model import EXCLUDABLE, EXCLUDE_SOURCES, LearnedModel

__all__ = ["DROP_REASONS", "TRAJECTORY_DROP_REASONS", "DesiredState", "FeedForward", "FeedForwardCommand",
           "TrajectoryEffort", "TrajectoryPoint", "controller_derivatives"]

#: Reasons a desired state is dropped (counted under ``feedforward.drops.<reason>``).
DROP_REASONS = ("unknown_joint", "missing_joint", "wrong_length", "non_finite", "no_point")
#: Reasons a whole trajectory is dropped (counted under ``trajectory.drops.<reason>``).
TRAJECTORY_DROP_REASONS = (*DROP_REASONS, "unordered_time")


@dataclass(frozen=True)
class TrajectoryPoint:
    """One point of a desired trajectory.

    Attributes:
        time_from_start_ns: Time of the point after the trajectory's stamp [ns].
        positions: [rad] per name.
        velocities: [rad/s] per name, or empty (zero).
        accelerations: [rad/s²] per name, or empty (zero).
    """

    time_from_start_ns: int
    positions: np.ndarray
    velocities: np.ndarray = field(default_factory=lambda: np.zeros(0))
    accelerations: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class DesiredState:
    """A desired trajectory (``trajectory_msgs/JointTrajectory`` without ROS types).

    Attributes:
        stamp_ns: Header stamp [ns]; 0 means "now".
        names: Joint names, the order of every point's arrays.
        points: The points (at least one).
    """

    stamp_ns: int
    names: tuple[str, ...]
    points: tuple[TrajectoryPoint, ...]


@dataclass(frozen=True)
class TrajectoryEffort:
    """Efforts of every point of a trajectory, in the trajectory's joint order.

    Attributes:
        effort: (m, n) feed-forward torques [N·m] (finite), row k for point k, columns as ``names``.
        fallback: (m,) whether point k got the rigid-body part (model not ready, or σ above ``max_std``).
        velocities: (m, n) the velocities used [rad/s] (the points', or the controller's interpolation).
        accelerations: (m, n) the accelerations used [rad/s²] (likewise).
    """

    effort: np.ndarray
    fallback: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray


def controller_derivatives(times_s: np.ndarray, positions: np.ndarray, velocities: np.ndarray | None,
                           accelerations: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations at the points as ``joint_trajectory_controller`` interpolates them.

    The controller interpolates linearly between points that carry positions only, with a cubic between
    points that carry positions and velocities, with a quintic when accelerations are given too. At a
    point it samples the segment that starts there (the last point: the segment that ends there). So:

    * accelerations given: used as they are;
    * velocities without accelerations: the cubic of the segment from point k to k + 1 (duration T,
      Δ = p₁ − p₀) has q̈(0) = (6Δ − (4v₀ + 2v₁)T)/T² at its start and q̈(T) = (−6Δ + (2v₀ + 4v₁)T)/T²
      at its end;
    * positions only: q̇ = Δ/T of the segment that starts at the point (zero at the last point: the
      controller holds it), q̈ = 0.

    A single point without derivatives gets zeros.

    Args:
        times_s: (m,) times of the points [s], strictly increasing.
        positions: (m, n) [rad].
        velocities: (m, n) [rad/s] or None.
        accelerations: (m, n) [rad/s²] or None (ignored without velocities: the controller needs both).

    Returns:
        ``(q̇, q̈)``, each (m, n).

    >>> t = np.array([0.0, 1.0])
    >>> v, a = controller_derivatives(t, np.array([[0.0], [1.0]]), np.array([[0.0], [0.0]]), None)
    >>> a.ravel().tolist()  # the cubic rest-to-rest: q̈ = 6Δ/T² at the start, −6Δ/T² at the end
    [6.0, -6.0]
    >>> controller_derivatives(t, np.array([[0.0], [1.0]]), None, None)[0].ravel().tolist()
    [1.0, 0.0]
    """
    m, n = positions.shape
    if velocities is None:
        v = np.zeros((m, n))
        if m > 1:
            v[:-1] = np.diff(positions, axis=0) / np.diff(times_s)[:, None]
        return v, np.zeros((m, n))
    if accelerations is not None:
        return velocities, accelerations
    a = np.zeros((m, n))
    if m > 1:
        T = np.diff(times_s)[:, None]
        delta = np.diff(positions, axis=0)
        v0, v1 = velocities[:-1], velocities[1:]
        a[:-1] = (6.0 * delta - (4.0 * v0 + 2.0 * v1) * T) / T**2
        a[-1] = ((-6.0 * delta[-1] + (2.0 * v0[-1] + 4.0 * v1[-1]) * T[-1]) / T[-1] ** 2)
    return velocities, a


@dataclass(frozen=True)
class FeedForwardCommand:
    """The answer to a desired state, in the order of :attr:`FeedForward.joints`.

    Attributes:
        stamp_ns: The time the state was evaluated for [ns] (the point's, or ``now``).
        q: Desired positions used [rad]; dq [rad/s], ddq [rad/s²] likewise.
        tau: Feed-forward torques [N·m] (finite).
        std: Their predictive σ [N·m] (+inf before the noise is known).
        source: ``"model"`` or ``"rigid_body"`` (the fallback).
        reason: Why the fallback was used (``"not_ready"``, ``"std"``), or None.
    """

    stamp_ns: int
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    tau: np.ndarray
    std: np.ndarray
    source: str
    reason: str | None = None


class FeedForward:
    """Answers desired states with the learned model's torques (see the module docstring).

    Args:
        model: The learned model (joint torques).
        joints: Output order (a controller's joint list); default the model's joints. Every name must
            be a joint of the model.
        max_std: σ [N·m] above which the rigid-body part is used instead; 0 disables the check.
        exclude: Terms left out of every answer (``gravity``, ``friction``: a robot that compensates
            them itself; ``feedforward.exclude``), from the model's own rigid body or the URDF's
            (``exclude_source``; :meth:`LearnedModel.excluded`). σ is unchanged.
        exclude_source: ``model`` or ``urdf`` (``feedforward.exclude_source``).
        effort_limits: |τ| allowed per model joint [N·m] (the URDF's ``<limit effort>``; inf: none): an
            answer beyond it is clamped and counted (``clamped``, ``clamped_points``). None: no limit.

    Raises:
        ConfigurationError: A model that does not output joint torques, an unknown or repeated output
            joint, a negative/non-finite ``max_std``, an unknown term or source, or limits of another
            length or not > 0.
    """

    def __init__(self, model: LearnedModel, *, joints: Sequence[str] | None = None,
                 max_std: float = 0.0, exclude: Sequence[str] = (), exclude_source: str = "model",
                 effort_limits: Sequence[float] | np.ndarray | None = None) -> None:
        if model.output != OutputKind.JOINT_TORQUES:
            raise ConfigurationError("feed-forward needs robot.output: joint_torques (a wrench model "
                                     "predicts a sensor reading, not actuator torques)")
        self.model = model
        self._model_joints = model.joints
        out = tuple(joints) if joints else model.joints
        unknown = [j for j in out if j not in self._model_joints]
        if unknown or len(set(out)) != len(out):
            raise ConfigurationError(f"feedforward.joints must name distinct joints of robot.joints "
                                     f"{list(self._model_joints)}, got {list(out)}")
        self.joints: tuple[str, ...] = out
        self._out_index = np.array([self._model_joints.index(j) for j in out])
        if not (np.isfinite(max_std) and max_std >= 0.0):
            raise ConfigurationError(f"feedforward.max_std must be a finite number >= 0 N·m, got "
                                     f"{max_std!r}")
        self.max_std = float(max_std)
        if not set(exclude) <= set(EXCLUDABLE) or exclude_source not in EXCLUDE_SOURCES:
            raise ConfigurationError(f"feedforward.exclude must be a subset of {list(EXCLUDABLE)} and "
                                     f"feedforward.exclude_source one of {list(EXCLUDE_SOURCES)}, got "
                                     f"{list(exclude)} and {exclude_source!r}")
        self.exclude, self.exclude_source = tuple(exclude), str(exclude_source)
        n = len(self._model_joints)
        limits = np.full(n, np.inf) if effort_limits is None else np.asarray(effort_limits, dtype=np.float64)
        if limits.shape != (n,) or bool(np.any(~(limits > 0.0))):
            raise ConfigurationError(f"effort limits must be {n} values > 0 N·m (inf: none), got {limits!r}")
        #: |τ| allowed per joint of :attr:`joints` [N·m].
        self.effort_limits = limits[self._out_index]
        self._limits = limits  # in the model's joint order
        self._index_cache: dict[tuple[str, ...], np.ndarray] = {}
        # consecutive per-cycle desired states are one path: friction that remembers carries its stick
        # state from one to the next (from the measured path's at the first)
        self._history: StickState | None = None
        self.counts: dict[str, int] = {"published": 0, "fallback.not_ready": 0, "fallback.std": 0,
                                       "missing_velocities": 0, "missing_accelerations": 0, "clamped": 0,
                                       **{f"drops.{r}": 0 for r in DROP_REASONS}}
        self.last_error: str | None = None
        #: The drop reason of :attr:`last_error` (a key of :data:`TRAJECTORY_DROP_REASONS`), or None.
        self.last_reason: str | None = None
        #: Trajectories answered, points that fell back to the rigid-body part, drops by reason.
        self.trajectory_counts: dict[str, int] = {"published": 0, "points": 0, "fallback_points": 0,
                                                  "clamped_points": 0,
                                                  "interpolated_velocities": 0,
                                                  "interpolated_accelerations": 0,
                                                  **{f"drops.{r}": 0 for r in TRAJECTORY_DROP_REASONS}}

    def fallback_message(self, reason: str | None) -> str:
        """Say why a command fell back to the rigid-body part (``FeedForwardCommand.reason``)."""
        why = ("the model is not ready (residual warm-up)" if reason == "not_ready"
               else f"its std exceeds feedforward.max_std = {self.max_std:g} N·m")
        return "feed-forward falls back to the rigid-body part: " + why

    def reject(self, message: str, *, trajectory: bool) -> None:
        """Count a controller message that could not be converted (``drops.non_finite``) and say why."""
        (self._trajectory_drop if trajectory else self._drop)("non_finite", message)

    def _drop(self, reason: str, message: str) -> None:
        self.counts[f"drops.{reason}"] += 1
        self.last_error, self.last_reason = message, reason

    def _index(self, names: tuple[str, ...], drop: Callable[[str, str], None] | None = None
               ) -> np.ndarray | None:
        """Position in ``names`` of each model joint, or None (counted by ``drop``) when they do not fit."""
        index = self._index_cache.get(names)
        if index is not None:
            return index
        drop = drop or self._drop
        unknown = [n for n in names if n not in self._model_joints]
        if unknown:
            drop("unknown_joint", f"unknown joint(s) {unknown} (the model's joints: "
                                  f"{list(self._model_joints)})")
            return None
        missing = [j for j in self._model_joints if j not in names]
        if missing or len(set(names)) != len(names):
            drop("missing_joint", f"the desired state lacks joint(s) {missing} or repeats names: "
                                  f"{list(names)}")
            return None
        index = np.array([names.index(j) for j in self._model_joints])
        if len(self._index_cache) < 16:  # a controller sends one name list; a bound against floods
            self._index_cache[names] = index
        return index

    def _point(self, desired: DesiredState, now_ns: int
               ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray] | None:
        """``(stamp, q, q̇, q̈)`` at now (names' order), or None (counted)."""
        n = len(desired.names)
        arrays: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
        for point in desired.points:
            p = np.asarray(point.positions, dtype=np.float64)
            v = np.asarray(point.velocities, dtype=np.float64)
            a = np.asarray(point.accelerations, dtype=np.float64)
            if p.shape != (n,) or v.shape not in ((0,), (n,)) or a.shape not in ((0,), (n,)):
                self._drop("wrong_length", f"a point has {p.size} positions, {v.size} velocities, {a.size} "
                                           f"accelerations for {n} names")
                return None
            if v.size == 0:
                self.counts["missing_velocities"] += 1
                v = np.zeros(n)
            if a.size == 0:
                self.counts["missing_accelerations"] += 1
                a = np.zeros(n)
            stacked = np.concatenate([p, v, a])
            if not (np.abs(stacked).max(initial=0.0) <= MAX_ABS_INPUT):
                self._drop("non_finite", "a point holds NaN, inf or absurdly large values")
                return None
            arrays.append((desired.stamp_ns + int(point.time_from_start_ns), p, v, a))
        if not arrays:
            self._drop("no_point", "the desired state has no point")
            return None
        if len(arrays) == 1 or desired.stamp_ns == 0 or now_ns <= arrays[0][0]:
            first = arrays[0]
            return (now_ns if desired.stamp_ns == 0 else first[0], first[1], first[2], first[3])
        for (t0, p0, v0, a0), (t1, p1, v1, a1) in itertools.pairwise(arrays):
            if t0 <= now_ns <= t1:
                w = 0.0 if t1 == t0 else (now_ns - t0) / (t1 - t0)
                return now_ns, p0 + w * (p1 - p0), v0 + w * (v1 - v0), a0 + w * (a1 - a0)
        return arrays[-1]

    def compute(self, desired: DesiredState, now_ns: int) -> FeedForwardCommand | None:
        """Return the feed-forward command for a desired state, or None when it is dropped (counted).

        Args:
            desired: The desired trajectory.
            now_ns: The current time on the trajectory's clock [ns].

        Returns:
            The command in the order of :attr:`joints`, or None (see :attr:`last_error`).
        """
        index = self._index(desired.names)
        if index is None:
            return None
        point = self._point(desired, now_ns)
        if point is None:
            return None
        stamp, p, v, a = point
        q, dq, ddq = p[index], v[index], a[index]
        if self._history is None:
            self._history = self.model.stick_state()
        try:
            parts = self.model.predict_parts(q, dq, ddq, exclude=self.exclude,
                                             exclude_source=self.exclude_source, history=self._history)
        except RejectedSampleError as err:  # e.g. a regressor overflow at an absurd state
            self._drop("non_finite", f"the model refused the state: {err}")
            return None
        reason = None
        if not self.model.ready:
            reason = "not_ready"
        elif self.max_std > 0.0 and bool(np.any(parts.std > self.max_std)):
            reason = "std"
        tau = parts.total if reason is None else parts.rigid_body
        if not np.isfinite(tau).all():
            self._drop("non_finite", "the model's prediction is not finite")
            return None
        if bool(np.any(np.abs(tau) > self._limits)):
            tau = np.clip(tau, -self._limits, self._limits)
            self.counts["clamped"] += 1
        if reason is not None:
            self.counts[f"fallback.{reason}"] += 1
        self.counts["published"] += 1
        out = self._out_index
        return FeedForwardCommand(stamp, q[out], dq[out], ddq[out], tau[out], parts.std[out],
                                  "model" if reason is None else "rigid_body", reason)

    def _trajectory_drop(self, reason: str, message: str) -> None:
        self.trajectory_counts[f"drops.{reason}"] += 1
        self.last_error, self.last_reason = message, reason

    def trajectory(self, desired: DesiredState) -> TrajectoryEffort | None:
        """Return the efforts of every point of a trajectory, or None when it is dropped (counted).

        Each point's effort is the model at its positions, velocities and accelerations; missing
        derivatives come from the interpolation ``joint_trajectory_controller`` uses between the points
        (:func:`controller_derivatives`). All points are evaluated in one vectorised call. Where the
        model is not ready or a point's σ exceeds ``max_std``, that point gets the rigid-body part.

        Args:
            desired: The trajectory (every point with the same fields; ``time_from_start`` increasing).

        Returns:
            The efforts in the trajectory's joint order, or None (see :attr:`last_error` and
            ``trajectory_counts['drops.<reason>']``).

        >>> import numpy as np
        >>> from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
        >>> from semiparam_ros.core.estimator.online import OnlineEstimator
        >>> from semiparam_ros.serving.learned_model import LearnedModel
        >>> cfg = EstimatorConfig.from_flat({**ICUB_RIGHT_ARM, "robot.output": OutputKind.JOINT_TORQUES})
        >>> est = OnlineEstimator(cfg)
        >>> ff = FeedForward(LearnedModel(est))
        >>> points = tuple(TrajectoryPoint(k * 10**8, np.full(4, 0.1 * k), np.zeros(4)) for k in range(3))
        >>> out = ff.trajectory(DesiredState(0, ff.joints, points))
        >>> out.effort.shape, out.fallback.tolist()  # nothing learned: the rigid-body part everywhere
        ((3, 4), [True, True, True])
        >>> ff.trajectory(DesiredState(0, ff.joints, points[::-1])) is None, ff.last_error
        (True, 'time_from_start must increase from point to point')
        """
        index = self._index(desired.names, self._trajectory_drop)
        if index is None:
            return None
        points = desired.points
        if not points:
            self._trajectory_drop("no_point", "the trajectory has no point")
            return None
        n = len(desired.names)
        try:
            P = np.array([p.positions for p in points], dtype=np.float64)
            V = np.array([p.velocities for p in points], dtype=np.float64)
            A = np.array([p.accelerations for p in points], dtype=np.float64)
        except ValueError:  # ragged: points with different lengths
            P = V = A = np.zeros((0, 0))
        if P.shape != (len(points), n) or V.shape[1:] not in ((0,), (n,)) or A.shape[1:] not in ((0,), (n,)):
            self._trajectory_drop("wrong_length", f"every point must have {n} positions and 0 or {n} "
                                                  f"velocities and accelerations, all points alike")
            return None
        if not all(np.abs(a).max(initial=0.0) <= MAX_ABS_INPUT for a in (P, V, A)):
            self._trajectory_drop("non_finite", "a point holds NaN, inf or absurdly large values")
            return None
        times = np.array([p.time_from_start_ns for p in points], dtype=np.int64)
        if np.any(np.diff(times) <= 0):
            self._trajectory_drop("unordered_time", "time_from_start must increase from point to point")
            return None
        counts = self.trajectory_counts
        if V.shape[1] == 0:
            counts["interpolated_velocities"] += 1
        if A.shape[1] == 0:
            counts["interpolated_accelerations"] += 1
        V, A = controller_derivatives(1e-9 * times.astype(np.float64), P, V if V.shape[1] else None,
                                      A if A.shape[1] and V.shape[1] else None)
        try:
            parts = self.model.predict_parts(P[:, index], V[:, index], A[:, index], exclude=self.exclude,
                                             exclude_source=self.exclude_source)
        except RejectedSampleError as err:
            self._trajectory_drop("non_finite", f"the model refused a point: {err}")
            return None
        std = np.atleast_2d(parts.std)
        if not self.model.ready:
            fallback = np.ones(len(points), dtype=bool)
        elif self.max_std > 0.0:
            fallback = np.any(std > self.max_std, axis=1)
        else:
            fallback = np.zeros(len(points), dtype=bool)
        tau = np.where(fallback[:, None], np.atleast_2d(parts.rigid_body), np.atleast_2d(parts.total))
        if not np.isfinite(tau).all():
            self._trajectory_drop("non_finite", "the model's prediction is not finite")
            return None
        beyond = np.any(np.abs(tau) > self._limits, axis=1)
        if beyond.any():
            tau = np.clip(tau, -self._limits, self._limits)
            counts["clamped_points"] += int(beyond.sum())
        effort = np.empty_like(tau)
        effort[:, index] = tau  # back to the trajectory's joint order
        counts["published"] += 1
        counts["points"] += len(points)
        counts["fallback_points"] += int(fallback.sum())
        return TrajectoryEffort(effort, fallback, V, A)

