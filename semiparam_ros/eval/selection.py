"""Hyperparameter selection from protocol runs over a grid, one learner at a time.

The reproduction selects λ_NP and σ by running the paper's protocol *within the training bag* (train on its
first half, test-then-train on parts of the second half) at every grid point, with every learner in each
run. Score of a grid point for a learner: its force RMSE at regime over the best force RMSE any grid point
gave it, plus the same for torque (so force in N and torque in N·m weigh equally); lowest wins. GURLS,
the library of the paper, likewise selects each model's regularization for that model; selecting once for
SP and reusing the values for NP is the other option the results page shows.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from semiparam_ros.eval.report import first_key

__all__ = ["GridPoint", "select"]


@dataclass(frozen=True)
class GridPoint:
    """One grid point's result for one learner.

    Attributes:
        lam: ``nonparametric.lam`` of the run.
        sigma: ``nonparametric.sigma`` of the run.
        force: Force RMSE at regime [N].
        torque: Torque RMSE at regime [N·m].
        force_first: Force RMSE over the first seconds [N].
        torque_first: Torque RMSE over the first seconds [N·m].
        score: ``force / best force + torque / best torque`` over the grid.
    """

    lam: float
    sigma: float
    force: float
    torque: float
    force_first: float
    torque_first: float
    score: float


def select(reports: Sequence[Mapping[str, Any]], kind: str) -> list[GridPoint]:
    """Score every grid point for one learner; best first.

    Args:
        reports: Protocol reports (``evaluate --json``), one per grid point, each with ``kind`` in it.
        kind: The learner to select for (``"NP"``, ``"SP"``, ``"SPJ"``, ...).

    Returns:
        The grid points sorted by score (ties keep the reports' order); empty if no report has ``kind``.

    Raises:
        ValueError: If a report lacks the configuration or the force/torque results.
    """
    raw = []
    for rep in reports:
        stats = rep.get("models", {}).get(kind)
        if stats is None:
            continue
        try:
            cfg = rep["config"]
            first = f"_{first_key(rep['protocol'].get('first_s', 3.0))}"
            raw.append((float(cfg["nonparametric.lam"]), float(cfg["nonparametric.sigma"]),
                        float(stats["force_rmse"]), float(stats["torque_rmse"]),
                        float(stats[f"force_rmse{first}"]), float(stats[f"torque_rmse{first}"])))
        except KeyError as err:
            raise ValueError(f"selection report without {err}") from err
    if not raw:
        return []
    f_min = min(r[2] for r in raw)
    t_min = min(r[3] for r in raw)
    points = [GridPoint(*r, score=r[2] / f_min + r[3] / t_min) for r in raw]
    return sorted(points, key=lambda p: p.score)
