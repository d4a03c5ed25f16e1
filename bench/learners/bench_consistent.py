"""Benchmark: the estimator's step with the consistent SP (the default) beside the paper's cascade.

The node's whole per-sample work (``OnlineEstimator.step``: check, a-priori prediction with variance, σ,
the contact gate, learning) in one process on the same samples, for the two combinations, alternating in
blocks of 200 samples so that the machine's load hits both alike; after an untimed warm-up (the
standardizer and gate warm-ups). Robots: the iCub F/T set-up on ``bags/icub_xy`` (4 joints, 6 outputs)
and a 7-joint arm on a simulated Panda log (200 Hz excitation, joint torques). D ∈ {500, 1000}. Reported:
median and p99 per step [µs] and the ratio of the medians, and the CPU time per step of all the
process's threads (the consistent SP's worker thread included). One BLAS thread. Usage::

    PYTHONPATH=$PWD .venv/bin/python bench/learners/bench_consistent.py [--quick] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import statistics
import tempfile
import time

import numpy as np
from threadpoolctl import threadpool_limits

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.messages import Sample
from semiparam_ros.eval.bags.replay import load_samples

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "bench_consistent.json"


def samples_of(config, bag) -> list[Sample]:
    data, _ = load_samples(bag, config)
    n = data.X.shape[1] // 3
    return [Sample(int(s), x[:n], x[n:2 * n], x[2 * n:], y)
            for s, x, y in zip(data.stamps_ns, data.X, data.Y, strict=True)]


def run(config, samples: list[Sample], warmup: int, block: int) -> dict[str, dict[str, float]]:
    ests = {c: OnlineEstimator(config.with_overrides({"semiparametric.combination": c}))
            for c in ("cascade", "consistent")}
    for est in ests.values():
        for s in samples[:warmup]:
            est.step(s)
    times: dict[str, list[float]] = {c: [] for c in ests}
    cpu = dict.fromkeys(ests, 0.0)
    clock = time.perf_counter
    for start in range(warmup, len(samples), block):
        for c, est in ests.items():
            c0 = time.process_time()
            for s in samples[start:start + block]:
                t0 = clock()
                est.step(s)
                times[c].append(clock() - t0)
            # the consistent SP adds its cross-products' blocks on a worker thread: its CPU time (all the
            # process's threads) counts the block in flight, waited for before the other model runs
            cross = getattr(est.model, "_cross", None)
            if cross is not None:
                cross.wait()
            cpu[c] += time.process_time() - c0
    out = {}
    for c, t in times.items():
        us = np.array(t) * 1e6
        out[c] = {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)), "n": len(us),
                  "cpu_us_per_step": 1e6 * cpu[c] / len(us)}
    out["ratio_median"] = {"consistent/cascade": out["consistent"]["median_us"] / out["cascade"]["median_us"]}
    out["ratio_cpu"] = {"consistent/cascade": out["consistent"]["cpu_us_per_step"]
                        / out["cascade"]["cpu_us_per_step"]}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer samples (a smoke run)")
    ap.add_argument("--json", type=pathlib.Path, default=RESULTS)
    args = ap.parse_args()
    from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
    from semiparam_ros.sim.writer import write_recording

    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp, threadpool_limits(1):
        rec = simulate_arm(ArmScenarioConfig(name="bench", robot="panda", duration=30.0, rate=200.0, seed=1))
        panda_bag = write_recording(rec, pathlib.Path(tmp) / "panda")
        icub = (ROOT / "config" / "icub_right_arm.yaml", ROOT / "bags" / "icub_xy")
        cases = {"icub (4 joints, wrench)": icub,
                 "panda (7 joints, torques)": (ROOT / "config" / "panda.yaml", panda_bag)}
        for name, (cfg_path, bag) in cases.items():
            for d in (500, 1000):
                cfg = load_config(cfg_path).with_overrides({"nonparametric.n_features": d})
                samples = samples_of(cfg, bag)[: 1600 if args.quick else 4000]
                res = run(cfg, samples, warmup=1000 if not args.quick else 600, block=200)
                results[f"{name}, D={d}"] = res
                print(f"{name}, D={d}: cascade {res['cascade']['median_us']:.0f} µs (p99 "
                      f"{res['cascade']['p99_us']:.0f}), consistent {res['consistent']['median_us']:.0f} µs "
                      f"(p99 {res['consistent']['p99_us']:.0f}), ratio "
                      f"{res['ratio_median']['consistent/cascade']:.2f}; CPU per step "
                      f"{res['cascade']['cpu_us_per_step']:.0f}"
                      f" / {res['consistent']['cpu_us_per_step']:.0f} µs, ratio "
                      f"{res['ratio_cpu']['consistent/cascade']:.2f}", flush=True)
    meta = {"machine": platform.machine(), "python": platform.python_version(), "cpus": os.cpu_count(),
            "load_average": os.getloadavg(), "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"meta": meta, "results": results}, indent=1))
    print(f"wrote {args.json}; load average {meta['load_average']}; medians "
          f"{statistics.median(r['ratio_median']['consistent/cascade'] for r in results.values()):.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
