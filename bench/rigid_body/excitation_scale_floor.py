"""Benchmark: how far κ of the base regressor can fall, and what the optimiser's budget and objective buy.

κ(Y) of the stacked base regressor (friction and offset columns included, the parameters' own units) is
bounded below by its columns' scales alone: ``σ_max ≥ max_i ‖y_i‖`` and ``σ_min ≤ min_i ‖y_i‖``, so

    κ(Y) ≥ max_i ‖y_i‖ / min_i ‖y_i‖        (the column ratio),

and ``κ(Y) ≤ (column ratio) · κ(Y D)`` with ``D`` the columns' equilibration (``κ(Y D)``: the scale-free
conditioning, how far from orthogonal the columns are). A Coulomb column ``sign(q̇)`` has norm √N whatever the
motion, the gravity columns ≈ g√N times a lever arm: the column ratio is set by the units and the robot, and
a target on κ below it cannot be met by any motion. For the simulated Panda and UR5 (``config/<robot>.yaml``,
margin 0.1, 20 s), this prints κ, the column ratio and κ(Y D) of ``excite``'s default design and of five
random multi-sines of the same duration and limits (the baseline of ``bench_identification_end_to_end``);
with ``--variants`` also of designs with a larger budget (800 iterations, 32 draws), a sharper smooth κ
(p = 16, 32 in place of 8) and one 20 s period of 12 harmonics in place of two 10 s periods of 6. Usage::

    PYTHONPATH=$PWD .venv/bin/python bench/rigid_body/excitation_scale_floor.py [--variants] [--json PATH]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import pathlib
import platform
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.build import build_regressor
from semiparam_ros.core.fourier import FourierTrajectory
from semiparam_ros.core.rigid_body import excitation
from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "excitation_scale_floor.json"
DURATION = 20.0
N_GRID = 400  # samples per period, as excite reports κ

#: name → (design_excitation keywords, power of the smooth κ)
VARIANTS: dict[str, tuple[dict[str, Any], float]] = {
    "800 iterations, 32 draws": ({"iterations": 800, "n_starts": 32}, 8.0),
    "smooth κ with p = 16": ({}, 16.0),
    "smooth κ with p = 32": ({}, 32.0),
    "one 20 s period, 12 harmonics": ({"period": 20.0, "n_harmonics": 12}, 8.0),
}


def scales(regressor: RigidBodyRegressor, trajectory: FourierTrajectory) -> dict[str, float]:
    """Return κ(Y), the column ratio and κ(Y D) over one period of the trajectory."""
    q, dq, ddq = trajectory.evaluate(np.arange(N_GRID) * (trajectory.period / N_GRID))
    Y = regressor.base_regressor(q, dq, ddq).reshape(-1, regressor.n_base)
    norms = np.linalg.norm(Y, axis=0)
    s = np.linalg.svd(Y, compute_uv=False)
    se = np.linalg.svd(Y / norms, compute_uv=False)
    return {"kappa": float(s[0] / s[-1]), "column_ratio": float(norms.max() / norms.min()),
            "kappa_equilibrated": float(se[0] / se[-1])}


@contextlib.contextmanager
def soft_power(power: float) -> Iterator[None]:
    """Let the optimiser minimise the smooth κ of ``power`` inside the block (an experiment: the library
    keeps one power, ``_SOFT_POWER``, the default of ``_soft_log_condition``)."""
    soft = excitation._soft_log_condition
    defaults = soft.__defaults__
    soft.__defaults__ = (power,)
    try:
        yield
    finally:
        soft.__defaults__ = defaults


def design(regressor: RigidBodyRegressor, limits: excitation.ExcitationLimits, keywords: dict[str, Any],
           power: float) -> tuple[FourierTrajectory, float]:
    """Design with ``excite``'s defaults but ``keywords`` and the smooth κ's ``power``; and its seconds."""
    t0 = time.perf_counter()
    # one BLAS thread, as excite runs it (the optimiser's path depends on the last bits)
    with soft_power(power), threadpool_limits(1):
        exc = excitation.design_excitation(regressor, limits, duration=DURATION, **keywords)
    return exc.trajectory, time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    ap.add_argument("--variants", action="store_true", help="also the larger budget and other objectives")
    ap.add_argument("--json", type=pathlib.Path, default=RESULTS)
    args = ap.parse_args()
    out: dict[str, Any] = {}
    print("| arm | trajectory | κ | column ratio (κ ≥) | κ(Y D), scale-free | ratio to the random median | "
          "designed in |")
    print("|---|---|---|---|---|---|---|")
    for robot in args.robots:
        reg = build_regressor(load_config(ROOT / "config" / f"{robot}.yaml"))
        limits = excitation.ExcitationLimits.from_regressor(reg, margin=0.1)
        randoms = [scales(reg, excitation.random_multisine(reg, limits, period=DURATION, seed=s))
                   for s in range(5)]
        median = float(np.median([r["kappa"] for r in randoms]))
        rows: dict[str, dict[str, float]] = {}
        cases = {"excite (default)": ({}, 8.0), **(VARIANTS if args.variants else {})}
        for name, (keywords, power) in cases.items():
            traj, seconds = design(reg, limits, keywords, power)
            rows[name] = {**scales(reg, traj), "design_s": seconds}
        for s, r in enumerate(randoms):
            rows[f"random multi-sine, seed {s}"] = {**r, "design_s": 0.0}
        for name, r in rows.items():
            took = f"{r['design_s']:.0f} s" if r["design_s"] else "—"
            print(f"| {robot} | {name} | {r['kappa']:.1f} | {r['column_ratio']:.1f} | "
                  f"{r['kappa_equilibrated']:.1f} | {r['kappa'] / median:.2f} | {took} |", flush=True)
        out[robot] = {"random_median_kappa": median, "target_kappa": median / 3.0, "rows": rows}
    meta = {"machine": platform.machine(), "python": platform.python_version(), "cpus": os.cpu_count(),
            "load_average": os.getloadavg(), "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"meta": meta, "duration_s": DURATION, "robots": out}, indent=1))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
