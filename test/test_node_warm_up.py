"""The node's kernel warm-up runs the whole step (predict, gate, learn) before real input arrives, whatever
the acceleration estimator's own warm-up: otherwise the first real samples pay the loading of the compiled
kernels (tens of ms of latency: bench_node measured a 35–43 ms p99 period with the Kalman estimator when
the warm-up's 40 samples all fell inside the filter's 141 ms settling time)."""

from __future__ import annotations

import pytest
from ros_helpers import in_process_node

pytestmark = pytest.mark.ros


@pytest.mark.parametrize("method", ["savgol", "kalman"])
def test_warm_up_steps_through_the_acceleration_estimators_warm_up(tmp_path, monkeypatch, method):
    with in_process_node(tmp_path, monkeypatch, **{"acceleration.method": method}) as node:
        assert node.estimator.config["acceleration.method"] == method
        # at least three synthetic samples went through the step; none was learned by the real estimator
        assert node._warm_up_kernels() >= 3
        assert node.estimator.n_samples_learned == 0
