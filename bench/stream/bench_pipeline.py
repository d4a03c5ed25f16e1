"""Benchmark: per-message cost of the message-to-sample pipeline at 1 kHz, old vs new, in one run.

One *pair* is ``SamplePipeline.add`` of a 13-name JointState (the iCub right arm's 4
configured joints scattered among 9 others) plus ``add`` of the wrench stamped 0.2 ms later —
what the node does per millisecond at 1 kHz. Two stamp patterns:

* ``uniform``  — exactly 1 ms apart (simulated bags);
* ``jittered`` — 1 ms ± 50 µs uniform jitter (a real driver's stamps: no two windows share a spacing).

The *old* implementation is the committed version of ``core/stream/acceleration.py`` and
``core/stream/pipeline.py`` at ``--baseline`` (default: the commit before this benchmark's changes), extracted
with ``git show`` to a temporary directory and imported next to the current one, so both run in the same
process on the same messages. The samples of both are compared (stamps equal, q̈ relative difference
reported).

Also timed: ``estimator.update`` alone (Savitzky–Golay, window 9, polyorder 2, 4 joints) old vs new.
Timings are medians over repeats of the mean per call of back-to-back blocks (short blocks, so that
preemption on the shared 2-core machine hits few of them). One BLAS thread. Usage::

    .venv/bin/python bench/stream/bench_pipeline.py [--quick] [--baseline REV] [--json PATH]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import pathlib
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import types
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

import semiparam_ros.core.stream.acceleration as new_acceleration
import semiparam_ros.core.stream.pipeline as new_pipeline
from semiparam_ros.core.stream.messages import JointStateData, WrenchData

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "bench_pipeline.json"
DEFAULT_BASELINE = "d123a1e"  # last commit before the pipeline speed-up
CONFIGURED = ("r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow")
NAMES = (
    "torso_pitch", "torso_roll", "r_shoulder_pitch", "torso_yaw", "r_shoulder_roll", "neck_pitch",
    "r_shoulder_yaw", "neck_roll", "r_elbow", "neck_yaw", "r_wrist_prosup", "r_wrist_pitch", "r_wrist_yaw",
)
FRAME = "r_arm_ft_sensor"
T0 = 10**9


def load_baseline(rev: str, tmp: pathlib.Path) -> types.ModuleType:
    """Extract acceleration.py and pipeline.py at ``rev`` into ``tmp``; import them as ``_old_*``."""
    modules = {}
    for name in ("acceleration", "pipeline"):
        source = subprocess.run(
            ["git", "-C", str(ROOT), "show", f"{rev}:semiparam_ros/core/{name}.py"],
            check=True, capture_output=True, text=True,
        ).stdout
        source = source.replace("semiparam_ros.core.stream.acceleration", "_old_acceleration")
        path = tmp / f"_old_{name}.py"
        path.write_text(source)
        spec = importlib.util.spec_from_file_location(f"_old_{name}", path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[f"_old_{name}"] = module
        spec.loader.exec_module(module)
        modules[name] = module
    return modules["pipeline"]


def make_stream(n: int, jitter_s: float, seed: int) -> list[tuple[JointStateData, WrenchData]]:
    """``n`` (joint state, wrench) pairs at 1 kHz; smooth motion of all 13 joints."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3 + rng.uniform(-jitter_s, jitter_s, n)
    stamps = T0 + np.round(t * 1e9).astype(np.int64)
    freq = rng.uniform(0.2, 1.0, len(NAMES))
    pairs = []
    for stamp in stamps.tolist():
        ts = (stamp - T0) * 1e-9
        q = 0.5 * np.sin(2 * np.pi * freq * ts)
        dq = np.pi * freq * np.cos(2 * np.pi * freq * ts)
        js = JointStateData(stamp, NAMES, q, dq, 0.1 * q)
        f = np.array([1.0, -2.0, 9.0]) + 0.1 * np.sin(ts)
        w = WrenchData(stamp + 200_000, FRAME, f, 0.1 * f)
        pairs.append((js, w))
    return pairs


def time_blocks(step: Callable[[int], object], n: int, block: int) -> dict[str, float]:
    """Mean µs per call over consecutive blocks of ``block`` calls; median/min/max over the blocks."""
    per_call = []
    i = 0
    while i + block <= n:
        t0 = time.perf_counter()
        for k in range(i, i + block):
            step(k)
        per_call.append((time.perf_counter() - t0) / block * 1e6)
        i += block
    return {"median_us": statistics.median(per_call), "min_us": min(per_call), "max_us": max(per_call),
            "blocks": len(per_call)}


def run_pipeline(module: types.ModuleType, pairs: list, warmup: int, block: int) -> tuple[dict, list]:
    pipe = module.SamplePipeline(CONFIGURED, frame_id=FRAME, sync_tolerance=0.0005)
    samples: list = []
    for js, w in pairs[:warmup]:
        samples += pipe.add(js)
        samples += pipe.add(w)
    rest = pairs[warmup:]
    add = pipe.add

    def step(k: int) -> None:
        js, w = rest[k]
        samples.extend(add(js))
        samples.extend(add(w))

    timing = time_blocks(step, len(rest), block)
    timing["samples"] = len(samples)
    timing["drops"] = sum(pipe.drops.values())
    return timing, samples


def run_estimator(module: types.ModuleType, pairs: list, warmup: int, block: int) -> dict:
    est = module.make_estimator(len(CONFIGURED), module.AccelerationConfig())
    index = np.array([NAMES.index(j) for j in CONFIGURED])
    data = [(js.stamp_ns, np.ascontiguousarray(js.velocity[index])) for js, _ in pairs]
    for stamp, dq in data[:warmup]:
        est.update(stamp, dq)
    rest = data[warmup:]
    update = est.update

    def step(k: int) -> None:
        update(*rest[k])

    return time_blocks(step, len(rest), block)


def compare(old: list, new: list) -> dict[str, float | bool]:
    same_stamps = [s.stamp_ns for s in old] == [s.stamp_ns for s in new]
    if not same_stamps or not old:
        return {"same_stamps": same_stamps, "max_rel_ddq_diff": float("nan")}
    a = np.array([s.ddq for s in old])
    b = np.array([s.ddq for s in new])
    rel = float(np.max(np.abs(a - b)) / max(np.max(np.abs(a)), 1e-300))
    same_rest = all(np.array_equal(o.q, n.q) and np.array_equal(o.dq, n.dq) and np.array_equal(o.y, n.y)
                    for o, n in zip(old, new, strict=True))
    return {"same_stamps": True, "same_q_dq_y": same_rest, "max_rel_ddq_diff": rel}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer messages (a smoke run)")
    parser.add_argument("--baseline", default=DEFAULT_BASELINE, help="git revision of the old implementation")
    parser.add_argument("--json", type=pathlib.Path, default=None,
                        help=f"where to write the results (default {RESULTS.relative_to(ROOT)}; "
                             "--quick writes nowhere unless given)")
    args = parser.parse_args()
    n = 3000 if args.quick else 40000
    warmup, block, rounds = 200, 100, (1 if args.quick else 3)
    rows = []
    with tempfile.TemporaryDirectory() as tmp, threadpool_limits(1):
        old_pipeline = load_baseline(args.baseline, pathlib.Path(tmp))
        old_acceleration = sys.modules["_old_acceleration"]
        for pattern, jitter in (("uniform", 0.0), ("jittered", 50e-6)):
            pairs = make_stream(n, jitter, seed=1)
            res: dict[str, list] = {"old": [], "new": [], "old_est": [], "new_est": []}
            for _ in range(rounds):  # alternate, so that machine load hits both alike
                t_old, s_old = run_pipeline(old_pipeline, pairs, warmup, block)
                t_new, s_new = run_pipeline(new_pipeline, pairs, warmup, block)
                res["old"].append(t_old)
                res["new"].append(t_new)
                res["old_est"].append(run_estimator(old_acceleration, pairs, warmup, block))
                res["new_est"].append(run_estimator(new_acceleration, pairs, warmup, block))

            def med(key: str, res: dict = res) -> float:
                return statistics.median(r["median_us"] for r in res[key])

            rows.append({
                "stamps": pattern, "pairs": n - warmup,
                "pipeline_old_us": med("old"), "pipeline_new_us": med("new"),
                "pipeline_speedup": med("old") / med("new"),
                "estimator_old_us": med("old_est"), "estimator_new_us": med("new_est"),
                "estimator_speedup": med("old_est") / med("new_est"),
                "samples": res["new"][0]["samples"], "drops_new": res["new"][0]["drops"],
                "drops_old": res["old"][0]["drops"],
                "agreement": compare(s_old, s_new),
                "runs": {k: v for k, v in res.items()},
            })
    print("\n| stamps | pipeline pair old (µs) | new (µs) | speed-up | SG update old (µs) | new (µs) "
          "| speed-up | samples | max rel q̈ diff |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['stamps']} | {r['pipeline_old_us']:.1f} | {r['pipeline_new_us']:.1f} | "
              f"{r['pipeline_speedup']:.1f}× | {r['estimator_old_us']:.1f} | {r['estimator_new_us']:.1f} | "
              f"{r['estimator_speedup']:.1f}× | {r['samples']} | {r['agreement']['max_rel_ddq_diff']:.1e} |")
    out = args.json if args.json is not None else (None if args.quick else RESULTS)
    if out is not None:
        meta = {"python": platform.python_version(), "numpy": np.__version__, "machine": platform.machine(),
                "cpus": os.cpu_count(), "loadavg": os.getloadavg(), "quick": args.quick,
                "baseline": args.baseline, "configured_joints": CONFIGURED, "names": NAMES,
                "note": "median over blocks of 100 back-to-back calls, median over alternating rounds"}
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp_out = out.with_name(out.name + ".tmp")
        tmp_out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1, default=float))
        os.replace(tmp_out, out)
        print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
