"""Benchmark: what one per-cycle feed-forward answer costs with the served σ's calibration and friction that
remembers, against the same model without them (side by side, one process).

    .venv/bin/python bench/node/bench_cycle_cost.py [--data ../shared/data/kuka_lwr4] [--calls 3000]

The SP is learned on the real KUKA LWR4+ log 1 (``learn``'s path), written and loaded once per setting:
defaults; ``uncertainty.calibration_block: 0`` (one-step σ); ``parametric.stick_displacement: 0`` (static
friction); both off. For each, the median and 99th percentile wall time of ``FeedForward.compute`` on
consecutive desired states of log 3 (one per call, as ``~/desired_state`` at 1 kHz), one BLAS thread, on
two models: ``load_model``'s (the general path, what the node's served copy ran before it had its own) and
its frozen copy, what the node serves (``LearnedModel.snapshot``: a single state is one compiled call,
``ConsistentSemiparametricModel.frozen_model_one``). Prints a table and writes
``bench/results/bench_cycle_cost.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from semiparam_ros.core.config import load_evaluation_config  # noqa: E402
from semiparam_ros.core.estimator.online import OnlineEstimator  # noqa: E402
from semiparam_ros.eval.bags.replay import load_samples  # noqa: E402
from semiparam_ros.eval.models.served import NodeLearner  # noqa: E402
from semiparam_ros.serving.feedforward import DesiredState, FeedForward, TrajectoryPoint  # noqa: E402
from semiparam_ros.serving.learned_model import load_model  # noqa: E402

SETTINGS = {"defaults": {}, "one-step σ": {"uncertainty.calibration_block": 0.0},
            "static friction": {"parametric.stick_displacement": 0.0},
            "both off": {"uncertainty.calibration_block": 0.0, "parametric.stick_displacement": 0.0}}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "kuka_lwr4")
    p.add_argument("--calls", type=int, default=3000)
    p.add_argument("--json", type=Path, default=ROOT / "bench" / "results" / "bench_cycle_cost.json")
    args = p.parse_args(argv)
    if not args.data.is_dir():
        print(f"no data folder {args.data}: the KUKA LWR4+ logs are not shipped")
        return 0
    base = load_evaluation_config(ROOT / "config" / "kuka_lwr4.yaml",
                                  {"robot.urdf": str(args.data / "kuka_lwr4_cogimon.urdf")})
    train = load_samples(args.data / "measurements_1", base)[0]
    test = load_samples(args.data / "measurements_3", base)[0]
    n = len(base["robot.joints"])
    states = [test.X[k] for k in range(min(args.calls, len(test.X)))]
    rows = []
    print("| setting | model | median [µs] | p99 [µs] | ratio of medians to both off | "
          "median of the per-call ratios to loaded |")
    print("|---|---|---|---|---|---|")
    times = {}
    with tempfile.TemporaryDirectory() as folder:
        for name, overrides in SETTINGS.items():
            node = NodeLearner(OnlineEstimator(base.with_overrides(overrides), kind="SP"))
            for stamp, x, y in zip(train.stamps_ns, train.X, train.Y, strict=True):
                node.learn_one(x, y, stamp_ns=int(stamp))
            path = Path(folder) / "model.npz"
            node.estimator.save(path)
            loaded = load_model(path)
            # load_model's model, and the frozen copy the node serves (one compiled call per state),
            # call by call in turn so that the machine's drifts hit both alike
            models = {"loaded": FeedForward(loaded), "served copy": FeedForward(loaded.snapshot())}
            names = models["loaded"].joints
            elapsed: dict[str, list[float]] = {served: [] for served in models}
            for x in states:
                desired = DesiredState(0, names, (TrajectoryPoint(0, x[:n], x[n:2 * n], x[2 * n:]),))
                for served, ff in models.items():
                    start = time.perf_counter()
                    ff.compute(desired, now_ns=0)
                    elapsed[served].append(time.perf_counter() - start)
            for served, values in elapsed.items():
                times[(name, served)] = np.array(values) * 1e6
    for (name, served), t in times.items():
        row = {"setting": name, "model": served, "median_us": float(np.median(t)),
               "p99_us": float(np.percentile(t, 99)),
               "ratio": float(np.median(t) / np.median(times[("both off", served)])),
               "served_over_loaded": float(np.median(t / times[(name, "loaded")]))}
        rows.append(row)
        print(f"| {name} | {served} | {row['median_us']:.1f} | {row['p99_us']:.1f} | {row['ratio']:.2f} | "
              f"{row['served_over_loaded']:.2f} |")
    args.json.write_text(json.dumps({"date": time.strftime("%Y-%m-%d"), "calls": len(states), "rows": rows},
                                    indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
