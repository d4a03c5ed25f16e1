"""Where URDF frames sit on the regressor's bodies and in the base: the simulator's kinematic queries.

The regressor (:class:`~semiparam_ros.core.rigid_body.dynamics.RigidBodyRegressor`) lumps links into bodies; a
payload or a contact is placed on a body through the frame it is attached to. Poses are 4×4 homogeneous
transforms [m] in the URDF root (base) frame or in a body frame (the frame its parameters are expressed in).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.errors import ConfigurationError

__all__ = ["body_placement", "frame_in_body", "frame_placement"]


def _frame_id(reg: RigidBodyRegressor, frame_name: str) -> int:
    model = reg.pinocchio_model
    if not isinstance(frame_name, str) or not model.existFrame(frame_name):
        raise ConfigurationError(f"unknown frame {frame_name!r}: not a link or joint of the URDF")
    return int(model.getFrameId(frame_name))


def frame_in_body(reg: RigidBodyRegressor, frame_name: str) -> tuple[str, np.ndarray]:
    """Return the body a URDF frame (link or joint) is rigidly attached to, and its pose there.

    Use it to place a payload: a point at ``p`` in the frame is at ``T[:3, :3] @ p + T[:3, 3]`` in the
    body frame, whose parameter slot is ``reg.body_index(body)``.

    Args:
        reg: The regressor.
        frame_name: Name of a link or joint of the URDF (e.g. ``"r_hand_dh_frame"``).

    Returns:
        (body name, 4×4 homogeneous transform of the frame in the body frame, m).

    Raises:
        ConfigurationError: If the frame is unknown or not attached to one of ``reg.body_names``.
    """
    frame = reg.pinocchio_model.frames[_frame_id(reg, frame_name)]
    hits = np.flatnonzero(reg.body_joint_ids == int(frame.parentJoint))
    if hits.size == 0:
        raise ConfigurationError(
            f"frame {frame_name!r} is not attached to a body of the regressor ({list(reg.body_names)})")
    return reg.body_names[int(hits[0])], frame.placement.homogeneous.copy()


def frame_placement(reg: RigidBodyRegressor, q: Any, frame_name: str) -> np.ndarray:
    """Return the pose of a URDF frame in the base (URDF root) frame at joint positions q [rad].

    Raises:
        RejectedSampleError: On a bad q.
        ConfigurationError: On an unknown frame.
    """
    fid = _frame_id(reg, frame_name)
    model = reg.pinocchio_model
    data = model.createData()
    pin.forwardKinematics(model, data, reg.configuration(q))
    return pin.updateFramePlacement(model, data, fid).homogeneous.copy()


def body_placement(reg: RigidBodyRegressor, q: Any, body_name: str) -> np.ndarray:
    """Return the pose of a body frame (its parameters' frame) in the base frame at joint positions q [rad].

    Raises:
        RejectedSampleError: On a bad q.
        ConfigurationError: On an unknown body.
    """
    jid = int(reg.body_joint_ids[reg.body_index(body_name)])
    model = reg.pinocchio_model
    data = model.createData()
    pin.forwardKinematics(model, data, reg.configuration(q))
    return data.oMi[jid].homogeneous.copy()
