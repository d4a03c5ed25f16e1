"""Select the consistent residual's defaults (λ of the residual, novelty scale ν₀) by held-out *motion*.

For every pair of logs (train on one motion, test frozen on another): the KUKA LWR4+ logs (all ordered
pairs of the three), the simulated Panda and UR5 (1 kHz, excitation scenario, trained on seed 1, tested on
seed 2), and the simulated iCub (XY circles → XZ circles), with every other parameter at its default,
this trains P, NP and the consistent SP for each λ, then scores the frozen SP for every ν₀ at once (the
weight exp(−(ν/ν₀)²) only enters the prediction: the raw residual and ν are recorded per test sample).
Mean RMSE over the outputs on the whole test log. Prints a table and writes JSON.

    PYTHONPATH=$PWD .venv/bin/python bench/learners/consistent_selection.py \
        [--data ../shared/data/kuka_lwr4] \
        [--out bench/results/consistent_selection.json] [--lams 0.001 0.01 0.1]

About 20 min on 2 cores (the 1 kHz arms dominate); bags are simulated into a temporary folder.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from semiparam_ros.core.config import load_config
from semiparam_ros.core.stream.rate import measured_period_s
from semiparam_ros.eval.bags.replay import build_models, load_samples
from semiparam_ros.eval.protocol.prequential import train

ROOT = Path(__file__).resolve().parents[2]
NU0 = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0)


def rmse(P: np.ndarray, Y: np.ndarray) -> float:
    return float(np.mean(np.sqrt(np.mean((P - Y) ** 2, axis=0))))


def score(config_path: Path, train_bag: Path, test_bag: Path, lam: float, overrides: dict) -> dict:
    cfg = load_config(config_path).with_overrides({**overrides, "semiparametric.combination": "consistent",
                                                   "nonparametric.lam": lam})
    tr, _ = load_samples(train_bag, cfg)
    te, _ = load_samples(test_bag, cfg)
    models = build_models(cfg, ("P", "NP", "SP"), sample_period_s=measured_period_s(tr.stamps_ns))
    for m in models.values():
        train(m, tr)
    out = {"P": rmse(np.array([models["P"].predict_one(x).total for x in te.X]), te.Y),
           "NP": rmse(np.array([models["NP"].predict_one(x).total for x in te.X]), te.Y)}
    sp = models["SP"]
    npm = sp.nonparametric
    YP, R, NU = [], [], []
    for x in te.X:
        yp, r, _, phi = sp._model_valid(x, sp.parametric.phi_cached(x))
        if phi is not None:
            _, v = npm.rls.predict(phi, return_variance=True, checked=True)
            nu = npm.rls.lam * float(v[0])
            r = r / np.exp(-((nu / sp.novelty_scale) ** 2))  # undo the default weight: the raw residual
        else:
            nu = 0.0
        YP.append(yp)
        R.append(r)
        NU.append(nu)
    YP, R, NU = np.array(YP), np.array(R), np.array(NU)
    out["SP raw"] = rmse(YP + R, te.Y)
    for nu0 in NU0:
        out[f"SP nu0={nu0:g}"] = rmse(YP + np.exp(-((NU / nu0) ** 2))[:, None] * R, te.Y)
    out["nu percentiles 10/50/90"] = [float(v) for v in np.percentile(NU, [10, 50, 90])]
    return out


def simulate(tmp: Path) -> dict[str, tuple[Path, Path, Path]]:
    pairs = {}
    for robot in ("panda", "ur5"):
        for seed in (1, 2):
            subprocess.run([sys.executable, "-m", "semiparam_ros.cli.simulate", "--robot", robot,
                            "--scenario", "excitation", "--duration", "60", "--seed", str(seed), "--rate",
                            "1000", "--out", str(tmp / f"{robot}_s{seed}"), "--quiet", "--overwrite"],
                           check=True)
        pairs[f"{robot} s1→s2"] = (ROOT / "config" / f"{robot}.yaml",
                                   tmp / f"{robot}_s1" / f"{robot}_excitation_1000hz",
                                   tmp / f"{robot}_s2" / f"{robot}_excitation_1000hz")
    subprocess.run([sys.executable, "-m", "semiparam_ros.cli.simulate", "--scenario", "xy", "--scenario",
                    "xz", "--out", str(tmp / "icub"), "--quiet", "--overwrite"], check=True)
    pairs["icub xy→xz"] = (ROOT / "config" / "icub_right_arm.yaml", tmp / "icub" / "icub_xy",
                           tmp / "icub" / "icub_xz")
    return pairs


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "kuka_lwr4")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "consistent_selection.json")
    ap.add_argument("--lams", type=float, nargs="+", default=[0.001, 0.01, 0.1])
    args = ap.parse_args()
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        pairs = {}
        if args.data.is_dir():
            urdf = args.data / "kuka_lwr4_cogimon.urdf"
            for a, b in ((1, 2), (2, 1), (1, 3), (3, 1), (2, 3), (3, 2)):
                pairs[f"kuka {a}→{b}"] = (ROOT / "config" / "kuka_lwr4.yaml", args.data / f"measurements_{a}",
                                          args.data / f"measurements_{b}", {"robot.urdf": str(urdf)})
        for name, (cfg, tr, te) in simulate(Path(tmp)).items():
            pairs[name] = (cfg, tr, te, {})
        for lam in args.lams:
            for name, (cfg, tr, te, ov) in pairs.items():
                res = score(cfg, tr, te, lam, ov)
                results.setdefault(f"lam={lam:g}", {})[name] = res
                print(f"lam={lam:g} {name}: P {res['P']:.4f} NP {res['NP']:.4f} SP raw {res['SP raw']:.4f} "
                      + " ".join(f"{nu0:g}:{res[f'SP nu0={nu0:g}']:.4f}" for nu0 in NU0), flush=True)
    # the table: per (λ, ν₀), the worst frozen SP / frozen P over the pairs and the mean of that ratio
    print("\n| λ | ν₀ | worst SP/P | mean SP/P | pairs with SP ≤ P |\n|---|---|---|---|---|")
    summary = []
    for lam_key, per in results.items():
        for nu0 in NU0:
            ratios = [r[f"SP nu0={nu0:g}"] / r["P"] for r in per.values()]
            row = {"lam": lam_key, "nu0": nu0, "worst": max(ratios), "mean": float(np.mean(ratios)),
                   "at_most_P": sum(x <= 1.0 for x in ratios), "pairs": len(ratios)}
            summary.append(row)
            print(f"| {lam_key[4:]} | {nu0:g} | {row['worst']:.4f} | {row['mean']:.4f} | "
                  f"{row['at_most_P']} of {row['pairs']} |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"results": results, "summary": summary}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
