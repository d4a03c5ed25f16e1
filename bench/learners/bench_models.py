"""Benchmark: one test-then-train step of each learner on the iCub F/T problem, side by side in one run.

For D ∈ {250, 500, 1000} random features, the time of ``predict_learn_one(x, y)`` (a-priori prediction,
then the update) of:

* ``P``          — rigid-body RRLS on the 17 base parameters (6 rows per sample);
* ``NP``         — random features of the 12-d standardized x + RRLS with 6 outputs;
* ``SP cascade`` — the paper's: P, then a random-feature RRLS of the residual on the 18-d ``[x, ŷ]``;
* ``SP joint``   — :class:`~semiparam_ros.core.learners.joint.JointSemiparametricModel`: a
  random-feature RRLS over the 6 + 6·17 = 108 columns ``[y, Φ rows]`` plus a 17-d RRLS fed with its
  rotated-out rows.

The regressor is the real Pinocchio base regressor of the iCub right arm (its ≈9 µs is included in every
model but NP; ``bench/rigid_body/bench_regressor.py`` times it alone). Samples come from a simulated XY
bag-like stream (circles, all joints moving). One BLAS thread; medians over repeats of the mean of
back-to-back
calls, process CPU time next to the wall time (the machine is shared). Usage::

    .venv/bin/python bench/learners/bench_models.py [--quick] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import statistics
import time
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
from semiparam_ros.core.estimator.build import build_model, build_regressor

RESULTS = pathlib.Path(__file__).resolve().parent / "results" / "bench_models.json"
MODELS = (("P", "P", "cascade"), ("NP", "NP", "cascade"), ("SP cascade", "SP", "cascade"),
          ("SP joint", "SP", "joint"))


def stream(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Smooth joint trajectories (x = [q, q̇, q̈], rad…) and noisy wrenches of a fixed arm (N, N·m)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    w = rng.uniform(0.5, 1.5, 4)
    ph = rng.uniform(0, 2 * np.pi, 4)
    q = 0.5 * np.sin(np.outer(t, w) + ph)
    dq = 0.5 * w * np.cos(np.outer(t, w) + ph)
    ddq = -0.5 * w**2 * np.sin(np.outer(t, w) + ph)
    X = np.hstack([q, dq, ddq])
    Y = np.column_stack([np.sin(t * k) for k in range(1, 7)]) + 0.1 * rng.standard_normal((n, 6))
    return X, Y


def time_model(step: Callable[[int], object], calls: int, repeats: int) -> dict[str, float]:
    """Median over repeats of the mean µs per call (wall and process CPU)."""
    walls, cpus = [], []
    i = 0
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        for _ in range(calls):
            step(i)
            i += 1
        walls.append((time.perf_counter() - t0) / calls * 1e6)
        cpus.append((time.process_time() - c0) / calls * 1e6)
    return {"median_us": statistics.median(walls), "cpu_median_us": statistics.median(cpus),
            "min_us": min(walls), "max_us": max(walls), "calls": calls, "repeats": repeats}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (smoke run)")
    parser.add_argument("--json", type=pathlib.Path, default=RESULTS, help=f"output JSON (default {RESULTS})")
    args = parser.parse_args(argv)
    calls, repeats = (100, 3) if args.quick else (300, 15)
    sizes = (250, 500) if args.quick else (250, 500, 1000)
    base = EstimatorConfig.from_flat(ICUB_RIGHT_ARM)
    regressor = build_regressor(base)
    n = 400 + calls * repeats + 10
    X, Y = stream(n)
    rows = []
    with threadpool_limits(1):
        for D in sizes:
            row: dict[str, object] = {"D": D}
            for label, kind, combination in MODELS:
                cfg = base.with_overrides({"nonparametric.n_features": D,
                                           "semiparametric.combination": combination})
                model = build_model(cfg, kind, regressor)  # type: ignore[arg-type]
                for i in range(400):  # past the standardizer warm-up (200 samples)
                    model.learn_one(X[i], Y[i])

                def step(i: int, model=model) -> object:
                    j = 400 + i
                    return model.predict_learn_one(X[j], Y[j])

                step(0)
                row[label] = time_model(step, calls, repeats)
            rows.append(row)
            print(f"D={D}: " + ", ".join(f"{label} {row[label]['median_us']:.1f} µs" for label, *_ in MODELS),
                  flush=True)
    header = "| D | " + " | ".join(label for label, *_ in MODELS) + " | joint / cascade | joint / NP |"
    print("\n" + header + "\n|" + "---|" * (len(MODELS) + 3))
    for row in rows:
        med = {label: row[label]["median_us"] for label, *_ in MODELS}  # type: ignore[index]
        print(f"| {row['D']} | " + " | ".join(f"{med[label]:.1f}" for label, *_ in MODELS)
              + f" | {med['SP joint'] / med['SP cascade']:.2f} | {med['SP joint'] / med['NP']:.2f} |")
    result = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                          "loadavg": os.getloadavg()},
              "unit": "µs per predict_learn_one (median of repeats)", "rows": rows}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2))
    print(f"wrote {args.json} (load average {os.getloadavg()[0]:.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
