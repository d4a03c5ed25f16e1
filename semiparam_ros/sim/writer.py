"""Write a simulated recording as a rosbag2/MCAP bag with its ground-truth sidecar (one writer for all).

Every stamp is the sampling instant; log time = header stamp; messages in log-time order. The measurement
model decides the topics:

**F/T sensor** (:class:`~semiparam_ros.sim.scenario.SimulatedRecording`, the iCub arm):

* ``/joint_states`` (``sensor_msgs/msg/JointState``): the 13 joints of :data:`PUBLISHED_JOINT_ORDER`;
  noisy position (rad) and velocity (rad/s) of the four arm joints, the locked joints exact with velocity 0;
  **no acceleration**, effort empty.
* ``/wrench`` (``geometry_msgs/msg/WrenchStamped``): the measured F/T reading (N, N·m), frame
  ``r_arm_ft_sensor``.
* ``/ground_truth/wrench`` (WrenchStamped): the reading without noise (all effects included).
* ``/ground_truth/wrench/rigid_body`` (WrenchStamped): the rigid-body part Φπ(t) (payload included).
* ``/ground_truth/joint_accelerations`` (``trajectory_msgs/msg/JointTrajectory``): one point with the true
  q, q̇, q̈ of the four arm joints, stamped like ``/joint_states``.
* with contact episodes, at every wrench stamp (zero outside the episodes): ``/ground_truth/contact_wrench``
  (WrenchStamped), the force the environment applies to the hand at the origin of ``r_hand_dh_frame``, in
  that frame (N; torque 0), and ``/ground_truth/external_wrench`` (WrenchStamped), its transmitted wrench
  at the sensor (N, N·m, frame ``r_arm_ft_sensor``), included in ``/ground_truth/wrench`` (which then also
  applies the calibration error to it): what ``measured − predicted`` estimates.

**Joint torques** (:class:`~semiparam_ros.sim.arms.ArmRecording`; joints in the robot's order):

* ``/joint_states`` (JointState): noisy position (rad), velocity (rad/s) and the measured joint torques in
  ``effort`` (N·m); no accelerations.
* ``/ground_truth/joint_accelerations`` (JointTrajectory): one point with the true q, q̇, q̈.
* ``/ground_truth/joint_torques`` (JointState): true q, q̇ and the noise-free measured torques (N·m): rigid
  body + friction + contact.
* ``/ground_truth/joint_torques/rigid_body`` (JointState, effort only): Φ(q, q̇, q̈) π(t), the true
  parameters with the payload after the pickup (N·m).
* ``/ground_truth/joint_torques/friction`` (JointState, effort only): f_v q̇ + f_c tanh(q̇/v_s) + o + a q̈.
* with contact episodes (zero outside them): ``/ground_truth/external_joint_torques`` (JointState, effort
  only), the contact's effect on the measured torques ``−J(q)ᵀ F`` (N·m), and ``/ground_truth/contact_wrench``
  (WrenchStamped), the applied force at the end-effector frame's origin, in that frame (N; torque 0).

``scenario.yaml`` next to ``metadata.yaml`` records the seed, trajectory, true parameters, payload (mass,
time, stamp), every effect magnitude, contact episodes, the measured RMS of each part and the topics.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import yaml

from semiparam_ros.atomic import atomic_open
from semiparam_ros.core.stream.messages import JointStateData, WrenchData
from semiparam_ros.io.bags import BagWriter
from semiparam_ros.sim.arms import ArmRecording
from semiparam_ros.sim.effects import SENSOR_FRAME
from semiparam_ros.sim.scenario import PUBLISHED_JOINT_ORDER, SimulatedRecording

__all__ = [
    "GROUND_TRUTH_ACCELERATION_TOPIC",
    "GROUND_TRUTH_CONTACT_TOPIC",
    "GROUND_TRUTH_EXTERNAL_TORQUES_TOPIC",
    "GROUND_TRUTH_EXTERNAL_WRENCH_TOPIC",
    "GROUND_TRUTH_FRICTION_TOPIC",
    "GROUND_TRUTH_RIGID_TOPIC",
    "GROUND_TRUTH_RIGID_TORQUES_TOPIC",
    "GROUND_TRUTH_TORQUES_TOPIC",
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
GROUND_TRUTH_TORQUES_TOPIC = "/ground_truth/joint_torques"
GROUND_TRUTH_RIGID_TORQUES_TOPIC = "/ground_truth/joint_torques/rigid_body"
GROUND_TRUTH_FRICTION_TOPIC = "/ground_truth/joint_torques/friction"
GROUND_TRUTH_EXTERNAL_TORQUES_TOPIC = "/ground_truth/external_joint_torques"
SCENARIO_FILE = "scenario.yaml"
_JOINT_STATE = "sensor_msgs/msg/JointState"
_WRENCH = "geometry_msgs/msg/WrenchStamped"
_TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"


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
    recording: SimulatedRecording | ArmRecording,
    path: str | Path,
    *,
    overwrite: bool = False,
    compress: bool = True,
    progress: Callable[[int], None] | None = None,
) -> Path:
    """Write the recording as a bag folder ``path`` (``<name>.mcap``, ``metadata.yaml``, ``scenario.yaml``).

    Args:
        recording: The simulated recording (F/T sensor or joint torques: the module docstring's topics).
        path: Output folder (must not exist unless ``overwrite``).
        overwrite: Replace an existing bag folder written by this function.
        compress: zstd-compress the MCAP chunks.
        progress: Optional callback called with the number of units written since the last call (messages
            of an F/T recording, stamps of a joint-torque one).

    Returns:
        The bag folder.

    Raises:
        semiparam_ros.errors.BagError: If the folder exists (without ``overwrite``), is not a bag
            folder, or cannot be written.
    """
    path = Path(path)
    if overwrite and path.is_dir():
        (path / SCENARIO_FILE).unlink(missing_ok=True)  # ours; BagWriter replaces bag-only folders
    if isinstance(recording, ArmRecording):
        units, batch_size, topics = _torque_messages, 1000, _torque_topics
    else:
        units, batch_size, topics = _wrench_messages, 2000, _wrench_topics  # type: ignore[assignment]
    batch = 0
    with BagWriter(path, overwrite=overwrite, compress=compress) as bag:
        for _ in units(recording, bag):  # type: ignore[arg-type]
            batch += 1
            if progress is not None and batch == batch_size:
                progress(batch)
                batch = 0
        counts = dict(bag.counts)
    if progress is not None and batch:
        progress(batch)
    info = dict(recording.info)
    info["topics"] = topics(recording, counts)  # type: ignore[arg-type]
    write_sidecar(path, info)
    return path


def _wrench_sets(rec: SimulatedRecording) -> dict[int, tuple[str, np.ndarray, str]]:
    """Return the wrench topics of an F/T recording by write order at equal stamps (after the joints)."""
    sets = {
        2: (WRENCH_TOPIC, rec.measured_wrench, SENSOR_FRAME),
        3: (GROUND_TRUTH_WRENCH_TOPIC, rec.true_wrench, SENSOR_FRAME),
        4: (GROUND_TRUTH_RIGID_TOPIC, rec.rigid_wrench, SENSOR_FRAME),
    }
    if rec.contact_wrench is not None and rec.external_wrench is not None:
        hand_frame = str(rec.info["contacts"]["frame"])
        sets[5] = (GROUND_TRUTH_CONTACT_TOPIC, rec.contact_wrench, hand_frame)
        sets[6] = (GROUND_TRUTH_EXTERNAL_WRENCH_TOPIC, rec.external_wrench, SENSOR_FRAME)
    return sets


def _wrench_messages(rec: SimulatedRecording, bag: BagWriter) -> Iterator[None]:
    """Write an F/T recording's messages in log-time order; yield after each message."""
    names = list(PUBLISHED_JOINT_ORDER)
    arm_index = {name: i for i, name in enumerate(rec.joint_names)}
    arm_cols = np.array([arm_index.get(n, -1) for n in names])
    is_arm = arm_cols >= 0
    fixed_pos = np.array([rec.other_positions.get(n, 0.0) for n in names])
    n_joint = rec.joint_stamps.size
    n_wrench = rec.wrench_stamps.size
    # One merged, log-time ordered stream: (stamp, kind, index). Kinds in write order at equal stamps.
    wrench_sets = _wrench_sets(rec)
    n_kinds = 2 + len(wrench_sets)
    sizes = [n_joint, n_joint] + [n_wrench] * len(wrench_sets)
    stamps = np.concatenate([rec.joint_stamps, rec.joint_stamps] + [rec.wrench_stamps] * len(wrench_sets))
    kinds = np.repeat(np.arange(n_kinds), sizes)
    index = np.concatenate([np.arange(n) for n in sizes])
    order = np.lexsort((kinds, stamps))
    arm_names = list(rec.joint_names)
    for kind, i in zip(kinds[order].tolist(), index[order].tolist(), strict=True):
        if kind == 0:
            position = fixed_pos.copy()
            position[is_arm] = rec.q_measured[i, arm_cols[is_arm]]
            velocity = np.zeros(len(names))
            velocity[is_arm] = rec.dq_measured[i, arm_cols[is_arm]]
            bag.write_joint_state(JOINT_STATES_TOPIC,
                                  JointStateData(int(rec.joint_stamps[i]), names, position, velocity, ()))
        elif kind == 1:
            bag.write_joint_trajectory_point(GROUND_TRUTH_ACCELERATION_TOPIC, int(rec.joint_stamps[i]),
                                             arm_names, rec.q[i], rec.dq[i], rec.ddq[i])
        else:
            topic, values, frame = wrench_sets[kind]
            w = values[i]
            bag.write_wrench(topic, WrenchData(int(rec.wrench_stamps[i]), frame, w[:3], w[3:]))
        yield


def _wrench_topics(rec: SimulatedRecording, counts: dict[str, int]) -> dict[str, dict[str, object]]:
    topics: dict[str, dict[str, object]] = {
        JOINT_STATES_TOPIC: {"type": _JOINT_STATE, "count": counts.get(JOINT_STATES_TOPIC, 0),
                             "names": list(PUBLISHED_JOINT_ORDER)},
        WRENCH_TOPIC: {"type": _WRENCH, "count": counts.get(WRENCH_TOPIC, 0), "frame_id": SENSOR_FRAME},
        GROUND_TRUTH_WRENCH_TOPIC: {"type": _WRENCH, "count": counts.get(GROUND_TRUTH_WRENCH_TOPIC, 0)},
        GROUND_TRUTH_RIGID_TOPIC: {"type": _WRENCH, "count": counts.get(GROUND_TRUTH_RIGID_TOPIC, 0)},
        GROUND_TRUTH_ACCELERATION_TOPIC: {"type": _TRAJECTORY,
                                          "count": counts.get(GROUND_TRUTH_ACCELERATION_TOPIC, 0)},
    }
    sets = _wrench_sets(rec)
    for kind in (5, 6):
        if kind in sets:
            topic, _, frame = sets[kind]
            topics[topic] = {"type": _WRENCH, "count": counts.get(topic, 0), "frame_id": frame}
    return topics


def _torque_messages(rec: ArmRecording, bag: BagWriter) -> Iterator[None]:
    """Write a joint-torque recording's messages, stamp by stamp; yield after each stamp."""
    names = list(rec.joint_names)
    contacts = rec.config.contacts is not None
    frame = rec.robot.end_effector
    empty = np.empty(0)
    for i, stamp in enumerate(rec.stamps.tolist()):
        bag.write_joint_state(JOINT_STATES_TOPIC, JointStateData(stamp, names, rec.q_measured[i],
                                                                 rec.dq_measured[i], rec.measured_torques[i]))
        bag.write_joint_trajectory_point(GROUND_TRUTH_ACCELERATION_TOPIC, stamp, names, rec.q[i], rec.dq[i],
                                         rec.ddq[i])
        bag.write_joint_state(GROUND_TRUTH_TORQUES_TOPIC,
                              JointStateData(stamp, names, rec.q[i], rec.dq[i], rec.true_torques[i]))
        bag.write_joint_state(GROUND_TRUTH_RIGID_TORQUES_TOPIC,
                              JointStateData(stamp, names, empty, empty, rec.rigid_torques[i]))
        bag.write_joint_state(GROUND_TRUTH_FRICTION_TOPIC,
                              JointStateData(stamp, names, empty, empty, rec.friction_torques[i]))
        if rec.wrench is not None:
            w, truth = rec.wrench.measured[i], rec.wrench.true[i]
            bag.write_wrench(WRENCH_TOPIC, WrenchData(stamp, rec.wrench.frame, w[:3], w[3:]))
            bag.write_wrench(GROUND_TRUTH_WRENCH_TOPIC,
                             WrenchData(stamp, rec.wrench.frame, truth[:3], truth[3:]))
        if contacts:
            bag.write_joint_state(GROUND_TRUTH_EXTERNAL_TORQUES_TOPIC,
                                  JointStateData(stamp, names, empty, empty, rec.external_torques[i]))
            w = rec.contact_wrench[i]
            bag.write_wrench(GROUND_TRUTH_CONTACT_TOPIC, WrenchData(stamp, frame, w[:3], w[3:]))
        yield


def _torque_topics(rec: ArmRecording, counts: dict[str, int]) -> dict[str, dict[str, object]]:
    topics: dict[str, dict[str, object]] = {
        JOINT_STATES_TOPIC: {"type": _JOINT_STATE, "fields": "position, velocity, effort (measured torques)"},
        GROUND_TRUTH_ACCELERATION_TOPIC: {"type": _TRAJECTORY},
        GROUND_TRUTH_TORQUES_TOPIC: {"type": _JOINT_STATE,
                                     "fields": "position, velocity, effort (noise-free)"},
        GROUND_TRUTH_RIGID_TORQUES_TOPIC: {"type": _JOINT_STATE, "fields": "effort"},
        GROUND_TRUTH_FRICTION_TOPIC: {"type": _JOINT_STATE, "fields": "effort"},
    }
    if rec.wrench is not None:
        topics[WRENCH_TOPIC] = {"type": _WRENCH, "frame_id": rec.wrench.frame}
        topics[GROUND_TRUTH_WRENCH_TOPIC] = {"type": _WRENCH, "frame_id": rec.wrench.frame,
                                             "fields": "the reading without noise"}
    if rec.config.contacts is not None:
        topics[GROUND_TRUTH_EXTERNAL_TORQUES_TOPIC] = {"type": _JOINT_STATE, "fields": "effort (-J^T F)"}
        topics[GROUND_TRUTH_CONTACT_TOPIC] = {"type": _WRENCH, "frame_id": rec.robot.end_effector}
    for topic, entry in topics.items():
        entry["count"] = counts.get(topic, 0)
    return topics
