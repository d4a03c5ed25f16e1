"""The simulation pipeline shared by every simulated robot: stamps, seeds, payload, rigid body, contacts.

A recording is simulated in one order whatever is measured
(:func:`semiparam_ros.sim.generate.simulate_recording`):

1. stamps on the sampling grid of each stream (:func:`sample_stamps`) and the recording's random streams
   (:func:`recording_seeds`: trajectory, joint noise, measurement noise, contacts — the same children for
   every robot, so adding contacts leaves the other signals unchanged);
2. the trajectory (the robot's own: circles for the iCub hand, a multi-sine for the arms);
3. the true parameters and the payload picked up at the end effector (:func:`add_payload`);
4. the rigid-body outputs ``Φ(q, q̇, q̈) π(t)`` (:func:`rigid_outputs`);
5. contact episodes drawn once (:func:`draw_contacts`), then the measurement model: the F/T sensor's
   wrench with its harness, calibration and noise (:mod:`semiparam_ros.sim.effects`), or joint torques
   with friction and ``−Jᵀ F``;
6. the scenario description (``scenario.yaml``; :func:`limits_info`, :func:`contacts_info`) and one bag
   writer (:mod:`semiparam_ros.sim.writer`).

>>> sample_stamps(1_000_000_000, 3, 100.0, offset_ns=5)
array([1000000005, 1010000005, 1020000005])
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Protocol

import numpy as np

from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor, point_mass_parameters
from semiparam_ros.sim.contacts import ContactConfig, ContactEpisode, contact_forces, draw_episodes
from semiparam_ros.sim.frames import frame_in_body
from semiparam_ros.sim.ik import ArmKinematics

__all__ = [
    "DEFAULT_START_NS",
    "Measurement",
    "MeasurementModel",
    "RecordingConfig",
    "add_payload",
    "arm_kinematics",
    "column_rms",
    "contacts_info",
    "draw_contacts",
    "limits_info",
    "recording_seeds",
    "regressor_of",
    "rigid_outputs",
    "sample_stamps",
    "wrench_rms",
]


#: First stamp of every bag (2023-11-14T22:13:20Z), ns; fixed so that bags are deterministic.
DEFAULT_START_NS = 1_700_000_000 * 10**9


@dataclass(frozen=True)
class RecordingConfig:
    """What every simulated recording has, whatever the robot and the measurement.

    Subclassed by the iCub F/T scenario (:class:`~semiparam_ros.sim.scenario.ScenarioConfig`) and the
    joint-torque arms (:class:`~semiparam_ros.sim.arms.ArmScenarioConfig`), which add the trajectory,
    rates and measurement model.

    Attributes:
        name: Bag folder name.
        duration: Length of the recording [s].
        seed: Seed of the trajectory, the noise and the contacts (with the name: each bag its own noise).
        payload_mass: Mass picked up at the end effector [kg]; 0 for none.
        payload_time: Pickup time [s from the start]; None for the middle of the recording.
        contacts: Contact episodes at the end effector (:mod:`semiparam_ros.sim.contacts`), or None.
        start_ns: First stamp [ns].

    Raises:
        ValueError: An invalid value (checked by :meth:`check_common` from the subclasses).
    """

    name: str
    duration: float = 60.0
    seed: int = 0
    payload_mass: float = 0.0
    payload_time: float | None = None
    contacts: ContactConfig | None = None
    start_ns: int = DEFAULT_START_NS

    def check_common(self) -> None:
        """Check the shared fields.

        Raises:
            ValueError: A name that is not a plain folder name, a duration that is not a positive number, a
                negative or non-finite payload mass, a pickup outside the recording, a negative seed or
                start stamp, contacts that are not a :class:`ContactConfig`.
        """
        if not self.name or "/" in self.name:
            raise ValueError(f"name must be a plain folder name, got {self.name!r}")
        value = self.duration
        if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
            raise ValueError(f"duration must be a number, got {value!r}")
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"duration must be a positive number, got {value!r}")
        if not (np.isfinite(self.payload_mass) and self.payload_mass >= 0):
            raise ValueError(f"payload_mass must be finite and >= 0 kg, got {self.payload_mass!r}")
        if self.payload_time is not None and not (0 <= self.payload_time <= self.duration):
            raise ValueError(f"payload_time must be within [0, duration] = [0, {self.duration}] s")
        if int(self.seed) < 0 or int(self.start_ns) < 0:
            raise ValueError(f"seed and start_ns must be >= 0, got {self.seed!r} and {self.start_ns!r}")
        if self.contacts is not None and not isinstance(self.contacts, ContactConfig):
            raise ValueError("contacts must be a ContactConfig or None")

    def record(self, *, progress: Callable[[int], None] | None = None) -> Any:  # pragma: no cover - abstract
        """Simulate this recording with its robot's measurement model (F/T wrench or joint torques)."""
        raise NotImplementedError

    def progress_units(self) -> tuple[int, str]:  # pragma: no cover - abstract
        """Return the count and unit of the progress that simulating and writing this recording reports."""
        raise NotImplementedError

    @property
    def pickup_time(self) -> float | None:
        """Pickup time [s from the start], or None without payload."""
        if self.payload_mass <= 0:
            return None
        return 0.5 * self.duration if self.payload_time is None else float(self.payload_time)



@dataclass(frozen=True)
class Measurement:
    """What a robot's sensors report over one recording, with its parts ((N, t) arrays, units of y).

    Attributes:
        true: The noise-free reading (rigid body, the sensors' own effects and contacts).
        measured: ``true + noise``.
        noise: The sensor noise drawn.
        non_rigid: What the sensors add besides the rigid body and contacts: the F/T sensor's harness, or
            the joints' friction, offsets and armature.
        external: The contacts' part of the reading (None without contact episodes, F/T).
        contact_wrench: The contact as applied at the end effector (None without contact episodes, F/T).
    """

    true: np.ndarray
    measured: np.ndarray
    noise: np.ndarray
    non_rigid: np.ndarray
    external: np.ndarray | None = None
    contact_wrench: np.ndarray | None = None


class MeasurementModel(Protocol):
    """A robot's sensors: what they read of the rigid-body output along a recording.

    The F/T sensor's wrench (:class:`~semiparam_ros.sim.scenario.FTSensorMeasurement`) or the joint
    torques (:class:`~semiparam_ros.sim.arms.JointTorqueMeasurement`).

    ``output`` is an :class:`~semiparam_ros.core.kinds.OutputKind`; :meth:`measure` turns the rigid-body
    output along the trajectory into the reading, drawing its noise from ``rng`` only.
    """

    output: str

    def measure(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, t: np.ndarray, rigid: np.ndarray,
                force: np.ndarray | None, rng: np.random.Generator) -> Measurement:
        """Return the reading at the samples' states (rad, rad/s, rad/s²) and times t [s].

        ``rigid`` is the rigid-body output (N, t); ``force`` the contact force at the end effector (N, 3)
        [N, base frame], or None when the recording has no contact episodes.
        """
        ...


@lru_cache(maxsize=16)
def arm_kinematics(urdf: str, joints: tuple[str, ...], end_effector: str,
                   locked: tuple[tuple[str, float], ...] = ()) -> ArmKinematics:
    """Return the (cached) kinematics of a simulated arm (URDF file, moving joints, end effector, locks)."""
    return ArmKinematics(urdf, joints, locked=dict(locked) if locked else None, end_effector=end_effector)


@lru_cache(maxsize=16)
def regressor_of(urdf: str, joints: tuple[str, ...], *, output: str, ft_sensor: str | None = None,
                 locked: tuple[tuple[str, float], ...] = ()) -> RigidBodyRegressor:
    """Return the (cached; not thread-safe) rigid-body regressor that measures a simulated recording."""
    return RigidBodyRegressor.from_urdf(urdf, joints, output=output, ft_sensor=ft_sensor,
                                        locked=dict(locked) if locked else None)


def sample_stamps(start_ns: int, count: int, rate: float, offset_ns: int = 0) -> np.ndarray:
    """Return ``start + offset + round(i·1e9/rate)`` for i < count, as int64 ns."""
    return start_ns + offset_ns + np.rint(np.arange(count, dtype=np.float64) * (1e9 / rate)).astype(np.int64)


def recording_seeds(seed: int, name: str) -> list[np.random.Generator]:
    """Return the recording's four random streams: trajectory, joint noise, measurement noise, contacts.

    They are children of one seed sequence of the seed and the bag name, so each bag gets its own noise and
    drawing contacts (the fourth) changes none of the others.
    """
    seq = np.random.SeedSequence([int(seed), zlib.crc32(name.encode())])
    return [np.random.default_rng(s) for s in seq.spawn(4)]


def add_payload(reg: RigidBodyRegressor, params: np.ndarray, *, frame: str, mass: float,
                pickup_s: float | None, start_ns: int,
                point_in_frame: Sequence[float] | None = None) -> tuple[np.ndarray, dict[str, Any] | None]:
    """Add a point-mass payload to the body that carries ``frame``.

    Args:
        reg: The regressor (its body parameters are ``π[10·i : 10·i + 10]``).
        params: The full parameters before the pickup.
        frame: The URDF frame the payload is attached to.
        mass: Payload [kg].
        pickup_s: Pickup time [s from the start]; None: no payload.
        start_ns: The recording's first stamp [ns].
        point_in_frame: The payload's point in ``frame`` [m]; None: the frame's origin.

    Returns:
        The parameters after the pickup (a copy; equal to ``params`` without payload) and the payload's
        description for ``scenario.yaml`` (None without payload).
    """
    after = params.copy()
    if pickup_s is None:
        return after, None
    body, T = frame_in_body(reg, frame)
    point = T[:3, 3] if point_in_frame is None else T[:3, :3] @ np.asarray(point_in_frame) + T[:3, 3]
    slot = reg.body_index(body)
    after[10 * slot : 10 * slot + 10] += point_mass_parameters(mass, point)
    info: dict[str, Any] = {"mass_kg": float(mass), "time_s": float(pickup_s),
                            "stamp_ns": int(start_ns + round(pickup_s * 1e9))}
    if point_in_frame is None:
        info.update(body=body, frame=frame)
    else:
        info.update(frame=frame, point_in_frame_m=list(point_in_frame), body=body)
    info["point_in_body_m"] = [float(v) for v in point]
    return after, info


def rigid_outputs(reg: RigidBodyRegressor, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, after: np.ndarray,
                  params_before: np.ndarray, params_after: np.ndarray, *, chunk: int,
                  progress: Callable[[int], None] | None = None) -> np.ndarray:
    """Return ``Φ(q, q̇, q̈) π(t)`` per sample, ``π`` switching to ``params_after`` where ``after``.

    Args:
        reg: The regressor.
        q: (k, n) joint positions [rad].
        dq: (k, n) joint velocities [rad/s].
        ddq: (k, n) joint accelerations [rad/s²].
        after: (k,) whether the payload is held.
        params_before: The full parameters without the payload.
        params_after: The full parameters with it.
        chunk: Samples per regressor call (bounds the memory of the stacked regressor).
        progress: Called with the samples done after each chunk.

    Returns:
        (k, n_outputs) outputs [N, N·m].
    """
    count = q.shape[0]
    out = np.empty((count, reg.n_outputs))
    for start in range(0, count, chunk):
        stop = min(start + chunk, count)
        phi = reg.regressor(q[start:stop], dq[start:stop], ddq[start:stop])
        out[start:stop] = np.where(after[start:stop, None], phi @ params_after, phi @ params_before)
        if progress is not None:
            progress(stop - start)
    return out


def draw_contacts(config: ContactConfig | None, duration_s: float, t: np.ndarray,
                  rng: np.random.Generator) -> tuple[tuple[ContactEpisode, ...], np.ndarray]:
    """Draw the contact episodes of a recording and the force they apply at each time.

    Returns:
        The episodes (empty without ``config``) and the (k, 3) applied force [N], base frame.
    """
    if config is None:
        return (), np.zeros((t.size, 3))
    episodes = draw_episodes(config, duration_s, rng)
    return episodes, contact_forces(episodes, t)


def contacts_info(config: ContactConfig, frame: str, convention: str,
                  episodes: Sequence[ContactEpisode]) -> dict[str, Any]:
    """Describe the contacts for ``scenario.yaml``: how they were drawn, where they act, the episodes."""
    return {**config.as_dict(), "frame": frame, "convention": convention,
            "episodes": [e.as_dict() for e in episodes]}


def limits_info(q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                margin: float) -> dict[str, Any]:
    """Describe the motion against the joint limits for ``scenario.yaml`` (rad, rad/s, rad/s²)."""
    return {
        "q_min_rad": [float(v) for v in q.min(axis=0)],
        "q_max_rad": [float(v) for v in q.max(axis=0)],
        "joint_lower_rad": [float(v) for v in lower],
        "joint_upper_rad": [float(v) for v in upper],
        "max_abs_dq_rad_per_s": [float(v) for v in np.abs(dq).max(axis=0)],
        "max_abs_ddq_rad_per_s2": [float(v) for v in np.abs(ddq).max(axis=0)],
        "min_joint_limit_margin_rad": margin,
    }


def column_rms(x: np.ndarray) -> list[float]:
    """RMS of each column (e.g. per joint, N·m)."""
    return [float(v) for v in np.sqrt(np.mean(np.asarray(x) ** 2, axis=0))]


def wrench_rms(x: np.ndarray) -> list[float]:
    """Component-averaged RMS of the force and torque parts of (k, 6) wrenches (N, N·m)."""
    x = np.asarray(x)
    comp = np.sqrt(np.mean(x * x, axis=0))
    return [float(np.mean(comp[:3])), float(np.mean(comp[3:]))]
