"""Write a :class:`~semiparam_ros.sim.scenario.SimulatedRecording` as a rosbag2/MCAP bag with a sidecar.

Topics (every stamp is the sampling instant; log time = header stamp; messages in log-time order):

* ``/joint_states`` (``sensor_msgs/msg/JointState``): the 13 joints of :data:`PUBLISHED_JOINT_ORDER`;
  noisy position (rad) and velocity (rad/s) of the four arm joints, the locked joints exact with velocity 0;
  **no acceleration**, effort empty.
* ``/wrench`` (``geometry_msgs/msg/WrenchStamped``): the measured F/T reading (N, N·m), frame
  ``r_arm_ft_sensor``.
* ``/ground_truth/wrench`` (WrenchStamped): the reading without noise (all effects included).
* ``/ground_truth/wrench/rigid_body`` (WrenchStamped): the rigid-body part Φπ(t) (payload included).
* ``/ground_truth/joint_accelerations`` (``trajectory_msgs/msg/JointTrajectory``): one point with the true
  q, q̇, q̈ of the four arm joints, stamped like ``/joint_states``.

With contact episodes (``ScenarioConfig.contacts``), at every wrench stamp (zero outside the episodes):

* ``/ground_truth/contact_wrench`` (WrenchStamped): the force the environment applies to the hand at the
  origin of ``r_hand_dh_frame``, in that frame (N; torque 0).
* ``/ground_truth/external_wrench`` (WrenchStamped): its transmitted wrench at the sensor (N, N·m, frame
  ``r_arm_ft_sensor``), included in ``/ground_truth/wrench`` (which then also applies the calibration
  error to it): what ``measured − predicted`` estimates.

``scenario.yaml`` next to ``metadata.yaml`` records the seed, trajectory, payload (mass, time, stamp),
every effect magnitude and the measured RMS of each part.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import yaml

from semiparam_ros.atomic import atomic_open
from semiparam_ros.core.messages import JointStateData, WrenchData
from semiparam_ros.io.bags import BagWriter
from semiparam_ros.sim.effects import SENSOR_FRAME
from semiparam_ros.sim.scenario import PUBLISHED_JOINT_ORDER, SimulatedRecording

__all__ = [
    "GROUND_TRUTH_ACCELERATION_TOPIC",
    "GROUND_TRUTH_CONTACT_TOPIC",
    "GROUND_TRUTH_EXTERNAL_WRENCH_TOPIC",
    "GROUND_TRUTH_RIGID_TOPIC",
    "GROUND_TRUTH_WRENCH_TOPIC",
    "JOINT_STATES_TOPIC",
    "SCENARIO_FILE",
    "WRENCH_TOPIC",
    "write_recording",
    "write_sidecar",
]

JOINT_STATES_TOPIC = "/joint_states"
WRENCH_TOPIC = "/wrench"
GROUND_TRUTH_WRENCH_TOPIC = "/ground_truth/wrench"
GROUND_TRUTH_RIGID_TOPIC = "/ground_truth/wrench/rigid_body"
GROUND_TRUTH_ACCELERATION_TOPIC = "/ground_truth/joint_accelerations"
GROUND_TRUTH_CONTACT_TOPIC = "/ground_truth/contact_wrench"
GROUND_TRUTH_EXTERNAL_WRENCH_TOPIC = "/ground_truth/external_wrench"
SCENARIO_FILE = "scenario.yaml"


def write_sidecar(bag: Path, info: object) -> None:
    """Write a bag's ground-truth sidecar ``bag/scenario.yaml`` atomically (every simulated bag's format).

    Args:
        bag: The bag folder.
        info: The scenario description (plain YAML-serializable data).

    Raises:
        OSError: If the file cannot be written (an existing sidecar is then unchanged).
    """
    with atomic_open(bag / SCENARIO_FILE, "w") as handle:
        yaml.safe_dump(info, handle, sort_keys=False, default_flow_style=None, width=110)


def write_recording(
    recording: SimulatedRecording,
    path: str | Path,
    *,
    overwrite: bool = False,
    compress: bool = True,
    progress: Callable[[int], None] | None = None,
) -> Path:
    """Write the recording as a bag folder ``path`` (``<name>.mcap``, ``metadata.yaml``, ``scenario.yaml``).

    Args:
        recording: The simulated recording.
        path: Output folder (must not exist unless ``overwrite``).
        overwrite: Replace an existing bag folder written by this function.
        compress: zstd-compress the MCAP chunks.
        progress: Optional callback called with the number of messages written since the last call.

    Returns:
        The bag folder.

    Raises:
        semiparam_ros.errors.BagError: If the folder exists (without ``overwrite``), is not a bag
            folder, or cannot be written.
    """
    path = Path(path)
    if overwrite and path.is_dir():
        # The sidecar is ours; BagWriter replaces folders holding bag files only.
        (path / SCENARIO_FILE).unlink(missing_ok=True)
    rec = recording
    names = list(PUBLISHED_JOINT_ORDER)
    arm_index = {name: i for i, name in enumerate(rec.joint_names)}
    arm_cols = np.array([arm_index.get(n, -1) for n in names])
    is_arm = arm_cols >= 0
    fixed_pos = np.array([rec.other_positions.get(n, 0.0) for n in names])

    n_joint = rec.joint_stamps.size
    n_wrench = rec.wrench_stamps.size
    # One merged, log-time ordered stream: (stamp, kind, index). Kinds in write order at equal stamps.
    wrench_sets = {
        2: (WRENCH_TOPIC, rec.measured_wrench, SENSOR_FRAME),
        3: (GROUND_TRUTH_WRENCH_TOPIC, rec.true_wrench, SENSOR_FRAME),
        4: (GROUND_TRUTH_RIGID_TOPIC, rec.rigid_wrench, SENSOR_FRAME),
    }
    if rec.contact_wrench is not None and rec.external_wrench is not None:
        hand_frame = str(rec.info["contacts"]["frame"])
        wrench_sets[5] = (GROUND_TRUTH_CONTACT_TOPIC, rec.contact_wrench, hand_frame)
        wrench_sets[6] = (GROUND_TRUTH_EXTERNAL_WRENCH_TOPIC, rec.external_wrench, SENSOR_FRAME)
    n_kinds = 2 + len(wrench_sets)
    sizes = [n_joint, n_joint] + [n_wrench] * len(wrench_sets)
    stamps = np.concatenate([rec.joint_stamps, rec.joint_stamps] + [rec.wrench_stamps] * len(wrench_sets))
    kinds = np.repeat(np.arange(n_kinds), sizes)
    index = np.concatenate([np.arange(n) for n in sizes])
    order = np.lexsort((kinds, stamps))
    arm_names = list(rec.joint_names)
    batch = 0
    with BagWriter(path, overwrite=overwrite, compress=compress) as bag:
        for kind, i in zip(kinds[order].tolist(), index[order].tolist(), strict=True):
            if kind == 0:
                position = fixed_pos.copy()
                position[is_arm] = rec.q_measured[i, arm_cols[is_arm]]
                velocity = np.zeros(len(names))
                velocity[is_arm] = rec.dq_measured[i, arm_cols[is_arm]]
                bag.write_joint_state(
                    JOINT_STATES_TOPIC,
                    JointStateData(int(rec.joint_stamps[i]), names, position, velocity, ()),
                )
            elif kind == 1:
                bag.write_joint_trajectory_point(
                    GROUND_TRUTH_ACCELERATION_TOPIC,
                    int(rec.joint_stamps[i]),
                    arm_names,
                    rec.q[i],
                    rec.dq[i],
                    rec.ddq[i],
                )
            else:
                topic, values, frame = wrench_sets[kind]
                w = values[i]
                bag.write_wrench(topic, WrenchData(int(rec.wrench_stamps[i]), frame, w[:3], w[3:]))
            batch += 1
            if progress is not None and batch == 2000:
                progress(batch)
                batch = 0
        counts = dict(bag.counts)
    if progress is not None and batch:
        progress(batch)
    info = dict(rec.info)
    info["topics"] = {
        JOINT_STATES_TOPIC: {
            "type": "sensor_msgs/msg/JointState",
            "count": counts.get(JOINT_STATES_TOPIC, 0),
            "names": names,
        },
        WRENCH_TOPIC: {
            "type": "geometry_msgs/msg/WrenchStamped",
            "count": counts.get(WRENCH_TOPIC, 0),
            "frame_id": SENSOR_FRAME,
        },
        GROUND_TRUTH_WRENCH_TOPIC: {
            "type": "geometry_msgs/msg/WrenchStamped",
            "count": counts.get(GROUND_TRUTH_WRENCH_TOPIC, 0),
        },
        GROUND_TRUTH_RIGID_TOPIC: {
            "type": "geometry_msgs/msg/WrenchStamped",
            "count": counts.get(GROUND_TRUTH_RIGID_TOPIC, 0),
        },
        GROUND_TRUTH_ACCELERATION_TOPIC: {
            "type": "trajectory_msgs/msg/JointTrajectory",
            "count": counts.get(GROUND_TRUTH_ACCELERATION_TOPIC, 0),
        },
    }
    for kind in (5, 6):
        if kind in wrench_sets:
            topic, _, frame = wrench_sets[kind]
            info["topics"][topic] = {
                "type": "geometry_msgs/msg/WrenchStamped",
                "count": counts.get(topic, 0),
                "frame_id": frame,
            }
    write_sidecar(path, info)
    return path
