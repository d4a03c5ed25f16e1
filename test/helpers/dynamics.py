"""Independent rigid-body references: Pinocchio RNEA on a model built here, not by the package."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

G = 9.81


# ---------------------------------------------------------------- independent reference (plain Pinocchio)
def reference_model(urdf_text, joints, sensor=None, locked=None, gravity=(0, 0, -G)):
    """Reduced model built without the code under test; the sensor joint becomes a revolute joint at 0."""
    root = ET.fromstring(urdf_text)
    if sensor is not None:
        for j in root.findall("joint"):
            if j.get("name") == sensor:
                j.set("type", "revolute")
                ET.SubElement(j, "axis", xyz="0 0 1")
                ET.SubElement(j, "limit", effort="1", velocity="1", lower="-1", upper="1")
    full = pin.buildModelFromXML(ET.tostring(root, encoding="unicode"))
    q0 = pin.neutral(full)
    for name, val in (locked or {}).items():
        jm = full.joints[full.getJointId(name)]
        if jm.nq == 2:
            q0[jm.idx_q : jm.idx_q + 2] = np.cos(val), np.sin(val)
        else:
            q0[jm.idx_q] = val
    keep = set(joints) | ({sensor} if sensor else set())
    lock = [j for j in range(1, full.njoints) if full.names[j] not in keep]
    model = pin.buildReducedModel(full, lock, q0)
    model.gravity = pin.Motion(np.asarray(gravity, float), np.zeros(3))
    return model


def reference_state(model, joints, q, dq, ddq):
    qf, vf, af = pin.neutral(model), np.zeros(model.nv), np.zeros(model.nv)
    for i, name in enumerate(joints):
        jm = model.joints[model.getJointId(name)]
        if jm.nq == 2:  # continuous joint: (cos, sin)
            qf[jm.idx_q : jm.idx_q + 2] = np.cos(q[i]), np.sin(q[i])
        else:
            qf[jm.idx_q] = q[i]
        vf[jm.idx_v], af[jm.idx_v] = dq[i], ddq[i]
    return qf, vf, af


def reference_wrench(model, joints, sensor, q, dq, ddq):
    """Sensor reading from RNEA: minus the force transmitted to the subtree, in the joint frame."""
    data = model.createData()
    pin.rnea(model, data, *reference_state(model, joints, q, dq, ddq))
    f = data.f[model.getJointId(sensor)]
    return -np.concatenate([f.linear, f.angular])


def reference_torques(model, joints, q, dq, ddq):
    data = model.createData()
    tau = pin.rnea(model, data, *reference_state(model, joints, q, dq, ddq))
    return np.array([tau[model.joints[model.getJointId(n)].idx_v] for n in joints])
