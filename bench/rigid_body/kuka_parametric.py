"""Per-joint torque error of the rigid-body stage (P) on the real KUKA LWR4+ logs.

Train on measurements_1, then test-then-train on measurements_3 (each test sample is predicted before it
is learned). Variants: friction + offsets on/off, prior urdf/zero, column scaling on/off, and the
Coulomb velocity scale v_s; baselines: the CAD model (RNEA with the URDF, no learning) and persistence
(the previous measured torque). Optionally NP and SP with the package defaults. Errors: per-joint RMSE
[N·m] over the whole test log and over its second half ("regime"), and nMSE = MSE / var(τ_measured).

    PYTHONPATH=$PWD .venv/bin/python bench/rigid_body/kuka_parametric.py [--data ../shared/data/kuka_lwr4] \
        [--sp]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.build import build_model
from semiparam_ros.eval.bags.replay import load_samples

ROOT = Path(__file__).resolve().parents[2]


def run(model, train, test) -> tuple[np.ndarray, np.ndarray]:
    """Test-then-train through the training log, then the test log: (a-priori predictions on each)."""
    on_train = np.array([model.predict_learn_one(x, y).total for x, y in zip(train.X, train.Y, strict=True)])
    on_test = np.array([model.predict_learn_one(x, y).total for x, y in zip(test.X, test.Y, strict=True)])
    return on_train, on_test


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--data", type=Path, default=Path("/work/shared/data/kuka_lwr4"))
    p.add_argument("--sp", action="store_true", help="also NP and SP with the defaults (slower)")
    args = p.parse_args()
    base = load_config(ROOT / "config" / "kuka_lwr4.yaml").with_overrides(
        {"robot.urdf": str(args.data / "kuka_lwr4_cogimon.urdf")})
    train, _ = load_samples(args.data / "measurements_1", base)
    test, _ = load_samples(args.data / "measurements_3", base)
    n = test.Y.shape[1]
    variants: dict[str, dict] = {
        "P rigid only, prior zero, raw columns (paper)": {
            "parametric.friction": False, "parametric.offsets": False, "parametric.prior": "zero",
            "parametric.column_scaling": False},
        "P rigid only, prior zero": {"parametric.friction": False, "parametric.offsets": False,
                                     "parametric.prior": "zero"},
        "P rigid only, prior urdf": {"parametric.friction": False, "parametric.offsets": False},
        "P + friction + offsets, prior zero": {"parametric.prior": "zero"},
        "P + friction + offsets, prior urdf (default)": {},
        "P + friction + offsets + armature, prior urdf": {"parametric.armature": True},
        "P default, v_s = 0.01 rad/s": {"parametric.coulomb_velocity": 0.01},
        "P default, v_s = 0.02 rad/s": {"parametric.coulomb_velocity": 0.02},
        "P default, v_s = 0.1 rad/s": {"parametric.coulomb_velocity": 0.1},
    }
    preds: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    # CAD model: RNEA with the URDF (the urdf prior's prediction, never updated)
    cad = build_model(base.with_overrides({"parametric.friction": False, "parametric.offsets": False}), "P")
    preds["CAD (URDF RNEA, no learning)"] = (np.array([cad.predict_one(x).total for x in train.X]),
                                             np.array([cad.predict_one(x).total for x in test.X]))
    preds["persistence (previous measured torque)"] = (np.vstack([train.Y[:1], train.Y[:-1]]),
                                                       np.vstack([train.Y[-1:], test.Y[:-1]]))
    for name, over in variants.items():
        t0 = time.perf_counter()
        preds[name] = run(build_model(base.with_overrides(over), "P"), train, test)
        print(f"# {name}: {time.perf_counter() - t0:.1f} s", flush=True)
    if args.sp:
        for kind in ("NP", "SP"):
            t0 = time.perf_counter()
            preds[f"{kind} (defaults, D = {base['nonparametric.n_features']})"] = run(build_model(base, kind),
                                                                                     train, test)
            print(f"# {kind}: {time.perf_counter() - t0:.1f} s", flush=True)
    half = slice(len(test.Y) // 2, None)
    first = slice(0, 600)  # the first 3 s of the training log: what the prior is for
    var = test.Y.var(axis=0)
    print(f"\nKUKA LWR4+: train measurements_1 ({len(train.Y)} samples), test-then-train measurements_3 "
          f"({len(test.Y)} samples, 200 Hz). RMSE [N·m] per joint over the whole test log; mean over joints; "
          "then the mean over the second half (regime), the mean nMSE (MSE/var τ) over the whole log, and "
          "the mean RMSE over the first 3 s of the training log (from the prior, before data).\n")
    print("| model | " + " | ".join(f"j{i}" for i in range(n))
          + " | mean | mean 2nd half | mean nMSE | first 3 s of log 1 |")
    print("|---" * (n + 5) + "|")
    for name, (pr_train, pr) in preds.items():
        start = np.sqrt(((pr_train[first] - train.Y[first]) ** 2).mean(axis=0)).mean()
        err = pr - test.Y
        rmse = np.sqrt((err**2).mean(axis=0))
        rmse2 = np.sqrt((err[half] ** 2).mean(axis=0))
        nmse = (err**2).mean(axis=0) / var
        print(f"| {name} | " + " | ".join(f"{v:.3f}" for v in rmse)
              + f" | {rmse.mean():.3f} | {rmse2.mean():.3f} | {nmse.mean():.4f} | {start:.3f} |")
    print("\n| measured torque std [N·m] | " + " | ".join(f"{v:.3f}" for v in np.sqrt(var)) + " |")


if __name__ == "__main__":
    main()
