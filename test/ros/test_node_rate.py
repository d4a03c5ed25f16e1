"""The node converts its seconds-based diagnostics window and warm-up at the measured sample rate."""

from __future__ import annotations

import dataclasses

import pytest
from helpers.ros import in_process_node, source_bag

from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.core.stream.rate import samples_in
from semiparam_ros.io.bags import read_messages

pytestmark = pytest.mark.ros


def test_rmse_window_and_warmup_in_seconds_follow_the_measured_rate(tmp_path, monkeypatch):
    overrides = {"diagnostics.rmse_window": 0, "diagnostics.rmse_window_s": 0.7,
                 "nonparametric.standardizer_warmup": 0, "nonparametric.standardizer_warmup_s": 1.3}
    with in_process_node(tmp_path, monkeypatch, **overrides) as node:
        assert node._stats.rmse_window == 70  # provisional: 0.7 s at 100 Hz
        est = node.estimator
        t0 = None
        for msg in read_messages(source_bag(tmp_path)):  # a 100 Hz bag, replayed at 50 Hz
            t0 = msg.stamp_ns if t0 is None else t0
            msg = dataclasses.replace(msg, stamp_ns=t0 + 2 * (msg.stamp_ns - t0))
            kind = "joint_states" if isinstance(msg, JointStateData) else "wrench"
            node.loop.enqueue(kind, msg)
            node._process_queued()
            if est.n_samples_learned >= 12:
                break
        period = est.sample_period_s
        assert period == pytest.approx(0.02, rel=1e-6)
        assert node._stats.rmse_window == samples_in(0.7, period) == 35
        assert est.model.nonparametric.standardizer.warmup == samples_in(1.3, period) == 65
