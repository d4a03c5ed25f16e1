"""The pure core: numerics and the message-to-sample stream, never rclpy or message packages.

Rooms, bottom up: :mod:`~semiparam_ros.core.kinds` (output and input kinds),
:mod:`~semiparam_ros.core.config` (the parameter table), :mod:`~semiparam_ros.core.stream` (messages to
samples), :mod:`~semiparam_ros.core.learners` (recursive least squares, random features, P, NP, SP),
:mod:`~semiparam_ros.core.rigid_body` (URDF, regressor, identification, payload) and
:mod:`~semiparam_ros.core.estimator` (the online estimator: build, stream, checkpoint format).
"""

__all__ = [
    "checkpoint",
    "config",
    "estimator",
    "fourier",
    "kinds",
    "learners",
    "rigid_body",
    "stream",
    "validation",
]
