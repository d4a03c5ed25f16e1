"""Benchmark: can the estimator node keep up with 1 kHz paired input at D = 500 on this machine?

Generates a synthetic 1 kHz bag (joint states + wrenches with equal stamps every millisecond; the wrench is
the iCub right arm's rigid-body F/T wrench from the URDF plus a smooth non-rigid residual and noise),
starts the node as a separate process (``python -m semiparam_ros.ros.estimator_node`` with
``config/icub_right_arm.yaml``, D = 500, default sensor-data QoS), replays the bag over Fast DDS on
loopback at 1 kHz and measures:

* achieved learning rate (samples learned per second of playback, from the node's diagnostics) and the
  fraction of the sent pairs that were learned;
* latency percentiles: wrench published by the player → prediction received by the test process (this
  includes the Savitzky–Golay centring delay of ``window // 2`` joint states, 4 ms at 1 kHz), the node's
  own message-received → prediction-published latency, and the core step time (predict + learn);
* CPU% of the node process (psutil; 100 % = one core) and queue drops.

Prints a markdown table and writes ``bench/results/bench_node.json``. ``--quick`` plays 3 s instead of
20 s. Usage::

    .venv/bin/python bench/bench_node.py [--quick] [--seconds S] [--hz 1000] [--features 500]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "config" / "icub_right_arm.yaml"
RESULTS = REPO / "bench" / "results" / "bench_node.json"
JOINTS = ("r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow")


def make_bag(path: Path, *, seconds: float, hz: float = 1000.0, seed: int = 0) -> int:
    """Write a synthetic paired bag: /joint_states and /wrench (frame r_arm_ft_sensor) at ``hz``.

    Joint motion: sums of two sinusoids per joint around a mid-range posture (rad, rad/s, rad/s²
    analytic). Wrench: URDF rigid-body wrench + a smooth residual (≈1 N, 0.1 N·m) + Gaussian noise.

    Returns:
        Number of pairs written.
    """
    from semiparam_ros.core.config import load_config
    from semiparam_ros.core.estimator import build_regressor
    from semiparam_ros.core.messages import JointStateData, WrenchData
    from semiparam_ros.io.bags import BagWriter

    config = load_config(CONFIG)
    regressor = build_regressor(config)
    rng = np.random.default_rng(seed)
    n = round(seconds * hz)
    t = np.arange(n) / hz
    centre = np.array([-0.5, 0.5, 0.2, 0.9])
    amp = np.array([[0.35, 0.1], [0.25, 0.08], [0.3, 0.1], [0.4, 0.1]])
    freq = 2 * np.pi * np.array([[0.25, 0.9], [0.3, 1.1], [0.2, 0.7], [0.35, 1.3]])
    q = centre + (amp[:, 0] * np.sin(freq[:, 0] * t[:, None]) + amp[:, 1] * np.sin(freq[:, 1] * t[:, None]))
    phase0, phase1 = freq[:, 0] * t[:, None], freq[:, 1] * t[:, None]
    dq = amp[:, 0] * freq[:, 0] * np.cos(phase0) + amp[:, 1] * freq[:, 1] * np.cos(phase1)
    ddq = -amp[:, 0] * freq[:, 0] ** 2 * np.sin(phase0) - amp[:, 1] * freq[:, 1] ** 2 * np.sin(phase1)
    wrench = regressor.wrench(q, dq, ddq)
    residual = np.column_stack([
        0.8 * np.sin(q[:, 0] + q[:, 3]), 0.5 * np.cos(2 * q[:, 1]), 0.6 * np.tanh(3 * dq[:, 3]),
        0.08 * np.sin(q[:, 2]), 0.05 * np.cos(q[:, 0] * q[:, 3]), 0.06 * np.tanh(2 * dq[:, 0]),
    ])
    wrench = wrench + residual + rng.normal(0.0, [0.05] * 3 + [0.005] * 3, size=wrench.shape)
    t0 = 1_700_000_000 * 10**9
    with BagWriter(path) as bag:
        for k in range(n):
            stamp = t0 + round(k * 1e9 / hz)
            bag.write_joint_state("/joint_states", JointStateData(stamp, JOINTS, q[k], dq[k], np.zeros(4)))
            bag.write_wrench("/wrench", WrenchData(stamp, "r_arm_ft_sensor", wrench[k, :3], wrench[k, 3:]))
    return n


def _percentiles(values: list[float] | np.ndarray) -> dict[str, float]:
    arr = np.asarray(values, dtype=float)
    if arr.size == 0:
        return {"p50": float("nan"), "p90": float("nan"), "p99": float("nan"), "max": float("nan"),
                "mean": float("nan")}
    return {"p50": float(np.percentile(arr, 50)), "p90": float(np.percentile(arr, 90)),
            "p99": float(np.percentile(arr, 99)), "max": float(arr.max()), "mean": float(arr.mean())}


def run(seconds: float, hz: float, features: int, tmp: Path) -> dict:
    """Generate the bag, run the node, replay, measure; return the results."""
    sys.path.insert(0, str(REPO / "test"))
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import WrenchStamped
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from semiparam_ros.ros.bag_player import BagPlayer, load_raw

    load_before = os.getloadavg()[0]  # other processes competing for the 2 cores
    bag = tmp / "bag_1khz"
    t_gen = time.perf_counter()
    n_pairs = make_bag(bag, seconds=seconds, hz=hz)
    t_gen = time.perf_counter() - t_gen
    messages = load_raw(bag, ["/joint_states", "/wrench"])

    domain = 1 + (os.getpid() * 17) % 100
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(tmp / "ros_log"), PYTHONUNBUFFERED="1")
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR")})
    log = open(tmp / "node.log", "w")
    cmd = [sys.executable, "-m", "semiparam_ros.ros.estimator_node", "--ros-args",
           "--params-file", str(CONFIG), "-p", f"nonparametric.n_features:={features}",
           "-p", "diagnostics.period:=0.5"]
    node_proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, cwd=REPO)
    ps = psutil.Process(node_proc.pid)

    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = Node("bench_client", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    predictions: list[tuple[int, float]] = []
    diagnostics: list[tuple[float, dict[str, str]]] = []
    lock = threading.Lock()

    def on_prediction(msg: WrenchStamped) -> None:
        now = time.perf_counter()
        with lock:
            predictions.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, now))

    def on_diag(msg: DiagnosticArray) -> None:
        with lock:
            diagnostics.append((time.perf_counter(), {kv.key: kv.value for kv in msg.status[0].values}))

    qos = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(WrenchStamped, "/estimator/predicted_wrench", on_prediction, qos)
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    player = BagPlayer(node, messages)
    try:
        t_start = time.perf_counter()
        ok = player.wait_for_subscribers(timeout=60.0)
        while ok and node.count_publishers("/estimator/predicted_wrench") == 0:
            time.sleep(0.01)
        startup_s = time.perf_counter() - t_start
        if not ok:
            raise RuntimeError("the node did not subscribe within 60 s:\n" + (tmp / "node.log").read_text())
        time.sleep(1.0)  # let discovery settle in both directions
        with lock:
            diag_before = diagnostics[-1][1] if diagnostics else {}
        cpu_before = ps.cpu_times()
        wall_before = time.perf_counter()
        report = player.play(hz=hz)
        # wait until the node has drained its queue (predictions stop arriving)
        last = -1
        while True:
            time.sleep(0.3)
            with lock:
                count = len(predictions)
            if count == last:
                break
            last = count
        cpu_after = ps.cpu_times()
        wall_after = time.perf_counter()
        time.sleep(1.2)  # one more diagnostics period
        with lock:
            diag_after = diagnostics[-1][1] if diagnostics else {}
            diag_during = [d for (t, d) in diagnostics if wall_before < t <= wall_after]
            preds = list(predictions)
    finally:
        node_proc.send_signal(signal.SIGINT)
        try:
            node_proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            node_proc.kill()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        log.close()

    # wrench publish time by stamp (player publish order = bag order; wrench messages only)
    wrench_times: dict[int, float] = {}
    from rclpy.serialization import deserialize_message

    for msg, t_pub in zip(messages, report.publish_times, strict=True):
        if msg.topic == "/wrench":
            w = deserialize_message(msg.data, WrenchStamped)
            wrench_times[w.header.stamp.sec * 10**9 + w.header.stamp.nanosec] = t_pub
    latency_ms = [1e3 * (t_recv - wrench_times[s]) for s, t_recv in preds if s in wrench_times]
    cpu_s = (cpu_after.user - cpu_before.user) + (cpu_after.system - cpu_before.system)
    wall_s = wall_after - wall_before
    learned = int(diag_after.get("samples_learned", "0")) - int(diag_before.get("samples_learned", "0"))

    def during(key: str) -> list[float]:
        out = []
        for d in diag_during:
            try:
                value = float(d[key])
            except (KeyError, ValueError):
                continue
            if np.isfinite(value):
                out.append(value)
        return out

    if os.environ.get("BENCH_TRACE"):
        for d in diag_during:
            print({k: d.get(k) for k in ("queue_length", "pipeline_latency_mean_ms", "input_rate_hz",
                                         "learning_cpu_percent", "processed_in_period")})
    return {
        "config": {"seconds": seconds, "hz": hz, "n_features": features, "pairs_sent": n_pairs,
                   "messages_sent": report.published, "bag_generation_s": round(t_gen, 2)},
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "processor": platform.processor() or platform.machine(),
                    "load_average_1min_before": load_before, "load_average_1min_after": os.getloadavg()[0]},
        "startup_s": round(startup_s, 2),
        "playback_s": report.wall_s,
        "player_max_lag_ms": 1e3 * report.late_s,
        "samples_learned": learned,
        "predictions_received": len(preds),
        "learned_fraction": learned / n_pairs if n_pairs else float("nan"),
        "learning_rate_hz": learned / report.wall_s if report.wall_s > 0 else float("nan"),
        "input_rate_hz_diag_median": float(np.median(during("input_rate_hz"))) if during("input_rate_hz")
        else float("nan"),
        "latency_publish_to_prediction_ms": _percentiles(latency_ms),
        "node_pipeline_latency_ms": {"mean_of_periods": float(np.mean(during("pipeline_latency_mean_ms")))
                                     if during("pipeline_latency_mean_ms") else float("nan"),
                                     "max": max(during("pipeline_latency_max_ms"), default=float("nan"))},
        "core_step_ms": {"mean_of_periods": float(np.mean(during("update_latency_mean_ms")))
                         if during("update_latency_mean_ms") else float("nan"),
                         "max": max(during("update_latency_max_ms"), default=float("nan"))},
        "acceleration_delay_ms": float(diag_after.get("acceleration_delay_ms", "nan")),
        "node_cpu_percent": 100.0 * cpu_s / wall_s if wall_s > 0 else float("nan"),
        "learning_cpu_percent_median": float(np.median(during("learning_cpu_percent")))
        if during("learning_cpu_percent") else float("nan"),
        "queue_drops": int(diag_after.get("queue_drops", "0")),
        "drops_total": int(diag_after.get("drops_total", "0")),
        "drops": {k: v for k, v in diag_after.items() if k.startswith("drops.")},
        "rmse_force_N_final": float(diag_after.get("rmse_force_N", "nan")),
        "rmse_parametric_force_N_final": float(diag_after.get("rmse_parametric_force_N", "nan")),
    }


def table(res: dict) -> str:
    lat = res["latency_publish_to_prediction_ms"]
    rows = [
        ("pairs sent (joint_states + wrench)",
         f"{res['config']['pairs_sent']} at {res['config']['hz']:.0f} Hz"),
        ("D (random features)", res["config"]["n_features"]),
        ("samples learned", f"{res['samples_learned']} ({100 * res['learned_fraction']:.1f} %)"),
        ("achieved learning rate", f"{res['learning_rate_hz']:.0f} Hz"),
        ("latency wrench publish → prediction received p50 / p90 / p99 / max",
         f"{lat['p50']:.2f} / {lat['p90']:.2f} / {lat['p99']:.2f} / {lat['max']:.2f} ms"),
        ("  of which acceleration centring delay", f"{res['acceleration_delay_ms']:.1f} ms"),
        ("node: message received → prediction published (mean, max)",
         f"{res['node_pipeline_latency_ms']['mean_of_periods']:.3f} ms, "
         f"{res['node_pipeline_latency_ms']['max']:.2f} ms"),
        ("core step predict + learn (mean, max)",
         f"{res['core_step_ms']['mean_of_periods']:.3f} ms, {res['core_step_ms']['max']:.2f} ms"),
        ("node CPU (100 % = one core)", f"{res['node_cpu_percent']:.0f} %"),
        ("  of which running the estimator (median over periods)",
         f"{res['learning_cpu_percent_median']:.0f} %"),
        ("machine load average (1 min) before / after",
         "{:.1f} / {:.1f}".format(res["machine"]["load_average_1min_before"],
                                  res["machine"]["load_average_1min_after"])),
        ("queue drops / all drops", f"{res['queue_drops']} / {res['drops_total']}"),
        ("player max lag behind schedule", f"{res['player_max_lag_ms']:.1f} ms"),
    ]
    lines = ["| quantity | value |", "|---|---|"] + [f"| {k} | {v} |" for k, v in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 s of data instead of 20 s")
    parser.add_argument("--seconds", type=float, default=None)
    parser.add_argument("--hz", type=float, default=1000.0)
    parser.add_argument("--features", type=int, default=500)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    seconds = args.seconds if args.seconds is not None else (3.0 if args.quick else 20.0)
    with tempfile.TemporaryDirectory(prefix="bench_node_") as tmp:
        res = run(seconds, args.hz, args.features, Path(tmp))
    res["quick"] = bool(args.quick)
    print(table(res))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(res, indent=2, sort_keys=True) + "\n")
    print(f"\nwritten {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
