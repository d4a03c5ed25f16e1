"""Simulate and write a set of bags (what the ``simulate`` command runs), with a progress bar.

:func:`simulate_recording` is the one entry of the simulation pipeline (:mod:`semiparam_ros.sim.pipeline`):
the robot and its measurement model come with the configuration; :func:`~semiparam_ros.sim.writer.
write_recording` writes either.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from tqdm import tqdm

from semiparam_ros.sim.arms import ArmRecording
from semiparam_ros.sim.pipeline import RecordingConfig
from semiparam_ros.sim.scenario import SimulatedRecording
from semiparam_ros.sim.writer import write_recording

__all__ = ["generate", "simulate_recording"]


def simulate_recording(config: RecordingConfig, *,
                       progress: Callable[[int], None] | None = None) -> SimulatedRecording | ArmRecording:
    """Simulate one recording: the iCub's F/T sensor or an arm's joint torques, as the configuration says.

    Args:
        config: The scenario.
        progress: Called with the count of finished samples (F/T recordings; the arms report none).

    Returns:
        The stamped true and measured signals.

    Raises:
        ValueError: If the trajectory cannot be tracked within the joint limits.
    """
    return config.record(progress=progress)


def generate(
    out_dir: str | Path,
    configs: Sequence[RecordingConfig],
    *,
    overwrite: bool = False,
    compress: bool = True,
    progress: bool = True,
) -> list[Path]:
    """Simulate every scenario and write it as ``out_dir/<name>`` (bag folder with ``scenario.yaml``).

    Args:
        out_dir: Parent folder (created if missing).
        configs: The recordings, of any robot (:func:`semiparam_ros.sim.presets.preset_configs`).
        overwrite: Replace existing bag folders of the same names.
        compress: zstd-compress the MCAP chunks.
        progress: Show a tqdm progress bar on stderr (only when stderr is a terminal).

    Returns:
        The bag folders, in the order of ``configs``.

    Raises:
        ValueError: On an invalid scenario, an existing folder without ``overwrite`` (checked for all
            bags before anything is simulated), or a circle the arm cannot track.
    """
    show = bool(progress) and sys.stderr.isatty()  # a bar redrawn into a log or a pipe leaves frames
    out = Path(out_dir)
    names = [c.name for c in configs]
    if len(set(names)) != len(names):
        raise ValueError(f"scenario names must be unique, got {names}")
    if not overwrite:
        existing = [str(out / n) for n in names if (out / n).exists()]
        if existing:
            raise ValueError(f"bag folders exist already (use overwrite): {existing}")
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for config in configs:
        count, unit = config.progress_units()
        with tqdm(total=count, desc=config.name, unit=unit, disable=not show, leave=True) as bar:
            recording = simulate_recording(config, progress=bar.update)
            paths.append(write_recording(recording, out / config.name, overwrite=overwrite, compress=compress,
                                         progress=bar.update))
    return paths
