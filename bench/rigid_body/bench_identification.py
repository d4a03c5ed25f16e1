"""Benchmark and evidence: the physically consistent projection — its cost, and frozen rigid-body models
(consistent vs unconstrained vs CAD) on motion not seen.

    PYTHONPATH=$PWD .venv/bin/python bench/rigid_body/bench_identification.py

1. Real KUKA LWR4+ (../shared/data/kuka_lwr4): the estimator learns log 1 (``learn``, shipped
   ``config/kuka_lwr4.yaml``); its rigid-body part, frozen, predicts logs 2 (the same motion) and 3 (a
   faster one, outside the training range) with the unconstrained estimate, the consistent projection and
   the CAD model. RMSE per joint against the measured torques [N·m].
2. Simulated Panda (truth known): 20 s of excitation at 200 Hz learned, another motion predicted; RMSE
   against the true torques.
3. Cost: median wall time of 5 solves per robot (7 joints), cvxpy + Clarabel, after a first solve.

Prints tables and writes ``bench/results/bench_identification.json``.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import numpy as np

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.build import build_pipeline
from semiparam_ros.core.rigid_body.identification import consistent_parameters
from semiparam_ros.io.bags import iter_samples
from semiparam_ros.serving.bag_learning import learn_bags
from semiparam_ros.serving.learned_model import LearnedModel
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
from semiparam_ros.sim.writer import write_recording

ROOT = Path(__file__).resolve().parents[2]
KUKA = ROOT.parent / "shared" / "data" / "kuka_lwr4"


def _cost(est) -> list[float]:
    par = est.model.parametric
    times = []
    for _ in range(6):
        start = time.perf_counter()
        consistent_parameters(est.regressor, par.parameters, par.rls.R, est.column_scale, par.rls.lam)
        times.append(time.perf_counter() - start)
    return times[1:]


def main() -> None:
    out: dict = {"command": "PYTHONPATH=$PWD .venv/bin/python bench/rigid_body/bench_identification.py"}
    rows = []
    if KUKA.is_dir():
        cfg = load_config(ROOT / "config" / "kuka_lwr4.yaml").with_overrides(
            {"robot.urdf": str(KUKA / "kuka_lwr4_cogimon.urdf")})
        est, _ = learn_bags([KUKA / "measurements_1"], cfg)
        c = LearnedModel(est).consistent()
        reg = est.regressor
        cad = reg.to_base(reg.urdf_parameters())
        for log in ("measurements_2", "measurements_3"):
            samples = list(iter_samples(KUKA / log, build_pipeline(cfg),
                                        joint_states_topic="/robot/joint_states", wrench_topic=None))
            q, dq, ddq = (np.array([getattr(s, k) for s in samples]) for k in ("q", "dq", "ddq"))
            y = np.array([s.y for s in samples])
            phi = reg.base_regressor(q, dq, ddq)
            for name, p in (("CAD", cad), ("unconstrained", est.parameters), ("consistent", c.base)):
                rmse = np.sqrt(np.mean((phi @ p - y) ** 2, axis=0))
                rows.append({"data": f"KUKA 1→{log[-1]}", "model": name, "rmse_per_joint_Nm": rmse.tolist(),
                             "rmse_mean_Nm": float(rmse.mean())})
        out["kuka_solve_s"] = _cost(est)
    work = Path(tempfile.mkdtemp())
    rec = simulate_arm(ArmScenarioConfig(name="panda_id", robot="panda", duration=20.0, rate=200.0, seed=0))
    cfg = load_config(ROOT / "config" / "panda.yaml")
    est, _ = learn_bags([write_recording(rec, work / "panda_id")], cfg)
    c = LearnedModel(est).consistent()
    other = simulate_arm(ArmScenarioConfig(name="panda_other", robot="panda", duration=20.0, rate=200.0,
                                           seed=0))
    reg = est.regressor
    phi = reg.base_regressor(other.q, other.dq, other.ddq)
    truth = other.rigid_torques + other.friction_torques
    for name, p in (("CAD", reg.to_base(reg.urdf_parameters())), ("unconstrained", est.parameters),
                    ("consistent", c.base)):
        rmse = np.sqrt(np.mean((phi @ p - truth) ** 2, axis=0))
        rows.append({"data": "Panda (sim), another motion, vs truth", "model": name,
                     "rmse_per_joint_Nm": rmse.tolist(), "rmse_mean_Nm": float(rmse.mean())})
    out["panda_solve_s"] = _cost(est)
    out["rows"] = rows
    print("| data | model | RMSE per joint [N·m] | mean |")
    print("|---|---|---|---|")
    for r in rows:
        per = " ".join(f"{v:.3f}" for v in r["rmse_per_joint_Nm"])
        print(f"| {r['data']} | {r['model']} | {per} | {r['rmse_mean_Nm']:.4f} |")
    for key in ("kuka_solve_s", "panda_solve_s"):
        if key in out:
            print(f"{key}: median {1e3 * float(np.median(out[key])):.0f} ms per solve")
    path = ROOT / "bench" / "results" / "bench_identification.json"
    path.write_text(json.dumps(out, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
