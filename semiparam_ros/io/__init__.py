"""File formats: rosbag2 / MCAP bags and excitation trajectories.

Bags are read, written and recovered when damaged (:mod:`~semiparam_ros.io.bags`,
:mod:`~semiparam_ros.io.mcap_scan`); excitation trajectories are :mod:`~semiparam_ros.io.trajectory_files`.
"""

__all__ = [
    "bags",
    "mcap_scan",
    "trajectory_files",
]
