"""Benchmark: ``~/trajectory`` → ``~/trajectory_with_effort``, the node's work per trajectory, by stage.

A Panda model with the default configuration (consistent SP, D = 500), learned on 10 s of a simulated
excitation so that its residual is in use, answers trajectories of N points (positions and velocities:
the accelerations come from the controller's cubic). Stages, as the node runs them: rclpy's
deserialisation of the message, the conversion to arrays, the model at every point (one vectorised
call), writing the efforts into the message, rclpy's serialisation. Medians over repeats, one BLAS
thread. Usage::

    .venv/bin/python bench/node/bench_trajectory.py [--points 10 100 1000 10000] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import statistics
import tempfile
import time

import numpy as np
from builtin_interfaces.msg import Duration
from rclpy.serialization import deserialize_message, serialize_message
from threadpoolctl import threadpool_limits
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from semiparam_ros import load_model
from semiparam_ros.core.config import load_config
from semiparam_ros.ros import conversions as cv
from semiparam_ros.serving.bag_learning import learn_bags
from semiparam_ros.serving.feedforward import FeedForward
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
from semiparam_ros.sim.writer import write_recording

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "bench_trajectory.json"


def trajectory(names: list[str], n_points: int, seed: int) -> JointTrajectory:
    rng = np.random.default_rng(seed)
    t = np.arange(1, n_points + 1) * 0.01
    w, phase = rng.uniform(0.5, 2.0, 7), rng.uniform(0, 2 * np.pi, 7)
    p = 0.8 * np.sin(np.outer(t, w) + phase) + np.r_[0, 0, 0, -1.5, 0, 1.0, 0]
    v = 0.8 * w * np.cos(np.outer(t, w) + phase)
    msg = JointTrajectory(joint_names=names)
    for k in range(n_points):
        sec, nsec = divmod(round(t[k] * 1e9), 10**9)
        msg.points.append(JointTrajectoryPoint(positions=p[k].tolist(), velocities=v[k].tolist(),
                                               time_from_start=Duration(sec=sec, nanosec=nsec)))
    return msg


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--points", type=int, nargs="+", default=[10, 100, 1000, 10000])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--json", type=pathlib.Path, default=RESULTS)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rec = simulate_arm(ArmScenarioConfig(name="panda_bench", robot="panda", duration=10.0, rate=500.0,
                                             seed=0))
        bag = write_recording(rec, pathlib.Path(tmp) / "panda_bench")
        config = load_config(ROOT / "config" / "panda.yaml")
        learn_bags([bag], config, checkpoint=pathlib.Path(tmp) / "panda.npz")
        model = load_model(pathlib.Path(tmp) / "panda.npz")
    ff = FeedForward(model)
    rows = []
    print("| points | deserialise [ms] | to arrays [ms] | model at every point [ms] | fill efforts [ms] "
          "| serialise [ms] | total [ms] | per point [µs] |")
    print("|---|---|---|---|---|---|---|---|")
    with threadpool_limits(1):
        for n_points in args.points:
            raw = serialize_message(trajectory(list(model.joints), n_points, seed=n_points))
            stages: dict[str, list[float]] = {k: [] for k in ("deserialise", "arrays", "model", "fill",
                                                              "serialise")}
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                msg = deserialize_message(raw, JointTrajectory)
                t1 = time.perf_counter()
                desired = cv.desired_state_from_msg(msg)
                t2 = time.perf_counter()
                filled = ff.trajectory(desired)
                t3 = time.perf_counter()
                assert filled is not None and not filled.fallback.any()
                cv.fill_trajectory_effort(msg, filled.effort)
                t4 = time.perf_counter()
                serialize_message(msg)
                t5 = time.perf_counter()
                for key, dt in zip(stages, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4), strict=True):
                    stages[key].append(1e3 * dt)
            med = {k: statistics.median(v) for k, v in stages.items()}
            total = sum(med.values())
            rows.append({"points": n_points, **{f"{k}_ms": v for k, v in med.items()}, "total_ms": total})
            print(f"| {n_points} | " + " | ".join(f"{med[k]:.2f}" for k in stages)
                  + f" | {total:.1f} | {1e3 * total / n_points:.1f} |")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"benchmark": "bench_trajectory", "rows": rows}, indent=1) + "\n")
    print(f"\nwrote {args.json}")


if __name__ == "__main__":
    main()
