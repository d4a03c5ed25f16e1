"""How well a learned model fits the logs it learned: per output, beside the URDF's, with the excitation.

What ``learn`` prints at the end. The logs are sampled uniformly as they stream by (a
:class:`SampleReservoir` of at most a few thousand samples, seeded: bounded memory whatever the logs'
length), and at the end the served model (``load_model``'s, frozen), its rigid-body part and the URDF's
rigid body (RNEA with the CAD inertias, no friction) are scored on that sample. These are errors **on the
training logs**: a sanity check (units, joints, a model that learned nothing) — how the model does on
motion it has not seen is what ``evaluate`` and ``real_robots`` measure.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.kinds import OutputKind

__all__ = ["RESERVOIR_SIZE", "FitSummary", "SampleReservoir", "fit_summary"]

#: Samples kept by :class:`SampleReservoir` for the summary.
RESERVOIR_SIZE = 4000
_WRENCH_NAMES = ("fx", "fy", "fz", "tx", "ty", "tz")


class SampleReservoir:
    """A uniform random sample of at most ``capacity`` rows of a stream (Vitter's algorithm R), seeded.

    Args:
        width_x: Width of an input row (``3n``: q, q̇, q̈).
        width_y: Width of an output row.
        capacity: Rows kept (≥ 1).
        seed: Seed of the replacement draws.

    >>> r = SampleReservoir(1, 1, capacity=3)
    >>> for k in range(10):
    ...     r.add(np.array([k]), np.array([2 * k]))
    >>> X, Y = r.arrays()
    >>> X.shape, r.seen, bool(np.all(Y == 2 * X))
    ((3, 1), 10, True)
    """

    def __init__(self, width_x: int, width_y: int, *, capacity: int = RESERVOIR_SIZE, seed: int = 0) -> None:
        self._X = np.empty((max(1, capacity), width_x))
        self._Y = np.empty((max(1, capacity), width_y))
        self._rng = np.random.default_rng(seed)
        #: Rows offered so far.
        self.seen = 0

    def add(self, x: np.ndarray, y: np.ndarray) -> None:
        """Offer one row (copied when kept)."""
        capacity = self._X.shape[0]
        if self.seen < capacity:
            slot = self.seen
        else:
            slot = int(self._rng.integers(self.seen + 1))
            if slot >= capacity:
                self.seen += 1
                return
        self._X[slot], self._Y[slot] = x, y
        self.seen += 1

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the kept rows ``(X, Y)`` (copies)."""
        n = min(self.seen, self._X.shape[0])
        return self._X[:n].copy(), self._Y[:n].copy()


@dataclass(frozen=True)
class FitSummary:
    """Errors on the training logs' sample (see the module docstring).

    Attributes:
        outputs: Output names (the joints, or ``fx … tz``).
        unit: Unit of the outputs.
        n_samples: Samples scored.
        rms: (t,) RMS of the measured output.
        model: (t,) RMSE of the served (frozen, consistent) model.
        rigid_body: (t,) RMSE of its rigid-body part.
        urdf: (t,) RMSE of the URDF's rigid body.
        condition: Condition number of the rigid-body information matrix (physical units; NaN for NP).
        weakest: The least excited direction, named by its parameters ('' for NP).
    """

    outputs: tuple[str, ...]
    unit: str
    n_samples: int
    rms: np.ndarray
    model: np.ndarray
    rigid_body: np.ndarray
    urdf: np.ndarray
    condition: float
    weakest: str

    def text(self) -> str:
        """Return the table ``learn`` prints."""
        width = max(8, *(len(name) for name in self.outputs))
        lines = [f"fit on {self.n_samples} samples of the training logs (RMSE [{self.unit}]; new motion: "
                 "evaluate / real_robots)",
                 f"  {'output':<{width}} {'measured':>9} {'URDF':>9} {'rigid':>9} {'model':>9}"]
        for k, name in enumerate(self.outputs):
            values = (self.rms[k], self.urdf[k], self.rigid_body[k], self.model[k])
            lines.append(f"  {name:<{width}} " + " ".join(f"{v:9.3g}" for v in values))
        lines.append(f"  {'mean':<{width}} {self.rms.mean():9.3g} {self.urdf.mean():9.3g} "
                     f"{self.rigid_body.mean():9.3g} {self.model.mean():9.3g}")
        if np.isfinite(self.condition):
            lines.append(f"excitation: information condition number {self.condition:.2g}; weakest: "
                         f"{self.weakest}")
        return "\n".join(lines)

    def as_dict(self) -> dict[str, Any]:
        """Plain values for the ``--json`` report."""
        return {"outputs": list(self.outputs), "unit": self.unit, "n_samples": self.n_samples,
                "rms": self.rms.tolist(), "rmse_model": self.model.tolist(),
                "rmse_rigid_body": self.rigid_body.tolist(), "rmse_urdf": self.urdf.tolist(),
                "condition": self.condition, "weakest": self.weakest}


def fit_summary(estimator: OnlineEstimator, X: np.ndarray, Y: np.ndarray) -> FitSummary | None:
    """Score the served model, its rigid body and the URDF on samples ``(X, Y)`` of the training logs.

    Args:
        estimator: The learned estimator.
        X: (N, 3n) rows ``[q, q̇, q̈]`` [rad, rad/s, rad/s²].
        Y: (N, t) measured outputs.

    Returns:
        The summary, or None without samples.
    """
    from semiparam_ros.serving.learned_model import LearnedModel

    if len(X) == 0:
        return None
    n = X.shape[1] // 3
    q, dq, ddq = X[:, :n], X[:, n:2 * n], X[:, 2 * n:]
    model = LearnedModel(estimator)
    parts = model.predict_parts(q, dq, ddq)
    urdf = model.cad(q, dq, ddq)

    def rmse(prediction: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean((Y - prediction) ** 2, axis=0))

    kind = estimator.config.output_kind
    names = tuple(estimator.config["robot.joints"]) if kind == OutputKind.JOINT_TORQUES else _WRENCH_NAMES
    condition, weakest = float("nan"), ""
    if estimator.traits.takes_rigid or estimator.kind != "NP":
        try:
            report = model.excitation()
        except ValueError:  # no rigid-body part
            pass
        else:
            condition = report.condition
            name, w = report.least_excited[0][1][0]
            weakest = f"{name} ({w:+.2f})"
    return FitSummary(names, kind.unit, len(X), np.sqrt(np.mean(Y ** 2, axis=0)), rmse(parts.total),
                      rmse(parts.rigid_body), rmse(urdf), condition, weakest)
