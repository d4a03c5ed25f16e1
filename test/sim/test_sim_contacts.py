"""Contact episodes: drawn within their ranges, exact force profiles, and the iCub F/T sensor's transmitted
wrench against Pinocchio's RNEA with an external force; bags with contacts read back; a contacts-then-payload
scenario exists."""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin
import pytest
import yaml

from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.core.rigid_body.urdf import icub_urdf_path
from semiparam_ros.io.bags import read_topic_arrays
from semiparam_ros.sim.contacts import ContactConfig, ContactEpisode, contact_forces, draw_episodes
from semiparam_ros.sim.effects import SENSOR_FRAME
from semiparam_ros.sim.generate import preset_configs
from semiparam_ros.sim.ik import ARM_JOINTS
from semiparam_ros.sim.scenario import CONTACTS_DURATION_S, ScenarioConfig, simulate
from semiparam_ros.sim.writer import write_recording

HAND = "r_hand_dh_frame"
SHORT = ContactConfig(rate=30.0, duration_range=(0.2, 1.0), window=(1.0, 5.0), min_gap=0.3)


@pytest.mark.parametrize("seed", range(20))
def test_episodes_respect_their_ranges(seed):
    config = ContactConfig(rate=5.0, duration_range=(0.2, 3.0), force_range=(5.0, 30.0), window=(10.0, 130.0))
    episodes = draw_episodes(config, 150.0, np.random.default_rng(seed))
    assert len(episodes) == 10  # 5 per minute over 120 s
    for ep in episodes:
        assert 10.0 <= ep.start and ep.end <= 130.0
        assert 0.2 <= ep.duration <= 3.0 and 5.0 <= ep.peak_force <= 30.0
        assert abs(np.linalg.norm(ep.direction) - 1.0) < 1e-12
        assert ep.ramp == min(config.ramp, ep.duration / 4)
    for a, b in itertools.pairwise(episodes):
        assert b.start >= a.end + config.min_gap - 1e-12


def test_directions_cover_the_sphere():
    config = ContactConfig(rate=30.0, window=(0.0, 6000.0))
    directions = np.array([e.direction for e in draw_episodes(config, 6000.0, np.random.default_rng(0))])
    # Uniform on the sphere: each component has mean 0 and variance 1/3 (n = 3000; 5σ bounds).
    n = directions.shape[0]
    assert np.all(np.abs(directions.mean(axis=0)) < 5 * np.sqrt(1 / 3 / n))
    assert np.all(np.abs((directions**2).mean(axis=0) - 1 / 3) < 5 * np.sqrt(4 / 45 / n))


def test_force_profile_is_a_smooth_trapezoid_zero_outside():
    ep = ContactEpisode(start=2.0, duration=1.0, peak_force=20.0, direction=(0.0, 0.6, 0.8), ramp=0.1)
    t = np.array([1.999, 2.0, 2.05, 2.1, 2.5, 2.9, 2.95, 3.0, 3.001])
    F = contact_forces((ep,), t)
    magnitude = np.linalg.norm(F, axis=1)
    expected = 20.0 * np.array([0.0, 0.0, 0.5, 1.0, 1.0, 1.0, 0.5, 0.0, 0.0])
    np.testing.assert_allclose(magnitude, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(F[4], [0.0, 12.0, 16.0], rtol=0, atol=1e-12)


def test_invalid_contact_configs_are_refused():
    for kwargs in (
        {"rate": 0.0},
        {"force_range": (30.0, 5.0)},
        {"duration_range": (0.0, 1.0)},
        {"window": (5.0, 1.0)},
        {"ramp": -1.0},
    ):
        with pytest.raises(ValueError):
            ContactConfig(**kwargs)
    with pytest.raises(ValueError, match="per minute"):
        draw_episodes(ContactConfig(rate=100.0, duration_range=(1.0, 2.0)), 60.0, np.random.default_rng(0))


@pytest.fixture(scope="module")
def icub_pair():
    with_contacts = simulate(ScenarioConfig(name="icub_c", trajectory="xy", duration=6.0, contacts=SHORT))
    without = simulate(ScenarioConfig(name="icub_c", trajectory="xy", duration=6.0))
    return with_contacts, without


def test_icub_transmitted_wrench_equals_rnea_with_the_external_force(icub_pair):
    rec, _ = icub_pair
    locked = rec.info["locked_joints_rad"]
    reg = RigidBodyRegressor.from_urdf(icub_urdf_path(), ARM_JOINTS, ft_sensor=SENSOR_FRAME, locked=locked)
    model = reg.pinocchio_model
    data = model.createData()
    hand = model.getFrameId(HAND)
    sensor = model.joints[model.getJointId(SENSOR_FRAME)]
    idx_q = [model.joints[model.getJointId(n)].idx_q for n in ARM_JOINTS]
    idx_v = [model.joints[model.getJointId(n)].idx_v for n in ARM_JOINTS]
    t = (rec.wrench_stamps - rec.config.start_ns) * 1e-9
    force = contact_forces(rec.contact_episodes, t)
    active = np.flatnonzero(np.linalg.norm(force, axis=1) > 0)
    assert active.size > 50
    for i in active:
        q, v, a = pin.neutral(model), np.zeros(model.nv), np.zeros(model.nv)
        q[idx_q], v[idx_v], a[idx_v] = rec.wrench_q[i], rec.wrench_dq[i], rec.wrench_ddq[i]
        pin.framesForwardKinematics(model, data, q)
        p = data.oMf[hand].translation
        fext = [pin.Force.Zero() for _ in range(model.njoints)]
        jid = model.frames[hand].parentJoint
        fext[jid] = data.oMi[jid].actInv(pin.Force(force[i], np.cross(p, force[i])))
        diff = pin.rnea(model, data, q, v, a, fext) - pin.rnea(model, data, q, v, a)
        # The reading is the wrench the distal side exerts on the sensor: minus the free-flyer's "torque".
        expected = -diff[sensor.idx_v : sensor.idx_v + 6]
        # |F| ≤ 30 N at ≤ 0.3 m: terms ≤ 10 N·m, exact to ≈1e-14; 1e-10 keeps a wide margin.
        np.testing.assert_allclose(rec.external_wrench[i], expected, rtol=0, atol=1e-10)
        np.testing.assert_allclose(
            rec.contact_wrench[i, :3], data.oMf[hand].rotation.T @ force[i], atol=1e-12
        )
    others = np.setdiff1d(np.arange(t.size), active)
    assert not np.any(rec.external_wrench[others]) and not np.any(rec.contact_wrench[others])


def test_icub_contacts_change_only_the_reading_through_the_sensor(icub_pair):
    rec, plain = icub_pair
    for field in ("q_measured", "dq_measured", "rigid_wrench", "cable_wrench", "wrench_q"):
        np.testing.assert_array_equal(getattr(rec, field), getattr(plain, field))
    E = rec.config.effects.calibration
    transmitted = rec.external_wrench + rec.external_wrench @ E.T  # the sensor's calibration error applies
    np.testing.assert_allclose(rec.true_wrench - plain.true_wrench, transmitted, rtol=0, atol=1e-12)
    # Same noise draws: (truth + ε) − truth is ε up to one rounding of |truth| ≤ 40 N (≈1e-14).
    np.testing.assert_allclose(
        rec.measured_wrench - rec.true_wrench, plain.measured_wrench - plain.true_wrench, rtol=0, atol=1e-12
    )
    assert "contacts" not in plain.info and plain.external_wrench is None


def test_icub_contact_bag_reads_back(icub_pair, tmp_path):
    rec, _ = icub_pair
    path = write_recording(rec, tmp_path / "icub_c")
    contact = read_topic_arrays(path, "/ground_truth/contact_wrench")
    external = read_topic_arrays(path, "/ground_truth/external_wrench")
    assert contact.frame_id == HAND and external.frame_id == SENSOR_FRAME
    assert np.array_equal(contact.stamp_ns, rec.wrench_stamps) and np.array_equal(
        external.stamp_ns, rec.wrench_stamps
    )
    np.testing.assert_array_equal(contact.fields["wrench"], rec.contact_wrench)
    np.testing.assert_array_equal(external.fields["wrench"], rec.external_wrench)
    np.testing.assert_array_equal(read_topic_arrays(path, "/wrench").fields["wrench"], rec.measured_wrench)
    info = yaml.safe_load((path / "scenario.yaml").read_text())
    assert [e["start_s"] for e in info["contacts"]["episodes"]] == [e.start for e in rec.contact_episodes]
    assert len(rec.contact_episodes) == 2 and info["contacts"]["frame"] == HAND
    assert info["topics"]["/ground_truth/external_wrench"]["count"] == rec.wrench_stamps.size


def test_contacts_scenario_puts_the_pickup_after_the_last_contact():
    (config,) = preset_configs("icub", ("contacts",))
    assert config.name == "icub_contacts" and config.duration == CONTACTS_DURATION_S
    assert config.contacts is not None and config.payload_mass == 0.5
    start, end = config.contacts.span(config.duration)
    assert config.pickup_time is not None and config.pickup_time >= end + 10.0  # 10 s of contact-free error
    episodes = draw_episodes(config.contacts, config.duration, np.random.default_rng(0))
    assert len(episodes) == round(config.contacts.rate * (end - start) / 60.0) >= 3


def test_cli_writes_an_icub_contacts_bag(tmp_path):
    from semiparam_ros.cli.simulate import main

    args = [
        "--scenario",
        "contacts",
        "--duration",
        "6",
        "--contact-rate",
        "40",
        "--contact-force",
        "10",
        "12",
    ]
    assert main([*args, "--rate", "100", "--out", str(tmp_path), "--quiet"]) == 0
    info = yaml.safe_load((tmp_path / "icub_contacts" / "scenario.yaml").read_text())
    episodes = info["contacts"]["episodes"]
    assert len(episodes) == 2 and all(10 <= e["peak_force_N"] <= 12 for e in episodes)  # 40/min · 3 s
    assert info["payload"]["time_s"] == 4.5 and episodes[-1]["end_s"] <= 3.9
    assert info["topics"]["/ground_truth/external_wrench"]["count"] == 600
