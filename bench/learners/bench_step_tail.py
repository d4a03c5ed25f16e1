"""Benchmark: the default estimator's step time distribution on a 1 kHz 7-joint arm, as the node runs it.

A simulated Panda at 1 kHz (joint torques, excitation), the package defaults with D random features, the
consistent projection solved on the node's schedule (every ``parametric.consistent_period`` of the
samples' time, in line here; the node's worker solves it off the sample path): after 12 s (the first
projection is in place), 8 s of steps are timed one by one. Reported: median, p95, p99, p99.9, max and
mean [µs] of ``OnlineEstimator.step`` (check, prediction, σ, gate, learning). A 1 kHz arm keeps up when the
mean is below 1000 µs; the tail says how late a single sample can be published. One BLAS thread. Usage::

    PYTHONPATH=$PWD .venv/bin/python bench/learners/bench_step_tail.py [--features 1000] [--repeats 3]
        [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import tempfile
import time

import numpy as np
from bench_consistent import samples_of  # this folder: run as a script
from threadpoolctl import threadpool_limits

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.messages import Sample

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "bench_step_tail.json"
RATE = 1000.0
WARM_S, TIMED_S = 12.0, 8.0


def timed_steps(config, samples: list[Sample]) -> np.ndarray:
    """Step times [µs] of the timed window, after the warm-up with the projection solved in line."""
    est = OnlineEstimator(config)
    est.inline_projection = True
    n0 = int(WARM_S * RATE)
    for s in samples[:n0]:
        est.step(s)
    out = []
    clock = time.perf_counter
    for s in samples[n0:n0 + int(TIMED_S * RATE)]:
        t0 = clock()
        est.step(s)
        out.append(clock() - t0)
    return np.array(out) * 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--features", type=int, default=1000, help="D (default %(default)s)")
    ap.add_argument("--repeats", type=int, default=3, help="runs, each on a fresh estimator")
    ap.add_argument("--json", type=pathlib.Path, default=RESULTS)
    args = ap.parse_args()
    from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
    from semiparam_ros.sim.writer import write_recording

    with tempfile.TemporaryDirectory() as tmp, threadpool_limits(1):
        rec = simulate_arm(ArmScenarioConfig(name="bench", robot="panda", duration=WARM_S + TIMED_S + 1.0,
                                             rate=RATE, seed=1))
        bag = write_recording(rec, pathlib.Path(tmp) / "panda")
        config = load_config(ROOT / "config" / "panda.yaml").with_overrides(
            {"nonparametric.n_features": args.features})
        samples = samples_of(config, bag)
        runs = []
        for r in range(args.repeats):
            us = timed_steps(config, samples)
            row = {"median": float(np.median(us)), "p95": float(np.percentile(us, 95)),
                   "p99": float(np.percentile(us, 99)), "p99.9": float(np.percentile(us, 99.9)),
                   "max": float(us.max()), "mean": float(us.mean()), "n": int(us.size)}
            runs.append(row)
            print(f"run {r + 1}: " + ", ".join(f"{k} {v:.0f}" for k, v in row.items()) + " µs", flush=True)
    meta = {"machine": platform.machine(), "python": platform.python_version(), "cpus": os.cpu_count(),
            "load_average": os.getloadavg(), "time": time.strftime("%Y-%m-%d %H:%M:%S"),
            "features": args.features, "rate_hz": RATE}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"meta": meta, "runs": runs}, indent=1))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
