"""Benchmark: can the estimator node keep up with 1 kHz paired input at D = 500 and 1000, per executor?

Generates a synthetic 1 kHz bag (joint states + wrenches with equal stamps every millisecond; the wrench is
the iCub right arm's rigid-body F/T wrench from the URDF plus a smooth non-rigid residual and noise),
then, for every executor × D in one run (side by side, same bag, same machine load), starts the node as a
separate process (``python -m semiparam_ros.ros.main --executor E`` with
``config/icub_right_arm.yaml``, default sensor-data QoS), replays the bag over Fast DDS on loopback at
1 kHz and measures:

* achieved learning rate (samples learned per second of playback, from the node's diagnostics) and the
  fraction of the sent pairs that were learned;
* latency percentiles: wrench published by the player → prediction received by the test process (this
  includes the Savitzky–Golay centring delay of ``window // 2`` joint states, 4 ms at 1 kHz), the node's
  own message-received → prediction-published latency (p99 per diagnostics period; the largest of them
  bounds the p99 of the whole run), and the core step time (predict + learn);
* CPU% of the node process (psutil; 100 % = one core) and queue drops.

Targets: at D = 1000 ≥ 99.9 % learned, node p99 < 2 ms, node CPU ≤ 80 %; at D = 500 CPU ≤ 50 %.
The load average of the machine is recorded before and after every run: on a shared machine, compare
the columns of one run, not runs of different days. Prints markdown tables and writes
``bench/results/bench_node.json``. ``--quick`` plays 3 s instead of 15 s (the full run takes ≈ 3 min).
Usage::

    .venv/bin/python bench/node/bench_node.py [--quick] [--seconds S] [--hz 1000] [--features 500 1000]
        [--executors events single_threaded] [--acceleration savgol kalman]
        [--save-every S] [--compare-with DIR]
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
    from semiparam_ros.core.estimator.build import build_regressor
    from semiparam_ros.core.stream.messages import JointStateData, WrenchData
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


TARGETS = {"learned_fraction_min": {"1000": 0.999}, "node_p99_ms_max": {"1000": 2.0},
           "node_cpu_percent_max": {"500": 50.0, "1000": 80.0}}


def run(messages: list, n_pairs: int, hz: float, features: int, executor: str, tmp: Path,
        save_every_s: float = 0.0, code: Path | None = None, acceleration: str = "savgol",
        max_delay_s: float | None = None, busy: bool = False) -> dict:
    """Run the node with ``executor`` and ``features``, replay the messages, measure; return the results.

    With ``save_every_s`` > 0 the client calls ``~/save`` (checkpoint in ``tmp``) that often during the
    playback, and the reply times are recorded. With ``code`` the node is imported from that checkout
    (``PYTHONPATH`` and working directory) instead of this one: a before/after comparison in one run.
    ``acceleration`` is the node's ``acceleration.method`` (``savgol``: centred, delayed by half its
    window; ``kalman``: causal, no delay). ``max_delay_s`` sets ``overload.max_delay`` (None: the
    default; 0: learn every sample however late, the node before graceful overload). ``busy``: a
    busy-looping process competes for the cores during the run (a saturated machine on purpose).
    """
    sys.path.insert(0, str(REPO / "test"))
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import WrenchStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from ros_harness import client, private_domain
    from std_srvs.srv import Trigger

    from semiparam_ros.ros.bag_player import BagPlayer

    load_before = os.getloadavg()[0]  # other processes competing for the 2 cores
    domain, env = private_domain(tmp, 17)
    log_path = tmp / f"node_{executor}_{features}.log"
    log = open(log_path, "w")
    cmd = [sys.executable, "-m", "semiparam_ros.ros.main", "--executor", executor, "--ros-args",
           "--params-file", str(CONFIG), "-p", f"nonparametric.n_features:={features}",
           "-p", "diagnostics.period:=0.5", "-p", f"acceleration.method:={acceleration}"]
    if max_delay_s is not None:
        cmd += ["-p", f"overload.max_delay:={max_delay_s}"]
    if save_every_s > 0:
        cmd += ["-p", f"checkpoint.path:={tmp / f'ckpt_{executor}_{features}.npz'}", "-p",
                "checkpoint.load_on_start:=false"]
    node_env = env if code is None else dict(env, PYTHONPATH=str(code))
    node_proc = subprocess.Popen(cmd, env=node_env, stdout=log, stderr=subprocess.STDOUT,
                                 cwd=REPO if code is None else code)
    ps = psutil.Process(node_proc.pid)
    burner = (subprocess.Popen([sys.executable, "-c", "while True: pass"]) if busy else None)

    context, node, client_executor = client(domain, "bench_client")
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
    spinner = threading.Thread(target=client_executor.spin, daemon=True)
    spinner.start()
    player = BagPlayer(node, messages)
    save_client = node.create_client(Trigger, "/estimator/save")
    save_times_ms: list[float] = []
    save_failures: list[str] = []
    playing = threading.Event()

    def saver() -> None:  # ~/save every save_every_s while the bag plays
        while True:
            time.sleep(save_every_s)
            if not playing.is_set():
                return
            t0 = time.perf_counter()
            future = save_client.call_async(Trigger.Request())
            while not future.done() and time.perf_counter() - t0 < 30.0:
                time.sleep(0.001)
            save_times_ms.append(1e3 * (time.perf_counter() - t0))
            if not (future.done() and future.result().success):
                save_failures.append(future.result().message if future.done() else "no reply in 30 s")

    try:
        t_start = time.perf_counter()
        ok = player.wait_for_subscribers(timeout=60.0)
        while ok and node.count_publishers("/estimator/predicted_wrench") == 0:
            time.sleep(0.01)
        startup_s = time.perf_counter() - t_start
        if not ok:
            raise RuntimeError("the node did not subscribe within 60 s:\n" + log_path.read_text())
        time.sleep(1.0)  # let discovery settle in both directions
        with lock:
            diag_before = diagnostics[-1][1] if diagnostics else {}
        cpu_before = ps.cpu_times()
        wall_before = time.perf_counter()
        if save_every_s > 0:
            save_client.wait_for_service(timeout_sec=10.0)
            threading.Thread(target=saver, daemon=True).start()
            playing.set()
        report = player.play(hz=hz)
        playing.clear()
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
        if burner is not None:
            burner.kill()
            burner.wait()
        node_proc.send_signal(signal.SIGINT)
        try:
            node_proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            node_proc.kill()
        client_executor.shutdown(timeout_sec=1.0)
        if os.environ.get("BENCH_KEEP_LOGS"):
            import shutil

            shutil.copy(log_path, Path(os.environ["BENCH_KEEP_LOGS"]) / log_path.name)
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
    skipped = int(diag_after.get("learning_skipped", "0")) - int(diag_before.get("learning_skipped", "0"))

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
    p99s = during("pipeline_latency_p99_ms")
    return {
        "config": {"hz": hz, "n_features": features, "executor": executor, "pairs_sent": n_pairs,
                   "acceleration": acceleration, "overload_max_delay_s": max_delay_s, "busy_core": busy,
                   "code": str(code) if code is not None else "this checkout",
                   "messages_sent": report.published},
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "processor": platform.processor() or platform.machine(),
                    "load_average_1min_before": load_before, "load_average_1min_after": os.getloadavg()[0]},
        "startup_s": round(startup_s, 2),
        "playback_s": report.wall_s,
        "player_max_lag_ms": 1e3 * report.late_s,
        "samples_learned": learned,
        "predictions_received": len(preds),
        "learning_skipped": skipped,
        "learned_fraction": learned / n_pairs if n_pairs else float("nan"),
        "learning_rate_hz": learned / report.wall_s if report.wall_s > 0 else float("nan"),
        "input_rate_hz_diag_median": float(np.median(during("input_rate_hz"))) if during("input_rate_hz")
        else float("nan"),
        "latency_publish_to_prediction_ms": _percentiles(latency_ms),
        "node_pipeline_latency_ms": {"mean_of_periods": float(np.mean(during("pipeline_latency_mean_ms")))
                                     if during("pipeline_latency_mean_ms") else float("nan"),
                                     "max": max(during("pipeline_latency_max_ms"), default=float("nan")),
                                     "p99_median_of_periods": float(np.median(p99s)) if p99s
                                     else float("nan"),
                                     "p99_max_of_periods": max(p99s, default=float("nan"))},
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
        "save_every_s": save_every_s,
        "save_reply_ms": _percentiles(save_times_ms) | {"n": len(save_times_ms)},
        "save_failures": save_failures,
    }


def _verdict(res: dict) -> str:
    """Which issue-15 targets this run meets ("–" where none applies to its D)."""
    d = str(res["config"]["n_features"])
    out = []
    if d in TARGETS["learned_fraction_min"]:
        out.append(f"learned {'✓' if res['learned_fraction'] >= TARGETS['learned_fraction_min'][d] else '✗'}")
    if d in TARGETS["node_p99_ms_max"]:
        ok = res["node_pipeline_latency_ms"]["p99_max_of_periods"] < TARGETS["node_p99_ms_max"][d]
        out.append(f"p99 {'✓' if ok else '✗'}")
    if d in TARGETS["node_cpu_percent_max"]:
        out.append(f"CPU {'✓' if res['node_cpu_percent'] <= TARGETS['node_cpu_percent_max'][d] else '✗'}")
    return ", ".join(out) or "–"


def table(runs: list[dict]) -> str:
    """One markdown table, one column per run (executor × D)."""
    def lat(r: dict) -> str:
        v = r["latency_publish_to_prediction_ms"]
        return f"{v['p50']:.2f} / {v['p99']:.2f} / {v['max']:.1f}"

    rows = [
        ("D (random features)", lambda r: r["config"]["n_features"]),
        ("executor", lambda r: r["config"]["executor"]),
        ("acceleration estimator", lambda r: r["config"].get("acceleration", "savgol")),
        ("overload.max_delay, ms (– = default)",
         lambda r: "–" if r["config"].get("overload_max_delay_s") is None
         else f"{1e3 * r['config']['overload_max_delay_s']:g}"),
        ("a busy-looping process on the machine", lambda r: "yes" if r["config"].get("busy_core") else "no"),
        ("code", lambda r: r["config"].get("code", "this checkout")),
        ("pairs sent at 1 kHz", lambda r: r["config"]["pairs_sent"]),
        ("samples learned", lambda r: f"{r['samples_learned']} ({100 * r['learned_fraction']:.2f} %)"),
        ("predicted without learning (late)", lambda r: r.get("learning_skipped", "–")),
        ("predictions received", lambda r: f"{r['predictions_received']}"),
        ("node CPU (100 % = one core)", lambda r: f"{r['node_cpu_percent']:.0f} %"),
        ("  of which the estimator (median of periods)",
         lambda r: f"{r['learning_cpu_percent_median']:.0f} %"),
        ("node received → published: mean / p99 (median, max of periods) / max, ms",
         lambda r: "{:.3f} / {:.2f}, {:.2f} / {:.1f}".format(
             r["node_pipeline_latency_ms"]["mean_of_periods"],
             r["node_pipeline_latency_ms"]["p99_median_of_periods"],
             r["node_pipeline_latency_ms"]["p99_max_of_periods"], r["node_pipeline_latency_ms"]["max"])),
        ("end to end (wrench publish → prediction received) p50 / p99 / max, ms", lat),
        ("  of which acceleration delay, ms", lambda r: f"{r['acceleration_delay_ms']:.1f}"),
        ("core step predict + learn, mean ms", lambda r: f"{r['core_step_ms']['mean_of_periods']:.3f}"),
        ("queue drops / all drops", lambda r: f"{r['queue_drops']} / {r['drops_total']}"),
        ("player max lag, ms", lambda r: f"{r['player_max_lag_ms']:.1f}"),
        ("~/save calls: n, reply p50 / max, ms", lambda r: "{} , {:.1f} / {:.1f}".format(
            r["save_reply_ms"]["n"], r["save_reply_ms"]["p50"], r["save_reply_ms"]["max"])
            if r.get("save_every_s") else "–"),
        ("load average (1 min) before / after", lambda r: "{:.1f} / {:.1f}".format(
            r["machine"]["load_average_1min_before"], r["machine"]["load_average_1min_after"])),
        ("issue-15 targets", _verdict),
    ]
    lines = ["| quantity | " + " | ".join(f"run {k + 1}" for k in range(len(runs))) + " |",
             "|---|" + "---|" * len(runs)]
    lines += [f"| {name} | " + " | ".join(str(f(r)) for r in runs) + " |" for name, f in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 s of data instead of 15 s")
    parser.add_argument("--seconds", type=float, default=None)
    parser.add_argument("--hz", type=float, default=1000.0)
    parser.add_argument("--features", type=int, nargs="+", default=[500, 1000])
    parser.add_argument("--executors", nargs="+", default=["events", "single_threaded"],
                        choices=["single_threaded", "events"])
    parser.add_argument("--acceleration", nargs="+", default=["savgol"], choices=["savgol", "kalman"],
                        help="the node's acceleration.method; each is run (default: savgol only)")
    parser.add_argument("--save-every", type=float, default=0.0, metavar="S",
                        help="call ~/save every S seconds during the playback (0: never)")
    parser.add_argument("--compare-with", type=Path, default=None, metavar="DIR",
                        help="also run the node of another checkout (e.g. `git worktree add /tmp/base "
                             "main`), before each run of this one")
    parser.add_argument("--max-delay", type=float, nargs="+", default=[None], metavar="S",
                        help="the node's overload.max_delay [s]; each is run side by side (0: learn every "
                             "sample however late; default: the node's default)")
    parser.add_argument("--busy", action="store_true",
                        help="a busy-looping process competes for the cores during every run")
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    seconds = args.seconds if args.seconds is not None else (3.0 if args.quick else 15.0)
    t0 = time.perf_counter()
    runs = []
    with tempfile.TemporaryDirectory(prefix="bench_node_") as tmp:
        sys.path.insert(0, str(REPO / "test"))
        from semiparam_ros.ros.bag_player import load_raw

        bag = Path(tmp) / "bag_1khz"
        n_pairs = make_bag(bag, seconds=seconds, hz=args.hz)
        messages = load_raw(bag, ["/joint_states", "/wrench"])
        for features in args.features:
            for executor in args.executors:  # the executors of one D back to back: same load
                for acceleration in args.acceleration:
                    for code in ([args.compare_with.resolve()] if args.compare_with else []) + [None]:
                        for max_delay in args.max_delay:
                            res = run(messages, n_pairs, args.hz, features, executor, Path(tmp),
                                      args.save_every, code, acceleration, max_delay, args.busy)
                            print(f"D = {features}, {executor}, {acceleration}, {res['config']['code']}, "
                                  f"max_delay {max_delay}: learned {100 * res['learned_fraction']:.2f} %, "
                                  f"CPU {res['node_cpu_percent']:.0f} %", flush=True)
                            runs.append(res)
    print()
    print(table(runs))
    result = {"benchmark": "bench_node", "quick": bool(args.quick), "seconds": seconds, "hz": args.hz,
              "targets": TARGETS, "wall_s": round(time.perf_counter() - t0, 1),
              "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                          "processor": platform.processor() or platform.machine(),
                          "platform": platform.platform(), "load_average_at_end": os.getloadavg()},
              "runs": runs}
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=2, sort_keys=True) + "\n")
    print(f"\nwritten {args.output} ({result['wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
