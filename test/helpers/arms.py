"""References on the real arms' URDFs: random states and Pinocchio RNEA."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from helpers.dynamics import reference_model as dynamics_reference_model
from helpers.dynamics import reference_torques, reference_wrench
from semiparam_ros.core.config import EstimatorConfig


# ---------------------------------------------------------------- independent reference (plain Pinocchio)
def reference_model(config: EstimatorConfig, sensor: str | None = None) -> pin.Model:
    """The URDF's model built without the code under test (test_dynamics' reference, from a config)."""
    return dynamics_reference_model(config.urdf_path().read_text(), config["robot.joints"], sensor,
                                    config.locked, gravity=config["robot.gravity"])


def reference_rnea(model: pin.Model, joints, q, dq, ddq, sensor: str | None = None) -> np.ndarray:
    """Joint torques [N·m], or the F/T reading [N, N·m] through ``sensor``, from plain RNEA."""
    if sensor is None:
        return reference_torques(model, joints, q, dq, ddq)
    return reference_wrench(model, joints, sensor, q, dq, ddq)


def random_state(config: EstimatorConfig, rng: np.random.Generator):
    n = len(config["robot.joints"])
    return rng.uniform(-1.5, 1.5, n), rng.normal(0, 1.0, n), rng.normal(0, 5.0, n)
