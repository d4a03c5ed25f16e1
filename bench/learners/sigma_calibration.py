"""Coverage of the served σ on new motion: the one-step σ against the σ calibrated by frozen copies.

For each pair of real logs (train on one or two, test on another: a faster motion) the served model is
learned as ``learn`` learns it (the node's estimator, checkpoint, ``load_model``) once per setting of
``uncertainty.calibration_block`` — 0 is the one-step σ (what was served before the calibration) — and
scored frozen on the test log: ±2σ coverage over all samples and by motion state (the evaluation's slices),
the RMSE (which the calibration does not change) and the median served σ. One-step coverage (the
estimator's published σ, test-then-train on the test log) is printed beside it: the calibration must leave
it alone.

    .venv/bin/python bench/learners/sigma_calibration.py [--data ../shared/data/kuka_lwr4] \
        [--blocks 0 20] [--json bench/results/sigma_calibration.json]

Then the same on simulated point-to-point arms whose friction remembers (Dahl; rests between moves,
quantized encoders, differentiated velocities: :mod:`semiparam_ros.sim.point_to_point`): a Panda at 1 kHz
and a UR5 at 100 Hz, trained on 60 s of one seed's moves and tested on 30 s of another's. Without the KUKA
data folder (not shipped) only the simulated arms run.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from semiparam_ros.cli.evaluate import parse_overrides  # noqa: E402
from semiparam_ros.core.config import load_evaluation_config  # noqa: E402
from semiparam_ros.core.estimator.build import build_pipeline  # noqa: E402
from semiparam_ros.core.estimator.online import OnlineEstimator  # noqa: E402
from semiparam_ros.errors import RejectedSampleError  # noqa: E402
from semiparam_ros.eval.bags.replay import load_samples  # noqa: E402
from semiparam_ros.eval.models.served import NodeLearner, serve  # noqa: E402
from semiparam_ros.eval.protocol.prequential import SampleArrays  # noqa: E402
from semiparam_ros.eval.protocol.slices import SLICES, motion_slices, slice_coverage  # noqa: E402
from semiparam_ros.sim.point_to_point import PointToPointArm  # noqa: E402

PAIRS = ((("measurements_1",), "measurements_3"), (("measurements_2",), "measurements_3"),
         (("measurements_1", "measurements_2"), "measurements_3"))


def learn_logs(config, logs, train_names):
    """The node's SP learned on the training logs in order (one recording each), as ``learn`` learns."""
    node = NodeLearner(OnlineEstimator(config, kind="SP"))
    for name in train_names:
        node.estimator.start_recording()
        data = logs[name]
        for stamp, x, y in zip(data.stamps_ns, data.X, data.Y, strict=True):
            try:
                node.learn_one(x, y, stamp_ns=int(stamp))
            except RejectedSampleError:
                continue
    return node


def served_on(node, test):
    """The node's model written, loaded as a user would (``load_model``) and predicted on the test log."""
    served = serve(node.estimator)
    n = len(served.joints)
    X = test.X
    total, sigma = served.predict(X[:, :n], X[:, n:2 * n], X[:, 2 * n:])
    return served, test.Y - total, sigma


def run_pair(config, logs, train_names, test_name, block):
    """Learn the served model on the training logs with one calibration block; score it on the test log."""
    cfg = config.with_overrides({"uncertainty.calibration_block": float(block)})
    node = learn_logs(cfg, logs, train_names)
    test = logs[test_name]
    served, err, sigma = served_on(node, test)
    n, X = len(served.joints), test.X
    inside = np.abs(err) <= 2.0 * sigma
    masks = motion_slices(X, n, test.n_outputs, test.sample_period_s)
    cov = slice_coverage(inside, masks)
    # one step ahead on the test log: the estimator's published σ, test-then-train
    online = node.copy()
    hits = []
    for stamp, x, y in zip(test.stamps_ns, test.X, test.Y, strict=True):
        try:
            res = online.estimator.step(online._sample(x, y, int(stamp)))
        except RejectedSampleError:
            continue
        # the model's a-priori error (its fast correction left out): what the one-step σ is of
        correction = res.prediction.correction
        model_total = res.prediction.total - (0.0 if correction is None else correction)
        hits.append(np.abs(y - model_total) <= 2.0 * res.std)
    return {"train": "+".join(train_names), "test": test_name, "block_s": block,
            "rmse": float(np.sqrt(np.mean(err**2))), "coverage": cov,
            "median_sigma": float(np.median(sigma)),
            "scales": [[None if np.isnan(c) else float(c) for c in row] for row in served.sigma_scales()],
            "one_step_coverage": float(np.mean(hits))}


def arrays_of(config, states):
    """The samples the node's pipeline makes of joint states, as arrays."""
    pipeline = build_pipeline(config)
    samples = [s for msg in states for s in pipeline.add(msg)]
    return SampleArrays.from_samples(samples)


def simulated_logs(overrides: dict | None = None):
    """(config, logs, pairs) of the simulated point-to-point arms."""
    out = []
    for robot, rate in (("panda", 1000.0), ("ur5", 100.0)):
        config = load_evaluation_config(ROOT / "config" / f"{robot}.yaml", dict(overrides or {}))
        train = PointToPointArm(robot, seconds=60.0, rate_hz=rate, seed=1).states()[0]
        test = PointToPointArm(robot, seconds=30.0, rate_hz=rate, seed=2).states()[0]
        logs = {f"{robot} P2P seed 1": arrays_of(config, train),
                f"{robot} P2P seed 2": arrays_of(config, test)}
        out.append((config, logs, (((f"{robot} P2P seed 1",), f"{robot} P2P seed 2"),)))
    return out


def _plain(value):
    """JSON without NaN (null instead)."""
    if isinstance(value, float) and value != value:
        return None
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def all_cases(data: Path, overrides: dict | None = None):
    """(config, logs, pairs) of the KUKA pairs (when ``data`` holds the logs) and the simulated arms."""
    cases = []
    if data.is_dir():
        config = load_evaluation_config(ROOT / "config" / "kuka_lwr4.yaml",
                                        {"robot.urdf": str(data / "kuka_lwr4_cogimon.urdf"),
                                         **(overrides or {})})
        logs = {name: load_samples(data / name, config)[0]
                for name in ("measurements_1", "measurements_2", "measurements_3")}
        cases.append((config, logs, PAIRS))
    else:
        print(f"no data folder {data}: the KUKA LWR4+ logs are not shipped; simulated arms only")
    return cases + simulated_logs(overrides)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "kuka_lwr4")
    p.add_argument("--blocks", type=float, nargs="+", default=[0.0, 20.0])
    p.add_argument("--json", type=Path, default=ROOT / "bench" / "results" / "sigma_calibration.json")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="NAME=VALUE",
                   help="override a parameter of every arm's configuration (repeatable), to compare a choice")
    args = p.parse_args(argv)
    cases = all_cases(args.data, parse_overrides(args.overrides))
    rows = []
    header = ("| train → test | block [s] | RMSE [N·m] | median σ | coverage all | "
              + " | ".join(SLICES) + " | one-step coverage |")
    print(header)
    print("|" + "---|" * (6 + len(SLICES)))
    for config, logs, (train_names, test_name), block in (
            (c, lg, pair, b) for c, lg, pairs in cases for pair in pairs for b in args.blocks):
        start = time.perf_counter()
        row = run_pair(config, logs, train_names, test_name, block)
        row["seconds"] = time.perf_counter() - start
        rows.append(row)
        cov = row["coverage"]
        print(f"| {row['train']} → {test_name} | {block:g} | {row['rmse']:.3f} | {row['median_sigma']:.3f} "
              f"| {cov['all']:.3f} | " + " | ".join(f"{cov[k]:.3f}" for k in SLICES)
              + f" | {row['one_step_coverage']:.3f} |", flush=True)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    command = " ".join(["bench/learners/sigma_calibration.py", *sys.argv[1:]])
    doc = {"date": time.strftime("%Y-%m-%d"), "command": command, "rows": rows}
    args.json.write_text(json.dumps(_plain(doc), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
