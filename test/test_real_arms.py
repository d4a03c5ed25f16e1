"""Joint-torque arms (issue 12): URDF prior, friction/offset columns, column scaling, parameter files."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from semiparam_ros.core.config import EstimatorConfig, load_config
from semiparam_ros.core.estimator import OnlineEstimator, build_regressor, column_scale
from semiparam_ros.core.messages import JointStateData, Sample

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = sorted((ROOT / "config").glob("*.yaml"))
T0_NS = 1_763_800_000 * 10**9
SMALL = {"nonparametric.n_features": 32, "nonparametric.standardizer_warmup": 20}


def ur5() -> EstimatorConfig:
    return load_config(ROOT / "config" / "ur5.yaml").with_overrides(SMALL)


# ---------------------------------------------------------------- independent reference (plain Pinocchio)
def reference_model(config: EstimatorConfig, sensor: str | None = None) -> pin.Model:
    """The URDF's model built without the code under test (locked joints at their positions); an F/T
    sensor joint becomes a revolute joint kept at 0, so RNEA reports the force through it."""
    root = ET.fromstring(config.urdf_path().read_text())
    if sensor is not None:
        for j in root.findall("joint"):
            if j.get("name") == sensor:
                j.set("type", "revolute")
                ET.SubElement(j, "axis", xyz="0 0 1")
                ET.SubElement(j, "limit", effort="1", velocity="1", lower="-1", upper="1")
    full = pin.buildModelFromXML(ET.tostring(root, encoding="unicode"))
    q0 = pin.neutral(full)
    for name, val in config.locked.items():
        q0[full.joints[full.getJointId(name)].idx_q] = val
    keep = set(config["robot.joints"]) | ({sensor} if sensor else set())
    model = pin.buildReducedModel(full, [j for j in range(1, full.njoints) if full.names[j] not in keep], q0)
    model.gravity = pin.Motion(np.asarray(config["robot.gravity"]), np.zeros(3))
    return model


def reference_rnea(model: pin.Model, joints, q, dq, ddq, sensor: str | None = None) -> np.ndarray:
    qf, vf, af = pin.neutral(model), np.zeros(model.nv), np.zeros(model.nv)
    ids = [model.joints[model.getJointId(n)] for n in joints]
    for i, jm in enumerate(ids):
        qf[jm.idx_q], vf[jm.idx_v], af[jm.idx_v] = q[i], dq[i], ddq[i]
    data = model.createData()
    tau = pin.rnea(model, data, qf, vf, af)
    if sensor is None:
        return np.array([tau[jm.idx_v] for jm in ids])
    f = data.f[model.getJointId(sensor)]  # force the proximal side applies on the distal subtree
    return -np.concatenate([f.linear, f.angular])


def random_state(config: EstimatorConfig, rng: np.random.Generator):
    n = len(config["robot.joints"])
    return rng.uniform(-1.5, 1.5, n), rng.normal(0, 1.0, n), rng.normal(0, 5.0, n)


def multisine(n_joints: int, t: np.ndarray, seed: int):
    """q, q̇, q̈ [rad, rad/s, rad/s²] of independent sums of sines (an exciting trajectory)."""
    rng = np.random.default_rng(seed)
    f = rng.uniform(0.05, 0.6, size=(n_joints, 4))
    a = rng.uniform(0.1, 0.4, size=(n_joints, 4))
    ph = rng.uniform(0, 2 * np.pi, size=(n_joints, 4))
    w = 2 * np.pi * f
    arg = w[None] * t[:, None, None] + ph[None]
    return ((a * np.sin(arg)).sum(-1), (a * w * np.cos(arg)).sum(-1), (-a * w**2 * np.sin(arg)).sum(-1))


# ---------------------------------------------------------------- URDF prior
PRIOR_CASES = [
    ("ur5.yaml", None, {}),
    ("panda.yaml", None, {"parametric.armature": True}),
    ("icub_right_arm.yaml", "r_arm_ft_sensor", {"parametric.prior": "urdf", "parametric.column_scaling": True,
                                                "parametric.sensor_offset": True}),
]


@pytest.mark.parametrize(("file", "sensor", "overrides"), PRIOR_CASES)
@pytest.mark.parametrize("kind", ["P", "SP", "SPJ"])
def test_urdf_prior_first_prediction_is_rnea(file, sensor, overrides, kind):
    """Before any data the prediction is RNEA with the URDF's parameters (friction, offsets, armature and
    sensor offsets at 0). Tolerance 1e-9 N·m/N: Φ_b diag(1/c)·(c ⊙ π_b) reproduces RNEA to a few ulps of
    the largest term (|y| ≤ ~100 here, ε·100·n_base ≈ 1e-12)."""
    cfg = load_config(ROOT / "config" / file).with_overrides({**SMALL, **overrides})
    if kind == "SPJ":
        cfg = cfg.with_overrides({"semiparametric.combination": "joint"})
    est = OnlineEstimator(cfg, kind="P" if kind == "P" else "SP")
    model = reference_model(cfg, sensor)
    rng = np.random.default_rng(1)
    for i in range(3):  # the first prediction, and two more while only the prior and one sample are known
        q, dq, ddq = random_state(cfg, rng)
        ref = reference_rnea(model, cfg["robot.joints"], q, dq, ddq, sensor)
        res = est.step(Sample(T0_NS + i, q, dq, ddq, ref))  # data consistent with the prior
        np.testing.assert_allclose(res.prediction.total, ref, rtol=0, atol=1e-9)
    assert np.abs(ref).max() > 1.0  # a real comparison, not zeros


def test_zero_prior_predicts_zero_before_data():
    cfg = ur5().with_overrides({"parametric.prior": "zero"})
    est = OnlineEstimator(cfg, kind="P")
    q, dq, ddq = random_state(cfg, np.random.default_rng(2))
    assert np.array_equal(est.model.predict_one(np.concatenate([q, dq, ddq])).total, np.zeros(6))


@pytest.mark.parametrize("combination", ["cascade", "joint"])
def test_forgetting_keeps_the_urdf_prior(combination):
    """With bounded forgetting the regularizer is kept around π₀ (the learners regress δ = π − π₀): 3000
    samples that only excite one state, generated by the URDF, leave the prediction at RNEA elsewhere.
    (A prior set as initial weights would be forgotten: its d = Rπ₀ decays as β^n, here 0.99³⁰⁰⁰.)"""
    cfg = ur5().with_overrides({"parametric.forgetting": 0.99, "nonparametric.forgetting": 0.99,
                                "semiparametric.combination": combination})
    est = OnlineEstimator(cfg, kind="SP")
    model = reference_model(cfg)
    joints = cfg["robot.joints"]
    rng = np.random.default_rng(3)
    q, dq, ddq = random_state(cfg, rng)
    y = reference_rnea(model, joints, q, dq, ddq)
    for i in range(3000):
        est.step(Sample(T0_NS + i, q, dq, ddq, y))
    q2, dq2, ddq2 = random_state(cfg, rng)
    ref = reference_rnea(model, joints, q2, dq2, ddq2)
    pred = est.model.predict_one(np.concatenate([q2, dq2, ddq2]))
    np.testing.assert_allclose(pred.parametric, ref, rtol=0, atol=1e-8)
    reg = est.regressor
    np.testing.assert_allclose(est.parameters, reg.to_base(reg.urdf_parameters()), rtol=0, atol=1e-9)


# ---------------------------------------------------------------- friction and offsets
def test_friction_and_offsets_are_recovered_from_noise_free_torques():
    """UR5, exact q̈, τ = RNEA(URDF) + f_v q̇ + f_c tanh(q̇/v_s) + o (built here, not with the regressor's
    columns). With prior urdf the learner regresses δ = θ − θ₀, whose true value is zero except for the
    friction and offsets. Ridge bias: ‖δ̂ − δ*‖ ≤ λ‖δ*‖/σ_min(Φ̃)² (Φ̃ the stacked scaled regressor); rounding
    of the Givens recursion adds O(κ(Φ̃)·ε·‖δ*‖). Both are computed here and are below 1e-6 of the smallest
    coefficient, so every coefficient is asserted to 1e-6 relative."""
    lam = 1e-9
    cfg = ur5().with_overrides({"parametric.lam": lam, "parametric.coulomb_velocity": 0.05})
    est = OnlineEstimator(cfg, kind="P")
    reg = est.regressor
    joints = cfg["robot.joints"]
    n = len(joints)
    fv = np.linspace(0.5, 3.0, n)        # N·m·s/rad
    fc = np.linspace(2.0, 0.3, n)        # N·m
    off = np.array([0.4, -1.2, 0.8, -0.05, 0.15, -0.3])  # N·m
    t = np.arange(4000) * 0.01
    q, dq, ddq = multisine(n, t, seed=5)
    model = reference_model(cfg)
    tau = np.array([reference_rnea(model, joints, q[i], dq[i], ddq[i]) for i in range(len(t))])
    tau += fv * dq + fc * np.tanh(dq / 0.05) + off
    for i in range(len(t)):
        est.step(Sample(T0_NS + i, q[i], dq[i], ddq[i], tau[i]))
    names = est.parameter_names
    got = dict(zip(names, est.parameters, strict=True))
    for i, j in enumerate(joints):
        for kind, true in (("viscous", fv[i]), ("coulomb", fc[i]), ("offset", off[i])):
            assert got[f"{j}.{kind}"] == pytest.approx(true, rel=1e-6), f"{j}.{kind}"
    # the bound behind the 1e-6: bias and rounding, from the conditioning of this very data
    c = column_scale(cfg, reg)
    Phi = (reg.base_regressor(q, dq, ddq) / c).reshape(-1, reg.n_base)
    sv = np.linalg.svd(Phi, compute_uv=False)
    pi0 = reg.to_base(reg.urdf_parameters())
    pi_true = pi0.copy()
    for i, j in enumerate(joints):
        for kind, true in (("viscous", fv[i]), ("coulomb", fc[i]), ("offset", off[i])):
            pi_true[names.index(f"{j}.{kind}")] = true
    delta = c * (pi_true - pi0)
    rounding = 100 * (sv[0] / sv[-1]) * np.finfo(float).eps * np.linalg.norm(c * pi_true)
    bound = lam * np.linalg.norm(delta) / sv[-1] ** 2 + rounding
    friction = np.flatnonzero(delta)
    assert np.all(bound / np.abs(delta[friction]) < 1e-6)
    assert np.linalg.norm(c * (est.parameters - pi_true)) <= bound


def test_extra_columns_are_named_per_joint_and_absent_for_a_wrench():
    reg = build_regressor(ur5().with_overrides({"parametric.armature": True}))
    names = reg.base_parameter_names
    for kind in ("viscous", "coulomb", "offset"):
        assert [n for n in names if n.endswith("." + kind)] == [f"{j}.{kind}" for j in ur5()["robot.joints"]]
    # shoulder_pan's axis is fixed in the base: its armature merges with an inertia of link 1
    assert not any(n == "shoulder_pan_joint.armature" for n in names)
    assert any("shoulder_pan_joint.armature" in n for n in names)
    icub = load_config(ROOT / "config" / "icub_right_arm.yaml").with_overrides({"parametric.friction": True})
    assert not any("." in n.split("_")[-1] for n in build_regressor(icub).base_parameter_names)


def test_column_scaling_makes_lambda_act_on_output_units():
    """θ = c ⊙ π_b with c the columns' RMS: every scaled column has unit RMS on the base-parameter states."""
    cfg = ur5()
    reg = build_regressor(cfg)
    c = column_scale(cfg, reg)
    rng = np.random.default_rng(0)
    lo, hi = reg.position_limits()
    k = max(64, 3 * reg.n_params)
    qs = rng.uniform(lo, hi, size=(k, reg.n_joints))
    dqs = rng.uniform(-1.5, 1.5, size=(k, reg.n_joints))
    ddqs = rng.uniform(-10.0, 10.0, size=(k, reg.n_joints))
    Phi = (reg.base_regressor(qs, dqs, ddqs) / c).reshape(-1, reg.n_base)
    np.testing.assert_allclose(np.sqrt((Phi**2).mean(axis=0)), 1.0, rtol=1e-12)
    assert np.array_equal(column_scale(cfg.with_overrides({"parametric.column_scaling": False}), reg),
                          np.ones(reg.n_base))


def test_checkpoint_keeps_the_prior_and_refuses_another_prior(tmp_path):
    cfg = ur5()
    est = OnlineEstimator(cfg, kind="SP")
    rng = np.random.default_rng(6)
    for i in range(30):
        q, dq, ddq = random_state(cfg, rng)
        est.step(Sample(T0_NS + i, q, dq, ddq, rng.normal(size=6)))
    est.save(tmp_path / "c.npz")
    other = OnlineEstimator(cfg, kind="SP")
    other.load(tmp_path / "c.npz")
    np.testing.assert_array_equal(other.parameters, est.parameters)
    zero = OnlineEstimator(cfg.with_overrides({"parametric.prior": "zero"}), kind="SP")
    with pytest.raises(ValueError, match=r"parametric\.prior"):
        zero.load(tmp_path / "c.npz")


# ---------------------------------------------------------------- shipped parameter files
def test_template_lists_every_parameter_with_its_default(tmp_path):
    """Uncommenting config/template.yaml's '# key: value' lines gives a file that sets every parameter, to its
    default (the F/T names are blanked there: a joint-torque arm has no sensor)."""
    import re

    from semiparam_ros.core.config import PARAMETERS

    text = (ROOT / "config" / "template.yaml").read_text()
    body = text[text.index("estimator:"):]
    lines = [re.sub(r"^(\s*)# (\w+:.*)$", r"\1\2", line) for line in body.splitlines()
             if not re.match(r"^\s*#   ", line)]
    (tmp_path / "t.yaml").write_text("\n".join(lines) + "\n")
    import yaml

    def flatten(tree, prefix=""):
        out = {}
        for k, v in tree.items():
            out.update(flatten(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v})
        return out

    flat = flatten(yaml.safe_load((tmp_path / "t.yaml").read_text())["estimator"]["ros__parameters"])
    assert set(flat) == {p.name for p in PARAMETERS}
    blank = {"robot.ft_sensor", "robot.frame_id", "robot.urdf", "robot.joints", "robot.output"}
    for p in PARAMETERS:
        if p.name not in blank:
            assert flat[p.name] == p.default, p.name
    assert load_config(tmp_path / "t.yaml")["robot.output"] == "joint_torques"


@pytest.mark.parametrize("path", CONFIGS, ids=[p.stem for p in CONFIGS])
def test_shipped_parameter_files_validate_and_run(path):
    """Every config/*.yaml loads, builds the SP estimator and learns from joint-state messages at 1 kHz
    (the window in seconds is sized at that rate)."""
    cfg = load_config(path).with_overrides(SMALL)
    if path.stem == "template":  # placeholders: the file validates; run it on a 6-joint arm
        assert cfg["robot.output"] == "joint_torques" and len(cfg["robot.joints"]) == 6
        cfg = cfg.with_overrides({"robot.urdf": ur5()["robot.urdf"], "robot.joints": ur5()["robot.joints"]})
    if not cfg.urdf_path().is_file():
        pytest.skip(f"{cfg['robot.urdf']} is not present on this machine")
    est = OnlineEstimator(cfg, kind="SP")
    if cfg["robot.output"] != "joint_torques":  # the iCub wrench file: samples straight to the learner
        rng = np.random.default_rng(8)
        for i in range(30):
            q, dq, ddq = random_state(cfg, rng)
            res = est.step(Sample(T0_NS + i, q, dq, ddq, rng.normal(size=6)))
            assert np.isfinite(res.prediction.total).all()
        return
    joints = tuple(cfg["robot.joints"])
    t = np.arange(200) * 1e-3
    q, dq, _ = multisine(len(joints), t, seed=7)
    results = []
    for i in range(len(t)):
        msg = JointStateData(T0_NS + i * 1_000_000, joints, q[i], dq[i], np.full(len(joints), 0.5))
        results += est.process_joint_state(msg)
    window = est.pipeline.estimator.window
    assert window == 81  # 0.08 s at 1 kHz
    assert len(results) == len(t) - window // 2 - (window // 2)  # every decided sample but the warm-up
    assert est.n_dropped == window // 2
    assert all(np.isfinite(r.prediction.total).all() for r in results)
