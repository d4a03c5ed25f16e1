"""Causal low-delay q̈ (Kalman: constant jerk or snap) against the centred Savitzky–Golay.

Every estimate comes from the streaming estimators of ``semiparam_ros.core.stream.acceleration`` (the node's
code). Two errors per estimator, both as RMS of (estimate − reference) relative to the RMS of the reference:
- *own stamp*: the estimate against the reference at the stamp it refers to (what learning sees);
- *newest stamp*: the estimate against the reference at the newest joint state received when it was
  emitted (what a consumer that needs q̈ *now* gets: for S-G the delay turns into error).

Data:
1. Synthetic: sums of sines ≤ 1.5 Hz (as bench/stream/accel_window.py), white velocity noise σ_v, 100 Hz and
   1 kHz.
2. Simulated Panda (semiparam_ros.sim.arms, excitation scenario, the simulator's own noise), 1 kHz and 100 Hz,
   exact q̈ known.
3. Real KUKA LWR4+ logs 1 and 3 (200 Hz): no true q̈ exists. Reference: a NON-CAUSAL estimate, zero-phase
   4th-order Butterworth at 4 Hz on q̇ (filtfilt) then a central difference — it favours smooth estimates
   and is itself an estimate, so the KUKA column ranks the estimators only roughly.
4. SP's torque prediction error (test-then-train, RMSE per joint [N·m] and their mean) with each estimator:
   Panda (train on one excitation recording, test on another, same physical robot) at 1 kHz and 100 Hz, and
   KUKA (config/kuka_lwr4.yaml, train log 1, test log 3) — both against the measured torque at the sample's
   own stamp and at the newest stamp.

    PYTHONPATH=$PWD .venv/bin/python bench/stream/bench_acceleration.py [--kuka DIR] [--quick] [--no-sp]

Writes bench/results/bench_acceleration.json and bench/results/bench_acceleration.md.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.signal import butter, filtfilt

from semiparam_ros.core.stream.acceleration import AccelerationConfig, make_estimator

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results"


@dataclass(frozen=True)
class Variant:
    label: str
    params: dict  # acceleration.* parameters (EstimatorConfig names without the prefix)

    def acceleration_config(self) -> AccelerationConfig:
        p = dict(self.params)
        return AccelerationConfig(method=p.pop("method"), **p)


VARIANTS = (
    Variant("savgol 0.08 s quadratic (before)", {"method": "savgol", "window_s": 0.08, "polyorder": 2}),
    Variant("savgol 0.04 s", {"method": "savgol", "window_s": 0.04, "polyorder": 2}),
    Variant("savgol 0.08 s cubic", {"method": "savgol", "window_s": 0.08, "polyorder": 3}),
    Variant("savgol 0.12 s cubic (default)", {"method": "savgol", "window_s": 0.12, "polyorder": 3}),
    Variant("finite_difference 0.02 s, 20 Hz", {"method": "finite_difference", "window_s": 0.02,
                                                "cutoff_hz": 20.0}),
    Variant("kalman jerk 4 Hz", {"method": "kalman", "kalman_model": "jerk", "bandwidth_hz": 4.0}),
    Variant("kalman jerk 6 Hz", {"method": "kalman", "kalman_model": "jerk", "bandwidth_hz": 6.0}),
    Variant("kalman jerk 8 Hz", {"method": "kalman", "kalman_model": "jerk", "bandwidth_hz": 8.0}),
    Variant("kalman jerk 10 Hz", {"method": "kalman", "kalman_model": "jerk", "bandwidth_hz": 10.0}),
    Variant("kalman jerk 12 Hz", {"method": "kalman", "kalman_model": "jerk", "bandwidth_hz": 12.0}),
    Variant("kalman jerk 16 Hz", {"method": "kalman", "kalman_model": "jerk", "bandwidth_hz": 16.0}),
    Variant("kalman snap 4 Hz", {"method": "kalman", "kalman_model": "snap", "bandwidth_hz": 4.0}),
    Variant("kalman snap 5 Hz", {"method": "kalman", "kalman_model": "snap", "bandwidth_hz": 5.0}),
    Variant("kalman snap 6 Hz", {"method": "kalman", "kalman_model": "snap", "bandwidth_hz": 6.0}),
    Variant("kalman snap 8 Hz", {"method": "kalman", "kalman_model": "snap", "bandwidth_hz": 8.0}),
    Variant("kalman snap 10 Hz", {"method": "kalman", "kalman_model": "snap", "bandwidth_hz": 10.0}),
)
SP_VARIANTS = ("savgol 0.08 s quadratic (before)", "savgol 0.08 s cubic", "savgol 0.12 s cubic (default)",
               "finite_difference 0.02 s, 20 Hz", "kalman jerk 8 Hz", "kalman jerk 12 Hz", "kalman snap 5 Hz",
               "kalman snap 6 Hz", "kalman snap 8 Hz")


def stream(stamps: np.ndarray, dq: np.ndarray, config: AccelerationConfig):
    """Run the streaming estimator; return (ref index, newest index, ddq, delay_s, lag_s, µs/sample)."""
    est = make_estimator(dq.shape[1], config)
    index = {int(s): k for k, s in enumerate(stamps.tolist())}
    ref, newest, out = [], [], []
    t0 = time.perf_counter()
    for k, (s, v) in enumerate(zip(stamps.tolist(), dq, strict=True)):
        for r, d in est.update_trusted(int(s), v):
            if d is not None:
                ref.append(index[r])
                newest.append(k)
                out.append(d)
    us = (time.perf_counter() - t0) / len(stamps) * 1e6
    return np.array(ref), np.array(newest), np.array(out), est.delay_s, est.lag_s, us


def rel_rms(err: np.ndarray, ref: np.ndarray) -> float:
    return float(np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(ref**2)))


def qdd_errors(stamps: np.ndarray, dq: np.ndarray, ddq_ref: np.ndarray, margin: int) -> dict:
    """Errors of every variant; samples within ``margin`` of either end are left out (reference edges)."""
    out = {}
    n = len(stamps)
    for v in VARIANTS:
        ref, newest, est, delay, lag, us = stream(stamps, dq, v.acceleration_config())
        keep = (ref >= margin) & (newest < n - margin)
        r, w, e = ref[keep], newest[keep], est[keep]
        out[v.label] = {"delay_s": delay, "lag_s": lag, "us_per_sample": us,
                        "own_stamp": rel_rms(e - ddq_ref[r], ddq_ref[r]),
                        "newest_stamp": rel_rms(e - ddq_ref[w], ddq_ref[w])}
    return out


def sines(rate: float, sigma_v: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    t = np.arange(0.0, 30.0, dt)
    f = rng.uniform(0.1, 1.5, size=(6, 5))
    a = rng.uniform(0.05, 0.3, size=(6, 5))
    ph = rng.uniform(0, 2 * np.pi, size=(6, 5))
    arg = 2 * np.pi * f[None] * t[:, None, None] + ph[None]
    w = 2 * np.pi * f[None]
    dq = (a[None] * w * np.cos(arg)).sum(-1)
    ddq = (-a[None] * w**2 * np.sin(arg)).sum(-1)
    stamps = 10**9 + np.round(t * 1e9).astype(np.int64)
    return stamps, dq + sigma_v * rng.standard_normal(dq.shape), ddq


def panda(rate: float, name: str, duration: float):
    from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm

    return simulate_arm(ArmScenarioConfig(name=name, robot="panda", duration=duration, rate=rate))


def kuka_arrays(root: Path, log: str):
    from semiparam_ros.io.bags import read_topic_arrays

    joints = [f"lwr_{i}_joint" for i in range(7)]
    arr = read_topic_arrays(root / log, "/robot/joint_states", joints=joints)
    dt = float(np.median(np.diff(arr.stamp_ns))) * 1e-9
    dq = arr.fields["velocity"]
    b, a = butter(4, 4.0 * 2 * dt)
    ref = np.gradient(filtfilt(b, a, dq, axis=0), dt, axis=0)
    return arr.stamp_ns, dq, ref, 1.0 / dt


# ------------------------------------------------------------------------------------------------ SP
def sp_errors(config, train_msgs, test_msgs) -> dict:
    """Test-then-train SP over the train messages then the test messages (pipeline restarted between)."""
    from semiparam_ros.core.estimator.online import OnlineEstimator

    est = OnlineEstimator(config, kind="SP")
    for m in train_msgs:
        est.process(m)
    est.pipeline.reset()
    stamps, pred, meas = [], [], []
    newest = []
    t0 = time.perf_counter()
    for m in test_msgs:
        for r in est.process(m):
            stamps.append(r.sample.stamp_ns)
            newest.append(m.stamp_ns)
            pred.append(r.prediction.total)
            meas.append(r.sample.y)
    elapsed = time.perf_counter() - t0
    pred, meas = np.array(pred), np.array(meas)
    y_at = {m.stamp_ns: np.asarray(m.effort) for m in test_msgs}
    y_new = np.array([y_at[s] for s in newest])
    rmse = np.sqrt(np.mean((pred - meas) ** 2, axis=0))
    rmse_new = np.sqrt(np.mean((pred - y_new) ** 2, axis=0))
    return {"rmse_per_joint_Nm": rmse.tolist(), "rmse_mean_Nm": float(rmse.mean()),
            "rmse_newest_mean_Nm": float(rmse_new.mean()), "samples": len(pred),
            "delay_s": est.pipeline.estimator.delay_s,
            "wall_s": elapsed}


def messages_from_recording(rec):
    from semiparam_ros.core.stream.messages import JointStateData

    names = tuple(rec.joint_names)
    return [JointStateData(int(s), names, q, dq, tau) for s, q, dq, tau in
            zip(rec.stamps.tolist(), rec.q_measured, rec.dq_measured, rec.measured_torques, strict=True)]


def sp_table(config, train_msgs, test_msgs) -> dict:
    by_label = {v.label: v for v in VARIANTS}
    out = {}
    for label in SP_VARIANTS:
        over = {f"acceleration.{k}": val for k, val in by_label[label].params.items()}
        over["acceleration.window"] = 0
        out[label] = sp_errors(config.with_overrides(over), train_msgs, test_msgs)
        print(f"    SP {label}: mean RMSE {out[label]['rmse_mean_Nm']:.4f} N·m "
              f"({out[label]['wall_s']:.0f} s)", flush=True)
    return out


# ------------------------------------------------------------------------------------------------ main
def qdd_markdown(title: str, table: dict[str, dict]) -> list[str]:
    cols = list(table)
    lines = [f"**{title}** — relative RMS error of q̈ (own stamp / newest stamp)", "",
             "| estimator | delay [ms] | " + " | ".join(cols) + " |", "|---" * (len(cols) + 2) + "|"]
    for v in VARIANTS:
        first = table[cols[0]][v.label]
        delay = first["delay_s"] * 1e3
        cells = [f"{table[c][v.label]['own_stamp']:.4f} / {table[c][v.label]['newest_stamp']:.4f}"
                 for c in cols]
        lines.append(f"| {v.label} | {delay:.1f} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def sp_markdown(title: str, table: dict[str, dict]) -> list[str]:
    n = len(next(iter(table.values()))["rmse_per_joint_Nm"])
    lines = [f"**{title}** — SP torque RMSE [N·m], test-then-train on the test log", "",
             "| estimator | " + " | ".join(f"j{i + 1}" for i in range(n)) + " | mean | mean vs newest |",
             "|---" * (n + 3) + "|"]
    for label, r in table.items():
        lines.append(f"| {label} | " + " | ".join(f"{v:.4f}" for v in r["rmse_per_joint_Nm"])
                     + f" | {r['rmse_mean_Nm']:.4f} | {r['rmse_newest_mean_Nm']:.4f} |")
    return [*lines, ""]


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--kuka", type=Path, default=Path("/work/shared/data/kuka_lwr4"))
    p.add_argument("--quick", action="store_true", help="shorter Panda recordings (smoke run)")
    p.add_argument("--no-sp", action="store_true", help="q̈ tables only")
    args = p.parse_args()
    results: dict = {"command": "PYTHONPATH=$PWD .venv/bin/python bench/stream/bench_acceleration.py"
                     + (" --quick" if args.quick else "") + (" --no-sp" if args.no_sp else "")}
    md: list[str] = ["# q̈ estimators: error vs delay, and SP's prediction error with each", "",
                     f"Command: `{results['command']}`", ""]

    synth = {}
    for rate, sigma in ((100.0, 0.005), (100.0, 0.02), (1000.0, 0.005), (1000.0, 0.02)):
        stamps, dq, ddq = sines(rate, sigma)
        synth[f"{int(rate)} Hz σ_v={sigma}"] = qdd_errors(stamps, dq, ddq, margin=int(0.3 * rate))
        print(f"sines {rate} Hz σ={sigma} done", flush=True)
    results["qdd_sines"] = synth
    md += qdd_markdown("Sums of sines ≤ 1.5 Hz, exact q̈", synth)

    dur = 20.0 if args.quick else 60.0
    recs = {}
    pandas = {}
    for rate in (1000.0, 100.0):
        train = panda(rate, "bench_accel_train", dur)
        test = panda(rate, "bench_accel_test", dur / 2)
        recs[rate] = (train, test)
        pandas[f"Panda {int(rate)} Hz"] = qdd_errors(test.stamps, test.dq_measured, test.ddq,
                                                     margin=int(0.3 * rate))
        print(f"panda {rate} Hz q̈ done", flush=True)
    results["qdd_panda"] = pandas
    md += qdd_markdown("Simulated Panda (excitation, simulator noise), exact q̈", pandas)

    kuka_ok = args.kuka.is_dir()
    if kuka_ok:
        kk = {}
        for log in ("measurements_1", "measurements_3"):
            stamps, dq, ref, rate = kuka_arrays(args.kuka, log)
            kk[f"KUKA {log} ({rate:.0f} Hz)"] = qdd_errors(stamps, dq, ref, margin=int(0.3 * rate))
        results["qdd_kuka"] = kk
        md += qdd_markdown("Real KUKA LWR4+ logs; reference = NON-CAUSAL zero-phase Butterworth 4 Hz + "
                           "central difference (no true q̈ exists)", kk)
        print("kuka q̈ done", flush=True)

    if not args.no_sp:
        from semiparam_ros.core.config import load_config

        sp: dict = {}
        panda_cfg = load_config(ROOT / "config" / "panda.yaml")
        for rate, (train, test) in recs.items():
            print(f"  SP Panda {int(rate)} Hz", flush=True)
            sp[f"Panda {int(rate)} Hz"] = sp_table(panda_cfg, messages_from_recording(train),
                                                   messages_from_recording(test))
        if kuka_ok:
            from semiparam_ros.io.bags import read_messages

            cfg = load_config(ROOT / "config" / "kuka_lwr4.yaml").with_overrides(
                {"robot.urdf": str(args.kuka / "kuka_lwr4_cogimon.urdf")})
            topic = cfg["topics.joint_states"]
            train, test = (list(read_messages(args.kuka / log, joint_states_topic=topic, wrench_topic=None))
                           for log in ("measurements_1", "measurements_3"))
            print("  SP KUKA", flush=True)
            sp["KUKA train 1 → test 3"] = sp_table(cfg, train, test)
        results["sp"] = sp
        for title, table in sp.items():
            md += sp_markdown(title, table)

    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_acceleration.json").write_text(json.dumps(results, indent=1) + "\n")
    (RESULTS / "bench_acceleration.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
