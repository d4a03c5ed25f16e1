"""The node's plain-Python parts without rclpy: the learning loop (queue, overload policy, version), the
checkpoint writer (periodic, on request, after a reset, at shutdown, failures) and the model service.

The reference is the estimator driven by hand on the same messages (test_estimator's streams)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from helpers.streams import assert_same_state, feed, rich_stream, snapshot

from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.messages import WrenchData
from semiparam_ros.errors import CheckpointError
from semiparam_ros.serving.checkpoint_writer import CheckpointWriter, warm_start
from semiparam_ros.serving.learning_loop import LearningLoop
from semiparam_ros.serving.model_service import ModelService


def _kind(msg) -> str:
    return "wrench" if isinstance(msg, WrenchData) else "joint_states"


def _loop(max_delay_s: float = 0.0, queue_size: int = 100_000, **overrides) -> LearningLoop:
    cfg = EstimatorConfig.from_flat({**ICUB_RIGHT_ARM, "nonparametric.n_features": 50, **overrides})
    return LearningLoop(OnlineEstimator(cfg), queue_size=queue_size, max_delay_s=max_delay_s)


def test_loop_learns_every_sample_as_the_estimator_driven_by_hand():
    messages = rich_stream().messages
    loop = _loop()
    for msg in messages:
        loop.enqueue(_kind(msg), msg)
    results = []
    while loop.queue:
        _, data, t_recv = loop.queue.popleft()
        assert not loop.late(t_recv)  # max_delay 0: never late
        results += loop.step(data).results
    est = OnlineEstimator(loop.estimator.config)
    expected = feed(est, messages)
    assert len(results) == len(expected) > 500
    for a, b in zip(results, expected, strict=True):
        assert np.array_equal(a.prediction.total, b.prediction.total)
    assert_same_state(snapshot(loop.estimator), snapshot(est))
    assert loop.version == sum(r.learned for r in results) > 0  # one bump per learning step


def test_full_queue_drops_the_oldest_and_says_so():
    loop = _loop(queue_size=3)
    messages = rich_stream().messages[:5]
    dropped = [loop.enqueue(_kind(m), m, float(i)) for i, m in enumerate(messages)]
    assert dropped == [False, False, False, True, True]
    assert [t for _, _, t in loop.queue] == [2.0, 3.0, 4.0]


def test_late_input_is_predicted_and_not_learned():
    loop = _loop(max_delay_s=1e-3)
    messages = rich_stream().messages
    for msg in messages[:400]:
        loop.step(msg)
    learned = loop.estimator.n_samples_learned
    old = time.perf_counter() - 1.0  # waited a second: late
    assert loop.late(old) and not loop.late(time.perf_counter() + 1.0)
    stepped = [loop.step(m, skip_learning=loop.late(old)) for m in messages[400:420]]
    results = [r for s in stepped for r in s.results]
    assert results and not any(r.learned for r in results)
    assert all(np.all(np.isfinite(r.prediction.total)) for r in results)
    assert loop.estimator.n_samples_learned == learned
    assert loop.estimator.n_learning_skipped == len(results)


def test_new_drops_are_reported_once_and_reset_clears_the_baseline():
    loop = _loop()
    msg = rich_stream().messages[0]
    bad = type(msg)(**{**msg.__dict__, "stamp_ns": 0}) if hasattr(msg, "__dict__") else None
    if bad is None:
        pytest.skip("messages are not plain dataclasses")
    assert loop.step(bad).new_drops == 1
    assert loop.step(bad).new_drops == 1
    loop.reset()
    assert loop.estimator.n_dropped == 0
    assert loop.step(bad).new_drops == 1  # counted from zero again, never negative


def test_apply_pending_waits_for_an_empty_queue():
    loop = _loop()
    msg = rich_stream().messages[0]
    loop.enqueue(_kind(msg), msg)
    assert not loop.apply_pending()
    loop.queue.clear()
    assert loop.apply_pending()


def _writer_parts(loop: LearningLoop):
    results: list[tuple[bool, str]] = []
    return results, dict(snapshot=loop.snapshot, version=lambda: loop.version,
                         on_result=lambda ok, text: results.append((ok, text)))


def test_checkpoint_on_request_at_stop_and_after_reset_round_trips(tmp_path):
    path = tmp_path / "model.npz"
    loop = _loop()
    for msg in rich_stream().messages[:300]:
        loop.step(msg)
    results, parts = _writer_parts(loop)
    writer = CheckpointWriter(path, period_s=0.0, **parts)
    writer.start()
    ok, text = writer.save(timeout_s=10.0)
    assert ok and path.exists() and str(loop.estimator.n_samples_learned) in text
    restored = OnlineEstimator(loop.estimator.config)
    restored.load(path)
    assert_same_state(snapshot(restored), snapshot(loop.estimator))
    loop.reset()
    writer.request_reset()
    deadline = time.monotonic() + 10.0
    while len(results) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert len(results) == 2  # the reset was persisted without a request
    fresh = OnlineEstimator(loop.estimator.config)
    fresh.load(path)
    assert fresh.n_samples_learned == 0
    assert writer.stop(save=True)  # nothing changed since: up to date, no write
    assert len(results) == 2


def test_periodic_checkpoint_only_when_learning_changed_the_state(tmp_path):
    path = tmp_path / "model.npz"
    loop = _loop()
    results, parts = _writer_parts(loop)
    writer = CheckpointWriter(path, period_s=0.05, **parts)
    writer.start()
    time.sleep(0.3)
    assert results == [] and not path.exists()  # nothing learned: nothing written
    for msg in rich_stream().messages[:300]:
        loop.step(msg)
    deadline = time.monotonic() + 10.0
    while not results and time.monotonic() < deadline:
        time.sleep(0.01)
    assert results and results[0][0] and path.exists()
    writer.stop(save=False)


def test_failed_write_is_reported_and_the_thread_lives_on(tmp_path):
    loop = _loop()
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    results, parts = _writer_parts(loop)
    writer = CheckpointWriter(blocker / "model.npz", period_s=0.0, **parts)
    writer.start()
    for msg in rich_stream().messages[:100]:  # learned after the start: the final checkpoint is due
        loop.step(msg)
    ok, text = writer.save(timeout_s=10.0)
    assert not ok and "checkpoint failed" in text and results == [(False, text)]
    ok, _ = writer.save(timeout_s=10.0)  # still answering
    assert not ok
    assert not writer.stop(save=True)  # the final checkpoint failed too: reported


def test_disabled_checkpoints_answer_at_once():
    loop = _loop()
    _, parts = _writer_parts(loop)
    writer = CheckpointWriter(None, period_s=1.0, **parts)
    writer.start()
    assert writer.save(timeout_s=1.0) == (False, "checkpoint.enabled is false: no checkpoint is kept")
    assert writer.stop(save=True)


def test_save_waits_only_so_long_for_a_blocked_disk(tmp_path):
    loop = _loop()
    gate = threading.Event()

    def slow_snapshot():
        gate.wait(10.0)
        return loop.snapshot()

    writer = CheckpointWriter(tmp_path / "m.npz", period_s=0.0, snapshot=slow_snapshot)
    writer.start()
    ok, text = writer.save(timeout_s=0.1)
    assert not ok and "not written within 0.1 s" in text
    gate.set()
    assert writer.stop(save=True)


def test_warm_start_loads_says_why_cold_and_refuses_a_broken_file(tmp_path):
    loop = _loop()
    for msg in rich_stream().messages[:200]:
        loop.step(msg)
    path = tmp_path / "model.npz"
    est = OnlineEstimator(loop.estimator.config)
    assert warm_start(est, None, load=True) == [
        "cold start: checkpoint.enabled is false (nothing learned is kept)"]
    assert "no checkpoint at" in warm_start(est, path, load=True)[-1]
    writer = CheckpointWriter(path, period_s=0.0, snapshot=loop.snapshot)
    writer.start()
    assert writer.save(timeout_s=10.0)[0]
    writer.stop(save=False)
    assert warm_start(est, path, load=False)[-1] == "cold start: checkpoint.load_on_start is false"
    assert est.n_samples_learned == 0
    assert "warm start from" in warm_start(est, path, load=True)[-1]
    assert_same_state(snapshot(est), snapshot(loop.estimator))
    path.write_bytes(path.read_bytes()[:100])  # truncated
    with pytest.raises(CheckpointError, match="load_on_start:=false"):
        warm_start(OnlineEstimator(loop.estimator.config), path, load=True)


def test_model_service_serves_the_model_and_a_new_payload_once():
    loop = _loop(**{"robot.output": "joint_torques", "parametric.consistent": False})
    service = ModelService(loop, loop.estimator.config)
    assert service.feedforward is not None and service.projection is None
    q = np.full(len(loop.estimator.config["robot.joints"]), 0.3)
    assert np.allclose(service.gravity(q), service.serving.gravity(q))
    assert service.refresh() is None  # no projection: no link inertias to publish
    assert service.payload() is None and service.payload() is None  # no tare, nothing learned: nothing
    stats = service.statistics()
    assert stats["feedforward.ready"] is False and "feedforward.age_p50_ms" not in stats
    service.record_age(2.0)
    service.record_age(4.0)
    stats = service.statistics()
    assert stats["feedforward.age_p50_ms"] == 3.0 and stats["feedforward.answered_in_period"] == 2
    assert "feedforward.age_p50_ms" not in service.statistics()  # a new period
    assert service.export_urdf(None)[0] is False
    service.close()


def test_the_live_estimator_predicts_with_each_new_consistent_solution():
    """The node's per-sample predictions use the worker's consistent rigid body (the one the feed-forward
    and ``load_model`` serve) from the first solution of a learned state on: its parametric part is then
    Φ(x)·(c ⊙ π_consistent), recomputed here from the worker's solution. A solution of the state before
    anything was learned (the prior) is not applied."""
    from semiparam_ros.core.stream.messages import JointStateData

    loop = _loop(**{"robot.output": "joint_torques", "gate.enabled": False})
    est = loop.estimator
    service = ModelService(loop, est.config)
    try:
        worker = service.projection
        assert worker is not None and est.projects
        service.submit_projection()  # nothing learned yet
        assert worker.wait(timeout=120.0) is not None
        assert not service.apply_consistent() and est.model.rigid_override is None
        joints = est.config["robot.joints"]
        n = len(joints)
        for i in range(300):  # 3 s at 100 Hz of a slow sine, torques 0.2 N·m above the CAD gravity
            t = 0.01 * i
            q = 0.4 * np.sin(0.7 * t + np.arange(n))
            dq = 0.28 * np.cos(0.7 * t + np.arange(n))
            effort = service.serving.cad(q, dq, np.zeros(n)) + 0.2
            loop.step(JointStateData(10**9 + 10**7 * i, tuple(joints), q, dq, effort))
        assert est.n_samples_learned > 0 and loop.version > 0
        service.submit_projection()
        latest = worker.wait(timeout=120.0)
        assert latest is not None and worker.solved == 2
        assert service.apply_consistent()
        rigid = est.column_scale * latest.base
        np.testing.assert_array_equal(est.model.rigid_override, rigid)
        assert not service.apply_consistent()  # no new solution: nothing to do
        q, dq, ddq = np.full(n, 0.1), np.full(n, 0.2), np.full(n, -0.3)
        Phi = est.regressor.base_regressor(q, dq, ddq) / est.column_scale  # the learner's columns (θ = c ⊙ π)
        pred = est.model.predict_one(np.concatenate([q, dq, ddq]))
        np.testing.assert_allclose(pred.parametric, Phi @ rigid, rtol=1e-10, atol=1e-10)
    finally:
        service.close()


def test_a_default_checkpoint_of_another_robot_is_moved_aside_and_a_configured_one_refused(tmp_path):
    """At the default path a checkpoint that does not fit (another URDF text, another structure, a corrupt
    file) is never loaded nor overwritten: it is moved aside and the start is cold, saying so. The same
    file given as checkpoint.path is refused with the way out."""
    from semiparam_ros.core.config import EstimatorConfig
    from semiparam_ros.errors import CheckpointError
    from semiparam_ros.serving.checkpoint_writer import default_checkpoint_path

    cfg = EstimatorConfig.from_flat({**ICUB_RIGHT_ARM, "nonparametric.n_features": 8})
    other = OnlineEstimator(cfg.with_overrides({"nonparametric.n_features": 16}))  # another structure
    path = default_checkpoint_path("/arm/estimator")
    assert path.parent.parent.name == "semiparam_ros"
    path.parent.mkdir(parents=True, exist_ok=True)
    other.save(path)
    written = path.read_bytes()
    with pytest.raises(CheckpointError, match="load_on_start"):
        warm_start(OnlineEstimator(cfg), path, load=True)  # configured: refused, file untouched
    assert path.read_bytes() == written
    notes = warm_start(OnlineEstimator(cfg), path, load=True, default=True)
    assert "moved aside" in notes[-1] and not path.exists()
    aside = [p for p in path.parent.iterdir() if ".aside-" in p.name]
    assert len(aside) == 1 and aside[0].read_bytes() == written
    mine = OnlineEstimator(cfg)
    mine.save(path)
    assert "warm start from" in warm_start(OnlineEstimator(cfg), path, load=True, default=True)[-1]
    # the same structure learned on another URDF text: moved aside too (a second one never overwrites)
    state = dict(np.load(path))
    state["meta.urdf"] = np.array(str(state["meta.urdf"]).replace("<robot", "<robot ", 1))
    with path.open("wb") as fh:
        np.savez(fh, **state)
    notes = warm_start(OnlineEstimator(cfg), path, load=True, default=True)
    assert "another URDF" in notes[-1]
    assert len([p for p in path.parent.iterdir() if ".aside-" in p.name]) == 2
