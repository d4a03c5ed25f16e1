"""Magnitudes of each part of the simulated Panda and UR5 joint torques (RMS per joint, N·m).

Run from the repository root::

    PYTHONPATH=$PWD .venv/bin/python bench/sim/sim_arm_magnitudes.py

Simulates the 120 s ``contacts`` scenario of each arm at 100 Hz (seed 0) and prints, per joint, the RMS of
the measured torque, its rigid-body part, the CAD error (RNEA with the URDF's parameters minus RNEA with the
true ones), friction + offsets and noise before the pickup, the payload's effect after it, and the contacts'
effect during the episodes. The table is in ``bags/README.md``.
"""

from __future__ import annotations

import numpy as np

from semiparam_ros.sim.arms import arm_regressor, simulate_arm
from semiparam_ros.sim.generate import preset_configs


def _rms(x: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(np.asarray(x) ** 2, axis=0))


def main() -> None:
    """Print the table."""
    for robot in ("panda", "ur5"):
        (config,) = preset_configs(robot, ("contacts",), rate=100.0)
        rec = simulate_arm(config)
        reg = arm_regressor(robot)
        phi = reg.regressor(rec.q, rec.dq, rec.ddq)
        before = (rec.stamps - rec.stamps[0]) * 1e-9 < config.pickup_time
        in_contact = np.linalg.norm(rec.external_torques, axis=1) > 0
        print(
            robot,
            "episodes",
            len(rec.contact_episodes),
            "peak N",
            [round(e.peak_force, 1) for e in rec.contact_episodes],
            "duration s",
            [round(e.duration, 2) for e in rec.contact_episodes],
        )
        rows = (
            ("measured torque", rec.measured_torques[before]),
            ("rigid (true)", rec.rigid_torques[before]),
            ("CAD error (URDF RNEA - true rigid)", (phi @ rec.parameters_urdf - rec.rigid_torques)[before]),
            ("friction+offset", rec.friction_torques[before]),
            ("noise", (rec.measured_torques - rec.true_torques)[before]),
            ("payload effect (after)", (rec.rigid_torques - phi @ rec.parameters_before)[~before]),
            ("contact effect (in episodes)", rec.external_torques[in_contact]),
        )
        for name, values in rows:
            print(f"  {name:38s}", " ".join(f"{v:6.3f}" for v in _rms(values)))


if __name__ == "__main__":
    main()
