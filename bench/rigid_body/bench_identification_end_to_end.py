"""Benchmark: identification end to end — excite → record (simulated) → learn → export_urdf, vs the truth.

For the simulated Panda (7 joints) and UR5 (6 joints) at 1 kHz, with the simulator's perturbed CAD (true
masses ±15 %, centres of mass ±1 cm off the URDF's), friction, noise and a 1.2 kg payload on the distal
body from the start:

1. ``excite --config config/<robot>.yaml --duration 20 --out traj.yaml`` designs the trajectory;
2. ``simulate --robot <robot> --trajectory traj.yaml --duration 20 --scenario payload --payload-mass 1.2
   --payload-time 0`` records it (the "robot");
3. ``learn`` the bag with the robot's parameter file, ``export_urdf`` the checkpoint;
4. the exported links' masses and centres of mass, the joints' friction and the payload beyond the URDF are
   compared with the simulator's truth (``scenario.yaml``).

The same is done with the simulator's own random multi-sine of the same duration (no ``--trajectory``),
side by side. Every step is the command a user runs (their ``main``), in one process. Usage::

    PYTHONPATH=$PWD .venv/bin/python bench/rigid_body/bench_identification_end_to_end.py [--json PATH] \\
        [--robots panda ur5] [--seeds 1 2] [--soft-power P]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import pathlib
import tempfile
import time
from typing import Any

import numpy as np
import yaml
from excitation_scale_floor import soft_power  # this folder: run as a script

from semiparam_ros.cli import excite, export_urdf, learn, simulate
from semiparam_ros.core.rigid_body.excitation import ExcitationLimits, condition_number, random_multisine
from semiparam_ros.io.trajectory_files import read_excitation
from semiparam_ros.serving.learned_model import load_model

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "bench_identification_end_to_end.json"
DURATION = 20.0
HELD_OUT_SEED = 100  # the random multi-sine the identified rigid bodies are compared on


def _run(main: Any, argv: list[str]) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = main(argv)
    if status != 0:
        raise RuntimeError(f"{argv}: exit {status}\n{out.getvalue()}")
    return out.getvalue()


def identify(robot: str, folder: pathlib.Path, trajectory: pathlib.Path | None, seed: int) -> dict[str, Any]:
    """Record, learn and export one run; return identified vs true."""
    config = str(ROOT / "config" / f"{robot}.yaml")
    tag = f"{robot}_{'designed' if trajectory else 'multisine'}_{seed}"
    argv = ["--robot", robot, "--scenario", "payload", "--payload-mass", "1.2", "--payload-time", "0",
            "--duration", str(DURATION), "--seed", str(seed), "--out", str(folder / tag), "--quiet"]
    if trajectory is not None:
        argv += ["--trajectory", str(trajectory)]
    bag = pathlib.Path(_run(simulate.main, argv).split()[-1])
    ckpt = folder / f"{tag}.npz"
    _run(learn.main, [str(bag), "--config", config, "--checkpoint", str(ckpt), "--quiet"])
    _run(export_urdf.main, ["--checkpoint", str(ckpt), "--out", str(folder / f"{tag}.urdf")])
    truth = yaml.safe_load((bag / "scenario.yaml").read_text())
    model = load_model(ckpt)
    reg = model.estimator.regressor
    estimate = model.consistent()
    true_full = np.asarray(truth["true_parameters"]["after_payload"])
    cad = reg.urdf_parameters()
    links = []
    for i, body in enumerate(reg.body_names):
        mass, com, _ = estimate.link(i)
        p = true_full[10 * i: 10 * i + 10]
        links.append({"body": body, "true_mass_kg": float(p[0]), "mass_kg": mass,
                      "mass_error_percent": 100 * (mass - p[0]) / p[0],
                      "cad_mass_error_percent": 100 * (cad[10 * i] - p[0]) / p[0],
                      "com_error_mm": 1000 * float(np.linalg.norm(com - p[1:4] / p[0]))})
    names = reg.parameter_names
    fr = truth["friction"]
    joints = []
    for j, joint in enumerate(reg.joint_names):
        fv = float(estimate.full[names.index(f"{joint}.viscous")])
        fc = float(estimate.full[names.index(f"{joint}.coulomb")])
        joints.append({"joint": joint, "true_viscous": fr["viscous_Nms_per_rad"][j], "viscous": fv,
                       "true_coulomb": fr["coulomb_Nm"][j], "coulomb": fc})
    # the identified rigid body on held-out motion: Φ(x)(π_est − π_true) on a random multi-sine of another
    # seed, inertial columns only (friction and offsets are compared below); the base parameters decide it,
    # so the directions the data cannot see (the split of the masses between links) do not count
    limits = ExcitationLimits.from_regressor(reg, margin=0.1)
    held_out = random_multisine(reg, limits, period=DURATION, seed=HELD_OUT_SEED)
    q, dq, ddq = held_out.evaluate(np.arange(0.0, DURATION, 0.01))
    n_inertial = true_full.size
    phi = reg.regressor(q, dq, ddq)[..., :n_inertial]
    delta_tau = phi @ (estimate.full[:n_inertial] - true_full)
    rigid_rmse = float(np.mean(np.sqrt(np.mean(delta_tau**2, axis=0))))
    payload = model.payload()
    body = reg.body_index(reg.distal_body_name)
    delta = true_full[10 * body: 10 * body + 10] - reg.urdf_parameters()[10 * body: 10 * body + 10]
    return {
        "robot": robot, "excitation": "designed" if trajectory else "random multi-sine", "seed": seed,
        "links": links, "joints": joints,
        "held_out_rigid_rmse_Nm": rigid_rmse,
        "max_mass_error_percent": max(abs(r["mass_error_percent"]) for r in links),
        "max_cad_mass_error_percent": max(abs(r["cad_mass_error_percent"]) for r in links),
        "median_mass_error_percent": float(np.median([abs(r["mass_error_percent"]) for r in links])),
        "max_com_error_mm": max(r["com_error_mm"] for r in links),
        "max_viscous_error": max(abs(r["viscous"] - r["true_viscous"]) for r in joints),
        "max_coulomb_error": max(abs(r["coulomb"] - r["true_coulomb"]) for r in joints),
        "payload": {"true_mass_kg": float(delta[0]), "mass_kg": payload.mass, "mass_std_kg": payload.mass_std,
                    "mass_error_sigmas": abs(payload.mass - float(delta[0])) / payload.mass_std,
                    "com_error_mm": 1000 * float(np.linalg.norm(payload.com - delta[1:4] / delta[0])),
                    "com_error_sigmas_max": float(np.max(np.abs(payload.com - delta[1:4] / delta[0])
                                                         / payload.com_std))},
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=pathlib.Path, default=RESULTS)
    ap.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--soft-power", type=float, default=None,
                    help="an experiment: excite minimises the smooth κ of this power (the library's: 8)")
    args = ap.parse_args()
    if args.soft_power is not None:
        with soft_power(args.soft_power):
            return run(args)
    return run(args)


def run(args: argparse.Namespace) -> int:
    """Design, record, learn and export for each robot and seed; print and save the table."""
    rows, designs = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        for robot in args.robots:
            traj = folder / f"{robot}_traj.yaml"
            t0 = time.perf_counter()
            _run(excite.main, ["--config", str(ROOT / "config" / f"{robot}.yaml"),
                               "--duration", str(DURATION), "--out", str(traj)])
            design_s = time.perf_counter() - t0
            described = read_excitation(traj)
            model_reg = load_config_regressor(robot)
            limits = ExcitationLimits.from_regressor(model_reg, margin=0.1)
            baseline = [condition_number(model_reg,
                                         random_multisine(model_reg, limits, period=DURATION, seed=s))
                        for s in range(5)]
            designs[robot] = {"condition_number": described.description["condition_number"],
                              "random_multisine_median": float(np.median(baseline)),
                              "random_multisine": baseline, "design_s": design_s,
                              "limit_usage": described.description["limit_usage_at_1khz"]}
            print(f"{robot}: designed κ {designs[robot]['condition_number']:.1f} vs random multi-sine median "
                  f"{np.median(baseline):.1f} (designed in {design_s:.0f} s)", flush=True)
            for seed in args.seeds:
                for trajectory in (traj, None):
                    r = identify(robot, folder, trajectory, seed)
                    rows.append(r)
                    p = r["payload"]
                    print(f"| {robot} | {r['excitation']} | {seed} | {r['median_mass_error_percent']:.1f} / "
                          f"{r['max_mass_error_percent']:.1f} % "
                          f"(CAD {r['max_cad_mass_error_percent']:.1f}) | "
                          f"{r['max_com_error_mm']:.0f} | {r['max_viscous_error']:.3f} | "
                          f"{r['max_coulomb_error']:.3f} | {p['mass_kg']:.3f} ± {p['mass_std_kg']:.3f} "
                          f"({p['mass_error_sigmas']:.1f}σ) | {p['com_error_mm']:.0f} mm "
                          f"({p['com_error_sigmas_max']:.1f}σ) | held-out rigid body "
                          f"{r['held_out_rigid_rmse_Nm']:.4f} N·m |", flush=True)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"duration_s": DURATION, "designs": designs, "rows": rows}, indent=1))
    print(f"wrote {args.json}")
    return 0


def load_config_regressor(robot: str) -> Any:
    """Return the regressor of a robot's parameter file."""
    from semiparam_ros.core.config import load_config
    from semiparam_ros.core.estimator.build import build_regressor

    return build_regressor(load_config(ROOT / "config" / f"{robot}.yaml"))


if __name__ == "__main__":
    raise SystemExit(main())
