"""semiparam_ros: online semiparametric inverse dynamics learning for ROS 2 Jazzy.

Subpackages:
    core: pure numerics and the message-to-sample pipeline (never imports rclpy or message packages).
    io: rosbag2 / MCAP reading and writing.
    sim: the synthetic iCub right-arm data generator.
    eval: offline bag-replay evaluation (the paper's protocol), figures, hyperparameter selection.
    ros: the thin rclpy node.
    cli: command-line entry points (argument parsing only).

The public entry point of a learned model is :func:`load_model` (``from semiparam_ros import
load_model``): a checkpoint in, ``model.predict(q, dq, ddq)`` out (see :mod:`semiparam_ros.service.serving`).
"""

from typing import TYPE_CHECKING, Any

from semiparam_ros.version import __version__

__all__ = ["LearnedModel", "__version__", "load_model"]

if TYPE_CHECKING:
    from semiparam_ros.service.serving import LearnedModel, load_model


def __getattr__(name: str) -> Any:
    """Import the public API lazily (Pinocchio and the learners load only when first used)."""
    if name in ("load_model", "LearnedModel"):
        from semiparam_ros.service import serving

        return getattr(serving, name)
    raise AttributeError(f"module 'semiparam_ros' has no attribute {name!r}")
