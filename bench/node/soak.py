"""Soak benchmark: the node fed 1 kHz joint-state/wrench pairs for an hour; RSS and latency over time.

Starts the node as a separate process (``config/icub_right_arm.yaml``, default parameters: D = 500,
``overload.max_delay`` 1 ms) and publishes, from this process, a periodic synthetic stream (the motion
and wrench of ``bench/node/bench_node.py``'s bag, whose frequencies repeat every 60 s, with stamps that keep
increasing) at ``--hz`` for ``--seconds``. Every ``--window`` seconds it records: the node's RSS and CPU
(psutil), the latency of each prediction (pair published → prediction received, by stamp: includes the
acceleration estimator's centring delay), predictions received, and the node's diagnostics (samples
learned, learning skipped, drops, queue length). Prints a table and writes ``bench/results/soak.json``.

Usage::

    .venv/bin/python bench/node/soak.py [--seconds 3600] [--hz 1000] [--window 60] [--output PATH]
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

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "config" / "icub_right_arm.yaml"
RESULTS = REPO / "bench" / "results" / "soak.json"
JOINTS = ("r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow")
PERIOD_S = 60.0  # the stream repeats (every frequency is a multiple of 1/60 Hz)


def make_period(hz: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One 60 s period of (q rad, q̇ rad/s, wrench N and N·m) sampled at ``hz`` (bench_node's motion)."""
    from semiparam_ros.core.config import load_config
    from semiparam_ros.core.estimator.build import build_regressor

    regressor = build_regressor(load_config(CONFIG))
    rng = np.random.default_rng(seed)
    t = np.arange(round(PERIOD_S * hz)) / hz
    centre = np.array([-0.5, 0.5, 0.2, 0.9])
    amp = np.array([[0.35, 0.1], [0.25, 0.08], [0.3, 0.1], [0.4, 0.1]])
    freq = 2 * np.pi * np.array([[0.25, 0.9], [0.3, 1.1], [0.2, 0.7], [0.35, 1.3]])
    p0, p1 = freq[:, 0] * t[:, None], freq[:, 1] * t[:, None]
    q = centre + amp[:, 0] * np.sin(p0) + amp[:, 1] * np.sin(p1)
    dq = amp[:, 0] * freq[:, 0] * np.cos(p0) + amp[:, 1] * freq[:, 1] * np.cos(p1)
    ddq = -amp[:, 0] * freq[:, 0] ** 2 * np.sin(p0) - amp[:, 1] * freq[:, 1] ** 2 * np.sin(p1)
    wrench = regressor.wrench(q, dq, ddq)
    wrench = wrench + np.column_stack([
        0.8 * np.sin(q[:, 0] + q[:, 3]), 0.5 * np.cos(2 * q[:, 1]), 0.6 * np.tanh(3 * dq[:, 3]),
        0.08 * np.sin(q[:, 2]), 0.05 * np.cos(q[:, 0] * q[:, 3]), 0.06 * np.tanh(2 * dq[:, 0])])
    wrench = wrench + rng.normal(0.0, [0.05] * 3 + [0.005] * 3, size=wrench.shape)
    return q, dq, wrench


def _percentiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {"p50": float("nan"), "p99": float("nan"), "max": float("nan")}
    arr = np.asarray(values)
    return {"p50": float(np.percentile(arr, 50)), "p99": float(np.percentile(arr, 99)),
            "max": float(arr.max())}


def run(seconds: float, hz: float, window_s: float) -> dict:
    """Run the soak; return the per-window records and a summary."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import WrenchStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from ros_harness import client, private_domain
    from sensor_msgs.msg import JointState

    q, dq, wrench = make_period(hz)
    n_period = q.shape[0]
    tmp = Path(tempfile.mkdtemp(prefix="soak_"))
    domain, env = private_domain(tmp, 19)
    log = open(tmp / "node.log", "w")
    node_proc = subprocess.Popen(
        [sys.executable, "-m", "semiparam_ros.ros.main", "--ros-args", "--params-file", str(CONFIG),
         "-p", "checkpoint.path:=" + str(tmp / "soak.npz"), "-p", "checkpoint.load_on_start:=false"],
        env=env, stdout=log, stderr=subprocess.STDOUT, cwd=REPO)
    ps = psutil.Process(node_proc.pid)
    context, node, executor = client(domain, "soak_client")
    lock = threading.Lock()
    received: list[tuple[int, float]] = []
    diag: dict[str, str] = {}

    def on_prediction(msg: WrenchStamped) -> None:
        now = time.perf_counter()
        with lock:
            received.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, now))

    def on_diag(msg: DiagnosticArray) -> None:
        with lock:
            diag.clear()
            diag.update({kv.key: kv.value for kv in msg.status[0].values})

    node.create_subscription(WrenchStamped, "/estimator/predicted_wrench", on_prediction,
                             QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE))
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    pub_js = node.create_publisher(JointState, "/joint_states", qos_profile_sensor_data)
    pub_w = node.create_publisher(WrenchStamped, "/wrench", qos_profile_sensor_data)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    records: list[dict] = []
    try:
        deadline = time.monotonic() + 120.0
        while (pub_js.get_subscription_count() == 0
               or node.count_publishers("/estimator/predicted_wrench") == 0):
            if time.monotonic() > deadline or node_proc.poll() is not None:
                raise RuntimeError("the node did not come up:\n" + (tmp / "node.log").read_text())
            time.sleep(0.05)
        time.sleep(1.0)
        js, w = JointState(), WrenchStamped()
        js.name = list(JOINTS)
        js.effort = [0.0] * 4
        w.header.frame_id = "r_arm_ft_sensor"
        sent: dict[int, float] = {}
        t0_ns = time.time_ns()
        start = time.perf_counter()
        cpu_before = ps.cpu_times()
        next_window = start + window_s
        k = 0
        n_total = round(seconds * hz)
        while k < n_total:
            target = start + k / hz
            now = time.perf_counter()
            if target > now:
                time.sleep(max(0.0, target - now - 2e-4))
                while time.perf_counter() < target:
                    pass
            i = k % n_period
            stamp = t0_ns + round(k * 1e9 / hz)
            sec, nsec = divmod(stamp, 10**9)
            js.header.stamp.sec, js.header.stamp.nanosec = sec, nsec
            js.position = q[i].tolist()
            js.velocity = dq[i].tolist()
            w.header.stamp = js.header.stamp
            f, tq = wrench[i, :3], wrench[i, 3:]
            w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = float(f[0]), float(f[1]), float(f[2])
            w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = float(tq[0]), float(tq[1]), float(tq[2])
            t_pub = time.perf_counter()
            pub_js.publish(js)
            pub_w.publish(w)
            sent[stamp] = t_pub
            k += 1
            if t_pub >= next_window or k == n_total:
                time.sleep(0.05)  # the last predictions of the window arrive
                with lock:
                    got, received[:] = list(received), []
                    d = dict(diag)
                latency = [1e3 * (t - sent.pop(s)) for s, t in got if s in sent]
                for s in [s for s in sent if s < stamp - 10**9]:
                    del sent[s]  # never predicted (dropped or lost): forget after 1 s
                cpu = ps.cpu_times()
                rec = {
                    "t_s": round(t_pub - start, 1),
                    "pairs_sent": k,
                    "rss_mb": ps.memory_info().rss / 2**20,
                    "node_cpu_percent": 100.0 * ((cpu.user - cpu_before.user)
                                                 + (cpu.system - cpu_before.system)) / window_s,
                    "predictions": len(latency),
                    "latency_ms": _percentiles(latency),
                    "node_p99_ms": float(d.get("pipeline_latency_p99_ms", "nan")),
                    "samples_learned": int(d.get("samples_learned", "0")),
                    "learning_skipped": int(d.get("learning_skipped", "0")),
                    "drops_total": int(d.get("drops_total", "0")),
                    "queue_length": int(d.get("queue_length", "0")),
                    "load_average_1min": os.getloadavg()[0],
                }
                cpu_before = cpu
                records.append(rec)
                print(f"{rec['t_s']:7.0f} s  RSS {rec['rss_mb']:6.1f} MB  "
                      f"CPU {rec['node_cpu_percent']:3.0f} %  "
                      f"latency p50/p99/max {rec['latency_ms']['p50']:.2f}/{rec['latency_ms']['p99']:.2f}/"
                      f"{rec['latency_ms']['max']:.1f} ms  node p99 {rec['node_p99_ms']:.2f} ms  "
                      f"learned {rec['samples_learned']}  skipped {rec['learning_skipped']}  "
                      f"drops {rec['drops_total']}", flush=True)
                next_window += window_s
        alive = node_proc.poll() is None
    finally:
        node_proc.send_signal(signal.SIGTERM)
        try:
            rc = node_proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            node_proc.kill()
            rc = None
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        log.close()
    rss = [r["rss_mb"] for r in records]
    p99 = [r["latency_ms"]["p99"] for r in records]
    half = max(1, len(records) // 2)
    return {
        "config": {"seconds": seconds, "hz": hz, "window_s": window_s, "node_config": str(CONFIG.name),
                   "defaults": "D = 500, overload.max_delay 1 ms"},
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "processor": platform.processor() or platform.machine()},
        "summary": {
            "alive_at_end": alive, "exit_code_on_sigterm": rc,
            "checkpoint_written": (tmp / "soak.npz").exists(),
            "rss_mb_first_window": rss[0] if rss else None, "rss_mb_last_window": rss[-1] if rss else None,
            "rss_mb_max": max(rss, default=None),
            "rss_growth_second_half_mb": (rss[-1] - rss[half - 1]) if rss else None,
            "latency_p99_ms_median_of_windows": float(np.median(p99)) if p99 else None,
            "latency_p99_ms_max_of_windows": max(p99, default=None),
            "predictions": sum(r["predictions"] for r in records),
            "pairs_sent": records[-1]["pairs_sent"] if records else 0,
            "samples_learned": records[-1]["samples_learned"] if records else 0,
            "learning_skipped": records[-1]["learning_skipped"] if records else 0,
            "drops_total": records[-1]["drops_total"] if records else 0,
        },
        "windows": records,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=3600.0)
    parser.add_argument("--hz", type=float, default=1000.0)
    parser.add_argument("--window", type=float, default=60.0, help="seconds per recorded window")
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    res = run(args.seconds, args.hz, args.window)
    print(json.dumps(res["summary"], indent=2))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(res, indent=2) + "\n")
    print(f"written {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
