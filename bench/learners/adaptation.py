"""Adaptation, contact gate and uncertainty calibration of the online estimator, measured on bags.

Runs :class:`~semiparam_ros.core.estimator.online.OnlineEstimator` (the node's data path) over a bag with
configuration overrides, optionally adds contact episodes (a force at the F/T reading, known onset and
duration) to the measured wrench, and reports per run:

- ``rmse``: a-priori RMSE per output group over chosen time windows (s from the first sample);
- ``recovery_s``: after a payload pickup at ``--pickup`` s, the time until the trailing 2 s RMSE of the
  first group first falls below 1.25× its value over the 20 s before the pickup;
- ``coverage``: the fraction of a-priori errors within ±2σ (σ the published std) per group, after the
  gate's warm-up, split at the pickup;
- gate counts (gated, adopted).

Usage (one JSON line per run on stdout)::

    PYTHONPATH=$PWD .venv/bin/python bench/learners/adaptation.py BAG [--set name=value ...] [--pickup S]
        [--contact START:DURATION:FX,FY,FZ ...] [--window NAME:A:B ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

from semiparam_ros.cli.evaluate import parse_overrides
from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.gate import Verdict
from semiparam_ros.core.stream.messages import WrenchData
from semiparam_ros.io.bags import read_messages

ROOT = Path(__file__).resolve().parents[2]


def run(bag: str, overrides: dict, *, contacts: list[tuple[float, float, np.ndarray]], config_path: Path,
        joint_states_topic: str = "/joint_states", wrench_topic: str | None = "/wrench") -> dict:
    config = load_config(config_path).with_overrides(overrides)
    est = OnlineEstimator(config)
    t0 = None
    stamps, ys, preds, stds, learned, verdicts = [], [], [], [], [], []
    for msg in read_messages(bag, joint_states_topic=joint_states_topic, wrench_topic=wrench_topic):
        if isinstance(msg, WrenchData):
            if t0 is None:
                t0 = msg.stamp_ns
            t = (msg.stamp_ns - t0) * 1e-9
            for start, duration, force in contacts:
                if start <= t < start + duration:
                    msg = dataclasses.replace(msg, force=msg.force + force)
            results = est.process(msg)
        else:
            if t0 is None and wrench_topic is None:
                t0 = msg.stamp_ns
            results = est.process(msg)
        for r in results:
            stamps.append(r.sample.stamp_ns)
            ys.append(r.sample.y)
            preds.append(r.prediction.total)
            stds.append(r.std)
            learned.append(r.learned)
            verdicts.append(r.verdict.value if r.verdict is not None else "")
    return dict(t=(np.array(stamps) - stamps[0]) * 1e-9, y=np.array(ys), yhat=np.array(preds),
                std=np.array(stds), learned=np.array(learned), verdict=np.array(verdicts),
                forgetting=est.forgetting, not_learned=est.not_learned)


def groups(n_out: int, output: str) -> dict[str, slice]:
    if output == "wrench":
        return {"force": slice(0, 3), "torque": slice(3, 6)}
    return {"joints": slice(0, n_out), **{f"joint{i}": slice(i, i + 1) for i in range(n_out)}}


def summarize(res: dict, output: str, windows: dict[str, tuple[float, float]], pickup: float | None,
              warmup: float) -> dict:
    t, e, s = res["t"], res["y"] - res["yhat"], res["std"]
    g = groups(e.shape[1], output)
    out: dict = {"forgetting": res["forgetting"], "not_learned": res["not_learned"],
                 "adopted": int(np.sum(res["verdict"] == Verdict.ADOPTED.value))}
    for name, (a, b) in windows.items():
        m = (t >= a) & (t < b)
        out[f"rmse_{name}"] = {k: float(np.sqrt(np.mean(e[m, sl] ** 2))) for k, sl in g.items()}
    inside = np.abs(e) <= 2 * s
    spans = {"all": t >= warmup}
    if pickup is not None:
        spans = {"before_pickup": (t >= warmup) & (t < pickup), "after_pickup": t >= pickup}
    out["coverage"] = {span: {k: float(np.mean(inside[m, sl])) for k, sl in g.items()}
                       for span, m in spans.items()}
    if pickup is not None:
        first = next(iter(g.values()))
        before = (t >= pickup - 20) & (t < pickup)
        ref = np.sqrt(np.mean(e[before, first] ** 2))
        sq = np.mean(e[:, first] ** 2, axis=1)
        rec = None
        for i in np.flatnonzero(t >= pickup + 2.0):
            w = (t > t[i] - 2.0) & (t <= t[i])
            if np.sqrt(np.mean(sq[w])) < 1.25 * ref:
                rec = float(t[i] - pickup)
                break
        out["recovery_s"] = rec
        out["rmse_ref_before_pickup"] = float(ref)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("bag")
    ap.add_argument("--config", type=Path, default=ROOT / "config" / "icub_right_arm.yaml")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--pickup", type=float, default=None)
    ap.add_argument("--contact", action="append", default=[], metavar="START:DURATION:FX,FY,FZ")
    ap.add_argument("--window", action="append", default=[], metavar="NAME:A:B")
    ap.add_argument("--joint-states-topic", default="/joint_states")
    ap.add_argument("--wrench-topic", default="/wrench", help="'' for joint-torque logs")
    args = ap.parse_args(argv)
    overrides = parse_overrides(args.set)
    contacts = []
    for c in args.contact:
        a, d, f = c.split(":")
        contacts.append((float(a), float(d), np.array([float(v) for v in f.split(",")])))
    windows = {}
    for w in args.window:
        name, a, b = w.split(":")
        windows[name] = (float(a), float(b))
    config = load_config(args.config).with_overrides(overrides)
    res = run(args.bag, overrides, contacts=contacts, config_path=args.config,
              joint_states_topic=args.joint_states_topic, wrench_topic=args.wrench_topic or None)
    summary = summarize(res, config["robot.output"], windows, args.pickup, config["gate.warmup"])
    summary["set"] = args.set
    summary["contacts"] = args.contact
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
