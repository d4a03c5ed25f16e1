"""The simulator: synthetic bags of an F/T-sensing iCub arm and of joint-torque arms, with their truth.

:mod:`~semiparam_ros.sim.generate` holds the entry point and presets, :mod:`~semiparam_ros.sim.recording`
the one recording pipeline and its measurement models, :mod:`~semiparam_ros.sim.writer` the one writer.
"""

__all__ = [
    "arms",
    "closed_loop",
    "contacts",
    "effects",
    "encoders",
    "frames",
    "generate",
    "ik",
    "recording",
    "scenario",
    "trajectories",
    "writer",
]
