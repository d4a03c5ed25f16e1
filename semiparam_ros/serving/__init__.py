"""The model served: the learning loop, ``load_model``, feed-forward, checkpoints and ``learn``.

Plain Python between the learners and the node or the command line (never rclpy):
:mod:`~semiparam_ros.serving.learning_loop` (the node's queue and overload policy),
:mod:`~semiparam_ros.serving.assembly` (the node's parts built from a configuration),
:mod:`~semiparam_ros.serving.learned_model` (``load_model`` and the model it returns),
:mod:`~semiparam_ros.serving.model_service` (what the node serves beside its predictions),
:mod:`~semiparam_ros.serving.feedforward` (desired states and trajectories),
:mod:`~semiparam_ros.serving.checkpoint_writer`, :mod:`~semiparam_ros.serving.projection` (the consistent
parameters in a worker process) and :mod:`~semiparam_ros.serving.bag_learning` (bags into a checkpoint).
"""

__all__ = [
    "assembly",
    "bag_learning",
    "checkpoint_writer",
    "feedforward",
    "learned_model",
    "learning_loop",
    "model_service",
    "projection",
]
