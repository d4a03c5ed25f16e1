"""What a real F/T sensor reads beyond the rigid-body wrench: cables, friction, calibration, drift, noise.

All wrenches are ``[fx, fy, fz, tx, ty, tz]`` (N, N·m) in the sensor frame ``r_arm_ft_sensor`` (the
``r_upper_arm`` link frame), torques about the sensor origin, sign as the sensor reads them: the wrench the
distal subtree exerts on the proximal link. A force ``F`` that an external body applies to the distal
subtree at a point ``a`` therefore adds ``[F, a × F]`` to the reading.

The measurement model, applied at every wrench stamp t (s from the start of the bag):

    w_true(t)  = Φ(q, q̇, q̈) π(t)  +  Σ_cables [F_c, a_c × F_c]
    w_meas(t)  = (I + E) w_true(t)  +  o  +  d(t)  +  ε(t)

1. **Harness cables** (``cables``): two cable bundles run from anchors on the chest (fixed in the ``chest``
   frame, proximal to the sensor) to anchors on the upper arm (beyond the sensor) and on the forearm
   (crossing the elbow). Each pulls its distal anchor towards its chest anchor with the tension
   ``T = T_ref·exp((L − L_ref)/ℓ) + F_c·tanh(L̇/v₀) + b·L̇``: an elastic, exponentially stiffening term of
   the cable length L (m, a nonlinear function of the shoulder and elbow angles) plus the friction of the
   cable sliding in its sheath (smooth Coulomb + viscous in the sliding speed L̇, m/s). Cables entirely
   inside the distal subtree (or joint friction at the elbow) are internal to it and are not seen.
2. **Calibration error** ``E`` (a fixed 6×6 matrix, a few % on the diagonal blocks, small cross-talk),
   applied to the whole true wrench. A learner with the rigid-body prediction ŷ among its inputs can
   learn it; a rigid-body model can only partly absorb it.
3. **Constant offset** ``o`` and **thermal drift** ``d(t) = d_∞ (1 − exp(−t/τ))`` (τ in minutes).
4. **Gaussian noise** ε with standard deviations ``force_noise_std`` (N) and ``torque_noise_std`` (N·m),
   independent per component and sample.

**Calibration of the magnitudes.** :data:`REFERENCE_EFFECTS` lists plausible reference magnitudes (cable
tensions of 2.1 and 1.7 N, sheath friction 0.65 and 0.4 N, bending stiffness 0.35 N·m/rad, 2 % calibration
error, offsets ≤ 0.9 N). The paper's own measure of "how much the rigid-body model cannot explain" is its
P model in the XY→XZ protocol (trained on all XY samples, tested with updates on 10 parts of XZ): ≈2 N and
≈0.4 N·m at regime. With the reference magnitudes our P stayed at 3.2 N and 0.65 N·m, because the harness
acts differently in the two planes and the parameters fitted on XY absorb XY-specific effects. All
non-rigid effects are therefore scaled by :data:`CALIBRATED_EFFECTS_SCALE` = 0.65 in
:data:`DEFAULT_EFFECTS`, which gives P 2.09 N and 0.415 N·m in that protocol (noise unchanged). The scale
was chosen on P alone — the learners being compared (NP, SP) played no part in it.

Default magnitudes (:data:`DEFAULT_EFFECTS`; component-averaged RMS — the mean over fx, fy, fz (tx, ty,
tz) of each component's RMS, as the paper's error metric — over a 60 s bag at 0.6 m/s; also in
:data:`NOMINAL_RMS` and ``bags/README.md``, checked by ``test/sim/test_simulate.py``):

=========== ================================ ===================================================
trajectory  non-rigid part (all effects)     left by a rigid-body least-squares fit of that bag
=========== ================================ ===================================================
xy circle   2.3 N, 0.36 N·m                  1.7 N, 0.15 N·m
xz circle   1.35 N, 0.32 N·m                 1.2 N, 0.25 N·m
multi-sine  3.1 N, 0.13 N·m                  2.5 N, 0.06 N·m
=========== ================================ ===================================================

Noise: 0.3 N and 0.03 N·m on the wrench; 1e-4 rad (position) and 2e-3 rad/s (velocity) on the joints.
Every magnitude scales with :meth:`EffectParameters.scaled` (``simulate --effects-scale/--noise-scale``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pinocchio as pin

from semiparam_ros.core.config import ICUB_RIGHT_ARM
from semiparam_ros.sim.ik import ArmKinematics

__all__ = [
    "CALIBRATED_EFFECTS_SCALE",
    "DEFAULT_EFFECTS",
    "NOMINAL_RMS",
    "REFERENCE_EFFECTS",
    "SENSOR_FRAME",
    "BendingParameters",
    "CableParameters",
    "EffectParameters",
    "bending_moment",
    "cable_lengths",
    "cable_wrench",
    "harness_wrench",
    "sensor_reading",
]

#: The F/T sensor frame of the iCub right arm (the ``r_upper_arm`` link frame): the estimator's iCub.
SENSOR_FRAME: str = ICUB_RIGHT_ARM["robot.ft_sensor"]
_CHEST_FRAME = "chest"


def _vec(values: object, shape: tuple[int, ...], what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64).reshape(shape)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be finite")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class CableParameters:
    """One harness cable from the chest to a link beyond the sensor.

    Attributes:
        name: Label used in ``scenario.yaml``.
        chest_anchor: Anchor on the chest, in the ``chest`` link frame (m).
        distal_frame: URDF frame of the distal anchor (a link beyond the sensor).
        distal_anchor: Anchor in ``distal_frame`` (m).
        tension_ref: Elastic tension T_ref at the reference length (N).
        length_ref: Reference length L_ref (m).
        length_scale: Stiffening length ℓ (m): the tension grows by e per ℓ of extension.
        coulomb: Sheath Coulomb friction F_c (N).
        viscous: Sheath viscous friction b (N·s/m).
        smoothing: Velocity v₀ of the tanh that smooths the Coulomb term (m/s).
    """

    name: str
    chest_anchor: np.ndarray
    distal_frame: str
    distal_anchor: np.ndarray
    tension_ref: float
    length_ref: float
    length_scale: float
    coulomb: float
    viscous: float
    smoothing: float = 0.005

    def __post_init__(self) -> None:
        object.__setattr__(self, "chest_anchor", _vec(self.chest_anchor, (3,), "chest_anchor"))
        object.__setattr__(self, "distal_anchor", _vec(self.distal_anchor, (3,), "distal_anchor"))
        for name in ("tension_ref", "coulomb", "viscous"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"cable {self.name}: {name} must be finite and >= 0, got {value!r}")
        for name in ("length_ref", "length_scale", "smoothing"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"cable {self.name}: {name} must be positive, got {value!r}")

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python description (for ``scenario.yaml``)."""
        return {
            "name": self.name,
            "chest_anchor_m": [float(v) for v in self.chest_anchor],
            "distal_frame": self.distal_frame,
            "distal_anchor_m": [float(v) for v in self.distal_anchor],
            "tension_ref_N": float(self.tension_ref),
            "length_ref_m": float(self.length_ref),
            "length_scale_m": float(self.length_scale),
            "sheath_coulomb_N": float(self.coulomb),
            "sheath_viscous_Ns_per_m": float(self.viscous),
            "sheath_smoothing_m_per_s": float(self.smoothing),
        }


@dataclass(frozen=True)
class BendingParameters:
    """Elastic bending moment of the harness bundle crossing the shoulder.

    The bundle resists the rotation of the upper arm relative to the chest away from its rest orientation
    (the sensor orientation at the joint positions ``rest_posture``): with θ the rotation vector of that
    rotation (rad, sensor frame), the distal subtree receives the moment ``−k·(1 + |θ|²/θ₀²)·θ``
    (N·m) — linear for small rotations, stiffening for large ones.

    Attributes:
        stiffness: k (N·m/rad).
        stiffening_angle: θ₀ (rad).
        rest_posture: Arm joint positions (rad) of the rest orientation.
    """

    stiffness: float = 0.0
    stiffening_angle: float = 1.0
    rest_posture: tuple[float, ...] = (0.0, 0.3, 0.0, 0.8)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.stiffness) and self.stiffness >= 0):
            raise ValueError(f"bending stiffness must be finite and >= 0, got {self.stiffness!r}")
        if not (np.isfinite(self.stiffening_angle) and self.stiffening_angle > 0):
            raise ValueError(f"stiffening_angle must be positive, got {self.stiffening_angle!r}")
        object.__setattr__(self, "rest_posture", tuple(float(v) for v in self.rest_posture))

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python description (for ``scenario.yaml``)."""
        return {
            "stiffness_Nm_per_rad": float(self.stiffness),
            "stiffening_angle_rad": float(self.stiffening_angle),
            "rest_posture_rad": list(self.rest_posture),
        }


def _default_calibration() -> np.ndarray:
    """Return the fixed calibration error E of the default sensor (seeded: the same everywhere)."""
    rng = np.random.default_rng(20160516)
    E = np.zeros((6, 6))
    E[:3, :3] = rng.normal(0.0, 0.02, (3, 3))  # force gain/cross-talk, ≈2 %
    E[3:, 3:] = rng.normal(0.0, 0.02, (3, 3))  # torque gain/cross-talk, ≈2 %
    E[3:, :3] = rng.normal(0.0, 0.002, (3, 3))  # force → torque, m (≈2 mm lever)
    E[:3, 3:] = rng.normal(0.0, 0.1, (3, 3))  # torque → force, 1/m
    return E


@dataclass(frozen=True)
class EffectParameters:
    """Every non-rigid effect and noise level of the simulated sensor and encoders, in one place.

    Attributes:
        cables: Harness cables crossing the sensor.
        bending: Elastic bending moment of the harness at the shoulder.
        calibration: Calibration error E (6×6), the sensor reads (I + E)·w.
        offset: Constant offset o (6,) (N, N·m).
        drift: Final value d_∞ (6,) of the thermal drift (N, N·m).
        drift_time_constant: τ of the drift (s).
        force_noise_std: σ of the force noise (N).
        torque_noise_std: σ of the torque noise (N·m).
        position_noise_std: σ of the joint position noise (rad).
        velocity_noise_std: σ of the joint velocity noise (rad/s).
    """

    cables: tuple[CableParameters, ...]
    bending: BendingParameters = field(default_factory=BendingParameters)
    calibration: np.ndarray = field(default_factory=_default_calibration)
    offset: np.ndarray = field(default_factory=lambda: np.array([0.9, -0.6, 0.7, 0.05, -0.07, 0.04]))
    drift: np.ndarray = field(default_factory=lambda: np.array([0.5, 0.3, -0.4, 0.03, 0.02, -0.03]))
    drift_time_constant: float = 300.0
    force_noise_std: float = 0.3
    torque_noise_std: float = 0.03
    position_noise_std: float = 1e-4
    velocity_noise_std: float = 2e-3

    def __post_init__(self) -> None:
        object.__setattr__(self, "cables", tuple(self.cables))
        object.__setattr__(self, "calibration", _vec(self.calibration, (6, 6), "calibration"))
        object.__setattr__(self, "offset", _vec(self.offset, (6,), "offset"))
        object.__setattr__(self, "drift", _vec(self.drift, (6,), "drift"))
        if not (np.isfinite(self.drift_time_constant) and self.drift_time_constant > 0):
            raise ValueError(f"drift_time_constant must be positive (s), got {self.drift_time_constant!r}")
        for name in ("force_noise_std", "torque_noise_std", "position_noise_std", "velocity_noise_std"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")

    def scaled(self, effects: float = 1.0, noise: float = 1.0) -> EffectParameters:
        """Copy with every non-rigid effect multiplied by ``effects`` and every noise σ by ``noise``.

        Args:
            effects: Factor on cable tensions and friction, E, o and d_∞ (0 removes them).
            noise: Factor on the four noise standard deviations (0 removes noise).

        Returns:
            The scaled parameters.

        Raises:
            ValueError: If a factor is negative or not finite.
        """
        for name, value in (("effects", effects), ("noise", noise)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} scale must be finite and >= 0, got {value!r}")
        cables = tuple(
            replace(
                c,
                tension_ref=c.tension_ref * effects,
                coulomb=c.coulomb * effects,
                viscous=c.viscous * effects,
            )
            for c in self.cables
        )
        return replace(
            self,
            cables=cables,
            bending=replace(self.bending, stiffness=self.bending.stiffness * effects),
            calibration=self.calibration * effects,
            offset=self.offset * effects,
            drift=self.drift * effects,
            force_noise_std=self.force_noise_std * noise,
            torque_noise_std=self.torque_noise_std * noise,
            position_noise_std=self.position_noise_std * noise,
            velocity_noise_std=self.velocity_noise_std * noise,
        )

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python description with units in the keys (for ``scenario.yaml``)."""
        return {
            "cables": [c.as_dict() for c in self.cables],
            "harness_bending": self.bending.as_dict(),
            "calibration_error_E": [[float(v) for v in row] for row in self.calibration],
            "offset_N_Nm": [float(v) for v in self.offset],
            "drift_final_N_Nm": [float(v) for v in self.drift],
            "drift_time_constant_s": float(self.drift_time_constant),
            "force_noise_std_N": float(self.force_noise_std),
            "torque_noise_std_Nm": float(self.torque_noise_std),
            "joint_position_noise_std_rad": float(self.position_noise_std),
            "joint_velocity_noise_std_rad_per_s": float(self.velocity_noise_std),
        }


#: Component-averaged RMS (force N, torque N·m) of the default effects on 60 s bags at 0.6 m/s (with the
#: default trajectory variability): ``non_rigid`` = true reading − rigid-body wrench; ``unexplained`` =
#: what a least-squares fit of the base parameters to the noiseless reading leaves.
NOMINAL_RMS: dict[str, dict[str, tuple[float, float]]] = {
    "xy": {"non_rigid": (2.32, 0.359), "unexplained": (1.68, 0.154)},
    "xz": {"non_rigid": (1.35, 0.319), "unexplained": (1.20, 0.253)},
    "multisine": {"non_rigid": (3.13, 0.132), "unexplained": (2.52, 0.058)},
}

#: Reference magnitudes of the harness and sensor errors (before the calibration below): tensions, friction
#: and bending stiffness as listed, 2 % calibration error, the offset and drift of :class:`EffectParameters`.
REFERENCE_EFFECTS = EffectParameters(
    cables=(
        CableParameters(
            name="upper_arm_harness",
            chest_anchor=(-0.04, 0.10, 0.05),
            distal_frame="r_upper_arm",
            distal_anchor=(0.03, 0.0, 0.07),
            tension_ref=2.1,
            length_ref=0.18,
            length_scale=0.04,
            coulomb=0.65,
            viscous=3.1,
        ),
        CableParameters(
            name="forearm_harness",
            chest_anchor=(-0.03, 0.09, 0.07),
            distal_frame="r_forearm",
            distal_anchor=(0.0, -0.10, 0.02),
            tension_ref=1.7,
            length_ref=0.25,
            length_scale=0.05,
            coulomb=0.4,
            viscous=2.1,
        ),
    ),
    bending=BendingParameters(stiffness=0.35, stiffening_angle=1.0, rest_posture=(-0.85, 1.4, 0.45, 1.4)),
)

#: Factor on every non-rigid effect of :data:`REFERENCE_EFFECTS` (noise unchanged) that gives the paper's
#: parametric error in its protocol: a rigid-body model trained on the XY circles and tested (with updates)
#: on the XZ circles stays at ≈2.1 N and ≈0.41 N·m at regime (paper: ≈2 N, ≈0.4 N·m). With the reference
#: magnitudes it stayed at 3.2 N and 0.65 N·m.
CALIBRATED_EFFECTS_SCALE = 0.65

#: Default sensor and harness of the simulated iCub right arm (magnitudes in the module docstring).
DEFAULT_EFFECTS = REFERENCE_EFFECTS.scaled(CALIBRATED_EFFECTS_SCALE, 1.0)


def _anchor_positions(
    kin: ArmKinematics, q: np.ndarray, cables: Sequence[CableParameters]
) -> tuple[np.ndarray, np.ndarray]:
    """Chest and distal anchor positions of every cable in the sensor frame, for one configuration."""
    frames = [SENSOR_FRAME, _CHEST_FRAME, *(c.distal_frame for c in cables)]
    poses = kin.frame_poses(q, frames)
    Rs, ps = poses[0]
    Rc, pc = poses[1]
    chest = np.empty((len(cables), 3))
    distal = np.empty((len(cables), 3))
    for i, cable in enumerate(cables):
        Rd, pd = poses[2 + i]
        chest[i] = Rs.T @ (Rc @ cable.chest_anchor + pc - ps)
        distal[i] = Rs.T @ (Rd @ cable.distal_anchor + pd - ps)
    return chest, distal


def cable_lengths(kin: ArmKinematics, q: np.ndarray, cables: Sequence[CableParameters]) -> np.ndarray:
    """Length (m) of every cable, chest anchor to distal anchor, at each configuration.

    Args:
        kin: Arm kinematics (locked joints included).
        q: Joint positions (k, n) (rad).
        cables: The cables.

    Returns:
        (k, number of cables) lengths in m.
    """
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    out = np.empty((q.shape[0], len(cables)))
    for j, qj in enumerate(q):
        chest, distal = _anchor_positions(kin, qj, cables)
        out[j] = np.linalg.norm(chest - distal, axis=1)
    return out


def cable_wrench(
    kin: ArmKinematics,
    q: np.ndarray,
    dq: np.ndarray,
    cables: Sequence[CableParameters],
    *,
    eps: float = 1e-6,
) -> np.ndarray:
    """Return the wrench the harness cables add to the sensor reading (sensor frame).

    Each cable pulls its distal anchor a towards its chest anchor c with the tension T (module
    docstring); the sliding speed L̇ = dL/dt is the directional derivative of the length along q̇, taken by a
    central difference with step ``eps`` (s).

    Args:
        kin: Arm kinematics (with the same locked joints as the simulation).
        q: Joint positions (k, n) (rad).
        dq: Joint velocities (k, n) (rad/s).
        cables: The cables.
        eps: Time step of the central difference for L̇ (s).

    Returns:
        (k, 6) ``[fx, fy, fz, tx, ty, tz]`` in N and N·m.
    """
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    dq = np.atleast_2d(np.asarray(dq, dtype=np.float64))
    out = np.zeros((q.shape[0], 6))
    if not cables:
        return out
    for j in range(q.shape[0]):
        chest, distal = _anchor_positions(kin, q[j], cables)
        diff = chest - distal
        length = np.linalg.norm(diff, axis=1)
        plus = cable_lengths(kin, q[j] + eps * dq[j], cables)[0]
        minus = cable_lengths(kin, q[j] - eps * dq[j], cables)[0]
        rate = (plus - minus) / (2.0 * eps)
        for i, cable in enumerate(cables):
            tension = (
                cable.tension_ref * np.exp((length[i] - cable.length_ref) / cable.length_scale)
                + cable.coulomb * np.tanh(rate[i] / cable.smoothing)
                + cable.viscous * rate[i]
            )
            force = tension * diff[i] / length[i]
            out[j, :3] += force
            out[j, 3:] += np.cross(distal[i], force)
    return out


def bending_moment(kin: ArmKinematics, q: np.ndarray, bending: BendingParameters) -> np.ndarray:
    """Return the harness bending moment added to the sensor reading (sensor frame).

    Args:
        kin: Arm kinematics.
        q: Joint positions (k, n) (rad).
        bending: Bending parameters.

    Returns:
        (k, 3) moment in N·m (the force part of this effect is zero).
    """
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    out = np.zeros((q.shape[0], 3))
    if bending.stiffness == 0.0:
        return out
    (Rs0, _), (Rc0, _) = kin.frame_poses(np.asarray(bending.rest_posture), [SENSOR_FRAME, _CHEST_FRAME])
    rest = Rc0.T @ Rs0  # sensor orientation in the chest at rest
    for j, qj in enumerate(q):
        (Rs, _), (Rc, _) = kin.frame_poses(qj, [SENSOR_FRAME, _CHEST_FRAME])
        theta = pin.log3(rest.T @ (Rc.T @ Rs))  # rotation from rest, in the sensor frame
        angle2 = float(theta @ theta)
        out[j] = -bending.stiffness * (1.0 + angle2 / bending.stiffening_angle**2) * theta
    return out


def harness_wrench(kin: ArmKinematics, q: np.ndarray, dq: np.ndarray, params: EffectParameters) -> np.ndarray:
    """Everything the harness adds to the reading: cable tensions with sheath friction, bending moment.

    Args:
        kin: Arm kinematics.
        q: Joint positions (k, n) (rad).
        dq: Joint velocities (k, n) (rad/s).
        params: Effect parameters.

    Returns:
        (k, 6) wrench in N, N·m (sensor frame).
    """
    out = cable_wrench(kin, q, dq, params.cables)
    out[:, 3:] += bending_moment(kin, q, params.bending)
    return out


def sensor_reading(true_wrench: np.ndarray, t: np.ndarray, params: EffectParameters) -> np.ndarray:
    """Return the noiseless sensor output: calibration error, offset and drift applied to the true wrench.

    Args:
        true_wrench: (k, 6) wrench at the sensor (N, N·m), rigid body + cables.
        t: (k,) time since the start of the recording (s), for the drift.
        params: Effect parameters.

    Returns:
        (k, 6) ``(I + E) w + o + d_∞ (1 − exp(−t/τ))`` (N, N·m).
    """
    w = np.asarray(true_wrench, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64).reshape(-1, 1)
    drift = params.drift * (1.0 - np.exp(-t / params.drift_time_constant))
    return w + w @ params.calibration.T + params.offset + drift
