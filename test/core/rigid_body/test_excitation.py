"""Excitation design: limits read from the URDF, limits held at 1 kHz (checked with Pinocchio's RNEA), the
reported condition number and σ against direct computations, the files a controller and the simulator read,
and the bad inputs (missing limits, infeasible margins and efforts)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import mcap_ros2.decoder
import numpy as np
import pinocchio as pin
import pytest
import yaml
from helpers import REPO
from mcap.reader import make_reader

from semiparam_ros.cli import excite, simulate
from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.build import build_regressor
from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.core.rigid_body.excitation import (
    ExcitationLimits,
    InfeasibleExcitationError,
    condition_number,
    design_excitation,
    limit_usage,
    parameter_std,
    random_multisine,
)
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.io.bags import read_topic_arrays
from semiparam_ros.io.trajectory_files import read_excitation, write_excitation

UR5 = REPO / "config" / "ur5.yaml"


@pytest.fixture(scope="module")
def ur5() -> RigidBodyRegressor:
    return build_regressor(load_config(UR5))


@pytest.fixture(scope="module")
def small(ur5):
    """A quick design: 3 harmonics, 4 s period repeated twice, a few iterations."""
    limits = ExcitationLimits.from_regressor(ur5, margin=0.1)
    return design_excitation(ur5, limits, duration=8.0, period=4.0, n_harmonics=3, iterations=3, n_grid=40,
                             n_starts=4)


def _urdf_limits(reg: RigidBodyRegressor) -> dict[str, dict[str, float]]:
    """The joints' <limit> attributes read with ElementTree (independent of Pinocchio)."""
    root = ET.fromstring(reg.urdf_xml)
    out = {}
    for joint in root.iter("joint"):
        limit = joint.find("limit")
        if joint.get("name") in reg.joint_names and limit is not None:
            out[joint.get("name")] = {k: float(v) for k, v in limit.attrib.items()}
    return out


def test_limits_are_the_urdf_values_with_the_margin(ur5):
    urdf = _urdf_limits(ur5)
    margin = 0.2
    lim = ExcitationLimits.from_regressor(ur5, margin=margin, max_acceleration=3.0,
                                          overrides={"elbow_joint.velocity": 1.5})
    for j, name in enumerate(ur5.joint_names):
        lo, hi = urdf[name]["lower"], urdf[name]["upper"]
        assert lim.lower[j] == pytest.approx(lo + margin * (hi - lo), rel=1e-12)
        assert lim.upper[j] == pytest.approx(hi - margin * (hi - lo), rel=1e-12)
        v = 1.5 if name == "elbow_joint" else urdf[name]["velocity"]
        assert lim.velocity[j] == pytest.approx((1 - margin) * v, rel=1e-12)
        assert lim.effort[j] == pytest.approx((1 - margin) * urdf[name]["effort"], rel=1e-12)
        assert lim.acceleration[j] == pytest.approx((1 - margin) * 3.0)


def test_design_holds_every_limit_at_1khz_and_starts_at_rest(ur5, small):
    lim, traj = small.limits, small.trajectory
    assert small.periods == 2 and traj.period == pytest.approx(4.0)
    t = np.arange(round(small.duration * 1000) + 1) / 1000.0  # the whole trajectory at 1 kHz
    q, dq, ddq = traj.evaluate(t)
    assert np.all(q >= lim.lower - 1e-12) and np.all(q <= lim.upper + 1e-12)
    assert np.all(np.abs(dq) <= lim.velocity * (1 + 1e-9))
    # Efforts with Pinocchio's RNEA on the regressor's model at the URDF's inertials (not the regressor).
    model = ur5.pinocchio_model
    data = model.createData()
    tau = np.array([pin.rnea(model, data, ur5.configuration(q[i]), dq[i], ddq[i])
                    for i in range(0, t.size, 7)])
    assert np.all(np.abs(tau) <= lim.effort * (1 + 1e-9))
    for at in (0.0, traj.period, small.duration):  # at rest where it starts, between periods and at the end
        _, v, a = traj.evaluate(at)
        np.testing.assert_allclose(v, 0.0, atol=1e-12)
        np.testing.assert_allclose(a, 0.0, atol=1e-12)
    used = limit_usage(ur5, traj, lim)
    assert max(float(np.max(u)) for u in used.values()) <= 1.0
    assert float(np.max(used["position"])) > 0.5  # the limits are used, not a timid trajectory


def test_condition_number_and_sigma_against_direct_computation(ur5, small):
    traj = small.trajectory
    t = np.arange(2000) * (traj.period / 2000)
    q, dq, ddq = traj.evaluate(t)
    Y = ur5.base_regressor(q, dq, ddq).reshape(-1, ur5.n_base)
    kappa = np.linalg.cond(Y)
    # The report uses 400 samples of the period; the κ of a finer grid agrees to a few percent.
    assert small.condition_number == pytest.approx(kappa, rel=0.05)
    # σ against the normal equations' inverse (closed form), on the same 400-sample grid.
    t400 = np.arange(400) * (traj.period / 400)
    Y = ur5.base_regressor(*traj.evaluate(t400)).reshape(-1, ur5.n_base)
    cov = np.linalg.inv(Y.T @ Y) * 400 / (1000.0 * small.duration)
    sigma = parameter_std(ur5, traj, rate=1000.0, duration=small.duration, n_grid=400)
    # Both are within κ²·ε of the exact value, relative to the largest σ.
    tol = 100 * np.linalg.cond(Y) ** 2 * np.finfo(float).eps
    np.testing.assert_allclose(sigma, np.sqrt(np.diag(cov)), rtol=max(tol, 1e-9))
    np.testing.assert_allclose(small.parameter_std, sigma, rtol=1e-12)


def test_designed_beats_the_random_multisine_of_the_same_limits(ur5):
    # A short run of the optimiser already beats the median of random multi-sines filling the same limits.
    lim = ExcitationLimits.from_regressor(ur5, margin=0.1)
    designed = design_excitation(ur5, lim, duration=10.0, period=10.0, n_harmonics=4, iterations=15,
                                 n_grid=60, n_starts=8)
    baseline = [condition_number(ur5, random_multisine(ur5, lim, period=10.0, seed=s)) for s in range(5)]
    assert designed.condition_number < np.median(baseline)
    for s in range(2):  # the baseline respects the same limits
        used = limit_usage(ur5, random_multisine(ur5, lim, period=10.0, seed=s), lim)
        assert max(float(np.max(u)) for u in used.values()) <= 1.0


def test_missing_limit_is_named_and_can_be_given(tmp_path):
    config = load_config(REPO / "config" / "panda.yaml")
    reg = build_regressor(config)
    text = reg.urdf_xml.replace('<joint name="panda_joint7" type="revolute">',
                                '<joint name="panda_joint7" type="continuous">')
    assert text != reg.urdf_xml
    continuous = RigidBodyRegressor(text, reg.spec)
    missing = r"panda_joint7.*no lower limit.*--limit panda_joint7\.lower"
    with pytest.raises(ConfigurationError, match=missing):
        ExcitationLimits.from_regressor(continuous)
    lim = ExcitationLimits.from_regressor(continuous, margin=0.0, overrides={"panda_joint7.lower": -1.0,
                                                                             "panda_joint7.upper": 1.0})
    assert (lim.lower[6], lim.upper[6]) == (-1.0, 1.0)
    with pytest.raises(ConfigurationError, match=r"JOINT\.KIND"):
        ExcitationLimits.from_regressor(reg, overrides={"panda_joint9.velocity": 1.0})


def test_infeasible_margin_and_effort(ur5, tmp_path, capsys):
    with pytest.raises(InfeasibleExcitationError, match="margin"):
        ExcitationLimits.from_regressor(ur5, margin=0.5)
    lim = ExcitationLimits.from_regressor(ur5, overrides={"shoulder_lift_joint.effort": 0.5})
    with pytest.raises(InfeasibleExcitationError, match="shoulder_lift_joint"):
        design_excitation(ur5, lim, duration=4.0, n_harmonics=2, iterations=0, n_grid=20, n_starts=1)
    # The command: exit 2 with the reason, nothing written.
    out = tmp_path / "t.yaml"
    assert excite.main(["--config", str(UR5), "--duration", "4", "--out", str(out), "--margin", "0.7"]) == 2
    assert "margin" in capsys.readouterr().err
    assert excite.main(["--config", str(UR5), "--duration", "4", "--out", str(out), "--iterations", "0",
                        "--harmonics", "2", "--limit", "shoulder_lift_joint.effort=0.5"]) == 2
    assert "shoulder_lift_joint" in capsys.readouterr().err
    assert excite.main(["--config", str(UR5), "--duration", "4", "--out", str(out), "--limit", "elbow"]) == 2
    assert not out.exists()


def test_files_a_controller_and_the_simulator_read(ur5, small, tmp_path):
    out = tmp_path / "traj.yaml"
    written = write_excitation(out, small, point_rate=50.0, lead_in=2.0)
    assert written == [out, tmp_path / "traj.excitation.yaml"]
    msg = yaml.safe_load(out.read_text())
    assert msg["joint_names"] == list(ur5.joint_names)
    points = msg["points"]
    assert len(points) == round(small.duration * 50) + 1
    times = np.array([p["time_from_start"]["sec"] + 1e-9 * p["time_from_start"]["nanosec"] for p in points])
    np.testing.assert_allclose(times, 2.0 + np.arange(times.size) / 50.0, atol=1e-9)
    q, dq, ddq = small.trajectory.evaluate(times - 2.0)
    np.testing.assert_allclose([p["positions"] for p in points], q, atol=1e-15)
    np.testing.assert_allclose([p["velocities"] for p in points], dq, atol=1e-15)
    np.testing.assert_allclose([p["accelerations"] for p in points], ddq, atol=1e-15)
    with pytest.raises(FileExistsError):
        write_excitation(out, small)
    back = read_excitation(out)
    assert back.joint_names == ur5.joint_names and back.periods == 2 and back.lead_in == 2.0
    np.testing.assert_array_equal(back.trajectory.cos_coef, small.trajectory.cos_coef)
    np.testing.assert_array_equal(back.trajectory.sin_coef, small.trajectory.sin_coef)
    assert back.description["condition_number"] == small.condition_number

    # .mcap: one JointTrajectory, decoded by mcap_ros2 (independent of the rosbags writer).
    mcap_file = write_excitation(tmp_path / "bagged.mcap", small, point_rate=20.0,
                                 topic="/jtc/joint_trajectory")[0]
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[mcap_ros2.decoder.DecoderFactory()])
        decoded = [(c.topic, s.name, m) for s, c, _, m in reader.iter_decoded_messages()]
    assert [(t, n) for t, n, _ in decoded] == [("/jtc/joint_trajectory",
                                                "trajectory_msgs/msg/JointTrajectory")]
    first = decoded[0][2].points
    assert len(first) == round(small.duration * 20) + 1
    np.testing.assert_allclose(first[7].positions, small.trajectory.evaluate(7 / 20.0)[0][0], atol=1e-15)


def test_simulator_drives_the_arm_on_the_excitation(small, tmp_path, capsys):
    write_excitation(tmp_path / "traj.yaml", small)
    argv = ["--robot", "ur5", "--scenario", "excitation", "--duration", "2", "--rate", "100", "--out",
            str(tmp_path / "bags"), "--quiet", "--trajectory", str(tmp_path / "traj.yaml")]
    assert simulate.main(argv) == 0
    bag = capsys.readouterr().out.split()[-1]
    truth = read_topic_arrays(bag, "/ground_truth/joint_accelerations")
    t = (truth.stamp_ns - truth.stamp_ns[0]) * 1e-9
    q, _, ddq = small.trajectory.evaluate(t)
    np.testing.assert_allclose(truth.fields["positions"], q, atol=1e-12)
    np.testing.assert_allclose(truth.fields["accelerations"], ddq, atol=1e-12)
    # Another robot's joints: refused with exit 2.
    assert simulate.main(["--robot", "panda", "--out", str(tmp_path / "p"), "--quiet", "--duration", "1",
                          "--trajectory", str(tmp_path / "traj.yaml")]) == 2
    assert "joints" in capsys.readouterr().err
    assert math.isfinite(small.condition_number)


def test_the_objective_s_gradient_equals_its_finite_differences(ur5):
    """``value_and_gradient`` (one difference of the regressor per joint and kind, then the chain through the
    scaling, the Fourier maps and the rest constraint) against central differences of ``objective`` in
    every coefficient, with and without the effort penalty active."""
    from semiparam_ros.core.rigid_body.excitation import _Design

    rng = np.random.default_rng(3)
    for effort in (None, 0.35):
        full = ExcitationLimits.from_regressor(ur5).effort
        overrides = {} if effort is None else {f"{j}.effort": effort * e
                                               for j, e in zip(ur5.joint_names, full, strict=True)}
        lim = ExcitationLimits.from_regressor(ur5, margin=0.1, overrides=overrides)
        design = _Design(ur5, lim, 10.0, 4, 60)
        z = 0.5 * rng.standard_normal(design.size)
        value, grad = design.value_and_gradient(z)
        assert value == pytest.approx(design.objective(z), rel=1e-12)
        h = 1e-6
        numeric = np.array([(design.objective(z + h * e) - design.objective(z - h * e)) / (2 * h)
                            for e in np.eye(design.size)])
        # central differences: O(h²) truncation and O(ε|f|/h) rounding; the gradient's own differences of the
        # regressor are forward, O(FD_STEP) relative
        np.testing.assert_allclose(grad, numeric, rtol=1e-3, atol=1e-4 * np.abs(numeric).max())
        if effort is not None:
            assert float(np.max(limit_usage(ur5, design.scaled(z), lim)["effort"])) > 1.0  # the penalty acts


def test_cli_defaults_are_the_library_s():
    from semiparam_ros.core.rigid_body import excitation

    args = excite.build_parser().parse_args(["--config", "c.yaml", "--duration", "1", "--out", "t.yaml"])
    assert (args.harmonics, args.iterations, args.period) == (
        excitation.DEFAULT_HARMONICS, excitation.DEFAULT_ITERATIONS, excitation.DEFAULT_PERIOD_S)
