"""A semiparametric model that stays a model: a consistent, abstaining residual plus a fast error tracker.

The paper's cascade (:class:`~semiparam_ros.core.learners.cascade.SemiparametricModel`) is an excellent
one-step-ahead predictor and a poor *model*: trained on one motion and used without updates on another it
is worse than its own rigid-body part, because (a) its residual learned the targets ``y − Φ(x)π̂_t`` while
π̂_t was still moving, so it is inconsistent with the final π̂; (b) random Fourier features are global
cosines, so away from the data the residual does not fall back to zero; (c) its one-step accuracy comes
from the residual stage tracking the latest samples, which says nothing about other states. This model
separates the two jobs (two time scales) and publishes them apart.

**1. Rigid-body part** — the cascade's parametric stage, fitted alone and first (the physical model keeps
priority): π̂ = π₀ + δ̂ regularized toward the prior π₀ (the URDF's parameters); the model predicts
``ŷ_P = Φ(x)θ_ref`` with its reference θ_ref (π̂ at most :attr:`REFERENCE_PERIOD` old, or the consistent
rigid body set by :meth:`use_rigid`; section 2).

**2. Consistent residual** (the slow part: the model's correction). The residual of rigid-body
parameters θ = π₀ + δ over all the data seen (with the learners' forgetting β),

    W(δ) = argmin_W Σ_m β^{n−m} ‖y_m − Φ_m π₀ − Φ_m δ − Wᵀφ_m‖² + λ‖W‖²  =  A⁻¹(B_y − Σ_k B_Φk δ),

is linear in δ. The model predicts with a **reference** θ_ref: the rigid body set by :meth:`use_rigid`
(the node's physically consistent projection), or else the learned π̂, followed every
:attr:`REFERENCE_PERIOD` of learned samples. One random-feature
:class:`~semiparam_ros.core.learners.rrls.RecursiveRLS` regresses ``y − Φθ_ref`` on ``φ(s(x))`` (t
columns, like the cascade's), and the cross-products ``B_E = Σ_m β^{n−m} φ_m Φ_E,mᵀ`` of the features
with the regressor's non-zero entries are kept beside it
(:class:`~semiparam_ros.core.learners.cross_products.EntryCrossProducts`: one matrix product per 32
samples, on a worker thread off the sample path). A new reference θ changes the learner's right-hand side
by ``−B_E S(θ − θ_ref)`` (S scatters the change over the entries): one triangular solve with t right-hand
sides (:meth:`RecursiveRLS.shift_rhs`) makes it exactly the learner that learned ``y − Φθ`` from the
start. So ``r = φᵀA⁻¹B(θ_ref)`` is the residual of the rigid body the model predicts with: it never goes
stale when the rigid body moves (the consistency correction of adaptive semiparametric dynamics learning,
here exact), and other parameters θ' are predicted with ``r − (φᵀA⁻¹B_E) S(θ' − θ_ref)`` (two triangular
solves: off the sample path).

**3. The residual's weight.** The same forward substitution gives the residual stage's relative
predictive variance ``v = φA⁻¹φᵀ`` (``ν = λv`` is the fraction of its prior variance left at x: ≈ 0 where
the data determine the residual, about 1 far from it). The residual is used per output with the weight
``g = s²(1 − ν)/(s²(1 − ν) + σ²v/ν₀)`` (:meth:`residual_weight`; ``novelty_scale`` ν₀): s² the variance
of the rigid-body part's *recent* systematic error, s²(1 − ν) the part of it the data explain at x, σ²
the residual's noise variance, σ²v its predictive variance at x. Where the rigid body is poor, a residual
of moderate confidence is used; where it is excellent, the model abstains unless the residual is
confident, and far from the data it falls back to its rigid-body part instead of extrapolating cosines.
**model(x) = ŷ_P + g·r** is what is used frozen, at desired states and for feed-forward. Its variance
(:meth:`model_variance`, what ``predict_model`` reports) is the error variance of ``ŷ_P + g·r`` as an
estimate of the rigid body's systematic error — what the weight misses of the part the data explain, the
residual's own error counted with the length c over which its errors stay correlated
(:meth:`correlation_samples`: consecutive samples of one motion are not independent), and the part the
data do not explain. The online prediction's variance stays the residual's own ``v``: its errors are the
fast correction's, one step ahead.

The online weight is 0 on an output where a copy of the residual a tenth to two tenths of a second old
does worse than its own rigid body on the samples learned since, by more than two standard errors
(:meth:`residual_use`): a residual that fits what belongs to time (errors correlated over a tenth of a
second) helps one step ahead and harms a moment later, and the online prediction is then its rigid part
and fast correction. The model used alone (below) keeps its served weight, which already counts the
residual's error over the length its errors stay correlated.

**4. Fast correction** (the tracker: one step ahead, payloads, contacts). Two parts, both learned only
from the samples the model learns (the contact gate's refusals are held out of them too):

* a *fast rigid-body correction* ``Φ(x) δ_f``: recursive ridge regression of the model's error
  ``e = y − model(x)`` on the regressor rows with a short memory (``tracker_time_constant`` τ_f, but at
  least 10 rows per parameter: β = exp(−1/N), N = max(τ_f/T, 10p/t) samples once the sample period T is
  known): a payload or a drift of the inertial parameters is a change ``Φ(x)Δπ``, which it follows
  within about τ_f and carries to nearby states through Φ (it fades like the local tracker below, over
  :attr:`FAST_FADE` times its distances). It is used with the weight ``w = max(0, 1 − 9r̂v/c²)`` of its
  value c against its own standard deviation ``√(r̂v)`` (v the fast learner's relative predictive
  variance, r̂ the noise variance of the model's error estimated by the tracker: the correction counts
  only as far as it stands out from its noise by three standard deviations, at once for a payload), and
  only on the outputs where it recently saved a significant part of the one-step squared error: where it
  only fits noise (a model already at the noise floor) it adds nothing;
* a *local error tracker* for the rest, ``e − wΦδ_f`` (:class:`ErrorTracker`): a bank of exponential
  smoothers of the error with gains K ∈ {0, 0.1, 0.3, 1} (none, averages, the last error carried over),
  the one with the smallest recent one-step error used per output — K = 1 where the error drifts faster
  than its noise (persistence of the model's error), K = 0 where noise dominates; the chosen estimate is
  shrunk by the noise it carries, ``b̂·max(0, 1 − 4r̂K/(2 − K)/b̂²)`` (r̂ the error's white-noise
  variance), so that a smoother chosen for a lucky streak of noise adds (almost) nothing
  (:attr:`ErrorTracker.used_estimate`). The estimate ``b̂`` was
  made at the state ``x_b`` of the last learned sample and is used at x with the weight
  ``κ = exp(−½ Σ_j [((q_j − q_b,j)/ℓ_q)² + ((q̇_j − q̇_b,j)/ℓ_q̇)²])``: one step later κ ≈ 1, at a state far
  from the last learned one (a model h seconds old, a desired state, a new motion) κ → 0.

Both parts also fade with the **age** of the learned state, per output by ``α = exp(−a/τ)``
(:meth:`age_fades`; a = :attr:`prediction_age_s`, the sample period times the samples between the newest
learned sample and the predicted one, set by the estimator from the stamps; τ = min(τ_f, ½(1 + c)T), the
shorter of the correction's memory and the time the output's errors stay correlated): one sample after a
learned one α = 1; through a contact the gate holds out, or for a model queried h seconds after its last
update, the correction of errors that old fades out — at once where the errors are white, over the
memory it was learned with where they persist (a payload, a drift).

Prediction: ``model(x) + α(w Φ(x)δ_f + κ b̂)``; a frozen model is ``model(x)`` (:meth:`predict_model`),
its residual weighted for the error it has on other motion: the residual's errors stay correlated over
c samples (:meth:`correlation_samples`), so its error there is ``c σ² v`` rather than ``σ² v``
(:meth:`residual_weight` with ``served``).

Parts (:class:`~semiparam_ros.core.learners.contract.Prediction`): ``parametric = ŷ_P``,
``residual = g·r + correction``, ``correction = wΦδ_f + κb̂`` (so ``total − correction`` is model(x)),
``variance`` the relative variance of the rigid-body part plus the residual stage's.

Units: x = [q, q̇, q̈] (rad, rad/s, rad/s²), y in N and N·m (wrench in the sensor frame) or N·m (joint
torques); ℓ_q in rad, ℓ_q̇ in rad/s.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.linalg import solve_triangular

from semiparam_ros.core.learners._consistent_kernels import (
    aged_saving_step,
    fast_total,
    model_alone_one,
    saving_step,
    scale_step,
    shrunk_choice,
    significant_saving,
    stage_pending,
    state_weight,
    tracker_step,
    weighted_residual,
)
from semiparam_ros.core.learners.adaptation import forgetting_factor
from semiparam_ros.core.learners.base import Regressor, checked_rigid
from semiparam_ros.core.learners.contract import Prediction, PredictionContext
from semiparam_ros.core.learners.cross_products import EntryCrossProducts
from semiparam_ros.core.learners.features import Standardizer
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.core.learners.two_stage import TwoStageModel
from semiparam_ros.core.validation import check_finite_array, check_positive_int, check_range
from semiparam_ros.errors import CheckpointError

__all__ = ["ConsistentSemiparametricModel", "ErrorTracker", "structural_entries"]


class ErrorTracker:
    """Smoothers of a model's recent error, the best of them chosen by its recent one-step accuracy.

    A bank of exponential smoothers ``b_K ← b_K + K(e − b_K)`` of the model's error e, one per gain K in
    :attr:`GAINS` (K = 0: no correction, the model alone; K = 1: the last error carried over; in between,
    averages over about 1/K samples — the steady-state Kalman filters of a drifting error seen through
    noise, for drift-to-noise ratios from none to large). Each smoother's a-priori one-step squared error
    is averaged over about ``stats_samples`` learned samples, and per output the smoother with the
    smallest one is used: where the error drifts faster than its noise, K → 1; where noise dominates (a
    model at the noise floor), K = 0 and the tracker adds nothing. The choice needs no model of the noise
    and follows a change of regime within ``stats_samples`` samples. The correction uses the chosen
    estimate shrunk by the noise it carries (:attr:`used_estimate`).

    An estimate made at the state ``x_b`` of the last learned sample is used at x with the weight
    ``κ = exp(−½ Σ_j [((q_j − q_b,j)/ℓ_q)² + ((q̇_j − q̇_b,j)/ℓ_q̇)²])``. The increments of the error
    also give its white-noise variance per output (``r̂ = −E[d_m d_{m−1}]``, d the increments), used by
    the fast rigid-body correction (:meth:`noise_variance`).

    Args:
        n_outputs: t, the number of outputs.
        n_joints: n (the state coordinates are q and q̇ of the n joints).
        position_scale: ℓ_q [rad] of the fading weight.
        velocity_scale: ℓ_q̇ [rad/s] of the fading weight.
        stats_samples: About how many learned samples the running statistics average over.

    Raises:
        ConfigurationError: Invalid sizes or scales.

    Example:
        >>> import numpy as np
        >>> tr = ErrorTracker(1, 1, position_scale=0.1, velocity_scale=1.0, stats_samples=5)
        >>> x = np.array([0.0, 0.0, 0.0])  # q, q̇, q̈ of one joint
        >>> for _ in range(20):  # the model is 0.5 too low, without noise: carry the error over
        ...     tr.update(x, np.array([0.5]), np.array([0.0]))
        >>> tr.correction(x).round(3).tolist()
        [0.5]
        >>> float(tr.correction(np.array([1.0, 0.0, 0.0]))[0]) < 1e-10  # 10 ℓ_q away: nothing
        True
    """

    #: Gains of the smoothers: none, about 10 and 3 samples averaged, the last error.
    GAINS = np.array([0.0, 0.1, 0.3, 1.0])

    def __init__(self, n_outputs: int, n_joints: int, *, position_scale: float, velocity_scale: float,
                 stats_samples: int = 20) -> None:
        self.n_outputs = check_positive_int("n_outputs", n_outputs)
        self.n_joints = check_positive_int("n_joints", n_joints)
        pos = check_range("position_scale", position_scale, 0.0, lo_inclusive=False)
        vel = check_range("velocity_scale", velocity_scale, 0.0, lo_inclusive=False)
        self.stats_samples = check_positive_int("stats_samples", stats_samples, minimum=2)
        n = self.n_joints
        self._inv_scale = np.concatenate([np.full(n, 1.0 / pos), np.full(n, 1.0 / vel)])
        self.position_scale, self.velocity_scale = float(pos), float(vel)
        self.reset()

    def reset(self) -> None:
        """Forget the estimates and the statistics."""
        t, k = self.n_outputs, len(self.GAINS)
        self.estimates = np.zeros((k, t))     # b_K (units of y)
        self.errors = np.zeros((k, t))        # running a-priori squared error of each smoother
        self.state: np.ndarray | None = None  # scaled [q, q̇] of the last learned sample
        self.last_error = np.zeros(t)         # e of the last learned sample
        self.last_increment = np.zeros(t)     # its increment e − e_prev
        self.cov_increment = np.zeros(t)      # running E[d_m d_{m−1}]
        self.n_errors = 0                     # learned samples seen
        self._used: np.ndarray | None = None   # used_estimate, until the next update
        self._noise: np.ndarray | None = None  # noise_variance(), until the next update

    def weight(self, x: np.ndarray) -> float:
        """κ ∈ [0, 1] at the state x = [q, q̇, q̈] (0 before any learned sample)."""
        if self.state is None:
            return 0.0
        return float(state_weight(x, self._inv_scale, self.state))

    @property
    def chosen(self) -> np.ndarray:
        """Index into :attr:`GAINS` of the smoother used, per output (K = 0 until 2 errors are seen)."""
        if self.n_errors < 2:
            return np.zeros(self.n_outputs, dtype=np.int64)
        return np.argmin(self.errors, axis=0)

    @property
    def estimate(self) -> np.ndarray:
        """b̂ (t,): the chosen smoother's estimate per output, units of y."""
        return self.estimates[self.chosen, np.arange(self.n_outputs)]

    @property
    def used_estimate(self) -> np.ndarray:
        """The chosen estimate shrunk by its own noise: ``b̂ · max(0, 1 − z²·r̂K/(2 − K)/b̂²)`` per output.

        ``r̂K/(2 − K)`` is the variance a smoother of gain K keeps of white noise of variance r̂
        (:meth:`noise_variance`): an estimate that does not stand out from it by z = 2 standard deviations
        is noise carried over and is not used.
        """
        used = self._used
        if used is None:  # (compiled: the smallest running error's smoother, shrunk)
            used = self._used = np.empty(self.n_outputs)
            shrunk_choice(self.estimates, self.errors, self.GAINS, self.noise_variance(), self.SHRINK_Z ** 2,
                          self.n_errors >= 2, used)
        return used

    #: Standard deviations by which an estimate must stand out from its noise to be used.
    SHRINK_Z = 2.0

    def correction(self, x: np.ndarray) -> np.ndarray:
        """``κ(x) b̂`` (t,), units of y, with b̂ the :attr:`used_estimate`."""
        return self.weight(x) * self.used_estimate

    def noise_variance(self) -> np.ndarray:
        """r̂ (t,): the white-noise variance of the error, ``max(0, −E[d_m d_{m−1}])`` [units of y²]."""
        noise = self._noise
        if noise is None:
            noise = self._noise = np.maximum(-self.cov_increment, 0.0)
        return noise

    def update(self, x: np.ndarray, y: np.ndarray, model: np.ndarray, weight: float | None = None) -> None:
        """Absorb a learned sample: its state x, measurement y and the model's a-priori prediction.

        Args:
            x: The state ``[q, q̇, q̈]`` (validated, finite).
            y: The measurement (t,).
            model: The prediction the error is relative to (t,).
            weight: ``weight(x)`` if already computed for this state (nothing updated since).
        """
        if weight is None:
            weight = self.weight(x)
        if self.state is None:
            self.state = np.empty(2 * self.n_joints)
        t = self.n_outputs
        noise, used = np.empty(t), np.empty(t)  # new arrays: values handed out before stay as they were
        # e = y − model: the increments' covariance, the smoothers, the state, r̂ and b̂ (one compiled call)
        tracker_step(self.estimates, self.errors, self.GAINS, self.last_error, self.last_increment,
                     self.cov_increment, self.state, self._inv_scale, x, y, model, weight, self.n_errors,
                     self.stats_samples, self.SHRINK_Z ** 2, noise, used)
        self._noise, self._used = noise, used
        self.n_errors += 1

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the tracker's state as arrays."""
        return {
            f"{prefix}estimates": self.estimates.copy(),
            f"{prefix}errors": self.errors.copy(),
            f"{prefix}state": np.zeros(0) if self.state is None else self.state.copy(),
            f"{prefix}last_error": self.last_error.copy(),
            f"{prefix}last_increment": self.last_increment.copy(),
            f"{prefix}cov_increment": self.cov_increment.copy(),
            f"{prefix}n_errors": np.array(self.n_errors),
        }

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Replace the state (validated first: sizes and finiteness).

        Raises:
            CheckpointError: Missing keys, wrong sizes or non-finite values.
        """
        t, n, k = self.n_outputs, self.n_joints, len(self.GAINS)
        try:
            vals = {name: np.asarray(state[f"{prefix}{name}"], dtype=np.float64)
                    for name in ("last_error", "last_increment", "cov_increment")}
            banks = {name: np.asarray(state[f"{prefix}{name}"], dtype=np.float64)
                     for name in ("estimates", "errors")}
            st = np.asarray(state[f"{prefix}state"], dtype=np.float64)
            n_errors = int(state[f"{prefix}n_errors"])
        except KeyError as err:
            raise CheckpointError(f"state is missing key {err}") from err
        bad = (any(v.shape != (t,) or not np.isfinite(v).all() for v in vals.values())
               or any(v.shape != (k, t) or not np.isfinite(v).all() for v in banks.values())
               or bool((banks["errors"] < 0).any()) or n_errors < 0
               or (st.size and (st.shape != (2 * n,) or not np.isfinite(st).all())))
        if bad:
            raise CheckpointError("tracker state has the wrong sizes or non-finite values")
        # own, writable copies: the update changes them in place
        self.estimates = np.ascontiguousarray(banks["estimates"]).copy()
        self.errors = np.ascontiguousarray(banks["errors"]).copy()
        self._used = self._noise = None
        self.last_error, self.last_increment = vals["last_error"].copy(), vals["last_increment"].copy()
        self.cov_increment = vals["cov_increment"].copy()
        self.state = st.copy() if st.size else None
        self.n_errors = n_errors


def structural_entries(regressor: Regressor, n_inputs: int, n_outputs: int, n_params: int,
                       samples: int = 8) -> np.ndarray:
    """Flat indices of the entries of ``Φ(x)`` (t × p) that are not identically zero.

    Found at ``samples`` random inputs (standard normal, a fixed seed: the same indices every time): an
    entry zero at all of them is structurally zero (a smooth function of the state vanishing on a set of
    measure zero is not hit by chance).

    Args:
        regressor: Maps x (n_inputs,) to Φ (n_outputs, n_params).
        n_inputs: Length of x.
        n_outputs: t.
        n_params: p.
        samples: Random inputs tried.

    Returns:
        Sorted int64 indices into ``Φ.reshape(-1)``.

    Example:
        >>> import numpy as np
        >>> structural_entries(lambda x: np.array([[x[0], 0.0], [1.0, x[1] ** 2]]), 2, 2, 2)
        array([0, 2, 3])
    """
    rng = np.random.default_rng(20161)
    nonzero = np.zeros(n_outputs * n_params, dtype=bool)
    for _ in range(samples):
        Phi = np.asarray(regressor(rng.standard_normal(n_inputs)), dtype=np.float64)
        nonzero |= Phi.reshape(-1) != 0.0
    return np.flatnonzero(nonzero).astype(np.int64)


class _Context(PredictionContext):
    """A prediction context that also keeps the local tracker's reference prediction and weight at x."""

    __slots__ = ("fast_candidate", "kappa", "model_only", "model_total", "raw_residual", "reference",
                 "residual_variance")

    def __init__(self, prediction: Prediction, model: Any, x: np.ndarray, Phi: np.ndarray | None,
                 phi: np.ndarray | None, model_total: np.ndarray, kappa: float,
                 raw_residual: np.ndarray | None, fast_candidate: np.ndarray, model_only: np.ndarray,
                 reference: np.ndarray, residual_variance: float | None = None) -> None:
        super().__init__(prediction, model, x, Phi, phi)
        self.model_total = model_total
        self.model_only = model_only  # model(x) = ŷ_P + g·r, without the fast corrections
        self.reference = reference  # θ_ref the rigid-body part ŷ_P was predicted with
        self.kappa = kappa  # the tracker's weight at x
        self.raw_residual = raw_residual  # r before its weight (None before the residual is ready)
        self.fast_candidate = fast_candidate  # κ_f Φδ_f at x before its weight (zeros without a tracker)
        self.residual_variance = residual_variance  # v = φA⁻¹φᵀ at x (None before the residual is ready)


class ConsistentSemiparametricModel(TwoStageModel):
    """Rigid-body part, consistent abstaining residual and fast error tracker (see the module docstring).

    Args:
        regressor: Maps x to ``Φ(x)`` (n_outputs, n_params).
        n_params: p, number of (base) parameters.
        n_inputs: Length of x (3 × joints).
        n_outputs: t, length of y.
        lam_parametric: λ of the rigid-body part.
        lam_nonparametric: λ of the residual (prior precision of its weights).
        n_features: D random features of the residual (input: the standardized x).
        sigma: Kernel width in standardized units of x.
        forgetting_parametric: β of the rigid-body part (per sample).
        forgetting_nonparametric: β of the residual (per sample).
        seed: Seed of the random features.
        standardizer: Optional fitted :class:`Standardizer` for x.
        standardizer_warmup: Online warm-up of the standardizer (samples; 0 = identity); the residual is
            zero and the rigid-body part learns alone until it is over.
        standardizer_min_scale: Floors of the warm-up's scales (units of x).
        prior: Prior mean π₀ of the rigid-body parameters (default zero).
        novelty_scale: ν₀ > 0 of the residual's weight ``s²(1 − ν)/(s²(1 − ν) + σ²v/ν₀)``.
        tracker: Whether the fast correction is used (False: the prediction is model(x)).
        tracker_position_scale: ℓ_q [rad] of the tracker's fading weight.
        tracker_velocity_scale: ℓ_q̇ [rad/s] of the tracker's fading weight.
        tracker_samples: Learned samples the tracker's statistics (its choice of smoother, the noise
            variance) average over.
        tracker_time_constant: τ_f [s], memory of the fast rigid-body correction (its ridge λ is
            ``lam_parametric``, toward zero).
        sample_period_s: Provisional sample period [s] converting τ_f until :meth:`on_period`.

    Raises:
        ConfigurationError: Invalid sizes or hyperparameters.

    Example:
        >>> import numpy as np
        >>> line = lambda x: np.array([[x[0], 1.0]])  # rigid part y = a·q + b (one joint)
        >>> m = ConsistentSemiparametricModel(line, 2, 3, 1, lam_parametric=1e-6, lam_nonparametric=1e-3,
        ...                                   n_features=300, sigma=1.0, standardizer_warmup=50)
        >>> q = np.linspace(-1.0, 1.0, 400)
        >>> for qi in q:
        ...     m.learn_one([qi, 0.0, 0.0], [3.0 * qi + 1.0 + 0.2 * np.sin(3.0 * qi)])
        >>> pred = m.predict_one([0.3, 0.0, 0.0])
        >>> bool(abs(pred.total[0] - pred.correction[0] - (1.9 + 0.2 * np.sin(0.9))) < 0.02)  # the model
        True
        >>> far = m.predict_model([30.0, 0.0, 0.0])  # far outside the data: (almost) its rigid-body part
        >>> bool(abs(far.total[0] - far.parametric[0]) < 0.02)
        True
    """

    _kind = "semiparametric_consistent"

    def __init__(self, regressor: Regressor, n_params: int, n_inputs: int, n_outputs: int, *,
                 lam_parametric: float = 1.0, lam_nonparametric: float = 1.0, n_features: int = 500,
                 sigma: float = 1.0, forgetting_parametric: float = 1.0,
                 forgetting_nonparametric: float = 1.0, seed: int = 0,
                 standardizer: Standardizer | None = None, standardizer_warmup: int = 0,
                 standardizer_min_scale: Any = 0.0, prior: Any = None, novelty_scale: float = 1.0,
                 tracker: bool = True, tracker_position_scale: float = 0.05,
                 tracker_velocity_scale: float = 0.5, tracker_samples: int = 50,
                 tracker_time_constant: float = 0.3, sample_period_s: float = 0.01) -> None:
        self.parametric = ParametricModel(regressor, n_params, n_outputs, lam=lam_parametric,
                                          forgetting=forgetting_parametric, prior=prior)
        p, t = self.parametric.n_params, self.parametric.n_outputs
        # the residual regresses y and the entries of Φ that are not identically zero (about half of a
        # joint-torque regressor's: a joint's torque does not depend on the bodies before it, friction
        # columns are diagonal); the others would only be learned as zeros at the cost of their columns
        self._phi_entries = structural_entries(regressor, int(n_inputs), t, p)
        self._entry_rows = self._phi_entries // p  # output row and parameter column of each entry
        self._entry_cols = self._phi_entries % p
        self.nonparametric = NonparametricModel(int(n_inputs), t,
                                                n_features=n_features,
                                                sigma=sigma, lam=lam_nonparametric,
                                                forgetting=forgetting_nonparametric, seed=seed,
                                                standardizer=standardizer,
                                                standardizer_warmup=standardizer_warmup,
                                                standardizer_min_scale=standardizer_min_scale)
        self.n_inputs = int(n_inputs)
        self.n_outputs = t
        self.n_params = p
        self.novelty_scale = check_range("novelty_scale", novelty_scale, 0.0, lo_inclusive=False)
        self.use_tracker = bool(tracker)
        self.tracker = ErrorTracker(t, max(1, self.n_inputs // 3), position_scale=tracker_position_scale,
                                    velocity_scale=tracker_velocity_scale, stats_samples=tracker_samples)
        self.tracker_time_constant = check_range("tracker_time_constant", tracker_time_constant, 0.0,
                                                 lo_inclusive=False)
        self.fast = RecursiveRLS(p, 1, lam_parametric, forgetting=self._fast_forgetting(sample_period_s))
        self.n_samples_seen = 0
        self._held: tuple[np.ndarray, float] | None = None  # (g·r, its relative variance) last computed
        self._raw: np.ndarray | None = None  # r, before its weight, of the last full prediction
        self._fast_candidate = np.zeros(t)   # κ_f Φδ_f of the last full prediction
        self._model_only = np.zeros(t)       # model(x) of the last full prediction
        self._rigid: np.ndarray | None = None  # the rigid-body parameters predicted with (None: learned)
        # the residual learner regresses y − Φθ_ref for the reference θ_ref the model predicts with; the
        # cross-products of its features with the learned regressor entries re-reference it exactly
        self._reference = self.parametric.prior.copy()   # θ_ref (learner units)
        self._cross = EntryCrossProducts(self.nonparametric.rls.n_features, self._phi_entries.size)
        self._since_reference = 0  # learned samples since θ_ref last followed π̂
        self._reference_samples = self._reference_count(sample_period_s)
        self._aged_samples = max(round(self.AGED_COPY_S / float(sample_period_s)), 1)  # between copies
        self._recent_beta = self._scale_forgetting(sample_period_s)
        self._corr_beta = self._correlation_forgetting(sample_period_s)
        self._period_s = float(sample_period_s)  # T [s]: what the age fade counts c's samples in
        self._no_fade = np.ones(t)
        self._no_fade.flags.writeable = False
        self._reset_scales()

    def _reset_scales(self) -> None:
        self._scale_weight = 0.0                       # Σ β^{n−m} over the samples the residual learned
        self._scale_model = np.zeros(self.n_outputs)   # Σ β^{n−m} (y − ŷ_P − r)²: σ² × the weight
        self._recent_rigid = np.zeros(self.n_outputs)  # recent mean of (y − ŷ_P)² (SCALE_TIME_CONSTANT)
        self._recent_n = 0                             # samples in it
        self._fast_errors = np.zeros((2, self.n_outputs))  # recent mean of d and d², d the fast saving
        self._corr = np.zeros((2, self.n_outputs))     # smoothed residual error m, Σ β^{n−m} m² (its memory)
        self._fast_n = 0                               # samples in them
        self._aged_errors = np.zeros((2, self.n_outputs))  # mean of d and d², d the aged residual's saving
        self._aged_n = 0                                   # samples in them
        self._residual_use = np.ones(self.n_outputs, dtype=np.bool_)  # residual_use()
        self._aged_copies: list[tuple[np.ndarray, np.ndarray] | None] = [None, None]  # (θ_ref, W)
        self._aged_count = 0                               # learned samples since the newer copy
        self._weight_cache: tuple[np.ndarray, np.ndarray] | None = None  # (s², σ²/ν₀) until the next learn
        self._fast_mask: np.ndarray | None = None      # _fast_useful() until the next learn
        self._shift_cache: tuple[tuple[int, bytes], np.ndarray] | None = None  # _rigid_shift's last Ω
        self._served_cache: tuple[Any, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None

    #: The fast rigid-body correction fades like the local tracker but over this many times its distances
    #: (it is a rigid-body correction, valid further from where it was learned than a local error).
    FAST_FADE = 4.0

    #: The fast correction remembers at least this many rows per parameter (a statistical floor: p
    #: parameters need several times p equations before a noisy fit is worth adding to the prediction).
    FAST_ROWS_PER_PARAMETER = 10

    #: Memory [s] of the rigid-body part's recent error scale s² in the residual's weight (at least
    #: :attr:`SCALE_MIN_SAMPLES` samples): how quickly the model trusts its residual more where the rigid
    #: body turns out poor on a new motion.
    SCALE_TIME_CONSTANT = 1.0
    SCALE_MIN_SAMPLES = 10

    def _scale_forgetting(self, sample_period_s: float) -> float:
        """β_s = exp(−1/N) of the recent error scale, N = max(SCALE_TIME_CONSTANT/T, SCALE_MIN_SAMPLES)."""
        samples = max(self.SCALE_TIME_CONSTANT / float(sample_period_s), float(self.SCALE_MIN_SAMPLES))
        return forgetting_factor(samples, 1.0)

    #: Without a rigid body set by :meth:`use_rigid`, the reference θ_ref follows the learned π̂ every this
    #: many seconds of learned samples (at least :attr:`REFERENCE_MIN_SAMPLES`; at first after 1, 2, 4, …
    #: samples): the model's rigid part and its residual are those of π̂ at most that old (one triangular
    #: solve with t right-hand sides each time, instead of regressing every regressor entry at every
    #: sample).
    REFERENCE_PERIOD = 0.5
    REFERENCE_MIN_SAMPLES = 10

    def _reference_count(self, sample_period_s: float) -> int:
        """Learned samples between two re-references: max(REFERENCE_PERIOD/T, REFERENCE_MIN_SAMPLES)."""
        return max(round(self.REFERENCE_PERIOD / float(sample_period_s)), self.REFERENCE_MIN_SAMPLES)

    def _rereference(self, theta: np.ndarray) -> None:
        """Make θ the reference: the residual learner becomes exactly the one that learned ``y − Φθ``.

        Its right-hand side changes by ``−Σ_m β^{n−m} φ_m (Φ_m (θ − θ_ref))ᵀ = −B_E S`` (S scattering θ −
        θ_ref over the learned entries): ``d ← d − R⁻ᵀ B_E S``, one triangular solve with t right-hand
        sides (:meth:`RecursiveRLS.shift_rhs`).
        """
        change = theta - self._reference
        if self._scale_weight > 0.0 and self._phi_entries.size and np.any(change != 0.0):
            self.nonparametric.rls.shift_rhs(self._cross.settled() @ self._scatter(change))
        self._reference = np.array(theta, dtype=np.float64)
        self._since_reference = 0

    def _scatter(self, change: np.ndarray) -> np.ndarray:
        """Return S (E, t): a change of the rigid-body parameters (p,) put on the learned entries' outputs."""
        scatter = np.zeros((self._phi_entries.size, self.n_outputs))
        scatter[np.arange(self._phi_entries.size), self._entry_rows] = change[self._entry_cols]
        return scatter

    def _rigid_shift(self, change: np.ndarray) -> np.ndarray:
        """``Ω = A⁻¹ B_E S`` (D, t): what predicting with θ_ref + ``change`` takes off the residual's weights.

        S scatters ``change`` over the learned entries (:meth:`_scatter`, as :meth:`_rereference`), so
        ``φΩ`` is ``Σ_e (φA⁻¹B_E)_e change_{c(e)}`` per output: two triangular solves with t right-hand
        sides, cached until the residual learns again (a served copy predicts with one projection for its
        whole life, and a per-cycle answer is then one product with Ω instead of two solves with the D × D
        factor).
        """
        rls = self.nonparametric.rls
        key = (rls.n_steps, change.tobytes())
        cached = self._shift_cache
        if cached is not None and cached[0] == key:
            return cached[1]
        R = rls.R
        rhs = self._cross.with_pending() @ self._scatter(change)  # B_E S (D, t)
        shift = solve_triangular(R, solve_triangular(R, rhs, trans="T", lower=False, check_finite=False),
                                 lower=False, check_finite=False)
        self._shift_cache = (key, shift)
        return shift

    def _entries_residual(self, phi: np.ndarray, change: np.ndarray) -> np.ndarray:
        """``Σ_e (φA⁻¹B_E)_e change_{c(e)}`` per output row (N, t): what other parameters take off r."""
        return phi @ self._rigid_shift(change)

    #: Window [s] of the smoothed error that measures how long the residual's errors stay correlated (at
    #: least :attr:`SCALE_MIN_SAMPLES` samples): a correlation longer than it counts as this long.
    CORRELATION_WINDOW = 1.0

    def _correlation_forgetting(self, sample_period_s: float) -> float:
        """β_c = exp(−1/L) of the smoothed error, L = max(CORRELATION_WINDOW/T, SCALE_MIN_SAMPLES) samples."""
        samples = max(self.CORRELATION_WINDOW / float(sample_period_s), float(self.SCALE_MIN_SAMPLES))
        return forgetting_factor(samples, 1.0)

    def _fast_forgetting(self, sample_period_s: float) -> float:
        """β_f = exp(−1/N), N = max(τ_f/T, 10·p/t) samples (τ_f in s, T the period in s)."""
        floor = self.FAST_ROWS_PER_PARAMETER * self.n_params / self.n_outputs
        samples = max(self.tracker_time_constant / float(sample_period_s), floor)
        return forgetting_factor(samples, 1.0)

    def on_period(self, sample_period_s: float) -> float | None:
        """Take the measured sample period T [s], and convert the fast correction's memory τ_f [s] at it.

        Besides what every learner converts
        (:meth:`~semiparam_ros.core.learners.contract.Learner.on_period`).

        Raises:
            ConfigurationError: On a period that is not a finite number > 0.
        """
        beta = super().on_period(sample_period_s)
        self.fast.set_forgetting(self._fast_forgetting(sample_period_s))
        self._recent_beta = self._scale_forgetting(sample_period_s)
        self._corr_beta = self._correlation_forgetting(sample_period_s)
        self._reference_samples = self._reference_count(sample_period_s)
        self._aged_samples = max(round(self.AGED_COPY_S / float(sample_period_s)), 1)  # between copies
        self._period_s = float(sample_period_s)
        return beta

    # ------------------------------------------------------------------ prediction
    def _model_valid(self, xv: np.ndarray, Phi: np.ndarray, rigid: np.ndarray | None = None, *,
                     held: bool = False, model_variance: bool = False
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """``(ŷ_P, g·r, relative variance, φ or None)`` for a validated x and its regressor.

        ``rigid``: other rigid-body parameters to predict with (see :meth:`predict_model`). ``held``: take
        the residual ``g·r`` and its relative variance as last computed (see :meth:`predict_held`).
        ``model_variance``: the relative variance of model(x) used alone (:meth:`model_variance`) instead
        of the online prediction's.
        """
        par_model, npm = self.parametric, self.nonparametric
        rows = np.ascontiguousarray(Phi)
        var = par_model.rls.predict(rows, return_variance=True, checked=True)[1]  # diag(Φ A⁻¹ Φᵀ)
        assert var is not None  # asked for
        own = rigid is None  # the model's own rigid part: the reference θ_ref (see use_rigid)
        yp = Phi @ (self._reference if rigid is None else rigid)
        if held and self._held is not None:
            r_held, v_held = self._held
            return yp, r_held.copy(), var + v_held, None
        if not npm.standardizer.ready:
            self._held = None
            return yp, np.zeros(self.n_outputs), var, None
        t = self.n_outputs
        phi = npm.features_of(xv)
        P, v = npm.rls.predict(phi, return_variance=True, checked=True)
        assert v is not None  # asked for
        raw = P[0] if rigid is None else P[0] - self._entries_residual(phi, rigid - self._reference)[0]
        s2, spread = self._weight_scales(served=model_variance)
        r = np.empty(t)
        weighted_residual(raw, s2, spread, npm.rls.lam, float(v[0]), r)
        if not model_variance:
            r *= self._residual_use  # the online weight only (residual_use)
        self._raw = raw
        if own and not model_variance:
            self._held = (r, float(v[0]))  # the residual a held prediction reuses (not copied: read only)
        if model_variance:
            return yp, r, var + self.model_variance(float(v[0])), phi
        return yp, r, var + float(v[0]), phi

    def residual_weight(self, v: Any, served: bool = False) -> np.ndarray:
        """Weight g ∈ [0, 1] of the residual per output at relative variance v.

        ``g = s²(1 − ν) / (s²(1 − ν) + κ σ² v)``: ``s²`` is the variance of the rigid-body part's recent
        systematic error (the mean of (y − ŷ_P)² over about :attr:`SCALE_TIME_CONSTANT` minus σ²), ``σ²``
        the residual's noise variance (the mean squared a-priori error of ŷ_P + r with the residual's
        memory), ``v = φA⁻¹φᵀ`` and ``ν = λv`` the fraction of the residual's prior variance the data leave
        at x (so ``s²(1 − ν)`` is the part of the error the data explain there and ``σ² v`` the residual's
        predictive variance), κ = ``1/novelty_scale``. This is the Wiener weight of an estimate whose
        signal has variance s²(1 − ν) and whose error has variance κσ²v: where the rigid body is poor
        (s² ≫ σ²v) a residual of moderate confidence is used, where it is excellent (s² → 0) or the state
        is novel (ν → 1) the model abstains. Before any statistics: 1 (the residual is then zero).

        ``served``: the weight of the model used alone (:meth:`predict_model`, a frozen or served copy),
        ``s²(1 − ν) / (s²(1 − ν) + κ c σ² v)`` with c = :meth:`correlation_samples`: its residual's error
        on other motion is ``c σ² v`` (errors correlated over c samples), and this weight minimises the
        error variance the model reports for itself (:meth:`model_variance`, κ = 1). The online prediction,
        whose correlated errors the fast correction tracks, keeps ``σ² v``.

        The online weight is 0 on an output where the residual does worse than its rigid body a moment
        later (:meth:`residual_use` false); the served weight is not changed by that test.

        Args:
            v: The residual's relative predictive variance, a scalar or (N,).
            served: The model used alone (see above).

        Returns:
            g, (t,) for a scalar v, else (N, t).
        """
        s2, spread = self._weight_scales(served)
        v_arr = np.asarray(v, dtype=np.float64)[..., None]
        signal = s2 * np.clip(1.0 - self.nonparametric.rls.lam * v_arr, 0.0, 1.0)  # s²(1 − ν)
        total = signal + spread * v_arr
        g = np.divide(signal, total, out=np.ones_like(total), where=total > 0.0)
        return g if served else g * self._residual_use

    def model_variance(self, v: Any) -> np.ndarray:
        """Return the residual stage's share of the relative variance of model(x) = ŷ_P + g·r used alone.

        Per output, in units of the residual's noise variance σ², with g the served weight
        (:meth:`residual_weight` with ``served``):

            ``[(1 − g)² s²(1 − ν) + g² c σ² v + s² ν] / σ²``

        the error variance of ``ŷ_P + g r`` as an estimate of the rigid body's systematic error: the part
        the data explain at x (``s²(1 − ν)``) is missed by ``1 − g``, the residual's own error ``c σ² v``
        enters with ``g``, and the part the data do not explain (``s² ν``) is all missed. ``c`` is
        :meth:`correlation_samples`: ``σ² v`` assumes independent errors, but the residual's errors stay
        correlated for about c samples (a motion's unmodelled effects drift; at 1 kHz far longer than
        at 100 Hz in samples), so the data hold about c times fewer independent samples than rows. With
        c = 1, g = 1 and ν = 0 this is v, the online prediction's share. What ``predict_model`` returns:
        the σ of a model frozen and used on other motion (``load_model``, feed-forward), not the σ of the
        one-step-ahead prediction, whose errors the fast correction tracks. Before any statistics: v.

        Args:
            v: The residual's relative predictive variance ``φA⁻¹φᵀ``, a scalar or (N,).

        Returns:
            (t,) for a scalar v, else (N, t); ≥ 0.

        Example:
            >>> m = ConsistentSemiparametricModel(lambda x: x[None, :1], 1, 3, 1, n_features=8)
            >>> m.model_variance(0.5).tolist()  # nothing learned yet: v itself
            [0.5]
        """
        g = self.residual_weight(v, served=True)
        s2, noise, c = self._served_scales()
        v_arr = np.asarray(v, dtype=np.float64)[..., None]
        nu = np.clip(self.nonparametric.rls.lam * v_arr, 0.0, 1.0)
        extra = (1.0 - g) ** 2 * s2 * (1.0 - nu) + g * g * c * noise * v_arr + s2 * nu
        fallback = np.broadcast_to(v_arr, extra.shape)
        return np.divide(extra, noise, out=np.array(fallback, dtype=np.float64), where=noise > 0.0)

    def correlation_samples(self) -> np.ndarray:
        """Return c (t,) ≥ 1: about how many consecutive samples the residual's errors stay correlated.

        By batch means: ``m`` smooths the residual's a-priori error ``e = y − ŷ_P − r`` over
        L = :attr:`CORRELATION_WINDOW` [s] (``a = 1 − β_c``). For white errors the smoothed error keeps
        ``a/(2 − a)`` of their variance; errors correlated over c ≪ L samples keep about c times more, so
        ``c = (Σβ m² / Σβ e²) · (2 − a)/a`` (both sums with the residual's memory), at most about 2L. 1
        before any statistics.

        Example:
            >>> m = ConsistentSemiparametricModel(lambda x: x[None, :1], 1, 3, 1, n_features=8)
            >>> m.correlation_samples().tolist()
            [1.0]
        """
        a = 1.0 - self._corr_beta
        ratio = np.divide(self._corr[1], self._scale_model, out=np.zeros(self.n_outputs),
                          where=self._scale_model > 0.0)
        return np.maximum(ratio * (2.0 - a) / a, 1.0)

    def _weight_scales(self, served: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``(s², σ²/ν₀)`` of the residual's weight, cached until the next learned sample.

        ``served``: ``(s², c σ²/ν₀)``, the model used alone (see :meth:`residual_weight`).
        """
        cache = self._weight_cache  # the scales change only when a sample is learned
        if cache is None:
            s2, noise = self.error_scales()
            cache = self._weight_cache = (s2, noise / self.novelty_scale)
        return (cache[0], cache[1] * self._served_scales()[2]) if served else cache

    def _served_scales(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(s², σ², c)`` of the model used alone, kept while the weight's scales are the same object.

        Every path that changes the error statistics replaces (or clears) the weight's scales, so their
        identity says when these are stale: a served copy, which learns nothing, computes them once.
        """
        token = self._weight_cache
        cached = self._served_cache
        if token is not None and cached is not None and cached[0] is token:
            return cached[1]
        s2, noise = self.error_scales()
        scales = (s2, noise, self.correlation_samples())
        self._served_cache = (token, scales)
        return scales

    def error_scales(self) -> tuple[np.ndarray, np.ndarray]:
        """``(s², σ²)`` (t,) each: the rigid-body part's systematic error and the residual's noise variances.

        Units of y². Zero before the residual learned a sample.
        """
        w = self._scale_weight
        if w <= 0.0:
            return np.zeros(self.n_outputs), np.zeros(self.n_outputs)
        noise = self._scale_model / w
        return np.maximum(self._recent_rigid - noise, 0.0), noise

    def residual_use(self) -> np.ndarray:
        """Per output (t,) bool: whether the online prediction uses the residual (its weight is 0 where not).

        False where a copy of the residual :attr:`AGED_COPY_S` to twice that old, scored on every learned
        sample against its own rigid body as it was then (``d = e² − (e − g·r_aged)²``, the residual's
        memory), made the squared error larger by more than two standard errors of the mean (the samples
        counted over the length c its errors stay correlated, :meth:`correlation_samples`): a residual
        that learned what belongs to time rather than to the state (errors correlated over a tenth of a
        second, such as a q̈ estimate's window error) fits each sample's neighbourhood one step ahead but
        is worse than no residual a moment later. True before there is enough evidence (fewer than
        :attr:`AGED_MIN_EVIDENCE` effective samples). The model used alone (:meth:`predict_model`, the
        served weight) does not depend on it.

        Example:
            >>> m = ConsistentSemiparametricModel(lambda x: x[None, :1], 1, 3, 1, n_features=8)
            >>> m.residual_use().tolist()
            [True]
        """
        return self._residual_use.copy()

    def _fast_useful(self) -> np.ndarray:
        """Per output: whether the fast correction recently reduced the one-step squared error significantly.

        The mean saving ``m`` of the recent samples must exceed two of its standard errors, ``2 s/√n``
        (n the samples averaged, at most about twice ``tracker_samples`` for the running mean): choosing by
        the smaller of two noisy errors alone would add the correction's noise where it saves nothing.
        """
        out = np.empty(self.n_outputs, dtype=np.bool_)
        significant_saving(self._fast_errors, min(self._fast_n, 2 * self.tracker.stats_samples - 1), out)
        return out

    def predict_checked(self, xv: np.ndarray, Phi: np.ndarray, *, held: bool = False
                       ) -> tuple[Prediction, np.ndarray, np.ndarray | None, float]:
        """Return the prediction, ``model(x) + wΦδ_f`` (the local tracker's reference), φ and κ(x)."""
        yp, r, var, phi = self._model_valid(xv, Phi, held=held)
        model_total = self._model_only = yp + r
        if not self.use_tracker:
            return Prediction(yp, r, model_total, var, np.zeros(self.n_outputs)), model_total, phi, 0.0
        kappa_state = self.tracker.weight(xv)
        fades = self.age_fades()
        kappa = kappa_state * float(fades.max())  # the tracker's weight of this state when learned
        # per output; the fast correction the same over FAST_FADE × the distances
        kappas = kappa_state * fades
        kappas_fast = kappa_state ** (1.0 / self.FAST_FADE ** 2) * fades
        P, v = self.fast.predict(Phi, return_variance=True, checked=True)
        assert v is not None  # asked for
        useful = self._fast_mask
        if useful is None:
            useful = self._fast_mask = self._fast_useful()
        t = self.n_outputs
        applied, fast, total = np.empty(t), np.empty(t), np.empty(t)
        residual, correction = np.empty(t), np.empty(t)
        # fast = model + [useful]·max(0, 1 − 9r̂v/c²)·κ_f c, total = fast + κ b̂ and the parts (one call)
        fast_total(model_total, np.ascontiguousarray(P[:, 0]), v, self.tracker.noise_variance(), kappas_fast,
                   useful, kappas, self.tracker.used_estimate, applied, fast, total, yp, residual, correction)
        self._fast_candidate = applied
        return Prediction(yp, residual, total, var, correction), fast, phi, kappa

    def age_fades(self) -> np.ndarray:
        """Weight of both fast corrections per output for the age of the learned state: ``exp(−a/τ)`` (t,).

        a = :attr:`prediction_age_s` [s] (the sample period times the samples between the newest learned
        sample and the predicted one). An output's error learned a while ago says something about its
        error now only as long as that output's errors stay correlated: τ = min(τ_f, ½(1 + c)T), τ_f =
        ``tracker_time_constant`` [s] (the correction's memory), c the output's
        :meth:`correlation_samples` (how many consecutive samples its errors stay correlated; ½(1 + c)
        samples is the time constant of a first-order process with that c) and T the sample period [s].
        Errors that are white (an output at its noise floor) fade within a sample or two; a payload's or a
        drift's, correlated for as long as c can measure (about 2 s), over τ_f. 1 when the previous sample
        was learned.

        Example:
            >>> m = ConsistentSemiparametricModel(lambda x: x[None, :1], 1, 3, 1, n_features=8,
            ...                                   tracker_time_constant=0.3, sample_period_s=0.01)
            >>> m.age_fades().tolist()
            [1.0]
            >>> m.prediction_age_s = 0.01  # one sample missed, errors not known to be correlated (c = 1)
            >>> np.round(m.age_fades(), 4).tolist()  # exp(−0.01 / (½ · 2 · 0.01))
            [0.3679]
        """
        age = self.prediction_age_s
        if age <= 0.0:
            return self._no_fade
        c = self._served_scales()[2]
        tau = np.minimum(self.tracker_time_constant, 0.5 * (1.0 + c) * self._period_s)
        return np.exp(-age / tau)

    def predict_one(self, x: Any, *, return_variance: bool = False) -> Prediction:
        """Predict ``model(x) + α(wΦ(x)δ_f + κ b̂)`` with its parts (``correction`` = the last terms).

        Args:
            x: The input ``[q, q̇, q̈]``.
            return_variance: Keep the relative predictive variance in the result (always computed: the
                residual's weight needs it).

        Raises:
            RejectedSampleError: Bad x or regressor output.
        """
        xv, _, Phi = self._check(x)
        pred = self.predict_checked(xv, Phi)[0]
        if not return_variance:
            pred = Prediction(pred.parametric, pred.residual, pred.total, None, pred.correction)
        return pred

    def rls_stages(self) -> tuple[RecursiveRLS, ...]:
        """Return the recursive least-squares learners holding this model's state (the learner contract)."""
        return (self.parametric.rls, self.nonparametric.rls, self.fast)

    def adaptive_stages(self) -> tuple[RecursiveRLS, ...]:
        """Return the two stages' learners (the fast tracker keeps its own memory: :meth:`on_period`)."""
        return (self.parametric.rls, self.nonparametric.rls)

    def predict_held(self, x: Any) -> Prediction:
        """Predict x as :meth:`predict_one` but with the residual held from the last full prediction.

        The rigid-body part, the fast correction and the tracker are evaluated at x (O(p²)); the residual
        ``g·r`` and its relative variance are those of the last :meth:`predict_one` or learned sample (the
        O(D²) triangular solve of the random-feature learner is skipped). This is the prediction of a
        node that falls behind: at 1 kHz the residual, a smooth function of the state, changes little in
        the few ms it is held. Before any residual was computed (warm-up) it is the full prediction.

        Args:
            x: The input ``[q, q̇, q̈]`` (rad, rad/s, rad/s²).

        Returns:
            The prediction with its parts and relative variance.

        Raises:
            RejectedSampleError: Bad x or regressor output.
        """
        xv, _, Phi = self._check(x)
        return self.predict_checked(xv, Phi, held=True)[0]

    def predict_model(self, x: Any, rigid: np.ndarray | None = None) -> Prediction:
        """Predict model(x) alone (rigid-body part + weighted residual; no fast correction).

        What a feed-forward term at a desired state uses: it does not depend on the last measurement. The
        residual has the weight of the model used alone (:meth:`residual_weight` with ``served``) and the
        variance is :meth:`model_variance`'s.

        Args:
            x: The input ``[q, q̇, q̈]``.
            rigid: Rigid-body parameters to predict with instead of the learned ones (the learner's units,
                e.g. a physically consistent projection). The residual stays consistent with them: it
                learned ``y − Φπ₀`` and ``Φ``, so ``r = E[y − Φπ₀] − E[Φ](π − π₀)`` for any π.

        Raises:
            RejectedSampleError: Bad x or regressor output.
        """
        xv, _, Phi = self._check(x)
        yp, r, var, _ = self._model_valid(xv, Phi, checked_rigid(rigid, self.n_params), model_variance=True)
        return Prediction(yp, r, yp + r, var)

    def use_rigid(self, rigid: np.ndarray | None) -> None:
        """Predict with these rigid-body parameters instead of the learned ones, from now on (None: learned).

        For the physically consistent projection of the learned parameters, re-solved off the sample
        path: the model's rigid part ŷ_P = Φ(x)π, its residual ``r = p − P(π − π₀)`` consistent with π,
        the residual's weight (s² is then the recent error of Φπ) and the fast correction (which learns
        the error of this model) all use π. The learners keep learning π̂ unconstrained: that is what the
        projection starts from. Not part of the saved state (the projection is solved again from it).

        Args:
            rigid: (p,) parameters in the learner's units (scaled columns), or None.

        Raises:
            RejectedSampleError: A wrong size or a non-finite value (the model is unchanged).

        Example:
            >>> m = ConsistentSemiparametricModel(lambda x: x[None, :1], 1, 3, 1, n_features=8, prior=[1.0])
            >>> m.use_rigid(np.array([2.0]))
            >>> float(m.predict_model([3.0, 0.0, 0.0]).parametric[0])  # Φ(x)π = 3 · 2
            6.0
        """
        checked = checked_rigid(rigid, self.n_params)
        self._rigid = None if checked is None else checked.copy()
        self._rereference(self.parameters if checked is None else checked)
        self._held = None

    @property
    def rigid_override(self) -> np.ndarray | None:
        """The rigid-body parameters set by :meth:`use_rigid` (learner units), or None (the learned ones)."""
        return None if self._rigid is None else self._rigid.copy()

    @property
    def reference_parameters(self) -> np.ndarray:
        """θ_ref (learner units): the rigid body the model's own predictions use (``rigid=None``)."""
        return self._reference.copy()

    def frozen_model_one(self, rigid: np.ndarray | None = None
                         ) -> Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Return :meth:`predict_model` at one state as one compiled call, for a model that learns no more.

        What a served copy answers a controller's per-cycle desired state with: the learned state, the
        served scales and the rigid-body change's share of the residual (``shift``, :meth:`_rigid_shift`)
        are copied once, so each call is the regressor's Φ (the caller's) and
        :func:`~semiparam_ros.core.learners._consistent_kernels.model_alone_one`. Equal to
        :meth:`predict_model` to rounding (the same formulas; the residual's change of parameters as one
        product with ``shift``). A pending update is applied first (as the next prediction would).

        Args:
            rigid: Rigid-body parameters (learner units) as in :meth:`predict_model`; None: θ_ref.

        Returns:
            ``f(x, Φ) → (ŷ_P, g·r, relative variance)``, each (t,), for a checked x (3n,) and its
            checked C-contiguous regressor Φ (t, p). Valid while the model is not changed (a copy from
            :meth:`copy`); after a change, call this again.

        Raises:
            RejectedSampleError: A wrong size or non-finite ``rigid``.

        Example:
            >>> m = ConsistentSemiparametricModel(lambda x: x[None, :1], 1, 3, 1, n_features=8, prior=[2.0])
            >>> f = m.frozen_model_one()
            >>> x = np.array([3.0, 0.0, 0.0])
            >>> yp, r, var = f(x, np.array([[3.0]]))
            >>> float(yp[0]), float(r[0])  # Φπ₀ = 6, nothing learned: r = 0
            (6.0, 0.0)
            >>> bool(np.isclose(var[0], m.predict_model(x).variance[0]))  # the prior's variance at x
            True
        """
        rigid_checked = checked_rigid(rigid, self.n_params)
        par, npm = self.parametric, self.nonparametric
        theta = (self._reference if rigid_checked is None else rigid_checked).copy()
        t, d = self.n_outputs, npm.rls.n_features
        shift = np.zeros((0, t))
        ready = bool(npm.standardizer.ready)
        std, rff = npm.standardizer, npm.rff
        mean, scale = std.mean_.copy(), std.scale_.copy()
        if ready:
            omega = np.ascontiguousarray(rff.omega_, dtype=np.float64)
            offset = np.ascontiguousarray(rff.offset_, dtype=np.float64)
            amplitude = float(rff.feature_scale)
            if rigid_checked is not None:
                shift = np.ascontiguousarray(self._rigid_shift(rigid_checked - self._reference))
        else:
            omega, offset, amplitude = np.zeros((self.n_inputs, d)), np.zeros(d), 0.0
        s2, spread = self._weight_scales(served=True)
        _, noise, c = self._served_scales()
        s2, spread, noise, c = (np.array(a, dtype=np.float64) for a in (s2, spread, noise, c))
        Mp, Mn, lam = par.rls.factor_copy(), npm.rls.factor_copy(), float(npm.rls.lam)

        def one(x: np.ndarray, Phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            yp, r, var = np.empty(t), np.empty(t), np.empty(t)
            model_alone_one(x, Phi, theta, Mp, Mn, mean, scale, omega, offset, amplitude, shift, s2, spread,
                            noise, c, lam, ready, yp, r, var)
            return yp, r, var

        return one

    def predict_model_many(self, X: Any, rigid: np.ndarray | None = None) -> Prediction:
        """:meth:`predict_model` of N inputs at once (arrays of shape (N, t); ``variance`` included).

        The regressors are evaluated row by row; both learners then predict all rows with one matrix
        product and one triangular solve each (BLAS level 3): equal to N calls of :meth:`predict_model` to
        rounding (the residual's weight :meth:`residual_weight` is smooth in v).

        Args:
            X: (N, n_inputs) inputs ``[q, q̇, q̈]``.
            rigid: Rigid-body parameters to predict with instead of the learned ones (see
                :meth:`predict_model`).

        Returns:
            The model's prediction per row: rigid-body part, weighted residual, total, relative variance.

        Raises:
            RejectedSampleError: Wrong shape, NaN/inf in X, or a bad regressor output.
        """
        X2 = check_finite_array("X", X, (None, self.n_inputs))
        par_model, npm = self.parametric, self.nonparametric
        Phi = par_model.phi_rows(X2)
        var = par_model.predict_phi_rows(Phi)[1]
        rigid = checked_rigid(rigid, self.n_params)
        yp = Phi @ (self._reference if rigid is None else rigid)
        r = np.zeros_like(yp)
        if npm.standardizer.ready:
            phi = np.ascontiguousarray(npm.rff.map_checked(npm.standardizer.apply_checked(X2)))
            P, v = npm.rls.predict(phi, return_variance=True, checked=True)
            assert v is not None  # asked for
            r = P if rigid is None else P - self._entries_residual(phi, rigid - self._reference)
            r = r * self.residual_weight(v, served=True)
            var = var + self.model_variance(v)
        return Prediction(yp, r, yp + r, var)

    # ------------------------------------------------------------------ learning
    def predict_ahead_checked(self, xv: np.ndarray) -> PredictionContext:
        """Do :meth:`predict_ahead` for an input already checked (finite, the model's shape) and copied."""
        Phi = self.parametric.phi_fresh(xv)
        self._raw = None
        self._fast_candidate = np.zeros(self.n_outputs)
        pred, model_total, phi, kappa = self.predict_checked(xv, Phi)
        raw = None if phi is None else self._raw
        v = None if phi is None or self._held is None else self._held[1]
        return _Context(pred, self, xv, Phi, phi, model_total, kappa, raw, self._fast_candidate,
                        self._model_only, self._reference, v)

    def learn_ahead_checked(self, context: PredictionContext, yv: np.ndarray) -> None:
        """Do :meth:`learn_ahead` for an output already checked (finite, ``n_outputs`` values)."""
        ctx = self._take(context)
        assert isinstance(ctx, _Context) and ctx.Phi is not None  # made by _predict_ahead_valid
        Phi, phi, xv = ctx.Phi, ctx.phi, ctx.x
        par_model, npm = self.parametric, self.nonparametric
        y0 = par_model.prior_output(Phi)
        target = yv.copy() if y0 is None else yv - y0
        # both learners' rows are checked before either changes: a refused value leaves the model as it was
        par_step = par_model.rls.checked_step(Phi, target.reshape(-1, 1), owned=True)
        fast_step = None
        model_only = ctx.model_only
        if self.use_tracker:
            # the fast correction learns the error of model(x) (the a-priori model, without corrections);
            # Φ is shared with the rigid-body step (nobody writes to it)
            fast_step = RecursiveRLS.checked_step(Phi, (yv - model_only).reshape(-1, 1), owned=True)
        if phi is None:
            npm.hold_warmup(xv, xv, yv.copy())  # learned by learn_held once the standardizer is ready
            par_model.rls.defer_step(par_step)
        else:
            # the residual learns y − Φθ_ref; its features' cross-products with the regressor's entries
            # are kept to re-reference it (_rereference)
            # (ŷ_P of the prediction is Φθ_ref unless the reference changed since)
            same = ctx.reference is self._reference
            rigid_part = ctx.prediction.parametric if same else Phi @ self._reference
            np_step = RecursiveRLS.checked_step(phi, (yv - rigid_part).reshape(1, -1), owned=True)
            par_model.rls.defer_step(par_step)
            beta = npm.rls.forgetting  # this step's β: the cross-products forget as the learner does
            npm.rls.defer_step(np_step)
            rows_phi, rows_entries, rows_beta, k = self._cross.staging()
            stage_pending(rows_phi, rows_entries, rows_beta, k, phi[0], Phi.reshape(-1), self._phi_entries,
                          beta)
            self._cross.staged()
            assert ctx.raw_residual is not None  # computed with φ
            self._scale_weight = beta * self._scale_weight + 1.0
            self._recent_n += 1
            a = max(1.0 / self._recent_n, 1.0 - self._recent_beta)
            # σ²'s sum of (y − ŷ_P − r)² and s²'s recent mean of (y − ŷ_P)², then the weight's (s², σ²/ν₀)
            t = self.n_outputs
            s2, spread = np.empty(t), np.empty(t)
            scale_step(self._scale_model, self._recent_rigid, self._corr, yv, ctx.prediction.parametric,
                       ctx.raw_residual, beta, a, 1.0 - self._corr_beta, self._scale_weight,
                       self.novelty_scale, s2, spread)
            self._weight_cache = (s2, spread)
            if ctx.residual_variance is not None:
                self._score_aged(Phi, phi, yv, s2, spread, ctx.residual_variance)
        if fast_step is not None:
            self.fast.defer_step(fast_step)
            self.tracker.update(xv, yv, ctx.model_total, ctx.kappa)
            self._fast_n += 1
            a = max(1.0 / self._fast_n, 1.0 / self.tracker.stats_samples)
            # what the full correction saved, e² − (e − κ_f Φδ_f)² with e = y − model(x): mean and square,
            # then where it is significant (_fast_useful)
            useful = np.empty(self.n_outputs, dtype=np.bool_)
            saving_step(self._fast_errors, yv, model_only, ctx.fast_candidate, a,
                        min(self._fast_n, 2 * self.tracker.stats_samples - 1), useful)
            self._fast_mask = useful
        par_model.n_samples_seen += 1
        npm.n_samples_seen += 1
        self.n_samples_seen += 1
        self._since_reference += 1
        # the reference follows π̂: every sample while the residual has learned nothing (free then), then
        # after 1, 2, 4, … learned samples (π̂ moves most at first), then every REFERENCE_PERIOD
        if self._rigid is None and self._since_reference >= min(self._reference_samples, self._recent_n):
            self._rereference(self.parameters)
        if phi is None:
            self.learn_held()

    #: Age [s] of the copy of the residual scored on every learned sample (between this and twice this):
    #: the online prediction leaves the residual out where a copy that old clearly does harm
    #: (:meth:`residual_use`).
    AGED_COPY_S = 0.1

    def _score_aged(self, Phi: np.ndarray, phi: np.ndarray, yv: np.ndarray, s2: np.ndarray,
                    spread: np.ndarray, v: float) -> None:
        """Score the aged copy of the residual on this sample (:attr:`AGED_COPY_S`); take a new one when due.

        Every ``AGED_COPY_S`` of learned samples the newer copy ``(θ_ref, W)`` becomes the older and a new
        one is taken (one triangular solve with t right-hand sides), so the copy scored is between one and
        two ``AGED_COPY_S`` old. :func:`aged_saving_step` then updates its saving's statistics (the
        residual's memory) and :attr:`_residual_use`.
        """
        npm = self.nonparametric
        self._aged_count += 1
        if self._aged_count >= self._aged_samples:
            self._aged_count = 0
            self._aged_copies = [self._aged_copies[1], (self._reference.copy(), npm.rls.weights.copy())]
        aged = self._aged_copies[0]
        if aged is None:
            return
        self._aged_n += 1
        a = max(1.0 / self._aged_n, 1.0 - npm.rls.forgetting)
        window = min(float(self._aged_n), (2.0 - a) / a)
        use = np.empty(self.n_outputs, dtype=np.bool_)
        aged_saving_step(self._aged_errors, yv, Phi, aged[0], phi[0], aged[1], s2, spread, npm.rls.lam, v, a,
                         window, self._corr[1], self._scale_model, 1.0 - self._corr_beta,
                         self.AGED_MIN_EVIDENCE, use)
        self._residual_use = use

    #: Effective samples (samples over the errors' correlation length) of the aged copy's saving below
    #: which the residual is used without the test.
    AGED_MIN_EVIDENCE = 10.0

    def learn_held(self) -> None:
        """Learn the warm-up's samples, in their order, once the residual's standardizer is ready.

        The residual learns nothing while its input standardizer warms up (its features need the
        statistics); the warm-up's samples (x, y) are held (at most the warm-up's length) and learned here
        as the samples they were: targets ``y − Φθ_ref`` for the reference θ_ref = π̂ of now (the model's
        rigid part from here on), one :meth:`RecursiveRLS.update_steps` call (O(N·D²) once, N the
        warm-up's samples), their cross-products with the regressor entries, and the error statistics of
        the residual's weight from their a-priori predictions. The rigid body and the fast correction
        learned these samples when they came. Nothing happens while the warm-up runs or nothing is held.
        """
        npm, par_model = self.nonparametric, self.parametric
        held = npm.take_held()
        if held is None:
            return
        X, Y = held
        if self._rigid is None:
            self._rereference(self.parameters)  # nothing learned by the residual yet: no solve
        Phis = par_model.phi_rows(X)  # (N, t, p)
        rigid = Phis @ self._reference  # (N, t)
        F = npm.rff.transform(npm.standardizer.transform(X))
        beta = npm.rls.forgetting
        raw = npm.rls.update_steps(F, Y - rigid, predict=True)
        assert raw is not None  # asked for
        t = self.n_outputs
        s2, spread = np.empty(t), np.empty(t)
        for m in range(X.shape[0]):
            rows_phi, rows_entries, rows_beta, k = self._cross.staging()
            stage_pending(rows_phi, rows_entries, rows_beta, k, F[m], Phis[m].reshape(-1), self._phi_entries,
                          beta)
            self._cross.staged()
            self._scale_weight = beta * self._scale_weight + 1.0
            self._recent_n += 1
            a = max(1.0 / self._recent_n, 1.0 - self._recent_beta)
            scale_step(self._scale_model, self._recent_rigid, self._corr, Y[m], rigid[m], raw[m], beta, a,
                       1.0 - self._corr_beta, self._scale_weight, self.novelty_scale, s2, spread)
        self._weight_cache = (s2, spread)
        self._held = None
        self._raw = None

    def _learn(self, x: Any, y: Any, want_prediction: bool) -> Prediction | None:
        """Predict x a priori (all parts), then learn (x, y); the prediction when asked for."""
        ctx = self.predict_ahead(x)
        self.learn_ahead(ctx, y)
        if not want_prediction:
            return None
        pred = ctx.prediction
        return Prediction(pred.parametric, pred.residual, pred.total, None, pred.correction)

    def reset(self) -> None:
        """Forget everything (both learners and the fast correction)."""
        super().reset()
        self.fast.reset()
        self.tracker.reset()
        self._held = None
        self._raw = None
        self._rigid = None  # a projection of what was forgotten
        self._reset_scales()
        self._cross.reset()
        self._reference = self.parametric.prior.copy()
        self._since_reference = 0

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the learners' and the tracker's state as arrays."""
        state = super().state_dict(prefix)
        state[f"{prefix}phi_entries"] = self._phi_entries.copy()
        # the staged rows are added now (the same sum, grouped as a loaded copy will have it): a model and
        # its loaded checkpoint then add the rows that follow in the same blocks, bit for bit
        state[f"{prefix}entries_rhs"] = self._cross.settled().copy()
        # θ_ref, the samples since it followed π̂, and whether use_rigid set it (not restored on load)
        state[f"{prefix}reference"] = np.concatenate([self._reference, [self._since_reference,
                                                                       float(self._rigid is not None)]])
        state.update(self.tracker.state_dict(f"{prefix}tracker."))
        state.update(self.fast.state_dict(f"{prefix}fast."))
        state[f"{prefix}scales"] = np.concatenate([[self._scale_weight, self._recent_n, self._fast_n],
                                                   self._scale_model, self._recent_rigid,
                                                   self._fast_errors.reshape(-1), self._corr.reshape(-1)])
        # the aged copy's test: its statistics and decision, and the copies (θ_ref, W) taken so far, flat
        state[f"{prefix}aged"] = np.concatenate([[self._aged_n, self._aged_count],
                                                 self._aged_errors.reshape(-1),
                                                 self._residual_use.astype(np.float64)])
        kept = [np.concatenate([theta, W.reshape(-1)]) for theta, W in
                (c for c in self._aged_copies if c is not None)]
        size = self.n_params + self.nonparametric.rls.n_features * self.n_outputs
        state[f"{prefix}aged_copies"] = np.array(kept, dtype=np.float64).reshape(len(kept), size)
        return state

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Replace the whole state (validated completely before anything changes).

        Raises:
            CheckpointError: Wrong kind, missing keys or sizes that do not match this model.
        """
        tracker = ErrorTracker(self.n_outputs, self.tracker.n_joints,
                               position_scale=self.tracker.position_scale,
                               velocity_scale=self.tracker.velocity_scale,
                               stats_samples=self.tracker.stats_samples)
        tracker.load_state_dict(state, f"{prefix}tracker.")
        entries = state.get(f"{prefix}phi_entries")
        if entries is None or not np.array_equal(np.asarray(entries), self._phi_entries):
            raise CheckpointError("the residual's regressor entries differ from this model's (a checkpoint "
                                  "of another robot or structure, or one written before the residual "
                                  "kept only the regressor's non-zero entries: learn it again)")
        fast = RecursiveRLS.from_state_dict(state, f"{prefix}fast.")
        if fast.n_features != self.n_params or fast.n_outputs != 1:
            raise CheckpointError(f"the fast correction's state has {fast.n_features} parameters, expected "
                                  f"{self.n_params}")
        scales = state.get(f"{prefix}scales")
        t = self.n_outputs
        if scales is None:
            raise CheckpointError("the checkpoint has no error scales of the residual's weight (written by "
                                  "an older version: learn it again)")
        scales = np.asarray(scales, dtype=np.float64)
        if (scales.shape != (3 + 6 * t,) or not np.isfinite(scales).all()
                or bool((scales[:3 + 2 * t] < 0.0).any()) or bool((scales[3 + 3 * t:3 + 4 * t] < 0.0).any())
                or bool((scales[3 + 5 * t:] < 0.0).any())):
            raise CheckpointError("the residual's error scales have the wrong size or invalid values")
        aged = state.get(f"{prefix}aged")
        if aged is None:
            raise CheckpointError("the checkpoint has no test of the residual at an age (a corrupt file: "
                                  "older versions are migrated)")
        aged = np.asarray(aged, dtype=np.float64)
        copies = np.asarray(state.get(f"{prefix}aged_copies", np.zeros((3, 0))), dtype=np.float64)
        size = self.n_params + self.nonparametric.rls.n_features * t
        if (aged.shape != (2 + 3 * t,) or not np.isfinite(aged).all() or aged[0] < 0.0 or aged[1] < 0.0
                or bool((aged[2 + t:2 + 2 * t] < 0.0).any())
                or not bool(np.isin(aged[2 + 2 * t:], (0.0, 1.0)).all())
                or copies.ndim != 2 or copies.shape[0] > 2 or copies.shape[1] != size
                or not np.isfinite(copies).all()):
            raise CheckpointError("the test of the residual at an age has the wrong size or invalid values")
        D, E, p = self.nonparametric.rls.n_features, self._phi_entries.size, self.n_params
        try:
            entries_rhs = np.asarray(state[f"{prefix}entries_rhs"], dtype=np.float64)
            reference = np.asarray(state[f"{prefix}reference"], dtype=np.float64)
        except KeyError as err:
            raise CheckpointError(f"state is missing key {err}") from err
        if (entries_rhs.shape != (D, E) or reference.shape != (p + 2,) or not np.isfinite(entries_rhs).all()
                or not np.isfinite(reference).all() or reference[p] < 0.0):
            raise CheckpointError("the residual's reference or its regressor cross-products have the wrong "
                                  "size or invalid values")
        super().load_state_dict(state, prefix)
        self.tracker, self.fast = tracker, fast
        self._cross.load(entries_rhs)
        self._reference, self._since_reference = reference[:p].copy(), int(reference[p])
        self._held = None
        self._raw = None
        self._rigid = None  # the projection of the loaded state is solved again
        self._scale_weight, self._recent_n, self._fast_n = float(scales[0]), int(scales[1]), int(scales[2])
        self._scale_model, self._recent_rigid = scales[3:3 + t].copy(), scales[3 + t:3 + 2 * t].copy()
        self._fast_errors = scales[3 + 2 * t:3 + 4 * t].reshape(2, t).copy()
        self._corr = scales[3 + 4 * t:].reshape(2, t).copy()
        self._aged_n, self._aged_count = int(aged[0]), int(aged[1])
        self._aged_errors = aged[2:2 + 2 * t].reshape(2, t).copy()
        self._residual_use = aged[2 + 2 * t:] == 1.0
        kept: list[tuple[np.ndarray, np.ndarray] | None] = [None] * (2 - copies.shape[0])
        kept += [(row[:p].copy(), row[p:].reshape(-1, t).copy()) for row in copies]
        self._aged_copies = kept
        self._weight_cache = self._fast_mask = self._shift_cache = self._served_cache = None
        if reference[p + 1] != 0.0:
            # it predicted with the learned parameters, or with a rigid body set by use_rigid, which is not
            # restored (solved again from the state): the learned parameters until then
            self._rereference(self.parameters)
