"""Command-line entry points: each parses its arguments and calls one library function.

``estimator`` is :mod:`semiparam_ros.ros.main`; the others (``learn``, ``learn-fleet``, ``evaluate``,
``real_robots``, ``tune``, ``simulate``, ``excite``, ``export_urdf``) are the modules here.
"""

__all__ = [
    "evaluate",
    "excite",
    "exit_codes",
    "export_urdf",
    "learn",
    "learn_fleet",
    "real_robots",
    "simulate",
    "tune",
]
