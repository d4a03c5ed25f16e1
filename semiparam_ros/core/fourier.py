"""Periodic joint trajectories as truncated Fourier series, with analytic derivatives.

A :class:`FourierTrajectory` is

    q(t) = a₀ + Σₖ [aₖ cos(kωt) + bₖ sin(kωt)],   k = 1 … K,

so that q (rad), q̇ (rad/s) and q̈ (rad/s²) are evaluated in closed form and are consistent to machine
precision. The simulator drives its arms with them (:mod:`semiparam_ros.sim.trajectories`) and the
excitation design optimises their coefficients (:mod:`semiparam_ros.core.rigid_body.excitation`).

Example:
    >>> import numpy as np
    >>> traj = FourierTrajectory(2 * np.pi / 10.0, [0.5], [[0.2]], [[0.0]])  # 0.5 + 0.2 cos(2πt/10)
    >>> q, dq, ddq = traj.evaluate([0.0, 2.5])
    >>> np.round(q[:, 0], 6).tolist(), np.round(dq[:, 0], 6).tolist()
    ([0.7, 0.5], [0.0, -0.125664])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MULTISINE_HARMONICS", "FourierTrajectory", "as_times", "random_multisine_terms"]


def as_times(t: np.ndarray | float) -> np.ndarray:
    """Return times (s) as a finite 1-D float array, or raise ValueError."""
    times = np.atleast_1d(np.asarray(t, dtype=np.float64))
    if times.ndim != 1 or not np.all(np.isfinite(times)):
        raise ValueError("t must be a finite scalar or 1-D array of times (s)")
    return times


@dataclass(frozen=True)
class FourierTrajectory:
    """A periodic joint trajectory as a truncated Fourier series with analytic derivatives.

    Attributes:
        omega: Fundamental angular frequency ω = 2π/T (rad/s).
        offset: Mean joint positions a₀, shape ``(n,)`` (rad).
        cos_coef: Cosine coefficients aₖ, shape ``(K, n)`` (rad), k = 1 … K.
        sin_coef: Sine coefficients bₖ, shape ``(K, n)`` (rad).
    """

    omega: float
    offset: np.ndarray
    cos_coef: np.ndarray
    sin_coef: np.ndarray

    def __post_init__(self) -> None:
        offset = np.atleast_1d(np.asarray(self.offset, dtype=np.float64))
        cos_coef = np.asarray(self.cos_coef, dtype=np.float64).reshape(-1, offset.size)
        sin_coef = np.asarray(self.sin_coef, dtype=np.float64).reshape(-1, offset.size)
        if cos_coef.shape != sin_coef.shape:
            raise ValueError("cos_coef and sin_coef must have the same shape (K, n)")
        if not (np.isfinite(self.omega) and self.omega > 0):
            raise ValueError(f"omega must be a positive finite angular frequency, got {self.omega!r}")
        if not (
            np.all(np.isfinite(offset)) and np.all(np.isfinite(cos_coef)) and np.all(np.isfinite(sin_coef))
        ):
            raise ValueError("Fourier coefficients must be finite")
        object.__setattr__(self, "omega", float(self.omega))
        object.__setattr__(self, "offset", offset)
        object.__setattr__(self, "cos_coef", cos_coef)
        object.__setattr__(self, "sin_coef", sin_coef)

    @property
    def period(self) -> float:
        """The period T = 2π/ω (s)."""
        return 2.0 * np.pi / self.omega

    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return int(self.offset.size)

    @property
    def n_harmonics(self) -> int:
        """Number of harmonics K."""
        return int(self.cos_coef.shape[0])

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
        k = np.arange(1, self.n_harmonics + 1, dtype=np.float64)
        kw = k * self.omega
        # Reduce the phase modulo 2π per harmonic in exact integer-period steps: for long bags
        # (t ~ 1000 s) this keeps the argument of cos/sin small without changing the value.
        t_red = np.mod(t, self.period)
        phase = np.outer(t_red, kw)
        c, s = np.cos(phase), np.sin(phase)
        q = self.offset + c @ self.cos_coef + s @ self.sin_coef
        dq = s @ (-kw[:, None] * self.cos_coef) + c @ (kw[:, None] * self.sin_coef)
        kw2 = (kw * kw)[:, None]
        ddq = -(c @ (kw2 * self.cos_coef) + s @ (kw2 * self.sin_coef))
        return q, dq, ddq

    @classmethod
    def fit_periodic(cls, samples: np.ndarray, period: float, n_harmonics: int) -> FourierTrajectory:
        """Fit the series to one period sampled on a uniform grid (least squares = truncated DFT).

        Args:
            samples: ``(N, n)`` joint positions at ``t = i·T/N``, i = 0 … N−1 (rad); the sample at
                ``t = T`` equals the first and is not included.
            period: The period T (s).
            n_harmonics: Number of harmonics K to keep; must satisfy ``K < N/2``.

        Returns:
            The fitted trajectory.

        Raises:
            ValueError: On bad shapes, non-finite samples or too many harmonics.
        """
        samples = np.asarray(samples, dtype=np.float64)
        if samples.ndim != 2 or samples.shape[0] < 4:
            raise ValueError("samples must have shape (N, n) with N >= 4")
        n_grid = samples.shape[0]
        if not (0 < n_harmonics < n_grid / 2):
            raise ValueError(f"n_harmonics must be in (0, N/2) = (0, {n_grid / 2}), got {n_harmonics}")
        if not np.all(np.isfinite(samples)):
            raise ValueError("samples must be finite")
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"period must be positive, got {period!r}")
        spectrum = np.fft.rfft(samples, axis=0) / n_grid
        offset = spectrum[0].real
        cos_coef = 2.0 * spectrum[1 : n_harmonics + 1].real
        sin_coef = -2.0 * spectrum[1 : n_harmonics + 1].imag
        return cls(2.0 * np.pi / period, offset, cos_coef, sin_coef)


#: The harmonics of a random multi-sine: the first three, then odd ones.
MULTISINE_HARMONICS: tuple[int, ...] = (1, 2, 3, 5, 7, 9, 11, 13)


def random_multisine_terms(rng: np.random.Generator, harmonics: np.ndarray,
                           n_joints: int) -> tuple[np.ndarray, np.ndarray]:
    """Draw a random multi-sine's terms: per joint, amplitudes ∝ U(0.5, 1)/k and phases U(0, 2π).

    Joint by joint, its amplitudes then its phases, so a seed gives the same terms to every caller. A term
    of amplitude A and phase φ is ``A sin(kωt + φ)``: cosine coefficient ``A sin φ``, sine ``A cos φ``.

    Args:
        rng: The generator drawn from.
        harmonics: (K,) the harmonic numbers k used (positive integers).
        n_joints: Number of joints n.

    Returns:
        ``(amplitudes, phases)``, each (n, K) (rad before any scaling; rad).
    """
    amplitudes = np.empty((n_joints, harmonics.size))
    phases = np.empty((n_joints, harmonics.size))
    for j in range(n_joints):
        amplitudes[j] = rng.uniform(0.5, 1.0, harmonics.size) / harmonics
        phases[j] = rng.uniform(0.0, 2.0 * np.pi, harmonics.size)
    return amplitudes, phases
