"""A UR5 joint-torque bag and its configuration, written for the evaluation tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from helpers import REPO

ROOT = REPO


CONFIG = ROOT / "config" / "icub_right_arm.yaml"


# --------------------------------------------------------------------------- joint torques
UR5_URDF = "example-robot-data://robots/ur_description/urdf/ur5_robot.urdf"


UR5_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
              "wrist_3_joint")


def write_ur5_torque_bag(path: Path, seconds: float, seed: int, rate_hz: float = 100.0) -> None:
    """A 6-joint JointState bag whose efforts are Pinocchio's RNEA torques (N·m) of a smooth motion, plus
    viscous friction (which the parametric stage's friction columns express), a position-dependent elastic
    torque (a cable or spring: which no rigid-body + friction model expresses) and sensor noise."""
    import pinocchio as pin

    from semiparam_ros.core.rigid_body.urdf import example_robot_data_path
    from semiparam_ros.core.stream.messages import JointStateData
    from semiparam_ros.io.bags import BagWriter

    model = pin.buildModelFromUrdf(str(example_robot_data_path(UR5_URDF.split("://", 1)[1])))
    data = model.createData()
    rng = np.random.default_rng(seed)
    amp, freq, phase = rng.uniform(0.3, 0.8, 6), rng.uniform(0.1, 0.3, 6), rng.uniform(0, 2 * np.pi, 6)
    with BagWriter(path) as writer:
        for k in range(int(seconds * rate_hz)):
            t = k / rate_hz
            w = 2 * np.pi * freq
            q = amp * np.sin(w * t + phase)
            dq = amp * w * np.cos(w * t + phase)
            ddq = -amp * w * w * np.sin(w * t + phase)
            tau = (pin.rnea(model, data, q, dq, ddq) + 0.5 * dq + 0.3 * np.sin(3.0 * q)
                   + 0.01 * rng.normal(size=6))
            msg = JointStateData(stamp_ns=1_000_000_000 + round(t * 1e9), names=UR5_JOINTS, position=q,
                                 velocity=dq, effort=tau)
            writer.write_joint_state("/joint_states", msg)


def ur5_config():
    from semiparam_ros.core.config import load_config

    return load_config(CONFIG).with_overrides({
        "robot.urdf": UR5_URDF, "robot.joints": list(UR5_JOINTS), "robot.locked_joints": [],
        "robot.locked_positions": [], "robot.output": "joint_torques", "nonparametric.n_features": 100,
        "nonparametric.standardizer_warmup": 100, "parametric.friction": False, "parametric.offsets": False})


def learned_panda_checkpoint(root: Path, name: str, *, seed: int, n_features: int) -> Path:
    """A checkpoint of config/panda.yaml (D = ``n_features``) learned by ``learn`` from 20 s of a simulated
    Panda at 200 Hz (known truth): what a node warm-starts from in the feed-forward tests."""
    from semiparam_ros.core.config import load_config
    from semiparam_ros.serving.bag_learning import learn_bags
    from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
    from semiparam_ros.sim.writer import write_recording

    rec = simulate_arm(ArmScenarioConfig(name=name, robot="panda", duration=20.0, rate=200.0, seed=seed))
    bag = write_recording(rec, root / name)
    config = load_config(REPO / "config" / "panda.yaml")
    config = config.with_overrides({"nonparametric.n_features": n_features})
    learn_bags([bag], config, checkpoint=root / "panda.npz")
    return root / "panda.npz"
