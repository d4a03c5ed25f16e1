"""The node's parts assembled from a configuration: regressor, estimator, warm start, loop, model service.

Plain Python (no rclpy): :class:`~semiparam_ros.ros.estimator_node.EstimatorNode` calls :func:`assemble`
once it has the URDF (from a file, or from a topic it waited on) and wires ROS entities to what comes back.
Everything that can go wrong here is a start-up error that names its fix.

>>> from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
>>> cfg = EstimatorConfig.from_flat({**ICUB_RIGHT_ARM, "nonparametric.n_features": 8})
>>> parts = assemble(cfg, checkpoint=None)
>>> parts.notes
['cold start: checkpoint.enabled is false (nothing learned is kept)']
>>> parts.loop.estimator.learning_enabled, parts.model.feedforward is None  # an F/T sensor: no feed-forward
(True, True)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.build import build_regressor
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.errors import CheckpointError, ConfigurationError, StartupError
from semiparam_ros.serving.checkpoint_writer import default_checkpoint_path, warm_start
from semiparam_ros.serving.learning_loop import LearningLoop, warm_up_kernels
from semiparam_ros.serving.model_service import ModelService

__all__ = ["Assembly", "assemble", "checkpoint_path"]


@dataclass
class Assembly:
    """What :func:`assemble` built.

    Attributes:
        loop: The learning loop around the (warm-started) estimator.
        model: What is served beside the per-sample predictions (feed-forward, gravity, payload, URDF).
        notes: What the warm start did, one line each (for the log).
    """

    loop: LearningLoop
    model: ModelService
    notes: list[str]


def checkpoint_path(config: EstimatorConfig, node_name: str) -> tuple[Path | None, bool]:
    """Return the node's checkpoint file and whether it is the default one.

    ``checkpoint.path`` (``~`` expanded) when given; else the default file under ``$ROS_HOME``
    (:func:`~semiparam_ros.serving.checkpoint_writer.default_checkpoint_path`); None when
    ``checkpoint.enabled`` is false.

    Args:
        config: The configuration.
        node_name: The node's fully qualified name.
    """
    if not config["checkpoint.enabled"]:
        return None, False
    text = str(config["checkpoint.path"])
    return (Path(text).expanduser(), False) if text else (default_checkpoint_path(node_name), True)


def assemble(config: EstimatorConfig, urdf_xml: str | None = None, *, source: str = "the URDF given",
             checkpoint: Path | None, default_checkpoint: bool = False) -> Assembly:
    """Build the estimator of ``config``, warm start it and put the loop and the model service around it.

    The compiled kernels are run once on a throw-away copy (:func:`warm_up_kernels`), so the first real
    sample does not pay for compilation.

    Args:
        config: The validated configuration.
        urdf_xml: The URDF text when it did not come from ``robot.urdf`` (a topic); None reads that.
        source: Where ``urdf_xml`` came from (for error messages).
        checkpoint: The checkpoint to warm start from (``checkpoint.load_on_start``), or None.
        default_checkpoint: ``checkpoint`` is the default file: one that does not fit is moved aside
            (:func:`~semiparam_ros.serving.checkpoint_writer.warm_start`).

    Returns:
        The assembled parts.

    Raises:
        StartupError: The URDF cannot be read or does not fit the joints, a parameter is invalid, or the
            checkpoint cannot be loaded (the message says how to proceed).
    """
    try:
        estimator = OnlineEstimator(config, regressor=build_regressor(config, urdf_xml, source=source))
    except (ConfigurationError, OSError) as err:
        raise StartupError(f"cannot build the estimator: {err}") from err
    warm_up_kernels(config, estimator)
    try:
        notes = warm_start(estimator, checkpoint, load=bool(config["checkpoint.load_on_start"]),
                           default=default_checkpoint)
    except CheckpointError as err:
        raise StartupError(str(err)) from err
    estimator.learning_enabled = bool(config["learning_enabled"])
    loop = LearningLoop(estimator, queue_size=config["queue_size"], max_delay_s=config["overload.max_delay"])
    try:
        model = ModelService(loop, config)
    except ConfigurationError as err:
        raise StartupError(f"invalid parameter: {err}") from err
    return Assembly(loop, model, notes)
