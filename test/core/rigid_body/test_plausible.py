"""Plausible exports (core.rigid_body.plausible): what the data did not determine stays at the URDF's values.

Against a simulator's truth and Pinocchio: on a well-excited Panda nothing is held and the export is the
consistent estimate; a link made implausible is held at its URDF values exactly and the rest re-fitted; a
payload carried by the hand is named; the file's comment and the command's warning say which links came
from where; on the real KUKA log that produced a 0.018 kg link 1.45 m off its frame, every exported link is
within the bounds or named.
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from helpers import KUKA, REPO

from semiparam_ros.core.config import load_config
from semiparam_ros.core.rigid_body.identification import export_urdf, link_of
from semiparam_ros.core.rigid_body.plausible import COM_DISTANCE_M, MASS_RATIO, check_link, plausible_links
from semiparam_ros.serving.bag_learning import learn_bags
from semiparam_ros.serving.learned_model import LearnedModel
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
from semiparam_ros.sim.writer import write_recording

pytest.importorskip("cvxpy")


def _learned(root, name, **sim):
    rec = simulate_arm(ArmScenarioConfig(name=name, robot="panda", duration=20.0, rate=200.0, **sim))
    bag = write_recording(rec, root / name)
    config = load_config(REPO / "config" / "panda.yaml").with_overrides({"nonparametric.n_features": 50})
    est, _ = learn_bags([bag], config)
    return est, rec


@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    return _learned(tmp_path_factory.mktemp("plausible"), "panda_plausible", seed=0)


def _inputs(est):
    par = est.model.parametric
    return par.parameters, par.rls.R, est.column_scale, par.rls.lam


def test_well_excited_links_are_all_from_the_data(panda):
    est, _ = panda
    model = LearnedModel(est)
    links = model.plausible_links()
    assert links.held == () and links.torque_change_rms == 0.0 and links.warning() == ""
    np.testing.assert_array_equal(links.estimate.full, model.consistent().full)
    assert all(link.from_data for link in links.links)


def test_an_implausible_link_is_held_at_the_urdf_and_the_rest_refitted(panda):
    est, _ = panda
    reg = est.regressor
    good = LearnedModel(est).consistent()
    bad = good.full.copy()
    i = 2  # panda_link3: a 100 g link 1.5 m off its frame (what a short real log gave the KUKA)
    bad[10 * i: 10 * i + 4] = [0.1, 0.1, 0.1, 0.1]
    links = plausible_links(reg, dataclasses.replace(good, full=bad), *_inputs(est))
    urdf = reg.urdf_parameters()
    assert [link.body for link in links.held] == [reg.body_names[i]]
    np.testing.assert_allclose(links.estimate.full[10 * i: 10 * i + 10], urdf[10 * i: 10 * i + 10],
                               rtol=1e-6, atol=1e-9)
    assert links.links[i].from_data == () and "not determined by the data" in links.warning()
    for k in range(reg.n_bodies):
        m, c, _ = links.estimate.link(k)
        mu, cu, _ = link_of(urdf, k)
        assert check_link(m, c, mu, cu, distal=k == reg.body_index(reg.distal_body_name)) == "", k
    # the price is measured: the exported links against the estimate they replace, over random states
    assert links.torque_change_rms > 0.0


def test_a_payload_on_the_hand_is_named(tmp_path):
    est, _ = _learned(tmp_path, "panda_carry_export", seed=3, payload_mass=1.2, payload_time=0.0,
                        perturbation=None)
    links = LearnedModel(est).plausible_links()
    hand = links.links[est.regressor.body_index(est.regressor.distal_body_name)]
    true_extra = 1.2
    assert hand.payload == pytest.approx(true_extra, rel=0.15)
    assert f"{hand.body} carries" in links.warning()


def test_the_exported_file_says_where_each_link_came_from(panda):
    est, _ = panda
    links = LearnedModel(est).plausible_links()
    text = export_urdf(est.regressor, links.estimate, links.comments())
    root = ET.fromstring(text)
    assert root.get("name") == "panda"
    comment = text[text.index("<!--"): text.index("-->")]
    for body in est.regressor.body_names:
        assert f"{body}: " in comment
    assert "from the data" in comment


def test_check_link_bounds():
    assert check_link(1.0, np.zeros(3), 1.0, np.zeros(3), distal=False) == ""
    assert "mass" in check_link(1.01 * MASS_RATIO, np.zeros(3), 1.0, np.zeros(3), distal=False)
    assert check_link(1.01 * MASS_RATIO, np.zeros(3), 1.0, np.zeros(3), distal=True) == ""  # a payload
    assert "mass" in check_link(0.99 / MASS_RATIO, np.zeros(3), 1.0, np.zeros(3), distal=True)
    far = np.array([0.0, 0.0, 1.01 * COM_DISTANCE_M])
    assert "centre of mass" in check_link(1.0, far, 1.0, np.zeros(3), distal=False)
    # a long link whose URDF centre of mass is far already: 1.5 × that distance is plausible
    assert check_link(1.0, far, 1.0, np.array([0.0, 0.0, 0.2]), distal=False) == ""


@pytest.mark.skipif(not (KUKA / "measurements_1").is_dir(), reason=f"{KUKA} is absent")
def test_kuka_log_1_exports_plausible_links_or_names_them(tmp_path, capsys):
    """The real log that gave lwr_6_link 0.018 kg with its centre of mass 1.45 m from its frame."""
    from semiparam_ros.cli import export_urdf as cli

    config = load_config(REPO / "config" / "kuka_lwr4.yaml").with_overrides(
        {"robot.urdf": str(KUKA / "kuka_lwr4_cogimon.urdf")})
    learn_bags([KUKA / "measurements_1"], config, checkpoint=tmp_path / "k1.npz")
    assert cli.main(["--checkpoint", str(tmp_path / "k1.npz"), "--out", str(tmp_path / "k1.urdf")]) == 0
    warning = capsys.readouterr().err
    root = ET.parse(tmp_path / "k1.urdf").getroot()
    cad = ET.parse(KUKA / "kuka_lwr4_cogimon.urdf").getroot()
    cad_mass = {link.get("name"): float(link.find("inertial/mass").get("value"))
                for link in cad.findall("link") if link.find("inertial") is not None}
    for i in range(1, 8):
        name = f"lwr_{i}_link"
        inertial = root.find(f"link[@name='{name}']/inertial")
        mass = float(inertial.find("mass").get("value"))
        com = np.array([float(v) for v in inertial.find("origin").get("xyz").split()])
        plausible = (cad_mass[name] / 4 <= mass <= 4 * cad_mass[name] and np.linalg.norm(com) <= 0.25)
        assert plausible or name in warning, (name, mass, com)
