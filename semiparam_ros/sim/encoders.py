"""Joint states as a robot's driver logs them: quantized encoder positions, jittered stamps.

A driver reads an encoder (positions in counts of ``resolution`` rad), stamps the reading with a clock
that jitters around the nominal period, and reports a velocity that is either the controller's own
(smooth, ``velocity="exact"``) or the backward difference of the quantized positions
(``velocity="differentiated"``: steps of ``resolution / Δt`` rad/s, as many drivers do). Loggers round
once more (a log written with four decimals holds 1e-4 rad). This is what the glitch check
(:mod:`semiparam_ros.core.stream.glitch`) must never mistake for an outlier.

>>> import numpy as np
>>> from semiparam_ros.sim.trajectories import PointToPoint
>>> traj = PointToPoint(np.array([[0.0], [0.5]]), np.array([1.0]), np.array([1.0]))
>>> states = encoder_readings(traj, ("j",), rate_hz=100.0, resolution=1e-4, seed=0)
>>> len(states), float(states[-1].position[0])
(250, 0.5)
>>> bool(np.all(np.abs(np.array([s.position for s in states]) / 1e-4 % 1 - 0.5) > 0.49))  # whole counts
True
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from semiparam_ros.core.stream.messages import JointStateData

__all__ = ["encoder_readings"]

_EPOCH_NS = 10**18  # stamps start here (positive, far from zero)


def encoder_readings(
    trajectory: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]] | object,
    names: Sequence[str],
    *,
    rate_hz: float,
    resolution: float,
    seed: int,
    duration: float | None = None,
    velocity: str = "exact",
    jitter: float = 0.1,
) -> list[JointStateData]:
    """Sample a trajectory as logged joint states.

    Args:
        trajectory: Callable ``t [s] → (q, q̇, q̈)`` (e.g.
            :class:`~semiparam_ros.sim.trajectories.PointToPoint`), with a ``duration`` attribute unless
            ``duration`` is given.
        names: Joint names of the messages.
        rate_hz: Nominal joint-state rate [Hz].
        resolution: Position quantum [rad] (0: not quantized).
        seed: Seed of the stamp jitter.
        duration: Length of the recording [s] (default: the trajectory's).
        velocity: ``"exact"`` (the trajectory's q̇) or ``"differentiated"`` (backward difference of the
            logged positions over the stamp interval).
        jitter: Stamp jitter, uniform within ± this fraction of the period (the values are read at the
            stamped times).

    Returns:
        Joint states (effort zero), stamps in ns.

    Raises:
        ValueError: Invalid rate, resolution, jitter or velocity mode.
    """
    if not (rate_hz > 0 and resolution >= 0 and 0 <= jitter < 0.5):
        raise ValueError("rate_hz > 0, resolution >= 0 and jitter in [0, 0.5) required")
    if velocity not in ("exact", "differentiated"):
        raise ValueError(f"velocity must be 'exact' or 'differentiated', got {velocity!r}")
    total = float(duration if duration is not None else trajectory.duration)  # type: ignore[attr-defined]
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    t = np.arange(round(total * rate_hz)) * dt + rng.uniform(-jitter, jitter, round(total * rate_hz)) * dt
    t = np.clip(t, 0.0, None)
    q, dq, _ = trajectory(t)  # type: ignore[operator]
    if resolution > 0:
        q = np.round(q / resolution) * resolution
    if velocity == "differentiated":
        dq = np.vstack([np.zeros((1, q.shape[1])), np.diff(q, axis=0) / np.diff(t)[:, None]])
    stamps = _EPOCH_NS + np.round(t * 1e9).astype(np.int64)
    names = tuple(names)
    zeros = np.zeros(len(names))
    return [JointStateData(int(s), names, qi, dqi, zeros) for s, qi, dqi in zip(stamps, q, dq, strict=True)]
