"""The node's kernel warm-up runs the whole step (predict, gate, learn) before real input arrives, whatever
the acceleration estimator's own warm-up: otherwise the first real samples pay the loading of the compiled
kernels (tens of ms of latency: bench_node measured a 35–43 ms p99 period with the Kalman estimator when
the warm-up's 40 samples all fell inside the filter's 141 ms settling time)."""

from __future__ import annotations

import pytest
import rclpy
from rclpy.parameter import Parameter
from ros_helpers import CONFIG, make_ros_env

from semiparam_ros.ros.estimator_node import EstimatorNode

pytestmark = pytest.mark.ros


@pytest.mark.parametrize("method", ["savgol", "kalman"])
def test_warm_up_steps_through_the_acceleration_estimators_warm_up(tmp_path, monkeypatch, method):
    env = make_ros_env(tmp_path, monkeypatch)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=env.domain_id)
    node = EstimatorNode(context=context, cli_args=["--ros-args", "--params-file", str(CONFIG)],
                         parameter_overrides=[Parameter("checkpoint.path", value=""),
                                              Parameter("acceleration.method", value=method)])
    try:
        assert node.estimator.config["acceleration.method"] == method
        # at least three synthetic samples went through the step; none was learned by the real estimator
        assert node._warm_up_kernels() >= 3
        assert node.estimator.n_samples_learned == 0
    finally:
        node.abort()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
