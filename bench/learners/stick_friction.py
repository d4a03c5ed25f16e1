"""Friction that remembers, chosen by held-out motion: frozen error with the stick state's δ side by side.

The served SP (learned as ``learn`` learns it, checkpoint, ``load_model``) is scored frozen on a held-out
log for each ``parametric.stick_displacement`` δ (0 = the static model of (q, q̇, q̈) served before): the
mean over the joints of each joint's RMSE, at rest (|q̇| < 0.01 rad/s) and in motion, their ratio, the ±2σ
coverage and the learned per-joint coefficients c [N·m]. Cases: the three real KUKA LWR4+ pairs (when
``--data`` holds them; few rests) and the simulated point-to-point arms with Dahl friction of
``sigma_calibration.py`` (Panda 1 kHz, UR5 100 Hz; their true Coulomb friction is listed beside c).

    .venv/bin/python bench/learners/stick_friction.py [--deltas 0 0.001 0.003 0.01] [--json ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from sigma_calibration import _plain, all_cases, learn_logs, served_on  # noqa: E402

from semiparam_ros.eval.protocol.slices import motion_slices  # noqa: E402


def run(config, logs, train_names, test_name, delta):
    """Learn the served SP with one δ on the training logs; score it frozen on the test log."""
    node = learn_logs(config.with_overrides({"parametric.stick_displacement": delta}), logs, train_names)
    test = logs[test_name]
    served, err, sigma = served_on(node, test)
    n, X = len(served.joints), test.X
    rest = motion_slices(X, n, test.n_outputs, test.sample_period_s)["at rest"]

    def rms(mask):
        values = [np.sqrt(np.mean(err[mask[:, k], k] ** 2)) for k in range(n) if mask[:, k].sum() >= 20]
        return float(np.mean(values)) if values else float("nan")

    stick = served.estimator.stick
    return {"train": "+".join(train_names), "test": test_name, "delta_rad": delta,
            "rmse": float(np.mean(np.sqrt(np.mean(err ** 2, axis=0)))), "at_rest": rms(rest),
            "in_motion": rms(~rest), "coverage": float(np.mean(np.abs(err) <= 2.0 * sigma)),
            "c_Nm": None if stick is None else [float(c) for c in stick.coefficient]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "kuka_lwr4")
    p.add_argument("--deltas", type=float, nargs="+", default=[0.0, 0.001, 0.003, 0.01])
    p.add_argument("--json", type=Path, default=ROOT / "bench" / "results" / "stick_friction.json")
    args = p.parse_args(argv)
    cases = all_cases(args.data)
    print("| train → test | δ [rad] | RMSE [N·m] | at rest | in motion | rest / motion | ±2σ coverage |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for config, logs, (train_names, test_name), delta in (
            (c, lg, pair, d) for c, lg, pairs in cases for pair in pairs for d in args.deltas):
        row = run(config, logs, train_names, test_name, delta)
        rows.append(row)
        print(f"| {row['train']} → {test_name} | {delta:g} | {row['rmse']:.4f} | {row['at_rest']:.4f} | "
              f"{row['in_motion']:.4f} | {row['at_rest'] / row['in_motion']:.2f} | {row['coverage']:.3f} |",
              flush=True)
    doc = {"date": time.strftime("%Y-%m-%d"),
           "command": " ".join(["bench/learners/stick_friction.py", *sys.argv[1:]]), "rows": rows}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(_plain(doc), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
