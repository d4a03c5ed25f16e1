"""Predictive standard deviation of the learners' outputs, with a running estimate of the noise scale.

Both stages are ridge regressions ``y_k = z w_k + ε_k``. With ``ε_k`` of variance ``s_k²`` and the
prior ``w ~ N(0, s_k²/λ I)``, the posterior predictive variance of a new output is (per component k)

    σ_k² = s_k² (1 + v),        v = z A⁻¹ zᵀ,

``A`` the (forgetting-weighted, regularized) Gram matrix of the learner. For the cascade the two stages'
``v`` add (each stage's weights are uncertain given its own inputs); the learners return ``v`` per output
(:meth:`predict_one` with ``return_variance=True``). The noise scale is not known and not constant (it
grows when the robot moves faster, and any model error the learners have not yet absorbed counts as
noise to the user of the prediction), so it is estimated online from the a-priori errors ``e_k = y_k −
ŷ_k``, which satisfy ``E[e_k²] = s_k² (1 + v)``:

    s_k² ← s_k² + α (e_k² / (1 + v) − s_k²),        α = 1 − exp(−Δt / τ_s),

an exponentially weighted mean over a time constant ``τ_s`` in seconds (Δt the stamp step, so the
estimate means the same at any rate). ``±2σ`` then holds ≈ 95 % of the a-priori errors when they are
near-Gaussian at the time scale τ_s; measured coverage is in docs/adaptation.md. The first sample sets
``s²`` to its own normalized square error. Samples that the contact gate refuses are not fed to the
estimate (a contact is not noise of the model; it would inflate σ and blind the gate).
"""

from __future__ import annotations

import math
from typing import Any, TypeGuard

import numpy as np

from semiparam_ros.core.learners._step_kernels import noise_std, noise_update
from semiparam_ros.core.learners.contract import Prediction
from semiparam_ros.errors import ConfigurationError, RejectedSampleError

__all__ = ["NoiseScale", "predict_with_variance"]


def predict_with_variance(model: Any, x: np.ndarray) -> Prediction:
    """A-priori prediction of a model with its relative predictive variance ``v`` per output.

    ``model.predict_one(x, return_variance=True)``: each stage's prediction and ``v = z A⁻¹ zᵀ`` come from
    one triangular solve with its factor (:meth:`RecursiveRLS.predict`), the stages' ``v`` summed; a
    residual stage still in its standardizer warm-up contributes 0 (it predicts 0 and is not uncertain
    about it — its uncertainty is then in the noise scale).

    Args:
        model: Any learner of :mod:`semiparam_ros.core.learners` (P, NP, the SP combinations) or
            :mod:`semiparam_ros.core.learners.joint`.
        x: The input ``[q, q̇, q̈]`` [rad, rad/s, rad/s²].

    Returns:
        The prediction; ``variance`` holds v per output (dimensionless, ≥ 0).

    Raises:
        RejectedSampleError: Wrong size or non-finite x, or a non-finite regressor.
    """
    pred = model.predict_one(x, return_variance=True)
    var = np.fmax(np.asarray(pred.variance, dtype=np.float64), 0.0)  # NaN (a warm-up) counts as 0
    return Prediction(pred.parametric, pred.residual, pred.total, var, pred.correction)


class NoiseScale:
    """Running per-output estimate of the noise variance ``s²`` [units of y²].

    Args:
        n_outputs: t, the number of output components.
        time_constant_s: τ_s > 0, the memory of the estimate [s].

    Raises:
        ConfigurationError: For t < 1 or τ_s not a finite number > 0.

    Attributes:
        s2: (t,) current estimate, or None before the first sample.
        n_samples: Samples absorbed.
    """

    def __init__(self, n_outputs: int, time_constant_s: float) -> None:
        if isinstance(n_outputs, bool) or not isinstance(n_outputs, int | np.integer) or n_outputs < 1:
            raise ConfigurationError(f"n_outputs must be an integer >= 1, got {n_outputs!r}")
        self.n_outputs = int(n_outputs)
        self.time_constant_s = _check_time_constant(time_constant_s)
        self.reset()

    def reset(self) -> None:
        """Forget the estimate."""
        self.s2: np.ndarray | None = None
        self._last_ns: int | None = None
        self.n_samples = 0

    def set_time_constant(self, time_constant_s: float) -> None:
        """Change τ_s [s] from the next sample on.

        Raises:
            ConfigurationError: If τ_s is not a finite number > 0.
        """
        self.time_constant_s = _check_time_constant(time_constant_s)

    def std(self, variance: np.ndarray | float) -> np.ndarray:
        """Predictive standard deviation ``sqrt(s² (1 + v))`` per output [units of y].

        Args:
            variance: v ≥ 0, the relative posterior variance (scalar or (t,)); NaN counts as 0.

        Returns:
            (t,) σ; +inf before the first sample (nothing is known yet).
        """
        if self.s2 is None:
            return np.full(self.n_outputs, np.inf)
        if _is_vector(variance, self.n_outputs):
            return noise_std(self.s2, variance)  # the expression below, compiled (bit-identical)
        v = np.fmax(np.asarray(variance, dtype=np.float64), 0.0)  # fmax: NaN counts as 0
        return np.sqrt(self.s2 * (1.0 + v))

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the estimate as arrays (empty ``s2`` before the first sample)."""
        return {f"{prefix}s2": np.array([] if self.s2 is None else self.s2, dtype=np.float64),
                f"{prefix}last_ns": np.array(-1 if self._last_ns is None else self._last_ns, dtype=np.int64),
                f"{prefix}n_samples": np.array(self.n_samples, dtype=np.int64)}

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Replace the estimate by one written by :meth:`state_dict` (validated before anything changes).

        Raises:
            KeyError: A key is missing.
            ValueError: Wrong size, a negative or non-finite variance, or a negative count.
        """
        s2 = np.asarray(state[f"{prefix}s2"], dtype=np.float64).reshape(-1)
        last = int(np.asarray(state[f"{prefix}last_ns"]))
        n = int(np.asarray(state[f"{prefix}n_samples"]))
        if s2.size and (s2.shape != (self.n_outputs,) or not np.isfinite(s2).all() or (s2 < 0).any()):
            raise ValueError(f"noise variance must be {self.n_outputs} finite values >= 0, got {s2}")
        if n < 0:
            raise ValueError(f"noise sample count must be >= 0, got {n}")
        self.s2 = s2.copy() if s2.size else None
        self._last_ns = None if last < 0 else last
        self.n_samples = n

    def restart_stream(self) -> None:
        """Begin a new recording: its first sample's time step weighs nothing (the estimate is kept)."""
        self._last_ns = None

    def skip(self, stamp_ns: int) -> None:
        """Let a sample pass without absorbing it (a gated contact): its time step weighs nothing.

        Args:
            stamp_ns: Sample stamp [ns].
        """
        if self._last_ns is not None:
            self._last_ns = max(self._last_ns, int(stamp_ns))

    def update(self, stamp_ns: int, error: np.ndarray, variance: np.ndarray | float) -> None:
        """Absorb the a-priori error of one sample.

        Args:
            stamp_ns: Sample stamp [ns]; a step that is not positive weighs nothing.
            error: (t,) ``y − ŷ`` [units of y], finite.
            variance: v of the prediction (scalar or (t,)); NaN counts as 0.

        Raises:
            RejectedSampleError: Wrong size or non-finite error (the estimate is unchanged).
        """
        e = np.asarray(error, dtype=np.float64).reshape(-1)
        if self.s2 is not None and _is_vector(e, self.n_outputs) and _is_vector(variance, self.n_outputs):
            # the expressions below, compiled (bit-identical), for the estimator's (t,) arrays
            dt = 0.0 if self._last_ns is None else max(stamp_ns - self._last_ns, 0) * 1e-9
            ok, s2 = noise_update(self.s2, e, variance, -math.expm1(-dt / self.time_constant_s))
            if not ok:
                raise RejectedSampleError(f"error must be {self.n_outputs} finite values, got {error!r}")
            self.s2 = s2
            self._last_ns = int(stamp_ns)
            self.n_samples += 1
            return
        if e.shape != (self.n_outputs,) or not np.isfinite(e).all():
            raise RejectedSampleError(f"error must be {self.n_outputs} finite values, got {error!r}")
        v = np.fmax(np.asarray(variance, dtype=np.float64), 0.0)  # fmax: NaN counts as 0
        target = e * e / (1.0 + v)
        if self.s2 is None:
            self.s2 = target
        else:
            dt = 0.0 if self._last_ns is None else max(stamp_ns - self._last_ns, 0) * 1e-9
            alpha = -math.expm1(-dt / self.time_constant_s)
            self.s2 = self.s2 + alpha * (target - self.s2)
        self._last_ns = int(stamp_ns)
        self.n_samples += 1


def _is_vector(value: Any, n: int) -> TypeGuard[np.ndarray]:
    """Whether ``value`` is a (n,) float64 ndarray (the compiled kernels' one signature)."""
    return type(value) is np.ndarray and value.shape == (n,) and value.dtype == np.float64


def _check_time_constant(value: float) -> float:
    tau = float(value)
    if not (math.isfinite(tau) and tau > 0.0):
        raise ConfigurationError(f"time constant must be a finite number > 0 s, got {value!r}")
    return tau
