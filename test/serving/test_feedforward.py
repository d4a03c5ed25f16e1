"""Feed-forward at desired states (core, no ROS): point selection, joint orders, fallback, bad input.

The expected torques are computed independently with Pinocchio's RNEA on the URDF (a fresh model is the
CAD model) or with :meth:`LearnedModel.predict` of a learned one.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from helpers import REPO

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.serving.feedforward import DesiredState, FeedForward, TrajectoryPoint
from semiparam_ros.serving.learned_model import LearnedModel
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm

PANDA = REPO / "config" / "panda.yaml"


@pytest.fixture(scope="module")
def learned():
    """A Panda estimator that learned 10 s at 200 Hz (residual ready, noise known)."""
    config = load_config(PANDA).with_overrides({"nonparametric.n_features": 100})
    est = OnlineEstimator(config)
    rec = simulate_arm(ArmScenarioConfig(name="ff", robot="panda", duration=10.0, rate=200.0, seed=1))
    for i in range(len(rec.stamps)):
        est.process(JointStateData(int(rec.stamps[i]), rec.joint_names, rec.q_measured[i],
                                               rec.dq_measured[i], rec.measured_torques[i]))
    return est, rec


def _point(q, dq=(), ddq=(), t_ns=0):
    return TrajectoryPoint(t_ns, np.asarray(q, float), np.asarray(dq, float), np.asarray(ddq, float))


def test_fresh_model_falls_back_to_the_cad_model():
    est = OnlineEstimator(load_config(PANDA).with_overrides({"nonparametric.n_features": 50}))
    ff = FeedForward(LearnedModel(est))
    pm = est.regressor.pinocchio_model
    data = pm.createData()
    q, dq, ddq = np.linspace(-0.5, 0.5, 7), np.full(7, 0.3), np.full(7, -1.0)
    q[3] = -1.5
    cmd = ff.compute(DesiredState(5, ff.joints, (_point(q, dq, ddq),)), now_ns=0)
    assert cmd is not None and cmd.source == "rigid_body" and cmd.reason == "not_ready"
    # the rigid-body part: the CAD model, through the consistent projection (its solver's accuracy)
    rnea = pin.rnea(pm, data, q, dq, ddq)
    np.testing.assert_allclose(cmd.tau, rnea, rtol=0, atol=1e-3 * np.abs(rnea).max())
    assert ff.counts["fallback.not_ready"] == 1 and ff.counts["published"] == 1


def test_joint_orders_and_interpolation_at_now(learned):
    est, rec = learned
    model = LearnedModel(est)
    joints = model.joints
    out_order = tuple(reversed(joints))
    ff = FeedForward(model, joints=out_order)
    rng = np.random.default_rng(0)
    q0, q1 = rec.q[100], rec.q[300]
    v0, v1 = rng.uniform(-0.5, 0.5, 7), rng.uniform(-0.5, 0.5, 7)
    a0, a1 = rng.uniform(-2, 2, 7), rng.uniform(-2, 2, 7)
    perm = rng.permutation(7)  # the controller's names in its own order
    names = tuple(joints[i] for i in perm)
    stamp = 10**9
    desired = DesiredState(stamp, names, (_point(q0[perm], v0[perm], a0[perm], 0),
                                          _point(q1[perm], v1[perm], a1[perm], 100_000_000)))
    now = stamp + 25_000_000  # a quarter of the way
    cmd = ff.compute(desired, now_ns=now)
    assert cmd is not None and cmd.source == "model" and cmd.stamp_ns == now
    qi, vi, ai = q0 + 0.25 * (q1 - q0), v0 + 0.25 * (v1 - v0), a0 + 0.25 * (a1 - a0)
    expected, std = model.predict(qi, vi, ai)
    back = [joints.index(j) for j in out_order]
    np.testing.assert_allclose(cmd.tau, expected[back], rtol=0, atol=1e-12 * (1 + np.abs(expected).max()))
    np.testing.assert_allclose(cmd.std, std[back], rtol=1e-12)
    np.testing.assert_allclose(cmd.q, qi[back], rtol=0, atol=1e-15)
    # before the first point: the first; after the last: the last; stamp 0: the first, at now
    first = ff.compute(desired, now_ns=stamp - 1)
    last = ff.compute(desired, now_ns=stamp + 10**9)
    np.testing.assert_allclose(first.q, q0[back])
    np.testing.assert_allclose(last.q, q1[back])
    zero = ff.compute(DesiredState(0, names, desired.points), now_ns=123)
    np.testing.assert_allclose(zero.q, q0[back])
    assert zero.stamp_ns == 123


def test_missing_velocities_count_as_zero_and_max_std_falls_back(learned):
    est, rec = learned
    model = LearnedModel(est)
    ff = FeedForward(model, max_std=1e-6)  # any σ exceeds it: the rigid-body part is sent
    cmd = ff.compute(DesiredState(1, model.joints, (_point(rec.q[50]),)), now_ns=1)
    parts = model.predict_parts(rec.q[50], np.zeros(7), np.zeros(7))
    assert cmd.source == "rigid_body" and cmd.reason == "std"
    np.testing.assert_array_equal(cmd.tau, parts.rigid_body)
    assert ff.counts["missing_velocities"] == 1 and ff.counts["missing_accelerations"] == 1
    assert ff.counts["fallback.std"] == 1


@pytest.mark.parametrize("names, point, reason", [
    (("panda_joint1", "gripper"), None, "unknown_joint"),
    (None, "short", "wrong_length"),
    (None, "nan", "non_finite"),
    (None, "inf_velocity", "non_finite"),
    (None, "huge", "non_finite"),
    ("missing", None, "missing_joint"),
    ("repeated", None, "missing_joint"),
    (None, "none", "no_point"),
])
def test_bad_desired_states_are_counted_drops_never_nan(learned, names, point, reason):
    est, _ = learned
    model = LearnedModel(est)
    ff = FeedForward(model)
    joints = model.joints
    if names == "missing":
        names = joints[:-1]
    elif names == "repeated":
        names = (*joints[:-1], joints[0])
    elif names is None:
        names = joints
    n = len(names)
    points = {
        None: (_point(np.zeros(n)),),
        "short": (_point(np.zeros(n - 1)),),
        "nan": (_point(np.r_[np.nan, np.zeros(n - 1)]),),
        "inf_velocity": (_point(np.zeros(n), np.r_[np.inf, np.zeros(n - 1)]),),
        "huge": (_point(np.full(n, 1e200)),),
        "none": (),
    }[point]
    assert ff.compute(DesiredState(1, tuple(names), points), now_ns=1) is None
    assert ff.counts[f"drops.{reason}"] == 1 and ff.counts["published"] == 0
    assert ff.last_error


def test_configuration_errors():
    est = OnlineEstimator(load_config(PANDA).with_overrides({"nonparametric.n_features": 20}))
    model = LearnedModel(est)
    with pytest.raises(ConfigurationError, match=r"feedforward\.joints"):
        FeedForward(model, joints=("panda_joint1", "nope"))
    with pytest.raises(ConfigurationError, match="max_std"):
        FeedForward(model, max_std=-1.0)
    wrench = OnlineEstimator(load_config(REPO / "config" / "icub_right_arm.yaml").with_overrides(
        {"nonparametric.n_features": 20}))
    with pytest.raises(ConfigurationError, match="joint_torques"):
        FeedForward(LearnedModel(wrench))
