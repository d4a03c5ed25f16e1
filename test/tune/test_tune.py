"""Tests of the hold-out hyperparameter selection (``tune``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import REPO

from semiparam_ros.cli.tune import main as tune_main
from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.build import build_model
from semiparam_ros.core.stream.rate import measured_period_s
from semiparam_ros.eval.bags.replay import load_samples
from semiparam_ros.tune.selection import CachedRegressor, holdout_search, split_holdout

ROOT = REPO
CONFIG = ROOT / "config" / "icub_right_arm.yaml"
XY = ROOT / "bags" / "icub_xy"
# a prefix of the committed bag and a small D keep the test fast; the full search is `tune` on the bag
N_SAMPLES = 900
SMALL = {"nonparametric.n_features": 60, "nonparametric.standardizer_warmup": 100}
GRID = {"parametric.lam": [1e-4, 1.0], "nonparametric.lam": [0.1, 10.0], "nonparametric.sigma": [1.0, 4.0]}


@pytest.fixture(scope="module")
def data():
    config = load_config(CONFIG).with_overrides(SMALL)
    samples, _ = load_samples(XY, config, limit=N_SAMPLES)
    return config, samples


def direct_holdout_nrmse(config, samples, holdout=0.2) -> float:
    """The hold-out error computed independently: fresh SP learner, learn the head, predict the tail."""
    n_hold = round(len(samples) * holdout)
    head, tail = slice(0, len(samples) - n_hold), slice(len(samples) - n_hold, len(samples))
    # the sample period as the product measures it (median step of the first stamps): it converts
    # adaptation.time_constant to β and a warm-up in seconds to samples
    model = build_model(config, "SP", sample_period_s=measured_period_s(samples.stamps_ns))
    for x, y in zip(samples.X[head], samples.Y[head], strict=True):
        model.learn_one(x, y)
    pred = np.array([model.predict_one(x).total for x in samples.X[tail]])
    rmse = np.sqrt(np.mean((pred - samples.Y[tail]) ** 2, axis=0))
    return float(np.mean(rmse / np.std(samples.Y[tail], axis=0)))


def test_tuned_values_are_no_worse_than_defaults_on_holdout(data) -> None:
    config, samples = data
    result = holdout_search(config, samples, holdout=0.2, grid=GRID)
    assert len(result.points) == 3 * 3 * 3  # the configuration's own values join each axis
    # rel 1e-9: the same arithmetic in the same order, so agreement is to the last bits; 1e-9 leaves room
    default_error = direct_holdout_nrmse(config, samples)
    assert result.default.score == pytest.approx(default_error, rel=1e-9)
    tuned_error = direct_holdout_nrmse(result.config, samples)
    assert tuned_error == pytest.approx(result.best.score, rel=1e-9)
    assert tuned_error <= default_error
    assert result.best.score == min(p.score for p in result.points)
    for key in ("parametric.lam", "nonparametric.lam", "nonparametric.sigma"):
        assert result.config[key] == result.best.values[key]


def test_tune_cli_writes_a_parameter_file_evaluate_accepts(tmp_path: Path, capsys) -> None:
    out = tmp_path / "tuned.yaml"
    argv = ["--train", str(XY), "--config", str(CONFIG), "--limit", "500", "--n-features", "40",
            "--set", "nonparametric.standardizer_warmup=100", "--lam-p", "0.01", "1", "--lam-np", "1",
            "--sigma", "2", "4", "--out", str(out), "--no-progress"]
    assert tune_main(argv) == 0
    printed = capsys.readouterr().out
    assert "| best" in printed or "best |" in printed
    tuned = load_config(out)  # the same loader the node's parameter declaration and evaluate use
    assert tuned["nonparametric.n_features"] == 40
    assert tuned["robot.joints"] == load_config(CONFIG)["robot.joints"]
    best_rows = ("| best |", "| best, default |")
    selected = next(line for line in printed.splitlines() if line.rstrip().endswith(best_rows)).split("|")
    assert tuned["parametric.lam"] == float(selected[1])
    assert tuned["nonparametric.sigma"] == float(selected[3])
    from semiparam_ros.cli.evaluate import main as evaluate_main

    assert evaluate_main(["paper", "--train", str(XY), "--test", str(XY), "--config", str(out),
                          "--train-limit", "200", "--test-limit", "200", "--splits", "2",
                          "--no-progress"]) == 0


def test_tune_spj_scores_the_joint_fit_and_selects_it(data, tmp_path: Path, capsys) -> None:
    """kind="SPJ": each grid point is scored with the joint semiparametric fit (the independent loop on a
    joint model gives the same hold-out error) and the tuned configuration selects it."""
    config, samples = data
    samples = samples.head(500)
    joint = config.with_overrides({"semiparametric.combination": "joint"})
    grid = {key: [config[key]] for key in ("parametric.lam", "nonparametric.lam", "nonparametric.sigma")}
    result = holdout_search(config, samples, holdout=0.2, grid=grid, kind="SPJ")
    assert len(result.points) == 1 and result.config["semiparametric.combination"] == "joint"
    assert result.default.score == pytest.approx(direct_holdout_nrmse(joint, samples), rel=1e-9)
    assert result.default.score != pytest.approx(direct_holdout_nrmse(config, samples), rel=1e-6)
    out = tmp_path / "tuned_joint.yaml"
    argv = ["--train", str(XY), "--config", str(CONFIG), "--limit", "300", "--n-features", "30",
            "--set", "nonparametric.standardizer_warmup=50", "--lam-p", "0.01", "--lam-np", "1",
            "--sigma", "4", "--model", "SPJ", "--out", str(out), "--no-progress"]
    assert tune_main(argv) == 0
    assert "holdout search of SPJ" in capsys.readouterr().out
    assert load_config(out)["semiparametric.combination"] == "joint"


def test_tune_rejects_bad_input(data) -> None:
    config, samples = data
    with pytest.raises(ValueError, match="holdout"):
        split_holdout(samples, 1.5)
    with pytest.raises(ValueError, match="cannot tune"):
        holdout_search(config, samples.head(100), grid={"robot.joints": [1.0]})
    with pytest.raises(ValueError, match="out of range"):
        holdout_search(config, samples.head(100), grid={"nonparametric.sigma": [-1.0]})
    assert tune_main(["--train", str(tmp_missing := XY.parent / "no_such_bag"), "--no-progress"]) == 2
    assert not tmp_missing.exists()


def test_cached_regressor_matches_the_regressor(data) -> None:
    from semiparam_ros.core.estimator.build import build_regressor

    config, samples = data
    reg = build_regressor(config)
    cached = CachedRegressor(reg)
    n = reg.n_joints
    for x in samples.X[:5]:
        q, dq, ddq = x[:n], x[n: 2 * n], x[2 * n:]
        np.testing.assert_array_equal(cached.base_regressor(q, dq, ddq), reg.base_regressor(q, dq, ddq))
        assert cached.base_regressor(q, dq, ddq) is cached.base_regressor(q, dq, ddq)
    assert cached.n_base == reg.n_base


def test_tune_on_a_joint_torque_bag_scores_per_joint_and_parallel_equals_serial(tmp_path: Path) -> None:
    """tune works on a 6-joint joint-torque bag (robot.output: joint_torques): the selected point is no worse
    on hold-out than the configuration's values (independent loop), and 2 parallel jobs give exactly the
    numbers of the serial search."""
    from helpers.bags import UR5_JOINTS as JOINTS6
    from helpers.bags import UR5_URDF as UR5
    from helpers.bags import ur5_config, write_ur5_torque_bag

    write_ur5_torque_bag(tmp_path / "ur5", 12.0, seed=3)
    small = {"nonparametric.n_features": 40, "nonparametric.standardizer_warmup": 50}
    config = ur5_config().with_overrides(small)
    samples, _ = load_samples(tmp_path / "ur5", config)
    grid = {"parametric.lam": [1e-4], "nonparametric.lam": [0.1, 1.0], "nonparametric.sigma": [2.0]}
    serial = holdout_search(config, samples, grid=grid, jobs=1)
    parallel = holdout_search(config, samples, grid=grid, jobs=2)
    assert serial.points == parallel.points  # same values, same scores, bit for bit
    assert set(serial.best.rmse) == {"torque"}  # one group over the joints, no "force"
    assert serial.default.score == pytest.approx(direct_holdout_nrmse(config, samples), rel=1e-9)
    assert direct_holdout_nrmse(serial.config, samples) <= serial.default.score * (1 + 1e-9)
    out = tmp_path / "tuned.yaml"
    argv = ["--train", str(tmp_path / "ur5"), "--config", str(CONFIG), "--set", f"robot.urdf={UR5}",
            "--set", f"robot.joints=[{', '.join(JOINTS6)}]", "--set", "robot.locked_joints=[]",
            "--set", "robot.locked_positions=[]", "--set", "robot.output=joint_torques",
            "--n-features", "30", "--lam-p", "0.01", "--lam-np", "1", "--sigma", "2", "--out", str(out),
            "--jobs", "1", "--no-progress"]
    assert tune_main(argv) == 0
    assert load_config(out)["robot.output"] == "joint_torques"
