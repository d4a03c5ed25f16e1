"""Payload identification on the simulated arms: tare before the pickup, estimate 10 s after it.

For each arm (Panda, UR5; ``config/<robot>.yaml``) and seed, a joint-torque recording of the ``payload``
scenario (the preset's payload, a point mass at ``payload_point`` of the end-effector frame, picked up at
``--pickup`` s of continuous multi-sine excitation, 1 kHz, the simulator's friction and noise) is fed
message by message to the node's ``OnlineEstimator``. 0.2 s before the pickup the payload is tared
(:meth:`OnlineEstimator.tare_payload`, what ``~/payload/tare`` does: the learner then detects the
pickup itself) and ``--after`` s after the pickup ``load_model(checkpoint).payload()`` is compared with
the truth (the change of the carrying body's parameters in the simulator). Also the estimate without a
tare, beyond the URDF (the consistent projection's distal body minus the CAD values), at that moment.

Target: mass within 2 %, centre of mass within 5 mm, 10 s after the pickup. Prints a markdown table and
writes ``bench/results/bench_payload.json``.

Usage::

    .venv/bin/python bench/rigid_body/bench_payload.py [--robots panda ur5] [--seeds 0 1 2] [--pickup 20] \
        [--after 10]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
RESULTS = REPO / "bench" / "results" / "bench_payload.json"


def run(robot: str, seed: int, pickup_s: float, after_s: float) -> dict:
    """One recording: the tared estimate and the URDF-referenced one against the truth."""
    from semiparam_ros import load_model
    from semiparam_ros.core.config import load_config
    from semiparam_ros.core.estimator.online import OnlineEstimator
    from semiparam_ros.core.rigid_body.dynamics import point_mass_parameters  # noqa: F401 (documents the truth
    from semiparam_ros.core.rigid_body.payload import payload_from_parameters
    from semiparam_ros.core.stream.messages import JointStateData
    from semiparam_ros.sim.arms import ARM_ROBOTS, ArmScenarioConfig, arm_regressor, simulate_arm

    spec = ARM_ROBOTS[robot]
    scenario = ArmScenarioConfig(name=f"{robot}_payload_{seed}", robot=robot, duration=pickup_s + after_s,
                                 seed=seed, payload_mass=spec.payload_mass, payload_time=pickup_s)
    rec = simulate_arm(scenario)
    reg = arm_regressor(robot)
    body = reg.body_index(reg.distal_body_name)
    cols = slice(10 * body, 10 * body + 10)
    delta = rec.parameters_after[cols] - rec.parameters_before[cols]
    truth = payload_from_parameters(delta, np.zeros((10, 10)), body=reg.distal_body_name, n_samples=0,
                                    reference="truth")
    config = load_config(REPO / "config" / f"{robot}.yaml")
    est = OnlineEstimator(config)
    # the tare a user makes just before picking the payload up (0.2 s before: the acceleration estimator
    # delays samples by half its window, so samples from before the tare are still learned after it)
    tare_ns = int(rec.stamps[0]) + round((pickup_s - 0.2) * 1e9)
    tared = False
    start = time.perf_counter()
    names = rec.joint_names
    for k in range(rec.stamps.shape[0]):
        stamp = int(rec.stamps[k])
        if not tared and stamp >= tare_ns:
            est.tare_payload()
            tared = True
        est.process(JointStateData(stamp, names, rec.q_measured[k], rec.dq_measured[k],
                                               rec.measured_torques[k]))
    elapsed = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "model.npz"
        est.save(path)
        model = load_model(path)
        tare = model.payload()
        model.estimator.payload = None
        urdf = model.payload()

    def row(p) -> dict:
        return {"mass_kg": p.mass, "mass_std_kg": p.mass_std, "com_m": p.com.tolist(),
                "com_std_m": p.com_std.tolist(), "inertia_kgm2": p.inertia.tolist(),
                "mass_error_percent": 100.0 * abs(p.mass - truth.mass) / truth.mass,
                "com_error_mm": 1e3 * float(np.linalg.norm(p.com - truth.com)),
                "n_samples": p.n_samples}

    return {"robot": robot, "seed": seed, "pickup_s": pickup_s, "after_s": after_s,
            "truth": {"mass_kg": truth.mass, "com_m": truth.com.tolist(), "body": truth.body},
            "tare": row(tare), "urdf": row(urdf), "replay_s": elapsed}


def table(runs: list[dict]) -> str:
    lines = ["| robot | seed | true m [kg] | tared m ± σ [kg] | m error | COM error [mm] (σ per axis) | "
             "beyond URDF: m error, COM error [mm] |",
             "|---|---|---|---|---|---|---|"]
    for r in runs:
        t, u = r["tare"], r["urdf"]
        lines.append(
            f"| {r['robot']} | {r['seed']} | {r['truth']['mass_kg']:.3f} | {t['mass_kg']:.4f} ± "
            f"{t['mass_std_kg']:.4f} | {t['mass_error_percent']:.2f} % | {t['com_error_mm']:.2f} "
            f"({', '.join(f'{1e3 * s:.2f}' for s in t['com_std_m'])}) | {u['mass_error_percent']:.1f} %, "
            f"{u['com_error_mm']:.1f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--pickup", type=float, default=20.0, help="seconds of excitation before the pickup")
    parser.add_argument("--after", type=float, default=10.0, help="seconds after the pickup")
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    runs = []
    for robot in args.robots:
        for seed in args.seeds:
            res = run(robot, seed, args.pickup, args.after)
            print(f"{robot} seed {seed}: mass error {res['tare']['mass_error_percent']:.2f} %, COM error "
                  f"{res['tare']['com_error_mm']:.2f} mm ({res['replay_s']:.0f} s)", flush=True)
            runs.append(res)
    print()
    print(table(runs))
    masses = [r["tare"]["mass_error_percent"] for r in runs]
    coms = [r["tare"]["com_error_mm"] for r in runs]
    summary = {"mass_error_percent_max": max(masses), "com_error_mm_max": max(coms),
               "target": {"mass_error_percent": 2.0, "com_error_mm": 5.0},
               "met": max(masses) <= 2.0 and max(coms) <= 5.0}
    print(json.dumps(summary))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({"runs": runs, "summary": summary}, indent=2) + "\n")
    print(f"written {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
