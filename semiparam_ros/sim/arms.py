"""Synthetic joint-torque recordings of URDF arms (Franka Panda, UR5): friction, payload, contacts.

The measurement model, at every joint-state stamp t (s from the first stamp), joints i = 1 … n:

    τ_meas(t) = Φ(q, q̇, q̈) π(t)  +  τ_f(q̇, q̈)  −  J(q)ᵀ F(t)  +  ε(t)
    τ_f,i     = f_v,i q̇ᵢ + f_c,i tanh(q̇ᵢ / v_s) + oᵢ + aᵢ q̈ᵢ

* **Trajectory**: a random multi-sine (:func:`~semiparam_ros.sim.trajectories.multisine`) inside the
  robot's position window, with |q̇| and |q̈| bounded for all t (:class:`ArmRobot`); q, q̇, q̈ exact.
* **True rigid-body parameters** π: the URDF's (a CAD model), perturbed once per robot and seed
  (:class:`ParameterPerturbation`): each body's mass scaled by (1 + δ), δ uniform in ±``mass``; its centre
  of mass shifted by up to ``com`` m per axis; its second moments of mass about the centre of mass
  (Σ = ½ tr(I_c) 1 − I_c, positive semi-definite) scaled along their principal axes by (1 + δ), δ uniform
  in ±``inertia``. Every body stays physically consistent. The same robot and seed give the same π in
  every bag, so that one bag can train and another test.
* **Payload**: a point mass attached at a point of the end-effector frame from ``payload_time`` on
  (persistent), added to the carrying body's parameters (π(t) changes once).
* **Friction** (:class:`JointFriction`): viscous ``f_v`` (N·m·s/rad), Coulomb ``f_c`` (N·m) with the smooth
  sign ``tanh(q̇/v_s)`` (v_s in rad/s), a constant offset ``o`` (N·m) and an optional armature ``a``
  (kg·m²), evaluated at the true q̇, q̈ — the convention of the learner's friction columns.
* **Contacts** (:mod:`semiparam_ros.sim.contacts`): a force F (N, base frame) at the end-effector frame's
  origin. The trajectory is kept (the controller compensates), so the joints carry the reaction and the
  measured torques change by ``−J(q)ᵀ F``, J the linear Jacobian (m/rad) of that point in the base frame.
  That change is what ``external = measured − predicted`` estimates.
* **Noise** ε: Gaussian, per joint (N·m); the published positions and velocities carry encoder and
  velocity noise (rad, rad/s). Nothing publishes accelerations.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from semiparam_ros.core.fourier import FourierTrajectory
from semiparam_ros.core.kinds import InputKind, OutputKind
from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor, is_physically_consistent
from semiparam_ros.core.rigid_body.urdf import resolve_urdf
from semiparam_ros.sim.contacts import (
    ContactEpisode,
)
from semiparam_ros.sim.ik import ArmKinematics
from semiparam_ros.sim.recording import (
    Measurement,
    RecordingConfig,
    add_payload,
    arm_kinematics,
    column_rms,
    contacts_info,
    draw_contacts,
    limits_info,
    recording_seeds,
    regressor_of,
    rigid_outputs,
    sample_stamps,
)
from semiparam_ros.sim.trajectories import multisine

__all__ = [
    "ARM_ROBOTS",
    "ARM_SCENARIOS",
    "DEFAULT_DURATION_S",
    "ArmRecording",
    "ArmRobot",
    "ArmScenarioConfig",
    "JointFriction",
    "JointTorqueMeasurement",
    "ParameterPerturbation",
    "SensorWrench",
    "arm_from_urdf",
    "arm_regressor",
    "arm_spec",
    "perturb_parameters",
    "sensor_wrench",
    "simulate_arm",
    "true_parameters",
]


def _floats(values: object, n: int, what: str, *, nonneg: bool = False) -> tuple[float, ...]:
    arr = np.asarray(values, dtype=np.float64).reshape(-1)
    if arr.size == 1 and n > 1:
        arr = np.full(n, float(arr[0]))
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be {n} finite numbers, got {values!r}")
    if nonneg and np.any(arr < 0):
        raise ValueError(f"{what} must be >= 0, got {values!r}")
    return tuple(float(v) for v in arr)


@dataclass(frozen=True)
class JointFriction:
    """Per-joint friction, offset and armature: ``τ_f = f_v q̇ + f_c tanh(q̇/v_s) + o + a q̈``.

    Attributes:
        viscous: f_v per joint (N·m·s/rad).
        coulomb: f_c per joint (N·m).
        offset: o per joint (N·m).
        armature: a per joint (kg·m²); zeros for none.
        smoothing: v_s of the smooth sign (rad/s).
    """

    viscous: tuple[float, ...]
    coulomb: tuple[float, ...]
    offset: tuple[float, ...]
    armature: tuple[float, ...]
    smoothing: float = 0.05

    def __post_init__(self) -> None:
        n = len(tuple(self.viscous))
        object.__setattr__(self, "viscous", _floats(self.viscous, n, "viscous friction", nonneg=True))
        object.__setattr__(self, "coulomb", _floats(self.coulomb, n, "Coulomb friction", nonneg=True))
        object.__setattr__(self, "offset", _floats(self.offset, n, "torque offset"))
        object.__setattr__(self, "armature", _floats(self.armature, n, "armature", nonneg=True))
        if not (np.isfinite(self.smoothing) and self.smoothing > 0):
            raise ValueError(
                f"friction smoothing velocity v_s must be positive (rad/s), got {self.smoothing!r}"
            )

    @property
    def n_joints(self) -> int:
        """Number of joints."""
        return len(self.viscous)

    def torques(self, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
        """Return τ_f (N·m) for velocities (k, n) in rad/s and accelerations (k, n) in rad/s²."""
        dq = np.asarray(dq, dtype=np.float64)
        ddq = np.asarray(ddq, dtype=np.float64)
        return (
            np.asarray(self.viscous) * dq
            + np.asarray(self.coulomb) * np.tanh(dq / self.smoothing)
            + np.asarray(self.offset)
            + np.asarray(self.armature) * ddq
        )

    def scaled(self, factor: float) -> JointFriction:
        """Copy with f_v, f_c, o and a multiplied by ``factor`` (≥ 0; 0 removes them)."""
        if not (np.isfinite(factor) and factor >= 0):
            raise ValueError(f"friction scale must be finite and >= 0, got {factor!r}")
        return replace(
            self,
            viscous=tuple(factor * v for v in self.viscous),
            coulomb=tuple(factor * v for v in self.coulomb),
            offset=tuple(factor * v for v in self.offset),
            armature=tuple(factor * v for v in self.armature),
        )

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python description with units in the keys (for ``scenario.yaml``)."""
        return {
            "model": "tau_f = viscous*dq + coulomb*tanh(dq/smoothing) + offset + armature*ddq",
            "smoothing_velocity_rad_per_s": float(self.smoothing),
            "viscous_Nms_per_rad": list(self.viscous),
            "coulomb_Nm": list(self.coulomb),
            "offset_Nm": list(self.offset),
            "armature_kgm2": list(self.armature),
        }


@dataclass(frozen=True)
class ParameterPerturbation:
    """How far the true inertial parameters are from the URDF's (module docstring).

    Attributes:
        mass: Maximum relative change of each mass (0 ≤ mass < 1).
        inertia: Maximum relative change of each principal second moment about the centre of mass
            (0 ≤ inertia < 1).
        com: Maximum shift of each centre of mass per axis (m).
    """

    mass: float = 0.15
    inertia: float = 0.15
    com: float = 0.01

    def __post_init__(self) -> None:
        for name in ("mass", "inertia", "com"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"perturbation {name} must be finite and >= 0, got {value!r}")
        if self.mass >= 1 or self.inertia >= 1:
            raise ValueError("perturbation mass and inertia must be below 1 (relative)")

    def as_dict(self) -> dict[str, float]:
        """Plain-Python description with units in the keys (for ``scenario.yaml``)."""
        return {"mass_relative": self.mass, "inertia_relative": self.inertia, "com_m": self.com}


def perturb_parameters(
    params: np.ndarray, perturbation: ParameterPerturbation, rng: np.random.Generator
) -> np.ndarray:
    """Return physically consistent perturbed copies of full inertial parameters (10 per body).

    Bodies of zero mass (frames without inertia) are left unchanged.

    Args:
        params: (10·b,) ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` per body (kg, kg·m, kg·m²),
            about each body frame's origin.
        perturbation: Magnitudes.
        rng: Random generator.

    Returns:
        (10·b,) perturbed parameters.

    Raises:
        ValueError: If a perturbed body is not physically consistent (a bad input body).
    """
    out = np.asarray(params, dtype=np.float64).copy()
    for b in range(out.size // 10):
        p = out[10 * b : 10 * b + 10]
        m = p[0]
        dm = rng.uniform(-1.0, 1.0)
        dc = rng.uniform(-1.0, 1.0, 3)
        ds = rng.uniform(-1.0, 1.0, 3)
        if m <= 0.0:
            continue
        c = p[1:4] / m
        I_o = np.array([[p[4], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]])
        I_c = I_o - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
        sigma = 0.5 * np.trace(I_c) * np.eye(3) - I_c  # second moments of the mass distribution (PSD)
        w, V = np.linalg.eigh(sigma)
        w = np.clip(w, 0.0, None) * (1.0 + perturbation.inertia * ds)
        sigma2 = (V * w) @ V.T
        m2 = m * (1.0 + perturbation.mass * dm)
        sigma2 *= m2 / m  # the second moments scale with the mass
        c2 = c + perturbation.com * dc
        I_c2 = np.trace(sigma2) * np.eye(3) - sigma2
        I_o2 = I_c2 + m2 * (float(c2 @ c2) * np.eye(3) - np.outer(c2, c2))
        new = np.array(
            [m2, *(m2 * c2), I_o2[0, 0], I_o2[0, 1], I_o2[1, 1], I_o2[0, 2], I_o2[1, 2], I_o2[2, 2]]
        )
        if not is_physically_consistent(new, tol=1e-12 * max(1.0, float(np.abs(new[4:]).max()))):
            raise ValueError(f"body {b}: perturbed parameters are not physically consistent")
        out[10 * b : 10 * b + 10] = new
    return out


@dataclass(frozen=True)
class ArmRobot:
    """A joint-torque arm preset: model, excitation bounds, friction, noise, payload.

    Attributes:
        name: Short name (``"panda"``, ``"ur5"``), the prefix of its bag names.
        urdf: ``robot.urdf`` value (:func:`~semiparam_ros.core.rigid_body.urdf.resolve_urdf`).
        joints: The moving joints, in the published order; every other joint is locked at 0.
        end_effector: Frame where payloads are attached and contacts act.
        position_window: (n, 2) joint range the excitation may use (rad), inside the URDF limits.
        max_velocity: Bound on every |q̇| of the excitation (rad/s).
        max_acceleration: Bound on every |q̈| of the excitation (rad/s²).
        base_period: Period of the excitation's fundamental (s).
        friction: True friction, offsets and armature.
        torque_noise_std: σ of the torque noise per joint (N·m).
        position_noise_std: σ of the joint position noise (rad).
        velocity_noise_std: σ of the joint velocity noise (rad/s).
        payload_mass: Default payload (kg).
        payload_point: Where the payload sits in the end-effector frame (m).
        ft_sensor: A fixed URDF joint holding a six-axis F/T sensor whose wrench is also recorded (on
            ``/wrench``), or ``None``.
    """

    name: str
    urdf: str
    joints: tuple[str, ...]
    end_effector: str
    position_window: tuple[tuple[float, float], ...]
    max_velocity: float
    max_acceleration: float
    base_period: float
    friction: JointFriction
    torque_noise_std: tuple[float, ...]
    position_noise_std: float
    velocity_noise_std: float
    payload_mass: float
    payload_point: tuple[float, float, float]
    ft_sensor: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python description (for ``scenario.yaml``)."""
        return {
            "name": self.name,
            "urdf": self.urdf,
            "joints": list(self.joints),
            "end_effector": self.end_effector,
            "ft_sensor": self.ft_sensor,
        }


_ZEROS7 = (0.0,) * 7
_ZEROS6 = (0.0,) * 6

#: The presets. Friction magnitudes are of the order reported for these arms (Panda: link-side torque
#: sensors, a few tenths of N·m; UR5: torques from motor currents, through the gearbox, N·m); noise of
#: the order of their torque readings' jitter. Armature is off by default (``simulate --armature``).
ARM_ROBOTS: dict[str, ArmRobot] = {
    "panda": ArmRobot(
        name="panda",
        urdf="example-robot-data://robots/panda_description/urdf/panda.urdf",
        joints=tuple(f"panda_joint{i}" for i in range(1, 8)),
        end_effector="panda_hand_tcp",
        position_window=(
            (-2.8973, 2.8973),
            (-1.7628, 1.7628),
            (-2.8973, 2.8973),
            (-3.0718, -0.0698),
            (-2.8973, 2.8973),
            (-0.0175, 3.7525),
            (-2.8973, 2.8973),
        ),
        max_velocity=1.0,
        max_acceleration=4.0,
        base_period=10.0,
        friction=JointFriction(
            viscous=(0.40, 0.50, 0.35, 0.45, 0.20, 0.25, 0.15),
            coulomb=(0.50, 0.70, 0.45, 0.60, 0.35, 0.40, 0.25),
            offset=(0.15, -0.30, 0.10, 0.25, -0.08, 0.12, -0.05),
            armature=_ZEROS7,
            smoothing=0.05,
        ),
        torque_noise_std=(0.08, 0.08, 0.08, 0.08, 0.03, 0.03, 0.03),
        position_noise_std=1e-5,
        velocity_noise_std=1e-3,
        payload_mass=1.0,
        payload_point=(0.02, 0.01, 0.03),
    ),
    "ur5": ArmRobot(
        name="ur5",
        urdf="example-robot-data://robots/ur_description/urdf/ur5_robot.urdf",
        joints=(
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
            "wrist_1_joint",
            "wrist_2_joint",
            "wrist_3_joint",
        ),
        end_effector="tool0",
        # Arm above its mounting plane (shoulder lift in [−π, 0]), elbow folded either way.
        position_window=((-3.1, 3.1), (-2.9, -0.25), (-2.6, 2.6), (-3.1, 3.1), (-3.1, 3.1), (-3.1, 3.1)),
        max_velocity=1.0,
        max_acceleration=4.0,
        base_period=10.0,
        friction=JointFriction(
            viscous=(1.8, 2.0, 1.4, 0.5, 0.5, 0.4),
            coulomb=(2.5, 3.0, 2.0, 0.9, 0.9, 0.7),
            offset=(0.4, -0.8, 0.5, 0.15, -0.10, 0.05),
            armature=_ZEROS6,
            smoothing=0.05,
        ),
        torque_noise_std=(0.3, 0.3, 0.3, 0.1, 0.1, 0.1),
        position_noise_std=2e-5,
        velocity_noise_std=2e-3,
        payload_mass=1.5,
        payload_point=(0.02, 0.0, 0.05),
    ),
}

def arm_spec(robot: str | ArmRobot) -> ArmRobot:
    """Return an arm: a preset by its key in :data:`ARM_ROBOTS`, or the arm itself.

    Raises:
        ValueError: For an unknown key.
    """
    if isinstance(robot, ArmRobot):
        return robot
    if robot not in ARM_ROBOTS:
        raise ValueError(f"robot must be one of {sorted(ARM_ROBOTS)} (or an arm of any URDF: --urdf), got "
                         f"{robot!r}")
    return ARM_ROBOTS[robot]


#: Friction, offsets and noise of :func:`arm_from_urdf`, per joint, as fractions of the joint's torque scale
#: (the largest URDF gravity torque over random poses): of the order of the presets' (the Panda's Coulomb
#: friction is ≈ 2 % of its largest gravity torques).
_VISCOUS_PER_TORQUE = 0.015  # N·m·s/rad per N·m
_COULOMB_PER_TORQUE = 0.02
_OFFSET_PER_TORQUE = 0.005
_NOISE_PER_TORQUE = 0.003
#: The least torque scale of a joint [N·m] (a wrist joint gravity barely loads).
_MIN_TORQUE_SCALE = 1.0


def arm_from_urdf(urdf: str, joints: Sequence[str], *, name: str | None = None,
                  end_effector: str | None = None, ft_sensor: str | None = None, max_velocity: float = 1.0,
                  max_acceleration: float = 4.0) -> ArmRobot:
    """Build a simulated arm of any fixed-base URDF (the user's own, for a dry run of identification).

    The excitation stays within 90 % of each joint's URDF range about its middle (±π for a continuous
    joint); friction, offsets and torque noise scale with each joint's torque scale, the largest URDF
    gravity torque over 64 random poses (at least 1 N·m): viscous 1.5 %, Coulomb 2 %, offsets ±0.5 %,
    noise 0.3 % of it; the payload is 5 % of the moving links' mass, 3 cm out along the end effector's z.
    Every other joint is locked at 0.

    Args:
        urdf: ``robot.urdf`` value (a file path, ``package://``, ``example-robot-data://``).
        joints: The moving joints, in the order they are published.
        name: Prefix of the bag names (default the URDF's robot name, made a plain identifier).
        end_effector: Frame where payloads are attached and contacts act (default the child link of the
            last joint).
        ft_sensor: A fixed joint of the URDF holding a six-axis F/T sensor: its wrench is recorded too
            (:class:`SensorWrench`), or ``None``.
        max_velocity: Bound on every |q̇| of the excitation [rad/s].
        max_acceleration: Bound on every |q̈| of the excitation [rad/s²].

    Returns:
        The arm.

    Raises:
        ValueError: If the URDF cannot be read or a joint or frame is not in it.
    """
    import re

    path = str(resolve_urdf(urdf))
    joints = tuple(joints)
    reg = regressor_of(path, joints, output=OutputKind.JOINT_TORQUES)
    lower, upper = reg.position_limits()
    lower = np.where(np.isfinite(lower), lower, -np.pi)
    upper = np.where(np.isfinite(upper), upper, np.pi)
    middle, half = 0.5 * (lower + upper), 0.45 * (upper - lower)
    window = tuple((float(a), float(b)) for a, b in zip(middle - half, middle + half, strict=True))
    rng = np.random.default_rng(0)
    q = rng.uniform(lower, upper, (64, len(joints)))
    gravity = np.abs(reg.wrench(q, np.zeros_like(q), np.zeros_like(q)))
    scale = np.maximum(gravity.max(axis=0), _MIN_TORQUE_SCALE)
    signs = np.where(np.arange(len(joints)) % 2 == 0, 1.0, -1.0)
    friction = JointFriction(viscous=tuple(_VISCOUS_PER_TORQUE * scale),
                             coulomb=tuple(_COULOMB_PER_TORQUE * scale),
                             offset=tuple(_OFFSET_PER_TORQUE * scale * signs),
                             armature=(0.0,) * len(joints), smoothing=0.05)
    masses = reg.urdf_parameters()[0::10][: reg.n_bodies]
    root = ET.parse(path).getroot()
    robot_name = name or re.sub(r"\W+", "_", root.get("name") or "robot").strip("_").lower() or "robot"
    if end_effector is None:
        child = {j.get("name"): j.find("child") for j in root.findall("joint")}
        element = child.get(joints[-1])
        if element is None:
            raise ValueError(f"joint {joints[-1]!r} is not in {urdf}")
        end_effector = str(element.get("link"))
    robot = ArmRobot(name=robot_name, urdf=path, joints=joints, end_effector=end_effector,
                     position_window=window, max_velocity=float(max_velocity),
                     max_acceleration=float(max_acceleration), base_period=10.0, friction=friction,
                     torque_noise_std=tuple(float(v) for v in _NOISE_PER_TORQUE * scale),
                     position_noise_std=1e-5, velocity_noise_std=1e-3,
                     payload_mass=round(0.05 * float(masses.sum()), 2), payload_point=(0.0, 0.0, 0.03),
                     ft_sensor=ft_sensor or None)
    if robot.ft_sensor is not None:  # the sensor must be a fixed joint with bodies beyond it
        regressor_of(path, joints, output=OutputKind.WRENCH, ft_sensor=robot.ft_sensor)
    return robot


#: Scenarios of the arms (:func:`semiparam_ros.sim.generate.preset_configs`): ``excitation`` (no payload),
#: ``payload`` (pickup at the middle), ``contacts`` (contact episodes in [0.15, 0.65]·T, then a pickup at
#: 0.75·T; 120 s unless given).
ARM_SCENARIOS: tuple[str, ...] = ("excitation", "payload", "contacts")

#: Default length of the ``excitation`` and ``payload`` scenarios (s); ``contacts``: see
#: :func:`~semiparam_ros.sim.contacts.contacts_timing`.
DEFAULT_DURATION_S = 60.0


@dataclass(frozen=True)
class ArmScenarioConfig(RecordingConfig):
    """One synthetic joint-torque recording of an arm (the shared fields: :class:`RecordingConfig`).

    Attributes:
        name: Bag folder name.
        robot: Key of :data:`ARM_ROBOTS`, or any arm (:func:`arm_from_urdf`).
        duration: Length (s).
        rate: Joint-state rate (Hz).
        seed: Seed. The true parameters depend on (robot, seed) only; trajectory and noise also on the
            name, so that bags of one robot differ but share one physical robot.
        perturbation: Distance of the true parameters from the URDF's; None for the URDF's exactly.
        friction_scale: Factor on the robot's friction, offsets and armature (0 removes them).
        armature: If given, the armature of every joint (kg·m²), replacing the robot's (before scaling).
        noise_scale: Factor on every noise σ (0 removes noise).
        trajectory: The joints' trajectory (one period, repeated; e.g. a designed excitation,
            :func:`~semiparam_ros.io.trajectory_files.read_excitation`), in the robot's joint order; None:
            the seeded random multi-sine.
    """

    duration: float = DEFAULT_DURATION_S
    robot: str | ArmRobot = "panda"
    rate: float = 1000.0
    perturbation: ParameterPerturbation | None = field(default_factory=ParameterPerturbation)
    friction_scale: float = 1.0
    armature: float | None = None
    noise_scale: float = 1.0
    trajectory: FourierTrajectory | None = None

    def __post_init__(self) -> None:
        self.check_common()
        spec = arm_spec(self.robot)
        n = len(spec.joints)
        if self.trajectory is not None and self.trajectory.n_joints != n:
            raise ValueError(f"the trajectory moves {self.trajectory.n_joints} joints, {spec.name} has {n}")
        if isinstance(self.rate, bool) or not (np.isfinite(self.rate) and self.rate > 0):
            raise ValueError(f"rate must be a positive number, got {self.rate!r}")
        if self.rate > 10_000:
            raise ValueError("rates above 10 kHz are not supported")
        for attr in ("friction_scale", "noise_scale"):
            value = getattr(self, attr)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{attr} must be finite and >= 0, got {value!r}")
        if self.armature is not None and not (np.isfinite(self.armature) and self.armature >= 0):
            raise ValueError(f"armature must be finite and >= 0 kg·m², got {self.armature!r}")

    def record(self, *, progress: Callable[[int], None] | None = None) -> ArmRecording:
        """Simulate this recording (:func:`simulate_arm`): joint torques.

        Args:
            progress: Accepted for the common interface; an arm reports no progress while simulating.
        """
        return simulate_arm(self)

    def progress_units(self) -> tuple[int, str]:
        """Return what the progress of writing counts: joint-state stamps."""
        return round(self.duration * self.rate), "stamp"

    def true_friction(self) -> JointFriction:
        """Return the friction of this recording (the robot's, armature replaced if given, scaled)."""
        fr = arm_spec(self.robot).friction
        if self.armature is not None:
            fr = replace(fr, armature=(float(self.armature),) * fr.n_joints)
        return fr.scaled(self.friction_scale)


@dataclass(frozen=True)
class SensorWrench:
    """An arm's six-axis F/T sensor over a recording: ``[f, τ]`` in the sensor frame (N, N·m).

    The reading is the wrench the bodies beyond the sensor exert on it (Φ_s(q, q̇, q̈) π_s: their true
    inertial parameters, the URDF's perturbed as the arm's are, a payload included after the pickup) plus a
    constant offset per axis (±2 % of the axis' RMS) and white noise (1 % of it).

    Attributes:
        frame: The sensor's frame (the fixed joint's name), the ``frame_id`` of the messages.
        rigid: (N, 6) the rigid-body wrench.
        true: (N, 6) rigid plus the offset (noise-free).
        measured: (N, 6) the reading.
        offset: (6,) the constant offset.
    """

    frame: str
    rigid: np.ndarray
    true: np.ndarray
    measured: np.ndarray
    offset: np.ndarray


def sensor_wrench(config: ArmScenarioConfig, spec: ArmRobot, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray,
                  after: np.ndarray) -> SensorWrench:
    """Simulate the F/T sensor of an arm that has one (see :class:`SensorWrench`).

    Args:
        config: The scenario (seed, perturbation, payload, noise scale).
        spec: The arm (its ``ft_sensor``).
        q: (N, n) positions [rad].
        dq: (N, n) velocities [rad/s].
        ddq: (N, n) accelerations [rad/s²].
        after: (N,) whether the payload is carried.

    Raises:
        ValueError: If the arm has no sensor, or the payload's frame is not beyond it.
    """
    if spec.ft_sensor is None:
        raise ValueError(f"{spec.name} has no F/T sensor")
    reg = regressor_of(str(resolve_urdf(spec.urdf)), tuple(spec.joints), output=OutputKind.WRENCH,
                       ft_sensor=spec.ft_sensor)
    rng = np.random.default_rng([int(config.seed), zlib.crc32(f"{spec.name}:{spec.ft_sensor}".encode())])
    urdf = reg.urdf_parameters()
    perturbation = config.perturbation
    before = urdf.copy() if perturbation is None else perturb_parameters(urdf, perturbation, rng)
    carried, _ = add_payload(reg, before, frame=spec.end_effector, mass=config.payload_mass,
                             pickup_s=config.pickup_time, start_ns=config.start_ns,
                             point_in_frame=spec.payload_point)
    rigid = rigid_outputs(reg, q, dq, ddq, after, before, carried, chunk=2000)
    rms = np.sqrt(np.mean(rigid**2, axis=0)) + 1e-3
    offset = 0.02 * rms * np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    noise = config.noise_scale * 0.01 * rms * np.random.default_rng(
        [int(config.seed), zlib.crc32(config.name.encode()), 6]).standard_normal(rigid.shape)
    true = rigid + offset
    return SensorWrench(spec.ft_sensor, rigid, true, true + noise, offset)


@dataclass(frozen=True)
class ArmRecording:
    """Stamped arrays of one arm recording. Joint arrays (N, n) are in the order of ``joint_names``.

    Attributes:
        config: The scenario.
        robot: The robot preset.
        joint_names: The moving joints.
        stamps: (N,) stamps (ns).
        q, dq, ddq: True positions, velocities, accelerations (rad, rad/s, rad/s²).
        q_measured, dq_measured: Noisy positions and velocities (rad, rad/s).
        rigid_torques: Φ(q, q̇, q̈) π(t) with the true parameters (payload after the pickup) (N·m).
        friction_torques: τ_f at the true q̇, q̈ (N·m).
        external_torques: Contact effect on the measured torques, ``−J(q)ᵀ F`` (N·m).
        true_torques: Noise-free measured torques: the sum of the three above (N·m).
        measured_torques: ``true_torques`` plus noise (N·m).
        contact_force: (N, 3) applied force at the end effector, base frame (N).
        contact_wrench: (N, 6) the same as ``[F, 0]`` in the end-effector frame (N).
        parameters_urdf: The URDF's full parameters.
        parameters_before, parameters_after: True full parameters before and after the pickup.
        contact_episodes: The contact episodes.
        info: Scenario description for ``scenario.yaml`` (plain Python).
        wrench: The F/T sensor's reading when the robot has one (:class:`SensorWrench`), else ``None``.
    """

    config: ArmScenarioConfig
    robot: ArmRobot
    joint_names: tuple[str, ...]
    stamps: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    q_measured: np.ndarray
    dq_measured: np.ndarray
    rigid_torques: np.ndarray
    friction_torques: np.ndarray
    external_torques: np.ndarray
    true_torques: np.ndarray
    measured_torques: np.ndarray
    contact_force: np.ndarray
    contact_wrench: np.ndarray
    parameters_urdf: np.ndarray
    parameters_before: np.ndarray
    parameters_after: np.ndarray
    contact_episodes: tuple[ContactEpisode, ...]
    info: dict[str, Any]
    wrench: SensorWrench | None = None


def arm_regressor(robot: str | ArmRobot) -> RigidBodyRegressor:
    """Return the joint-torque regressor of an arm (others locked at 0; cached, not thread-safe)."""
    spec = arm_spec(robot)
    return regressor_of(str(resolve_urdf(spec.urdf)), tuple(spec.joints), output=OutputKind.JOINT_TORQUES)


def _kinematics(robot: str | ArmRobot) -> ArmKinematics:
    spec = arm_spec(robot)
    return arm_kinematics(str(resolve_urdf(spec.urdf)), tuple(spec.joints), spec.end_effector)


def true_parameters(config: ArmScenarioConfig) -> np.ndarray:
    """Return the true rigid-body parameters of a recording's physical robot, before any payload.

    They depend on (robot, seed, perturbation) only: every recording — and the closed-loop plant of
    :mod:`semiparam_ros.sim.closed_loop` — of one robot and seed is the same physical robot.

    Args:
        config: The scenario (its ``robot``, ``seed`` and ``perturbation`` are read).

    Returns:
        Per body ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (kg, kg·m, kg·m²), the columns of
        :func:`arm_regressor`.
    """
    spec = arm_spec(config.robot)
    params_urdf = arm_regressor(spec).urdf_parameters()
    if config.perturbation is None:
        return params_urdf.copy()
    robot_rng = np.random.default_rng([int(config.seed), zlib.crc32(spec.name.encode())])
    return perturb_parameters(params_urdf, config.perturbation, robot_rng)


@dataclass(frozen=True)
class JointTorqueMeasurement:
    """An arm's joint torque sensors (a :class:`~semiparam_ros.sim.recording.MeasurementModel`).

    The reading is ``rigid + friction(q̇, q̈) − Jᵀ F`` (viscous and Coulomb friction, offsets, armature;
    a contact force F at the end effector) plus white noise per joint drawn from ``rng``.

    Args:
        kin: The arm's kinematics (the end effector's Jacobian for contacts).
        end_effector: The frame contacts act at.
        friction: The joints' friction, offsets and armature.
        noise_std: Noise standard deviation per joint [N·m].
    """

    kin: ArmKinematics
    end_effector: str
    friction: JointFriction
    noise_std: np.ndarray
    output: OutputKind = OutputKind.JOINT_TORQUES

    def measure(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, t: np.ndarray, rigid: np.ndarray,
                force: np.ndarray | None, rng: np.random.Generator) -> Measurement:
        """See :meth:`semiparam_ros.sim.recording.MeasurementModel.measure` (joint torques in N·m)."""
        count, n = rigid.shape
        tau_f = self.friction.torques(dq, ddq)
        contact_wrench = np.zeros((count, 6))
        external = np.zeros((count, n))
        if force is not None:
            for i in np.flatnonzero(np.any(force != 0.0, axis=1)):
                _, J = self.kin.position_jacobian(q[i])
                external[i] = -(J.T @ force[i])
                ((R, _p),) = self.kin.frame_poses(q[i], [self.end_effector])
                contact_wrench[i, :3] = R.T @ force[i]
        truth = rigid + tau_f + external
        noise = self.noise_std * rng.standard_normal((count, n))
        return Measurement(truth, truth + noise, noise, tau_f, external, contact_wrench)


def simulate_arm(config: ArmScenarioConfig) -> ArmRecording:
    """Simulate one arm recording (module docstring).

    Args:
        config: The scenario.

    Returns:
        The stamped true and measured signals.

    Raises:
        ValueError: If the robot's URDF cannot be loaded or the excitation leaves the joint limits.
    """
    spec = arm_spec(config.robot)
    reg = arm_regressor(spec)
    kin = _kinematics(spec)
    # Physical robot: (robot, seed) → true_parameters. Recording: (seed, name) → trajectory, noise, contacts.
    rng_traj, rng_joint, rng_torque, rng_contact = recording_seeds(config.seed, config.name)

    window = np.asarray(spec.position_window, dtype=np.float64)
    traj = multisine(
        window[:, 0],
        window[:, 1],
        seed=int(rng_traj.integers(2**31)),
        base_period=spec.base_period,
        max_velocity=spec.max_velocity,
        max_acceleration=spec.max_acceleration,
    ) if config.trajectory is None else config.trajectory
    count = round(config.duration * config.rate)
    stamps = sample_stamps(config.start_ns, count, config.rate)
    t = (stamps - config.start_ns) * 1e-9
    q, dq, ddq = traj.evaluate(t)
    lower, upper = reg.position_limits()
    margin = float(min(np.min(q - lower), np.min(upper - q)))
    if margin < 0.0:
        raise ValueError(f"the excitation leaves the joint limits by {-margin:.3g} rad")

    params_urdf = reg.urdf_parameters()
    params_before = true_parameters(config)
    pickup = config.pickup_time
    params_after, payload_info = add_payload(reg, params_before, frame=spec.end_effector,
                                             mass=config.payload_mass, pickup_s=pickup,
                                             start_ns=config.start_ns, point_in_frame=spec.payload_point)
    after = np.zeros(count, dtype=bool) if pickup is None else t >= pickup
    rigid = rigid_outputs(reg, q, dq, ddq, after, params_before, params_after, chunk=2000)

    friction = config.true_friction()
    if spec.ft_sensor is not None and config.contacts is not None:
        raise ValueError("contacts are simulated for joint torques only: no contacts with an F/T sensor")
    wrench = None if spec.ft_sensor is None else sensor_wrench(config, spec, q, dq, ddq, after)
    episodes, force = draw_contacts(config.contacts, config.duration, t, rng_contact)
    sensors = JointTorqueMeasurement(kin, spec.end_effector, friction,
                                     config.noise_scale * np.asarray(spec.torque_noise_std))
    reading = sensors.measure(q, dq, ddq, t, rigid, force, rng_torque)
    tau_f, truth, measured, noise = reading.non_rigid, reading.true, reading.measured, reading.noise
    external, contact_wrench = reading.external, reading.contact_wrench
    q_meas = q + config.noise_scale * spec.position_noise_std * rng_joint.standard_normal(q.shape)
    dq_meas = dq + config.noise_scale * spec.velocity_noise_std * rng_joint.standard_normal(dq.shape)

    info: dict[str, Any] = {
        "name": config.name,
        "robot": spec.as_dict(),
        "output": (OutputKind.JOINT_TORQUES if wrench is None else OutputKind.WRENCH).value,
        "ft_sensor": None if wrench is None else {
            "frame": wrench.frame, "offset_N_Nm": wrench.offset.tolist(),
            "noise": "white, 1 % of each axis' RMS (times the noise scale)",
            "model": "the wrench of the bodies beyond the sensor, their URDF parameters perturbed as the "
                     "arm's, the payload included after the pickup"},
        "seed": int(config.seed),
        "duration_s": float(config.duration),
        "start_stamp_ns": int(config.start_ns),
        InputKind.JOINT_STATES.value: {"rate_hz": float(config.rate), "count": int(count)},
        "joints": list(spec.joints),
        "trajectory": {
            "type": "multisine" if config.trajectory is None else "given (Fourier series)",
            "base_period_s": traj.period,
            "harmonics": [int(k) for k in np.flatnonzero(np.any(traj.cos_coef != 0, axis=1)) + 1],
            "position_window_rad": [list(w) for w in spec.position_window],
            "max_velocity_rad_per_s": spec.max_velocity,
            "max_acceleration_rad_per_s2": spec.max_acceleration,
        },
        "true_parameters": {
            "body_names": list(reg.body_names),
            "layout": "per body [m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] about the body frame "
            "origin (kg, kg m, kg m^2)",
            "perturbation": None if config.perturbation is None else config.perturbation.as_dict(),
            "urdf": [float(v) for v in params_urdf],
            "before_payload": [float(v) for v in params_before],
            "after_payload": [float(v) for v in params_after],
            "base_names": list(reg.base_parameter_names),
            "base_urdf": [float(v) for v in reg.to_base(params_urdf)],
            "base_before_payload": [float(v) for v in reg.to_base(params_before)],
            "base_after_payload": [float(v) for v in reg.to_base(params_after)],
        },
        "friction": friction.as_dict(),
        "noise": {
            "torque_std_Nm": [config.noise_scale * v for v in spec.torque_noise_std],
            "position_std_rad": config.noise_scale * spec.position_noise_std,
            "velocity_std_rad_per_s": config.noise_scale * spec.velocity_noise_std,
        },
        "payload": payload_info,
        "contacts": None if config.contacts is None else contacts_info(
            config.contacts, spec.end_effector, "force the environment applies to the robot at the frame "
            "origin; direction fixed in the base frame during an episode; measured torques change by -J^T F",
            episodes),
        "measured_rms_Nm": {
            "rigid": column_rms(rigid),
            "friction": column_rms(tau_f),
            "external": column_rms(external),
            "noise": column_rms(noise),
        },
        "limits": limits_info(q, dq, ddq, lower, upper, margin),
    }
    return ArmRecording(
        config=config,
        robot=spec,
        joint_names=spec.joints,
        stamps=stamps,
        q=q,
        dq=dq,
        ddq=ddq,
        q_measured=q_meas,
        dq_measured=dq_meas,
        rigid_torques=rigid,
        friction_torques=tau_f,
        external_torques=external,
        true_torques=truth,
        measured_torques=measured,
        contact_force=force,
        contact_wrench=contact_wrench,
        parameters_urdf=params_urdf,
        parameters_before=params_before,
        parameters_after=params_after,
        contact_episodes=episodes,
        info=info,
        wrench=wrench,
    )
