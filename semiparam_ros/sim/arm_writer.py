"""Write an :class:`~semiparam_ros.sim.arms.ArmRecording` as a rosbag2/MCAP bag with a sidecar.

Topics (every stamp is the sampling instant; log time = header stamp; messages in log-time order; joints in
the robot's order):

* ``/joint_states`` (``sensor_msgs/msg/JointState``): noisy position (rad), velocity (rad/s) and the
  measured joint torques in ``effort`` (N·m); no accelerations.
* ``/ground_truth/joint_accelerations`` (``trajectory_msgs/msg/JointTrajectory``): one point with the true
  q, q̇, q̈ (rad, rad/s, rad/s²).
* ``/ground_truth/joint_torques`` (JointState): true q, q̇ and the noise-free measured torques (N·m):
  rigid body + friction + contact.
* ``/ground_truth/joint_torques/rigid_body`` (JointState, effort only): Φ(q, q̇, q̈) π(t), the true
  parameters with the payload after the pickup (N·m).
* ``/ground_truth/joint_torques/friction`` (JointState, effort only): f_v q̇ + f_c tanh(q̇/v_s) + o + a q̈
  (N·m).

With contact episodes (zero outside them):

* ``/ground_truth/external_joint_torques`` (JointState, effort only): the contact's effect on the measured
  torques, ``−J(q)ᵀ F`` (N·m): what ``external = measured − predicted`` estimates.
* ``/ground_truth/contact_wrench`` (``geometry_msgs/msg/WrenchStamped``): the applied force at the
  end-effector frame's origin, in that frame (N; torque 0).

``scenario.yaml`` holds the true parameters (URDF, perturbed, after the payload; full and base), friction
coefficients and offsets, noise levels, payload, contact episodes and the topics.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from semiparam_ros.core.messages import JointStateData, WrenchData
from semiparam_ros.io.bags import BagWriter
from semiparam_ros.sim.arms import ArmRecording
from semiparam_ros.sim.writer import (
    GROUND_TRUTH_ACCELERATION_TOPIC,
    GROUND_TRUTH_CONTACT_TOPIC,
    SCENARIO_FILE,
    write_sidecar,
)

__all__ = [
    "GROUND_TRUTH_EXTERNAL_TORQUES_TOPIC",
    "GROUND_TRUTH_FRICTION_TOPIC",
    "GROUND_TRUTH_RIGID_TORQUES_TOPIC",
    "GROUND_TRUTH_TORQUES_TOPIC",
    "write_arm_recording",
]

JOINT_STATES_TOPIC = "/joint_states"
GROUND_TRUTH_TORQUES_TOPIC = "/ground_truth/joint_torques"
GROUND_TRUTH_RIGID_TORQUES_TOPIC = "/ground_truth/joint_torques/rigid_body"
GROUND_TRUTH_FRICTION_TOPIC = "/ground_truth/joint_torques/friction"
GROUND_TRUTH_EXTERNAL_TORQUES_TOPIC = "/ground_truth/external_joint_torques"

_JOINT_STATE = "sensor_msgs/msg/JointState"


def write_arm_recording(
    recording: ArmRecording,
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
        progress: Optional callback called with the number of stamps written since the last call.

    Returns:
        The bag folder.

    Raises:
        semiparam_ros.errors.BagError: If the folder exists (without ``overwrite``), is not a bag folder,
            or cannot be written.
    """
    path = Path(path)
    if overwrite and path.is_dir():
        (path / SCENARIO_FILE).unlink(missing_ok=True)  # ours; BagWriter replaces bag-only folders
    rec = recording
    names = list(rec.joint_names)
    contacts = rec.config.contacts is not None
    frame = rec.robot.end_effector
    empty = np.empty(0)
    batch = 0
    with BagWriter(path, overwrite=overwrite, compress=compress) as bag:
        for i, stamp in enumerate(rec.stamps.tolist()):
            bag.write_joint_state(
                JOINT_STATES_TOPIC,
                JointStateData(stamp, names, rec.q_measured[i], rec.dq_measured[i], rec.measured_torques[i]),
            )
            bag.write_joint_trajectory_point(
                GROUND_TRUTH_ACCELERATION_TOPIC, stamp, names, rec.q[i], rec.dq[i], rec.ddq[i]
            )
            bag.write_joint_state(
                GROUND_TRUTH_TORQUES_TOPIC,
                JointStateData(stamp, names, rec.q[i], rec.dq[i], rec.true_torques[i]),
            )
            bag.write_joint_state(
                GROUND_TRUTH_RIGID_TORQUES_TOPIC,
                JointStateData(stamp, names, empty, empty, rec.rigid_torques[i]),
            )
            bag.write_joint_state(
                GROUND_TRUTH_FRICTION_TOPIC,
                JointStateData(stamp, names, empty, empty, rec.friction_torques[i]),
            )
            if contacts:
                bag.write_joint_state(
                    GROUND_TRUTH_EXTERNAL_TORQUES_TOPIC,
                    JointStateData(stamp, names, empty, empty, rec.external_torques[i]),
                )
                w = rec.contact_wrench[i]
                bag.write_wrench(GROUND_TRUTH_CONTACT_TOPIC, WrenchData(stamp, frame, w[:3], w[3:]))
            batch += 1
            if progress is not None and batch == 1000:
                progress(batch)
                batch = 0
        counts = dict(bag.counts)
    if progress is not None and batch:
        progress(batch)
    topics: dict[str, dict[str, object]] = {
        JOINT_STATES_TOPIC: {"type": _JOINT_STATE, "fields": "position, velocity, effort (measured torques)"},
        GROUND_TRUTH_ACCELERATION_TOPIC: {"type": "trajectory_msgs/msg/JointTrajectory"},
        GROUND_TRUTH_TORQUES_TOPIC: {
            "type": _JOINT_STATE,
            "fields": "position, velocity, effort (noise-free)",
        },
        GROUND_TRUTH_RIGID_TORQUES_TOPIC: {"type": _JOINT_STATE, "fields": "effort"},
        GROUND_TRUTH_FRICTION_TOPIC: {"type": _JOINT_STATE, "fields": "effort"},
    }
    if contacts:
        topics[GROUND_TRUTH_EXTERNAL_TORQUES_TOPIC] = {"type": _JOINT_STATE, "fields": "effort (-J^T F)"}
        topics[GROUND_TRUTH_CONTACT_TOPIC] = {"type": "geometry_msgs/msg/WrenchStamped", "frame_id": frame}
    for topic, entry in topics.items():
        entry["count"] = counts.get(topic, 0)
    info = dict(rec.info)
    info["topics"] = topics
    write_sidecar(path, info)
    return path
