"""A UR5 at 100 Hz moving point to point with Dahl friction, learned as the node learns under settings."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from semiparam_ros.core.config import EstimatorConfig, load_evaluation_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.serving.learned_model import LearnedModel, load_model
from semiparam_ros.sim.point_to_point import PointToPointArm

ROOT = Path(__file__).resolve().parents[2]


def served_ur5(name: str, values: Iterable[Any], folder: Path) -> tuple[EstimatorConfig, dict, list]:
    """Learn 60 s of seed 1's moves once per value of parameter ``name``; return the configuration,
    ``{value: (estimator, load_model of its checkpoint)}`` and seed 2's 30 s of joint states (held out)."""
    config = load_evaluation_config(ROOT / "config" / "ur5.yaml", {})
    train = PointToPointArm("ur5", seconds=60.0, rate_hz=100.0, seed=1).states()[0]
    test = PointToPointArm("ur5", seconds=30.0, rate_hz=100.0, seed=2).states()[0]
    served: dict[Any, tuple[OnlineEstimator, LearnedModel]] = {}
    for value in values:
        est = OnlineEstimator(config.with_overrides({name: value}))
        for msg in train:
            est.process(msg)
        path = folder / f"{name}_{value:g}.npz"
        est.save(path)
        served[value] = (est, load_model(path))
    return config, served, test
