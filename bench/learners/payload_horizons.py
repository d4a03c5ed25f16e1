"""Benchmark: SP against its rigid body at every age, on a truth-known Panda carrying a payload.

The recipe (a user's truth-known check): the Panda of example-robot-data (fingers locked at 0 m) with a
1.2 kg point payload on link 7, 0.15 m along its z; measured torques = Pinocchio's RNEA of that true model
+ viscous friction 0.10–0.45 N·m·s/rad + Coulomb 0.18–0.60 N·m × tanh(q̇/0.02) + offsets (±0.3 N·m) +
white noise 0.03 N·m; each joint moves as three sinusoids at 0.08–0.45 Hz spanning 80 % of its range;
60 s to learn, another 30 s of other sinusoids to test, 1 kHz. The logs are written as bags and read
through the node's pipeline (``real_robots``' path: q̈ from the messages' own stamps), and the models are
scored at every age (one step, 0.1 s, 1 s, 10 s, frozen) by the delay line of
:mod:`semiparam_ros.eval.protocol.horizon`.

    .venv/bin/python bench/learners/payload_horizons.py [--set NAME=VALUE ...] [--json PATH]

Prints the horizon table and SP/P per age; writes ``bench/results/payload_horizons.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pinocchio as pin

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from semiparam_ros.cli.evaluate import parse_overrides  # noqa: E402
from semiparam_ros.core.config import load_evaluation_config  # noqa: E402
from semiparam_ros.core.estimator.build import build_regressor  # noqa: E402
from semiparam_ros.core.stream.messages import JointStateData  # noqa: E402
from semiparam_ros.eval.protocol.horizon import DEFAULT_HORIZONS, horizon_markdown  # noqa: E402
from semiparam_ros.io.bags import BagWriter  # noqa: E402
from semiparam_ros.report.real_robot import evaluate_logs  # noqa: E402

RATE = 1000.0
PAYLOAD_KG, PAYLOAD_Z_M = 1.2, 0.15


def true_model(urdf_xml: str, joints: tuple[str, ...]) -> pin.Model:
    """The Panda with its other joints locked at 0 and the payload added to link 7's body."""
    full = pin.buildModelFromXML(urdf_xml)
    lock = [j for j in range(1, full.njoints) if full.names[j] not in joints]
    model = pin.buildReducedModel(full, lock, pin.neutral(full))
    last = model.getJointId(joints[-1])
    model.inertias[last] = model.inertias[last] + pin.Inertia(PAYLOAD_KG, np.array([0.0, 0.0, PAYLOAD_Z_M]),
                                                              np.zeros((3, 3)))
    return model


def motion(lower: np.ndarray, upper: np.ndarray, seconds: float, seed: int
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Three sinusoids per joint at 0.08–0.45 Hz spanning 80 % of its range: stamps [s], q, q̇, q̈."""
    rng = np.random.default_rng(seed)
    n = lower.size
    t = np.arange(round(seconds * RATE)) / RATE
    freq = rng.uniform(0.08, 0.45, (n, 3))
    phase = rng.uniform(0, 2 * np.pi, (n, 3))
    share = rng.dirichlet(np.ones(3), n)  # each sinusoid's part of the amplitude
    amp = 0.8 * 0.5 * (upper - lower)[:, None] * share
    centre = 0.5 * (upper + lower)
    w = 2 * np.pi * freq
    arg = w[None] * t[:, None, None] + phase[None]
    q = centre + (amp * np.sin(arg)).sum(-1)
    dq = (amp * w * np.cos(arg)).sum(-1)
    ddq = -(amp * w * w * np.sin(arg)).sum(-1)
    return t, q, dq, ddq


def torques(model: pin.Model, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, rng: np.random.Generator,
            friction: dict[str, np.ndarray]) -> np.ndarray:
    """Measured torques [N·m]: RNEA of the true model + friction + offsets + white noise."""
    data = model.createData()
    rigid = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    fr = friction["viscous"] * dq + friction["coulomb"] * np.tanh(dq / 0.02) + friction["offset"]
    return rigid + fr + 0.03 * rng.standard_normal(q.shape)


def write_bag(path: Path, joints: tuple[str, ...], t: np.ndarray, q: np.ndarray, dq: np.ndarray,
              tau: np.ndarray) -> None:
    with BagWriter(path) as bag:
        for k in range(t.size):
            stamp = 1_000_000_000 + round(t[k] * 1e9)
            bag.write_joint_state("/joint_states", JointStateData(stamp, joints, q[k], dq[k], tau[k]))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="NAME=VALUE")
    p.add_argument("--train-seconds", type=float, default=60.0)
    p.add_argument("--test-seconds", type=float, default=30.0)
    p.add_argument("--json", type=Path, default=ROOT / "bench" / "results" / "payload_horizons.json")
    args = p.parse_args(argv)
    cfg = load_evaluation_config(ROOT / "config" / "panda.yaml",
                                 {"topics.joint_states": "/joint_states", **parse_overrides(args.overrides)})
    regressor = build_regressor(cfg)
    joints = tuple(cfg["robot.joints"])
    model = true_model(regressor.urdf_xml, joints)
    lower, upper = regressor.position_limits()
    rng = np.random.default_rng(7)
    n = len(joints)
    friction = {"viscous": rng.uniform(0.10, 0.45, n), "coulomb": rng.uniform(0.18, 0.60, n),
                "offset": rng.uniform(-0.3, 0.3, n)}
    with tempfile.TemporaryDirectory() as folder:
        bags = {}
        for name, seconds, seed in (("train", args.train_seconds, 1), ("test", args.test_seconds, 2)):
            t, q, dq, ddq = motion(lower, upper, seconds, seed)
            bags[name] = Path(folder) / name
            write_bag(bags[name], joints, t, q, dq, torques(model, q, dq, ddq, rng, friction))
        comparison = evaluate_logs(cfg, bags["train"], bags["test"], friction_joints=joints, splits=1,
                                   inject=False, horizons=DEFAULT_HORIZONS)
    report = comparison.horizons
    assert report is not None
    print(horizon_markdown(report))
    ratios = {h.label: report.mean("SP", h.label) / report.mean("P", h.label) for h in report.horizons}
    print("| age | " + " | ".join(ratios) + " |")
    print("|---|" + "---|" * len(ratios))
    print("| SP / P | " + " | ".join(f"{v:.3f}" for v in ratios.values()) + " |")
    out = {"recipe": __doc__.split("\n\n")[1], "overrides": args.overrides,
           "friction": {k: v.tolist() for k, v in friction.items()},
           "sp_over_p": ratios,
           "rmse": {m: {h.label: report.mean(m, h.label) for h in report.horizons}
                    for m in ("P", "NP", "SP", "persistence") if m in report.rmse}}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=1))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
