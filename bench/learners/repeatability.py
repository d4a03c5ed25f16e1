"""Benchmark: how well one recording of a motion predicts a second recording of the same motion.

The floor of any model learned from one log and used frozen on a repetition of the same motion is the
robot's run-to-run repeatability: at the same states (q, q̇, q̈), two runs differ by what the state does not
determine (sensor drift, hysteresis, temperature). This script aligns the second log to the first by the
sample shift that minimises the mean squared position difference, then scores **log A's own measured torque
at log B's states** as a prediction of log B — a model that remembered log A perfectly — with the
protocol's scoring (``evaluate``/``real_robots``: 10 sequential parts of log B, RMSE over the second half
of each part, mean over joints, mean over parts) and over the whole log, beside the frozen models of the
``real_robots`` JSON of the same pair. Log A's torque carries its own noise; a model could average it away,
so log A's torque smoothed by centred moving averages is scored too, the best window chosen on log B
itself (an optimistic floor: no model learned from log A alone knows that window). Usage::

    PYTHONPATH=$PWD .venv/bin/python bench/learners/repeatability.py --data /path/to/kuka_lwr4 \\
        [--a measurements_1 --b measurements_2] [--config config/kuka_lwr4.yaml] \\
        [--report docs/figures/real_robots_12.json] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import pathlib

import numpy as np
from scipy.ndimage import uniform_filter1d

from semiparam_ros.core.config import load_config
from semiparam_ros.eval.bags.replay import load_samples
from semiparam_ros.eval.protocol.prequential import split_bounds

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "repeatability_kuka_12.json"
MAX_SHIFT = 400  # samples searched either way for the alignment
SMOOTHING_S = (0.03, 0.05, 0.1, 0.2, 0.4, 0.8)  # widths [s] of the moving averages of log A's torque


def align(qa: np.ndarray, qb: np.ndarray) -> tuple[int, float]:
    """Return the shift s (B's sample i ↔ A's i + s) minimising the mean squared position difference."""
    best = (np.inf, 0)
    for s in range(-MAX_SHIFT, MAX_SHIFT + 1):
        a, b = (qa[s:], qb) if s >= 0 else (qa, qb[-s:])
        m = min(len(a), len(b))
        err = float(np.mean((a[:m] - b[:m]) ** 2))
        best = min(best, (err, s))
    return best[1], best[0]


def protocol_rmse(err: np.ndarray, splits: int = 10) -> tuple[float, np.ndarray]:
    """Mean over parts of the joint-averaged RMSE over each part's second half; and per joint (all parts)."""
    per_part, per_joint_sq = [], []
    for start, stop in split_bounds(err.shape[0], splits):
        seg = err[start + (stop - start) // 2: stop]
        rmse = np.sqrt(np.mean(seg**2, axis=0))
        per_part.append(float(rmse.mean()))
        per_joint_sq.append(np.mean(seg**2, axis=0))
    return float(np.mean(per_part)), np.sqrt(np.mean(per_joint_sq, axis=0))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=pathlib.Path, required=True, help="folder holding the two logs")
    ap.add_argument("--a", default="measurements_1", help="the log a model would learn (default %(default)s)")
    ap.add_argument("--b", default="measurements_2", help="its repetition (default %(default)s)")
    ap.add_argument("--config", type=pathlib.Path, default=ROOT / "config" / "kuka_lwr4.yaml")
    ap.add_argument("--report", type=pathlib.Path, default=ROOT / "docs" / "figures" / "real_robots_12.json",
                    help="real_robots JSON of the same pair, for the frozen models beside (optional)")
    ap.add_argument("--json", type=pathlib.Path, default=RESULTS)
    args = ap.parse_args()
    config = load_config(args.config)
    A, _ = load_samples(args.data / args.a, config)
    B, _ = load_samples(args.data / args.b, config)
    n = A.X.shape[1] // 3
    shift, msq = align(A.X[:, :n], B.X[:, :n])
    ia = np.arange(B.X.shape[0]) + shift
    keep = (ia >= 0) & (ia < A.X.shape[0])
    qa, qb = A.X[ia[keep], :n], B.X[keep, :n]
    err = B.Y[keep] - A.Y[ia[keep]]
    regime, per_joint = protocol_rmse(err)
    whole = np.sqrt(np.mean(err**2, axis=0))
    names = list(config["robot.joints"])
    rows: dict[str, dict[str, float]] = {
        f"{args.a}'s torque at {args.b}'s states": {"regime": regime, "whole": float(whole.mean())}}
    period = float(np.median(np.diff(A.stamps_ns))) * 1e-9
    smoothed = []
    for width in SMOOTHING_S:
        ya = uniform_filter1d(A.Y, 2 * round(width / period / 2) + 1, axis=0, mode="nearest")  # odd: centred
        e = B.Y[keep] - ya[ia[keep]]
        smoothed.append((protocol_rmse(e)[0], width, float(np.sqrt(np.mean(e**2, axis=0)).mean())))
    best, width, best_whole = min(smoothed)
    rows[f"{args.a}'s torque smoothed over {width:g} s (best of {len(SMOOTHING_S)} on {args.b})"] = {
        "regime": best, "whole": best_whole}
    if args.report.exists():
        protocol = json.loads(args.report.read_text())["protocol"]["models"]
        for model in ("P frozen", "NP frozen", "SP frozen", "SPC frozen"):
            if model in protocol:
                rows[model] = {"regime": float(protocol[model]["torque_rmse"])}
    print(f"{args.b} aligned to {args.a}: shift {shift} samples, max |Δq| "
          f"{np.abs(qa - qb).max():.4f} rad (rms {np.sqrt(msq):.5f}); {int(keep.sum())} samples")
    print("| predictor of " + args.b + " | RMSE at regime [N·m] | whole log |")
    print("|---|---|---|")
    for name, r in rows.items():
        print(f"| {name} | {r['regime']:.4f} | {r.get('whole', float('nan')):.4f} |")
    print("per joint at regime: " + ", ".join(f"{j} {v:.3f}" for j, v in zip(names, per_joint, strict=True)))
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"a": args.a, "b": args.b, "shift": shift, "samples": int(keep.sum()),
                                     "max_abs_dq_rad": float(np.abs(qa - qb).max()), "rows": rows,
                                     "per_joint_regime": dict(zip(names, per_joint.tolist(), strict=True)),
                                     "per_joint_whole": dict(zip(names, whole.tolist(), strict=True))},
                                    indent=1))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
