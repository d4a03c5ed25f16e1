"""What limits the closed loop's identification floor: least squares of torques with fresh noise draws.

The closed loop (``bench/node/closed_loop.py``) compares the learned feed-forward with least squares of
the training torques at the recording's true states. This bench asks whether that floor is the torque
noise: it fits the same regressor (the learner's, ``config/panda.yaml``) at the true states of the
``panda_excitation`` recording (seed 0) to the noise-free torques and to the noise-free torques plus
independent draws of the simulator's torque noise (its per-joint σ), for each training duration, and
prints the RMS error [N·m] of each fit's feed-forward against the true model along the closed loop's
reference (multi-sine seed 20261126, 30 s, 1 kHz).

    PYTHONPATH=$PWD .venv/bin/python bench/node/closed_loop_floor.py [--draws 8] [--durations 60 180]

Writes ``bench/results/closed_loop_floor.json``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.build import build_regressor
from semiparam_ros.sim.arms import ArmScenarioConfig, arm_spec, simulate_arm
from semiparam_ros.sim.closed_loop import ArmPlant, desired_trajectory

ROOT = Path(__file__).resolve().parents[2]
TEST_SEED = 20261126  # the closed loop's reference


def _ff_errors(phi: np.ndarray, taus: list[np.ndarray], reference: np.ndarray,
               true_ff: np.ndarray) -> np.ndarray:
    """RMS feed-forward error [N·m] per joint (k, n) of the least-squares fit of each of k torque sets.

    One ``lstsq`` with the k torque sets as right-hand sides (the regressor is factored once).
    """
    rhs = np.stack([tau.reshape(-1) for tau in taus], axis=1)
    theta = np.linalg.lstsq(phi, rhs, rcond=None)[0]  # (p, k)
    ff = np.einsum("Njp,pk->kNj", reference, theta)
    return np.sqrt(np.mean((ff - true_ff) ** 2, axis=1))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--draws", type=int, default=8, help="independent torque-noise draws per duration")
    p.add_argument("--durations", type=float, nargs="+", default=[60.0, 180.0], help="training [s]")
    p.add_argument("--json", type=Path, default=ROOT / "bench" / "results" / "closed_loop_floor.json")
    args = p.parse_args()
    regressor = build_regressor(load_config(ROOT / "config" / "panda.yaml"))
    plant = ArmPlant("panda", seed=0)
    _, qd, dqd, ddqd = desired_trajectory("panda", TEST_SEED, 30.0, 1000.0)
    true_ff = plant.inverse_dynamics(qd, dqd, ddqd)
    reference = regressor.regressor(qd, dqd, ddqd)
    sigma = np.asarray(arm_spec("panda").torque_noise_std)
    rows = {}
    for duration in args.durations:
        rec = simulate_arm(ArmScenarioConfig(name="panda_excitation", robot="panda", duration=duration,
                                             rate=1000.0, seed=0))
        phi = regressor.regressor(rec.q, rec.dq, rec.ddq).reshape(-1, reference.shape[-1])
        shape = rec.true_torques.shape
        noisy = [rec.true_torques + sigma * np.random.default_rng(seed).standard_normal(shape)
                 for seed in range(args.draws)]
        errors = _ff_errors(phi, [rec.true_torques, rec.measured_torques, *noisy], reference, true_ff)
        noise_free, recorded, draws = errors[0], errors[1], errors[2:]
        rows[f"{duration:g} s"] = {"noise_free": noise_free.tolist(), "draws_mean": draws.mean(0).tolist(),
                                   "draws_min": draws.min(0).tolist(), "draws_max": draws.max(0).tolist(),
                                   "the_recording": recorded.tolist()}
        print(f"{duration:g} s: noise-free {np.abs(noise_free).max():.1e}; mean over {args.draws} draws "
              + " ".join(f"{v:.5f}" for v in draws.mean(0)) + "; the recording's "
              + " ".join(f"{v:.5f}" for v in recorded), flush=True)
    out = {"command": "PYTHONPATH=$PWD .venv/bin/python bench/node/closed_loop_floor.py",
           "what": "RMS feed-forward error [N·m] per joint of least squares at the true states",
           "torque_noise_std_Nm": sigma.tolist(), "draws": args.draws, "rows": rows}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=1))
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
