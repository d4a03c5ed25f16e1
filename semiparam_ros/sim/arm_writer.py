"""Deprecated: the joint-torque bag writer is :func:`semiparam_ros.sim.writer.write_recording` (one writer).

Kept for one release: :func:`write_arm_recording` warns and calls it; the topic names live in
:mod:`semiparam_ros.sim.writer`.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

from semiparam_ros.sim.arms import ArmRecording
from semiparam_ros.sim.writer import (
    GROUND_TRUTH_EXTERNAL_TORQUES_TOPIC,
    GROUND_TRUTH_FRICTION_TOPIC,
    GROUND_TRUTH_RIGID_TORQUES_TOPIC,
    GROUND_TRUTH_TORQUES_TOPIC,
    write_recording,
)

__all__ = [
    "GROUND_TRUTH_EXTERNAL_TORQUES_TOPIC",
    "GROUND_TRUTH_FRICTION_TOPIC",
    "GROUND_TRUTH_RIGID_TORQUES_TOPIC",
    "GROUND_TRUTH_TORQUES_TOPIC",
    "write_arm_recording",
]


def write_arm_recording(recording: ArmRecording, path: str | Path, *, overwrite: bool = False,
                        compress: bool = True, progress: Callable[[int], None] | None = None) -> Path:
    """Write a joint-torque recording (deprecated: :func:`semiparam_ros.sim.writer.write_recording`)."""
    warnings.warn("write_arm_recording is deprecated: use semiparam_ros.sim.writer.write_recording",
                  DeprecationWarning, stacklevel=2)
    return write_recording(recording, path, overwrite=overwrite, compress=compress, progress=progress)
