"""Tests of semiparam_ros.core.rigid_body.dynamics against Pinocchio's RNEA on independently built models."""

from __future__ import annotations

import copy
import pickle
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest
from helpers.dynamics import G, reference_model, reference_state, reference_torques, reference_wrench

from semiparam_ros.core.rigid_body.dynamics import (
    INERTIAL_PARAMETER_NAMES,
    RigidBodyRegressor,
    is_physically_consistent,
    point_mass_parameters,
)
from semiparam_ros.core.rigid_body.urdf import icub_urdf_path
from semiparam_ros.errors import ConfigurationError, RejectedSampleError
from semiparam_ros.sim.frames import body_placement, frame_in_body, frame_placement

ICUB_JOINTS = ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]
ICUB_SENSOR = "r_arm_ft_sensor"
UR5_JOINTS = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
]
UR5_SENSOR = "ft_sensor_joint"
SENSOR_MASS, TOOL_MASS = 0.3, 1.2










def random_states(reg, rng, k):
    lo, hi = reg.position_limits()
    q = rng.uniform(lo, hi, size=(k, reg.n_joints))
    return q, rng.normal(0, 2.0, size=q.shape), rng.normal(0, 10.0, size=q.shape)


def link_subtree(urdf_text, link):
    """Links at and beyond `link` (URDF tree walk)."""
    root = ET.fromstring(urdf_text)
    children = {}
    for j in root.findall("joint"):
        children.setdefault(j.find("parent").get("link"), []).append(j.find("child").get("link"))
    out, stack = [], [link]
    while stack:
        cur = stack.pop()
        out.append(cur)
        stack.extend(children.get(cur, []))
    return out


def link_mass(urdf_text, names):
    root = ET.fromstring(urdf_text)
    total = 0.0
    for link in root.findall("link"):
        mass = link.find("inertial/mass")
        if link.get("name") in names and mass is not None:
            total += float(mass.get("value"))
    return total


# ---------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def icub_text():
    return icub_urdf_path().read_text()


@pytest.fixture(scope="module")
def icub():
    return RigidBodyRegressor.from_urdf(icub_urdf_path(), ICUB_JOINTS, ft_sensor=ICUB_SENSOR)


@pytest.fixture(scope="module")
def ur5_path(tmp_path_factory):
    """UR5 from example-robot-data with an F/T sensor at the flange (tool0) and a tool beyond it."""
    src = icub_urdf_path().parents[2] / "ur_description" / "urdf" / "ur5_robot.urdf"
    root = ET.parse(src).getroot()

    def add_link(name, mass, com, inertia):
        link = ET.SubElement(root, "link", name=name)
        inertial = ET.SubElement(link, "inertial")
        ET.SubElement(inertial, "origin", xyz=" ".join(map(str, com)), rpy="0.1 -0.2 0.3")
        ET.SubElement(inertial, "mass", value=str(mass))
        ixx, iyy, izz = inertia
        ET.SubElement(
            inertial, "inertia", ixx=str(ixx), ixy="0", ixz="0", iyy=str(iyy), iyz="0", izz=str(izz)
        )

    def add_fixed(name, parent, child, xyz, rpy):
        joint = ET.SubElement(root, "joint", name=name, type="fixed")
        ET.SubElement(joint, "origin", xyz=xyz, rpy=rpy)
        ET.SubElement(joint, "parent", link=parent)
        ET.SubElement(joint, "child", link=child)

    # The sensor's distal half, then a tool with an off-axis centre of mass.
    add_link("ft_sensor_link", SENSOR_MASS, (0.0, 0.0, 0.01), (2e-4, 2e-4, 3e-4))
    add_link("tool_link", TOOL_MASS, (0.03, -0.02, 0.08), (4e-3, 5e-3, 2e-3))
    add_fixed(UR5_SENSOR, "tool0", "ft_sensor_link", "0 0 0.005", "0 0 0.7")
    add_fixed("tool_joint", "ft_sensor_link", "tool_link", "0 0 0.03", "0.2 0 0")
    path = tmp_path_factory.mktemp("ur5") / "ur5_ft.urdf"
    path.write_text(ET.tostring(root, encoding="unicode"))
    return path


# ---------------------------------------------------------------- iCub F/T sensor
def test_icub_layout(icub):
    assert icub.joint_names == tuple(ICUB_JOINTS)
    assert icub.n_outputs == 6 and icub.n_joints == 4
    assert icub.body_names == ("r_upper_arm", "r_elbow_1")
    assert icub.n_params == 20 == len(icub.parameter_names)
    assert icub.parameter_names[:10] == tuple(f"{p}_r_upper_arm" for p in INERTIAL_PARAMETER_NAMES)
    assert icub.sensor_frame == ICUB_SENSOR
    assert icub.distal_body_name == "r_elbow_1"
    assert icub.body_index("r_elbow_1") == 1


@pytest.mark.parametrize(
    "locked",
    [
        None,
        {
            "r_wrist_prosup": 0.4,
            "r_wrist_pitch": -0.6,
            "r_wrist_yaw": 0.2,
            "torso_pitch": 0.3,
            "torso_yaw": -0.5,
        },
    ],
)
def test_icub_wrench_matches_rnea(icub_text, locked):
    reg = RigidBodyRegressor.from_urdf(icub_urdf_path(), ICUB_JOINTS, ft_sensor=ICUB_SENSOR, locked=locked)
    ref = reference_model(icub_text, ICUB_JOINTS, ICUB_SENSOR, locked)
    rng = np.random.default_rng(1)
    pi = reg.urdf_parameters()
    for q, dq, ddq in zip(*random_states(reg, rng, 25), strict=True):
        expected = reference_wrench(ref, ICUB_JOINTS, ICUB_SENSOR, q, dq, ddq)
        np.testing.assert_allclose(reg.regressor(q, dq, ddq) @ pi, expected, rtol=0, atol=1e-10)
        np.testing.assert_allclose(reg.wrench(q, dq, ddq), expected, rtol=0, atol=1e-10)


def test_icub_static_force_is_distal_weight(icub, icub_text):
    distal_mass = link_mass(icub_text, link_subtree(icub_text, "r_upper_arm"))
    assert distal_mass > 1.0
    ref = reference_model(icub_text, ICUB_JOINTS, ICUB_SENSOR)
    data = ref.createData()
    rng = np.random.default_rng(2)
    zero = np.zeros(4)
    for q in random_states(icub, rng, 10)[0]:
        w = icub.wrench(q, zero, zero)
        assert np.linalg.norm(w[:3]) == pytest.approx(distal_mass * G, rel=1e-12)
        # The force is the distal weight: it points along gravity once rotated to the base frame.
        pin.forwardKinematics(ref, data, reference_state(ref, ICUB_JOINTS, q, zero, zero)[0])
        rot = data.oMi[ref.getJointId(ICUB_SENSOR)].rotation
        np.testing.assert_allclose(rot @ w[:3], [0, 0, -distal_mass * G], atol=1e-10)


def test_regressor_batch_equals_single_and_returns_fresh_arrays(icub):
    rng = np.random.default_rng(3)
    qs, dqs, ddqs = random_states(icub, rng, 5)
    batch = icub.regressor(qs, dqs, ddqs)
    assert batch.shape == (5, 6, 20)
    first = icub.regressor(qs[0], dqs[0], ddqs[0])
    for i in range(5):
        np.testing.assert_array_equal(batch[i], icub.regressor(qs[i], dqs[i], ddqs[i]))
    np.testing.assert_array_equal(first, batch[0])  # not overwritten by later calls


def test_payload_point_mass_in_distal_slot_matches_rnea(icub, icub_text):
    """The simulator's payload recipe: urdf_parameters() + point_mass_parameters() in the hand body's slot."""
    body, T = frame_in_body(icub, "r_hand_dh_frame")
    assert body == icub.distal_body_name
    p_body = T[:3, :3] @ np.array([0.02, 0.0, 0.05]) + T[:3, 3]
    mass = 0.5
    pi = icub.urdf_parameters()
    i = icub.body_index(body)
    pi[10 * i : 10 * i + 10] += point_mass_parameters(mass, p_body)

    ref = reference_model(icub_text, ICUB_JOINTS, ICUB_SENSOR)
    jid = ref.getJointId("r_elbow")
    ref.inertias[jid] = ref.inertias[jid] + pin.Inertia(mass, p_body, np.zeros((3, 3)))
    rng = np.random.default_rng(4)
    for q, dq, ddq in zip(*random_states(icub, rng, 10), strict=True):
        expected = reference_wrench(ref, ICUB_JOINTS, ICUB_SENSOR, q, dq, ddq)
        np.testing.assert_allclose(icub.wrench(q, dq, ddq, pi), expected, atol=1e-10)
        # The hand pose agrees with Pinocchio's forward kinematics on the reference model.
        data = ref.createData()
        pin.framesForwardKinematics(ref, data, reference_state(ref, ICUB_JOINTS, q, dq, ddq)[0])
        fid = ref.getFrameId("r_hand_dh_frame")
        np.testing.assert_allclose(
            frame_placement(icub, q, "r_hand_dh_frame"), data.oMf[fid].homogeneous, atol=1e-12
        )
        np.testing.assert_allclose(body_placement(icub, q, body) @ T, data.oMf[fid].homogeneous, atol=1e-12)


def test_point_mass_parameters_match_pinocchio_inertia():
    c = np.array([0.1, -0.2, 0.05])
    expected = pin.Inertia(2.5, c, np.zeros((3, 3))).toDynamicParameters()
    np.testing.assert_allclose(point_mass_parameters(2.5, c), expected, atol=1e-15)
    with pytest.raises(ValueError, match="mass"):
        point_mass_parameters(-1.0, c)
    with pytest.raises(ValueError, match="position"):
        point_mass_parameters(1.0, [0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="shape"):
        point_mass_parameters(1.0, [0.0, 0.0])


def test_limits_come_from_urdf(icub_text):
    reg = RigidBodyRegressor.from_urdf(
        icub_urdf_path(), ["r_elbow", "r_shoulder_pitch"], ft_sensor=ICUB_SENSOR
    )
    lo, hi = reg.position_limits()
    np.testing.assert_allclose(lo, [0.0959931, -1.65806])
    np.testing.assert_allclose(hi, [1.85005, 0.0872665])
    np.testing.assert_allclose(reg.velocity_limits(), [100.0, 100.0])


# ---------------------------------------------------------------- joint torques
def test_icub_joint_torques_match_rnea(icub_text):
    joints = ["r_elbow", "r_shoulder_pitch", "r_shoulder_yaw", "r_shoulder_roll"]  # not model order
    locked = {"r_wrist_pitch": -0.3, "torso_roll": 0.2}
    reg = RigidBodyRegressor.from_urdf(icub_urdf_path(), joints, output="joint_torques", locked=locked)
    assert reg.output_names == tuple(joints) and reg.n_outputs == 4 and reg.sensor_frame is None
    ref = reference_model(icub_text, joints, None, locked)
    rng = np.random.default_rng(5)
    pi = reg.urdf_parameters()
    # Splitting the bodies at the sensor changes the parameter layout, not the torques.
    split = RigidBodyRegressor.from_urdf(
        icub_urdf_path(), joints, output="joint_torques", locked=locked, ft_sensor=ICUB_SENSOR
    )
    assert split.n_params == reg.n_params + 10 and split.n_base == reg.n_base
    for q, dq, ddq in zip(*random_states(reg, rng, 25), strict=True):
        expected = reference_torques(ref, joints, q, dq, ddq)
        np.testing.assert_allclose(reg.regressor(q, dq, ddq) @ pi, expected, rtol=0, atol=1e-10)
        np.testing.assert_allclose(split.wrench(q, dq, ddq), expected, rtol=0, atol=1e-10)


# ---------------------------------------------------------------- base parameters
@pytest.mark.parametrize("output", ["wrench", "joint_torques"])
def test_base_parameters_reproduce_output_and_have_full_rank(output):
    reg = RigidBodyRegressor.from_urdf(
        icub_urdf_path(), ICUB_JOINTS, ft_sensor=ICUB_SENSOR if output == "wrench" else None, output=output
    )
    rng = np.random.default_rng(6)
    qs, dqs, ddqs = random_states(reg, rng, 60)
    full = reg.regressor(qs, dqs, ddqs).reshape(-1, reg.n_params)
    base = reg.base_regressor(qs, dqs, ddqs).reshape(-1, reg.n_base)
    assert 0 < reg.n_base < reg.n_params
    assert len(reg.base_parameter_names) == reg.n_base
    for pi in (reg.urdf_parameters(), rng.normal(size=reg.n_params)):
        y = full @ pi
        np.testing.assert_allclose(base @ reg.to_base(pi), y, atol=1e-10 * max(1.0, np.abs(y).max()))
    # Φ = Φ_b K on fresh data, and Φ_b has full column rank there.
    np.testing.assert_allclose(base @ reg.base.projection, full, atol=1e-9)
    s = np.linalg.svd(base, compute_uv=False)
    assert s[-1] / s[0] > 1e-6
    assert np.linalg.matrix_rank(full) == reg.n_base


def test_base_parameter_count_is_stable_across_seeds(icub):
    sizes = {icub.compute_base_parameters(seed=s).n_base for s in range(4)}
    assert sizes == {icub.n_base}
    # Deterministic: the same seed gives the same map.
    again = RigidBodyRegressor.from_urdf(icub_urdf_path(), ICUB_JOINTS, ft_sensor=ICUB_SENSOR)
    assert again.base_parameter_names == icub.base_parameter_names
    np.testing.assert_array_equal(again.base.coefficients, icub.base.coefficients)


def test_base_parameter_names_are_readable_combinations(icub):
    names = icub.base_parameter_names
    # The total distal mass is identifiable only as a sum; the elbow-body mass enters the upper-arm moments
    # through the 0.08428 m offset of the elbow joint.
    assert "m_r_upper_arm + m_r_elbow_1" in names
    assert any(n.startswith("mcz_r_upper_arm + 0.08428*m_r_elbow_1") for n in names)
    for name in names:
        for term in name.replace(" - ", " + ").split(" + "):
            assert term.split("*")[-1] in icub.parameter_names


def test_sensor_offset_columns():
    reg = RigidBodyRegressor.from_urdf(
        icub_urdf_path(), ICUB_JOINTS, ft_sensor=ICUB_SENSOR, sensor_offset=True
    )
    plain = RigidBodyRegressor.from_urdf(icub_urdf_path(), ICUB_JOINTS, ft_sensor=ICUB_SENSOR)
    assert reg.n_params == plain.n_params + 6
    assert reg.parameter_names[-6:] == tuple(f"offset_{c}" for c in ("fx", "fy", "fz", "tx", "ty", "tz"))
    q, dq, ddq = (np.full(4, 0.3), np.full(4, 0.2), np.full(4, -1.0))
    phi = reg.regressor(q, dq, ddq)
    np.testing.assert_array_equal(phi[:, -6:], np.eye(6))
    np.testing.assert_array_equal(phi[:, :-6], plain.regressor(q, dq, ddq))
    np.testing.assert_array_equal(reg.urdf_parameters()[-6:], 0.0)
    assert reg.n_base == plain.n_base + 6
    offset = np.arange(1.0, 7.0)
    pi = np.concatenate([plain.urdf_parameters(), offset])
    np.testing.assert_allclose(
        reg.base_regressor(q, dq, ddq) @ reg.to_base(pi), plain.wrench(q, dq, ddq) + offset
    )


# ---------------------------------------------------------------- second robot: UR5 with a flange sensor
def test_ur5_flange_sensor_matches_rnea(ur5_path):
    text = ur5_path.read_text()
    reg = RigidBodyRegressor.from_urdf(ur5_path, UR5_JOINTS, ft_sensor=UR5_SENSOR, gravity=(0.5, -1.0, -9.7))
    assert reg.body_names == ("ft_sensor_link",)  # sensor half and tool lumped beyond the sensor
    assert reg.distal_body_name == "ft_sensor_link"
    ref = reference_model(text, UR5_JOINTS, UR5_SENSOR, gravity=(0.5, -1.0, -9.7))
    rng = np.random.default_rng(7)
    for q, dq, ddq in zip(*random_states(reg, rng, 20), strict=True):
        np.testing.assert_allclose(
            reg.wrench(q, dq, ddq), reference_wrench(ref, UR5_JOINTS, UR5_SENSOR, q, dq, ddq), atol=1e-10
        )
    zero = np.zeros(6)
    w = reg.wrench(rng.uniform(-1, 1, 6), zero, zero)
    assert np.linalg.norm(w[:3]) == pytest.approx(
        (SENSOR_MASS + TOOL_MASS) * np.linalg.norm([0.5, -1.0, -9.7])
    )
    # One body beyond the sensor: the wrench identifies all 10 of its parameters.
    assert reg.n_base == 10


def test_ur5_joint_torques_match_rnea(ur5_path):
    text = ur5_path.read_text()
    reg = RigidBodyRegressor.from_urdf(ur5_path, UR5_JOINTS, output="joint_torques")
    ref = reference_model(text, UR5_JOINTS)
    rng = np.random.default_rng(8)
    pi = reg.urdf_parameters()
    for q, dq, ddq in zip(*random_states(reg, rng, 20), strict=True):
        np.testing.assert_allclose(
            reg.regressor(q, dq, ddq) @ pi, reference_torques(ref, UR5_JOINTS, q, dq, ddq), atol=1e-10
        )
    qs, dqs, ddqs = random_states(reg, rng, 40)
    full = reg.regressor(qs, dqs, ddqs).reshape(-1, reg.n_params)
    np.testing.assert_allclose(
        reg.base_regressor(qs, dqs, ddqs).reshape(-1, reg.n_base) @ reg.to_base(pi), full @ pi, atol=1e-9
    )
    assert {reg.compute_base_parameters(seed=s).n_base for s in (1, 2)} == {reg.n_base}


def test_continuous_joints_moving_and_locked(ur5_path, tmp_path):
    """Continuous joints use (cos, sin) in Pinocchio; q stays an angle in rad for the caller."""
    root = ET.parse(ur5_path).getroot()
    for j in root.findall("joint"):
        if j.get("name") in ("shoulder_pan_joint", "wrist_3_joint"):
            j.set("type", "continuous")
    path = tmp_path / "ur5_continuous.urdf"
    path.write_text(ET.tostring(root, encoding="unicode"))
    joints = UR5_JOINTS[:5]
    locked = {"wrist_3_joint": 2.5}
    reg = RigidBodyRegressor.from_urdf(path, joints, ft_sensor=UR5_SENSOR, locked=locked)
    lo, hi = reg.position_limits()
    assert lo[0] == -np.inf and hi[0] == np.inf and np.isfinite(lo[1:]).all()
    ref = reference_model(path.read_text(), joints, UR5_SENSOR, locked)
    rng = np.random.default_rng(10)
    for _ in range(10):
        q = rng.uniform(-3, 3, 5)
        dq, ddq = rng.normal(size=5), rng.normal(size=5)
        np.testing.assert_allclose(
            reg.wrench(q, dq, ddq), reference_wrench(ref, joints, UR5_SENSOR, q, dq, ddq), atol=1e-10
        )


def test_physical_consistency():
    reg = RigidBodyRegressor.from_urdf(icub_urdf_path(), ICUB_JOINTS, output="joint_torques")
    pi = reg.urdf_parameters().reshape(-1, 10)
    assert all(is_physically_consistent(p) for p in pi if p[0] > 0)
    assert is_physically_consistent(point_mass_parameters(0.5, [0.1, 0.2, -0.3]))  # degenerate but physical
    body = pin.Inertia(2.0, np.array([0.1, 0.0, 0.0]), np.diag([0.01, 0.02, 0.025])).toDynamicParameters()
    assert is_physically_consistent(body)
    assert not is_physically_consistent(np.r_[-1.0, body[1:]])  # negative mass
    bad = pin.Inertia(2.0, np.zeros(3), np.diag([0.01, 0.01, 0.03])).toDynamicParameters()
    assert not is_physically_consistent(bad)  # violates Ixx + Iyy >= Izz
    with pytest.raises(ValueError, match="10 finite"):
        is_physically_consistent(np.zeros(9))


# ---------------------------------------------------------------- copies
def test_pickle_and_deepcopy_rebuild_an_equivalent_regressor(icub):
    rng = np.random.default_rng(9)
    q, dq, ddq = (x[0] for x in random_states(icub, rng, 1))
    for other in (pickle.loads(pickle.dumps(icub)), copy.deepcopy(icub)):
        assert other is not icub and other.parameter_names == icub.parameter_names
        assert other.base_parameter_names == icub.base_parameter_names
        np.testing.assert_array_equal(other.regressor(q, dq, ddq), icub.regressor(q, dq, ddq))
        np.testing.assert_array_equal(other.urdf_parameters(), icub.urdf_parameters())


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"joints": ["r_shoulder_pitch", "r_elbw"]}, "r_elbw"),
        ({"ft_sensor": "r_arm_ft"}, "r_arm_ft"),
        ({"ft_sensor": "r_elbow", "joints": ["r_shoulder_pitch"]}, "fixed"),
        ({"ft_sensor": None}, "ft_sensor"),
        ({"joints": ["r_shoulder_pitch", "r_shoulder_pitch"]}, "more than once"),
        ({"joints": []}, "empty"),
        ({"joints": None}, "sequence"),
        ({"joints": "r_elbow"}, "sequence"),
        ({"locked": [("r_wrist_yaw", 0.1)]}, "mapping"),
        ({"joints": ["r_arm_ft_sensor"], "ft_sensor": None, "output": "joint_torques"}, "r_arm_ft_sensor"),
        ({"locked": {"r_wrist_yw": 0.1}}, "r_wrist_yw"),
        ({"locked": {"r_wrist_yaw": float("nan")}}, "r_wrist_yaw"),
        ({"locked": {"r_elbow": 0.1}}, "r_elbow"),
        ({"gravity": (0.0, np.inf, -9.81)}, "gravity"),
        ({"gravity": (0.0, -9.81)}, "gravity"),
        ({"gravity": ("a", "b", "c")}, "gravity"),
        ({"output": "torques"}, "output"),
    ],
)
def test_bad_construction_raises_value_error(kwargs, match):
    args = {"joints": ICUB_JOINTS, "ft_sensor": ICUB_SENSOR} | kwargs
    joints = args.pop("joints")
    with pytest.raises(ValueError, match=match):
        RigidBodyRegressor.from_urdf(icub_urdf_path(), joints, **args)


def test_missing_urdf_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        RigidBodyRegressor.from_urdf(tmp_path / "nope.urdf", ICUB_JOINTS, ft_sensor=ICUB_SENSOR)


def test_bad_state_vectors_raise_value_error_naming_vector_and_joint(icub):
    ok = np.zeros(4)
    with pytest.raises(ValueError, match=r"^q must have shape \(4,\)"):
        icub.regressor(np.zeros(3), ok, ok)
    with pytest.raises(ValueError, match=r"^ddq must have shape"):
        icub.regressor(ok, ok, np.zeros(5))
    bad = ok.copy()
    bad[2] = np.nan
    with pytest.raises(ValueError, match=r"^dq has non-finite values at joint\(s\) \['r_shoulder_yaw'\]"):
        icub.regressor(ok, bad, ok)
    bad[2] = np.inf
    with pytest.raises(ValueError, match="r_shoulder_yaw"):
        icub.base_regressor(bad, ok, ok)
    # Huge but finite inputs (the squares overflow) are not mistaken for non-finite ones by the fast check;
    # positions enter through sin/cos only, so the regressor stays finite.
    with np.errstate(over="ignore"):
        assert np.all(np.isfinite(icub.regressor(np.full(4, 1e160), ok, ok)))
    mixed = ok.copy()
    mixed[[0, 1]] = [np.inf, -np.inf]
    with pytest.raises(
        ValueError, match=r"q has non-finite values at joint\(s\) \['r_shoulder_pitch', 'r_shoulder_roll'\]"
    ):
        icub.regressor(mixed, ok, ok)
    batch = np.zeros((3, 4))
    batch[1, 3] = np.nan
    with pytest.raises(ValueError, match=r"ddq has non-finite values at joint\(s\) \['r_elbow'\]"):
        icub.regressor(np.zeros((3, 4)), np.zeros((3, 4)), batch)
    with pytest.raises(ValueError, match=r"^dq must be numeric"):
        icub.regressor(ok, ["a", "b", "c", "d"], ok)
    with pytest.raises(ValueError, match="params"):
        icub.wrench(ok, ok, ok, np.zeros(19))
    with pytest.raises(ValueError, match="pi_full"):
        icub.to_base(np.full(20, np.nan))
    with pytest.raises(ValueError, match="unknown body"):
        icub.body_index("r_hand")
    with pytest.raises(ValueError, match="unknown frame"):
        frame_placement(icub, ok, "r_hnd")
    with pytest.raises(ValueError, match="not attached"):
        frame_in_body(icub, "chest")


def test_one_spec_builds_the_same_regressor_as_the_keywords_and_pickles(icub, icub_text):
    """RegressorSpec is the one record of the construction options: the spec and the keyword form give the
    same regressor (Pinocchio's RNEA-independent check: equal matrices at random states), a deep copy
    rebuilds from the spec, a misspelt option is a ConfigurationError naming it."""
    import copy

    from semiparam_ros.core.rigid_body.urdf import RegressorSpec

    spec = RegressorSpec(ICUB_JOINTS, ft_sensor=ICUB_SENSOR)
    by_spec = RigidBodyRegressor(icub_text, spec)
    rng = np.random.default_rng(5)
    q, dq, ddq = (rng.uniform(-1, 1, (4, len(ICUB_JOINTS))) for _ in range(3))
    assert np.array_equal(by_spec.regressor(q, dq, ddq), icub.regressor(q, dq, ddq))
    clone = copy.deepcopy(by_spec)
    assert clone.spec == by_spec.spec
    assert np.array_equal(clone.regressor(q, dq, ddq), icub.regressor(q, dq, ddq))
    with pytest.raises(ConfigurationError, match="ft_sensr"):
        RigidBodyRegressor.from_urdf(icub_urdf_path(), ICUB_JOINTS, ft_sensr=ICUB_SENSOR)
    with pytest.raises(ConfigurationError, match="not both"):
        RigidBodyRegressor.from_urdf(icub_urdf_path(), spec, output="wrench")
    with pytest.raises(ConfigurationError, match="RegressorSpec"):
        RigidBodyRegressor(icub_text, ICUB_JOINTS)  # type: ignore[arg-type]  # the constructor takes a spec


@pytest.mark.parametrize("config_name", ["icub_right_arm.yaml", "panda.yaml"])
def test_base_regressors_of_many_inputs_are_the_rows_one_by_one(config_name):
    """The vectorised base regressor (friction, offset and base columns applied to all rows at once) is
    the per-row one, column factors included: exactly, but for the Coulomb columns' tanh, which numpy may
    round otherwise on a whole array (|Δ| ≤ 2 ulp of values ≤ 1)."""
    from helpers import REPO

    from semiparam_ros.core.config import load_config
    from semiparam_ros.core.estimator.build import build_regressor, column_scale, regressor_function

    cfg = load_config(REPO / "config" / config_name)
    reg = build_regressor(cfg)
    rng = np.random.default_rng(4)
    qs, dqs, ddqs = random_states(reg, rng, 40)
    X = np.ascontiguousarray(np.hstack([qs, dqs, ddqs]))
    factor = 1.0 / column_scale(cfg, reg)
    for f in (None, factor):
        many = reg.base_regressor_of_inputs(X, f)
        rows = np.array([reg.base_regressor_of_input(x, f) for x in X])
        assert many.shape == rows.shape == (40, reg.n_outputs, reg.n_base)
        scale = 1.0 if f is None else np.abs(f).max()
        np.testing.assert_allclose(many, rows, rtol=0.0, atol=4 * np.finfo(float).eps * scale)
    fn = regressor_function(reg, column_scale(cfg, reg))
    np.testing.assert_allclose(fn.many(X), np.array([fn(x) for x in X]), rtol=0.0,
                               atol=4 * np.finfo(float).eps * np.abs(factor).max())
    with pytest.raises(RejectedSampleError):
        reg.base_regressor_of_inputs(X[:, :-1])
