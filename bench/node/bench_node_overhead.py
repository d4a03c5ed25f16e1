"""Benchmark: the node's own CPU per paired sample, outside the estimator, in-process (no executor, no DDS).

What a shared machine cannot spoil as easily as bench_node.py's wall-clock figures: the CPU time (thread
time) per joint-state/wrench pair of

* ``core``: ``OnlineEstimator.process`` on already converted messages;
* ``node``: what the node's subscription callbacks do with the serialised messages the executor hands
  them — convert, queue, run the estimator, publish the outputs (one subscriber on
  ``~/predicted_wrench``, as in bench_node.py), record the statistics — without the executor itself.

``node − core`` is the node's own overhead per pair. Both run on the same 1 kHz synthetic bag as
bench_node.py (``make_bag``), alternating ``--repeats`` times on fresh nodes; medians are printed. With
``--compare-with DIR`` the same measurement runs, alternating, in a subprocess importing another checkout
(whose node may take message objects rather than bytes: then the deserialisation the executor would do is
included in its ``node`` time, as it is in its executor).

Usage::

    PYTHONPATH=$PWD .venv/bin/python bench/node/bench_node_overhead.py [--features 500] [--seconds 3]
        [--repeats 3] [--compare-with DIR] [--output FILE.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "config" / "icub_right_arm.yaml"


def measure(features: int, seconds: float, repeats: int) -> dict[str, list[float]]:
    """Alternate core-only and node-path runs on fresh nodes; return µs of thread CPU per pair."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.parameter import Parameter
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    sys.path.insert(0, str(REPO / "bench"))
    from bench_node import make_bag

    from semiparam_ros.ros import conversions
    from semiparam_ros.ros.bag_player import load_raw
    from semiparam_ros.ros.estimator_node import EstimatorNode

    raw_input = hasattr(conversions, "joint_state_from_cdr")  # this branch: the callbacks get bytes
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bag"
        n_pairs = make_bag(bag, seconds=seconds)
        messages = [("joint_states" if m.topic == "/joint_states" else "wrench", bytes(m.data))
                    for m in load_raw(bag, ["/joint_states", "/wrench"])]
    types = {"joint_states": JointState, "wrench": WrenchStamped}
    convert = {"joint_states": conversions.joint_state_from_msg, "wrench": conversions.wrench_from_msg}
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=1 + os.getpid() % 100)
    out: dict[str, list[float]] = {"core": [], "node": []}
    try:
        for _ in range(repeats):
            for mode in ("core", "node"):
                overrides = [Parameter("checkpoint.path", value=""),
                             Parameter("nonparametric.n_features", value=features)]
                node = EstimatorNode(context=context, cli_args=["--ros-args", "--params-file", str(CONFIG)],
                                     parameter_overrides=overrides)
                sub = node.create_subscription(WrenchStamped, "~/predicted_wrench", lambda _m: None, 100)
                try:
                    if mode == "core":
                        est = node.estimator
                        data = [(k, convert[k](deserialize_message(raw, types[k]))) for k, raw in messages]
                        t0 = time.thread_time()
                        for _, item in data:
                            est.process(item)
                    else:
                        t0 = time.thread_time()
                        # this checkout's node takes input through node.inputs; older ones through _intake
                        intake = node.inputs.intake if hasattr(node, "inputs") else node._intake
                        for kind, raw in messages:
                            intake(kind, raw if raw_input else deserialize_message(raw, types[kind]))
                            node._process_queued()
                    out[mode].append(1e6 * (time.thread_time() - t0) / n_pairs)
                finally:
                    node.destroy_subscription(sub)
                    node.abort()
                    node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--features", type=int, default=500)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--compare-with", type=Path, default=None, metavar="DIR")
    parser.add_argument("--output", type=Path, default=None,
                        help="also save the medians and samples as JSON here")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)  # child mode
    args = parser.parse_args(argv)
    if args.json:
        print(json.dumps(measure(args.features, args.seconds, args.repeats)))
        return 0
    codes = ([args.compare_with.resolve()] if args.compare_with else []) + [REPO]
    results: dict[str, dict[str, list[float]]] = {str(c): {"core": [], "node": []} for c in codes}
    for _ in range(args.repeats):  # alternate the checkouts, one repeat each, so they share the load
        for code in codes:
            cmd = [sys.executable, str(Path(__file__).resolve()), "--json", "--features", str(args.features),
                   "--seconds", str(args.seconds), "--repeats", "1"]
            env = dict(os.environ, PYTHONPATH=str(code))
            line = subprocess.run(cmd, env=env, cwd=code, check=True, capture_output=True,
                                  text=True).stdout.strip().splitlines()[-1]
            for key, values in json.loads(line).items():
                results[str(code)][key] += values
    print(f"D = {args.features}, µs of CPU per pair (median of {args.repeats}; load average "
          f"{os.getloadavg()[0]:.1f})")
    print("| checkout | core | node | node − core |\n|---|---|---|---|")
    summary = {}
    for code, res in results.items():
        core, node = float(np.median(res["core"])), float(np.median(res["node"]))
        print(f"| {code} | {core:.0f} | {node:.0f} | {node - core:.0f} |")
        summary[code] = {"core_us": core, "node_us": node, "overhead_us": node - core, "samples": res}
    if args.output is not None:
        doc = {"features": args.features, "repeats": args.repeats, "load_average": os.getloadavg()[0],
               "checkouts": summary}
        args.output.write_text(json.dumps(doc, indent=1))
        print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
