"""Dask clusters: the serial numbers, a worker lost mid-run, clear errors, a fleet, selection on other bags.

Every cluster here is a real ``distributed.LocalCluster`` (``--cluster local:2``: a scheduler and two
worker processes). References: the serial run of the same command (``--jobs 1``), separate ``learn``
runs for the fleet, and ``load_model`` on a checkpoint of ``learn`` for the validation score.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import cloudpickle
import numpy as np
import pytest
from helpers import REPO
from helpers.jobs import square_or_die_once
from threadpoolctl import threadpool_limits

from semiparam_ros import load_model
from semiparam_ros.core.config import load_config, write_config
from semiparam_ros.eval.bags.replay import Topics, evaluate_bags, load_samples
from semiparam_ros.jobs.cluster import connect, run_on_cluster
from semiparam_ros.serving.bag_learning import learn_bags
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
from semiparam_ros.sim.writer import write_recording
from semiparam_ros.tune.fleet import learn_fleet
from semiparam_ros.tune.held_out import validation_error, validation_search

pytestmark = pytest.mark.slow

ICUB = REPO / "config" / "icub_right_arm.yaml"
KUKA = REPO.parent / "shared" / "data" / "kuka_lwr4"
needs_kuka = pytest.mark.skipif(not (KUKA / "measurements_1").is_dir(), reason=f"{KUKA} is absent")
SMALL_GRID = ["--lam-p", "0.01", "--lam-np", "0.1", "1", "--sigma", "4"]

cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import test modules


def _cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", "import sys; from semiparam_ros.cli.tune import main; "
                           "sys.exit(main(sys.argv[1:]))", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO)


def test_tune_on_a_local_cluster_equals_the_serial_run(tmp_path):
    common = ["--train", str(REPO / "bags" / "icub_xy"), "--config", str(ICUB), "--limit", "1500",
              *SMALL_GRID]
    serial = _cli(*common, "--jobs", "1", "--json", str(tmp_path / "serial.json"))
    cluster = _cli(*common, "--cluster", "local:2", "--json", str(tmp_path / "cluster.json"))
    assert serial.returncode == 0 and cluster.returncode == 0, (serial.stderr, cluster.stderr)
    a, b = (json.loads((tmp_path / f).read_text()) for f in ("serial.json", "cluster.json"))
    assert a["selections"] == b["selections"]  # the same points, scores and selection, to the last bit
    assert serial.stdout.splitlines()[-1] == cluster.stdout.splitlines()[-1]


def test_evaluate_on_a_local_cluster_equals_the_serial_run():
    config = load_config(ICUB)
    kwargs = {"kinds": ("P", "NP", "SP"), "train_limit": 1200, "test_limit": 1000, "splits": 2,
              "horizons": (0.0, 1.0, "frozen")}
    serial, info_s = evaluate_bags(REPO / "bags" / "icub_xy", REPO / "bags" / "icub_xz", config, **kwargs)
    cluster, info_c = evaluate_bags(REPO / "bags" / "icub_xy", REPO / "bags" / "icub_xz", config,
                                    cluster="local:2", **kwargs)
    # the same arithmetic, to rounding: the consistent SP's matrix products and triangular solves run in
    # BLAS, whose blocking and threads may differ between this process and the workers (the Givens sweeps
    # are the package's own compiled loops, equal to the last bit); 1e-9 of the outputs' scale is far
    # above what 2200 well-conditioned updates accumulate (≈ 1e-13 measured)
    assert serial.kinds == cluster.kinds
    for kind in serial.kinds:
        scale = float(np.abs(serial.predictions[kind]).max())
        np.testing.assert_allclose(serial.predictions[kind], cluster.predictions[kind], rtol=0,
                                   atol=1e-9 * scale)
    hs, hc = info_s["horizons"], info_c["horizons"]
    assert list(hs.rmse) == list(hc.rmse) == ["CAD", "P", "NP", "SP", "persistence"]
    for table_s, table_c in ((hs.rmse, hc.rmse), (hs.rmse_inside, hc.rmse_inside),
                             (hs.rmse_outside, hc.rmse_outside)):
        for model in table_s:  # NaN where no sample: equal too
            for label in table_s[model]:
                np.testing.assert_allclose(table_s[model][label], table_c[model][label], rtol=1e-9)


def test_a_worker_killed_mid_run_loses_nothing(tmp_path):
    marker = str(tmp_path / "killed")
    with connect("local:2") as client:
        results = run_on_cluster(client, square_or_die_once, [(x, marker) for x in range(10)])
    assert Path(marker).exists()  # a worker did die
    assert results == [x * x for x in range(10)]


def test_an_unreachable_scheduler_is_exit_2_naming_it_within_seconds(tmp_path):
    start = time.monotonic()
    done = _cli("--train", str(REPO / "bags" / "icub_xy"), "--config", str(ICUB), "--limit", "300",
                *SMALL_GRID, "--cluster", "tcp://127.0.0.1:9", timeout=120)
    elapsed = time.monotonic() - start
    print(f"unreachable scheduler: exit {done.returncode} after {elapsed:.1f} s")
    assert done.returncode == 2, done.stderr
    assert "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in done.stderr
    assert "Traceback" not in done.stderr
    assert elapsed < 30  # a refused address fails at once; a silent one after 10 s (plus the start-up)


def _arm_bag(root: Path, robot: str, seed: int) -> Path:
    rec = simulate_arm(ArmScenarioConfig(name=f"{robot}_{seed}", robot=robot, duration=6.0, rate=200.0,
                                         seed=seed))
    return write_recording(rec, root / f"{robot}_{seed}")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Three robots (a simulated Panda and UR5 with two logs each, the KUKA logs 1 and 3 when present), an
    empty robot folder and a robot whose only log lost its data file."""
    root = tmp_path_factory.mktemp("fleet")
    configs = root.parent / f"{root.name}_configs"
    configs.mkdir()
    robots = ["panda", "ur5"]
    for robot in robots:
        (root / robot).mkdir()
        for seed in (0, 1):
            _arm_bag(root / robot, robot, seed)
        write_config(load_config(REPO / "config" / f"{robot}.yaml").with_overrides(
            {"nonparametric.n_features": 64}), configs / f"{robot}.yaml")
    if (KUKA / "measurements_1").is_dir():
        (root / "kuka").mkdir()
        for log in (1, 3):
            (root / "kuka" / f"measurements_{log}").symlink_to(KUKA / f"measurements_{log}")
        write_config(load_config(REPO / "config" / "kuka_lwr4.yaml").with_overrides(
            {"robot.urdf": str(KUKA / "kuka_lwr4_cogimon.urdf"), "nonparametric.n_features": 64}),
            configs / "kuka.yaml")
        robots.append("kuka")
    (root / "empty_arm").mkdir()
    broken = root / "broken_arm"
    broken.mkdir()
    bag = _arm_bag(broken, "panda", 2)
    for f in bag.glob("*.mcap"):
        f.unlink()  # the bag is listed but its data is not where the worker looks
    write_config(load_config(configs / "panda.yaml"), configs / "broken_arm.yaml")
    return root, configs, robots


def test_learn_fleet_equals_separate_learn_runs_and_reports_what_failed(fleet, tmp_path):
    root, configs, robots = fleet
    rows = learn_fleet(root, str(configs / "{robot}.yaml"), tmp_path / "out", cluster="local:2")
    by_name = {r.robot: r for r in rows}
    assert [r.robot for r in rows] == sorted(by_name)
    assert by_name["empty_arm"].status == "skipped"
    broken = by_name["broken_arm"]
    assert broken.status == "failed" and "broken_arm" in broken.error and "on worker tcp://" in broken.error
    for robot in robots:
        row = by_name[robot]
        assert row.status == "learned" and row.frozen_rmse is not None and np.isfinite(row.frozen_rmse)
        bags = sorted((root / robot).iterdir())
        with threadpool_limits(1):  # as a worker runs
            learn_bags(bags[:-1], load_config(configs / f"{robot}.yaml"),
                       checkpoint=tmp_path / f"{robot}.npz")
        fleet_ckpt, alone = np.load(row.checkpoint), np.load(tmp_path / f"{robot}.npz")
        assert set(fleet_ckpt.files) == set(alone.files)
        for key in alone.files:
            np.testing.assert_array_equal(fleet_ckpt[key], alone[key], err_msg=f"{robot}: {key}")
        # the frozen error on the held-out log, recomputed from the separate run's checkpoint
        config = load_config(configs / f"{robot}.yaml")
        test, _ = load_samples(bags[-1], config, Topics.from_config(config))
        n = len(config["robot.joints"])
        tau, std = load_model(tmp_path / f"{robot}.npz").predict(test.X[:, :n], test.X[:, n:2 * n],
                                                                 test.X[:, 2 * n:])
        assert row.frozen_rmse == pytest.approx(np.mean(np.sqrt(np.mean((tau - test.Y) ** 2, axis=0))),
                                                rel=1e-9)
        # by motion state: the fast slice's errors, joint by joint from its own velocity
        dq = test.X[:, n:2 * n]
        fast = [np.sqrt(np.mean((tau - test.Y)[np.abs(dq[:, j]) >= 0.2, j] ** 2)) for j in range(n)
                if (np.abs(dq[:, j]) >= 0.2).sum() >= 20]
        assert row.frozen_slices["fast"] == pytest.approx(np.mean(fast), rel=1e-9)
        assert row.coverage["all"] == pytest.approx(np.mean(np.abs(tau - test.Y) <= 2 * std), rel=1e-9)
    summary = (tmp_path / "out" / "fleet.md").read_text()
    assert "| empty_arm | skipped |" in summary and "| broken_arm | failed |" in summary
    assert "by motion state" in summary
    assert len(json.loads((tmp_path / "out" / "fleet.json").read_text())) == len(rows)


@needs_kuka
def test_tune_selects_by_the_error_on_another_log(tmp_path):
    """tune --train KUKA log 1 --validate log 3: the scores are those of a learn run scored on log 3."""
    config = load_config(REPO / "config" / "kuka_lwr4.yaml").with_overrides(
        {"robot.urdf": str(KUKA / "kuka_lwr4_cogimon.urdf"), "nonparametric.n_features": 64})
    train, validate = [KUKA / "measurements_1"], [KUKA / "measurements_3"]
    # two points: the configuration's values (always in the grid) and a hundred times its residual's λ
    lam = config["nonparametric.lam"]
    grid = {"parametric.lam": [config["parametric.lam"]], "nonparametric.lam": [lam, 100.0 * lam],
            "nonparametric.sigma": [config["nonparametric.sigma"]]}
    selection = validation_search(config, train, validate, grid=grid, cluster="local:2")
    assert len(selection.points) == 2
    assert selection.best.score == min(p.score for p in selection.points)
    for i, point in enumerate(selection.points):
        # the frozen RMSE as a user gets it: learn → checkpoint → load_model(...).predict on log 3
        cfg = config.with_overrides(point.values)
        learn_bags(train, cfg, checkpoint=tmp_path / f"point{i}.npz")
        test, _ = load_samples(validate[0], cfg, Topics.from_config(cfg))
        model = load_model(tmp_path / f"point{i}.npz")
        tau, _ = model.predict(test.X[:, :7], test.X[:, 7:14], test.X[:, 14:])
        frozen = float(np.mean(np.sqrt(np.mean((tau - test.Y) ** 2, axis=0))))
        assert point.rmse["torque"] == pytest.approx(frozen, rel=1e-9), point.rmse
        # and the whole score, recomputed in this process
        again = validation_error(cfg, [str(t) for t in train], [str(v) for v in validate],
                                 Topics.from_config(cfg))
        assert again.score == pytest.approx(point.score, rel=1e-12)


class _Workers:
    """A scheduler's answer about its workers (what ``Client.run`` returns), without a cluster."""

    def __init__(self, versions):
        self.versions = versions

    def wait_for_workers(self, n, timeout):
        pass

    def run(self, fn):
        return self.versions


def test_workers_without_the_package_or_with_another_version_are_named():
    from semiparam_ros.errors import ClusterError
    from semiparam_ros.jobs.cluster import _check_workers
    from semiparam_ros.version import __version__

    _check_workers(_Workers({"tcp://a:1": __version__}), "tcp://s:8786", 1.0)  # fine
    with pytest.raises(ClusterError, match=r"without semiparam_ros: tcp://b:2"):
        _check_workers(_Workers({"tcp://a:1": __version__, "tcp://b:2": None}), "tcp://s:8786", 1.0)
    with pytest.raises(ClusterError, match=r"another semiparam_ros .*tcp://c:3 \(0\.0\.1\)"):
        _check_workers(_Workers({"tcp://c:3": "0.0.1"}), "tcp://s:8786", 1.0)
