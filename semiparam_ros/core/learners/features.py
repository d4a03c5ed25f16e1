"""Random Fourier features for the Gaussian kernel, and input standardization.

:class:`RandomFourierFeatures` maps an input x to ``φ(x) = √(2/D)·cos(x Ω + b)`` with the entries of
``Ω`` (n_inputs × D) drawn from ``N(0, 1/σ²)`` and ``b`` from ``U[0, 2π)`` (Rahimi & Recht 2007; the
same formulation as scikit-learn's ``RBFSampler`` with ``gamma = 1/(2σ²)``), so that
``φ(x)·φ(x′) ≈ exp(−‖x − x′‖² / 2σ²)`` with an error of order ``1/√D``.

:class:`Standardizer` rescales inputs to zero mean and unit variance per coordinate, either from a batch
(:meth:`Standardizer.fit`) or online from the first N samples of a stream (Welford's algorithm), after
which its statistics are frozen so the feature map stays fixed while the learner runs. Inputs whose
variance is (numerically) zero get scale 1 so they pass through centred instead of blowing up.

Units: the inputs are whatever the caller feeds (for the learners ``x = [q, q̇, q̈]`` in rad, rad/s,
rad/s², optionally followed by a predicted wrench in N and N·m); σ is in the units of the standardized
input (dimensionless when a standardizer is used).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from semiparam_ros.core.validation import check_positive_int, check_range
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError

__all__ = ["RandomFourierFeatures", "Standardizer"]

_RFF_VERSION = 1
_STD_VERSION = 1


def _as_inputs(X: Any, n_inputs: int, what: str = "X") -> tuple[np.ndarray, bool]:
    """Return X as a finite (n, n_inputs) float64 array and whether it was a single 1-D sample."""
    X2 = np.asarray(X, dtype=np.float64)
    single = X2.ndim == 1
    if single:
        X2 = X2[None, :]
    if X2.ndim != 2 or X2.shape[1] != n_inputs:
        raise RejectedSampleError(f"{what} must have shape (n, {n_inputs}) or ({n_inputs},), "
                                  f"got {np.shape(X)}")
    if X2.size and not np.isfinite(X2).all():
        raise RejectedSampleError(f"{what} contains NaN or inf")
    return X2, single


class RandomFourierFeatures:
    """Random Fourier feature map of the Gaussian kernel ``exp(−‖x − x′‖² / 2σ²)``.

    Args:
        n_inputs: Input dimension.
        n_features: D, the number of features.
        sigma: Kernel width σ > 0 (input units).
        seed: Seed of the random draw of Ω and b (the same seed gives the same map).

    Raises:
        ConfigurationError: For non-positive sizes or σ ≤ 0 / non-finite.

    Example:
        >>> import numpy as np
        >>> rff = RandomFourierFeatures(n_inputs=3, n_features=4000, sigma=1.0, seed=0)
        >>> x, x2 = np.zeros(3), np.full(3, 0.5)
        >>> exact = np.exp(-np.sum((x - x2) ** 2) / 2)  # Gaussian kernel, σ = 1
        >>> bool(abs(rff.transform(x) @ rff.transform(x2) - exact) < 0.05)  # error ~ 1/√D
        True
    """

    def __init__(self, n_inputs: int, n_features: int, sigma: float, seed: int = 0) -> None:
        self.n_inputs = check_positive_int("n_inputs", n_inputs)
        self.n_features = check_positive_int("n_features", n_features)
        self.sigma = check_range("sigma", sigma, 0.0, lo_inclusive=False)
        self.seed = int(seed)
        rng = np.random.default_rng(self.seed)
        self.omega_ = rng.normal(0.0, 1.0 / sigma, size=(self.n_inputs, self.n_features))
        self.offset_ = rng.uniform(0.0, 2.0 * np.pi, size=self.n_features)
        self.feature_scale = math.sqrt(2.0 / self.n_features)

    def transform(self, X: Any) -> np.ndarray:
        """Map inputs to features.

        Args:
            X: One sample (n_inputs,) or a batch (n, n_inputs).

        Returns:
            (D,) for one sample, (n, D) for a batch.

        Raises:
            RejectedSampleError: Wrong shape, NaN or inf.
        """
        X2, single = _as_inputs(X, self.n_inputs)
        F = self.map_checked(X2)
        return F[0] if single else F

    def map_checked(self, X: np.ndarray) -> np.ndarray:
        """Features of already validated input (1-D or 2-D float64), without checks."""
        F = X @ self.omega_
        F += self.offset_
        np.cos(F, out=F)
        F *= self.feature_scale
        return F

    __call__ = transform

    def kernel(self, X: Any, Y: Any) -> np.ndarray:
        """Exact Gaussian kernel matrix ``exp(−‖x − y‖² / 2σ²)`` that the features approximate (n, m)."""
        X2, _ = _as_inputs(X, self.n_inputs)
        Y2, _ = _as_inputs(Y, self.n_inputs, "Y")
        sq = np.sum(X2**2, 1)[:, None] + np.sum(Y2**2, 1)[None, :] - 2.0 * X2 @ Y2.T
        return np.exp(-np.maximum(sq, 0.0) / (2.0 * self.sigma**2))

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the map as arrays (Ω and b are stored, so reloading needs no RNG)."""
        return {
            f"{prefix}version": np.array(_RFF_VERSION),
            f"{prefix}sigma": np.array(self.sigma),
            f"{prefix}seed": np.array(self.seed),
            f"{prefix}omega": self.omega_.copy(),
            f"{prefix}offset": self.offset_.copy(),
        }

    @classmethod
    def from_state_dict(cls, state: dict[str, np.ndarray], prefix: str = "") -> RandomFourierFeatures:
        """Rebuild the map from :meth:`state_dict` output.

        Raises:
            CheckpointError: Missing keys, wrong version, inconsistent shapes or non-finite arrays.
        """
        try:
            if int(state[f"{prefix}version"]) != _RFF_VERSION:
                raise CheckpointError("unsupported RandomFourierFeatures state version")
            omega = np.asarray(state[f"{prefix}omega"], dtype=np.float64)
            offset = np.asarray(state[f"{prefix}offset"], dtype=np.float64)
            sigma = float(state[f"{prefix}sigma"])
            seed = int(state[f"{prefix}seed"])
        except KeyError as err:
            raise CheckpointError(f"RandomFourierFeatures state is missing key {err}") from err
        if omega.ndim != 2 or offset.shape != (omega.shape[1],):
            raise CheckpointError(f"inconsistent RandomFourierFeatures state: omega {omega.shape}, "
                             f"offset {offset.shape}")
        if not (np.isfinite(omega).all() and np.isfinite(offset).all()):
            raise CheckpointError("RandomFourierFeatures state is not finite")
        obj = cls.__new__(cls)
        obj.n_inputs, obj.n_features = int(omega.shape[0]), int(omega.shape[1])
        if not (math.isfinite(sigma) and sigma > 0.0):
            raise CheckpointError(f"invalid sigma {sigma!r} in RandomFourierFeatures state")
        obj.sigma, obj.seed = sigma, seed
        obj.omega_, obj.offset_ = np.ascontiguousarray(omega), offset.copy()
        obj.feature_scale = math.sqrt(2.0 / obj.n_features)
        return obj

    def __repr__(self) -> str:
        return (f"RandomFourierFeatures(n_inputs={self.n_inputs}, n_features={self.n_features}, "
                f"sigma={self.sigma}, seed={self.seed})")


class Standardizer:
    """Per-coordinate standardization ``(x − mean) / scale``.

    Either fit on a batch with :meth:`fit`, given explicitly (``mean``, ``scale``), or estimated online:
    with ``warmup = N > 0`` the first N samples passed to :meth:`partial_fit` update Welford running
    statistics, then the statistics freeze and :attr:`ready` becomes true.

    Args:
        n_inputs: Input dimension.
        warmup: Number of samples of the online warm-up (0 = no online warm-up).
        mean: Optional fixed mean (n_inputs,); requires ``scale`` too.
        scale: Optional fixed scale (n_inputs,), entries > 0.
        min_scale: Floor of the estimated scale, a scalar or one value per input (≥ 0, in the inputs'
            units). An online warm-up that happens while the robot is at rest measures only sensor noise
            (≈1e-4 rad) and would blow later motion up to thousands of standardized units, where the
            random features carry no information; the floor keeps the scale at a physical operating range.

    Raises:
        ConfigurationError: Bad sizes, or inconsistent / non-finite / non-positive mean and scale.

    Example:
        >>> import numpy as np
        >>> s = Standardizer(2).fit(np.array([[0.0, 10.0], [2.0, 30.0]]))  # means 1, 20; stds 1, 10
        >>> s.transform(np.array([2.0, 10.0]))
        array([ 1., -1.])
    """

    #: Relative standard deviation below which an input counts as constant (scale 1).
    ZERO_VARIANCE_RTOL = 1e-12

    def __init__(self, n_inputs: int, warmup: int = 0, *, mean: Any = None, scale: Any = None,
                 min_scale: Any = 0.0) -> None:
        self.n_inputs = check_positive_int("n_inputs", n_inputs)
        self.warmup = check_positive_int("warmup", warmup, minimum=0)
        floor = np.broadcast_to(np.asarray(min_scale, dtype=np.float64), (self.n_inputs,)).copy()
        if not (np.isfinite(floor).all() and (floor >= 0).all()):
            raise ConfigurationError(f"min_scale must be finite and >= 0, got {min_scale!r}")
        self.min_scale_ = floor
        self.count_ = 0
        self._m2 = np.zeros(self.n_inputs)
        self.mean_ = np.zeros(self.n_inputs)
        self.scale_ = np.ones(self.n_inputs)
        self._ready = False
        if (mean is None) != (scale is None):
            raise ConfigurationError("give both mean and scale, or neither")
        if mean is not None:
            m = np.asarray(mean, dtype=np.float64)
            s = np.asarray(scale, dtype=np.float64)
            if m.shape != (self.n_inputs,) or s.shape != (self.n_inputs,):
                raise ConfigurationError(f"mean and scale must have shape ({self.n_inputs},)")
            if not (np.isfinite(m).all() and np.isfinite(s).all() and (s > 0).all()):
                raise ConfigurationError("mean must be finite and scale finite and > 0")
            self.mean_, self.scale_, self._ready = m.copy(), s.copy(), True

    @classmethod
    def identity(cls, n_inputs: int) -> Standardizer:
        """Return a ready standardizer that leaves inputs unchanged (mean 0, scale 1)."""
        return cls(n_inputs, mean=np.zeros(n_inputs), scale=np.ones(n_inputs))

    @property
    def ready(self) -> bool:
        """Whether the statistics are final (fitted, given, or the warm-up is complete)."""
        return self._ready

    def _finish(self, mean: np.ndarray, var: np.ndarray) -> None:
        std = np.sqrt(np.maximum(var, 0.0))
        constant = std <= self.ZERO_VARIANCE_RTOL * (1.0 + np.abs(mean))
        self.mean_ = mean.copy()
        self.scale_ = np.maximum(np.where(constant, 1.0, std), self.min_scale_)
        self._ready = True

    def set_warmup(self, warmup: int) -> None:
        """Change the length of an unfinished online warm-up (e.g. once the sample rate is measured).

        If ``warmup`` samples or more were already fed, the statistics freeze now.

        Args:
            warmup: New warm-up length [samples], ≥ 1.

        Raises:
            ConfigurationError: If ``warmup`` < 1.
            ValueError: If the standardizer is already ready (a programming error: nothing to change).
        """
        warmup = check_positive_int("warmup", warmup)
        if self._ready:
            raise ValueError("the standardizer is already ready: its warm-up cannot change")
        self.warmup = warmup
        if self.count_ >= warmup:
            self._finish(self.mean_, self._m2 / self.count_)

    def fit(self, X: Any) -> Standardizer:
        """Set the statistics from a batch (n ≥ 1, population variance) and freeze them.

        Returns:
            self.

        Raises:
            RejectedSampleError: Wrong shape, NaN/inf, or no rows.
        """
        X2, _ = _as_inputs(X, self.n_inputs)
        if X2.shape[0] == 0:
            raise RejectedSampleError("cannot fit a Standardizer on zero samples")
        mean = X2.mean(axis=0)
        self._finish(mean, X2.var(axis=0))
        self.count_ = X2.shape[0]
        self._m2 = X2.var(axis=0) * X2.shape[0]
        return self

    def partial_fit(self, X: Any) -> bool:
        """Feed samples to the online warm-up; samples after the warm-up (or once ready) are ignored.

        Args:
            X: One sample (n_inputs,) or a batch (n, n_inputs).

        Returns:
            :attr:`ready` after the call.

        Raises:
            RejectedSampleError: Wrong shape or NaN/inf (statistics unchanged).
        """
        X2, _ = _as_inputs(X, self.n_inputs)
        for x in X2:
            if self._ready or self.count_ >= self.warmup:
                break
            self.count_ += 1
            delta = x - self.mean_
            self.mean_ = self.mean_ + delta / self.count_
            self._m2 = self._m2 + delta * (x - self.mean_)
            if self.count_ == self.warmup:
                self._finish(self.mean_, self._m2 / self.count_)
        return self._ready

    def transform(self, X: Any) -> np.ndarray:
        """Standardize one sample (n_inputs,) or a batch (n, n_inputs).

        Raises:
            ValueError: If not :attr:`ready` (a call before the warm-up: a programming error).
            RejectedSampleError: Wrong shape, NaN/inf.
        """
        if not self._ready:
            raise ValueError(f"Standardizer is not ready (warm-up {self.count_}/{self.warmup} samples); "
                             "fit it or feed the warm-up first")
        X2, single = _as_inputs(X, self.n_inputs)
        Y = self.apply_checked(X2)
        return Y[0] if single else Y

    def apply_checked(self, X: np.ndarray) -> np.ndarray:
        """Standardize already validated input with the current statistics, without checks."""
        return (X - self.mean_) / self.scale_

    def copy(self) -> Standardizer:
        """Return an independent copy."""
        return Standardizer.from_state_dict(self.state_dict())

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the statistics (including an unfinished warm-up) as arrays."""
        return {
            f"{prefix}version": np.array(_STD_VERSION),
            f"{prefix}warmup": np.array(self.warmup),
            f"{prefix}count": np.array(self.count_),
            f"{prefix}mean": self.mean_.copy(),
            f"{prefix}m2": self._m2.copy(),
            f"{prefix}scale": self.scale_.copy(),
            f"{prefix}min_scale": self.min_scale_.copy(),
            f"{prefix}ready": np.array(self._ready),
        }

    @classmethod
    def from_state_dict(cls, state: dict[str, np.ndarray], prefix: str = "") -> Standardizer:
        """Rebuild a standardizer from :meth:`state_dict` output.

        Raises:
            CheckpointError: Missing keys, wrong version, inconsistent shapes or invalid values.
        """
        try:
            if int(state[f"{prefix}version"]) != _STD_VERSION:
                raise CheckpointError("unsupported Standardizer state version")
            mean = np.asarray(state[f"{prefix}mean"], dtype=np.float64)
            m2 = np.asarray(state[f"{prefix}m2"], dtype=np.float64)
            scale = np.asarray(state[f"{prefix}scale"], dtype=np.float64)
            warmup = int(state[f"{prefix}warmup"])
            count = int(state[f"{prefix}count"])
            ready = bool(state[f"{prefix}ready"])
            min_scale = np.asarray(state[f"{prefix}min_scale"], dtype=np.float64)
        except KeyError as err:
            raise CheckpointError(f"Standardizer state is missing key {err}") from err
        if mean.ndim != 1 or m2.shape != mean.shape or scale.shape != mean.shape or mean.size == 0:
            raise CheckpointError("inconsistent Standardizer state shapes")
        if not (np.isfinite(mean).all() and np.isfinite(m2).all() and np.isfinite(scale).all()
                and (scale > 0).all() and count >= 0 and warmup >= 0):
            raise CheckpointError("invalid Standardizer state values")
        obj = cls(mean.size, warmup, min_scale=min_scale)
        obj.mean_, obj._m2, obj.scale_ = mean.copy(), m2.copy(), scale.copy()
        obj.count_, obj._ready = count, ready
        return obj

    def __repr__(self) -> str:
        return f"Standardizer(n_inputs={self.n_inputs}, warmup={self.warmup}, ready={self._ready})"
