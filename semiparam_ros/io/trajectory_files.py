"""Excitation trajectories as files: a ``JointTrajectory`` a controller runs, and its exact description.

:func:`write_excitation` writes two files for one designed excitation
(:class:`~semiparam_ros.core.rigid_body.excitation.Excitation`):

* the **trajectory** for a ``joint_trajectory_controller``, a ``trajectory_msgs/msg/JointTrajectory``
  sampled at ``point_rate`` (positions in rad, velocities in rad/s, accelerations in rad/s²; efforts
  empty), its first point ``lead_in`` seconds after the start so that the controller has time to bring the
  arm from wherever it stands to the trajectory's first point (where it is at rest):

  - ``traj.mcap``: a rosbag2 folder ``traj/`` holding the one message on ``topic``; ``ros2 bag play traj``
    sends it to the controller (a 20 s trajectory at 100 points/s is ~1 MB: too long for a command-line
    argument of ``ros2 topic pub``);
  - ``traj.yaml``: the message's fields as YAML (for a script: ``yaml.safe_load`` then
    ``rosidl_runtime_py.set_message_fields``);

* the **description** ``traj.excitation.yaml``: the Fourier coefficients (what the simulator reads to
  drive a simulated arm exactly, :func:`read_excitation`), the limits, the condition number and each base
  parameter's σ per N·m of noise.

Example:
    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> from semiparam_ros.core.fourier import FourierTrajectory
    >>> traj = FourierTrajectory(2 * np.pi / 2.0, [0.1], [[0.0]], [[0.2]])
    >>> times, q, dq, ddq = sample_points(traj, periods=1, point_rate=2.0, lead_in=1.0)
    >>> times.tolist(), np.round(q[:, 0], 6).tolist()
    ([1.0, 1.5, 2.0, 2.5, 3.0], [0.1, 0.3, 0.1, -0.1, 0.1])
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from semiparam_ros.atomic import atomic_write_text
from semiparam_ros.core.fourier import FourierTrajectory
from semiparam_ros.core.rigid_body.excitation import Excitation
from semiparam_ros.io.bags import JOINT_TRAJECTORY_TYPE, BagWriter

__all__ = [
    "DEFAULT_TOPIC",
    "ExcitationFile",
    "description_path",
    "read_excitation",
    "sample_points",
    "write_excitation",
]

#: Where a ``joint_trajectory_controller`` named ``joint_trajectory_controller`` takes trajectories.
DEFAULT_TOPIC = "/joint_trajectory_controller/joint_trajectory"
_SUFFIX = ".excitation.yaml"
_FORMAT = "semiparam_ros excitation 1"


@dataclass(frozen=True)
class ExcitationFile:
    """What :func:`read_excitation` returns.

    Attributes:
        joint_names: The joints of the trajectory's columns.
        trajectory: One period (rad, rad/s, rad/s²), at rest at t = 0.
        periods: Repetitions in the written trajectory.
        lead_in: Time before the first point of the written trajectory (s).
        description: The whole description (plain Python).
    """

    joint_names: tuple[str, ...]
    trajectory: FourierTrajectory
    periods: int
    lead_in: float
    description: dict[str, Any]


def description_path(path: str | Path) -> Path:
    """Return the description beside a trajectory file: ``traj.yaml``/``.mcap`` → ``traj.excitation.yaml``."""
    path = Path(path)
    if path.name.endswith(_SUFFIX):
        return path
    return path.with_name(path.name.rsplit(".", 1)[0] + _SUFFIX)


def sample_points(trajectory: FourierTrajectory, *, periods: int, point_rate: float,
                  lead_in: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sample the trajectory's points, both ends included (it ends where it starts, at rest).

    Args:
        trajectory: One period.
        periods: Repetitions.
        point_rate: Points per second (Hz).
        lead_in: Time from start of the first point (s).

    Returns:
        ``(time_from_start (m,) s, q, q̇, q̈ (m, n))``.

    Raises:
        ValueError: A non-positive rate or period count, or a negative lead-in.
    """
    if not (math.isfinite(point_rate) and point_rate > 0) or periods < 1 or not (lead_in >= 0):
        raise ValueError("point_rate must be positive, periods ≥ 1 and lead_in ≥ 0")
    duration = periods * trajectory.period
    count = round(duration * point_rate)
    t = np.arange(count + 1) * (duration / count)
    q, dq, ddq = trajectory.evaluate(t)
    return lead_in + t, q, dq, ddq


def _duration(seconds: float) -> dict[str, int]:
    ns = round(seconds * 1e9)
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _description(excitation: Excitation, joint_names: tuple[str, ...], lead_in: float,
                 point_rate: float) -> dict[str, Any]:
    traj = excitation.trajectory
    return {
        "format": _FORMAT,
        "joint_names": list(joint_names),
        "period_s": traj.period,
        "periods": excitation.periods,
        "duration_s": excitation.duration,
        "lead_in_s": float(lead_in),
        "point_rate_hz": float(point_rate),
        "fourier": {
            "form": "q(t) = offset + sum_k cos_coef[k-1] cos(k w t) + sin_coef[k-1] sin(k w t), "
                    "w = 2 pi / period",
            "offset_rad": traj.offset.tolist(),
            "cos_coef_rad": traj.cos_coef.tolist(),
            "sin_coef_rad": traj.sin_coef.tolist(),
        },
        "condition_number": excitation.condition_number,
        "optimizer_iterations": excitation.iterations,
        "limits": excitation.limits.as_dict(),
        "limit_usage_at_1khz": {k: v.tolist() for k, v in excitation.usage.items()},
        "base_parameters": {
            "note": f"sigma of each base parameter after {excitation.rate:g} Hz x {excitation.duration:g} s "
                    "with 1 N m white torque noise per joint; scale by the sensor's noise",
            "names": list(excitation.parameter_names),
            "sigma_per_Nm_noise": excitation.parameter_std.tolist(),
            "cad": excitation.cad_values.tolist(),
        },
    }


def write_excitation(path: str | Path, excitation: Excitation, *, point_rate: float = 100.0,
                     lead_in: float = 5.0, topic: str = DEFAULT_TOPIC, overwrite: bool = False) -> list[Path]:
    """Write the trajectory (``.yaml`` message fields or ``.mcap`` bag) and its description beside it.

    Args:
        path: ``*.yaml`` or ``*.mcap`` (the bag folder is the path without ``.mcap``).
        excitation: The designed excitation.
        point_rate: Points per second (Hz).
        lead_in: Time from start of the first point (s).
        topic: The bag's topic (``.mcap`` only).
        overwrite: Replace existing files.

    Returns:
        The files written: the trajectory (the ``.mcap`` file inside its bag folder) and the description.

    Raises:
        ValueError: Another suffix, or invalid point rate or lead-in.
        OSError: A file that exists (without ``overwrite``) or cannot be written.
    """
    path = Path(path)
    if path.suffix not in (".yaml", ".yml", ".mcap"):
        raise ValueError(f"the trajectory file must end in .yaml or .mcap, got {str(path)!r}")
    joints = excitation.limits.joint_names
    times, q, dq, ddq = sample_points(excitation.trajectory, periods=excitation.periods,
                                      point_rate=point_rate, lead_in=lead_in)
    described = description_path(path)
    for target in (path if path.suffix != ".mcap" else path.with_suffix(""), described):
        if target.exists() and not overwrite:
            raise FileExistsError(f"{target} exists (pass --overwrite to replace it)")
    if path.suffix == ".mcap":
        written = _write_bag(path.with_suffix(""), joints, times, q, dq, ddq, topic, overwrite)
    else:
        message = {
            "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
            "joint_names": list(joints),
            "points": [
                {"positions": q[i].tolist(), "velocities": dq[i].tolist(), "accelerations": ddq[i].tolist(),
                 "effort": [], "time_from_start": _duration(float(times[i]))}
                for i in range(times.size)
            ],
        }
        atomic_write_text(path, yaml.safe_dump(message, sort_keys=False, default_flow_style=None, width=200))
        written = path
    atomic_write_text(described, yaml.safe_dump(_description(excitation, joints, lead_in, point_rate),
                                                sort_keys=False, default_flow_style=None, width=200))
    return [written, described]


def _write_bag(folder: Path, joints: tuple[str, ...], times: np.ndarray, q: np.ndarray, dq: np.ndarray,
               ddq: np.ndarray, topic: str, overwrite: bool) -> Path:
    with BagWriter(folder, overwrite=overwrite, compress=True) as bag:
        types = bag.typestore.types
        point_type = types["trajectory_msgs/msg/JointTrajectoryPoint"]
        duration_type = types["builtin_interfaces/msg/Duration"]
        points = [point_type(positions=q[i], velocities=dq[i], accelerations=ddq[i], effort=np.zeros(0),
                             time_from_start=duration_type(**_duration(float(times[i]))))
                  for i in range(times.size)]
        header = types["std_msgs/msg/Header"](stamp=types["builtin_interfaces/msg/Time"](sec=0, nanosec=0),
                                              frame_id="")
        message = types[JOINT_TRAJECTORY_TYPE](header=header, joint_names=list(joints), points=points)
        bag.write_message(topic, JOINT_TRAJECTORY_TYPE, message, log_time_ns=0)
    return folder / f"{folder.name}.mcap"


def read_excitation(path: str | Path) -> ExcitationFile:
    """Read an excitation's description (given itself, or the trajectory file it lies beside).

    Args:
        path: ``traj.excitation.yaml``, or ``traj.yaml`` / ``traj.mcap`` with it beside.

    Returns:
        The joints, the exact trajectory and how it was written.

    Raises:
        ValueError: Not an excitation description, or inconsistent coefficients.
        OSError: The file cannot be read.
    """
    described = description_path(path)
    try:
        doc = yaml.safe_load(described.read_text(encoding="utf-8"))
    except yaml.YAMLError as err:
        raise ValueError(f"{described}: not YAML: {err}") from err
    if not isinstance(doc, dict) or doc.get("format") != _FORMAT:
        raise ValueError(f"{described}: not an excitation description (format {_FORMAT!r})")
    try:
        fourier = doc["fourier"]
        traj = FourierTrajectory(2.0 * math.pi / float(doc["period_s"]), fourier["offset_rad"],
                                 fourier["cos_coef_rad"], fourier["sin_coef_rad"])
        joints = tuple(str(j) for j in doc["joint_names"])
        periods, lead_in = int(doc["periods"]), float(doc["lead_in_s"])
    except (KeyError, TypeError) as err:
        raise ValueError(f"{described}: incomplete excitation description ({err})") from err
    if len(joints) != traj.n_joints:
        raise ValueError(f"{described}: {len(joints)} joint names for {traj.n_joints} trajectories")
    return ExcitationFile(joints, traj, periods, lead_in, doc)
