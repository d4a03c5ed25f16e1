"""Contact episodes: external forces at the hand or end effector, drawn at random, with exact ground truth.

A contact episode is a pure force ``F(t)`` (N) that the environment (a person, a table) applies to the
robot at the origin of a frame rigidly attached to the last link (the iCub's ``r_hand_dh_frame``, the
Panda's ``panda_hand_tcp``, the UR's ``tool0``). Its direction is fixed in the robot's base (URDF root)
frame during the episode; its magnitude follows a smooth trapezoid

    F(t) = f · u · s(t),   s = ½(1 − cos(π (t − t₀)/r)) on the rise, 1 on the plateau, mirrored on the fall,

with ``t₀`` the start, ``d`` the duration, ``r = min(ramp, d/4)`` the rise and fall time (s), ``f`` the
peak magnitude (N) and ``u`` a unit vector. ``F`` is exactly zero outside ``[t₀, t₀ + d]``.

Episodes are drawn by :func:`draw_episodes`: a window of W s holds ``N = round(rate·W/60)`` episodes, one
in each of N equal slots (stratified, so the count is exact and the episodes spread over the window, but
their timing is random); in its slot of length L an episode lasts d ~ uniform in ``duration_range``
(capped at ``L − min_gap``), starts uniformly where it fits and ends at least ``min_gap`` before the slot
does. Peak magnitudes are uniform in ``force_range`` (N), directions uniform on the sphere.

How a contact shows in the measurement is computed by the scenario modules (the same rigid-body
machinery as the rest of the simulation): for an F/T sensor, the transmitted wrench ``[F_s, a × F_s]`` in
the sensor frame (``a`` the contact point seen from the sensor); for joint-torque sensors on a trajectory
the controller keeps following, ``τ_measured − τ_contact-free = −J(q)ᵀ F`` with ``J`` the linear Jacobian
(m/rad) of the contact point in the base frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["CONTACTS_DURATION_S", "ContactConfig", "ContactEpisode", "contact_forces", "contacts_timing",
           "draw_episodes"]

#: Length of a ``contacts`` scenario when no duration is given (s): contacts in [18, 78] s, payload
#: pickup at 90 s, 30 s to adopt it (every simulated robot's ``contacts`` scenario).
CONTACTS_DURATION_S = 120.0
#: Where a ``contacts`` scenario picks its payload up unless told: this fraction of its duration.
_PICKUP_FRACTION = 0.75


def contacts_timing(duration: float | None, payload_time: float | None) -> tuple[float, float]:
    """Return the duration and the payload pickup time of a ``contacts`` scenario.

    Args:
        duration: Length (s), or None for :data:`CONTACTS_DURATION_S`.
        payload_time: Pickup time (s), or None for 0.75 of the duration (after the contact window
            ``[0.15, 0.65]·T`` of :class:`ContactConfig`).

    Returns:
        ``(duration, payload_time)`` in s.
    """
    length = CONTACTS_DURATION_S if duration is None else float(duration)
    return length, _PICKUP_FRACTION * length if payload_time is None else payload_time


def _pair(value: object, what: str, *, positive: bool) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be two numbers (min, max), got {value!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
        raise ValueError(f"{what} must be finite with min <= max, got {value!r}")
    if (lo <= 0.0) if positive else (lo < 0.0):
        raise ValueError(f"{what} must be {'positive' if positive else '>= 0'}, got {value!r}")
    return lo, hi


@dataclass(frozen=True)
class ContactConfig:
    """How contact episodes are drawn.

    Attributes:
        rate: Episodes per minute of the window (> 0); the count is round(rate·W/60).
        duration_range: (min, max) duration of an episode (s).
        force_range: (min, max) peak magnitude of the force (N).
        window: (start, end) of the time span that holds the episodes (s from the start of the
            recording); None for ``(0.15·T, 0.65·T)`` with T the recording's duration, which leaves the
            last third of the recording for a later payload pickup and the model's recovery.
        min_gap: Minimum time between the end of one episode and the start of the next (s).
        ramp: Rise and fall time of the force (s), at most a quarter of each episode.
    """

    rate: float = 4.0
    duration_range: tuple[float, float] = (0.2, 3.0)
    force_range: tuple[float, float] = (5.0, 30.0)
    window: tuple[float, float] | None = None
    min_gap: float = 1.0
    ramp: float = 0.05

    def __post_init__(self) -> None:
        if isinstance(self.rate, bool) or not (np.isfinite(self.rate) and self.rate > 0):
            raise ValueError(
                f"contact rate must be a positive number of episodes per minute, got {self.rate!r}"
            )
        object.__setattr__(
            self, "duration_range", _pair(self.duration_range, "contact duration_range", positive=True)
        )
        object.__setattr__(self, "force_range", _pair(self.force_range, "contact force_range", positive=True))
        if self.window is not None:
            object.__setattr__(self, "window", _pair(self.window, "contact window", positive=False))
        for name in ("min_gap", "ramp"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"contact {name} must be finite and >= 0 s, got {value!r}")

    def span(self, duration: float) -> tuple[float, float]:
        """Return the window (s) for a recording of ``duration`` s, clipped to ``[0, duration]``."""
        start, end = self.window if self.window is not None else (0.15 * duration, 0.65 * duration)
        return max(0.0, start), min(float(duration), end)

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python description with units in the keys (for ``scenario.yaml``)."""
        return {
            "rate_per_min": float(self.rate),
            "duration_range_s": list(self.duration_range),
            "force_range_N": list(self.force_range),
            "window_s": None if self.window is None else list(self.window),
            "min_gap_s": float(self.min_gap),
            "ramp_s": float(self.ramp),
        }


@dataclass(frozen=True)
class ContactEpisode:
    """One contact: a force of fixed direction (base frame) with a smooth trapezoidal magnitude.

    Attributes:
        start: Start time t₀ (s from the start of the recording).
        duration: Duration d (s); the force is zero outside ``[start, start + duration]``.
        peak_force: Peak magnitude f (N).
        direction: Unit vector u (3,) in the base frame.
        ramp: Rise and fall time r (s), ≤ d/4.
    """

    start: float
    duration: float
    peak_force: float
    direction: tuple[float, float, float]
    ramp: float

    @property
    def end(self) -> float:
        """End time t₀ + d (s)."""
        return self.start + self.duration

    def profile(self, t: np.ndarray) -> np.ndarray:
        """Return s(t) ∈ [0, 1] (module docstring) at times ``t`` (s)."""
        t = np.asarray(t, dtype=np.float64)
        u = t - self.start
        out = np.where((u >= 0.0) & (u <= self.duration), 1.0, 0.0)
        if self.ramp > 0:
            rise = (u >= 0.0) & (u < self.ramp)
            fall = (u > self.duration - self.ramp) & (u <= self.duration)
            out = np.where(rise, 0.5 * (1.0 - np.cos(np.pi * u / self.ramp)), out)
            out = np.where(fall, 0.5 * (1.0 - np.cos(np.pi * (self.duration - u) / self.ramp)), out)
        return out

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python description with units in the keys (for ``scenario.yaml``)."""
        return {
            "start_s": float(self.start),
            "end_s": float(self.end),
            "duration_s": float(self.duration),
            "peak_force_N": float(self.peak_force),
            "direction_base": [float(v) for v in self.direction],
            "peak_force_base_N": [float(self.peak_force * v) for v in self.direction],
            "ramp_s": float(self.ramp),
        }


def draw_episodes(
    config: ContactConfig, duration: float, rng: np.random.Generator
) -> tuple[ContactEpisode, ...]:
    """Draw the contact episodes of one recording (module docstring).

    Args:
        config: How to draw them.
        duration: Length of the recording (s).
        rng: Random generator (its own stream: drawing contacts must not change any other signal).

    Returns:
        The episodes, in time order, each entirely inside the window, separated by at least ``min_gap``.

    Raises:
        ValueError: If the rate leaves too little time per episode for the shortest duration and the gap.
    """
    start, end = config.span(duration)
    lo_d, hi_d = config.duration_range
    lo_f, hi_f = config.force_range
    count = int(np.floor(config.rate * max(0.0, end - start) / 60.0 + 0.5))
    if count == 0:
        return ()
    slot = (end - start) / count
    if slot - config.min_gap < lo_d:
        raise ValueError(
            f"{config.rate} contacts per minute leave {slot:.3g} s per episode: too short for a "
            f"{lo_d} s episode and a {config.min_gap} s gap"
        )
    episodes: list[ContactEpisode] = []
    for k in range(count):
        d = rng.uniform(lo_d, min(hi_d, slot - config.min_gap))
        t0 = start + k * slot + rng.uniform(0.0, slot - config.min_gap - d)
        f = rng.uniform(lo_f, hi_f)
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
        direction = (float(u[0]), float(u[1]), float(u[2]))
        episodes.append(ContactEpisode(float(t0), float(d), float(f), direction, min(config.ramp, d / 4.0)))
    return tuple(episodes)


def contact_forces(episodes: tuple[ContactEpisode, ...], t: np.ndarray) -> np.ndarray:
    """Return the applied force F(t) (N, base frame) of all episodes at times ``t`` (s).

    Args:
        episodes: The episodes.
        t: (k,) times (s from the start of the recording).

    Returns:
        (k, 3) force the environment applies to the robot at the contact point, base-frame axes.
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    out = np.zeros((t.size, 3))
    for ep in episodes:
        out += ep.peak_force * np.outer(ep.profile(t), np.asarray(ep.direction))
    return out
