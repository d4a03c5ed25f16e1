"""Periodic joint trajectories with analytic derivatives, and the Cartesian circles of the paper.

Every joint trajectory the simulator produces is a truncated Fourier series

    q(t) = a₀ + Σₖ [aₖ cos(kωt) + bₖ sin(kωt)],   k = 1 … K,

so that q (rad), q̇ (rad/s) and q̈ (rad/s²) are evaluated in closed form and are consistent to machine
precision: a rigid-body model fed the true q̈ reproduces the true wrench exactly, which the tests rely on.

* :class:`~semiparam_ros.core.fourier.FourierTrajectory` (re-exported here) — the series itself, fitted
  to one sampled period (the converged closed-loop inverse-kinematics orbit of :mod:`semiparam_ros.sim.ik`)
  or drawn at random (:func:`multisine`).
* :class:`PointToPoint` — moves between random targets at the velocity limits, with rests (not periodic;
  piecewise-constant q̈).
* :class:`CartesianCircle` — the hand's reference path: a circle of radius r (m) travelled at constant speed
  v (m/s) in the XY (transverse) or XZ (sagittal) plane of the robot's root frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from semiparam_ros.core.fourier import (
    MULTISINE_HARMONICS,
    FourierTrajectory,
    as_times,
    random_multisine_terms,
)

__all__ = [
    "CartesianCircle",
    "FourierTrajectory",
    "ModulatedOrbit",
    "PointToPoint",
    "SlowSignal",
    "multisine",
]


def multisine(
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    seed: int,
    base_period: float = 20.0,
    harmonics: tuple[int, ...] = MULTISINE_HARMONICS,
    margin: float = 0.1,
    max_velocity: float = 1.5,
    max_acceleration: float = 8.0,
) -> FourierTrajectory:
    """Return a random multi-sine excitation that stays inside the joint limits.

    Each joint gets the listed harmonics of ``1/base_period`` with random phases and amplitudes ∝ 1/k;
    amplitudes are then scaled so that the sum of their absolute values (a bound on the excursion) fits in
    the range ``[lower + m, upper − m]`` (m = ``margin`` × range) and the velocity/acceleration bounds
    ``Σ|aₖ|kω ≤ max_velocity`` and ``Σ|aₖ|(kω)² ≤ max_acceleration`` hold, so limits hold for all t.

    Args:
        lower: Lower joint limits (rad), shape ``(n,)``.
        upper: Upper joint limits (rad), shape ``(n,)``.
        seed: Seed of the random phases and amplitudes (deterministic).
        base_period: Period of the fundamental (s).
        harmonics: Harmonic numbers k used (positive integers).
        margin: Fraction of each joint's range kept free at both ends.
        max_velocity: Bound on every |q̇| (rad/s).
        max_acceleration: Bound on every |q̈| (rad/s²).

    Returns:
        The excitation as a :class:`FourierTrajectory` of period ``base_period``.

    Raises:
        ValueError: On inconsistent limits or parameters.
    """
    lower = np.asarray(lower, dtype=np.float64).reshape(-1)
    upper = np.asarray(upper, dtype=np.float64).reshape(-1)
    if lower.shape != upper.shape or not np.all(upper > lower):
        raise ValueError("lower/upper must have the same shape with upper > lower")
    if not (0 <= margin < 0.5):
        raise ValueError(f"margin must be in [0, 0.5), got {margin}")
    if not (base_period > 0 and max_velocity > 0 and max_acceleration > 0):
        raise ValueError("base_period, max_velocity and max_acceleration must be positive")
    ks = np.asarray(sorted(set(harmonics)), dtype=np.int64)
    if ks.size == 0 or ks[0] < 1:
        raise ValueError("harmonics must be positive integers")
    rng = np.random.default_rng(seed)
    n = lower.size
    omega = 2.0 * np.pi / base_period
    half = 0.5 * (upper - lower) * (1.0 - 2.0 * margin)
    centre = 0.5 * (upper + lower)
    n_harm = int(ks[-1])
    cos_coef = np.zeros((n_harm, n))
    sin_coef = np.zeros((n_harm, n))
    amplitudes, phases = random_multisine_terms(rng, ks, n)
    for j in range(n):
        amp, phase = amplitudes[j], phases[j]
        kw = ks * omega
        scale = min(
            half[j] / amp.sum(),
            max_velocity / float(np.sum(amp * kw)),
            max_acceleration / float(np.sum(amp * kw * kw)),
        )
        amp = amp * scale
        cos_coef[ks - 1, j] = amp * np.sin(phase)
        sin_coef[ks - 1, j] = amp * np.cos(phase)
    return FourierTrajectory(omega, centre, cos_coef, sin_coef)


@dataclass(frozen=True)
class CartesianCircle:
    """A circle travelled at constant speed by the hand, in a coordinate plane of the root frame.

    The angle is θ(t) = v·t/r, starting at ``centre + r·e₁`` and turning from e₁ towards e₂, where
    (e₁, e₂) = (x, y) for ``plane="xy"`` and (x, z) for ``plane="xz"``.

    Attributes:
        centre: Circle centre in the root frame (m), shape ``(3,)``.
        radius: Radius r (m).
        speed: Tangential speed v (m/s).
        plane: ``"xy"`` (transverse) or ``"xz"`` (sagittal).
    """

    centre: np.ndarray
    radius: float
    speed: float
    plane: str

    def __post_init__(self) -> None:
        centre = np.asarray(self.centre, dtype=np.float64).reshape(-1)
        if centre.shape != (3,) or not np.all(np.isfinite(centre)):
            raise ValueError("centre must be a finite 3-vector (m)")
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"radius must be positive (m), got {self.radius!r}")
        if not (np.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f"speed must be positive (m/s), got {self.speed!r}")
        if self.plane not in ("xy", "xz"):
            raise ValueError(f"plane must be 'xy' or 'xz', got {self.plane!r}")
        object.__setattr__(self, "centre", centre)
        object.__setattr__(self, "radius", float(self.radius))
        object.__setattr__(self, "speed", float(self.speed))

    @property
    def omega(self) -> float:
        """Angular rate v/r (rad/s)."""
        return self.speed / self.radius

    @property
    def period(self) -> float:
        """Time for one revolution, 2πr/v (s)."""
        return 2.0 * np.pi / self.omega

    def _axes(self) -> tuple[np.ndarray, np.ndarray]:
        e1 = np.array([1.0, 0.0, 0.0])
        e2 = np.array([0.0, 1.0, 0.0]) if self.plane == "xy" else np.array([0.0, 0.0, 1.0])
        return e1, e2

    def position(self, t: np.ndarray | float) -> np.ndarray:
        """Return the reference hand position (m) at times ``t`` (s); shape ``(m, 3)``."""
        th = self.omega * np.atleast_1d(np.asarray(t, dtype=np.float64))
        e1, e2 = self._axes()
        return self.centre + self.radius * (np.outer(np.cos(th), e1) + np.outer(np.sin(th), e2))

    def velocity(self, t: np.ndarray | float) -> np.ndarray:
        """Return the reference hand velocity (m/s) at times ``t`` (s); shape ``(m, 3)``."""
        th = self.omega * np.atleast_1d(np.asarray(t, dtype=np.float64))
        e1, e2 = self._axes()
        return self.speed * (np.outer(-np.sin(th), e1) + np.outer(np.cos(th), e2))


@dataclass(frozen=True)
class SlowSignal:
    """A smooth, slowly varying random signal bounded by 1, with analytic derivatives and integral.

    ``c(t) = Σₘ aₘ sin(νₘ t + pₘ)`` with ``aₘ ≥ 0`` and ``Σₘ aₘ ≤ 1``, so ``|c(t)| ≤ 1`` for all t.

    Attributes:
        amplitudes: aₘ (dimensionless), shape ``(M,)``.
        frequencies: νₘ (rad/s), shape ``(M,)``.
        phases: pₘ (rad), shape ``(M,)``.
    """

    amplitudes: np.ndarray
    frequencies: np.ndarray
    phases: np.ndarray

    def __post_init__(self) -> None:
        a = np.atleast_1d(np.asarray(self.amplitudes, dtype=np.float64))
        nu = np.atleast_1d(np.asarray(self.frequencies, dtype=np.float64))
        p = np.atleast_1d(np.asarray(self.phases, dtype=np.float64))
        if not (a.shape == nu.shape == p.shape) or a.ndim != 1:
            raise ValueError("amplitudes, frequencies and phases must be 1-D arrays of the same length")
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(nu)) and np.all(np.isfinite(p))):
            raise ValueError("SlowSignal coefficients must be finite")
        if np.any(a < 0) or a.sum() > 1.0 + 1e-12 or np.any(nu <= 0):
            raise ValueError("amplitudes must be >= 0 with sum <= 1 and frequencies > 0")
        object.__setattr__(self, "amplitudes", a)
        object.__setattr__(self, "frequencies", nu)
        object.__setattr__(self, "phases", p)

    @classmethod
    def random(
        cls,
        rng: np.random.Generator,
        *,
        components: int = 4,
        min_period: float = 5.0,
        max_period: float = 40.0,
    ) -> SlowSignal:
        """Draw a signal with ``components`` sines.

        Periods are log-uniform in ``[min_period, max_period]`` (s), phases uniform, amplitudes uniform in
        [0.5, 1] normalised to sum to 1 (so the signal comes close to ±1).

        Args:
            rng: Random generator (seeded by the caller).
            components: Number of sines M.
            min_period: Shortest period (s).
            max_period: Longest period (s).

        Returns:
            The signal.

        Raises:
            ValueError: On non-positive or inverted periods or no components.
        """
        if components < 1 or not (0 < min_period <= max_period):
            raise ValueError("need components >= 1 and 0 < min_period <= max_period")
        periods = np.exp(rng.uniform(np.log(min_period), np.log(max_period), components))
        amp = rng.uniform(0.5, 1.0, components)
        phases = rng.uniform(0.0, 2.0 * np.pi, components)
        return cls(amp / amp.sum(), 2.0 * np.pi / periods, phases)

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(c, ċ, c̈)`` at the times ``t`` (s), each of shape ``(m,)`` (1, 1/s, 1/s²)."""
        arg = np.outer(np.asarray(t, dtype=np.float64), self.frequencies) + self.phases
        s, c = np.sin(arg), np.cos(arg)
        a, nu = self.amplitudes, self.frequencies
        return s @ a, c @ (a * nu), -(s @ (a * nu * nu))

    def integral(self, t: np.ndarray) -> np.ndarray:
        """Return ``∫₀ᵗ c(τ) dτ`` (s) at the times ``t`` (s)."""
        t = np.asarray(t, dtype=np.float64)
        arg = np.outer(t, self.frequencies) + self.phases
        return (np.cos(self.phases) - np.cos(arg)) @ (self.amplitudes / self.frequencies)

    def as_dict(self) -> dict[str, list[float]]:
        """Plain-Python description (for ``scenario.yaml``)."""
        return {
            "amplitudes": [float(v) for v in self.amplitudes],
            "periods_s": [float(v) for v in 2.0 * np.pi / self.frequencies],
            "phases_rad": [float(v) for v in self.phases],
        }


@dataclass(frozen=True)
class ModulatedOrbit:
    """A periodic joint orbit travelled at a slowly varying rate and slowly blended with nearby orbits.

    The orbits are functions of the circle angle φ (rad): ``Qₖ(φ) = Fₖ(φ/ωₖ)`` with ``Fₖ`` a
    :class:`FourierTrajectory` of angular frequency ωₖ (the circle's v/r). The phase advances at the
    modulated rate ``φ̇ = ω₀ (1 + A·s(t))`` with ``s`` a :class:`SlowSignal` (so the hand speed varies by at
    most ±A around the nominal), and the joint path is the first-order blend

        q(t) = Q₀(φ) + Σₖ cₖ(t) (Qₖ(φ) − Q₀(φ)),

    where Qₖ are the orbits of slightly displaced circles (centre shifted, radius changed) and cₖ slow
    signals in [−1, 1]: the hand follows a circle whose centre and radius wander by up to the displacements
    (to second order in the displacement). q̇ and q̈ follow by the chain and product rules in closed form,
    so q, q̇, q̈ stay exactly consistent.

    Attributes:
        base: The nominal orbit F₀.
        variants: Orbits Fₖ of the displaced circles.
        weights: One slow signal cₖ per variant.
        speed: The slow signal s of the rate modulation.
        speed_amplitude: A (dimensionless, 0 ≤ A < 1).
    """

    base: FourierTrajectory
    variants: tuple[FourierTrajectory, ...]
    weights: tuple[SlowSignal, ...]
    speed: SlowSignal
    speed_amplitude: float

    def __post_init__(self) -> None:
        if len(self.variants) != len(self.weights):
            raise ValueError("one weight signal per variant orbit is required")
        if any(v.n_joints != self.base.n_joints for v in self.variants):
            raise ValueError("variant orbits must have the base orbit's joints")
        if not (np.isfinite(self.speed_amplitude) and 0.0 <= self.speed_amplitude < 1.0):
            raise ValueError(f"speed_amplitude must be in [0, 1), got {self.speed_amplitude!r}")

    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return self.base.n_joints

    def phase(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Circle angle φ (rad), φ̇ (rad/s), φ̈ (rad/s²) at the times ``t`` (s)."""
        t = np.asarray(t, dtype=np.float64)
        w0, amp = self.base.omega, self.speed_amplitude
        s, ds, _ = self.speed.evaluate(t)
        return w0 * (t + amp * self.speed.integral(t)), w0 * (1.0 + amp * s), w0 * amp * ds

    @staticmethod
    def _in_phase(traj: FourierTrajectory, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q, dq, ddq = traj.evaluate(phi / traj.omega)
        return q, dq / traj.omega, ddq / traj.omega**2

    def evaluate(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations at the times ``t``.

        Args:
            t: Times (s), scalar or 1-D array of length m.

        Returns:
            ``(q, dq, ddq)``, each of shape ``(m, n)`` (rad, rad/s, rad/s²).

        Raises:
            ValueError: If a time is not finite.
        """
        t = as_times(t)
        phi, dphi, ddphi = self.phase(t)
        dphi_, ddphi_ = dphi[:, None], ddphi[:, None]
        Q0, Q0p, Q0pp = self._in_phase(self.base, phi)
        q = Q0.copy()
        dq = Q0p * dphi_
        ddq = Q0pp * dphi_**2 + Q0p * ddphi_
        for variant, weight in zip(self.variants, self.weights, strict=True):
            Qk, Qkp, Qkpp = self._in_phase(variant, phi)
            D, Dp, Dpp = Qk - Q0, Qkp - Q0p, Qkpp - Q0pp
            c, dc, ddc = (v[:, None] for v in weight.evaluate(t))
            q += c * D
            dq += dc * D + c * Dp * dphi_
            ddq += ddc * D + 2.0 * dc * Dp * dphi_ + c * (Dpp * dphi_**2 + Dp * ddphi_)
        return q, dq, ddq


@dataclass(frozen=True)
class PointToPoint:
    """Point-to-point moves with rests: synchronised trapezoidal velocity profiles, closed-form q, q̇, q̈.

    Move i goes from ``waypoints[i]`` to ``waypoints[i + 1]`` in ``durations[i]`` seconds, every joint on
    the same normalised profile s(τ) ∈ [0, 1]: constant acceleration for the first ``ramp`` fraction of
    the move, constant velocity, constant deceleration for the last ``ramp`` fraction (acceleration steps,
    the hardest case for a glitch check: q̈ jumps from 0 to its peak in one sample). The arm then rests
    ``rests[i]`` seconds (q̇ = q̈ = 0). Before the first move and after the last the arm is at rest.

    Attributes:
        waypoints: ``(M + 1, n)`` joint positions [rad].
        durations: ``(M,)`` move durations [s] (> 0).
        rests: ``(M,)`` rests after each move [s] (≥ 0).
        ramp: Acceleration (and deceleration) fraction of a move, in (0, 0.5].
        start: Rest before the first move [s] (≥ 0).
    """

    waypoints: np.ndarray
    durations: np.ndarray
    rests: np.ndarray
    ramp: float = 0.25
    start: float = 0.5

    def __post_init__(self) -> None:
        way = np.asarray(self.waypoints, dtype=np.float64)
        dur = np.asarray(self.durations, dtype=np.float64).reshape(-1)
        rest = np.asarray(self.rests, dtype=np.float64).reshape(-1)
        if way.ndim != 2 or way.shape[0] != dur.size + 1 or rest.shape != dur.shape:
            raise ValueError("waypoints must be (M + 1, n) with M durations and M rests")
        if not (np.all(np.isfinite(way)) and np.all(dur > 0) and np.all(rest >= 0)
                and np.all(np.isfinite(rest))):
            raise ValueError("waypoints finite, durations > 0 and rests >= 0 required")
        if not (0.0 < self.ramp <= 0.5) or not (self.start >= 0):
            raise ValueError(f"ramp must be in (0, 0.5] and start >= 0, got {self.ramp}, {self.start}")
        object.__setattr__(self, "waypoints", way)
        object.__setattr__(self, "durations", dur)
        object.__setattr__(self, "rests", rest)

    @classmethod
    def random(cls, lower: np.ndarray, upper: np.ndarray, velocity_limits: np.ndarray, *, seed: int,
               moves: int = 20, speed: float = 1.0, ramp: float = 0.25, margin: float = 0.1,
               rest_range: tuple[float, float] = (0.2, 1.5)) -> PointToPoint:
        """Random moves inside the joint limits whose fastest joint reaches ``speed`` × its velocity limit.

        Args:
            lower: Lower joint limits (n,) [rad].
            upper: Upper joint limits (n,) [rad].
            velocity_limits: |q̇| limits (n,) [rad/s] (a URDF's ``<limit velocity=…>``).
            seed: Seed of the targets and rests (deterministic).
            moves: Number of moves M.
            speed: Fraction of the velocity limit the leading joint of each move reaches, in (0, 1].
            ramp: Acceleration fraction of each move (peak q̈ = peak q̇ / (ramp · duration)).
            margin: Fraction of each joint's range kept free at both ends.
            rest_range: Rest after each move, uniform in this range [s].

        Returns:
            The trajectory.

        Raises:
            ValueError: On inconsistent limits or parameters.
        """
        lower = np.asarray(lower, dtype=np.float64).reshape(-1)
        upper = np.asarray(upper, dtype=np.float64).reshape(-1)
        vlim = np.asarray(velocity_limits, dtype=np.float64).reshape(-1)
        if not (lower.shape == upper.shape == vlim.shape and np.all(upper > lower) and np.all(vlim > 0)):
            raise ValueError("lower, upper, velocity_limits: one shape, upper > lower, limits > 0")
        if not (0.0 < speed <= 1.0 and 0 <= margin < 0.5 and moves >= 1):
            raise ValueError("speed in (0, 1], margin in [0, 0.5), moves >= 1 required")
        rng = np.random.default_rng(seed)
        lo = lower + margin * (upper - lower)
        hi = upper - margin * (upper - lower)
        way = rng.uniform(lo, hi, (moves + 1, lower.size))
        # peak of the normalised profile: 1 / ((1 − ramp) T); the leading joint reaches speed · its limit
        dist = np.abs(np.diff(way, axis=0))
        durations = np.max(dist / (speed * vlim), axis=1) / (1.0 - ramp)
        rests = rng.uniform(*rest_range, moves)
        return cls(way, durations, rests, ramp=ramp)

    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return int(self.waypoints.shape[1])

    @property
    def duration(self) -> float:
        """Total duration [s]: the first rest, every move and the rest after it."""
        return float(self.start + self.durations.sum() + self.rests.sum())

    def __call__(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return q [rad], q̇ [rad/s], q̈ [rad/s²] at times t [s], each of shape ``(len(t), n)``."""
        times = as_times(t)
        rho = self.ramp
        begins = self.start + np.concatenate(([0.0], np.cumsum(self.durations + self.rests)[:-1]))
        i = np.clip(np.searchsorted(begins, times, side="right") - 1, 0, self.durations.size - 1)
        T = self.durations[i]
        tau = np.clip((times - begins[i]) / T, 0.0, 1.0)
        moving = (times >= begins[i]) & (times - begins[i] < T)
        peak = 1.0 / (1.0 - rho)  # ds/dτ at cruise
        acc = peak / rho  # d²s/dτ² while ramping
        s = np.where(tau < rho, 0.5 * acc * tau**2,
                     np.where(tau <= 1.0 - rho, 0.5 * acc * rho**2 + peak * (tau - rho),
                              1.0 - 0.5 * acc * (1.0 - tau) ** 2))
        ds = np.where(tau < rho, acc * tau, np.where(tau <= 1.0 - rho, peak, acc * (1.0 - tau)))
        dds = np.where(tau < rho, acc, np.where(tau <= 1.0 - rho, 0.0, -acc))
        ds, dds = ds * moving, dds * moving
        start = np.where((times < begins[0])[:, None], self.waypoints[0], self.waypoints[i])
        delta = self.waypoints[i + 1] - self.waypoints[i]
        s = np.where(times < begins[0], 0.0, s)
        q = start + s[:, None] * delta
        dq = (ds / T)[:, None] * delta
        ddq = (dds / T**2)[:, None] * delta
        return q, dq, ddq
