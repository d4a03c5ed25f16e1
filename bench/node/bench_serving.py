"""Benchmark: the public model API — vectorised vs single-state prediction, and ``learn`` vs real time.

    PYTHONPATH=$PWD .venv/bin/python bench/node/bench_serving.py [--repeats 5]

1. ``load_model(ckpt).predict`` at N = 1000 states: one call with (N, n) arrays vs N calls with (n,)
   arrays, side by side, median of ``--repeats`` (7-joint Panda, D = 500, the consistent SP default).
   Target: ≥ 20× faster per state.
2. ``learn`` (:func:`semiparam_ros.serving.bag_learning.learn_bags`, the node's pipeline) with the defaults
   on a simulated 1 kHz Panda recording (60 s) and on the three real 200 Hz KUKA logs: recorded time per wall
   time. Target: a 1 kHz log ≥ 3× faster than real time on 2 cores.

Prints tables and writes ``bench/results/bench_serving.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_info

from semiparam_ros import load_model
from semiparam_ros.core.config import load_config
from semiparam_ros.serving.bag_learning import learn_bags
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
from semiparam_ros.sim.writer import write_recording

ROOT = Path(__file__).resolve().parents[2]
KUKA = ROOT.parent / "shared" / "data" / "kuka_lwr4"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--output", type=Path, default=ROOT / "bench" / "results" / "bench_serving.json")
    args = p.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench_serving_"))

    rec = simulate_arm(ArmScenarioConfig(name="panda_excitation", robot="panda", duration=60.0, rate=1000.0,
                                         seed=0))
    bag = write_recording(rec, work / "panda_excitation")
    panda = load_config(ROOT / "config" / "panda.yaml")
    learn_runs = []
    t0 = time.perf_counter()
    _, report = learn_bags([bag], panda, checkpoint=work / "panda.npz")
    learn_runs.append({"data": "simulated Panda, 1 kHz, 60 s", "samples": report.samples,
                       "wall_s": time.perf_counter() - t0, "log_s": report.log_s,
                       "realtime_factor": report.realtime_factor,
                       "us_per_sample": 1e6 * report.wall_s / report.samples})
    if KUKA.is_dir():
        kuka = load_config(ROOT / "config" / "kuka_lwr4.yaml").with_overrides(
            {"robot.urdf": str(KUKA / "kuka_lwr4_cogimon.urdf")})
        bags = [KUKA / f"measurements_{i}" for i in (1, 2, 3)]
        _, report = learn_bags(bags, kuka)
        learn_runs.append({"data": "real KUKA LWR4+, 200 Hz, logs 1–3", "samples": report.samples,
                           "wall_s": report.wall_s, "log_s": report.log_s,
                           "realtime_factor": report.realtime_factor,
                           "us_per_sample": 1e6 * report.wall_s / report.samples})

    model = load_model(work / "panda.npz")
    n_states = 1000
    idx = np.random.default_rng(0).integers(0, len(rec.q), n_states)
    q, dq, ddq = rec.q[idx], rec.dq[idx], rec.ddq[idx]
    single, batch = [], []
    for _ in range(args.repeats):
        t1 = time.perf_counter()
        for i in range(n_states):
            model.predict(q[i], dq[i], ddq[i])
        single.append(time.perf_counter() - t1)
        t1 = time.perf_counter()
        model.predict(q, dq, ddq)
        batch.append(time.perf_counter() - t1)
    s, b = float(np.median(single)), float(np.median(batch))
    # where a vectorised call spends its time
    est = model.estimator
    xs = np.concatenate([q, dq, ddq], axis=1)
    t1 = time.perf_counter()
    for x in xs:
        est.regressor.base_regressor_of_input(x)
    regressor_s = time.perf_counter() - t1

    print("| N states | N single calls [ms] | one vectorised call [ms] | per state single / vectorised [µs] "
          "| speed-up (target ≥ 20×) | of which Pinocchio regressors [ms] |")
    print("|---|---|---|---|---|---|")
    per_s, per_b = 1e6 * s / n_states, 1e6 * b / n_states
    print(f"| {n_states} | {1e3 * s:.1f} | {1e3 * b:.1f} | {per_s:.0f} / {per_b:.0f} | {s / b:.1f}× | "
          f"{1e3 * regressor_s:.1f} |")
    print()
    print("| learned data | samples | wall [s] | recorded [s] | µs per sample | × real time (target ≥ 3 at "
          "1 kHz) |")
    print("|---|---|---|---|---|---|")
    for r in learn_runs:
        print(f"| {r['data']} | {r['samples']} | {r['wall_s']:.1f} | {r['log_s']:.1f} | "
              f"{r['us_per_sample']:.0f} | {r['realtime_factor']:.2f} |")
    out = {
        "command": "PYTHONPATH=$PWD .venv/bin/python bench/node/bench_serving.py",
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "processor": platform.processor() or platform.machine(),
                    "blas": [{k: i.get(k) for k in ("internal_api", "num_threads")}
                             for i in threadpool_info()],
                    "load_average_1min": os.getloadavg()[0]},
        "predict": {"n_states": n_states, "repeats": args.repeats, "single_calls_s": single,
                    "vectorised_s": batch, "speedup_median": s / b, "regressor_loop_s": regressor_s,
                    "n_features": int(model.config["nonparametric.n_features"]),
                    "n_base_parameters": int(est.regressor.n_base)},
        "learn": learn_runs,
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(out, indent=2))
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
