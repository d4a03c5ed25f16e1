"""One checkpoint per robot of a fleet, learned in parallel, with a summary (``learn-fleet``).

``ROOT`` holds one folder per robot, each holding that robot's bags (rosbag2 folders or ``.mcap`` files).
Every robot is one job: its bags are learned in name order by
:func:`~semiparam_ros.serving.bag_learning.learn_bags`
(exactly what ``learn BAG… --config C`` does), except the last one when there are two or more, which is
held out: the learned model, frozen, predicts its states as served (``LearnedModel.predict``) and the
summary reports that error. The configuration of robot ``r`` is the file ``config_pattern`` names with
``{robot}`` replaced by ``r``. A robot folder without bags is listed as skipped; a robot whose job fails
(a bag missing where its worker looks, a configuration that does not fit) is listed with the error, and
the others finish.

Jobs run in this process, on this machine's cores (``jobs``) or on a Dask cluster (``cluster``); the
checkpoint comes back to this process as bytes and is written here (atomically), so the output folder
need not be shared with the workers.

>>> import tempfile, pathlib
>>> root = pathlib.Path(tempfile.mkdtemp())
>>> (root / "arm_without_bags").mkdir()
>>> robots = discover_robots(root)
>>> robots[0].name, robots[0].bags
('arm_without_bags', ())
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from semiparam_ros.atomic import atomic_write_bytes, atomic_write_text
from semiparam_ros.core.config import load_config
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.bags.replay import Topics, load_samples
from semiparam_ros.eval.protocol.slices import SLICES, motion_slices, slice_coverage, slice_rmse
from semiparam_ros.jobs.parallel import run_jobs
from semiparam_ros.serving.bag_learning import learn_bags
from semiparam_ros.serving.learned_model import LearnedModel

__all__ = ["FleetRow", "Robot", "discover_robots", "fleet_markdown", "learn_fleet"]

_PLACEHOLDER = "{robot}"


@dataclass(frozen=True)
class Robot:
    """One robot of the fleet: its name (its folder's), its bags in name order, its configuration file."""

    name: str
    bags: tuple[str, ...]
    config: str = ""


@dataclass
class FleetRow:
    """What the fleet run did for one robot.

    Attributes:
        robot: The robot's name.
        status: ``"learned"``, ``"skipped"`` (no bags) or ``"failed"``.
        bags: Bags learned.
        held_out: The held-out bag, or None (a single bag: nothing held out).
        samples: Samples formed while learning.
        learned: Samples learned.
        drops: Input dropped, by reason.
        frozen_rmse: Mean over the outputs of the frozen model's RMSE on the held-out bag [N·m or N, N·m].
        frozen_slices: The same by motion state (:mod:`~semiparam_ros.eval.protocol.slices`).
        coverage: The frozen model's ±2σ coverage on the held-out bag, over all samples (``all``) and by
            motion state.
        checkpoint: The checkpoint written, or None.
        error: Why the robot failed or was skipped.
    """

    robot: str
    status: str
    bags: list[str] = field(default_factory=list)
    held_out: str | None = None
    samples: int = 0
    learned: int = 0
    drops: dict[str, int] = field(default_factory=dict)
    frozen_rmse: float | None = None
    frozen_slices: dict[str, float] = field(default_factory=dict)
    coverage: dict[str, float] = field(default_factory=dict)
    checkpoint: str | None = None
    error: str = ""


def _bags_of(folder: Path) -> tuple[str, ...]:
    bags = [p for p in folder.iterdir()
            if (p.is_dir() and (p / "metadata.yaml").is_file()) or (p.is_file() and p.suffix == ".mcap")]
    return tuple(str(p) for p in sorted(bags, key=lambda p: p.name))


def discover_robots(root: str | Path, config_pattern: str = "") -> list[Robot]:
    """Return the robots under ``root`` (a folder each, in name order) with their bags and parameter files.

    Args:
        root: The fleet's folder.
        config_pattern: Path of each robot's parameter file, ``{robot}`` standing for its name.

    Returns:
        The robots.

    Raises:
        ConfigurationError: ``root`` is not a folder, or the pattern lacks ``{robot}``.
    """
    root = Path(root)
    if not root.is_dir():
        raise ConfigurationError(f"fleet root {root} is not a folder")
    if config_pattern and _PLACEHOLDER not in config_pattern:
        raise ConfigurationError(f"--config-per-robot must contain {_PLACEHOLDER}, got {config_pattern!r}")
    return [Robot(p.name, _bags_of(p), config_pattern.replace(_PLACEHOLDER, p.name))
            for p in sorted(root.iterdir(), key=lambda p: p.name) if p.is_dir()]


def _learn_robot(robot: Robot) -> tuple[FleetRow, bytes | None]:
    """Learn the robot's bags but the last, score the frozen model on it; return the checkpoint as bytes."""
    config = load_config(robot.config)
    train = list(robot.bags[:-1]) if len(robot.bags) > 1 else list(robot.bags)
    held_out = robot.bags[-1] if len(robot.bags) > 1 else None
    with tempfile.TemporaryDirectory() as tmp:
        est, report = learn_bags(train, config, checkpoint=Path(tmp) / "robot.npz")
        data = (Path(tmp) / "robot.npz").read_bytes()
    row = FleetRow(robot.name, "learned", bags=train, held_out=held_out, samples=report.samples,
                   learned=report.learned, drops=report.drops)
    if held_out is not None:
        test, _ = load_samples(held_out, config, Topics.from_config(config))
        model = LearnedModel(est)
        n = len(model.joints)
        tau, std = model.predict(test.X[:, :n], test.X[:, n:2 * n], test.X[:, 2 * n:])
        err = np.asarray(tau) - test.Y
        row.frozen_rmse = float(np.mean(np.sqrt(np.mean(err**2, axis=0))))
        masks = motion_slices(test.X, n, test.n_outputs, test.sample_period_s)
        row.frozen_slices = slice_rmse(err, masks)
        row.coverage = slice_coverage(np.abs(err) <= 2.0 * np.asarray(std), masks)
    return row, data


def learn_fleet(root: str | Path, config_pattern: str, out: str | Path, *, jobs: int = 1,
                cluster: str | None = None, progress: bool = False) -> list[FleetRow]:
    """Learn one checkpoint per robot under ``root`` into ``out`` and write the summary there.

    Args:
        root: One folder per robot, holding its bags.
        config_pattern: Each robot's parameter file, ``{robot}`` standing for its folder's name.
        out: Output folder: ``<robot>.npz`` per robot, ``fleet.md`` and ``fleet.json``.
        jobs: Robots learned in parallel on this machine (-1: all cores).
        cluster: A Dask scheduler address or ``local:N`` instead of ``jobs``.
        progress: Progress on stderr.

    Returns:
        One row per robot folder, in name order.

    Raises:
        ConfigurationError: A bad root or pattern, or no robot folder at all.
        OSError: The output cannot be written.
    """
    robots = discover_robots(root, config_pattern)
    if not robots:
        raise ConfigurationError(f"no robot folder under {root}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = {r.name: FleetRow(r.name, "skipped", error="no bags") for r in robots if not r.bags}
    todo = [r for r in robots if r.bags]
    labels = [f"robot {r.name} ({', '.join(Path(b).name for b in r.bags)})" for r in todo]
    outcomes = run_jobs(_robot_job, [(r,) for r in todo], jobs=jobs, cluster=cluster, labels=labels,
                        unit="robot", progress=progress) if todo else []
    for robot, outcome in zip(todo, outcomes, strict=True):
        if isinstance(outcome, str):
            rows[robot.name] = FleetRow(robot.name, "failed", bags=list(robot.bags), error=outcome)
            continue
        row, data = outcome
        if data is not None:
            path = out / f"{robot.name}.npz"
            atomic_write_bytes(path, data)
            row.checkpoint = str(path)
        rows[robot.name] = row
    ordered = [rows[r.name] for r in robots]
    atomic_write_text(out / "fleet.json", json.dumps([asdict(r) for r in ordered], indent=1) + "\n")
    atomic_write_text(out / "fleet.md", fleet_markdown(ordered))
    return ordered


def _robot_job(robot: Robot) -> tuple[FleetRow, bytes | None] | str:
    """Run one robot's job: its ``(row, checkpoint bytes)``, or why it failed.

    Bad input only (a bag missing where this worker looks, a configuration that does not fit): the reason,
    naming the worker on a cluster. A programming error propagates.
    """
    try:
        return _learn_robot(robot)
    except (ValueError, OSError) as err:  # a bag missing where this worker looks, a bad configuration
        where = ""
        try:
            from distributed import get_worker

            where = f" (on worker {get_worker().address})"
        except (ImportError, ValueError):  # not in a Dask worker
            pass
        return f"{type(err).__name__}: {err}{where}"


def fleet_markdown(rows: Sequence[FleetRow]) -> str:
    """Return the summary tables: robot, status, bags, samples, drops, frozen error on the held-out bag.

    Then the frozen error and ±2σ coverage by motion state, for the robots scored.
    """
    lines = ["| robot | status | bags learned | held-out bag | samples | learned | drops "
             "| frozen RMSE on the held-out bag | note |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        drops = ", ".join(f"{k} {v}" for k, v in r.drops.items()) or "—"
        rmse = "—" if r.frozen_rmse is None else f"{r.frozen_rmse:.4g}"
        held = "—" if r.held_out is None else Path(r.held_out).name
        lines.append(f"| {r.robot} | {r.status} | {len(r.bags)} | {held} | {r.samples} | {r.learned} "
                     f"| {drops} | {rmse} | {r.error} |")
    scored = [r for r in rows if r.frozen_slices]
    if scored:
        lines += ["", "Frozen RMSE (±2σ coverage) on the held-out bag by motion state:", "",
                  "| robot | " + " | ".join(SLICES) + " | all |", "|---" * (len(SLICES) + 2) + "|"]
        for r in scored:
            cells = [f"{r.frozen_slices[k]:.4g} ({r.coverage.get(k, float('nan')):.2f})" for k in SLICES]
            lines.append(f"| {r.robot} | " + " | ".join(cells)
                         + f" | {r.frozen_rmse:.4g} ({r.coverage.get('all', float('nan')):.2f}) |")
    return "\n".join(lines) + "\n"
