"""Taking N messages already queued on a subscription: one executor wait per message (public API) against
the node's ``InputStreams.drain`` loop of ``sub.handle.take_message`` (the call the executor itself makes).

Usage: ``PYTHONPATH=. .venv/bin/python bench/node/bench_drain.py [--n 500] [--repeats 7] [--json PATH]``.
Prints the median time per message of each way and their ratio, from the same run.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.VOLATILE)
NAMES = [f"joint_{i}" for i in range(16)]


def _fill(pub, n: int, received: list) -> None:
    """Publish n messages and wait until DDS holds them all for the subscription."""
    msg = JointState(name=NAMES, position=[0.1] * 16, velocity=[0.2] * 16, effort=[0.0] * 16)
    for k in range(n):
        msg.header.stamp.nanosec = k
        pub.publish(msg)
    time.sleep(0.3 + n * 2e-4)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--n", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--json", default="")
    ns = parser.parse_args()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=77)
    node = rclpy.create_node("bench_drain", context=context)
    received: list = []
    sub = node.create_subscription(JointState, "/bench_js", received.append, QOS)
    pub = node.create_publisher(JointState, "/bench_js", QOS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    time.sleep(0.5)  # discovery
    per_wait, per_take = [], []
    for _ in range(ns.repeats):
        received.clear()
        _fill(pub, ns.n, received)
        t0 = time.perf_counter()
        while len(received) < ns.n:
            executor.spin_once(timeout_sec=1.0)
        per_wait.append((time.perf_counter() - t0) / ns.n)

        received.clear()
        _fill(pub, ns.n, received)
        t0 = time.perf_counter()
        while len(received) < ns.n:  # the node's InputStreams.drain: take until the history is empty
            with sub.handle:
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
            if taken is None:
                executor.spin_once(timeout_sec=1.0)
                continue
            received.append(taken[0])
        per_take.append((time.perf_counter() - t0) / ns.n)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=context)
    wait_us, take_us = 1e6 * statistics.median(per_wait), 1e6 * statistics.median(per_take)
    result = {"n": ns.n, "repeats": ns.repeats, "executor_wait_per_message_us": wait_us,
              "take_per_message_us": take_us, "ratio": wait_us / take_us, "load1": os.getloadavg()[0]}
    print(json.dumps(result, indent=1))
    if ns.json:
        with open(ns.json, "w") as fh:
            json.dump(result, fh, indent=1)


if __name__ == "__main__":
    main()
