"""The public model API: ``learn`` → self-contained checkpoint → ``load_model`` → ``predict`` / ``gravity``.

Checked against independent computations: Pinocchio's RNEA and generalized gravity on the URDF (the CAD
model before any data), the simulator's true parameters (after learning), the estimator's own single-state
prediction (the vectorised path), and message-by-message driving of :class:`OnlineEstimator` (``learn``).
"""

from __future__ import annotations

import json
import shutil
import warnings

import numpy as np
import pinocchio as pin
import pytest
from helpers import REPO

from semiparam_ros import load_model
from semiparam_ros.cli import learn as learn_cli
from semiparam_ros.core.checkpoint import atomic_save_npz, load_npz
from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.errors import CheckpointError, RejectedSampleError
from semiparam_ros.io.bags import read_messages
from semiparam_ros.serving.bag_learning import learn_bags
from semiparam_ros.sim.arms import ArmScenarioConfig, arm_regressor, simulate_arm
from semiparam_ros.sim.writer import write_recording

PANDA = REPO / "config" / "panda.yaml"
SMALL = {"nonparametric.n_features": 100}


@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    """A 20 s, 200 Hz simulated Panda recording (known truth), its bag and a learned checkpoint."""
    root = tmp_path_factory.mktemp("serving")
    rec = simulate_arm(ArmScenarioConfig(name="panda_train", robot="panda", duration=20.0, rate=200.0,
                                         seed=3))
    bag = write_recording(rec, root / "panda_train")
    config = load_config(PANDA).with_overrides(SMALL)
    est, report = learn_bags([bag], config, checkpoint=root / "panda.npz")
    return {"root": root, "rec": rec, "bag": bag, "config": config, "est": est, "report": report,
            "ckpt": root / "panda.npz"}


def _states(rng, n, k):
    q = rng.uniform(-1.0, 1.0, (k, n))
    q[:, 3] = rng.uniform(-2.5, -0.5, k)  # the Panda's elbow lives in [-3.07, -0.07]
    return q, rng.uniform(-1.0, 1.0, (k, n)), rng.uniform(-3.0, 3.0, (k, n))


def test_fresh_model_is_the_cad_model_rnea_and_gravity(tmp_path):
    """Before any data (URDF prior), predict = rigid-body part = RNEA with the URDF's inertias."""
    config = load_config(PANDA).with_overrides(SMALL)
    est = OnlineEstimator(config)
    est.save(tmp_path / "fresh.npz")
    model = load_model(tmp_path / "fresh.npz")
    pmodel = est.regressor.pinocchio_model
    data = pmodel.createData()
    rng = np.random.default_rng(0)
    q, dq, ddq = _states(rng, 7, 20)
    total, std = model.predict(q, dq, ddq, consistent=False)
    parts = model.predict_parts(q, dq, ddq, consistent=False)
    # the default predicts with the consistent projection, which returns the (consistent) CAD values to the
    # interior-point solver's accuracy
    projected = model.predict(q, dq, ddq)[0]
    assert np.abs(projected - total).max() <= 1e-3 * np.abs(total).max()
    for i in range(20):
        rnea = pin.rnea(pmodel, data, q[i], dq[i], ddq[i])
        scale = 1.0 + np.abs(rnea).max()
        np.testing.assert_allclose(total[i], rnea, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(model.cad(q[i], dq[i], ddq[i]), rnea, rtol=0, atol=1e-9 * scale)
        gravity = pin.computeGeneralizedGravity(pmodel, data, q[i])
        np.testing.assert_allclose(model.gravity(q[i], consistent=False), gravity, rtol=0,
                                   atol=1e-9 * (1 + np.abs(gravity).max()))
        # the default is the gravity of the rigid body predict uses: the projection of the CAD values
        assert np.abs(model.gravity(q[i]) - gravity).max() <= 1e-3 * (1 + np.abs(gravity).max())
    np.testing.assert_array_equal(parts.residual, 0.0)
    assert np.isinf(std).all()  # no noise estimate yet: honest +inf
    assert not model.ready and model.n_samples_learned == 0


def test_learned_model_recovers_the_true_robot(panda):
    """After 20 s of excitation: gravity and torques of the true (perturbed) robot, friction included."""
    model = load_model(panda["ckpt"])
    rec = panda["rec"]
    assert model.ready and model.n_samples_learned == panda["report"].learned > 3500
    idx = np.arange(0, len(rec.q), 37)
    q, dq, ddq = rec.q[idx], rec.dq[idx], rec.ddq[idx]
    truth = rec.rigid_torques[idx] + rec.friction_torques[idx]
    pred, std = model.predict(q, dq, ddq, consistent=False)
    rms = np.sqrt(np.mean((pred - truth) ** 2, axis=0))
    noise = np.asarray(rec.robot.torque_noise_std)
    assert (rms < 1.5 * noise).all(), (rms, noise)  # the model error is below the measurement noise
    assert np.isfinite(std).all() and (std > 0).all()
    # gravity of the identified inertias vs the true robot's (Pinocchio on the true parameters)
    rigid = arm_regressor("panda")  # the simulator's own, without friction columns
    true_gravity = rigid.regressor(q, np.zeros_like(q), np.zeros_like(q)) @ rec.parameters_before
    err = np.sqrt(np.mean((model.gravity(q) - true_gravity) ** 2, axis=0))
    assert (err < 0.1 + 0.01 * np.sqrt(np.mean(true_gravity**2, axis=0))).all(), err


@pytest.mark.parametrize("served", [False, True], ids=["loaded", "served copy"])
def test_vectorised_equals_single_states(panda, served):
    """N states in one call equal N single calls, on a loaded model and on its frozen served copy (whose
    single states are one compiled call, :meth:`frozen_model_one`, and the N-state path numpy's)."""
    model = load_model(panda["ckpt"])
    if served:
        model = model.snapshot()
    rng = np.random.default_rng(1)
    q, dq, ddq = _states(rng, 7, 50)
    batch = model.predict_parts(q, dq, ddq)
    history = model.stick_state()  # the rows are one path: friction that remembers carries it along them
    assert history is not None
    for i in range(50):
        one = model.predict_parts(q[i], dq[i], ddq[i], history=history)
        scale = 1.0 + np.abs(one.total).max()
        # same mathematics, BLAS-3 instead of one forward substitution: rounding ≈ cond(R)·ε relative
        for a, b in ((batch.total[i], one.total), (batch.rigid_body[i], one.rigid_body),
                     (batch.residual[i], one.residual)):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-8 * scale)
        np.testing.assert_allclose(batch.std[i], one.std, rtol=1e-8)
    assert batch.total.shape == (50, 7) and one.total.shape == (7,)


def test_predict_refuses_bad_input_without_changing_anything(panda):
    model = load_model(panda["ckpt"])
    q = np.zeros(7)
    before = model.predict(q, q, q)[0]
    for args in ((np.zeros(6), q, q), (q, np.zeros((2, 7)), q), (np.full(7, np.nan), q, q),
                 (q, np.full(7, np.inf), q), (np.zeros((0, 7)), np.zeros((0, 7)), np.zeros((0, 7)))):
        with pytest.raises(RejectedSampleError):
            model.predict(*args)
    np.testing.assert_array_equal(model.predict(q, q, q)[0], before)


def test_checkpoint_is_self_contained_and_refuses_foreign_files(panda, tmp_path):
    # learn with a URDF copy, then remove it: the checkpoint carries its own
    urdf = tmp_path / "panda.urdf"
    shutil.copy(panda["config"].urdf_path(), urdf)
    config = panda["config"].with_overrides({"robot.urdf": str(urdf)})
    est = OnlineEstimator(config)
    est.save(tmp_path / "own.npz")
    urdf.unlink()
    model = load_model(tmp_path / "own.npz")
    assert model.joints == tuple(config["robot.joints"])
    assert model.versions["semiparam_ros"] and model.versions["pinocchio"]
    ckpt = panda["ckpt"]
    raw = ckpt.read_bytes()
    (tmp_path / "cut.npz").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(CheckpointError):
        load_model(tmp_path / "cut.npz")
    with pytest.raises(CheckpointError):
        load_model(tmp_path / "missing.npz")
    np.savez(tmp_path / "foreign.npz", a=np.zeros(3))
    with pytest.raises(CheckpointError, match=r"not a semiparam_ros checkpoint"):
        load_model(tmp_path / "foreign.npz")
    old = {k: v for k, v in load_npz(ckpt).items() if k not in ("meta.config", "meta.urdf")}
    atomic_save_npz(tmp_path / "old.npz", old)
    with pytest.raises(CheckpointError, match="older version"):
        load_model(tmp_path / "old.npz")
    bad = load_npz(ckpt)
    bad["meta.config"] = np.array(json.dumps({"nonparametric.n_feature": 3}))  # misspelt
    atomic_save_npz(tmp_path / "bad.npz", bad)
    with pytest.raises(CheckpointError, match=r"nonparametric\.n_feature"):
        load_model(tmp_path / "bad.npz")


def test_checkpoint_of_another_robot_is_refused(panda, tmp_path):
    """Same joints and structure, other inertias in the URDF: the warm start names the difference."""
    text = panda["config"].urdf_path().read_text()
    changed = text.replace('<mass value="4.970684"/>', '<mass value="5.970684"/>', 1)
    assert changed != text
    urdf = tmp_path / "other.urdf"
    urdf.write_text(changed)
    other = OnlineEstimator(panda["config"].with_overrides({"robot.urdf": str(urdf)}))
    with pytest.raises(CheckpointError, match="other inertial parameters"):
        other.load(panda["ckpt"])


def test_noise_state_and_snapshot(panda):
    est = panda["est"]
    model = load_model(panda["ckpt"])
    np.testing.assert_array_equal(model.estimator.noise.s2, est.noise.s2)  # σ does not warm up again
    live = load_model(panda["ckpt"])
    frozen = live.snapshot()
    q, dq, ddq = panda["rec"].q[500], panda["rec"].dq[500], panda["rec"].ddq[500]
    before = frozen.predict(q, dq, ddq)[0]
    rec = panda["rec"]
    joints = tuple(rec.joint_names)
    live.estimator.gate_enabled = False  # the shifted torques would be a contact to the (restored) gate
    for i in range(0, 400):  # more learning on the live estimator (stamps after the checkpoint's)
        live.estimator.process(JointStateData(
            int(rec.stamps[-1]) + (i + 1) * 5_000_000, joints, rec.q_measured[i], rec.dq_measured[i],
            rec.measured_torques[i] + 0.5))
    np.testing.assert_array_equal(frozen.predict(q, dq, ddq)[0], before)
    assert not np.array_equal(live.predict(q, dq, ddq)[0], before)


def test_learn_equals_driving_the_estimator_message_by_message(panda):
    """``learn`` is the node's data path: the same parameters bit for bit as feeding the messages."""
    est = OnlineEstimator(panda["config"])
    for msg in read_messages(panda["bag"], joint_states_topic="/joint_states", wrench_topic=None):
        est.process(msg)
    np.testing.assert_array_equal(est.parameters, panda["est"].parameters)
    assert est.n_samples_learned == panda["report"].learned
    report = panda["report"]
    assert report.samples == report.learned + sum(report.not_learned.values())
    assert report.log_s == pytest.approx(20.0, abs=0.3) and report.realtime_factor > 0


def test_learn_cli_two_bags_init_and_errors(panda, tmp_path, capsys):
    bag = panda["bag"]
    cfg = tmp_path / "panda.yaml"
    shutil.copy(PANDA, cfg)
    out = tmp_path / "two.npz"
    code = learn_cli.main([str(bag), str(bag), "--config", str(cfg), "--set", "nonparametric.n_features=100",
                           "--checkpoint", str(out), "--json", str(tmp_path / "r.json"), "--quiet"])
    assert code == 0, capsys.readouterr()
    report = json.loads((tmp_path / "r.json").read_text())
    # the second bag's stamps start before the first one's end: learned, not dropped as out of order
    assert report["learned"] == 2 * panda["report"].learned
    assert "joint_state_backwards_stamp" not in report["drops"]
    assert load_model(out).n_samples_learned == report["learned"]
    # continue from it
    code = learn_cli.main([str(bag), "--config", str(cfg), "--set", "nonparametric.n_features=100",
                           "--init", str(out), "--checkpoint", str(tmp_path / "three.npz"), "--quiet"])
    assert code == 0
    assert load_model(tmp_path / "three.npz").n_samples_learned == 3 * panda["report"].learned
    # errors: one line, exit 2
    assert learn_cli.main([str(tmp_path / "nope"), "--config", str(cfg), "--checkpoint", str(out)]) == 2
    assert learn_cli.main([str(bag), "--config", str(cfg), "--set", "nonparametric.n_feature=3",
                           "--checkpoint", str(out)]) == 2
    err = capsys.readouterr().err
    assert "learn: error:" in err and "Traceback" not in err


def test_learn_reports_a_truncated_bag(panda, tmp_path):
    mcap = next(panda["bag"].glob("*.mcap"))
    cut = tmp_path / "cut.mcap"
    raw = mcap.read_bytes()
    cut.write_bytes(raw[: int(0.6 * len(raw))])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing leaks: the report says it
        _, report = learn_bags([cut], panda["config"])
    assert report.recovered == [str(cut)]
    assert 0 < report.learned < panda["report"].learned


def test_excited_marks_the_states_the_training_data_cover(panda, tmp_path):
    """The trained model covers its own recording's states; a fresh model (URDF prior only) covers none.

    Reference: the rigid-body learner's relative variance by one ``predict_one`` per state.
    """
    model = load_model(panda["ckpt"])
    rec = panda["rec"]
    idx = np.arange(0, len(rec.q), 97)
    inside = model.excited(rec.q[idx], rec.dq[idx], rec.ddq[idx])
    par = model.estimator.model.parametric
    reference = [par.predict_one(np.r_[rec.q[i], rec.dq[i], rec.ddq[i]], return_variance=True).variance.max()
                 <= 1.0 for i in idx]
    assert inside.tolist() == reference
    assert inside.mean() > 0.95  # the states it learned from
    assert bool(model.excited(rec.q[0], rec.dq[0], rec.ddq[0])) == reference[0]  # one state: a bool
    OnlineEstimator(panda["config"]).save(tmp_path / "fresh.npz")
    fresh = load_model(tmp_path / "fresh.npz")
    assert not fresh.excited(rec.q[idx], rec.dq[idx], rec.ddq[idx]).any()


def test_left_out_terms_are_those_of_the_prediction(panda):
    """``exclude=("gravity",)`` subtracts the gravity of the very rigid body the prediction uses (the
    consistent projection by default): the rigid-body part at rest minus ``gravity(q)`` is the same at
    every posture (the joints' constant offsets), and friction is the closed form of the identified
    viscous and Coulomb parameters. σ is unchanged by leaving terms out."""
    model = load_model(panda["ckpt"])
    rng = np.random.default_rng(3)
    q, dq, ddq = _states(rng, 7, 30)
    zeros = np.zeros_like(q)
    rest = model.predict_parts(q, zeros, zeros).rigid_body
    offsets = rest - model.gravity(q) - model.stick_torque(q, zeros)  # the stick state: the path's
    np.testing.assert_allclose(offsets, np.broadcast_to(offsets[0], offsets.shape), rtol=0,
                               atol=1e-9 * (1 + np.abs(rest).max()))
    total, std = model.predict(q, dq, ddq)
    friction = model.friction(dq) + model.stick_torque(q, dq)
    assert np.abs(model.stick_torque(q, dq)).max() > 0
    for exclude, minus in ((("gravity",), model.gravity(q)), (("friction",), friction),
                           (("gravity", "friction"), model.gravity(q) + friction)):
        left, left_std = model.predict(q, dq, ddq, exclude=exclude)
        np.testing.assert_allclose(left, total - minus, rtol=0, atol=1e-9 * (1 + np.abs(total).max()))
        np.testing.assert_array_equal(left_std, std)
    names = model.parameter_names
    pi = model.rigid_parameters()
    cv = model.config["parametric.coulomb_velocity"]
    viscous = np.array([pi[names.index(f"{j}.viscous")] for j in model.joints])
    coulomb = np.array([pi[names.index(f"{j}.coulomb")] for j in model.joints])
    np.testing.assert_allclose(model.friction(dq), viscous * dq + coulomb * np.tanh(dq / cv), rtol=1e-12,
                               atol=1e-12)
    cad_left, _ = model.predict(q, dq, ddq, exclude=("gravity",), exclude_source="urdf")
    np.testing.assert_allclose(cad_left, total - model.cad(q, zeros, zeros), rtol=0,
                               atol=1e-9 * (1 + np.abs(total).max()))
    with pytest.raises(ValueError):
        model.predict(q, dq, ddq, exclude=("inertia",))


def test_learn_prints_the_fit_beside_the_urdf(panda, tmp_path, capsys):
    """The fit summary scores the served model, its rigid body and the URDF on a sample of the log: checked
    against the simulator (the URDF's error is the RMS of truth − RNEA_urdf, within noise) and against
    load_model's own predictions on the same rows."""
    report = panda["report"]
    fit = report.fit
    rec = panda["rec"]
    assert fit is not None and fit.n_samples == min(4000, report.samples) and fit.outputs == rec.joint_names
    # the URDF misses friction, offsets and the 15 % inertial perturbation: far worse than the model
    assert fit.model.mean() < 0.5 * fit.urdf.mean()
    urdf = arm_regressor("panda").wrench(rec.q, rec.dq, rec.ddq)
    independent = np.sqrt(np.mean((rec.measured_torques - urdf) ** 2, axis=0))
    np.testing.assert_allclose(fit.urdf, independent, rtol=0.15)  # a 4000-row sample of 4000 rows
    code = learn_cli.main([str(panda["bag"]), "--config", str(PANDA), "--set", "nonparametric.n_features=100",
                           "--checkpoint", str(tmp_path / "m.npz"), "--json", str(tmp_path / "r.json")])
    out = capsys.readouterr().out
    assert code == 0 and "fit on" in out and "URDF" in out and "panda_joint4" in out
    assert "excitation: information condition number" in out
    assert json.loads((tmp_path / "r.json").read_text())["fit"]["rmse_urdf"] == pytest.approx(
        fit.urdf.tolist(), rel=1e-9)


def test_load_model_names_what_a_file_is_when_it_is_no_checkpoint(panda, tmp_path):
    (tmp_path / "my_arm.yaml").write_text("/**:\n  ros__parameters:\n    robot: {joints: [a]}\n")
    (tmp_path / "arm.urdf").write_text("<?xml version='1.0'?>\n<robot name='a'/>\n")
    (tmp_path / "empty.npz").write_bytes(b"")
    for name, what in (("my_arm.yaml", "a YAML file"), ("arm.urdf", "an XML/URDF file"),
                       ("empty.npz", "is empty")):
        with pytest.raises(CheckpointError, match=what):
            load_model(tmp_path / name)
    mcap = next(panda["bag"].glob("*.mcap"))
    with pytest.raises(CheckpointError, match="an MCAP bag"):
        load_model(mcap)
    with pytest.raises(CheckpointError, match="a bag folder"):
        load_model(panda["bag"])


def test_learn_without_a_robot_says_what_to_set(panda, tmp_path, capsys):
    cfg = tmp_path / "bare.yaml"
    cfg.write_text("/**:\n  ros__parameters:\n    topics: {joint_states: /joint_states}\n")
    code = learn_cli.main([str(panda["bag"]), "--config", str(cfg), "--checkpoint", str(tmp_path / "x.npz")])
    assert code == 2
    err = capsys.readouterr().err
    assert "robot.urdf and robot.joints are not set" in err and "config/template.yaml" in err
