"""Benchmark: the one-off cost of learning the standardizer warm-up's held samples.

The residual (NP, the consistent SP's residual, the cascade's) cannot learn while its input standardizer
warms up (``nonparametric.standardizer_warmup_s``, 2 s by default); it holds those samples and learns them
in one compiled update once the statistics are ready. That update is O(N·D²) once (N = the warm-up's
samples: 400 at 200 Hz, 2000 at 1 kHz) and falls on the step that ends the warm-up. This script steps the
node's estimator (``OnlineEstimator.step``, the default configuration of a 7-joint arm, a simulated Panda
log) at 200 Hz and 1 kHz with D ∈ {500, 1000} and reports, per model (NP, the default consistent SP): the
time of that step [ms], the median step after the warm-up [µs] and their ratio, and how many samples a
node at that rate receives meanwhile (the learning loop's overload policy predicts those with the held
residual and does not learn them: ``docs/performance.md``). One BLAS thread. Usage::

    PYTHONPATH=$PWD .venv/bin/python bench/learners/bench_warmup_replay.py [--json PATH]

Writes ``bench/results/bench_warmup_replay.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import sys
import tempfile
import time

import numpy as np
from threadpoolctl import threadpool_limits

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.messages import Sample

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_consistent import samples_of  # a sibling script

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "bench_warmup_replay.json"
AFTER = 300  # steps timed after the warm-up ends


def run(config, samples: list[Sample], kind: str, rate: float) -> dict[str, float]:
    """Step one estimator until AFTER steps past the warm-up's end; the times of the interesting steps."""
    est = OnlineEstimator(config, kind=kind)
    residual = est.model if kind == "NP" else est.model.nonparametric
    clock = time.perf_counter
    end_step, end_ms, held, after = -1, 0.0, 0, []
    for i, s in enumerate(samples):
        before = residual.held_rows
        t0 = clock()
        est.step(s)
        dt = clock() - t0
        if end_step < 0 and before > 0 and residual.held_rows == 0:
            end_step, end_ms, held = i, 1e3 * dt, before + 1
        elif end_step >= 0:
            after.append(dt)
            if len(after) == AFTER:
                break
    if end_step < 0:
        raise RuntimeError("the warm-up did not end within the log")
    median_us = float(np.median(after) * 1e6)
    return {"held_rows": held, "warmup_end_step": end_step, "end_step_ms": end_ms,
            "median_step_after_us": median_us, "ratio": end_ms * 1e3 / median_us,
            "samples_arriving_meanwhile": end_ms * 1e-3 * rate}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=pathlib.Path, default=RESULTS)
    args = ap.parse_args()
    from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
    from semiparam_ros.sim.writer import write_recording

    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp, threadpool_limits(1):
        for rate in (200.0, 1000.0):
            scenario = ArmScenarioConfig(name="bench", robot="panda", duration=4.0, rate=rate, seed=1)
            rec = simulate_arm(scenario)
            bag = write_recording(rec, pathlib.Path(tmp) / f"panda_{rate:.0f}")
            for d in (500, 1000):
                cfg = load_config(ROOT / "config" / "panda.yaml").with_overrides(
                    {"nonparametric.n_features": d})
                samples = samples_of(cfg, bag)
                for kind in ("NP", "SP"):
                    res = run(cfg, samples, kind, rate)
                    key = f"panda {rate:.0f} Hz, D={d}, {kind}"
                    results[key] = res
                    print(f"{key}: {res['held_rows']} held rows learned in a {res['end_step_ms']:.1f} ms "
                          "step "
                          f"(median step after {res['median_step_after_us']:.0f} µs, "
                          f"{res['ratio']:.0f}×; {res['samples_arriving_meanwhile']:.0f} samples arrive "
                          "meanwhile)", flush=True)
    meta = {"machine": platform.machine(), "python": platform.python_version(), "cpus": os.cpu_count(),
            "load_average": os.getloadavg(), "time": time.strftime("%Y-%m-%d %H:%M:%S"),
            "command": "PYTHONPATH=$PWD .venv/bin/python bench/learners/bench_warmup_replay.py"}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"meta": meta, "results": results}, indent=1))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
