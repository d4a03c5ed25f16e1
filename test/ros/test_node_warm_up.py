"""The node's kernel warm-up runs the whole step (predict, gate, learn) before real input arrives, whatever
the acceleration estimator's own warm-up: otherwise the first real samples pay the loading of the compiled
kernels (tens of ms of latency: bench_node measured a 35–43 ms p99 period with the Kalman estimator when
the warm-up's 40 samples all fell inside the filter's 141 ms settling time)."""

from __future__ import annotations

import pytest

from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.serving.learning_loop import warm_up_kernels


@pytest.mark.parametrize("output", ["wrench", "joint_torques"])
@pytest.mark.parametrize("method", ["savgol", "kalman"])
def test_warm_up_steps_through_the_acceleration_estimators_warm_up(method, output):
    cfg = EstimatorConfig.from_flat({**ICUB_RIGHT_ARM, "acceleration.method": method, "robot.output": output})
    est = OnlineEstimator(cfg)
    # at least three synthetic samples went through the step; none was learned by the real estimator
    assert warm_up_kernels(cfg, est) >= 3
    assert est.n_samples_learned == 0
