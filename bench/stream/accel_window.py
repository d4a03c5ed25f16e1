"""Choose acceleration.window_s by measurement.

Two measurements, printed as tables:
1. Simulated smooth joint trajectories (sums of sines up to 1.5 Hz, the band of excitation trajectories),
   velocities with white noise, at 100 Hz and 1 kHz: RMS error of the Savitzky–Golay q̈ (polyorder 2) against
   the exact q̈, relative to the RMS of q̈, for window_s in a grid (``--polyorder``: the fit's degree).
2. The real KUKA LWR4+ logs (200 Hz): RMS of (measured torque − RNEA(q, q̇, q̈̂) with the URDF), and the RMS
   difference of q̈̂ against a non-causal reference (zero-phase 4th-order Butterworth at 4 Hz on q̇, then a
   central difference), for the same grid.

    PYTHONPATH=$PWD .venv/bin/python bench/stream/accel_window.py [--kuka /work/shared/data/kuka_lwr4] \\
        [--polyorder 3]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.signal import butter, filtfilt, savgol_filter

from semiparam_ros.core.stream.acceleration import samples_for_window

GRID_S = (0.02, 0.04, 0.06, 0.08, 0.1, 0.12, 0.16, 0.2)


def sg_ddq(dq: np.ndarray, window_s: float, dt: float, polyorder: int = 2) -> np.ndarray:
    window = samples_for_window(window_s, dt, "savgol", polyorder)  # the node's conversion
    return savgol_filter(dq, window, polyorder, deriv=1, delta=dt, axis=0, mode="interp")


def simulated(rate: float, sigma_v: float, seed: int = 0, polyorder: int = 2) -> dict[float, float]:
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    t = np.arange(0.0, 30.0, dt)
    n_j = 6
    f = rng.uniform(0.1, 1.5, size=(n_j, 5))
    a = rng.uniform(0.05, 0.3, size=(n_j, 5))
    ph = rng.uniform(0, 2 * np.pi, size=(n_j, 5))
    arg = 2 * np.pi * f[None] * t[:, None, None] + ph[None]
    w = 2 * np.pi * f[None]
    dq = (a[None] * w * np.cos(arg)).sum(-1)
    ddq = (-a[None] * w**2 * np.sin(arg)).sum(-1)
    noisy = dq + sigma_v * rng.standard_normal(dq.shape)
    out = {}
    for ws in GRID_S:
        est = sg_ddq(noisy, ws, dt, polyorder)
        m = samples_for_window(ws, dt)
        sl = slice(m, -m)
        out[ws] = float(np.sqrt(np.mean((est[sl] - ddq[sl]) ** 2)) / np.sqrt(np.mean(ddq[sl] ** 2)))
    return out


def kuka(root: Path, polyorder: int = 2) -> tuple[dict[float, float], dict[float, float], float]:
    from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
    from semiparam_ros.io.bags import read_topic_arrays

    joints = [f"lwr_{i}_joint" for i in range(7)]
    reg = RigidBodyRegressor.from_urdf(root / "kuka_lwr4_cogimon.urdf", joints, output="joint_torques")
    torque_err: dict[float, list[float]] = {ws: [] for ws in GRID_S}
    ref_err: dict[float, list[float]] = {ws: [] for ws in GRID_S}
    for log in ("measurements_1", "measurements_3"):
        arr = read_topic_arrays(root / log, "/robot/joint_states", joints=joints)
        t = arr.stamp_ns * 1e-9
        dt = float(np.median(np.diff(t)))
        q, dq, tau = arr.fields["position"], arr.fields["velocity"], arr.fields["effort"]
        b, a = butter(4, 4.0 * 2 * dt)
        ref = np.gradient(filtfilt(b, a, dq, axis=0), dt, axis=0)
        for ws in GRID_S:
            ddq = sg_ddq(dq, ws, dt, polyorder)
            m = samples_for_window(GRID_S[-1], dt)
            sl = slice(m, -m)
            pred = reg.wrench(q[sl], dq[sl], ddq[sl])
            torque_err[ws].append(float(np.sqrt(np.mean((tau[sl] - pred) ** 2))))
            rel = np.sqrt(np.mean((ddq[sl] - ref[sl]) ** 2)) / np.sqrt(np.mean(ref[sl] ** 2))
            ref_err[ws].append(float(rel))
    return ({k: float(np.mean(v)) for k, v in torque_err.items()},
            {k: float(np.mean(v)) for k, v in ref_err.items()}, 1.0 / dt)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--kuka", type=Path, default=Path("/work/shared/data/kuka_lwr4"))
    p.add_argument("--polyorder", type=int, default=2, help="degree of the local polynomial fit of q̇")
    args = p.parse_args()
    cases = [(100.0, 0.005), (100.0, 0.02), (1000.0, 0.005), (1000.0, 0.02)]
    sims = {c: simulated(*c, polyorder=args.polyorder) for c in cases}
    print(f"relative RMS error of q̈ (simulated, sums of sines ≤ 1.5 Hz; polyorder {args.polyorder}), by "
          "window_s [s]")
    print("| window_s | " + " | ".join(f"{int(r)} Hz σ_v={s}" for r, s in cases) + " |")
    print("|---" * (len(cases) + 1) + "|")
    for ws in GRID_S:
        print(f"| {ws:g} | " + " | ".join(f"{sims[c][ws]:.4f}" for c in cases) + " |")
    if args.kuka.is_dir():
        terr, rerr, rate = kuka(args.kuka, args.polyorder)
        print(f"\nKUKA LWR4+ logs 1 and 3 ({rate:.0f} Hz): torque RMSE of URDF RNEA with q̈̂ [N·m, mean over "
              "joints and logs]; relative RMS of q̈̂ − zero-phase reference")
        print("| window_s | samples | torque RMSE | q̈ vs reference |")
        print("|---|---|---|---|")
        for ws in GRID_S:
            print(f"| {ws:g} | {samples_for_window(ws, 1 / rate)} | {terr[ws]:.4f} | {rerr[ws]:.4f} |")


if __name__ == "__main__":
    main()
