"""The thin rclpy node and what it needs of ROS: topics, parameters, diagnostics, lifecycle.

:mod:`~semiparam_ros.ros.estimator_node` wires ROS entities to :mod:`semiparam_ros.serving`;
:mod:`~semiparam_ros.ros.main` is the ``estimator`` command line; the other modules are the node's inputs,
outputs, feed-forward endpoints, parameters, parameter files, diagnostics, message conversions, the
``~/save`` service, the robot description, the lifecycle variant and the bag player of the tests.
"""

__all__ = [
    "bag_player",
    "callbacks",
    "conversions",
    "description",
    "diagnostics",
    "estimator_node",
    "feedforward_endpoints",
    "inputs",
    "lifecycle_node",
    "main",
    "outputs",
    "parameter_files",
    "parameters",
    "save_service",
]
