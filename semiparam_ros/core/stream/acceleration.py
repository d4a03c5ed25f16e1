"""Joint-acceleration estimators from stamped joint velocities.

Robots publish joint positions and velocities but rarely accelerations, yet the inverse-dynamics input
is ``x = [q, q̇, q̈]``. Two estimators are provided; both use the actual message stamps (not a nominal
rate), so jittered or irregular streams are handled, and both are causal: an estimate only uses
velocities already received.

``method="savgol"`` — centred local polynomial (Savitzky–Golay) derivative.
    A polynomial of degree ``polyorder`` is fitted by least squares to the last ``window`` (odd)
    velocities against their true stamps and differentiated at the **middle** sample. The estimate is
    zero-phase (no lag with respect to the stamp it refers to) and exact for velocities that are
    polynomials of degree ≤ ``polyorder`` in time; it is emitted ``window // 2`` samples late
    (``delay_s``), for the stamp of the middle sample. For uniform stamps it equals
    ``scipy.signal.savgol_filter(dq, window, polyorder, deriv=1, delta=dt)`` at that sample.

``method="finite_difference"`` — causal filtered finite difference.
    ``(q̇_k − q̇_{k−w+1}) / (t_k − t_{k−w+1})`` over the last ``window`` samples, followed by a
    first-order low-pass with cut-off ``cutoff_hz`` (discretised with the actual step,
    ``α = 1 − exp(−Δt/τ)``, ``τ = 1/(2π f_c)``). It is emitted at once, for the newest stamp, but lags
    the true acceleration at low frequencies by ``lag_s = (w − 1)Δt/2 + Δt(1 − α)/α`` (≈ the half
    span of the difference plus τ − Δt/2 when Δt ≪ τ).

``method="kalman"`` — causal Kalman filter with a constant-snap (default) or constant-jerk model.
    Per joint, the state ``[q̇, q̈, d³q/dt³]`` (``kalman_model="jerk"``) or ``[q̇, q̈, d³q/dt³, d⁴q/dt⁴]``
    (``"snap"``) follows a chain of integrators driven by white noise (continuous time, discretised
    exactly with the actual step); q̇ is measured. One tuning in physical units, the bandwidth
    ``bandwidth_hz`` (f_b), fixes the ratio of process to measurement noise densities so that the
    steady-state continuous-time filter is a Butterworth loop at ω = 2π f_b, at any rate. The estimate
    is emitted at once, for the newest stamp, with no low-frequency lag (a velocity that is a
    polynomial of degree 2 (jerk) or 3 (snap) in time is tracked exactly); the price is a larger noise
    and an error at frequency f of ≈ 2.6 (f/f_b)³ (snap) or a +2 (f/f_b)² amplitude overshoot (jerk)
    (see :class:`KalmanEstimator`).

All estimators decide every input stamp exactly once, in stamp order: an estimate, or ``None`` for
the samples that cannot get one (the warm-up after start, a reset, or a gap longer than ``max_gap_s``).
Memory is bounded by ``window`` (by 4 × n_joints + 16 numbers for ``kalman``).

Rate-independent window (``window_s``). A window given in seconds is converted to samples at the
**measured** joint-state rate: the first :data:`RATE_SAMPLES` stamps are held back, the median of their
intervals ``Δt`` fixes ``window = 2·round(window_s / (2Δt)) + 1`` (odd, ≥ 3) for ``savgol`` and
``round(window_s / Δt) + 1`` (≥ 2) for ``finite_difference``, and the held samples are then fed to that
estimator, so they are decided as usual (only later). The median ignores a few jittered or dropped stamps;
the window then stays fixed (a rate change later is absorbed by the true-stamp fit). ``window_s = 0.12``
(the node's default) is 13 samples at 100 Hz, 25 at 200 Hz and 121 at 1 kHz; the savgol estimate then
refers to the stamp ``window_s / 2 = 60 ms`` before the newest joint state.

Degree of the savgol fit. On a symmetric window the slope of a degree-2 fit equals that of a degree-1
fit: an average of q̈ over the window with weights ∝ h² − s² (h = window_s/2), which passes a component
of angular frequency ω with the gain ``1 − (ωh)²/10 + O((ωh)⁴)``. That is a *systematic* error of q̈
(−0.7 % at ωh = 0.26, a 1 Hz component in a 0.08 s window), which a learner fitting τ = Φ(q, q̇, q̈)θ
cannot average away: it bends the inertial parameters and so every feed-forward. A degree-3 fit (the
node's default, ``polyorder=3``) has a gain error of order (ωh)⁴ instead, at a larger noise for one
window; the default window is longer to keep the noise near that of the degree-2 fit in 0.08 s.
Measurements behind the defaults: ``bench/stream/accel_window.py`` (``--polyorder``) and
docs/acceleration.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from semiparam_ros.core.stream.rate import RATE_SAMPLES, measured_period_s
from semiparam_ros.errors import ConfigurationError, RejectedSampleError

__all__ = [
    "KALMAN_PRIOR_VARIANCE",
    "KALMAN_SETTLE",
    "KALMAN_STATES",
    "METHODS",
    "RATE_SAMPLES",
    "AccelerationConfig",
    "AccelerationEstimator",
    "Decision",
    "FiniteDifferenceEstimator",
    "KalmanEstimator",
    "RateAdaptiveEstimator",
    "SavitzkyGolayEstimator",
    "estimate_accelerations",
    "kalman_matrices",
    "kalman_step_reference",
    "make_estimator",
    "samples_for_window",
    "savgol_weights_reference",
]

METHODS = ("savgol", "finite_difference", "kalman")

#: Process models of the Kalman estimator: state length (q̇ and its derivatives), by model name.
KALMAN_STATES = {"jerk": 3, "snap": 4}

#: Warm-up of the Kalman estimator in units of 1/ω (ω = 2π·bandwidth_hz), by model: from a diffuse start
#: the variance of its q̈ estimate falls within 2× of its steady state after ω·t ≈ 3.2–3.5 (jerk) and
#: 4.6–5.0 (snap) at 100 Hz – 1 kHz.
KALMAN_SETTLE = {"jerk": 4.0, "snap": 5.5}

#: Prior variance of the scaled derivatives beyond q̇ (q̈/ω, q⃛/ω², …) at a (re)start, in the filter's
#: units (unit noise densities): effectively diffuse, 10⁴ times the standard deviation of any signal seen.
KALMAN_PRIOR_VARIANCE = 1e8


Decision = tuple[int, "np.ndarray | None"]
"""``(stamp_ns, ddq)`` for one input stamp: the estimate in rad/s², or ``None`` (warm-up / gap)."""


@dataclass(frozen=True)
class AccelerationConfig:
    """Settings of the joint-acceleration estimator.

    Attributes:
        method: ``"savgol"`` (centred local polynomial, delayed, zero phase),
            ``"finite_difference"`` (causal, immediate, lagging) or ``"kalman"`` (causal, immediate, no
            low-frequency lag; Kalman filter, see ``kalman_model``).
        window: Samples used per estimate; odd for ``savgol``; ≥ 2. Ignored when ``window_s`` is set.
        window_s: Window length in seconds (> 0), converted to samples at the measured rate (see the
            module docstring); ``None`` uses ``window``.
        polyorder: Polynomial degree of ``savgol`` (1 ≤ polyorder < window).
        cutoff_hz: Low-pass cut-off of ``finite_difference`` in Hz (> 0; ``math.inf`` disables it).
        max_gap_s: Restart the estimator when two consecutive stamps are further apart than this (s);
            ``None`` never restarts (a gap then just widens the fit window). The node's parameter
            ``acceleration.max_gap_s`` defaults to 0.1 s: at 100 Hz a window of 9 spans 80 ms, and a fit
            across a longer hole is several times less accurate than a restart, which costs
            ``2·(window // 2)`` samples.
        bandwidth_hz: Bandwidth f_b of ``kalman`` in Hz (> 0): the steady-state continuous-time filter
            is a Butterworth loop (order 3 or 4, see ``kalman_model``) at 2π f_b rad/s. Window,
            window_s, polyorder and cutoff_hz do not apply to ``kalman``.
        kalman_model: Process model of ``kalman``: ``"jerk"`` (constant jerk, state q̇, q̈, q⃛) or
            ``"snap"`` (constant snap, one derivative more: less bias, more noise at one bandwidth).

    Raises:
        ConfigurationError: Any setting out of range (checked on construction).
    """

    method: str = "savgol"
    window: int = 9
    polyorder: int = 2
    cutoff_hz: float = 20.0
    max_gap_s: float | None = None
    window_s: float | None = None
    bandwidth_hz: float = 6.0
    kalman_model: str = "snap"

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ConfigurationError(f"acceleration method must be one of {METHODS}, got {self.method!r}")
        if self.window_s is not None:
            if not (isinstance(self.window_s, int | float) and math.isfinite(self.window_s)
                    and self.window_s > 0):
                raise ConfigurationError(
                    f"acceleration window_s must be a finite number > 0 (s), got {self.window_s!r}")
            if self.method == "savgol" and not 1 <= int(self.polyorder) <= 10:
                raise ConfigurationError(f"savgol polyorder must be in [1, 10], got {self.polyorder}")
        elif (isinstance(self.window, bool) or not isinstance(self.window, int | np.integer)
              or self.window < 2):
            raise ConfigurationError(f"acceleration window must be an integer >= 2, got {self.window!r}")
        elif self.method == "savgol":
            if self.window % 2 == 0 or self.window < 3:
                raise ConfigurationError(f"savgol window must be odd and >= 3, got {self.window}")
            if not 1 <= int(self.polyorder) < self.window:
                raise ConfigurationError(
                    f"savgol polyorder must be in [1, window={self.window}), got {self.polyorder}"
                )
        if isinstance(self.bandwidth_hz, bool) or not (
                isinstance(self.bandwidth_hz, int | float) and math.isfinite(self.bandwidth_hz)
                and self.bandwidth_hz > 0):
            raise ConfigurationError(
                f"acceleration bandwidth_hz must be a finite number > 0 (Hz), got {self.bandwidth_hz!r}")
        if self.kalman_model not in KALMAN_STATES:
            raise ConfigurationError(f"acceleration kalman_model must be one of {tuple(KALMAN_STATES)}, "
                                     f"got {self.kalman_model!r}")
        if not (self.cutoff_hz > 0):  # also rejects NaN
            raise ConfigurationError(f"acceleration cutoff_hz must be > 0, got {self.cutoff_hz}")
        if self.max_gap_s is not None and not (self.max_gap_s > 0 and math.isfinite(self.max_gap_s)):
            raise ConfigurationError(
                f"acceleration max_gap_s must be a finite positive number or None, got {self.max_gap_s}"
            )


@njit(cache=True, nogil=True)
def _savgol_weights(stamps_ns: np.ndarray, half: int, order: int) -> np.ndarray:
    """Least-squares derivative weights at ``stamps_ns[half]`` (1/s) for a degree-``order`` fit.

    The local times ``s = (t − t_mid)/scale`` (``scale`` = the larger end offset, so ``|s| ≤ 1``) get an
    orthonormal polynomial basis ``φ_0 … φ_order`` on the window's points by Gram–Schmidt applied twice
    (``φ_{k+1} ∝ s·φ_k`` minus its projections), tracking each ``φ_k(0)`` and ``φ_k'(0)`` through the
    same linear operations. The least-squares fit of ``y`` is ``Σ_k (φ_k·y) φ_k``, so the derivative at
    the middle is ``w·y`` with ``w = Σ_k φ_k'(0) φ_k / scale``. O(window · order²), no factorisation, and
    well conditioned for any distinct stamps (the monomial Vandermonde matrix never appears).
    """
    m = stamps_ns.shape[0]
    mid = stamps_ns[half]
    scale = float(max(abs(stamps_ns[0] - mid), abs(stamps_ns[m - 1] - mid)))
    s = np.empty(m)
    for i in range(m):
        s[i] = float(stamps_ns[i] - mid) / scale  # the int64 difference is exact
    phi = np.empty((order + 1, m))
    val0 = np.empty(order + 1)  # φ_k(0)
    der0 = np.empty(order + 1)  # φ_k'(0)
    inv = 1.0 / math.sqrt(m)
    for i in range(m):
        phi[0, i] = inv
    val0[0] = inv
    der0[0] = 0.0
    u = np.empty(m)
    for k in range(order):
        for i in range(m):
            u[i] = s[i] * phi[k, i]
        u0 = 0.0  # (s·φ_k)(0)
        u1 = val0[k]  # (s·φ_k)'(0) = φ_k(0)
        for _ in range(2):  # classical Gram–Schmidt, twice: orthogonal to rounding
            for j in range(k + 1):
                c = 0.0
                for i in range(m):
                    c += u[i] * phi[j, i]
                for i in range(m):
                    u[i] -= c * phi[j, i]
                u0 -= c * val0[j]
                u1 -= c * der0[j]
        norm = 0.0
        for i in range(m):
            norm += u[i] * u[i]
        norm = math.sqrt(norm)
        for i in range(m):
            phi[k + 1, i] = u[i] / norm
        val0[k + 1] = u0 / norm
        der0[k + 1] = u1 / norm
    weights = np.zeros(m)
    for k in range(1, order + 1):
        d = der0[k]
        for i in range(m):
            weights[i] += d * phi[k, i]
    inv_scale_s = 1e9 / scale
    for i in range(m):
        weights[i] *= inv_scale_s
    return weights


@njit(cache=True, nogil=True)
def _savgol_apply(stamps_ns: np.ndarray, vel: np.ndarray, half: int, order: int) -> np.ndarray:
    """``weights(stamps) @ vel``: the derivative (rad/s²) of each column of ``vel`` at the middle stamp."""
    weights = _savgol_weights(stamps_ns, half, order)
    m, n = vel.shape
    out = np.zeros(n)
    for i in range(m):
        w = weights[i]
        for j in range(n):
            out[j] += w * vel[i, j]
    return out


def savgol_weights_reference(stamps_ns: np.ndarray, half: int, order: int) -> np.ndarray:
    """Pure-numpy reference of the compiled weights: minimum-norm least squares on the Vandermonde matrix.

    Args:
        stamps_ns: The window's stamps (ns), strictly increasing, shape ``(m,)`` with ``m > order``.
        half: Index of the sample the derivative refers to.
        order: Polynomial degree.

    Returns:
        Weights ``w`` (1/s) with ``q̈(t_half) ≈ w · q̇_window``, shape ``(m,)``.
    """
    offsets = np.asarray(stamps_ns, dtype=np.int64) - int(stamps_ns[half])
    tau = offsets * 1e-9
    scale = max(abs(tau[0]), abs(tau[-1]))
    V = np.vander(tau / scale, order + 1, increasing=True)  # columns 1, s, s², …
    return np.linalg.lstsq(V, np.eye(len(tau)), rcond=None)[0][1] / scale


class AccelerationEstimator:
    """Common interface and stamp/gap handling of the estimators.

    Subclasses implement :meth:`_estimate`. Use :func:`make_estimator` to build one from a config.
    Stamps and velocities of the window are kept in doubled ring buffers, so the last ``m`` samples
    are always one contiguous view and an update allocates nothing but its result.

    Args:
        n_joints: Number of joints (length of each velocity vector).
        config: The settings.
    """

    def __init__(self, n_joints: int, config: AccelerationConfig) -> None:
        if n_joints < 1:
            raise ConfigurationError(f"n_joints must be >= 1, got {n_joints}")
        self.n_joints = int(n_joints)
        self.config = config
        self._w = int(config.window)
        self._max_gap_s = config.max_gap_s
        self._tring = np.zeros(2 * self._w, dtype=np.int64)
        self._ring = np.zeros((2 * self._w, self.n_joints))
        self._count = 0  # samples written since the last (re)start (ring position)
        self._m = 0  # samples in the window (≤ window)
        self._last_stamp: int | None = None
        self._mean_dt_s = math.nan  # running mean of the sample interval, for the stated delay/lag
        self._n_dt = 0

    # -- stated timing ---------------------------------------------------------------------------
    @property
    def delay_samples(self) -> int:
        """Samples between the newest input and the stamp of the estimate emitted with it."""
        return 0

    @property
    def mean_dt_s(self) -> float:
        """Mean interval between the velocities seen so far (s); NaN before two samples."""
        return self._mean_dt_s

    @property
    def delay_s(self) -> float:
        """Emission delay (s): newest input stamp minus the stamp the estimate refers to.

        ``delay_samples × mean interval`` (NaN before two samples when ``delay_samples > 0``).
        """
        return 0.0 if self.delay_samples == 0 else self.delay_samples * self._mean_dt_s

    @property
    def lag_s(self) -> float:
        """Low-frequency phase lag of the estimate behind the true q̈ at its own stamp (s)."""
        return 0.0

    # -- streaming -------------------------------------------------------------------------------
    def reset(self) -> list[Decision]:
        """Forget the history (e.g. after a gap in the stream).

        Returns:
            ``(stamp, None)`` for each received stamp that had not been decided yet.
        """
        pending = self._pending_stamps()
        self._m = 0
        self._count = 0
        self._last_stamp = None
        self._reset_filter()
        return [(s, None) for s in pending]

    def update(self, stamp_ns: int, dq: np.ndarray) -> list[Decision]:
        """Add one velocity sample and return the stamps decided by it.

        Args:
            stamp_ns: Stamp in ns, strictly after the previous one.
            dq: Joint velocities (rad/s), shape ``(n_joints,)``, finite.

        Returns:
            Decisions ``(stamp_ns, ddq | None)`` in stamp order (ddq in rad/s²): usually one; none while
            a ``savgol`` window fills past its middle; several after a gap.

        Raises:
            RejectedSampleError: Stamp not increasing, wrong shape or non-finite velocity (state unchanged).
        """
        stamp_ns = int(stamp_ns)
        dq = np.asarray(dq, dtype=np.float64)
        if dq.shape != (self.n_joints,):
            raise RejectedSampleError(f"dq must have shape ({self.n_joints},), got {dq.shape}")
        if not np.isfinite(dq).all():
            raise RejectedSampleError("dq contains NaN or inf")
        if self._last_stamp is not None and stamp_ns <= self._last_stamp:
            raise RejectedSampleError(f"stamps must increase: {stamp_ns} after {self._last_stamp}")
        return self.update_trusted(stamp_ns, dq)

    def update_trusted(self, stamp_ns: int, dq: np.ndarray) -> list[Decision]:
        """:meth:`update` without its input checks, for callers that screened the sample already.

        Args:
            stamp_ns: Stamp in ns (a Python int), strictly after the previous one.
            dq: Joint velocities (rad/s), float64, shape ``(n_joints,)``, finite (copied).

        Returns:
            As :meth:`update`. Invalid input here corrupts the estimator: use :meth:`update` unless the
            caller guarantees the preconditions (as
            :class:`~semiparam_ros.core.stream.pipeline.SamplePipeline` does).
        """
        decisions: list[Decision] | None = None
        last = self._last_stamp
        if last is not None:
            dt_s = (stamp_ns - last) * 1e-9
            gap = self._max_gap_s
            if gap is not None and dt_s > gap:
                decisions = self.reset()
            else:
                self._n_dt += 1
                if self._n_dt == 1:
                    self._mean_dt_s = dt_s
                else:
                    self._mean_dt_s += (dt_s - self._mean_dt_s) / min(self._n_dt, 1000)
        self._last_stamp = stamp_ns
        w = self._w
        k = self._count % w
        self._tring[k] = stamp_ns
        self._tring[k + w] = stamp_ns
        self._ring[k] = dq
        self._ring[k + w] = dq
        self._count += 1
        if self._m < w:
            self._m += 1
        if decisions:
            decisions.extend(self._estimate())
            return decisions
        return self._estimate()

    def _start(self) -> int:
        """Ring index of the oldest buffered sample."""
        return (self._count - self._m) % self._w

    def _window(self) -> np.ndarray:
        """Return the buffered velocities, oldest first, shape ``(m, n_joints)`` (a view)."""
        start = self._start()
        return self._ring[start : start + self._m]

    def _stamp_window(self) -> np.ndarray:
        """Return the buffered stamps (ns), oldest first, shape ``(m,)`` (a view)."""
        start = self._start()
        return self._tring[start : start + self._m]

    # -- subclass hooks --------------------------------------------------------------------------
    @property
    def window(self) -> int:
        """Samples per estimate."""
        return self._w

    def _estimate(self) -> list[Decision]:  # pragma: no cover - abstract
        raise NotImplementedError

    def _pending_stamps(self) -> list[int]:
        return []

    def _reset_filter(self) -> None:
        pass


class SavitzkyGolayEstimator(AccelerationEstimator):
    """Centred local-polynomial derivative on true stamps (zero phase, delayed by ``window // 2``).

    The first ``window // 2`` samples after a (re)start are decided ``None`` at once; the sample in the
    middle of each full window gets its estimate when the window's last sample arrives.

    The weights are recomputed for every window from its own stamps (exact for irregular stamps) by a
    compiled orthogonal-polynomial construction (:func:`_savgol_weights`, O(window · polyorder²); ≈1 µs
    for window 9, polyorder 2), equal to the least-squares weights of
    :func:`savgol_weights_reference` to rounding.

    Noise: for uniform stamps with white velocity noise σ (rad/s), the estimate's noise is
    ``σ · ‖c‖ / Δt`` with ``c`` the derivative coefficients (``scipy.signal.savgol_coeffs(window,
    polyorder, deriv=1)``), e.g. ≈ 0.13 σ/Δt for window 9, polyorder 2.
    """

    def __init__(self, n_joints: int, config: AccelerationConfig) -> None:
        super().__init__(n_joints, config)
        self._half = config.window // 2
        self._order = int(config.polyorder)
        self._n_seen = 0  # samples since the last (re)start
        # compile (or load from numba's cache) now, not at the first full window inside a 1 kHz loop
        _savgol_apply(np.arange(self._w, dtype=np.int64) + 1, self._ring[: self._w], self._half, self._order)

    @property
    def delay_samples(self) -> int:
        """``window // 2``: the estimate refers to the middle of the window."""
        return self._half

    def _reset_filter(self) -> None:
        self._n_seen = 0

    def _pending_stamps(self) -> list[int]:
        # sample i (0-based since the restart) is decided None if i < half, else when sample i + half
        # arrives; so the newest min(n_seen - half, half) samples are still undecided
        n_pending = max(0, min(self._n_seen - self._half, self._half))
        return self._stamp_window()[self._m - n_pending :].tolist() if n_pending else []

    def _estimate(self) -> list[Decision]:
        assert self._last_stamp is not None  # called after update() stored the stamp
        self._n_seen += 1
        if self._n_seen <= self._half:
            return [(self._last_stamp, None)]
        w = self._w
        if self._m < w:
            return []
        start = self._count % w  # the window is full: oldest sample right after the newest
        stamps = self._tring[start : start + w]
        ddq = _savgol_apply(stamps, self._ring[start : start + w], self._half, self._order)
        return [(int(stamps[self._half]), ddq)]


class FiniteDifferenceEstimator(AccelerationEstimator):
    """Causal finite difference over ``window`` samples, then a first-order low-pass at ``cutoff_hz``.

    The first ``window − 1`` samples after a (re)start are decided ``None``; later samples get an
    estimate at once, for their own stamp, lagging the truth by :attr:`lag_s`. The low-pass state is
    initialised with the first difference, which lags less than the settled filter; the resulting
    start-up error is at most ≈ τ · |d³q/dt³| and decays with time constant τ.
    """

    def __init__(self, n_joints: int, config: AccelerationConfig) -> None:
        super().__init__(n_joints, config)
        self._tau_s = 0.0 if math.isinf(config.cutoff_hz) else 1.0 / (2.0 * math.pi * config.cutoff_hz)
        self._state: np.ndarray | None = None

    @property
    def lag_s(self) -> float:
        """Low-frequency lag (s) at the mean interval Δt: difference plus discrete low-pass.

        ``(window − 1)/2 · Δt`` for the difference plus ``Δt · (1 − α)/α`` with ``α = 1 − exp(−Δt/τ)``
        for the low-pass (→ τ − Δt/2 for Δt ≪ τ); NaN before two samples.
        """
        dt = self._mean_dt_s
        lag = 0.5 * (self.config.window - 1) * dt
        if self._tau_s > 0.0 and dt == dt:
            alpha = -math.expm1(-dt / self._tau_s)
            lag += dt * (1.0 - alpha) / alpha
        return lag

    def _reset_filter(self) -> None:
        self._state = None

    def _estimate(self) -> list[Decision]:
        stamp = self._last_stamp
        assert stamp is not None  # called after update() stored the stamp
        if self._m < self._w:
            return [(stamp, None)]
        stamps = self._stamp_window()
        span_s = (stamp - int(stamps[0])) * 1e-9
        window = self._window()
        raw = (window[-1] - window[0]) / span_s
        if self._state is None or self._tau_s == 0.0:
            self._state = raw
        else:
            dt_s = (stamp - int(stamps[-2])) * 1e-9
            alpha = -math.expm1(-dt_s / self._tau_s)
            self._state = self._state + alpha * (raw - self._state)
        return [(stamp, self._state.copy())]


def kalman_matrices(h: float, n_states: int = 3) -> tuple[np.ndarray, np.ndarray, float]:
    """Discrete integrator-chain model for one step, in the filter's scaled units (pure numpy).

    Time is scaled by ω (``h = ω·Δt``, dimensionless) and the state is ``[q̇, q̈/ω, q⃛/ω², …]`` (all
    rad/s), ``n_states`` long (3: constant jerk, 4: constant snap); the continuous model is a chain of
    ``n_states`` integrators driven by white noise of unit density on the last derivative, observed
    through ``q̇`` with white noise of unit density. Exact zero-order discretisation:
    ``F = exp(A h)``, ``F_ij = h^(j−i)/(j−i)!``, and ``Q = ∫₀ʰ exp(A s) G Gᵀ exp(Aᵀ s) ds``,
    ``Q_ij = h^p / (p (m−1−i)! (m−1−j)!)`` with ``p = 2m − 1 − i − j``; the per-sample measurement
    variance of a unit-density white noise averaged over the step is ``R = 1/h``.

    Args:
        h: Scaled step ω·Δt (> 0).
        n_states: Length m of the state (3 or 4).

    Returns:
        ``(F, Q, R)``: transition (m, m), process covariance (m, m), measurement variance.
    """
    m = int(n_states)
    F = np.zeros((m, m))
    Q = np.empty((m, m))
    for i in range(m):
        for j in range(i, m):
            F[i, j] = h ** (j - i) / math.factorial(j - i)
        for j in range(m):
            p = 2 * m - 1 - i - j
            Q[i, j] = h**p / (p * math.factorial(m - 1 - i) * math.factorial(m - 1 - j))
    return F, Q, 1.0 / h


def kalman_step_reference(x: np.ndarray, P: np.ndarray, h: float, z: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Pure-numpy reference of one predict + update of :class:`KalmanEstimator` (scaled units).

    Args:
        x: State, shape ``(m, n_joints)`` (one column per joint; the covariance is shared, since every
            joint has the same model and the same stamps).
        P: Covariance of each column, shape ``(m, m)``.
        h: Scaled step ω·Δt (> 0).
        z: Measured velocities (rad/s), shape ``(n_joints,)``.

    Returns:
        ``(x, P)`` after the step (new arrays); the covariance by the Joseph form.
    """
    m = x.shape[0]
    F, Q, R = kalman_matrices(h, m)
    xp = F @ x
    Pp = F @ P @ F.T + Q
    H = np.zeros((1, m))
    H[0, 0] = 1.0
    S = Pp[0, 0] + R
    K = Pp[:, :1] / S
    x_new = xp + K @ (z[None, :] - xp[:1])
    IKH = np.eye(m) - K @ H
    return x_new, IKH @ Pp @ IKH.T + R * (K @ K.T)


@njit(cache=True, nogil=True)
def _kalman_step(x: np.ndarray, P: np.ndarray, h: float, z: np.ndarray) -> None:
    """In-place compiled :func:`kalman_step_reference` (same operations, explicit loops; m = x.shape[0])."""
    m, n = x.shape
    fact = np.ones(2 * m)
    for i in range(1, 2 * m):
        fact[i] = fact[i - 1] * i
    hp = np.ones(2 * m)  # powers of h
    for i in range(1, 2 * m):
        hp[i] = hp[i - 1] * h
    F = np.zeros((m, m))
    for i in range(m):
        for j in range(i, m):
            F[i, j] = hp[j - i] / fact[j - i]
    # predict: x ← F x (in place, rows top-down: row i uses rows ≥ i, not yet overwritten), P ← F P Fᵀ + Q
    for j in range(n):
        for i in range(m):
            acc = 0.0
            for k in range(i, m):
                acc += F[i, k] * x[k, j]
            x[i, j] = acc
    FP = np.zeros((m, m))
    for i in range(m):
        for c in range(m):
            acc = 0.0
            for k in range(i, m):
                acc += F[i, k] * P[k, c]
            FP[i, c] = acc
    Pp = np.empty((m, m))
    for r in range(m):
        for c in range(m):
            acc = 0.0
            for k in range(c, m):
                acc += FP[r, k] * F[c, k]
            p = 2 * m - 1 - r - c
            Pp[r, c] = acc + hp[p] / (p * fact[m - 1 - r] * fact[m - 1 - c])
    # update with the velocity measurement (variance R = 1/h)
    R = 1.0 / h
    S = Pp[0, 0] + R
    K = np.empty(m)
    for r in range(m):
        K[r] = Pp[r, 0] / S
    for j in range(n):
        innov = z[j] - x[0, j]
        for r in range(m):
            x[r, j] += K[r] * innov
    # Joseph form: (I − K H) Pp (I − K H)ᵀ + R K Kᵀ, symmetric and positive by construction
    A = np.empty((m, m))
    for r in range(m):
        for c in range(m):
            A[r, c] = Pp[r, c] - K[r] * Pp[0, c]
    for r in range(m):
        for c in range(r, m):  # upper triangle, mirrored: exactly symmetric
            v = A[r, c] - A[r, 0] * K[c] + R * K[r] * K[c]
            P[r, c] = v
            P[c, r] = v


class KalmanEstimator(AccelerationEstimator):
    """Causal Kalman filter on the joint velocities (immediate, no low-frequency lag).

    Model (per joint, continuous time), ``kalman_model="jerk"``: ``d/dt [q̇, q̈, q⃛] = [q̈, q⃛, w]`` with
    white snap ``w`` of density ``q_c`` (``"snap"``: one derivative more, white crackle); measurements
    ``q̇_k + v_k`` with white noise of density ``r_c``. Only the ratio matters for the estimate; it is set
    to ``q_c / r_c = ω^(2m)`` (m = state length, ω = 2π·``bandwidth_hz``), for which the steady-state
    Kalman–Bucy filter's error dynamics are an m-th-order Butterworth polynomial at ω: the tuning is in
    Hz and independent of the sample rate. Each step is discretised exactly with its own interval
    (:func:`kalman_matrices`), so jittered stamps are handled, and the per-sample measurement variance
    ``r_c/Δt`` keeps the filter the same continuous-time filter at any rate.

    Timing: the estimate refers to the newest stamp (``delay_s = 0``) and ``lag_s = 0``: a velocity that
    is a polynomial of degree m − 1 in time is tracked without error in steady state, so the
    low-frequency phase lag vanishes. In continuous time, with the Butterworth gains ``k``, the q̈
    estimate is ``q̈̂ = s·q̇ · (1 − (s^m + k₁ s^(m−1)) / B(s))``, ``B`` the Butterworth polynomial. For
    ``"jerk"`` (``k = (2ω, 2ω², ω³)``) a sinusoid of frequency ``f ≪ f_b`` has a relative amplitude
    overshoot ``|q̈̂/q̈| − 1 ≈ 2 (f/f_b)²`` (exactly ``√((1 + 4x²)/(1 + x⁶)) − 1``, ``x = f/f_b``) and a
    phase lag ≈ ``3 x³`` rad; for ``"snap"`` (``k₁ = 2.613 ω``) the relative error is ≈ ``2.613 x³``
    (mostly phase lead). White velocity noise is passed with a gain that grows like ``f_b^{3/2}`` —
    the trade-off the bandwidth sets. The sampled filter's exact steady-state response follows from
    its discrete steady-state gain.

    Start: the state starts diffuse at the first sample of a (re)start (velocity from that sample, the
    higher derivatives with variance :data:`KALMAN_PRIOR_VARIANCE` in scaled units); samples less than
    ``KALMAN_SETTLE[model] / ω`` after it are decided ``None`` (146 ms for snap at 6 Hz). Gaps longer
    than ``max_gap_s`` restart. Cost per sample: O(m² · n_joints) in a compiled kernel
    (:func:`_kalman_step`, equal to :func:`kalman_step_reference` to rounding); state m × n_joints and a
    shared m × m covariance.

    Args:
        n_joints: Number of joints.
        config: Settings (``method="kalman"``; ``bandwidth_hz``, ``kalman_model``, ``max_gap_s`` are used).
    """

    def __init__(self, n_joints: int, config: AccelerationConfig) -> None:
        super().__init__(n_joints, config)
        self._omega = 2.0 * math.pi * float(config.bandwidth_hz)
        m = KALMAN_STATES[config.kalman_model]
        self._x = np.zeros((m, self.n_joints))
        self._P = np.zeros((m, m))
        self._start_stamp: int | None = None
        self._settle_s = KALMAN_SETTLE[config.kalman_model] / self._omega
        self._settle_ns = self._settle_s * 1e9
        # compile (or load from numba's cache) now, not at the first sample inside a 1 kHz loop
        _kalman_step(np.zeros((m, self.n_joints)), np.eye(m), 0.1, np.zeros(self.n_joints))

    @property
    def window(self) -> int:
        """1: the filter keeps a state, not a window of samples."""
        return 1

    @property
    def omega(self) -> float:
        """Bandwidth ω = 2π·bandwidth_hz (rad/s)."""
        return self._omega

    @property
    def settle_s(self) -> float:
        """Warm-up after a (re)start during which stamps are decided ``None`` (s)."""
        return self._settle_s

    def _reset_filter(self) -> None:
        self._start_stamp = None

    def update_trusted(self, stamp_ns: int, dq: np.ndarray) -> list[Decision]:
        """See :meth:`AccelerationEstimator.update_trusted`; the estimate refers to ``stamp_ns``."""
        decisions: list[Decision] = []
        last = self._last_stamp
        if last is not None:
            dt_s = (stamp_ns - last) * 1e-9
            gap = self._max_gap_s
            if gap is not None and dt_s > gap:
                decisions = self.reset()
                last = None
            else:
                self._n_dt += 1
                if self._n_dt == 1:
                    self._mean_dt_s = dt_s
                else:
                    self._mean_dt_s += (dt_s - self._mean_dt_s) / min(self._n_dt, 1000)
        self._last_stamp = stamp_ns
        if last is None or self._start_stamp is None:
            self._start_stamp = stamp_ns
            self._x[:] = 0.0
            self._x[0] = dq
            self._P[:] = 0.0
            for i in range(1, self._P.shape[0]):
                self._P[i, i] = KALMAN_PRIOR_VARIANCE
            self._P[0, 0] = math.nan  # set from the first interval (R = 1/h), see below
            decisions.append((stamp_ns, None))
            return decisions
        h = self._omega * (stamp_ns - last) * 1e-9
        if self._P[0, 0] != self._P[0, 0]:  # second sample: the first one had the variance of this step
            self._P[0, 0] = 1.0 / h
        _kalman_step(self._x, self._P, h, dq)
        if stamp_ns - self._start_stamp < self._settle_ns:
            decisions.append((stamp_ns, None))
        else:
            decisions.append((stamp_ns, self._omega * self._x[1]))
        return decisions


def make_estimator(n_joints: int, config: AccelerationConfig | None = None) -> AccelerationEstimator:
    """Build the estimator a config asks for.

    Args:
        n_joints: Number of joints.
        config: Settings (default: ``AccelerationConfig()``, savgol window 9, polyorder 2).

    Returns:
        A :class:`SavitzkyGolayEstimator`, :class:`FiniteDifferenceEstimator` or
        :class:`KalmanEstimator` (a :class:`RateAdaptiveEstimator` around the first two when
        ``window_s`` is set).
    """
    config = config or AccelerationConfig()
    if config.method == "kalman":  # no window: window and window_s are ignored
        return KalmanEstimator(n_joints, config)
    if config.window_s is not None:
        return RateAdaptiveEstimator(n_joints, config)
    if config.method == "savgol":
        return SavitzkyGolayEstimator(n_joints, config)
    return FiniteDifferenceEstimator(n_joints, config)


def samples_for_window(window_s: float, dt_s: float, method: str = "savgol", polyorder: int = 2) -> int:
    """Convert a window in seconds to samples at the interval ``dt_s``.

    Args:
        window_s: Window length (s), > 0.
        dt_s: Sample interval (s), > 0.
        method: ``"savgol"`` (odd result, ≥ max(3, polyorder + 1 rounded up to odd)) or
            ``"finite_difference"`` (≥ 2).
        polyorder: Polynomial degree of savgol.

    Returns:
        ``2·round(window_s / (2·dt_s)) + 1`` for savgol, ``round(window_s / dt_s) + 1`` otherwise,
        raised to the smallest valid window.
    """
    if method == "savgol":
        low = max(3, int(polyorder) + 1)
        low += 1 - low % 2  # odd, above polyorder
        return max(low, 2 * round(window_s / (2.0 * dt_s)) + 1)
    return max(2, round(window_s / dt_s) + 1)


class RateAdaptiveEstimator(AccelerationEstimator):
    """An estimator whose window is given in seconds, sized at the measured joint-state rate.

    The first :data:`RATE_SAMPLES` samples (stamps and velocities) are held, undecided; the median of
    their intervals fixes the window (:func:`samples_for_window`), the inner estimator of
    ``config.method`` is built with it, and the held samples are fed to it in order. After that every
    call is forwarded. Intervals longer than ``max_gap_s`` are left out of the median (a dropout is not
    the rate). Memory: at most ``max(RATE_SAMPLES, window)`` samples.

    Args:
        n_joints: Number of joints.
        config: Settings with ``window_s`` set.
    """

    def __init__(self, n_joints: int, config: AccelerationConfig) -> None:
        if config.window_s is None:
            raise ConfigurationError("RateAdaptiveEstimator needs config.window_s")
        if n_joints < 1:
            raise ConfigurationError(f"n_joints must be >= 1, got {n_joints}")
        self.n_joints = int(n_joints)
        self.config = config
        self._inner: AccelerationEstimator | None = None
        self._held: list[tuple[int, np.ndarray]] = []

    @property
    def inner(self) -> AccelerationEstimator | None:
        """The sized estimator, or None while the rate is being measured."""
        return self._inner

    @property
    def window(self) -> int:
        """Samples per estimate; 0 while the rate is being measured."""
        return 0 if self._inner is None else self._inner.window

    @property
    def delay_samples(self) -> int:
        """As the inner estimator's (``window // 2`` for savgol); 0 before the rate is known."""
        return 0 if self._inner is None else self._inner.delay_samples

    @property
    def mean_dt_s(self) -> float:
        """Mean interval seen by the inner estimator (s); NaN before the rate is known."""
        return math.nan if self._inner is None else self._inner.mean_dt_s

    @property
    def delay_s(self) -> float:
        """Emission delay of the inner estimator (s); before the rate is known ``window_s / 2`` (savgol)."""
        if self._inner is None:
            window_s = self.config.window_s
            assert window_s is not None  # checked in __init__
            return 0.5 * window_s if self.config.method == "savgol" else 0.0
        return self._inner.delay_s

    @property
    def lag_s(self) -> float:
        """Low-frequency lag of the inner estimator (s); NaN before the rate is known (finite_difference)."""
        if self._inner is None:
            return 0.0 if self.config.method == "savgol" else math.nan
        return self._inner.lag_s

    def reset(self) -> list[Decision]:
        """Forget the history; the measured window is kept (the rate does not change with a dropout)."""
        if self._inner is not None:
            return self._inner.reset()
        held: list[Decision] = [(s, None) for s, _ in self._held]
        self._held = []
        return held

    def update(self, stamp_ns: int, dq: np.ndarray) -> list[Decision]:
        """See :meth:`AccelerationEstimator.update` (same checks, state unchanged on error)."""
        stamp_ns = int(stamp_ns)
        dq = np.asarray(dq, dtype=np.float64)
        if dq.shape != (self.n_joints,):
            raise RejectedSampleError(f"dq must have shape ({self.n_joints},), got {dq.shape}")
        if not np.isfinite(dq).all():
            raise RejectedSampleError("dq contains NaN or inf")
        last = self._held[-1][0] if self._inner is None and self._held else (
            self._inner._last_stamp if self._inner is not None else None)
        if last is not None and stamp_ns <= last:
            raise RejectedSampleError(f"stamps must increase: {stamp_ns} after {last}")
        return self.update_trusted(stamp_ns, dq)

    def update_trusted(self, stamp_ns: int, dq: np.ndarray) -> list[Decision]:
        """See :meth:`AccelerationEstimator.update_trusted`."""
        if self._inner is not None:
            return self._inner.update_trusted(stamp_ns, dq)
        self._held.append((int(stamp_ns), np.array(dq, dtype=np.float64)))
        if len(self._held) < RATE_SAMPLES:
            return []
        period = measured_period_s((s for s, _ in self._held), self.config.max_gap_s)
        if period is None:  # every interval was a dropout: keep measuring on the newest sample
            decided: list[Decision] = [(s, None) for s, _ in self._held[:-1]]
            self._held = self._held[-1:]
            return decided
        cfg = self.config
        assert cfg.window_s is not None  # checked in __init__
        window = samples_for_window(cfg.window_s, period, cfg.method, cfg.polyorder)
        sized = AccelerationConfig(method=cfg.method, window=window, polyorder=cfg.polyorder,
                                   cutoff_hz=cfg.cutoff_hz, max_gap_s=cfg.max_gap_s)
        inner = SavitzkyGolayEstimator(self.n_joints, sized) if cfg.method == "savgol" else \
            FiniteDifferenceEstimator(self.n_joints, sized)
        self._inner = inner
        held, self._held = self._held, []
        decisions: list[Decision] = []
        for s, v in held:
            decisions.extend(inner.update_trusted(s, v))
        return decisions


def estimate_accelerations(
    stamps_ns: np.ndarray, dq: np.ndarray, config: AccelerationConfig | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Run an estimator over a whole recording (offline convenience, e.g. to compare with ground truth).

    Gives exactly what the streaming estimator would produce for the same samples.

    Args:
        stamps_ns: Stamps in ns, shape ``(N,)``, strictly increasing.
        dq: Joint velocities (rad/s), shape ``(N, n)`` (or ``(N,)`` for one joint), finite.
        config: Estimator settings (default ``AccelerationConfig()``).

    Returns:
        ``(stamps_ns, ddq)``: the stamps that got an estimate, shape ``(m,)`` int64, and the estimates
        in rad/s², shape ``(m, n)``.

    Raises:
        RejectedSampleError: Mismatched shapes, stamps not increasing, or non-finite velocities.
    """
    stamps = np.asarray(stamps_ns)
    vel = np.asarray(dq, dtype=np.float64)
    if vel.ndim == 1:
        vel = vel[:, None]
    if stamps.ndim != 1 or vel.ndim != 2 or vel.shape[0] != stamps.shape[0]:
        raise RejectedSampleError(f"stamps_ns (N,) and dq (N, n) must match, got {stamps.shape} and "
                                  f"{np.shape(dq)}")
    estimator = make_estimator(vel.shape[1], config)
    out_stamps: list[int] = []
    out_ddq: list[np.ndarray] = []
    for stamp, v in zip(stamps.tolist(), vel, strict=True):
        for ref, ddq in estimator.update(int(stamp), v):
            if ddq is not None:
                out_stamps.append(ref)
                out_ddq.append(ddq)
    ddq_arr = np.stack(out_ddq) if out_ddq else np.empty((0, vel.shape[1]))
    return np.asarray(out_stamps, dtype=np.int64), ddq_arr
