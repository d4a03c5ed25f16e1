"""Benchmark: false drops and caught spikes of the glitch check, old rule vs new, on the same streams.

Streams (every one clean: a drop is a false drop):

* the three real KUKA LWR4+ logs (200 Hz, jittered stamps; read from ``../shared/data/kuka_lwr4`` when
  present);
* simulated Panda and UR5 point-to-point moves at their URDF velocity limits with rests
  (:class:`~semiparam_ros.sim.trajectories.PointToPoint`, acceleration steps of up to ≈15 rad/s²), at
  100 Hz and 1 kHz, positions quantized to 1e-4 rad, stamps jittered ±10 %, velocity either the
  controller's (exact) or the backward difference of the logged positions (differentiated).

Then the same simulated streams with 20 one-sample spikes each (10 velocity spikes of ±(2–20) rad/s, 10
position spikes of ±(0.05–0.5) rad, at random moving or resting states): the fraction dropped.

The *old* rule is ``core/stream/pipeline.py`` at ``--baseline`` (the commit before the hold-and-decide rule),
extracted with ``git show`` and imported beside the current one. Usage::

    .venv/bin/python bench/stream/bench_glitch.py [--baseline REV] [--json PATH]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import pathlib
import subprocess
import sys
import tempfile
import types
from dataclasses import replace

import numpy as np

import semiparam_ros.core.stream.pipeline as new_pipeline
from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.sim.arms import ARM_ROBOTS, arm_regressor
from semiparam_ros.sim.encoders import encoder_readings
from semiparam_ros.sim.trajectories import PointToPoint

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "bench_glitch.json"
KUKA = ROOT.parent / "shared" / "data" / "kuka_lwr4"
KUKA_JOINTS = tuple(f"lwr_{i}_joint" for i in range(7))
DEFAULT_BASELINE = "619064a"  # the last commit with the drop-at-once rule


def load_baseline(rev: str, tmp: pathlib.Path) -> types.ModuleType:
    """Import ``core/stream/pipeline.py`` at ``rev`` as ``_old_pipeline``."""
    src = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:semiparam_ros/core/stream/pipeline.py"],
                         check=True, capture_output=True, text=True).stdout
    path = tmp / "_old_pipeline.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("_old_pipeline", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["_old_pipeline"] = module
    spec.loader.exec_module(module)
    return module


def dropped(module: types.ModuleType, joints: tuple[str, ...], states: list[JointStateData]) -> set[int]:
    """Indices of the states the module's glitch check drops (the new rule counts a drop one state late)."""
    late = module is new_pipeline
    pipe = module.SamplePipeline(joints, output="joint_torques")
    out = set()
    for k, msg in enumerate(states):
        before = pipe.drops["glitch"]
        pipe.add(msg)
        if pipe.drops["glitch"] > before:
            out.add(k - 1 if late else k)
    return out


def kuka_streams() -> dict[str, tuple[tuple[str, ...], list[JointStateData]]]:
    if not KUKA.is_dir():
        return {}
    from semiparam_ros.io.bags import read_messages

    out = {}
    for log in (1, 2, 3):
        msgs = read_messages(KUKA / f"measurements_{log}", joint_states_topic="/robot/joint_states",
                             wrench_topic=None)
        msgs = [m for m in msgs if isinstance(m, JointStateData)]
        out[f"KUKA log {log} (200 Hz, real)"] = (KUKA_JOINTS, msgs)
    return out


def p2p_streams(seconds: float = 60.0) -> dict[str, tuple[tuple[str, ...], list[JointStateData]]]:
    out = {}
    for robot in ("panda", "ur5"):
        reg = arm_regressor(robot)
        lower, upper = reg.position_limits()
        traj = PointToPoint.random(lower, upper, reg.velocity_limits(), seed=7, moves=200)
        joints = tuple(ARM_ROBOTS[robot].joints)
        for hz in (100.0, 1000.0):
            for velocity in ("exact", "differentiated"):
                states = encoder_readings(traj, joints, rate_hz=hz, resolution=1e-4, seed=3,
                                          velocity=velocity, duration=seconds)
                out[f"{robot} P2P {hz:g} Hz, q 1e-4 rad, q̇ {velocity}"] = (joints, states)
    return out


def with_spikes(states: list[JointStateData], seed: int, n: int = 20
                ) -> tuple[list[JointStateData], set[int]]:
    rng = np.random.default_rng(seed)
    out = list(states)
    where = sorted(rng.choice(np.arange(50, len(states) - 50, 7), n, replace=False).tolist())
    for i, k in enumerate(where):
        joint = int(rng.integers(len(states[k].names)))
        sign = rng.choice([-1.0, 1.0])
        if i % 2 == 0:
            vel = out[k].velocity.copy()
            vel[joint] += sign * rng.uniform(2.0, 20.0)
            out[k] = replace(out[k], velocity=vel)
        else:
            pos = out[k].position.copy()
            pos[joint] += sign * rng.uniform(0.05, 0.5)
            out[k] = replace(out[k], position=pos)
    return out, set(where)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--baseline", default=DEFAULT_BASELINE)
    parser.add_argument("--json", type=pathlib.Path, default=RESULTS)
    parser.add_argument("--seconds", type=float, default=60.0, help="length of each simulated stream [s]")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        old = load_baseline(args.baseline, pathlib.Path(tmp))
        rows = []
        print("| clean stream | joint states | false drops, old rule | false drops, new rule |")
        print("|---|---|---|---|")
        sims = p2p_streams(args.seconds)
        for name, (joints, states) in {**kuka_streams(), **sims}.items():
            a, b = len(dropped(old, joints, states)), len(dropped(new_pipeline, joints, states))
            n = len(states)
            rows.append({"stream": name, "states": n, "old": a, "new": b})
            print(f"| {name} | {n} | {a} ({100 * a / n:.3f} %) | {b} ({100 * b / n:.3f} %) |")
        print()
        print("| stream with 20 one-sample spikes | spikes dropped, old rule | others dropped, old "
              "| spikes dropped, new rule | others dropped, new |")
        print("|---|---|---|---|---|")
        spikes = []
        for i, (name, (joints, states)) in enumerate(sims.items()):
            spiked, where = with_spikes(states, seed=i)
            a, b = dropped(old, joints, spiked), dropped(new_pipeline, joints, spiked)
            row = {"stream": name, "spikes": len(where), "old_caught": len(a & where),
                   "old_others": len(a - where), "new_caught": len(b & where), "new_others": len(b - where)}
            spikes.append(row)
            print(f"| {name} | {row['old_caught']} | {row['old_others']} | {row['new_caught']} | "
                  f"{row['new_others']} |")
    out = {"baseline": args.baseline, "false_drops": rows, "spikes": spikes}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=1) + "\n")
    print(f"\nwrote {args.json}")


if __name__ == "__main__":
    main()
