"""semiparam_ros: online semiparametric inverse dynamics learning for ROS 2 Jazzy.

Subpackages, bottom up (imports only go down; docs/architecture.md):
    core: pure numerics and the message-to-sample stream (never imports rclpy or message packages).
    io: rosbag2 / MCAP bags and excitation trajectories.
    jobs: parallel jobs, local or on a Dask cluster.
    serving: the model served — learning loop, ``load_model``, feed-forward, checkpoints, ``learn``.
    sim: the simulator (an F/T-sensing iCub arm, joint-torque arms) writing bags with their truth.
    eval: measurements — the protocol on arrays, reference models, bag runs.
    ros: the thin rclpy node.
    report: what a user runs on their bags — the paper's protocol, real logs, tables, figures.
    tune: hyperparameter selection by held-out motion, fleets.
    cli: command-line entry points (argument parsing only).

Beside them: ``errors`` (one error root), ``atomic`` (atomic writes), ``plain_json`` (reports as JSON),
``version``.

The public entry point of a learned model is :func:`load_model` (``from semiparam_ros import
load_model``): a checkpoint in, ``model.predict(q, dq, ddq)`` out (see
:mod:`semiparam_ros.serving.learned_model`).
"""

from typing import TYPE_CHECKING, Any

from semiparam_ros.version import __version__

__all__ = ["LearnedModel", "__version__", "load_model"]

if TYPE_CHECKING:
    from semiparam_ros.serving.learned_model import LearnedModel, load_model


def __getattr__(name: str) -> Any:
    """Import the public API lazily (Pinocchio and the learners load only when first used)."""
    if name in ("load_model", "LearnedModel"):
        from semiparam_ros.serving import learned_model

        return getattr(learned_model, name)
    raise AttributeError(f"module 'semiparam_ros' has no attribute {name!r}")
