"""Payload identification: the simulator's truth, a Monte Carlo of the propagation, checkpoints.

References: the simulated Panda's true parameters before and after a pickup (a point mass at a known
point of the end-effector frame); a Monte-Carlo sample of the parameter change for the propagated
standard deviations; the closed-form point mass and parallel-axis theorem.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import REPO

from semiparam_ros import load_model
from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.rigid_body.dynamics import point_mass_parameters
from semiparam_ros.core.rigid_body.payload import PayloadLearner, payload_beyond_urdf, payload_from_parameters
from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.errors import CheckpointError
from semiparam_ros.sim.arms import ARM_ROBOTS, ArmScenarioConfig, arm_regressor, simulate_arm


def _box(mass: float, size: tuple[float, float, float]) -> np.ndarray:
    """Inertia of a solid box about its centre [kg·m²]."""
    a, b, c = size
    return mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def test_values_and_propagated_std_against_closed_form_and_monte_carlo():
    mass, com, inertia = 2.0, np.array([0.03, -0.01, 0.12]), _box(2.0, (0.1, 0.06, 0.2))
    delta = point_mass_parameters(mass, com)
    delta[4:] += [inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2], inertia[2, 2]]
    rng = np.random.default_rng(0)
    L = rng.normal(size=(10, 10)) * np.r_[1e-3, [2e-4] * 3, [5e-5] * 6][:, None]
    cov = L @ L.T
    est = payload_from_parameters(delta, cov, body="b", n_samples=1, reference="tare")
    assert est.mass == pytest.approx(mass) and est.com == pytest.approx(com)
    np.testing.assert_allclose(est.inertia, inertia, atol=1e-12)
    # Monte Carlo of the same propagation: the first-order stds hold to a few % at these small spreads
    draws = rng.multivariate_normal(delta, cov, size=20000)
    samples = [payload_from_parameters(d, np.zeros((10, 10)), body="b", n_samples=1, reference="t")
               for d in draws[:4000]]
    mc_mass = np.std([s.mass for s in samples])
    mc_com = np.std([s.com for s in samples], axis=0)
    mc_izz = np.std([s.inertia[2, 2] for s in samples])
    assert est.mass_std == pytest.approx(mc_mass, rel=0.05)
    np.testing.assert_allclose(est.com_std, mc_com, rtol=0.05)
    assert est.inertia_std[2, 2] == pytest.approx(mc_izz, rel=0.05)


@pytest.fixture(scope="module")
def panda_pickup():
    """The simulated Panda (1 kHz, friction, noise) picking its preset payload up at 10 s of 20 s."""
    spec = ARM_ROBOTS["panda"]
    rec = simulate_arm(ArmScenarioConfig(name="payload_test", robot="panda", duration=20.0, seed=1,
                                         payload_mass=spec.payload_mass, payload_time=10.0))
    reg = arm_regressor("panda")
    body = reg.body_index(reg.distal_body_name)
    cols = slice(10 * body, 10 * body + 10)
    truth = payload_from_parameters(rec.parameters_after[cols] - rec.parameters_before[cols],
                                    np.zeros((10, 10)), body=reg.distal_body_name, n_samples=0, reference="t")
    est = OnlineEstimator(load_config(REPO / "config" / "panda.yaml"))
    tare_ns = int(rec.stamps[0]) + round(9.8e9)  # the user tares, then picks the payload up 0.2 s later
    detected_before_pickup = None
    for k in range(rec.stamps.shape[0]):
        stamp = int(rec.stamps[k])
        if est.payload is None and stamp >= tare_ns:
            est.tare_payload()
        if detected_before_pickup is None and stamp >= tare_ns + round(0.19e9):
            detected_before_pickup = est.payload.detected
        est.process_joint_state(JointStateData(stamp, rec.joint_names, rec.q_measured[k], rec.dq_measured[k],
                                               rec.measured_torques[k]))
    return est, truth, detected_before_pickup


def test_payload_after_a_tare_meets_the_target_on_the_simulated_panda(panda_pickup, tmp_path):
    """10 s after the pickup: mass within 2 %, centre of mass within 5 mm (from a checkpoint)."""
    est, truth, detected_before_pickup = panda_pickup
    assert detected_before_pickup is False  # nothing carried between the tare and the pickup
    path = tmp_path / "panda.npz"
    est.save(path)
    got = load_model(path).payload()
    assert got.detected and got.reference == "tare" and got.body == truth.body
    assert 9000 < got.n_samples < 10100  # the samples after the detected pickup
    assert abs(got.mass - truth.mass) <= 0.02 * truth.mass
    assert np.linalg.norm(got.com - truth.com) <= 0.005
    # its standard deviations are those of a well-determined estimate, not the prior's
    assert got.mass_std < 0.01 * truth.mass and np.all(got.com_std < 0.002)
    # the checkpoint holds the payload learner: the same estimate, bit for bit
    assert got.mass == est.payload.estimate().mass


def test_payload_learner_state_is_validated_on_load():
    reg = arm_regressor("panda")
    learner = PayloadLearner(reg, reg.to_base(reg.urdf_parameters()))
    state = learner.state_dict("payload.")
    bad = dict(state)
    bad["payload.reference"] = np.full(reg.n_base, np.nan)
    with pytest.raises(CheckpointError):
        PayloadLearner.from_state_dict(reg, bad, "payload.")
    del bad["payload.counts"]
    with pytest.raises(CheckpointError):
        PayloadLearner.from_state_dict(reg, bad, "payload.")


def test_payload_beyond_urdf_is_the_distal_change_of_the_consistent_estimate():
    reg = arm_regressor("panda")
    body = reg.body_index(reg.distal_body_name)
    full = reg.urdf_parameters().copy()
    full[10 * body: 10 * body + 10] += point_mass_parameters(0.8, [0.0, 0.02, 0.15])
    R = np.eye(reg.n_base) * 100.0
    got = payload_beyond_urdf(reg, full, R, np.ones(reg.n_base), 1e-3, np.ones(reg.n_params), 1e-4, 123)
    assert got.reference == "urdf" and got.n_samples == 123
    assert got.mass == pytest.approx(0.8) and got.com == pytest.approx([0.0, 0.02, 0.15])
    assert got.mass_std > 0
