"""Joint-torque arm recordings (Panda, UR5): torques against Pinocchio's RNEA on an independently built model
with the true parameters, friction against its formula, the payload against a body appended by Pinocchio,
contacts against RNEA with external forces, rates and stamps, bag read-back, parameter perturbation, CLI."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import yaml

from semiparam_ros.cli.simulate import main
from semiparam_ros.core.rigid_body.dynamics import is_physically_consistent
from semiparam_ros.core.rigid_body.urdf import resolve_urdf
from semiparam_ros.core.stream.pipeline import SamplePipeline
from semiparam_ros.io.bags import iter_samples, read_messages, read_topic_arrays
from semiparam_ros.sim.arms import (
    ARM_ROBOTS,
    ArmScenarioConfig,
    ParameterPerturbation,
    arm_regressor,
    perturb_parameters,
    simulate_arm,
)
from semiparam_ros.sim.contacts import ContactConfig
from semiparam_ros.sim.generate import preset_configs
from semiparam_ros.sim.writer import write_recording

ROBOTS = ("panda", "ur5")
#: Contacts packed into a short recording: 3 episodes in [0.5, 3.5] s.
SHORT_CONTACTS = ContactConfig(rate=60.0, duration_range=(0.2, 0.6), window=(0.5, 3.5), min_gap=0.2)


def independent_model(robot: str, params: np.ndarray | None = None) -> pin.Model:
    """The arm built straight from the URDF by Pinocchio (other joints locked at 0), with ``params`` set."""
    spec = ARM_ROBOTS[robot]
    full = pin.buildModelFromUrdf(str(resolve_urdf(spec.urdf)))
    lock = [full.getJointId(n) for n in list(full.names)[1:] if n not in spec.joints]
    model = pin.buildReducedModel(full, lock, pin.neutral(full))
    assert tuple(model.names)[1:] == spec.joints  # q columns = model joints, in order
    if params is not None:
        for j in range(1, model.njoints):
            model.inertias[j] = pin.Inertia.FromDynamicParameters(np.asarray(params[10 * (j - 1) : 10 * j]))
    return model


def rnea(model: pin.Model, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
    data = model.createData()
    return np.array([pin.rnea(model, data, q[i], dq[i], ddq[i]).copy() for i in range(q.shape[0])])


def tolerance(tau: np.ndarray) -> float:
    """Φπ and RNEA in double precision: each torque is a sum of ≈10²–10³ products of magnitude ≤ max|τ|·10,
    so both are exact to ≈10³·ε·max|τ| ≈ 1e-13·max|τ|; 1e-10·(1 + max|τ|) keeps a ≥ 10³ margin."""
    return 1e-10 * (1.0 + float(np.abs(tau).max()))


@pytest.fixture(scope="module", params=ROBOTS)
def clean(request):
    """Noise and friction off, payload at 1 s of 2 s, at 1 kHz."""
    config = ArmScenarioConfig(
        name=f"{request.param}_clean",
        robot=request.param,
        duration=2.0,
        rate=1000.0,
        payload_mass=ARM_ROBOTS[request.param].payload_mass,
        payload_time=1.0,
        friction_scale=0.0,
        noise_scale=0.0,
    )
    return simulate_arm(config)


def test_clean_torques_equal_rnea_with_the_true_parameters_before_the_pickup(clean):
    rec = clean
    before = rec.stamps < rec.stamps[0] + 1_000_000_000
    model = independent_model(rec.config.robot, rec.parameters_before)
    expected = rnea(model, rec.q[before], rec.dq[before], rec.ddq[before])
    np.testing.assert_allclose(rec.measured_torques[before], expected, rtol=0, atol=tolerance(expected))
    # The true robot is not the CAD model: the URDF's RNEA differs by far more than round-off.
    cad = rnea(independent_model(rec.config.robot), rec.q[before], rec.dq[before], rec.ddq[before])
    assert np.abs(cad - expected).max() > 1e3 * tolerance(expected)
    assert np.array_equal(rec.measured_torques, rec.true_torques)
    assert np.array_equal(rec.q_measured, rec.q) and np.array_equal(rec.dq_measured, rec.dq)


def test_payload_equals_a_body_appended_at_the_end_effector(clean):
    rec = clean
    spec = rec.robot
    after = rec.stamps >= rec.stamps[0] + 1_000_000_000
    model = independent_model(rec.config.robot, rec.parameters_before)
    frame = model.frames[model.getFrameId(spec.end_effector)]
    placement = frame.placement * pin.SE3(np.eye(3), np.asarray(spec.payload_point))
    model.appendBodyToJoint(
        frame.parentJoint, pin.Inertia(spec.payload_mass, np.zeros(3), np.zeros((3, 3))), placement
    )
    expected = rnea(model, rec.q[after], rec.dq[after], rec.ddq[after])
    np.testing.assert_allclose(rec.measured_torques[after], expected, rtol=0, atol=tolerance(expected))
    info = rec.info["payload"]
    assert (
        info["mass_kg"] == spec.payload_mass and info["time_s"] == 1.0 and info["frame"] == spec.end_effector
    )


@pytest.mark.parametrize("robot", ROBOTS)
def test_friction_and_offsets_follow_the_formula(robot):
    config = ArmScenarioConfig(
        name=f"{robot}_friction", robot=robot, duration=10.0, rate=100.0, noise_scale=0.0, armature=0.05
    )
    rec = simulate_arm(config)
    fr = rec.info["friction"]
    v_s = fr["smoothing_velocity_rad_per_s"]
    expected = (
        np.asarray(fr["viscous_Nms_per_rad"]) * rec.dq
        + np.asarray(fr["coulomb_Nm"]) * np.tanh(rec.dq / v_s)
        + np.asarray(fr["offset_Nm"])
        + np.asarray(fr["armature_kgm2"]) * rec.ddq
    )
    rigid = rnea(independent_model(robot, rec.parameters_before), rec.q, rec.dq, rec.ddq)
    np.testing.assert_allclose(rec.true_torques - rigid, expected, rtol=0, atol=tolerance(rigid))
    np.testing.assert_allclose(rec.friction_torques, expected, rtol=0, atol=1e-12)
    spec = ARM_ROBOTS[robot].friction
    assert fr["coulomb_Nm"] == list(spec.coulomb) and fr["offset_Nm"] == list(spec.offset)
    assert fr["armature_kgm2"] == [0.05] * len(spec.coulomb)
    # The excitation crosses zero velocity on every joint: Coulomb friction changes sign.
    assert np.all(rec.dq.max(axis=0) > 5 * v_s) and np.all(rec.dq.min(axis=0) < -5 * v_s)


@pytest.mark.parametrize("robot", ROBOTS)
def test_contact_torques_equal_rnea_with_the_external_force(robot):
    config = ArmScenarioConfig(
        name=f"{robot}_contacts",
        robot=robot,
        duration=4.0,
        rate=100.0,
        noise_scale=0.0,
        contacts=SHORT_CONTACTS,
    )
    rec = simulate_arm(config)
    spec = rec.robot
    model = independent_model(robot, rec.parameters_before)
    data = model.createData()
    fid = model.getFrameId(spec.end_effector)
    active = np.flatnonzero(np.linalg.norm(rec.contact_force, axis=1) > 0)
    assert active.size > 30
    for i in active:
        pin.framesForwardKinematics(model, data, rec.q[i])
        oMf = data.oMf[fid]
        F = rec.contact_force[i]
        f_world = pin.Force(F, np.cross(oMf.translation, F))  # about the world origin
        fext = [pin.Force.Zero() for _ in range(model.njoints)]
        jid = model.frames[fid].parentJoint
        fext[jid] = data.oMi[jid].actInv(f_world)
        with_contact = pin.rnea(model, data, rec.q[i], rec.dq[i], rec.ddq[i], fext).copy()
        without = pin.rnea(model, data, rec.q[i], rec.dq[i], rec.ddq[i]).copy()
        np.testing.assert_allclose(
            rec.external_torques[i], with_contact - without, rtol=0, atol=tolerance(without)
        )
        np.testing.assert_allclose(rec.contact_wrench[i, :3], oMf.rotation.T @ F, rtol=0, atol=1e-12)
    inactive = np.setdiff1d(np.arange(rec.stamps.size), active)
    assert not np.any(rec.external_torques[inactive]) and not np.any(rec.contact_wrench[inactive])
    np.testing.assert_array_equal(
        rec.true_torques, rec.rigid_torques + rec.friction_torques + rec.external_torques
    )
    # Without contacts, every other signal is the same (the episodes have their own random stream).
    plain = simulate_arm(
        ArmScenarioConfig(name=config.name, robot=robot, duration=4.0, rate=100.0, noise_scale=0.0)
    )
    np.testing.assert_array_equal(plain.rigid_torques, rec.rigid_torques)
    np.testing.assert_array_equal(plain.true_torques + rec.external_torques, rec.true_torques)


@pytest.mark.parametrize(("rate", "step_ns"), [(1000.0, 1_000_000), (100.0, 10_000_000)])
def test_rates_give_exact_stamps(rate, step_ns):
    rec = simulate_arm(ArmScenarioConfig(name="stamps", robot="panda", duration=1.5, rate=rate))
    assert rec.stamps.size == round(1.5 * rate)
    assert np.all(np.diff(rec.stamps) == step_ns) and rec.stamps[0] == rec.config.start_ns
    assert rec.info["joint_states"] == {"rate_hz": rate, "count": rec.stamps.size}


def test_bag_reads_back_with_the_project_reader(tmp_path):
    config = ArmScenarioConfig(
        name="ur5_bag", robot="ur5", duration=4.0, rate=100.0, payload_mass=1.5, contacts=SHORT_CONTACTS
    )
    rec = simulate_arm(config)
    path = write_recording(rec, tmp_path / "ur5_bag")
    names = list(rec.joint_names)
    js = read_topic_arrays(path, "/joint_states")
    assert js.names == tuple(names) and np.array_equal(js.stamp_ns, rec.stamps)
    np.testing.assert_array_equal(js.fields["position"], rec.q_measured)
    np.testing.assert_array_equal(js.fields["velocity"], rec.dq_measured)
    np.testing.assert_array_equal(js.fields["effort"], rec.measured_torques)
    acc = read_topic_arrays(path, "/ground_truth/joint_accelerations")
    np.testing.assert_array_equal(acc.fields["accelerations"], rec.ddq)
    for topic, values in (
        ("/ground_truth/joint_torques", rec.true_torques),
        ("/ground_truth/joint_torques/rigid_body", rec.rigid_torques),
        ("/ground_truth/joint_torques/friction", rec.friction_torques),
        ("/ground_truth/external_joint_torques", rec.external_torques),
    ):
        arrays = read_topic_arrays(path, topic)
        np.testing.assert_array_equal(arrays.fields["effort"], values)
        assert np.array_equal(arrays.stamp_ns, rec.stamps)
    contact = read_topic_arrays(path, "/ground_truth/contact_wrench")
    assert contact.frame_id == "tool0"
    np.testing.assert_array_equal(contact.fields["wrench"], rec.contact_wrench)
    # The streaming reader gives the same measured joint states.
    msgs = list(read_messages(path, wrench_topic=None))
    assert len(msgs) == rec.stamps.size
    np.testing.assert_array_equal(np.array([m.effort for m in msgs]), rec.measured_torques)
    info = yaml.safe_load((path / "scenario.yaml").read_text())
    assert info["output"] == "joint_torques" and info["joints"] == names
    assert info["true_parameters"]["after_payload"] == [float(v) for v in rec.parameters_after]
    assert len(info["contacts"]["episodes"]) == 3
    assert info["topics"]["/joint_states"]["count"] == rec.stamps.size


def test_perturbation_is_consistent_bounded_and_shared_by_the_bags_of_one_robot():
    a, b = preset_configs("panda", ("excitation", "payload"), rate=100.0, duration=1.0)
    ra, rb = simulate_arm(a), simulate_arm(b)
    np.testing.assert_array_equal(ra.parameters_before, rb.parameters_before)  # one physical robot
    assert not np.array_equal(ra.q, rb.q)  # two different excitations
    other_seed = simulate_arm(ArmScenarioConfig(name=a.name, robot="panda", duration=1.0, rate=100.0, seed=1))
    assert not np.array_equal(other_seed.parameters_before, ra.parameters_before)
    pert = ParameterPerturbation()
    urdf = ra.parameters_urdf
    for k in range(urdf.size // 10):
        p, u = ra.parameters_before[10 * k : 10 * k + 10], urdf[10 * k : 10 * k + 10]
        if u[0] <= 0:
            continue
        assert is_physically_consistent(p)
        assert abs(p[0] / u[0] - 1.0) <= pert.mass + 1e-12
        assert np.all(np.abs(p[1:4] / p[0] - u[1:4] / u[0]) <= pert.com + 1e-12)
        assert not np.allclose(p, u)


def test_perturbation_scales_principal_second_moments_within_bounds():
    rng = np.random.default_rng(3)
    # A body with an off-origin centre of mass and a full rotational inertia (kg, kg·m, kg·m²).
    m, c = 2.0, np.array([0.1, -0.05, 0.15])
    R = pin.rpy.rpyToMatrix(0.3, -0.2, 0.5)
    I_c = R @ np.diag([0.02, 0.03, 0.045]) @ R.T
    box = pin.Inertia(m, c, I_c).toDynamicParameters()
    assert is_physically_consistent(box)
    out = perturb_parameters(box, ParameterPerturbation(mass=0.2, inertia=0.2, com=0.0), rng)

    def second_moments(p):
        m, c = p[0], p[1:4] / p[0]
        I_o = np.array([[p[4], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]])
        I_c = I_o - m * (c @ c * np.eye(3) - np.outer(c, c))
        return np.linalg.eigvalsh(0.5 * np.trace(I_c) * np.eye(3) - I_c) / m

    ratio = second_moments(out) / second_moments(box)  # per unit mass, eigenvalues sorted
    assert np.all(ratio >= 0.8 - 1e-9) and np.all(ratio <= 1.2 + 1e-9)
    assert abs(out[0] / box[0] - 1.0) <= 0.2


@pytest.mark.parametrize("robot", ROBOTS)
def test_excitation_stays_inside_the_limits(robot):
    rec = simulate_arm(ArmScenarioConfig(name=f"{robot}_lim", robot=robot, duration=20.0, rate=100.0))
    spec = ARM_ROBOTS[robot]
    window = np.asarray(spec.position_window)
    assert np.all(rec.q >= window[:, 0]) and np.all(rec.q <= window[:, 1])
    lim = rec.info["limits"]
    assert np.all(rec.q >= np.asarray(lim["joint_lower_rad"])) and np.all(
        rec.q <= np.asarray(lim["joint_upper_rad"])
    )
    assert (
        np.abs(rec.dq).max() <= spec.max_velocity + 1e-9
        and np.abs(rec.ddq).max() <= spec.max_acceleration + 1e-9
    )


def test_same_config_gives_identical_recordings():
    config = ArmScenarioConfig(name="det", robot="ur5", duration=1.0, rate=100.0, contacts=SHORT_CONTACTS)
    a, b = simulate_arm(config), simulate_arm(config)
    for field in ("q_measured", "dq_measured", "measured_torques", "contact_force", "parameters_before"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


def test_cli_writes_arm_bags_and_rejects_options_of_another_robot(tmp_path, capsys):
    out = tmp_path / "bags"
    assert main(["--robot", "panda", "--rate", "100", "--duration", "1", "--out", str(out), "--quiet"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["panda_excitation_100hz", "panda_payload_100hz"]
    info = yaml.safe_load((out / "panda_payload_100hz" / "scenario.yaml").read_text())
    assert info["payload"]["mass_kg"] == 1.0 and info["payload"]["time_s"] == 0.5
    assert info["joint_states"]["count"] == 100
    args = [
        "--robot",
        "ur5",
        "--scenario",
        "contacts",
        "--duration",
        "6",
        "--contact-rate",
        "30",
        "--contact-force",
        "10",
        "20",
    ]
    assert (
        main([*args, "--rate", "1000", "--out", str(out), "--quiet", "--no-noise", "--no-perturbation"]) == 0
    )
    info = yaml.safe_load((out / "ur5_contacts_1000hz" / "scenario.yaml").read_text())
    assert (
        info["payload"]["time_s"] == 4.5
        and info["true_parameters"]["before_payload"] == info["true_parameters"]["urdf"]
    )
    assert len(info["contacts"]["episodes"]) == 2  # round(30/min · (3.9 − 0.9) s)
    assert all(10 <= e["peak_force_N"] <= 20 for e in info["contacts"]["episodes"])
    capsys.readouterr()
    for bad in (
        ["--robot", "ur5", "--radius", "0.1"],
        ["--robot", "panda", "--scenario", "xy"],
        ["--robot", "icub", "--friction-scale", "2"],
        ["--robot", "panda", "--preset", "paper"],
        ["--robot", "panda", "--rate", "-5"],
        ["--robot", "panda", "--scenario", "contacts", "--contact-rate", "1000"],
    ):
        assert main([*bad, "--out", str(tmp_path / "bad"), "--quiet", "--duration", "2"]) == 2, bad
        assert "simulate: error:" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists() or not any((tmp_path / "bad").iterdir())


def test_invalid_arm_configs_raise():
    for kwargs in (
        {"robot": "kuka"},
        {"rate": 0.0},
        {"payload_mass": -1.0},
        {"payload_time": 99.0, "payload_mass": 1.0},
        {"friction_scale": float("nan")},
        {"armature": -0.1},
    ):
        with pytest.raises(ValueError):
            ArmScenarioConfig(name="bad", duration=10.0, **kwargs)
    with pytest.raises(ValueError):
        ParameterPerturbation(mass=1.5)
    with pytest.raises(ValueError):
        preset_configs("panda", ("xy",))


@pytest.mark.parametrize("robot", ROBOTS)
def test_noise_free_data_identify_base_parameters_friction_and_offsets(robot):
    """The learner's convention: least squares on [base regressor, q̇, tanh(q̇/v_s), 1] per joint recovers the
    true base parameters, friction coefficients and offsets of a noise-free recording (no payload)."""
    rec = simulate_arm(
        ArmScenarioConfig(name=f"{robot}_ident", robot=robot, duration=20.0, rate=100.0, noise_scale=0.0)
    )
    reg = arm_regressor(robot)
    k, n = rec.q.shape
    v_s = rec.info["friction"]["smoothing_velocity_rad_per_s"]
    phi = reg.base_regressor(rec.q, rec.dq, rec.ddq)  # (k, n, n_base)
    fric = np.zeros((k, n, 3 * n))
    for i in range(n):
        fric[:, i, 3 * i] = rec.dq[:, i]
        fric[:, i, 3 * i + 1] = np.tanh(rec.dq[:, i] / v_s)
        fric[:, i, 3 * i + 2] = 1.0
    A = np.concatenate([phi, fric], axis=2).reshape(k * n, -1)
    scale = np.linalg.norm(A, axis=0)
    x, *_ = np.linalg.lstsq(A / scale, rec.true_torques.reshape(-1), rcond=None)
    x /= scale
    cond = np.linalg.cond(A / scale)
    truth = np.concatenate(
        [
            reg.to_base(rec.parameters_before),
            np.ravel(
                np.column_stack(
                    [rec.info["friction"][key] for key in ("viscous_Nms_per_rad", "coulomb_Nm", "offset_Nm")]
                )
            ),
        ]
    )
    # Relative error of a least-squares solution with zero residual: ≲ κ·ε (κ of the scaled matrix).
    err = np.abs(x - truth) / np.maximum(np.abs(truth), 1e-3)
    assert cond < 1e6 and err.max() < 1e-6, (cond, err.max())


@pytest.mark.parametrize("rate", [1000.0, 100.0])
def test_bag_feeds_the_joint_torque_pipeline(tmp_path, rate):
    """The project's replay path: every sample carries the measured q, q̇ and torques of its stamp, and the
    pipeline's q̈ estimate tracks the true q̈ (noise-dominated at 1 kHz with a 9-sample window)."""
    rec = simulate_arm(ArmScenarioConfig(name="pipe", robot="panda", duration=3.0, rate=rate))
    path = write_recording(rec, tmp_path / "pipe")
    pipeline = SamplePipeline(list(rec.joint_names), output="joint_torques")
    samples = list(iter_samples(path, pipeline))
    index = {int(s): i for i, s in enumerate(rec.stamps)}
    # Only the estimator's warm-up (half a window at the start) and the undecided end are missing.
    drops = {k: v for k, v in pipeline.drops.items() if v}
    assert set(drops) <= {"acceleration_warmup"} and len(samples) >= rec.stamps.size - 10
    rows = np.array([index[s.stamp_ns] for s in samples])
    np.testing.assert_array_equal(np.array([s.y for s in samples]), rec.measured_torques[rows])
    np.testing.assert_array_equal(np.array([s.q for s in samples]), rec.q_measured[rows])
    np.testing.assert_array_equal(np.array([s.dq for s in samples]), rec.dq_measured[rows])
    ddq_err = np.array([s.ddq for s in samples]) - rec.ddq[rows]
    # Savitzky–Golay (9 samples, order 2) on velocities with σ_v noise: σ_q̈ ≈ σ_v·rate·0.15; plus the
    # bias of a quadratic fit to a multi-sine of |q⃛| ≲ 4·(2π·1.3 Hz) over 9 samples.
    bound = 5 * 1e-3 * rate * 0.15 + 4 * (2 * np.pi * 1.3) * (9 / rate) ** 2
    assert np.sqrt(np.mean(ddq_err**2)) < bound


def test_one_pipeline_and_one_writer_for_both_measurements(tmp_path):
    """Both robots' configurations share RecordingConfig's fields and checks; one entry simulates either."""
    from semiparam_ros.sim.generate import simulate_recording
    from semiparam_ros.sim.recording import RecordingConfig
    from semiparam_ros.sim.scenario import ScenarioConfig, SimulatedRecording

    arm = ArmScenarioConfig(name="p", robot="panda", duration=2.0, rate=100.0, payload_mass=0.3)
    icub = ScenarioConfig(name="i", duration=2.0, payload_mass=0.3)
    for config in (arm, icub):
        assert isinstance(config, RecordingConfig) and config.pickup_time == 1.0
        for bad in ({"duration": 0.0}, {"seed": -1}, {"payload_mass": -1.0}, {"name": "a/b"},
                    {"payload_mass": 0.3, "payload_time": 100.0}):
            with pytest.raises(ValueError):
                type(config)(**{**{"name": config.name}, **bad})
    assert isinstance(simulate_recording(icub), SimulatedRecording)
    rec = simulate_recording(arm)
    one = write_recording(rec, tmp_path / "one" / "bag")
    assert (one / "bag.mcap").stat().st_size > 0 and "panda" in (one / "scenario.yaml").read_text()


def test_any_urdf_is_simulated_and_learned_from_its_parameter_file(tmp_path, capsys):
    """simulate --urdf FILE --joints …: the UR5's URDF given as a plain file (as a user's own arm is), clean
    torques equal to Pinocchio's RNEA of the true parameters, and the bag learned with the parameter file
    written beside it."""
    from semiparam_ros.cli import learn

    urdf = resolve_urdf(ARM_ROBOTS["ur5"].urdf)
    joints = list(ARM_ROBOTS["ur5"].joints)
    argv = ["--urdf", str(urdf), "--joints", *joints, "--duration", "3", "--rate", "200", "--scenario",
            "excitation", "--no-noise", "--friction-scale", "0", "--out", str(tmp_path), "--quiet"]
    assert main(argv) == 0
    (bag,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert bag.name == "ur5_excitation_200hz"
    info = yaml.safe_load((bag / "scenario.yaml").read_text())
    params = np.asarray(info["true_parameters"]["before_payload"])
    measured = read_topic_arrays(bag, "/joint_states").fields
    truth = read_topic_arrays(bag, "/ground_truth/joint_accelerations").fields
    model = pin.buildModelFromUrdf(str(urdf))  # the UR5's URDF moves exactly these six joints
    for j in range(1, model.njoints):
        model.inertias[j] = pin.Inertia.FromDynamicParameters(params[10 * (j - 1): 10 * j])
    expected = rnea(model, truth["positions"], truth["velocities"], truth["accelerations"])
    np.testing.assert_allclose(measured["effort"], expected, rtol=0, atol=tolerance(expected))
    config = yaml.safe_load((bag / "params.yaml").read_text())["/**"]["ros__parameters"]
    assert config["robot"] == {"urdf": str(urdf.resolve()), "joints": joints}
    assert learn.main([str(bag), "--config", str(bag / "params.yaml"), "--set", "nonparametric.n_features=20",
                       "--checkpoint", str(tmp_path / "m.npz"), "--quiet"]) == 0
    import re

    learned = re.search(r"learned (\d+) of (\d+) samples", capsys.readouterr().out)
    assert learned and learned[1] == learned[2] and int(learned[1]) >= 550  # 600 stamps, less the q̈ warm-up
    # misuse: one line, exit 2
    assert main(["--urdf", str(urdf), "--out", str(tmp_path / "x"), "--quiet"]) == 2
    assert main(["--robot", "panda", "--urdf", str(urdf), "--joints", *joints, "--quiet"]) == 2
    assert main(["--joints", *joints, "--quiet"]) == 2
    assert "--joints" in capsys.readouterr().err


def test_any_urdf_with_an_ft_sensor_records_its_wrench(tmp_path):
    """simulate --urdf … --ft-sensor: the iCub arm's F/T sensor, clean and at the URDF's inertias, reads
    Pinocchio's RNEA wrench through the sensor joint (an independent model) plus the stated constant offset;
    the parameter file beside the bag learns the wrench."""
    from helpers.dynamics import reference_model, reference_wrench

    from semiparam_ros.core.config import load_config
    from semiparam_ros.core.kinds import OutputKind

    urdf = resolve_urdf("example-robot-data://robots/icub_description/robots/icub.urdf")
    joints = ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]
    assert main(["--urdf", str(urdf), "--joints", *joints, "--ft-sensor", "r_arm_ft_sensor",
                 "--duration", "2", "--rate", "100", "--scenario", "excitation", "--no-noise",
                 "--no-perturbation", "--out", str(tmp_path), "--quiet"]) == 0
    (bag,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    info = yaml.safe_load((bag / "scenario.yaml").read_text())
    offset = np.asarray(info["ft_sensor"]["offset_N_Nm"])
    wrench = read_topic_arrays(bag, "/wrench")
    truth = read_topic_arrays(bag, "/ground_truth/joint_accelerations").fields
    assert wrench.frame_id == "r_arm_ft_sensor"
    model = reference_model(urdf.read_text(), joints, sensor="r_arm_ft_sensor")
    expected = np.array([reference_wrench(model, joints, "r_arm_ft_sensor", q, dq, ddq) for q, dq, ddq in
                         zip(truth["positions"], truth["velocities"], truth["accelerations"], strict=True)])
    np.testing.assert_allclose(wrench.fields["wrench"] - offset, expected, rtol=0,
                               atol=1e-9 * (1 + np.abs(expected).max()))
    config = load_config(bag / "params.yaml")
    assert config.output_kind == OutputKind.WRENCH and config["topics.wrench"] == "/wrench"
    assert main(["--robot", "panda", "--ft-sensor", "x", "--out", str(tmp_path / "x"), "--quiet"]) == 2
    assert main(["--urdf", str(urdf), "--joints", *joints, "--ft-sensor", "no_such_joint",
                 "--out", str(tmp_path / "y"), "--quiet"]) == 2
