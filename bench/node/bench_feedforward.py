"""Benchmark: latency desired state → feed-forward published, with the node learning at 1 kHz.

Starts the node (``python -m semiparam_ros.ros.main`` with ``config/panda.yaml``: 7 joints,
joint torques, D = 500, the defaults) as a separate process, warm-started from a checkpoint learned on a
simulated Panda recording (``--train-seconds``), so that it answers with a ready model (no not-ready
fallback), then streams over Fast DDS on loopback, from this process:
``/joint_states`` at ``--hz`` (a smooth motion whose efforts are the URDF's RNEA torques plus noise, so the
node learns every sample) and ``/estimator/desired_state`` (``trajectory_msgs/JointTrajectory``, one
point, stamped with the wall clock at publish) at the same rate, half a period later. Two latencies per
desired state: the round trip, publish call → receipt of ``/estimator/feedforward`` carrying its stamp
(this process's clock: the transport both ways and this client's own scheduling included), and the node's
own measure, stamp → feed-forward published (``feedforward.age_*`` of its diagnostics: transport in, the
wait behind learning, the prediction, the publish), and the share of the joint states learned while it
answers. Runs learning on and off side by side (``--repeats`` pairs, alternating), then the floor: a bare
rclpy node answering each desired state at once without a model (``echo_node.py``, unless ``--no-floor``).
The motion is computed before streaming, so the client only publishes; the CPU of the node's process
tree and of the client are reported. Prints a table and writes ``bench/results/bench_feedforward.json``.
Targets: ≥ 99 % answered within 2 ms and node-side p99 < 0.5 ms (or learning on within 1.2× of off),
≥ 95 % of the samples learned while serving.

    PYTHONPATH=$PWD .venv/bin/python bench/node/bench_feedforward.py [--seconds 20] [--hz 1000] [--repeats 2]
        [--set NAME=VALUE] [--variant NAME=VALUE[,NAME=VALUE]] [--compare-with DIR]
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
CONFIG = REPO / "config" / "panda.yaml"
RESULTS = REPO / "bench" / "results" / "bench_feedforward.json"


def _percentiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {"n": 0}
    a = np.asarray(values)
    return {"n": int(a.size), "p50": float(np.percentile(a, 50)), "p90": float(np.percentile(a, 90)),
            "p99": float(np.percentile(a, 99)), "p999": float(np.percentile(a, 99.9)), "max": float(a.max())}


#: Who answers the desired states: the estimator node, or a bare rclpy node that answers at once (the floor).
DESIGNS = {"node": "estimator", "echo": "bare rclpy echo (floor)"}


def _cpu(processes: list) -> float:
    """CPU time [s] (user + system) of these processes."""
    total = 0.0
    for process in processes:
        try:
            times = process.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += times.user + times.system
    return total


def train_checkpoint(tmp: Path, seconds: float) -> Path:
    """Learn a simulated Panda recording with the node's defaults (D = 500) into a checkpoint."""
    from semiparam_ros.core.config import load_config
    from semiparam_ros.serving.bag_learning import learn_bags
    from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
    from semiparam_ros.sim.writer import write_recording

    rec = simulate_arm(ArmScenarioConfig(name="panda_bench_ff", robot="panda", duration=seconds, rate=1000.0,
                                         seed=5))
    bag = write_recording(rec, tmp / "panda_bench_ff")
    learn_bags([bag], load_config(CONFIG), checkpoint=tmp / "trained.npz")
    return tmp / "trained.npz"


def _revision(checkout: Path) -> str:
    """The short commit of a checkout (its folder name when it is no git checkout)."""
    try:
        return subprocess.run(["git", "-C", str(checkout), "rev-parse", "--short", "HEAD"], check=True,
                              capture_output=True, text=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return checkout.name


def run(seconds: float, hz: float, learning: bool, tmp: Path, consistent: bool = True,
        checkpoint: Path | None = None, design: str = "node", overrides: tuple[str, ...] = (),
        checkout: Path = REPO) -> dict:
    """Start the node, stream joint states and desired states, return the measured latencies."""
    import rclpy
    from builtin_interfaces.msg import Duration
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from ros_harness import client, private_domain
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from semiparam_ros.core.config import load_config
    from semiparam_ros.core.estimator.build import build_regressor

    config = load_config(CONFIG)
    joints = list(config["robot.joints"])
    regressor = build_regressor(config)
    cad = regressor.urdf_parameters()
    n = len(joints)

    domain, env = private_domain(tmp, 13, 7 if learning else 0)
    log_path = tmp / f"node_{'learning' if learning else 'frozen'}_{int(consistent)}_{design}.log"
    log = open(log_path, "w")
    cmd = [sys.executable, "-m", "semiparam_ros.ros.main", "--ros-args", "--params-file",
           str(CONFIG), "-p", f"learning_enabled:={'true' if learning else 'false'}",
           "-p", "diagnostics.period:=0.5",
           "-p", f"parametric.consistent:={'true' if consistent else 'false'}"]
    for item in overrides:  # --set name=value: a node parameter
        name, _, value = item.partition("=")
        cmd += ["-p", f"{name}:={value}"]
    if checkpoint is not None:  # a copy: the node writes its final checkpoint there
        copy = tmp / f"warm_{'learning' if learning else 'frozen'}_{time.monotonic_ns()}.npz"
        copy.write_bytes(checkpoint.read_bytes())
        cmd += ["-p", f"checkpoint.path:={copy}", "-p", "checkpoint.period:=0.0"]
    if design == "echo":  # the floor: a bare rclpy node answering at once, no model
        cmd = [sys.executable, str(REPO / "bench" / "node" / "echo_node.py")]
    if checkout != REPO:  # the node of another checkout (python -m puts its folder first on the path)
        env = dict(env, PYTHONPATH=str(checkout))
    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, cwd=checkout)
    ps = psutil.Process(proc.pid)

    context, node, executor = client(domain, "bench_feedforward")
    received: dict[int, float] = {}
    diagnostics: list[dict[str, str]] = []
    lock = threading.Lock()

    def on_ff(msg: JointState) -> None:
        now = time.perf_counter()
        with lock:
            received[msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec] = now

    def on_diag(msg: DiagnosticArray) -> None:
        with lock:
            diagnostics.append({kv.key: kv.value for kv in msg.status[0].values})

    node.create_subscription(JointState, "/estimator/feedforward", on_ff,
                             QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    js_pub = node.create_publisher(JointState, "/joint_states",
                                   QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
    ds_pub = node.create_publisher(JointTrajectory, "/estimator/desired_state", 10)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    sent: dict[int, float] = {}
    try:
        deadline = time.monotonic() + 60.0
        while (node.count_subscribers("/joint_states") == 0 or node.count_subscribers(
                "/estimator/desired_state") == 0 or node.count_publishers("/estimator/feedforward") == 0):
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError("the node did not come up:\n" + log_path.read_text())
            time.sleep(0.05)
        time.sleep(1.0)
        rng = np.random.default_rng(0)
        period = 1.0 / hz
        count = int(seconds * hz)
        base_ns = 1_000_000_000_000
        w = 2 * np.pi * np.array([0.11, 0.13, 0.17, 0.19, 0.23, 0.29, 0.31])
        motion = []  # computed before streaming: the client only publishes, as a controller would
        for k in range(count):
            t = k * period
            q, dq, ddq = 0.5 * np.sin(w * t), 0.5 * w * np.cos(w * t), -0.5 * w * w * np.sin(w * t)
            q[3] -= 1.5
            motion.append((q, dq, ddq, regressor.regressor(q, dq, ddq) @ cad + 0.05 * rng.standard_normal(n)))
        family = [ps, *ps.children(recursive=True)]  # the answer process and the projection worker too
        me = psutil.Process()
        cpu0, mine0, wall0 = _cpu(family), _cpu([me]), time.perf_counter()
        start = time.perf_counter()
        for k, (q, dq, ddq, tau) in enumerate(motion):
            t = k * period
            stamp = base_ns + k * 1_000_000
            js = JointState()
            js.header.stamp.sec, js.header.stamp.nanosec = divmod(stamp, 10**9)
            js.name, js.position, js.velocity, js.effort = joints, q.tolist(), dq.tolist(), tau.tolist()
            target = start + t
            while (now := time.perf_counter()) < target:
                time.sleep(min(target - now, 2e-4))
            js_pub.publish(js)
            target = start + t + 0.5 * period
            ds = JointTrajectory()
            ds.joint_names = joints
            point = JointTrajectoryPoint(positions=q.tolist(), velocities=dq.tolist(),
                                         accelerations=ddq.tolist(), time_from_start=Duration())
            ds.points = [point]
            while (now := time.perf_counter()) < target:
                time.sleep(min(target - now, 2e-4))
            ds_stamp = time.time_ns()  # a controller stamps with its clock: the node reports the age
            ds.header.stamp.sec, ds.header.stamp.nanosec = divmod(ds_stamp, 10**9)
            sent[ds_stamp] = time.perf_counter()
            ds_pub.publish(ds)
        play_s = time.perf_counter() - start
        time.sleep(1.5)
        cpu1, mine1, wall1 = _cpu(family), _cpu([me]), time.perf_counter()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        log.close()
    with lock:
        got = dict(received)
        diag = diagnostics[-1] if diagnostics else {}
        all_diag = list(diagnostics)
    latency = [1e3 * (got[s] - t) for s, t in sent.items() if s in got]
    within_2ms = sum(1 for s, t in sent.items() if s in got and got[s] - t <= 2e-3) / max(len(sent), 1)
    skip = int(0.1 * len(latency))  # the first 10 %: the node's caches and the residual's warm-up
    node_p99 = [float(d["feedforward.age_p99_ms"]) for d in all_diag[2:]
                if "feedforward.age_p99_ms" in d]
    node_p50 = [float(d["feedforward.age_p50_ms"]) for d in all_diag[2:]
                if "feedforward.age_p50_ms" in d]
    # the samples' own predictions: message received → prediction ready, p99 per period
    sample_p99 = [float(d["pipeline_latency_p99_ms"]) for d in all_diag[2:]
                  if d.get("pipeline_latency_p99_ms", "nan") not in ("nan", "")]
    cpu = cpu1 - cpu0
    learned_before = int(all_diag[0].get("samples_learned", "0")) if all_diag else 0
    warm = checkpoint is not None
    label = DESIGNS[design] if checkout == REPO else f"{DESIGNS[design]} at {_revision(checkout)}"
    if overrides and design == "node":
        label += " (" + ", ".join(overrides) + ")"
    return {"design": label, "learning": learning,
            "consistent": consistent, "hz": hz, "seconds": seconds, "play_s": play_s,
            "warm_start": warm, "desired_sent": len(sent), "feedforward_received": len(latency),
            "answered_within_2ms": within_2ms, "joint_states_sent": count,
            "learned_while_serving": (int(diag.get("samples_learned", "0")) - learned_before) / count
            if learning else None,
            "fallback_not_ready": int(diag.get("feedforward.fallback.not_ready", "0")),
            "latency_ms": _percentiles(latency[skip:]),
            "node_latency_ms": {"p50_median_of_periods": float(np.median(node_p50)) if node_p50 else None,
                                "p99_median_of_periods": float(np.median(node_p99)) if node_p99 else None,
                                "p99_max_of_periods": max(node_p99, default=None)},
            "sample_latency_p99_ms_median_of_periods": float(np.median(sample_p99)) if sample_p99 else None,
            "parameters": list(overrides),
            "node_cpu_percent": 100.0 * cpu / (wall1 - wall0),
            "client_cpu_percent": 100.0 * (mine1 - mine0) / (wall1 - wall0),
            "samples_learned": int(diag.get("samples_learned", "0")),
            "feedforward_diagnostics": {k: v for k, v in diag.items() if k.startswith("feedforward.")},
            "learning_diagnostics": {k: v for k, v in diag.items()
                                     if k.startswith(("learning_skipped", "not_learned", "gate", "drops."))},
            "load_average_1min": os.getloadavg()[0]}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--hz", type=float, default=1000.0)
    p.add_argument("--repeats", type=int, default=2, help="learning on/off pairs, alternating")
    p.add_argument("--train-seconds", type=float, default=30.0,
                   help="simulated Panda recording learned into the checkpoint the node warm-starts from")
    p.add_argument("--output", type=Path, default=RESULTS)
    p.add_argument("--compare-with", type=Path, default=None, metavar="DIR",
                   help="also run the node of another checkout (e.g. a git worktree of an older commit), "
                        "alternating with this one's, on the same checkpoint")
    p.add_argument("--variant", action="append", default=[], metavar="NAME=VALUE[,NAME=VALUE]",
                   help="also run this checkout's node learning with these parameters, in each repeat "
                        "(repeatable), e.g. overload.max_delay=0.0")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="a node parameter for the estimator's runs (repeatable), e.g. overload.max_delay=0.0")
    p.add_argument("--no-floor", dest="floor", action="store_false",
                   help="skip the floor: a bare rclpy node (bench/node/echo_node.py) answering each desired "
                        "state at once, no model, in the same run")
    args = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_ff_"))
    print(f"node logs in {tmp}")
    checkpoint = train_checkpoint(tmp, args.train_seconds)
    designs = ("node", "echo") if args.floor else ("node",)
    checkouts = (REPO,) if args.compare_with is None else (REPO, args.compare_with.resolve())
    base = tuple(args.set)
    runs = []
    for _ in range(args.repeats):
        for design in designs:
            for checkout in (checkouts if design == "node" else (REPO,)):
                for learning in ((False,) if design == "echo" else (True, False)):
                    runs.append(run(args.seconds, args.hz, learning, tmp, True, checkpoint, design, base,
                                    checkout))
            if design == "node":  # each --variant: this checkout's node learning, with its parameters
                for variant in args.variant:
                    runs.append(run(args.seconds, args.hz, True, tmp, True, checkpoint, design,
                                    (*base, *variant.split(",")), REPO))
    print("| answered by | node (warm start) | desired states | within 2 ms | "
          "round trip p50 / p99 / max [ms] | stamped → published p50 / p99 (median of periods) [ms] | "
          "learned while serving | samples: received → predicted p99 (median of periods) [ms] | "
          "not-ready fallbacks | node CPU | client CPU |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    def ms(value: float | None, digits: int = 2) -> str:
        return "–" if value is None else f"{value:.{digits}f}"

    for r in runs:
        lat, nl = r["latency_ms"], r["node_latency_ms"]
        learned = "–" if r["learned_while_serving"] is None else f"{100 * r['learned_while_serving']:.1f} %"
        mode = "learning" if r["learning"] else "not learning"
        print(f"| {r['design']} | {mode} at {r['hz']:g} Hz | {r['desired_sent']} | "
              f"{100 * r['answered_within_2ms']:.1f} % | "
              f"{ms(lat.get('p50'))} / {ms(lat.get('p99'))} / {ms(lat.get('max'), 1)} | "
              f"{ms(nl['p50_median_of_periods'])} / {ms(nl['p99_median_of_periods'])} | {learned} | "
              f"{ms(r['sample_latency_p99_ms_median_of_periods'])} | "
              f"{r['fallback_not_ready']} | {r['node_cpu_percent']:.0f} % | "
              f"{r['client_cpu_percent']:.0f} % |")
    command = " ".join(["PYTHONPATH=$PWD .venv/bin/python bench/node/bench_feedforward.py", *sys.argv[1:]])
    out = {"command": command,
           "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                       "processor": platform.processor() or platform.machine()},
           "target": ">= 99 % answered within 2 ms and node-side p99 < 0.5 ms (or learning on within 1.2x of "
                     "off), >= 95 % of the samples learned while serving",
           "parameters": args.set, "runs": runs}
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(out, indent=2))
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
