"""``evaluate --per-sample`` / ``--per-sample-plot`` and the message for a joint the bag does not have.

The CSV's measured column is checked against the bag decoded independently (``read_messages``), its
predictions against the protocol result, its std against a hand-written exponentially weighted mean.
"""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from helpers.ros import CONFIG, write_torque_bag

from semiparam_ros.cli import evaluate as evaluate_cli
from semiparam_ros.io.bags import read_messages


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    root = tmp_path_factory.mktemp("per_sample")
    write_torque_bag(root / "train", 400)
    write_torque_bag(root / "test", 300)
    return root


def test_per_sample_csv_and_figure(bags, tmp_path):
    out, fig = tmp_path / "samples.csv", tmp_path / "samples.png"
    code = evaluate_cli.main([
        "paper", "--train", str(bags / "train"), "--test", str(bags / "test"), "--config", str(CONFIG),
        "--set", "robot.output=joint_torques", "--set", "nonparametric.n_features=30",
        "--models", "P", "SP", "--splits", "2", "--window", "0.5", "--no-progress",
        "--per-sample", str(out), "--per-sample-plot", str(fig)])
    assert code == 0
    assert fig.stat().st_size > 10_000
    with open(out) as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], rows[1:]
    joints = ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]
    assert header[:3] == ["split", "stamp_ns", "time_s"]
    assert header[3:7] == [f"measured.{j}" for j in joints]
    assert header[7:11] == [f"P.{j}" for j in joints] and header[11:15] == [f"P.std.{j}" for j in joints]
    assert header[15:19] == [f"SP.{j}" for j in joints]
    col = {name: i for i, name in enumerate(header)}
    effort = {m.stamp_ns: np.asarray(m.effort) for m in read_messages(bags / "test", wrench_topic=None)}
    stamps = [int(r[col["stamp_ns"]]) for r in body]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    assert {int(r[0]) for r in body} == {0, 1}
    for r in body:
        np.testing.assert_array_equal([float(r[col[f"measured.{j}"]]) for j in joints],
                                      effort[int(r[col["stamp_ns"]])])  # repr(float) round-trips exactly
    # the std: an exponentially weighted mean in time of the model's own squared a-priori errors
    tau = 2.0  # uncertainty.noise_time_constant of the shipped configuration
    j = joints[0]
    s2, last = None, None
    for r in body:
        std = float(r[col[f"SP.std.{j}"]])
        assert std == (math.inf if s2 is None else pytest.approx(math.sqrt(s2), rel=1e-12))
        e = float(r[col[f"measured.{j}"]]) - float(r[col[f"SP.{j}"]])
        t = int(r[col["stamp_ns"]])
        s2 = e * e if s2 is None else s2 + (1 - math.exp(-(t - last) * 1e-9 / tau)) * (e * e - s2)
        last = t


def test_a_joint_the_bag_lacks_is_named_with_the_bags_names(bags, capsys):
    code = evaluate_cli.main([
        "paper", "--train", str(bags / "train"), "--test", str(bags / "test"), "--config", str(CONFIG),
        "--set", "robot.output=joint_torques",
        "--set", "robot.joints=[r_shoulder_pitch, r_elbow, r_wrist_yaw]",
        "--set", "robot.locked_joints=[r_wrist_prosup, r_wrist_pitch]",
        "--set", "robot.locked_positions=[0, 0]", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert "lack the configured joint(s) ['r_wrist_yaw']" in err, err
    assert "they name ['r_shoulder_pitch', 'r_shoulder_roll', 'r_shoulder_yaw', 'r_elbow']" in err, err
    assert "drops" not in err


def test_evaluate_on_a_truncated_bag_says_so_in_the_json_and_the_report(bags, tmp_path, capsys):
    import json

    mcap = next((bags / "test").glob("*.mcap"))
    raw = mcap.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(raw[: int(0.7 * len(raw))])
    out = tmp_path / "report.json"
    code = evaluate_cli.main([
        "paper", "--train", str(bags / "train"), "--test", str(cut), "--config", str(CONFIG),
        "--set", "robot.output=joint_torques", "--set", "nonparametric.n_features=30",
        "--models", "P", "--splits", "2", "--window", "0.5", "--no-progress", "--json", str(out)])
    assert code == 0
    notes = json.loads(out.read_text())["protocol"]["recovered_bags"]
    assert len(notes) == 1 and "cut.mcap" in notes[0] and "recovered" in notes[0]
    assert "WARNING: bag" in capsys.readouterr().out


def test_joint_torques_lead_with_what_a_controller_gets(bags, tmp_path, capsys):
    """On joint torques the first table is the served model (frozen) beside one step ahead, persistence
    included; its numbers are the JSON's horizon means, and persistence one step ahead is the RMS of the
    measured torques' one-step differences on the scored samples, computed here from the bag itself."""
    import json

    out = tmp_path / "report.json"
    code = evaluate_cli.main([
        "paper", "--train", str(bags / "train"), "--test", str(bags / "test"), "--config", str(CONFIG),
        "--set", "robot.output=joint_torques", "--set", "nonparametric.n_features=30",
        "--models", "P", "SP", "--splits", "2", "--window", "0.5", "--no-progress", "--json", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert text.index("## What a controller gets") < text.index("## One step ahead (test-then-train")
    assert "## By the age of the model" not in text  # the full age table stays an option (--horizons)
    means = json.loads(out.read_text())["protocol"]["horizons"]["mean"]
    rows = {line.split("|")[1].strip(): line.split("|")[2:4] for line in text.splitlines()
            if line.startswith("| ") and line.count("|") == 4}
    for model in ("P", "SP"):
        assert float(rows[model][0]) == pytest.approx(means[model]["frozen"], abs=5e-4)
        assert float(rows[model][1]) == pytest.approx(means[model]["1 step"], abs=5e-4)
    persistence = rows["persistence (the previous measured output)"]
    assert persistence[0].strip() == "—"
    effort = np.array([m.effort for m in read_messages(bags / "test", wrench_topic=None)])
    # the pipeline's q̈ window drops the first samples (and holds the last): the scored ones are a
    # contiguous run of the bag, so the one-step differences over any long run agree to a few percent
    direct = float(np.mean(np.sqrt(np.mean(np.diff(effort, axis=0) ** 2, axis=0))))
    assert float(persistence[1]) == pytest.approx(direct, rel=0.1)
