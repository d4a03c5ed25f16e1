"""Helpers for the node tests: isolated DDS environment, node subprocess, in-process test client.

Every test gets its own ``ROS_DOMAIN_ID`` (derived from the pid and a counter, 1–100), discovery limited to
localhost and ``ROS_LOG_DIR`` in its temporary directory, both for the node subprocess and for the test's
own rclpy context.
"""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger

from helpers import REPO

CONFIG = REPO / "config" / "icub_right_arm.yaml"
BAGS = REPO / "bags"

_COUNTER = itertools.count()

#: Test subscribers: reliable, deep; the node publishes reliable (default QoS) so nothing is lost.
COLLECT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: Parameters that make a replay lose nothing: reliable input subscriptions, and every sample learned
#: however late it is processed (a replay faster than the node learns is an overload the node otherwise
#: answers by predicting late samples without learning them).
LEARN_EVERY_SAMPLE = "overload.max_delay:=0.0"
RELIABLE_JOINT_STATES = (
    "qos_overrides./joint_states.subscription.reliability:=reliable",
    "qos_overrides./joint_states.subscription.depth:=10000",
    LEARN_EVERY_SAMPLE,
)
RELIABLE_INPUTS = (
    *RELIABLE_JOINT_STATES,
    "qos_overrides./wrench.subscription.reliability:=reliable",
    "qos_overrides./wrench.subscription.depth:=10000",
)


def unique_domain_id() -> int:
    """A ROS_DOMAIN_ID in 1..100 unlikely to be shared with a concurrent test process."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:] or "0"
    return 1 + (os.getpid() * 13 + int(worker) * 31 + next(_COUNTER) * 7) % 100


@dataclass
class RosEnv:
    """Environment of one test: variables for subprocesses plus the temporary directory."""

    env: dict[str, str]
    domain_id: int
    tmp: Path


def make_ros_env(tmp_path: Path, monkeypatch: Any) -> RosEnv:
    """Isolate DDS and logging for this test (also for the test's own rclpy context)."""
    domain = unique_domain_id()
    log_dir = tmp_path / "ros_log"
    log_dir.mkdir(exist_ok=True)
    values = {
        "ROS_DOMAIN_ID": str(domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "ROS_LOG_DIR": str(log_dir),
        "ROS_HOME": str(tmp_path / "ros_home"),  # a node's default checkpoint lives there
        "RCUTILS_LOGGING_BUFFERED_STREAM": "0",
        "PYTHONUNBUFFERED": "1",
    }
    for key, value in values.items():
        monkeypatch.setenv(key, value)
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    return RosEnv(dict(os.environ), domain, tmp_path)


@contextmanager
def in_process_node(tmp_path: Path, monkeypatch: Any, **overrides: Any) -> Iterator[Any]:
    """An ``EstimatorNode`` in this process, in its own context (CONFIG, checkpoints off, ``overrides`` as
    parameter values by name); aborted and destroyed on exit, its context shut down."""
    from rclpy.parameter import Parameter

    from semiparam_ros.ros.estimator_node import EstimatorNode

    env = make_ros_env(tmp_path, monkeypatch)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=env.domain_id)
    values = {"checkpoint.enabled": False, **overrides}
    node = EstimatorNode(context=context, cli_args=["--ros-args", "--params-file", str(CONFIG)],
                         parameter_overrides=[Parameter(name, value=value) for name, value in values.items()])
    try:
        yield node
    finally:
        node.abort()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


class NodeProcess:
    """The estimator node as a subprocess (``python -m semiparam_ros.ros.main``)."""

    def __init__(self, ros_env: RosEnv, params: Iterable[str] = (), *, params_file: Path | None = CONFIG,
                 extra_args: Iterable[str] = (), tag: str = "node", executor: str | None = None,
                 node_args: Iterable[str] = ()) -> None:
        self.log_path = ros_env.tmp / f"{tag}_{next(_COUNTER)}.log"
        cmd = [sys.executable, "-m", "semiparam_ros.ros.main"]
        if executor is not None:
            cmd += ["--executor", executor]
        cmd += [*node_args, "--ros-args"]
        if params_file is not None:
            cmd += ["--params-file", str(params_file)]
        for p in params:
            cmd += ["-p", p]
        cmd += list(extra_args)
        self.cmd = cmd
        self._log = open(self.log_path, "w")
        self.proc = subprocess.Popen(cmd, env=ros_env.env, stdout=self._log, stderr=subprocess.STDOUT,
                                     cwd=REPO)

    def alive(self) -> bool:
        return self.proc.poll() is None

    def output(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text()

    def wait(self, timeout: float) -> int:
        return self.proc.wait(timeout=timeout)

    def kill(self) -> None:
        """SIGKILL: no shutdown handler runs (simulates a crash)."""
        if self.alive():
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(timeout=10)
        self._log.close()

    def stop(self, timeout: float = 20.0) -> int:
        """SIGINT (Ctrl-C) and wait: the node's clean shutdown path."""
        if self.alive():
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)
        self._log.close()
        return self.proc.returncode


class Collector:
    """Thread-safe list of received messages with their receive times."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.messages: list[Any] = []
        self.times: list[float] = []

    def __call__(self, msg: Any) -> None:
        with self.lock:
            self.messages.append(msg)
            self.times.append(time.perf_counter())

    def snapshot(self) -> list[Any]:
        with self.lock:
            return list(self.messages)

    def wait_for(self, predicate: Callable[[list[Any]], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate(self.snapshot()):
                return True
            time.sleep(0.02)
        return predicate(self.snapshot())


class TestClient:
    """An rclpy node in the test process with its own context, spun in a background thread."""

    __test__ = False  # not a pytest test class

    def __init__(self, ros_env: RosEnv, name: str = "test_client") -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=ros_env.domain_id)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # context shut down while spinning
            pass

    def collect(self, msg_type: type, topic: str, qos: QoSProfile = COLLECT_QOS) -> Collector:
        collector = Collector()
        self.node.create_subscription(msg_type, topic, collector, qos)
        return collector

    def wait_for_publisher(self, topic: str, timeout: float = 30.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.node.count_publishers(topic) > 0:
                return True
            time.sleep(0.02)
        return False

    def call(self, srv_type: type, name: str, request: Any, timeout: float = 30.0) -> Any:
        client = self.node.create_client(srv_type, name)
        try:
            assert client.wait_for_service(timeout_sec=timeout), f"service {name} not available"
            future = client.call_async(request)
            deadline = time.monotonic() + timeout
            while not future.done() and time.monotonic() < deadline:
                time.sleep(0.005)
            assert future.done(), f"service {name} did not answer in {timeout} s"
            return future.result()
        finally:
            self.node.destroy_client(client)

    def trigger(self, name: str, timeout: float = 30.0) -> Trigger.Response:
        return self.call(Trigger, name, Trigger.Request(), timeout)

    def set_parameters(self, node: str, values: dict[str, Any], timeout: float = 30.0) -> list[Any]:
        request = SetParameters.Request()
        for name, value in values.items():
            request.parameters.append(ParameterMsg(name=name, value=_parameter_value(value)))
        return list(self.call(SetParameters, f"{node}/set_parameters", request, timeout).results)

    def get_parameters(self, node: str, names: list[str], timeout: float = 30.0) -> dict[str, Any]:
        """Read parameters of a running node over its ``get_parameters`` service (values by name)."""
        request = GetParameters.Request(names=names)
        values = self.call(GetParameters, f"{node}/get_parameters", request, timeout).values
        return {name: Parameter.from_parameter_msg(ParameterMsg(name=name, value=v)).value
                for name, v in zip(names, values, strict=True)}

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=5.0)


def _parameter_value(value: Any) -> ParameterValue:
    if isinstance(value, bool):
        return ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=value)
    if isinstance(value, int):
        return ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)
    if isinstance(value, float):
        return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
    if isinstance(value, str):
        return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
    raise TypeError(f"unsupported parameter value {value!r}")


def parameters_names_from_msg(msg: Any) -> list[str]:
    """The parameter names of an ``~/inertial_parameters`` message, read as a subscriber would: one
    ``MultiArrayDimension`` labelled ``base_parameters`` over all values, then one dimension per value
    whose label is its name (docs/node.md)."""
    dims = msg.layout.dim
    assert dims and dims[0].label == "base_parameters" and len(dims) == len(msg.data) + 1, dims
    return [d.label for d in dims[1:]]


def stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def wrench_array(msg: Any) -> np.ndarray:
    f, t = msg.wrench.force, msg.wrench.torque
    return np.array([f.x, f.y, f.z, t.x, t.y, t.z])


def diagnostic_values(msg: Any) -> dict[str, str]:
    """Key → value of the first status of a DiagnosticArray."""
    return {kv.key: kv.value for kv in msg.status[0].values}


# ------------------------------------------------------------------------------------------ bags
TOPICS = ("/joint_states", "/wrench")
_BAG_CACHE: dict[str, Path] = {}


def source_bag(tmp_root: Path, name: str = "icub_xy") -> Path:
    """The committed synthetic bag ``bags/<name>``; simulated into ``tmp_root`` (8 s) if not committed."""
    committed = BAGS / name
    if (committed / "metadata.yaml").is_file():
        return committed
    if name not in _BAG_CACHE:
        from semiparam_ros.sim.generate import generate, preset_configs

        scenario = name.removeprefix("icub_")
        _BAG_CACHE[name] = generate(tmp_root, preset_configs("icub", (scenario,), duration=8.0),
                                    progress=False)[0]
    return _BAG_CACHE[name]


@dataclass
class OfflineReplay:
    """What offline replay of the same messages through :class:`OnlineEstimator` computes."""

    estimator: Any
    predictions: dict[int, Any]  # stamp → Prediction
    measured: dict[int, np.ndarray]  # stamp → y
    order: list[int]  # stamps in processing order


def offline_replay(bag: Path, n_messages: int, overrides: dict[str, Any] | None = None,
                   messages: Iterable[Any] | None = None) -> OfflineReplay:
    """Feed the first ``n_messages`` of the bag's /joint_states and /wrench (log-time order) to the core."""
    from semiparam_ros.core.config import load_config
    from semiparam_ros.core.estimator.online import OnlineEstimator
    from semiparam_ros.io.bags import read_messages

    est = OnlineEstimator(load_config(CONFIG).with_overrides(overrides or {}))
    out = OfflineReplay(est, {}, {}, [])
    source = messages if messages is not None else read_messages(bag)
    for i, msg in enumerate(source):
        if i >= n_messages:
            break
        results = est.process(msg)
        for r in results:
            out.predictions[r.sample.stamp_ns] = r.prediction
            out.measured[r.sample.stamp_ns] = np.asarray(r.sample.y)
            out.order.append(r.sample.stamp_ns)
    return out


def wait_until(predicate: Callable[[], bool], timeout: float, poll: float = 0.02) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll)
    return predicate()


def wait_quiet(collector: Collector, predicate: Callable[[list[Any]], bool], timeout: float,
               quiet: float = 0.5) -> bool:
    """Wait until ``predicate`` holds and no message arrived for ``quiet`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        n = len(collector.snapshot())
        time.sleep(quiet)
        msgs = collector.snapshot()
        if len(msgs) == n and predicate(msgs):
            return True
    return False


def write_torque_bag(path: Path, n: int, hz: float = 100.0) -> None:
    """Joint states with efforts = the URDF rigid-body joint torques (N·m) of a smooth motion."""
    from semiparam_ros.core.config import load_config
    from semiparam_ros.core.estimator.build import build_regressor
    from semiparam_ros.core.stream.messages import JointStateData
    from semiparam_ros.io.bags import BagWriter

    regressor = build_regressor(load_config(CONFIG).with_overrides({"robot.output": "joint_torques"}))
    t = np.arange(n)[:, None] / hz
    w = 2 * np.pi * np.array([0.3, 0.4, 0.25, 0.5])
    q = np.array([-0.5, 0.5, 0.2, 0.9]) + 0.3 * np.sin(w * t)
    dq, ddq = 0.3 * w * np.cos(w * t), -0.3 * w**2 * np.sin(w * t)
    tau = regressor.wrench(q, dq, ddq) + 0.05 * np.tanh(5 * dq)  # + friction the rigid body cannot explain
    with BagWriter(path) as bag:
        for k in range(n):
            stamp = 1_700_000_000_000_000_000 + round(k * 1e9 / hz)
            bag.write_joint_state("/joint_states", JointStateData(stamp, regressor.joint_names, q[k], dq[k],
                                                                  tau[k]))
