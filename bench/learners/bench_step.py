"""Benchmark: ``OnlineEstimator.step`` in-process, before vs after the one-pass step, in one run.

The estimator's whole per-sample work as the node calls it (sample check, a-priori prediction with its
variance, σ, the contact gate, learning, the noise scale, the result record) on the samples of
``bags/icub_xy`` (``config/icub_right_arm.yaml``: gate on, memory τ = 20 s), for D ∈ {500, 1000} random
features, with the gate on (the node's default) and off (the paper's protocol).

The *before* implementation is the whole package at ``--baseline`` (default: the commit before this
work), extracted with ``git archive`` into a temporary directory under another name
(``_old_semiparam_ros``) and imported next to the current one, so both run in the same process on the
same samples. Both estimators step every sample; they alternate in blocks of ``--block`` samples (each
block timed per step), so the machine's load hits both alike while each keeps its caches within a block.
The first ``--warmup`` samples (the standardizer and gate warm-ups) are stepped untimed. Reported: the
median and p99 per step, the ratio of the medians, and how far the two estimators' predictions and σ
drift apart (max relative difference over the timed samples). One BLAS thread. Usage::

    PYTHONPATH=$PWD .venv/bin/python bench/learners/bench_step.py [--quick] [--baseline REV] [--json PATH]
"""

from __future__ import annotations

import argparse
import importlib
import io
import json
import os
import pathlib
import platform
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
import types
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

import semiparam_ros
import semiparam_ros.core.learners.rrls as rrls
from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.eval.bags.replay import Topics
from semiparam_ros.io.bags import read_messages

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "bench_step.json"
CONFIG = ROOT / "config" / "icub_right_arm.yaml"
BAG = ROOT / "bags" / "icub_xy"
DEFAULT_BASELINE = "13c2755"  # last commit before the one-pass step
OLD = "_old_semiparam_ros"
TARGETS_US = {500: 150.0, 1000: 330.0}  # gate on, in-process median (the step's targets)


def load_baseline(rev: str, tmp: pathlib.Path) -> types.ModuleType:
    """Extract the package at ``rev`` into ``tmp`` as ``_old_semiparam_ros`` and import it."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", rev, "semiparam_ros"],
                             check=True, capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(tmp, filter="data")
    (tmp / "semiparam_ros").rename(tmp / OLD)
    for path in (tmp / OLD).rglob("*.py"):
        path.write_text(path.read_text().replace("semiparam_ros", OLD))
    sys.path.insert(0, str(tmp))
    for name in ("config", "estimator", "messages"):
        importlib.import_module(f"{OLD}.core.{name}")
    return importlib.import_module(OLD)


def samples_of(make_estimator: Any, config: Any, joint_state_type: type, n_messages: int) -> list[Any]:
    """The paired samples of the bag's first messages, through a fresh estimator's pipeline."""
    est = make_estimator(config)
    topics = Topics.from_config(load_config(CONFIG))
    out: list[Any] = []
    for msg in list(read_messages(BAG, joint_states_topic=topics.joint_states,
                                  wrench_topic=topics.wrench))[:n_messages]:
        out += est.pipeline.add(msg)
    return out


def compare(n_features: int, gate: bool, old: types.ModuleType, n_messages: int, warmup: int,
            block: int) -> dict[str, Any]:
    """Time old and new ``step`` on the same samples, alternating blocks."""
    overrides = {"nonparametric.n_features": n_features, "gate.enabled": gate}
    new_cfg = load_config(CONFIG).with_overrides(overrides)
    old_cfg = old.core.config.load_config(CONFIG).with_overrides(overrides)
    new_samples = samples_of(OnlineEstimator, new_cfg, JointStateData, n_messages)
    old_samples = samples_of(old.core.estimator.OnlineEstimator, old_cfg, old.core.messages.JointStateData,
                             n_messages)
    assert len(new_samples) == len(old_samples) > warmup
    new_est = OnlineEstimator(new_cfg)
    old_est = old.core.estimator.OnlineEstimator(old_cfg)
    times: dict[str, list[float]] = {"before": [], "after": []}
    results: dict[str, list[Any]] = {"before": [], "after": []}
    clock = time.perf_counter
    for i in range(warmup):
        old_est.step(old_samples[i])
        new_est.step(new_samples[i])
    for start in range(warmup, len(new_samples), block):
        stop = min(start + block, len(new_samples))
        for name, est, samples in (("before", old_est, old_samples), ("after", new_est, new_samples)):
            ts, rs = times[name], results[name]
            for i in range(start, stop):
                t0 = clock()
                r = est.step(samples[i])
                ts.append(clock() - t0)
                rs.append(r)
    total_old = np.array([r.prediction.total for r in results["before"]])
    total_new = np.array([r.prediction.total for r in results["after"]])
    std_old = np.array([r.std for r in results["before"]])
    std_new = np.array([r.std for r in results["after"]])
    learned = [r.learned for r in results["before"]] == [r.learned for r in results["after"]]
    scale = np.abs(total_old).max(axis=1, keepdims=True)
    row = {
        "D": n_features, "gate": gate, "samples_timed": len(times["after"]),
        "before_median_us": 1e6 * statistics.median(times["before"]),
        "after_median_us": 1e6 * statistics.median(times["after"]),
        "before_p99_us": 1e6 * float(np.percentile(times["before"], 99)),
        "after_p99_us": 1e6 * float(np.percentile(times["after"], 99)),
        "max_rel_diff_total": float((np.abs(total_new - total_old) / scale).max()),
        "bit_identical_total": bool(np.array_equal(total_new, total_old)),
        "max_rel_diff_std": float(np.nanmax(np.abs(std_new - std_old) / std_old)),
        "same_learned_flags": learned,
    }
    row["ratio"] = row["after_median_us"] / row["before_median_us"]
    row["after_kernel_median_us"] = kernel_share(new_cfg, new_samples, warmup, n_features)
    if gate:
        row["target_us"] = TARGETS_US[n_features]
    return row


def kernel_share(config: Any, samples: list[Any], warmup: int, n_features: int) -> float:
    """Median time [µs] of the random-feature learner's compiled Givens kernel per step (new code).

    A separate pass (a fresh estimator on the same samples) with ``qr_rls_steps`` wrapped in a timer:
    what remains of the step beyond it is the per-sample overhead this benchmark is about.
    """
    kernel = rrls.qr_rls_steps
    times: list[float] = []

    def timed(M: np.ndarray, *args: Any) -> Any:
        t0 = time.perf_counter()
        out = kernel(M, *args)
        if M.shape[0] == n_features:
            times.append(time.perf_counter() - t0)
        return out

    est = OnlineEstimator(config)
    for sample in samples[:warmup]:
        est.step(sample)
    rrls.qr_rls_steps = timed
    try:
        for sample in samples[warmup:]:
            est.step(sample)
    finally:
        rrls.qr_rls_steps = kernel
    return 1e6 * statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer samples (a smoke run)")
    parser.add_argument("--baseline", default=DEFAULT_BASELINE, help="git revision of the 'before' code")
    parser.add_argument("--block", type=int, default=200, help="samples per alternating block")
    parser.add_argument("--json", type=pathlib.Path, default=RESULTS)
    args = parser.parse_args(argv)
    n_messages, warmup = (4000, 1200) if args.quick else (12000, 1500)
    load_before = os.getloadavg()
    rows = []
    with tempfile.TemporaryDirectory() as tmp, threadpool_limits(1):
        old = load_baseline(args.baseline, pathlib.Path(tmp))
        for n_features in (500, 1000):
            for gate in (True, False):
                rows.append(compare(n_features, gate, old, n_messages, warmup, args.block))
    load_after = os.getloadavg()
    print(f"OnlineEstimator.step, in-process, bags/icub_xy, 1 BLAS thread; before = {args.baseline}; "
          f"load {load_before[0]:.1f} → {load_after[0]:.1f}")
    print("| D | gate | before median µs | after median µs | ratio | of which NP kernel | before p99 "
          "| after p99 | target | max rel. diff of predictions |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        target = f"≤ {r['target_us']:.0f}" if "target_us" in r else "–"
        print(f"| {r['D']} | {'on' if r['gate'] else 'off'} | {r['before_median_us']:.1f} | "
              f"{r['after_median_us']:.1f} | {r['ratio']:.2f} | {r['after_kernel_median_us']:.1f} | "
              f"{r['before_p99_us']:.0f} | {r['after_p99_us']:.0f} | {target} | "
              f"{r['max_rel_diff_total']:.1e} |")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({
        "benchmark": "bench_step", "baseline": args.baseline, "rows": rows,
        "samples": {"messages": n_messages, "untimed_warmup": warmup, "block": args.block},
        "machine": {"platform": platform.platform(), "processor": platform.processor(),
                    "cpu_count": os.cpu_count(), "python": platform.python_version(),
                    "numpy": np.__version__, "package": semiparam_ros.__name__,
                    "loadavg_before": load_before, "loadavg_after": load_after},
    }, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
