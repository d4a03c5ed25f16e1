"""The start-up check that measured efforts are the URDF's joint torques in N·m (core.estimator.units).

The truth is a simulated Panda (joint torques = RNEA of perturbed inertias + friction + noise, in N·m):
read as they are, nothing is flagged; read through a per-joint scale (what a driver reporting currents
does), exactly the joints whose gravity load the URDF predicts are named, each with the scale applied.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import REPO

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.estimator.units import MAX_RATIO, EffortUnitsCheck
from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm


@pytest.fixture(scope="module")
def panda():
    rec = simulate_arm(ArmScenarioConfig(name="units", robot="panda", duration=8.0, rate=200.0, seed=3))
    config = load_config(REPO / "config" / "panda.yaml").with_overrides({"nonparametric.n_features": 20})
    return rec, config


def _stream(est: OnlineEstimator, rec) -> None:
    for k, stamp in enumerate(rec.stamps):
        est.process(JointStateData(int(stamp), rec.joint_names, rec.q_measured[k], rec.dq_measured[k],
                                   rec.measured_torques[k]))


def test_torques_in_newton_metres_are_not_flagged(panda):
    rec, config = panda
    est = OnlineEstimator(config)
    _stream(est, rec)
    assert est.units_check is not None and est.units_check.done
    assert est.units_check.findings == () and est.warnings == []


def test_scaled_efforts_name_the_joints_and_their_scale(panda):
    """effort_scale multiplies the efforts on input: 1/10.5 reads like currents of a 10.5 N·m/A joint."""
    rec, config = panda
    scale = np.ones(7)
    scale[[1, 3]] = 1 / 10.5  # shoulder and elbow: large gravity torques
    scale[5] = -1.0  # a flipped sign
    est = OnlineEstimator(config.with_overrides({"robot.effort_scale": scale.tolist()}))
    _stream(est, rec)
    found = {f.joint: f.scale for f in est.units_check.findings}
    assert set(found) == {"panda_joint2", "panda_joint4", "panda_joint6"}
    # the fitted scale is the applied one times the measured/URDF ratio of the joint (≈ 1: 15 % perturbed)
    np.testing.assert_allclose(found["panda_joint2"], 1 / 10.5, rtol=0.3)
    assert found["panda_joint6"] < 0
    assert len(est.warnings) == 1
    assert "panda_joint2" in est.warnings[0] and "robot.effort_scale" in est.warnings[0]


def test_a_joint_the_urdf_barely_loads_is_not_judged():
    """The first joint of a vertical-axis arm carries no gravity torque: its efforts say nothing of units."""
    class Urdf:
        def wrench(self, q, dq, ddq):
            return np.array([1e-6 * q[0], 5.0 * np.sin(q[1])])

    check = EffortUnitsCheck(Urdf(), ("base", "shoulder"), n_samples=20)
    rng = np.random.default_rng(0)
    for k in range(40):
        q = rng.uniform(-1, 1, 2)
        check.add(k * 10**8, q, q, q, np.array([100.0 * q[0], 5.0 * np.sin(q[1]) * 3 * MAX_RATIO]))
    assert [f.joint for f in check.findings] == ["shoulder"]


def test_the_check_reads_one_sample_per_spacing_whatever_the_rate():
    class Urdf:
        calls = 0

        def wrench(self, q, dq, ddq):
            Urdf.calls += 1
            return np.ones(1)

    check = EffortUnitsCheck(Urdf(), ("a",), n_samples=10, spacing_s=0.01)
    for k in range(100):  # 1 kHz for 0.1 s: ten samples 10 ms apart
        check.add(k * 10**6, np.zeros(1), np.zeros(1), np.zeros(1), np.ones(1))
    assert Urdf.calls == 10 and check.done
