"""Synthetic recordings of the iCub right arm: trajectories, true and measured signals, as arrays.

A :class:`ScenarioConfig` describes one recording (trajectory, duration, stream rates, payload, effects,
seed); :func:`simulate` turns it into a :class:`SimulatedRecording` of stamped arrays, which
:mod:`semiparam_ros.sim.writer` writes as a rosbag2/MCAP bag. :func:`generate` does both for a preset.

Trajectories (joints ``r_shoulder_pitch, r_shoulder_roll, r_shoulder_yaw, r_elbow``; every other joint
locked — wrist, head and torso pitch/roll at 0, torso yaw as below):

* ``xy`` — the hand (``r_hand_dh_frame``) tracks a horizontal (transverse) circle in the root frame,
  centre (0.10, 0.17, 0.45) m, i.e. above the right shoulder with the arm raised; torso yaw locked at
  0.6 rad. Default radius 0.10 m and speed 0.6 m/s (period 1.05 s).
* ``xz`` — a vertical (sagittal) circle in the root frame, centre (−0.144, −0.205, 0.113) m, in front of
  the chest with the torso turned (torso yaw locked at −1.0 rad).
* ``multisine`` — a random multi-sine of the four joints inside their limits (torso yaw 0).

The circles are tracked by closed-loop inverse kinematics (:mod:`semiparam_ros.sim.ik`); the centres and
torso postures were chosen so that the whole circle stays ≥ 0.15 rad inside every joint limit with bounded
joint accelerations (≤ ≈17 rad/s²): with the wrist locked, the iCub arm's limits leave little room for a
10 cm circle, and a torso yaw (a rotation about the vertical, which changes neither the gravity direction
in the chest nor the sensor's dynamics) orients the arm towards the plane. The circle's position in the
root frame and the torso posture are part of each bag's ``scenario.yaml``.

Real circle tracking never repeats exactly; by default (:data:`DEFAULT_VARIABILITY`) the hand speed is
modulated slowly by ±15 % and the circle's centre and radius wander by ±1 cm (seeded slow signals with
periods of 4–40 s, see :class:`TrajectoryVariability`), which keeps ≥ 0.10 rad of clearance to every joint
limit. ``variability=None`` gives the exactly repeating nominal circle.

Time t is measured in seconds from the first joint-state stamp; the wrench stream starts
:data:`LEAD_IN_S` later and the joint states end :data:`LEAD_IN_S` after it, so the acceleration
estimator's warm-up costs no wrench. Every signal is evaluated at its own stamps, so ``q``, ``q̇``, ``q̈``
and the wrench are exactly consistent at every stamp.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from semiparam_ros.core.kinds import InputKind, OutputKind
from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.core.rigid_body.urdf import icub_urdf_path
from semiparam_ros.sim.contacts import (
    CONTACTS_DURATION_S,
    ContactEpisode,
)
from semiparam_ros.sim.effects import (
    DEFAULT_EFFECTS,
    SENSOR_FRAME,
    EffectParameters,
    harness_wrench,
    sensor_reading,
)
from semiparam_ros.sim.ik import ARM_JOINTS, ArmKinematics, ClikResult, clik_periodic_orbit
from semiparam_ros.sim.recording import (
    DEFAULT_START_NS,
    Measurement,
    RecordingConfig,
    add_payload,
    arm_kinematics,
    contacts_info,
    draw_contacts,
    limits_info,
    recording_seeds,
    regressor_of,
    rigid_outputs,
    sample_stamps,
    wrench_rms,
)
from semiparam_ros.sim.trajectories import (
    CartesianCircle,
    FourierTrajectory,
    ModulatedOrbit,
    SlowSignal,
    multisine,
)

__all__ = [
    "CIRCLES",
    "CONTACTS_DURATION_S",
    "DEFAULT_START_NS",
    "DEFAULT_VARIABILITY",
    "LEAD_IN_S",
    "OTHER_JOINTS",
    "PUBLISHED_JOINT_ORDER",
    "CircleSetup",
    "FTSensorMeasurement",
    "ScenarioConfig",
    "SimulatedRecording",
    "TrajectoryVariability",
    "hand_contact_wrenches",
    "simulate",
]

#: Joints published besides the four arm joints (locked; see ``SimulatedRecording.other_positions``).
OTHER_JOINTS: tuple[str, ...] = (
    "torso_pitch",
    "torso_roll",
    "torso_yaw",
    "neck_pitch",
    "neck_roll",
    "neck_yaw",
    "r_wrist_prosup",
    "r_wrist_pitch",
    "r_wrist_yaw",
)

#: Order of the names in the published ``JointState`` (deliberately not the configured order).
PUBLISHED_JOINT_ORDER: tuple[str, ...] = (
    "neck_pitch",
    "neck_roll",
    "neck_yaw",
    "torso_yaw",
    "torso_roll",
    "torso_pitch",
    "r_elbow",
    "r_shoulder_yaw",
    "r_shoulder_roll",
    "r_shoulder_pitch",
    "r_wrist_prosup",
    "r_wrist_pitch",
    "r_wrist_yaw",
)


_HAND_FRAME = "r_hand_dh_frame"


@dataclass(frozen=True)
class CircleSetup:
    """Where and how the hand draws a circle.

    Attributes:
        plane: ``"xy"`` or ``"xz"`` (root frame).
        centre: Circle centre in the root frame (m).
        torso_yaw: Locked torso yaw (rad).
        q_rest: Null-space rest posture of the four arm joints (rad).
        posture_gain: Null-space posture gain (1/s).
        limit_gain: Null-space joint-limit barrier gain (rad/s).
    """

    plane: str
    centre: tuple[float, float, float]
    torso_yaw: float
    q_rest: tuple[float, float, float, float]
    posture_gain: float
    limit_gain: float


#: The two circles of the paper (positions chosen as described in the module docstring).
CIRCLES: dict[str, CircleSetup] = {
    "xy": CircleSetup("xy", (0.10, 0.17, 0.45), 0.6, (-0.9, 2.35, -0.11, 1.39), 1.0, 0.1),
    "xz": CircleSetup("xz", (-0.144, -0.205, 0.113), -1.0, (-0.81, 0.51, 1.0, 1.46), 4.0, 0.0),
}


@dataclass(frozen=True)
class TrajectoryVariability:
    """Seeded, slow cycle-to-cycle variability of the circle scenarios (a real arm never repeats exactly).

    The iCub's Cartesian controller does not retrace its circle: the hand speed drifts around the commanded
    0.6 m/s and the drawn circle wanders by a few centimetres. The simulator reproduces this with slow
    random signals (:class:`~semiparam_ros.sim.trajectories.SlowSignal`, a sum of ``components`` sines with
    periods log-uniform in ``[min_period, max_period]``): the hand speed is ``v·(1 + speed·s(t))`` and the
    joint path is blended with the orbits of circles whose centre is shifted by ``centre`` (m) along each
    root-frame axis and whose radius is changed by ``radius`` (m), with weights in [−1, 1]
    (:class:`~semiparam_ros.sim.trajectories.ModulatedOrbit`; q, q̇, q̈ stay exactly consistent).

    Attributes:
        speed: Relative amplitude A of the speed modulation (0 ≤ A < 1).
        centre: Maximum displacement of the circle centre along each axis (m).
        radius: Maximum change of the radius (m).
        min_period: Shortest period of the slow signals (s).
        max_period: Longest period of the slow signals (s).
        components: Sines per slow signal.
    """

    speed: float = 0.15
    centre: float = 0.01
    radius: float = 0.01
    min_period: float = 4.0
    max_period: float = 40.0
    components: int = 4

    def __post_init__(self) -> None:
        for name in ("speed", "centre", "radius", "min_period", "max_period"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
                raise ValueError(f"variability {name} must be a number, got {value!r}")
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"variability {name} must be finite and >= 0, got {value!r}")
        if not self.speed < 0.5:
            raise ValueError(f"variability speed must be below 0.5, got {self.speed!r}")
        if not (0 < self.min_period <= self.max_period) or int(self.components) < 1:
            raise ValueError("variability needs 0 < min_period <= max_period and components >= 1")

    @property
    def active(self) -> bool:
        """Whether any variability is switched on."""
        return self.speed > 0 or self.centre > 0 or self.radius > 0

    def as_dict(self) -> dict[str, float]:
        """Plain-Python description with units in the keys (for ``scenario.yaml``)."""
        return {
            "speed_relative": float(self.speed),
            "centre_m": float(self.centre),
            "radius_m": float(self.radius),
            "min_period_s": float(self.min_period),
            "max_period_s": float(self.max_period),
            "components": int(self.components),
        }


#: Default variability of the circle scenarios (magnitudes and reasons in ``bags/README.md``).
DEFAULT_VARIABILITY = TrajectoryVariability()

#: Joint states start this long before the first wrench and end this long after the last (s), so that
#: the acceleration estimator's warm-up never costs a wrench sample (exactly ``duration·wrench_rate``
#: samples come out of the pipeline for estimator windows up to 2·LEAD_IN·joint_rate + 1 samples).
LEAD_IN_S = 0.2


@dataclass(frozen=True)
class ScenarioConfig(RecordingConfig):
    """One synthetic recording of the iCub arm's F/T sensor (the shared fields: :class:`RecordingConfig`).

    Attributes:
        name: Bag folder name (e.g. ``"icub_xy"``).
        trajectory: ``"xy"``, ``"xz"`` or ``"multisine"``.
        joint_rate: Joint-state rate (Hz).
        wrench_rate: Wrench rate (Hz).
        delay: The wrench is sampled ``delay`` s after the joint-state grid (may be negative; stamps are
            the true sampling instants of each stream).
        radius: Circle radius (m).
        speed: Hand speed on the circle (m/s).
        effects: Non-rigid effects and noise levels (already scaled).
        variability: Cycle-to-cycle variability of the circles (None or inactive: exact repetition).
        start_ns: First joint-state stamp (ns); the first wrench is ``LEAD_IN_S + delay`` later and the
            joint states continue ``LEAD_IN_S`` after the last wrench.
    """

    trajectory: str = "xy"
    joint_rate: float = 100.0
    wrench_rate: float = 100.0
    delay: float = 0.0
    radius: float = 0.10
    speed: float = 0.6
    effects: EffectParameters = field(default=DEFAULT_EFFECTS)
    variability: TrajectoryVariability | None = field(default=DEFAULT_VARIABILITY)

    def __post_init__(self) -> None:
        self.check_common()
        if self.trajectory not in ("xy", "xz", "multisine"):
            raise ValueError(f"trajectory must be 'xy', 'xz' or 'multisine', got {self.trajectory!r}")
        for attr in ("joint_rate", "wrench_rate", "radius", "speed"):
            value = getattr(self, attr)
            if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
                raise ValueError(f"{attr} must be a number, got {value!r}")
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{attr} must be a positive number, got {value!r}")
        if self.joint_rate > 10_000 or self.wrench_rate > 10_000:
            raise ValueError("rates above 10 kHz are not supported")
        if not (np.isfinite(self.delay) and abs(self.delay) < 1.0):
            raise ValueError(f"delay must be finite and below 1 s in magnitude, got {self.delay!r}")
        if int(self.start_ns) + min(0, round(self.delay * 1e9)) < 0:
            raise ValueError("start_ns + delay must be >= 0")
        if self.variability is not None and not isinstance(self.variability, TrajectoryVariability):
            raise ValueError("variability must be a TrajectoryVariability or None")

    def record(self, *, progress: Callable[[int], None] | None = None) -> SimulatedRecording:
        """Simulate this recording (:func:`simulate`): the F/T sensor's wrench.

        Args:
            progress: Called with the count of finished wrench samples.
        """
        return simulate(self, progress=progress)

    def progress_units(self) -> tuple[int, str]:
        """Return what the progress of simulating and writing counts: wrench samples and messages."""
        n_joint = round((self.duration + 2.0 * LEAD_IN_S) * self.joint_rate)
        n_wrench = round(self.duration * self.wrench_rate)
        return n_wrench + 2 * n_joint + (3 if self.contacts is None else 5) * n_wrench, "msg"


@dataclass(frozen=True)
class SimulatedRecording:
    """Stamped arrays of one synthetic recording (true and measured).

    Joint arrays are in the order of :data:`~semiparam_ros.sim.ik.ARM_JOINTS`; wrenches are
    ``[fx, fy, fz, tx, ty, tz]`` (N, N·m) in the sensor frame.

    Attributes:
        config: The scenario.
        joint_names: The four arm joints.
        joint_stamps: (N,) joint-state stamps (ns).
        q, dq, ddq: (N, 4) true positions, velocities, accelerations at the joint stamps (rad, rad/s, rad/s²).
        q_measured, dq_measured: (N, 4) noisy positions and velocities (rad, rad/s).
        other_positions: Positions of :data:`OTHER_JOINTS` (rad).
        wrench_stamps: (M,) wrench stamps (ns).
        rigid_wrench: (M, 6) rigid-body wrench Φπ(t) (payload included after the pickup).
        cable_wrench: (M, 6) harness cable wrench.
        true_wrench: (M, 6) the noiseless sensor output (calibration, offset and drift applied).
        measured_wrench: (M, 6) ``true_wrench`` plus noise.
        wrench_q, wrench_dq, wrench_ddq: (M, 4) true joint state at the wrench stamps.
        parameters_before, parameters_after: Full inertial parameters before and after the pickup.
        info: Scenario description for ``scenario.yaml`` (plain Python).
        contact_episodes: The contact episodes (empty without contacts).
        contact_wrench: (M, 6) applied contact force at the hand, ``[F, 0]`` (N) in the hand frame
            ``r_hand_dh_frame`` (about its origin, where it acts), or None without contacts.
        external_wrench: (M, 6) the contact's transmitted wrench at the sensor (N, N·m, sensor frame, before
            the sensor's calibration error), included in ``true_wrench``; None without contacts.
    """

    config: ScenarioConfig
    joint_names: tuple[str, ...]
    joint_stamps: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    q_measured: np.ndarray
    dq_measured: np.ndarray
    other_positions: dict[str, float]
    wrench_stamps: np.ndarray
    rigid_wrench: np.ndarray
    cable_wrench: np.ndarray
    true_wrench: np.ndarray
    measured_wrench: np.ndarray
    wrench_q: np.ndarray
    wrench_dq: np.ndarray
    wrench_ddq: np.ndarray
    parameters_before: np.ndarray
    parameters_after: np.ndarray
    info: dict[str, Any]
    contact_episodes: tuple[ContactEpisode, ...] = ()
    contact_wrench: np.ndarray | None = None
    external_wrench: np.ndarray | None = None


def _kinematics(torso_yaw: float) -> ArmKinematics:
    return arm_kinematics(str(icub_urdf_path()), ARM_JOINTS, _HAND_FRAME, (("torso_yaw", torso_yaw),))


def _regressor(torso_yaw: float) -> RigidBodyRegressor:
    return regressor_of(str(icub_urdf_path()), ARM_JOINTS, output=OutputKind.WRENCH, ft_sensor=SENSOR_FRAME,
                        locked=(("torso_yaw", torso_yaw),))


@lru_cache(maxsize=16)
def _circle_orbit(plane: str, radius: float, speed: float) -> tuple[ClikResult, CartesianCircle]:
    setup = CIRCLES[plane]
    circle = CartesianCircle(np.array(setup.centre), radius, speed, plane)
    result = clik_periodic_orbit(
        _kinematics(setup.torso_yaw),
        circle,
        np.array(setup.q_rest),
        posture_gain=setup.posture_gain,
        limit_gain=setup.limit_gain,
    )
    return result, circle


def _variant_orbits(
    plane: str, radius: float, speed: float, var: TrajectoryVariability
) -> tuple[tuple[FourierTrajectory, ...], list[dict[str, Any]]]:
    """Orbits of the displaced circles (centre along x, y, z; radius) and their description."""
    setup = CIRCLES[plane]
    centre = np.array(setup.centre)
    displaced: list[tuple[str, np.ndarray, float]] = []
    if var.centre > 0:
        for axis, name in enumerate("xyz"):
            shifted = centre.copy()
            shifted[axis] += var.centre
            displaced.append((f"centre_{name}", shifted, radius))
    if var.radius > 0:
        displaced.append(("radius", centre, radius + var.radius))
    orbits, info = [], []
    for name, c, r in displaced:
        result = _displaced_orbit(plane, tuple(float(v) for v in c), float(r), float(speed))
        orbits.append(result.trajectory)
        info.append(
            {
                "variant": name,
                "centre_m": [float(v) for v in c],
                "radius_m": float(r),
                "min_joint_limit_margin_rad": result.min_limit_margin,
            }
        )
    return tuple(orbits), info


@lru_cache(maxsize=32)
def _displaced_orbit(
    plane: str, centre: tuple[float, float, float], radius: float, speed: float
) -> ClikResult:
    setup = CIRCLES[plane]
    return clik_periodic_orbit(
        _kinematics(setup.torso_yaw),
        CartesianCircle(np.array(centre), radius, speed, plane),
        np.array(setup.q_rest),
        posture_gain=setup.posture_gain,
        limit_gain=setup.limit_gain,
    )


def _trajectory(
    config: ScenarioConfig, rng: np.random.Generator
) -> tuple[FourierTrajectory | ModulatedOrbit, float, dict[str, Any]]:
    """Return the joint trajectory, the locked torso yaw and its description."""
    if config.trajectory == "multisine":
        kin = _kinematics(0.0)
        traj = multisine(kin.lower, kin.upper, seed=int(rng.integers(2**31)))
        return (
            traj,
            0.0,
            {
                "type": "multisine",
                "base_period_s": traj.period,
                "harmonics": [int(k) for k in np.flatnonzero(np.any(traj.cos_coef != 0, axis=1)) + 1],
            },
        )
    setup = CIRCLES[config.trajectory]
    result, circle = _circle_orbit(config.trajectory, float(config.radius), float(config.speed))
    traj: FourierTrajectory | ModulatedOrbit = result.trajectory
    var = config.variability
    var_info: dict[str, Any] | None = None
    if var is not None and var.active:
        variants, variants_info = _variant_orbits(
            config.trajectory, float(config.radius), float(config.speed), var
        )

        def draw() -> SlowSignal:
            return SlowSignal.random(
                rng, components=int(var.components), min_period=var.min_period, max_period=var.max_period
            )

        speed_signal = draw()
        weights = tuple(draw() for _ in variants)
        traj = ModulatedOrbit(result.trajectory, variants, weights, speed_signal, float(var.speed))
        var_info = {
            **var.as_dict(),
            "speed_signal": speed_signal.as_dict(),
            "variants": [
                {**v, "weight_signal": w.as_dict()} for v, w in zip(variants_info, weights, strict=True)
            ],
        }
    return (
        traj,
        setup.torso_yaw,
        {
            "type": "circle",
            "plane": setup.plane,
            "frame": "root_link",
            "end_effector": _HAND_FRAME,
            "centre_m": list(setup.centre),
            "radius_m": float(config.radius),
            "speed_m_per_s": float(config.speed),
            "period_s": circle.period,
            "clik": {
                "q_rest_rad": list(setup.q_rest),
                "posture_gain_per_s": setup.posture_gain,
                "limit_gain_rad_per_s": setup.limit_gain,
                "periodicity_error_rad": result.periodicity_error,
                "fourier_harmonics": result.trajectory.n_harmonics,
                "fourier_fit_error_rad": result.fit_error,
                "hand_tracking_error_m": result.tracking_error,
                "min_joint_limit_margin_rad": result.min_limit_margin,
            },
            "variability": var_info,
        },
    )


def simulate(config: ScenarioConfig, *, progress: Callable[[int], None] | None = None) -> SimulatedRecording:
    """Simulate one recording.

    Args:
        config: The scenario.
        progress: Optional callback, called with a count of finished wrench samples.

    Returns:
        The stamped true and measured signals.

    Raises:
        ValueError: If the circle cannot be tracked within the joint limits (radius/speed too large).
    """
    rng_traj, rng_joint, rng_wrench, rng_contact = recording_seeds(config.seed, config.name)
    traj, torso_yaw, traj_info = _trajectory(config, rng_traj)
    kin = _kinematics(torso_yaw)
    reg = _regressor(torso_yaw)
    fx = config.effects

    n_joint = round((config.duration + 2.0 * LEAD_IN_S) * config.joint_rate)
    n_wrench = round(config.duration * config.wrench_rate)
    delay_ns = round((LEAD_IN_S + config.delay) * 1e9)
    joint_stamps = sample_stamps(config.start_ns, n_joint, config.joint_rate)
    wrench_stamps = sample_stamps(config.start_ns, n_wrench, config.wrench_rate, delay_ns)
    t_joint = (joint_stamps - config.start_ns) * 1e-9
    t_wrench = (wrench_stamps - config.start_ns) * 1e-9

    q, dq, ddq = traj.evaluate(t_joint)
    margin = min(float(np.min(q - kin.lower)), float(np.min(kin.upper - q)))
    if margin < 0.02:
        raise ValueError(
            f"the trajectory comes within {margin:.3f} rad of a joint limit (need 0.02): reduce the radius, "
            "speed or variability"
        )
    q_meas = q + fx.position_noise_std * rng_joint.standard_normal(q.shape)
    dq_meas = dq + fx.velocity_noise_std * rng_joint.standard_normal(dq.shape)

    wq, wdq, wddq = traj.evaluate(t_wrench)
    params_before = reg.urdf_parameters()
    pickup = config.pickup_time
    params_after, payload_info = add_payload(reg, params_before, frame=_HAND_FRAME, mass=config.payload_mass,
                                             pickup_s=pickup, start_ns=config.start_ns)
    after = np.zeros(n_wrench, dtype=bool) if pickup is None else t_wrench >= pickup
    rigid = rigid_outputs(reg, wq, wdq, wddq, after, params_before, params_after, chunk=500,
                          progress=progress)
    contact_info: dict[str, Any] | None = None
    episodes, force = draw_contacts(config.contacts, config.duration, t_wrench, rng_contact)
    if config.contacts is not None:
        contact_info = contacts_info(
            config.contacts, _HAND_FRAME, "force the environment applies to the hand at the frame origin; "
            "direction fixed in the root frame during an episode", episodes)
    sensor = FTSensorMeasurement(kin, fx)
    reading = sensor.measure(wq, wdq, wddq, t_wrench, rigid,
                             force if config.contacts is not None else None, rng_wrench)
    cables, truth, noise, measured = reading.non_rigid, reading.true, reading.noise, reading.measured

    other = dict.fromkeys(OTHER_JOINTS, 0.0)
    other.update({k: v for k, v in kin.locked_positions.items() if k in other})
    info: dict[str, Any] = {
        "name": config.name,
        "seed": int(config.seed),
        "duration_s": float(config.duration),
        "start_stamp_ns": int(config.start_ns),
        InputKind.JOINT_STATES.value: {"rate_hz": float(config.joint_rate), "count": n_joint},
        InputKind.WRENCH.value: {
            "rate_hz": float(config.wrench_rate),
            "count": n_wrench,
            "delay_s": float(config.delay),
            "lead_in_s": LEAD_IN_S,
        },
        "joints": list(ARM_JOINTS),
        "locked_joints_rad": {k: float(v) for k, v in other.items()},
        "trajectory": traj_info,
        "payload": payload_info,
        "effects": fx.as_dict(),
        "measured_rms": {
            "non_rigid_N_Nm": wrench_rms(truth - rigid),
            "harness_N_Nm": wrench_rms(cables),
            "noise_N_Nm": wrench_rms(noise),
            "rigid_N_Nm": wrench_rms(rigid),
        },
        "limits": limits_info(q, dq, ddq, kin.lower, kin.upper, margin),
    }
    if contact_info is not None:
        info["contacts"] = contact_info
    return SimulatedRecording(
        config=config,
        joint_names=ARM_JOINTS,
        joint_stamps=joint_stamps,
        q=q,
        dq=dq,
        ddq=ddq,
        q_measured=q_meas,
        dq_measured=dq_meas,
        other_positions=other,
        wrench_stamps=wrench_stamps,
        rigid_wrench=rigid,
        cable_wrench=cables,
        true_wrench=truth,
        measured_wrench=measured,
        wrench_q=wq,
        wrench_dq=wdq,
        wrench_ddq=wddq,
        parameters_before=params_before,
        parameters_after=params_after,
        info=info,
        contact_episodes=episodes,
        contact_wrench=reading.contact_wrench,
        external_wrench=reading.external,
    )


@dataclass(frozen=True)
class FTSensorMeasurement:
    """The iCub's six-axis F/T sensor in the upper arm.

    A :class:`~semiparam_ros.sim.recording.MeasurementModel`.
    The reading is ``sensor_reading(rigid + harness + contacts)`` (calibration, offset and drift of
    :mod:`semiparam_ros.sim.effects`) plus white noise, force then torque drawn from ``rng``.

    Args:
        kin: The arm's kinematics (harness and hand contacts).
        effects: The sensor's and harness's effect parameters.
    """

    kin: ArmKinematics
    effects: EffectParameters
    output: OutputKind = OutputKind.WRENCH

    def measure(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, t: np.ndarray, rigid: np.ndarray,
                force: np.ndarray | None, rng: np.random.Generator) -> Measurement:
        """See :meth:`~semiparam_ros.sim.recording.MeasurementModel.measure` (N, N·m, sensor frame)."""
        fx = self.effects
        cables = harness_wrench(self.kin, q, dq, fx)
        contact_w = external = None
        if force is not None:
            contact_w, external = hand_contact_wrenches(self.kin, q, force)
        truth = sensor_reading(rigid + cables if external is None else rigid + cables + external, t, fx)
        n = len(t)
        noise = np.empty((n, 6))
        noise[:, :3] = fx.force_noise_std * rng.standard_normal((n, 3))
        noise[:, 3:] = fx.torque_noise_std * rng.standard_normal((n, 3))
        return Measurement(truth, truth + noise, noise, cables, external, contact_w)


def hand_contact_wrenches(
    kin: ArmKinematics, q: np.ndarray, force: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Return a hand contact as applied (hand frame) and as transmitted to the F/T sensor (sensor frame).

    A force ``F`` applied to the distal subtree at the hand frame's origin ``p_h`` adds ``[F_s, a × F_s]``
    to the reading (module docstring of :mod:`semiparam_ros.sim.effects`), with ``F_s = R_sᵀ F`` and
    ``a = R_sᵀ (p_h − p_s)`` the hand origin seen from the sensor.

    Args:
        kin: Arm kinematics (same locked joints as the simulation).
        q: (k, 4) joint positions (rad).
        force: (k, 3) applied force (N), root-frame axes; rows that are exactly zero are skipped.

    Returns:
        ``(applied, transmitted)``: (k, 6) ``[R_hᵀ F, 0]`` in the hand frame and (k, 6)
        ``[F_s, a × F_s]`` (N, N·m) in the sensor frame.
    """
    applied = np.zeros((q.shape[0], 6))
    transmitted = np.zeros((q.shape[0], 6))
    for i in np.flatnonzero(np.any(force != 0.0, axis=1)):
        (Rs, ps), (Rh, ph) = kin.frame_poses(q[i], [SENSOR_FRAME, _HAND_FRAME])
        f_s = Rs.T @ force[i]
        transmitted[i, :3] = f_s
        transmitted[i, 3:] = np.cross(Rs.T @ (ph - ps), f_s)
        applied[i, :3] = Rh.T @ force[i]
    return applied, transmitted
