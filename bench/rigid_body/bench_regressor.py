"""Benchmark: cost of one rigid-body regressor evaluation (the per-tick cost of the parametric model).

Measures, for the iCub right arm (4 joints, F/T sensor in the upper arm) and for joint torques,
``RigidBodyRegressor.regressor`` and ``base_regressor`` on one state (the 1 kHz hot path), next to the bare
Pinocchio call they wrap (``computeJointTorqueRegressor`` on preallocated vectors: the floor for this
design), and the construction cost. Prints a markdown table and writes bench/results/bench_regressor.json.

Usage: ``.venv/bin/python bench/rigid_body/bench_regressor.py [--quick]``
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
import pinocchio as pin

from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.core.rigid_body.urdf import icub_urdf_path

ICUB_JOINTS = ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]
UR5_JOINTS = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
]
RESULTS = pathlib.Path(__file__).resolve().parent / "results" / "bench_regressor.json"


def per_call_us(fn: Callable[[], object], calls: int, repeats: int) -> dict[str, float]:
    """Median (and min/max) over `repeats` of the mean time per call of `calls` back-to-back calls, in µs."""
    fn()  # warm up
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        samples.append((time.perf_counter() - t0) / calls * 1e6)
    return {"median_us": statistics.median(samples), "min_us": min(samples), "max_us": max(samples)}


def bench_case(name: str, reg: RigidBodyRegressor, calls: int, repeats: int) -> list[dict[str, object]]:
    rng = np.random.default_rng(0)
    lo, hi = reg.position_limits()
    lo = np.where(np.isfinite(lo), lo, -np.pi)
    hi = np.where(np.isfinite(hi), hi, np.pi)
    q, dq, ddq = rng.uniform(lo, hi), rng.normal(size=reg.n_joints), rng.normal(size=reg.n_joints)
    model = reg.pinocchio_model
    data = model.createData()
    qf, vf, af = pin.neutral(model), np.zeros(model.nv), np.zeros(model.nv)

    def bare() -> object:
        return pin.computeJointTorqueRegressor(model, data, qf, vf, af)

    rows = []
    shape = f"{reg.n_outputs}x{reg.n_params}"
    for what, fn, cols in (
        ("pinocchio computeJointTorqueRegressor (floor)", bare, model.nv * 10 * (model.njoints - 1)),
        ("regressor", lambda: reg.regressor(q, dq, ddq), reg.n_params),
        ("base_regressor", lambda: reg.base_regressor(q, dq, ddq), reg.n_base),
    ):
        timing = per_call_us(fn, calls, repeats)
        rows.append({"case": name, "call": what, "columns": int(cols), "full_shape": shape, **timing})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run, ~2 s)")
    args = parser.parse_args()
    calls, repeats = (500, 5) if args.quick else (5000, 21)

    urdf = icub_urdf_path()
    t0 = time.perf_counter()
    icub_wrench = RigidBodyRegressor.from_urdf(urdf, ICUB_JOINTS, ft_sensor="r_arm_ft_sensor")
    build_ms = (time.perf_counter() - t0) * 1e3
    cases = [
        ("iCub right arm, F/T wrench", icub_wrench),
        (
            "iCub right arm, F/T wrench + offsets",
            RigidBodyRegressor.from_urdf(urdf, ICUB_JOINTS, ft_sensor="r_arm_ft_sensor", sensor_offset=True),
        ),
        (
            "iCub right arm, joint torques",
            RigidBodyRegressor.from_urdf(urdf, ICUB_JOINTS, output="joint_torques"),
        ),
        (
            "UR5, joint torques",
            RigidBodyRegressor.from_urdf(
                urdf.parents[2] / "ur_description" / "urdf" / "ur5_robot.urdf",
                UR5_JOINTS,
                output="joint_torques",
            ),
        ),
    ]
    rows: list[dict[str, object]] = []
    for name, reg in cases:
        rows.extend(bench_case(name, reg, calls, repeats))

    print(f"from_urdf (iCub wrench, incl. base parameters): {build_ms:.1f} ms\n")
    print("| case | call | columns | median µs | min µs | max µs |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['case']} | {r['call']} | {r['columns']} | {r['median_us']:.2f} | {r['min_us']:.2f} "
            f"| {r['max_us']:.2f} |"
        )
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "benchmark": "bench_regressor",
        "quick": args.quick,
        "calls_per_repeat": calls,
        "repeats": repeats,
        "from_urdf_ms": build_ms,
        "pinocchio": pin.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "rows": rows,
    }
    tmp = RESULTS.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(payload, indent=2) + "\n")
    os.replace(tmp, RESULTS)
    print(f"\nwrote {RESULTS}")


if __name__ == "__main__":
    main()
