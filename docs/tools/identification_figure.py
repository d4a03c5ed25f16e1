"""The identification chain's before and after, on a simulated arm whose truth is known.

Reads what ``scripts/docs_figures.sh`` wrote — a training bag and a test bag of one simulated arm (other
motion), the exported URDF — and draws two panels: each link's mass in the URDF, in truth and as
exported (a payload on the hand included); and per joint, the RMSE of the rigid-body torques on the test
motion of the URDF before and of the exported URDF after, against the simulator's true rigid-body torques
(``/ground_truth/joint_torques/rigid_body``)::

    .venv/bin/python -m docs.tools.identification_figure TRAIN_BAG TEST_BAG IDENTIFIED.urdf OUT.png
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import yaml

__all__ = ["draw", "main"]


def _rnea_torques(urdf_text: str, joints: list[str], q: np.ndarray, dq: np.ndarray,
                  ddq: np.ndarray) -> np.ndarray:
    from semiparam_ros.core.kinds import OutputKind
    from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
    from semiparam_ros.core.rigid_body.urdf import RegressorSpec

    reg = RigidBodyRegressor(urdf_text, RegressorSpec(tuple(joints), output=OutputKind.JOINT_TORQUES))
    return reg.wrench(q, dq, ddq)


def draw(train_bag: Path, test_bag: Path, identified: Path, out: Path) -> dict[str, object]:
    """Draw the figure; return its numbers (masses and per-joint RMSE) for the page."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from semiparam_ros.atomic import atomic_savefig
    from semiparam_ros.io.bags import read_topic_arrays

    info = yaml.safe_load((train_bag / "scenario.yaml").read_text())
    truth = info["true_parameters"]
    bodies = truth["body_names"]
    urdf_path = Path(info["robot"]["urdf"])
    joints = list(info["joints"])
    masses = {"URDF": np.asarray(truth["urdf"])[0::10][: len(bodies)],
              "truth": np.asarray(truth["after_payload"])[0::10][: len(bodies)]}
    root = ET.parse(identified).getroot()
    masses["exported"] = np.array([float(root.find(f"link[@name='{b}']/inertial/mass").get("value"))
                                   for b in bodies])
    state = read_topic_arrays(test_bag, "/ground_truth/joint_accelerations").fields
    rigid = read_topic_arrays(test_bag, "/ground_truth/joint_torques/rigid_body").fields["effort"]
    q, dq, ddq = state["positions"], state["velocities"], state["accelerations"]
    before = _rnea_torques(urdf_path.read_text(), joints, q, dq, ddq)
    after = _rnea_torques(identified.read_text(), joints, q, dq, ddq)
    rmse = {"URDF (before)": np.sqrt(np.mean((before - rigid) ** 2, axis=0)),
            "exported (after)": np.sqrt(np.mean((after - rigid) ** 2, axis=0))}
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10.5, 3.6))
    width = 0.27
    x = np.arange(len(bodies))
    for k, (label, values) in enumerate(masses.items()):
        ax0.bar(x + (k - 1) * width, values, width, label=label)
    ax0.set_xticks(x, [b.replace("_link", "") for b in bodies], rotation=30, fontsize=8)
    ax0.set_ylabel("link mass [kg]")
    ax0.legend(fontsize=8)
    ax0.set_title("masses (the hand carries a payload)", fontsize=9)
    x = np.arange(len(joints))
    for k, (label, values) in enumerate(rmse.items()):
        ax1.bar(x + (k - 0.5) * 0.4, values, 0.4, label=label)
    ax1.set_xticks(x, [j.replace("_joint", "") for j in joints], rotation=30, fontsize=8)
    ax1.set_yscale("log")
    ax1.set_ylabel("rigid-body torque RMSE on other motion [N·m]")
    ax1.legend(fontsize=8)
    ax1.set_title("the URDF before and after identification", fontsize=9)
    fig.tight_layout()
    try:
        atomic_savefig(fig, out, dpi=110, fmt="png")
    finally:
        plt.close(fig)
    return {"bodies": bodies, "masses": {k: v.tolist() for k, v in masses.items()},
            "joints": joints, "rmse": {k: v.tolist() for k, v in rmse.items()}}


def main(argv: list[str] | None = None) -> int:
    """Draw the figure from the command line (see the module docstring); print its numbers."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 4:
        print(__doc__, file=sys.stderr)
        return 2
    numbers = draw(*(Path(a) for a in args))
    for label, values in numbers["rmse"].items():  # type: ignore[union-attr]
        print(f"{label}: mean rigid-body torque RMSE {np.mean(values):.4f} N·m")
    for label, values in numbers["masses"].items():  # type: ignore[union-attr]
        print(f"{label} masses: " + ", ".join(f"{v:.3f}" for v in values))
    return 0


if __name__ == "__main__":
    sys.exit(main())
