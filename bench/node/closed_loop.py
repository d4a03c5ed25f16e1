"""Closed-loop proof of the learned feed-forward: a simulated torque-controlled Panda tracking a motion it
was not trained on, with low PD gains (a compliant robot).

    PYTHONPATH=$PWD .venv/bin/python bench/node/closed_loop.py [--duration 30] [--train-duration 60] [--quick]

1. Simulate a 1 kHz joint-torque recording of the Panda (the simulator's perturbed inertias, friction,
   offsets and noise; ``simulate`` preset ``panda_excitation``), write it as a bag, learn it with
   ``learn`` (the node's pipeline) into a checkpoint, and load it with ``load_model``.
2. Track another multi-sine motion (another seed: never seen) at 1 kHz with these controllers:
   PD alone; PD + CAD feed-forward (RNEA with the URDF inertias); PD + the true model's feed-forward (the
   plant's own inverse dynamics and friction: the floor); PD + learned feed-forward (frozen, all
   states of the reference in one vectorised call); PD + learned feed-forward still learning online (the
   estimator fed each tick's measured joint state, the feed-forward asked at the desired state).
3. Print per-joint RMS and max tracking error and save ``bench/results/closed_loop.json`` and
   ``docs/figures/closed_loop.png``.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from semiparam_ros import load_model
from semiparam_ros.cli.evaluate import parse_overrides
from semiparam_ros.core.config import load_config
from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.eval.bags.replay import load_samples
from semiparam_ros.serving.bag_learning import learn_bags
from semiparam_ros.serving.learned_model import LearnedModel
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
from semiparam_ros.sim.closed_loop import ArmPlant, desired_trajectory, pd_gains, run_loop
from semiparam_ros.sim.writer import write_recording

ROOT = Path(__file__).resolve().parents[2]
TEST_SEED = 20261126  # the reference motion's multi-sine seed (the training bag's comes from its name)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=30.0, help="tracked motion [s]")
    p.add_argument("--train-duration", type=float, default=60.0, help="training recording [s]")
    p.add_argument("--quick", action="store_true", help="10 s / 20 s: a smoke run (not the reported one)")
    p.add_argument("--json", type=Path, default=ROOT / "bench" / "results" / "closed_loop.json")
    p.add_argument("--figure", type=Path, default=ROOT / "docs" / "figures" / "closed_loop.png")
    p.add_argument("--skip-live", action="store_true",
                   help="leave out the live-model row (not the default; it predicts with a model that "
                        "changes every tick and takes minutes)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="NAME=VALUE",
                   help="override a parameter of config/panda.yaml (repeatable), e.g. to compare a choice")
    args = p.parse_args()
    if args.quick:
        args.duration, args.train_duration = 10.0, 20.0
    rate = 1000.0
    skip_s = 1.0  # the first second (the loop settling from rest) is left out of the scores

    # 1. train on a recording of another motion
    work = Path(tempfile.mkdtemp(prefix="closed_loop_"))
    rec = simulate_arm(ArmScenarioConfig(name="panda_excitation", robot="panda", duration=args.train_duration,
                                         rate=rate, seed=0))
    bag = write_recording(rec, work / "panda_excitation")
    config = load_config(ROOT / "config" / "panda.yaml").with_overrides(
        {"learning_enabled": True, **parse_overrides(args.overrides)})
    t0 = time.perf_counter()
    _, report = learn_bags([bag], config, checkpoint=work / "panda.npz")
    learn_s = time.perf_counter() - t0
    model = load_model(work / "panda.npz")
    print(f"learned {report.learned} samples ({report.log_s:.0f} s at {rate:g} Hz) in {learn_s:.1f} s "
          f"({report.realtime_factor:.2f}x real time)")

    # 2. the reference and the plant (the same physical robot as the recording)
    plant = ArmPlant("panda", seed=0)
    t, qd, dqd, ddqd = desired_trajectory("panda", TEST_SEED, args.duration, rate)
    kp, kd = pd_gains(plant, qd[0])
    inside = _inside_training_range(rec, qd, dqd)

    t1 = time.perf_counter()
    frozen_ff, frozen_std = model.predict(qd, dqd, ddqd)  # every desired state in one call
    batch_s = time.perf_counter() - t1
    joints = tuple(model.joints)
    cad_ff = model.cad(qd, dqd, ddqd)
    true_ff = plant.inverse_dynamics(qd, dqd, ddqd)  # the plant's own inverse dynamics: the floor
    floor_ff = _identification_floor(model, (rec.q, rec.dq, rec.ddq), rec.measured_torques, qd, dqd, ddqd)
    samples = load_samples(bag, config)[0]  # what the learner saw: the pipeline's q̈ and alignment
    n = len(joints)
    pipeline_ff = _identification_floor(
        model, (samples.X[:, :n], samples.X[:, n:2 * n], samples.X[:, 2 * n:]), samples.Y, qd, dqd, ddqd)
    ff_error = {"learned (frozen)": _rms(frozen_ff - true_ff),
                "batch LS, the pipeline's samples": _rms(pipeline_ff - true_ff),
                "batch LS, true training states": _rms(floor_ff - true_ff), "CAD": _rms(cad_ff - true_ff)}
    print("feed-forward error against the true model's along the reference, RMS per joint [N·m]:")
    for name, values in ff_error.items():
        print(f"  {name:32s} " + " ".join(f"{v:.4f}" for v in values))

    refresh = float(config["feedforward.refresh_period"])  # the node's default

    def online_law(refresh_s: float) -> tuple:
        """Learning online from each tick's measurement; the feed-forward served as the node serves it.

        The consistent projection is re-solved every second (the node's worker does it every
        ``parametric.consistent_period``) and attached to the served model, as in the node.
        """
        live = LearnedModel(load_model(work / "panda.npz").estimator, solve=False)
        served = [live.snapshot() if refresh_s > 0 else live]
        every = max(1, round(refresh_s * rate)) if refresh_s > 0 else round(rate)
        start_ns = 10**18  # any epoch: the estimator measures its own rate

        def feed(k: int, tk: float, q_m: np.ndarray, dq_m: np.ndarray, tau: np.ndarray) -> None:
            live.estimator.process(JointStateData(start_ns + round(tk * 1e9), joints, q_m, dq_m,
                                                              tau))
            if k % every == 0:
                consistent = LearnedModel(live.estimator).consistent()  # what the worker would send
                if refresh_s > 0:
                    served[0] = live.snapshot()
                served[0].attach_consistent(consistent)

        path: list = [None]  # consecutive desired states are one path, as the node's feed-forward carries it

        def law(k: int, tk: float, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, *_: object) -> np.ndarray:
            if path[0] is None:
                path[0] = served[0].stick_state()
            return served[0].predict_parts(q, dq, ddq, history=path[0]).total

        return law, feed

    laws = {
        "PD": (lambda k, *_: np.zeros(len(joints)), None),
        "PD + CAD feed-forward": (lambda k, *_: cad_ff[k], None),
        "PD + true-model feed-forward (the plant's own inverse dynamics)": (lambda k, *_: true_ff[k], None),
        "PD + learned feed-forward (frozen)": (lambda k, *_: frozen_ff[k], None),
        "PD + batch least squares on the samples the learner saw (the pipeline's q̈)":
            (lambda k, *_: pipeline_ff[k], None),
        "PD + batch least squares on the training recording's true states (the identification floor)":
            (lambda k, *_: floor_ff[k], None),
        f"PD + learned feed-forward (learning online, served copy refreshed every {refresh:g} s)":
            online_law(refresh),
    }
    if not args.skip_live:
        laws["PD + learned feed-forward (learning online, live model: not the default)"] = online_law(0.0)
    results = {}
    for name, (law, measured) in laws.items():
        t2 = time.perf_counter()
        run = run_loop(plant, t, qd, dqd, ddqd, law, kp, kd, seed=1, measured=measured)
        results[name] = {"rms_mrad": (1e3 * run.rms(skip_s)).tolist(),
                         "max_mrad": (1e3 * run.max_abs(skip_s)).tolist(),
                         "rms_all_mrad": float(1e3 * np.sqrt(np.mean(run.errors(skip_s) ** 2))),
                         "wall_s": time.perf_counter() - t2, "_run": run}
        r = results[name]
        print(f"{name[:60]:60s} RMS {r['rms_all_mrad']:8.3f} mrad  ({r['wall_s']:.1f} s)")

    cad = results["PD + CAD feed-forward"]["rms_all_mrad"]
    frozen = results["PD + learned feed-forward (frozen)"]["rms_all_mrad"]
    lines = ["| controller | " + " | ".join(f"j{i + 1}" for i in range(len(joints))) + " | all | ÷ CAD |",
             "|---|" + "---|" * (len(joints) + 2)]
    for name, r in results.items():
        rms = " | ".join(f"{v:.2f} / {m:.1f}" for v, m in zip(r["rms_mrad"], r["max_mrad"], strict=True))
        lines.append(f"| {name} | {rms} | {r['rms_all_mrad']:.2f} | {cad / r['rms_all_mrad']:.1f}× |")
    table = "\n".join(lines)
    print("\nper-joint RMS / max tracking error [mrad] after the first second:\n" + table)
    true = results["PD + true-model feed-forward (the plant's own inverse dynamics)"]["rms_all_mrad"]
    print(f"\nlearned (frozen) vs CAD feed-forward: {cad / frozen:.1f}x smaller RMS tracking error "
          f"(target >= 2x); vectorised feed-forward of {len(t)} states in {1e3 * batch_s:.0f} ms")
    print(f"learned (frozen) vs the true model's feed-forward: {frozen / true:.2f}x its RMS tracking error "
          "(target <= 2x)")

    out = {
        "machine": {"python": platform.python_version(), "processor": platform.processor(),
                    "node": platform.node()},
        "command": "PYTHONPATH=$PWD .venv/bin/python bench/node/closed_loop.py",
        "overrides": args.overrides, "robot": "panda", "rate_hz": rate, "duration_s": args.duration,
        "skip_s": skip_s,
        "train": {"bag": "panda_excitation (simulate_arm, seed 0)", "duration_s": args.train_duration,
                  "samples_learned": report.learned, "learn_wall_s": learn_s,
                  "realtime_factor": report.realtime_factor},
        "reference": {"multisine_seed": TEST_SEED, "share_of_states_inside_training_range": inside},
        "gains": {"rule": "K_p = m w^2, K_d = 2 m w, w = 2 pi 2 Hz, m = CAD mass-matrix diagonal at q_d(0)",
                  "kp": kp.tolist(), "kd": kd.tolist()},
        "frozen_std_median_Nm": np.median(frozen_std, axis=0).tolist(),
        "feedforward_error_rms_Nm": {k: v.tolist() for k, v in ff_error.items()},
        "vectorised_feedforward_s": batch_s,
        "results": {k: {kk: vv for kk, vv in v.items() if kk != "_run"} for k, v in results.items()},
        "learned_vs_cad_ratio": cad / frozen,
        "learned_vs_true_ratio": frozen / true,
        "table_markdown": table,
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=2))
    _figure(results, joints, skip_s, args.figure)
    print(f"wrote {args.json} and {args.figure}")


def _rms(error: np.ndarray) -> np.ndarray:
    """Per-joint RMS of (N, n) errors."""
    return np.sqrt(np.mean(error ** 2, axis=0))


def _identification_floor(model: LearnedModel, states: tuple[np.ndarray, np.ndarray, np.ndarray],
                          tau: np.ndarray, qd: np.ndarray, dqd: np.ndarray, ddqd: np.ndarray) -> np.ndarray:
    """The feed-forward of the best linear-in-parameters fit of training states and torques.

    Least squares of the measured torques [N·m] on the learner's own regressor (inertial parameters,
    friction, offsets) at the given (q, q̇, q̈) (every sample at once, the minimum-norm solution: the
    identifiable combinations are unique), evaluated at the reference. At the recording's *true* states:
    what any learner of the rigid-body part could reach from these 60 s of noisy torques; at the
    pipeline's samples: the same with the q̈ the learner saw.
    """
    regressor = model.estimator.regressor
    Phi = regressor.regressor(*states)
    theta = np.linalg.lstsq(Phi.reshape(-1, Phi.shape[-1]), tau.reshape(-1), rcond=None)[0]
    return regressor.regressor(qd, dqd, ddqd) @ theta


def _inside_training_range(rec: object, qd: np.ndarray, dqd: np.ndarray) -> float:
    """Share of reference states whose q and q̇ lie inside the training recording's per-joint range."""
    q, dq = rec.q, rec.dq  # type: ignore[attr-defined]
    ok = ((qd >= q.min(0)) & (qd <= q.max(0)) & (dqd >= dq.min(0)) & (dqd <= dq.max(0))).all(axis=1)
    return float(ok.mean())


def _figure(results: dict, joints: tuple[str, ...], skip_s: float, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7))
    width = 0.8 / len(results)
    for i, (name, r) in enumerate(results.items()):
        run = r["_run"]
        err = np.linalg.norm(run.q_desired - run.q, axis=1) * 1e3
        ax1.plot(run.t, err, lw=0.8, label=name)
        ax2.bar(np.arange(len(joints)) + i * width, r["rms_mrad"], width, label=name)
    ax1.set_yscale("log")
    ax1.set_xlabel("time [s]")
    ax1.set_ylabel("|q_d − q| [mrad]")
    ax1.axvline(skip_s, color="0.6", lw=0.6)
    ax1.legend(fontsize=7)
    ax1.set_title("Panda, 1 kHz torque control, PD at 2 Hz: tracking a motion not trained on")
    ax2.set_yscale("log")
    ax2.set_xticks(np.arange(len(joints)) + 0.4, [f"j{i + 1}" for i in range(len(joints))])
    ax2.set_ylabel("RMS tracking error [mrad]")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
