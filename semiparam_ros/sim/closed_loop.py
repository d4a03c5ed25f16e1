"""A torque-controlled simulated arm in closed loop: what a feed-forward term is worth.

The plant is the same physical robot as the simulator's recordings of one (robot, seed)
(:func:`~semiparam_ros.sim.arms.true_parameters`: perturbed CAD inertias, the preset's friction and
offsets), integrated with Pinocchio's forward dynamics (ABA):

    M(q) q̈ + h(q, q̇) = τ − τ_f(q̇),         τ_f = f_v q̇ + f_c tanh(q̇ / v_s) + o

with semi-implicit Euler sub-steps of at most 0.1 ms inside each control period (the Coulomb term is
stiff near q̇ = 0).
The controller runs at ``rate`` Hz on measured q, q̇ (the preset's encoder and velocity noise) and holds its
torque over the period:

    τ = τ_ff(q_d, q̇_d, q̈_d) + K_p (q_d − q_m) + K_d (q̇_d − q̇_m)

with low gains (a compliant robot): per joint, a critically damped loop of ``frequency_hz`` on the
diagonal of the CAD mass matrix at the start posture (:func:`pd_gains`), the same rule for any robot. The
joint torque sensors read ``τ + ε`` (the preset's torque noise), the convention of the recordings
(measured torque = rigid body + friction). Tracking error is ``q_d − q`` of the true state [rad].
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from semiparam_ros.sim.arms import ArmScenarioConfig, arm_regressor, arm_spec, true_parameters
from semiparam_ros.sim.trajectories import multisine

__all__ = ["ArmPlant", "LoopResult", "desired_trajectory", "pd_gains", "run_loop"]

#: Feed-forward law: (tick k, time [s], q_d, q̇_d, q̈_d, q_m, q̇_m, last measured τ) → τ_ff [N·m].
FeedForwardLaw = Callable[[int, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                           np.ndarray], np.ndarray]


class ArmPlant:
    """The true arm of a preset robot and seed, integrated by ABA with friction.

    Args:
        robot: Key of :data:`~semiparam_ros.sim.arms.ARM_ROBOTS`.
        seed: The physical robot's seed (as in :class:`~semiparam_ros.sim.arms.ArmScenarioConfig`).

    Attributes:
        joints: The moving joints.
        parameters: True parameters (per body, the regressor's columns).
    """

    def __init__(self, robot: str = "panda", seed: int = 0) -> None:
        self.spec = arm_spec(robot)
        config = ArmScenarioConfig(name=f"{robot}_closed_loop", robot=robot, seed=seed)
        self.regressor = arm_regressor(robot)
        self.parameters = true_parameters(config)
        self.friction = config.true_friction()
        self.joints = self.spec.joints
        model = self.regressor.pinocchio_model.copy()
        for i, jid in enumerate(range(1, model.njoints)):
            model.inertias[jid] = pin.Inertia.FromDynamicParameters(self.parameters[10 * i: 10 * i + 10])
        self.model = model
        self.data = model.createData()
        self._fv = np.asarray(self.friction.viscous)
        self._fc = np.asarray(self.friction.coulomb)
        self._fo = np.asarray(self.friction.offset)
        self._vs = self.friction.smoothing
        cad = self.regressor.pinocchio_model
        self._cad, self._cad_data = cad, cad.createData()

    def friction_torques(self, dq: np.ndarray) -> np.ndarray:
        """``τ_f(q̇)`` [N·m] (no armature in the presets)."""
        return self._fv * dq + self._fc * np.tanh(dq / self._vs) + self._fo

    def inverse_dynamics(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
        """Return the true model's torques ``RNEA_true(q, q̇, q̈) + τ_f(q̇)`` [N·m] at (N, n) states.

        The best feed-forward there is: what a learned one is measured against.
        """
        q, dq, ddq = (np.atleast_2d(np.asarray(a, dtype=np.float64)) for a in (q, dq, ddq))
        rigid = np.array([pin.rnea(self.model, self.data, q[i], dq[i], ddq[i]) for i in range(q.shape[0])])
        return rigid + self.friction_torques(dq)

    def step(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, period_s: float, substeps: int
             ) -> tuple[np.ndarray, np.ndarray]:
        """Advance the state by one control period under a held torque (semi-implicit Euler)."""
        h = period_s / substeps
        q, dq = q.copy(), dq.copy()
        for _ in range(substeps):
            ddq = pin.aba(self.model, self.data, q, dq, tau - self.friction_torques(dq))
            dq += h * ddq
            q += h * dq
        return q, dq

    def cad_mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Return the CAD (URDF) joint-space inertia matrix at q [kg·m²]."""
        M = pin.crba(self._cad, self._cad_data, q)
        return np.triu(M) + np.triu(M, 1).T


def pd_gains(plant: ArmPlant, q0: np.ndarray, frequency_hz: float = 2.0, damping: float = 1.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """Per-joint ``K_p = m ω²``, ``K_d = 2 ζ m ω`` with m the CAD mass-matrix diagonal at q0.

    Args:
        plant: The arm.
        q0: Posture [rad].
        frequency_hz: Closed-loop natural frequency ω/2π [Hz] (2 Hz: a compliant arm).
        damping: Damping ratio ζ.

    Returns:
        ``(K_p [N·m/rad], K_d [N·m·s/rad])``.
    """
    m = np.diag(plant.cad_mass_matrix(q0))
    w = 2.0 * np.pi * frequency_hz
    return m * w * w, 2.0 * damping * m * w


def desired_trajectory(robot: str, seed: int, duration_s: float, rate_hz: float
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return a multi-sine reference inside the preset's window and bounds (the recordings' kind of motion).

    Args:
        robot: Key of :data:`~semiparam_ros.sim.arms.ARM_ROBOTS`.
        seed: Seed of the multi-sine.
        duration_s: Length [s].
        rate_hz: Sample rate [Hz].

    Returns:
        ``(t [s], q_d [rad], q̇_d [rad/s], q̈_d [rad/s²])``, arrays (N,) and (N, n).
    """
    spec = arm_spec(robot)
    window = np.asarray(spec.position_window, dtype=np.float64)
    traj = multisine(window[:, 0], window[:, 1], seed=seed, base_period=spec.base_period,
                     max_velocity=spec.max_velocity, max_acceleration=spec.max_acceleration)
    t = np.arange(round(duration_s * rate_hz)) / rate_hz
    q, dq, ddq = traj.evaluate(t)
    return t, q, dq, ddq


@dataclass
class LoopResult:
    """One closed-loop run.

    Attributes:
        t: Control instants [s] (N,).
        q_desired: (N, n) [rad].
        q: True positions at each instant (N, n) [rad].
        tau: Commanded torques (N, n) [N·m].
        tau_ff: Their feed-forward part (N, n) [N·m].
    """

    t: np.ndarray
    q_desired: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    tau_ff: np.ndarray

    def errors(self, skip_s: float = 0.0) -> np.ndarray:
        """Tracking errors ``q_d − q`` after ``skip_s`` [rad], (M, n)."""
        keep = self.t >= skip_s
        return (self.q_desired - self.q)[keep]

    def rms(self, skip_s: float = 0.0) -> np.ndarray:
        """Per-joint RMS tracking error [rad]."""
        e = self.errors(skip_s)
        return np.sqrt(np.mean(e * e, axis=0))

    def max_abs(self, skip_s: float = 0.0) -> np.ndarray:
        """Per-joint largest |tracking error| [rad]."""
        return np.abs(self.errors(skip_s)).max(axis=0)


def run_loop(plant: ArmPlant, t: np.ndarray, q_d: np.ndarray, dq_d: np.ndarray, ddq_d: np.ndarray,
             feedforward: FeedForwardLaw, kp: np.ndarray, kd: np.ndarray, *, max_step_s: float = 1e-4,
             noise_scale: float = 1.0, seed: int = 0,
             measured: Callable[[int, float, np.ndarray, np.ndarray, np.ndarray], None] | None = None,
             ) -> LoopResult:
    """Track a reference with PD + a feed-forward law.

    Args:
        plant: The arm.
        t: Control instants [s], uniformly spaced.
        q_d: Desired positions (N, n) [rad].
        dq_d: Desired velocities (N, n) [rad/s].
        ddq_d: Desired accelerations (N, n) [rad/s²].
        feedforward: The feed-forward law (called once per tick, before the torque is applied).
        kp: Proportional gains (n,) [N·m/rad].
        kd: Derivative gains (n,) [N·m·s/rad].
        max_step_s: Largest integration sub-step [s] (the smooth Coulomb term is stiff: explicit steps
            must stay below ~2 I v_s / f_c, ≈ 0.2 ms on the Panda's wrist).
        noise_scale: Factor on the preset's measurement noise (0: none).
        seed: Seed of the measurement noise.
        measured: Called at each tick k ≥ 1, before the controller, with (k, t_k [s], q_m, q̇_m, τ_meas):
            the joint state a publisher would send at t_k (the controller's own measurement), effort the
            torque sensors' reading of the torque held over the last period (for learning online).

    Returns:
        The run.
    """
    spec = plant.spec
    rng = np.random.default_rng(seed)
    n = len(plant.joints)
    period = float(t[1] - t[0])
    substeps = max(1, int(np.ceil(period / max_step_s - 1e-9)))
    q, dq = q_d[0].copy(), dq_d[0].copy()
    q_true = np.empty_like(q_d)
    taus = np.empty_like(q_d)
    ffs = np.empty_like(q_d)
    tau_std = noise_scale * np.asarray(spec.torque_noise_std)
    last_tau = np.zeros(n)
    for k in range(len(t)):
        q_m = q + noise_scale * spec.position_noise_std * rng.standard_normal(n)
        dq_m = dq + noise_scale * spec.velocity_noise_std * rng.standard_normal(n)
        if measured is not None and k > 0:
            measured(k, float(t[k]), q_m, dq_m, last_tau)
        q_true[k] = q
        ff = np.asarray(feedforward(k, float(t[k]), q_d[k], dq_d[k], ddq_d[k], q_m, dq_m, last_tau))
        tau = ff + kp * (q_d[k] - q_m) + kd * (dq_d[k] - dq_m)
        ffs[k], taus[k] = ff, tau
        q, dq = plant.step(q, dq, tau, period, substeps)
        last_tau = tau + tau_std * rng.standard_normal(n)  # what the torque sensors read over the period
    return LoopResult(t, q_d, q_true, taus, ffs)
