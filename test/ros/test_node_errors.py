"""The node tells bad input from bugs: a sample the learner rejects is a counted drop, a programming error
is logged at FATAL level, propagates out of the callback (and so out of ``spin``) and is never counted."""

from __future__ import annotations

import pytest
from helpers.ros import in_process_node, source_bag

from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.errors import RejectedSampleError
from semiparam_ros.io.bags import read_messages
from semiparam_ros.ros.main import EXECUTORS

pytestmark = pytest.mark.ros


@pytest.fixture
def node(tmp_path, monkeypatch):
    with in_process_node(tmp_path, monkeypatch) as node:
        yield node


def _kind(msg):
    return "joint_states" if isinstance(msg, JointStateData) else "wrench"


@pytest.mark.parametrize("executor_name", list(EXECUTORS))  # the default first
def test_programming_error_propagates_and_is_not_a_drop(node, tmp_path, monkeypatch, executor_name):
    messages = read_messages(source_bag(tmp_path))
    est = node.estimator
    for _ in range(400):  # learn a little, through the node's own processing path
        msg = next(messages)
        node.loop.enqueue(_kind(msg), msg)
        node._process_queued()
    assert est.n_samples_learned > 0
    drops_before, learned_before = est.drops, est.n_samples_learned
    stats_before = node._stats.snapshot()

    def buggy(x, y):
        raise IndexError("injected bug")

    monkeypatch.setattr(est.model, "predict_learn_one", buggy)  # the learning path with the gate off
    # and with the contact gate on (predict, then learn the prediction's context: the estimator's entry)
    monkeypatch.setattr(est.model, "learn_ahead_checked", buggy)
    # through the executor, as live: queued input is processed by an executor callback (the catch-up
    # timer, armed as when a backlog remains), and the error raises out of spin_once
    executor = EXECUTORS[executor_name](context=node.context)
    executor.add_node(node)
    try:
        with pytest.raises(IndexError, match="injected bug"):
            for _ in range(100):
                msg = next(messages)
                node.loop.enqueue(_kind(msg), msg)
                node._catch_up.reset()
                executor.spin_once(timeout_sec=1.0)
    finally:
        executor.remove_node(node)
        executor.shutdown()
    assert est.drops == drops_before and est.n_samples_learned == learned_before
    stats = node._stats.snapshot()
    assert {k: v for k, v in stats.items() if "drop" in k} == {
        k: v for k, v in stats_before.items() if "drop" in k}

    def rejecting(x, y):
        raise RejectedSampleError("x contains NaN")

    monkeypatch.setattr(est.model, "predict_learn_one", rejecting)
    monkeypatch.setattr(est.model, "learn_ahead_checked", rejecting)
    n_rejected = 0
    for _ in range(100):
        msg = next(messages)
        node.loop.enqueue(_kind(msg), msg)
        node._process_queued()  # never raises
        n_rejected = est.drops["rejected_sample"]
    assert n_rejected > 0 and est.n_samples_learned == learned_before


def test_throttled_warning_is_logged_once_per_period_and_built_only_then(node, monkeypatch):
    """The node's own throttle: per key at most one warning every _LOG_THROTTLE_S, the text built lazily."""
    from semiparam_ros.ros import inputs
    from semiparam_ros.ros.inputs import ThrottledWarnings

    logged, built = [], []

    class Logger:
        def warning(self, text):
            logged.append(text)

    now = [1000.0]
    monkeypatch.setattr(inputs.time, "monotonic", lambda: now[0])
    warn = ThrottledWarnings(Logger(), 5.0)

    def text():
        built.append(1)
        return "lazy"

    for _ in range(5):
        warn("a", text)
        warn("b", "eager")
    assert logged == ["lazy", "eager"] and len(built) == 1
    now[0] += 5.0 - 1e-3
    warn("a", text)
    assert logged == ["lazy", "eager"] and len(built) == 1  # still within the period
    now[0] += 2e-3
    warn("a", text)
    assert logged == ["lazy", "eager", "lazy"] and len(built) == 2
