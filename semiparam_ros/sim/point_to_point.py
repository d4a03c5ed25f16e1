"""A joint-torque arm moving point to point with rests, its friction remembering (Dahl), as logged.

Real arms spend much of their time at rest between moves, and there a joint's friction holds whatever its
last motion left: a static model of (q, q̇, q̈) sees q̇ = 0 and knows nothing of it. This simulates that
case: :class:`~semiparam_ros.sim.trajectories.PointToPoint` moves (synchronised trapezoidal profiles,
rests between them), the joint torques of the arm's true rigid body (its URDF parameters perturbed, as
:func:`~semiparam_ros.sim.arms.simulate_arm` perturbs them for a seed) plus, per joint,

    τ_f = f_v q̇ + F + o,      dF/dq = (f_c / δ) (1 − (F / f_c) sgn(q̇))        (Dahl),

the Coulomb part F a Dahl element of pre-sliding displacement δ: in motion F → f_c sgn(q̇) within a few
δ of travel, at rest F keeps the value the approach left. The element is integrated exactly per step of
the true positions (``F ← s f_c + (F − s f_c) exp(−|Δq| / δ)``, s the step's direction), so it does not
depend on the rate. The logged joint states are :func:`~semiparam_ros.sim.encoders.encoder_readings`:
quantized positions, jittered stamps, velocities differentiated or exact; efforts carry white noise.

>>> F = dahl_friction(np.array([[0.0], [0.01], [0.01], [0.009]]), np.array([1.0]), 1e-3)
>>> [round(float(f), 3) for f in F[:, 0]]  # forward: +f_c; at rest: kept; 1 mrad back: towards −f_c
[0.0, 1.0, 1.0, -0.264]
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.sim.arms import ArmRobot, ArmScenarioConfig, arm_regressor, arm_spec, true_parameters
from semiparam_ros.sim.encoders import encoder_readings
from semiparam_ros.sim.trajectories import PointToPoint

__all__ = ["PointToPointArm", "dahl_friction", "point_to_point_states"]

_EPOCH_NS = 10**18  # encoder_readings' first stamp


def dahl_friction(q: np.ndarray, coulomb: np.ndarray, displacement: float,
                  initial: np.ndarray | None = None) -> np.ndarray:
    """Return the Dahl friction torque F along a sequence of positions (module docstring) [N·m].

    Args:
        q: (N, n) positions in time order [rad].
        coulomb: (n,) f_c ≥ 0 [N·m].
        displacement: δ > 0, the pre-sliding displacement [rad].
        initial: (n,) F at the first row (default 0).

    Returns:
        (N, n) F at each row.

    Raises:
        ValueError: For δ ≤ 0 or shapes that do not fit.
    """
    q = np.asarray(q, dtype=np.float64)
    fc = np.asarray(coulomb, dtype=np.float64)
    if not displacement > 0 or q.ndim != 2 or fc.shape != (q.shape[1],):
        raise ValueError("need δ > 0, q of shape (N, n) and f_c of shape (n,)")
    F = np.zeros_like(q)
    F[0] = 0.0 if initial is None else initial
    steps = np.diff(q, axis=0)
    decay = np.exp(-np.abs(steps) / displacement)
    target = np.sign(steps) * fc
    for k in range(steps.shape[0]):
        moved = steps[k] != 0.0
        F[k + 1] = np.where(moved, target[k] + (F[k] - target[k]) * decay[k], F[k])
    return F


@dataclass(frozen=True)
class PointToPointArm:
    """A simulated point-to-point recording of an arm with Dahl friction.

    Attributes:
        robot: A preset of :data:`~semiparam_ros.sim.arms.ARM_ROBOTS` (``panda``, ``ur5``) or any
            :class:`ArmRobot`.
        seconds: Length [s].
        rate_hz: Joint-state rate [Hz].
        seed: Seed of the moves, rests, stamps and noise (the true robot depends on ``robot_seed`` only).
        robot_seed: Seed of the true rigid body's perturbation (one physical robot across recordings).
        resolution: Encoder quantum [rad].
        velocity: ``"differentiated"`` (backward differences of the quantized positions) or ``"exact"``.
        speed: Fraction of the velocity limits the leading joint of a move reaches.
        rest_range: Rests between moves [s] (uniform).
        displacement: The Dahl element's δ [rad] (pre-sliding).
        noise_std: White noise on each effort [N·m].
    """

    robot: str | ArmRobot = "panda"
    seconds: float = 60.0
    rate_hz: float = 1000.0
    seed: int = 0
    robot_seed: int = 0
    resolution: float = 1e-4
    velocity: str = "differentiated"
    speed: float = 0.4
    rest_range: tuple[float, float] = (0.5, 3.0)
    displacement: float = 1e-3
    noise_std: float = 0.03

    def states(self) -> tuple[list[JointStateData], np.ndarray]:
        """Return the logged joint states (efforts in N·m) and the true noise-free efforts (N, n)."""
        spec = arm_spec(self.robot)
        reg = arm_regressor(spec)
        lower, upper = reg.position_limits()
        moves = max(2, int(self.seconds / (1.0 + float(np.mean(self.rest_range)))) + 2)
        traj = PointToPoint.random(lower, upper, reg.velocity_limits(), seed=self.seed, moves=moves,
                                   speed=self.speed, rest_range=self.rest_range)
        states = encoder_readings(traj, spec.joints, rate_hz=self.rate_hz, resolution=self.resolution,
                                  seed=self.seed, velocity=self.velocity, duration=self.seconds)
        t = (np.array([s.stamp_ns for s in states], dtype=np.int64) - _EPOCH_NS) * 1e-9
        q, dq, ddq = traj(t)
        params = true_parameters(ArmScenarioConfig(name="p2p", robot=spec, seed=self.robot_seed))
        rigid = np.vstack([reg.regressor(q[i:i + 2000], dq[i:i + 2000], ddq[i:i + 2000]) @ params
                           for i in range(0, len(t), 2000)])
        fr = spec.friction
        truth = (rigid + np.asarray(fr.viscous) * dq + np.asarray(fr.offset) + np.asarray(fr.armature) * ddq
                 + dahl_friction(q, np.asarray(fr.coulomb), self.displacement))
        rng = np.random.default_rng([self.seed, 7])
        measured = truth + self.noise_std * rng.standard_normal(truth.shape)
        return [replace(s, effort=m) for s, m in zip(states, measured, strict=True)], truth


def point_to_point_states(robot: str | ArmRobot = "panda", *, seeds: Sequence[int] = (0,),
                          **options: object) -> list[list[JointStateData]]:
    """Return one recording of :class:`PointToPointArm` per seed (one physical robot)."""
    return [PointToPointArm(robot, seed=int(s), **options).states()[0] for s in seeds]  # type: ignore[arg-type]
