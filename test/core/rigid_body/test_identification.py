"""Physically consistent parameters, excitation diagnostics and the URDF export, against a simulator's truth
and Pinocchio: every body a physical mass distribution, friction ≥ 0 and near the truth, the projection
feasible and idempotent, the exported URDF reproducing the consistent rigid-body prediction."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import REPO

from semiparam_ros.core.config import load_config
from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor, is_physically_consistent
from semiparam_ros.core.rigid_body.identification import (
    consistent_parameters,
    excitation_report,
    export_urdf,
    full_column_rms,
)
from semiparam_ros.core.rigid_body.urdf import RegressorSpec
from semiparam_ros.serving.bag_learning import learn_bags
from semiparam_ros.serving.learned_model import LearnedModel
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
from semiparam_ros.sim.writer import write_recording

pytest.importorskip("cvxpy")


@pytest.fixture(scope="module")
def learned(tmp_path_factory):
    rec = simulate_arm(ArmScenarioConfig(name="panda_id", robot="panda", duration=20.0, rate=200.0, seed=0))
    bag = write_recording(rec, tmp_path_factory.mktemp("id") / "panda_id")
    config = load_config(REPO / "config" / "panda.yaml").with_overrides({"nonparametric.n_features": 100})
    est, _ = learn_bags([bag], config)
    return est, rec


def test_consistent_estimate_is_physical_and_near_the_truth(learned):
    est, rec = learned
    model = LearnedModel(est)
    c = model.consistent()
    reg = est.regressor
    assert c.status == "optimal"
    for i in range(reg.n_bodies):
        assert is_physically_consistent(c.full[10 * i: 10 * i + 10], tol=1e-9), reg.body_names[i]
    truth = rec.parameters_before
    masses = np.array([c.link(i)[0] for i in range(reg.n_bodies)])
    true_masses = truth[0::10][: reg.n_bodies]
    # link 1 turns about the vertical: its mass never acts, the projection keeps the URDF's
    cad = reg.urdf_parameters()
    assert masses[0] == pytest.approx(cad[0], rel=1e-3)
    np.testing.assert_allclose(masses[1:], true_masses[1:], rtol=0.15)
    names = reg.parameter_names
    friction = rec.robot.friction
    for j, joint in enumerate(reg.joint_names):
        fv, fc = c.full[names.index(f"{joint}.viscous")], c.full[names.index(f"{joint}.coulomb")]
        assert fv >= 0 and fc >= 0
        assert fv == pytest.approx(friction.viscous[j], abs=0.05)  # N·m·s/rad
        assert fc == pytest.approx(friction.coulomb[j], abs=0.03)  # N·m
    # on data it has not seen (another motion of the same robot) it predicts as well as the
    # unconstrained estimate (the simulated excitation covers the state space well)
    rec2 = simulate_arm(ArmScenarioConfig(name="panda_other", robot="panda", duration=10.0, rate=200.0,
                                          seed=0))
    phi = reg.base_regressor(rec2.q, rec2.dq, rec2.ddq)
    truth2 = rec2.rigid_torques + rec2.friction_torques
    rms_c = np.sqrt(np.mean((phi @ c.base - truth2) ** 2))
    rms_u = np.sqrt(np.mean((phi @ est.parameters - truth2) ** 2))
    assert rms_c < 1.2 * rms_u
    frozen, _ = model.predict(rec2.q[:50], rec2.dq[:50], rec2.ddq[:50], consistent=True)
    parts = model.predict_parts(rec2.q[:50], rec2.dq[:50], rec2.ddq[:50], consistent=True)
    held = model.stick_torque(rec2.q[:50], rec2.dq[:50])  # friction that remembers joins the rigid body
    np.testing.assert_allclose(parts.rigid_body, phi[:50] @ c.base + held, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(frozen, parts.rigid_body + parts.residual, rtol=1e-12, atol=1e-12)


def test_projection_is_feasible_and_idempotent(learned):
    est, _ = learned
    reg = est.regressor
    rls = est.model.parametric.rls
    scale = est.column_scale
    first = consistent_parameters(reg, est.model.parametric.parameters, rls.R, scale, rls.lam)
    again = consistent_parameters(reg, scale * first.base, rls.R, scale, rls.lam, prior=first.full)
    # to the interior-point solver's accuracy: its 1e-8 gap leaves ~1e-5 relative in the weakest directions
    np.testing.assert_allclose(again.base, first.base, rtol=1e-4, atol=1e-5 * np.abs(first.base).max())
    # a consistent estimate (the URDF's) with its own prior comes back unchanged, in what it predicts
    # (directions neither the data nor the prior's weight pin down move within the solver's tolerance)
    cad = reg.urdf_parameters()
    same = consistent_parameters(reg, scale * reg.to_base(cad), rls.R, scale, rls.lam, prior=cad)
    rng = np.random.default_rng(1)
    q, dq, ddq = rng.uniform(-1, 1, (40, 7)), rng.uniform(-1, 1, (40, 7)), rng.uniform(-3, 3, (40, 7))
    q[:, 3] = rng.uniform(-2.5, -0.5, 40)
    phi = reg.base_regressor(q, dq, ddq)
    want = phi @ reg.to_base(cad)
    assert np.abs(phi @ same.base - want).max() <= 1e-4 * np.abs(want).max()
    with pytest.raises(ValueError):
        consistent_parameters(reg, np.zeros(3), rls.R, scale, rls.lam)


def test_excitation_report_names_the_weak_directions(learned):
    est, _ = learned
    rls = est.model.parametric.rls
    report = excitation_report(rls.R, est.column_scale, est.parameter_names)
    A = (rls.R * est.column_scale).T @ (rls.R * est.column_scale)
    np.testing.assert_allclose(report.eigenvalues, np.linalg.eigvalsh(A), rtol=1e-6,
                               atol=1e-9 * np.abs(A).max())
    assert report.condition == pytest.approx(report.eigenvalues[-1] / report.eigenvalues[0])
    assert len(report.least_excited) == 3 and all(names for _, names in report.least_excited)
    assert "condition number" in report.text()


def test_urdf_export_round_trip(learned, tmp_path):
    est, _ = learned
    c = LearnedModel(est).consistent()
    reg = est.regressor
    text = export_urdf(reg, c)
    config = est.config
    again = RigidBodyRegressor(text, RegressorSpec(
        tuple(config["robot.joints"]), output="joint_torques", friction=True,
        coulomb_velocity=config["parametric.coulomb_velocity"], joint_offsets=True))
    names = reg.parameter_names
    inertial = np.array([not n.endswith((".viscous", ".coulomb", ".offset", ".armature")) for n in names])
    full = np.where(inertial, c.full, 0.0)
    rng = np.random.default_rng(0)
    q, dq, ddq = rng.uniform(-1, 1, (30, 7)), rng.uniform(-1, 1, (30, 7)), rng.uniform(-3, 3, (30, 7))
    q[:, 3] = rng.uniform(-2.5, -0.5, 30)
    want = reg.regressor(q, dq, ddq) @ full
    got = again.regressor(q, dq, ddq) @ again.urdf_parameters()
    assert np.abs(got - want).max() <= 1e-9 * np.abs(want).max()
    import xml.etree.ElementTree as ET

    joints = {j.get("name"): j for j in ET.fromstring(text).findall("joint")}
    for joint in reg.joint_names:
        dyn = joints[joint].find("dynamics")
        assert float(dyn.get("damping")) == c.full[names.index(f"{joint}.viscous")]
        assert float(dyn.get("friction")) == c.full[names.index(f"{joint}.coulomb")]


def test_export_urdf_command(learned, tmp_path, capsys):
    from semiparam_ros.cli import export_urdf as cli

    est, _ = learned
    est.save(tmp_path / "panda.npz")
    assert cli.main(["--checkpoint", str(tmp_path / "panda.npz"), "--out", str(tmp_path / "id.urdf")]) == 0
    out = capsys.readouterr().out
    assert "condition number" in out and "panda_link1" in out and (tmp_path / "id.urdf").is_file()
    assert cli.main(["--checkpoint", str(tmp_path / "nope.npz"), "--out", str(tmp_path / "x.urdf")]) == 2


def test_a_payload_stays_on_the_distal_body(tmp_path):
    # URDF exact, 1.2 kg on the hand from the start: the base parameters cannot tell the payload's mass on
    # link 7 from mass on the links before it; the weaker CAD prior of the distal body keeps it there.
    rec = simulate_arm(ArmScenarioConfig(name="panda_carry", robot="panda", duration=20.0, rate=200.0, seed=3,
                                         payload_mass=1.2, payload_time=0.0, perturbation=None))
    bag = write_recording(rec, tmp_path / "panda_carry")
    config = load_config(REPO / "config" / "panda.yaml").with_overrides({"nonparametric.n_features": 100})
    est, _ = learn_bags([bag], config)
    reg = est.regressor
    par = est.model.parametric
    default = LearnedModel(est).consistent()
    uniform = consistent_parameters(reg, par.parameters, par.rls.R, est.column_scale, par.rls.lam,
                                    weights=full_column_rms(reg))
    d = reg.body_index(reg.distal_body_name)
    true_mass = rec.parameters_after[10 * d]
    assert true_mass == pytest.approx(reg.urdf_parameters()[10 * d] + 1.2)
    err_default = abs(default.link(d)[0] - true_mass) / true_mass
    err_uniform = abs(uniform.link(d)[0] - true_mass) / true_mass
    assert err_default < 0.10 < err_uniform
    for i in range(d):  # the links before it stay near their (exact) CAD masses
        assert default.link(i)[0] == pytest.approx(rec.parameters_after[10 * i], rel=0.10), reg.body_names[i]
