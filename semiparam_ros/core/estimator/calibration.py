"""σ for new motion: the model's σ scaled by what a frozen copy of it scored on later motion while learning.

The estimator's σ = sqrt(s² (1 + v)) (:mod:`semiparam_ros.core.learners.uncertainty`) describes the
model's a-priori error one sample ahead: s² is measured on the errors of a model that learned the
previous sample a millisecond ago. A served model is frozen and used on motion it has not seen, where its
errors are larger, and larger still at rest and around reversals (friction holds what its history left).
:class:`FrozenCalibration` measures that during learning, by blocked forward validation on the learning
stream itself:

* every ``block`` seconds of stamps a copy of the model (and of s²) is frozen;
* the copy is scored on the samples of the next block, from a quarter of a block after it was frozen on
  (so the scored states are not those it just learned), one sample per :data:`SCORE_PERIOD_S` of stamps
  (the same at any rate): ``z = |y − ŷ_copy(x)| / σ_copy(x)`` per output, ``σ_copy = sqrt(s²_m (1 + v))``
  with v the copy's relative posterior variance at x (it grows where the copy has seen no data) and s²_m
  the one-step noise variance **of the output's motion state m at x** when the copy was frozen
  (:attr:`FrozenCalibration.s2`: the estimator's running estimate of ``e²/(1 + v)``, over the model's
  one-step errors e without its fast correction, with the time constant ``uncertainty.noise_time_constant``
  counted in that state only — one estimate over all states follows whatever the arm did in its last
  seconds, a rest or a fast move);
* each z goes into a histogram of ``ln z`` per output and **motion state** (:func:`motion_states`: at
  rest, around a reversal, in motion), whose weights fade with a memory of :data:`MEMORY_S` seconds of
  stamps (bounded: a fixed number of bins, whatever the duration);
* the **scale** c of an output in a state is ``q₉₅(z) / 2``: it puts 95 % of those errors within ±2σ. A
  state with fewer than :data:`MIN_WEIGHT` scored samples takes the output's scale over all states; an
  output with fewer has none (NaN).

The served σ (``load_model``, the node's served copy, the feed-forward's σ fallback) is
``c_m · sqrt(s²_m (1 + v(x)))`` for each output's motion state m at x, or the one-step
``sqrt(s² (1 + v(x)))`` where there is no scale yet. The one-step σ the estimator publishes beside its
prediction at the measured state is unchanged. The histograms and s²_m are kept in the checkpoint.

Motion state of a state x = [q, q̇, q̈] (rad, rad/s, rad/s²), per joint: **at rest** when
|q̇| < :data:`REST_VELOCITY`; **around a reversal** when not at rest and |q̇| < :data:`REVERSAL_WINDOW_S`
· |q̈| (a sign change of q̇ within that time at the present acceleration, before or after); else **in
motion**. Joint torques: output j is judged by joint j. A wrench (or any other output): by the arm — at
rest when every joint is, around a reversal when any joint is, else in motion.

>>> X = np.array([[0.0, 0.001, 0.0], [0.0, 0.05, 1.0], [0.0, 0.5, 1.0]])  # one joint: q, q̇, q̈
>>> motion_states(X, 1, 1)[:, 0].tolist()  # at rest, around a reversal, in motion
[0, 1, 2]
>>> cal = FrozenCalibration(n_outputs=1, n_joints=1, block_s=20.0)
>>> cal.scales().tolist()  # nothing scored yet: the one-step σ is served
[[nan, nan, nan]]
>>> rng = np.random.default_rng(0)
>>> cal.add(np.tile([0.0, 1.0, 0.0], (2000, 1)), np.abs(rng.normal(0.0, 3.0, (2000, 1))))  # in motion
>>> [round(float(c), 1) for c in cal.scales()[0]]  # errors 3× σ: q₉₅/2 = 3 × 1.96 / 2
[2.9, 2.9, 2.9]
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from semiparam_ros.core.estimator.build import traits_of
from semiparam_ros.core.learners.uncertainty import predict_with_variance
from semiparam_ros.errors import ConfigurationError

__all__ = ["MEMORY_S", "MIN_WEIGHT", "REST_VELOCITY", "REVERSAL_WINDOW_S", "SCORE_PERIOD_S", "STATES",
           "FrozenCalibration", "model_alone", "motion_states", "served_sigma_one"]

#: The motion states, in the order of :meth:`FrozenCalibration.scales`' columns.
STATES = ("at rest", "reversal", "motion")
#: A joint slower than this is at rest [rad/s].
REST_VELOCITY = 0.01
#: A joint whose velocity would change sign within this time at its present acceleration is around a
#: reversal [s].
REVERSAL_WINDOW_S = 0.2
#: One sample is scored per this much of the stamps [s] (cost and statistics do not depend on the rate).
SCORE_PERIOD_S = 0.02
#: Memory of the histograms [s of stamps]: a score of this age weighs e⁻¹.
MEMORY_S = 3600.0
#: Scored samples (weight) a state needs for its own scale; fewer: the output's scale over all states.
MIN_WEIGHT = 100.0
#: Coverage the scale aims at for ±2σ.
COVERAGE = 0.95
_EDGES = np.linspace(math.log(1e-3), math.log(1e4), 323)  # ln z bins 0.05 wide (5 % in z), z in 1e-3…1e4


def motion_states(X: np.ndarray, n_joints: int, n_outputs: int) -> np.ndarray:
    """Return the motion state (index into :data:`STATES`) of each output at each state.

    Args:
        X: (N, 3n) states ``[q, q̇, q̈]`` [rad, rad/s, rad/s²].
        n_joints: n.
        n_outputs: t: joint torques when t = n (output j judged by joint j); otherwise every output is
            judged by the arm.

    Returns:
        (N, t) integers: 0 at rest, 1 around a reversal, 2 in motion.
    """
    X2 = np.asarray(X, dtype=np.float64)
    speed = np.abs(X2[:, n_joints:2 * n_joints])
    rest = speed < REST_VELOCITY
    reversal = ~rest & (speed < REVERSAL_WINDOW_S * np.abs(X2[:, 2 * n_joints:3 * n_joints]))
    if n_outputs != n_joints:
        arm_rest = np.all(rest, axis=1, keepdims=True)
        arm_reversal = ~arm_rest & np.any(reversal, axis=1, keepdims=True)
        state = np.where(arm_rest, 0, np.where(arm_reversal, 1, 2))
        return np.repeat(state, n_outputs, axis=1)
    return np.where(rest, 0, np.where(reversal, 1, 2))


@njit(cache=True, nogil=True)
def served_sigma_one(variance: np.ndarray, x: np.ndarray, n_joints: int, s2: np.ndarray, scales: np.ndarray,
                     per_state: np.ndarray, out: np.ndarray) -> None:
    """Write the served σ at one state, ``c_m sqrt(s²_m (1 + v))``, into ``out`` in one compiled call.

    m is each output's motion state at x (:func:`motion_states`, the same rules and order); where
    ``c_m s²_m`` is NaN (nothing scored) the one-step ``sqrt(s² (1 + v))``. ``1 + fmax(v, 0)`` as the
    numpy path (a NaN v counts as 0).

    Args:
        variance: (t,) the relative variance v.
        x: (3n,) the state ``[q, q̇, q̈]`` [rad, rad/s, rad/s²].
        n_joints: n.
        s2: (t,) the one-step noise variance (+inf: none yet, σ = +inf).
        scales: (t, 3) the scales c per motion state (NaN: none).
        per_state: (t, 3) the noise variances s²_m per motion state (NaN: none).
        out: (t,) output σ.
    """
    t = variance.shape[0]
    n = n_joints
    arm_state = 2  # outputs other than joint torques are judged by the arm
    if t != n:
        arm_rest, arm_reversal = True, False
        for j in range(n):
            speed = abs(x[n + j])
            rest = speed < REST_VELOCITY
            arm_rest = arm_rest and rest
            if not rest and speed < REVERSAL_WINDOW_S * abs(x[2 * n + j]):
                arm_reversal = True
        arm_state = 0 if arm_rest else (1 if arm_reversal else 2)
    for k in range(t):
        vk = variance[k]
        if not vk >= 0.0:
            vk = 0.0
        relative = 1.0 + vk
        if t == n:
            speed = abs(x[n + k])
            if speed < REST_VELOCITY:
                state = 0
            elif speed < REVERSAL_WINDOW_S * abs(x[2 * n + k]):
                state = 1
            else:
                state = 2
        else:
            state = arm_state
        served = scales[k, state] * math.sqrt(per_state[k, state] * relative)
        out[k] = math.sqrt(s2[k] * relative) if math.isnan(served) else served


def model_alone(model: Any, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return a learner's model at x without a fast correction, and its relative variance v (t,) each.

    What a served model predicts (the consistent SP's ``predict_model``; the other learners have no
    correction).

    Raises:
        RejectedSampleError: Bad x or regressor output.
    """
    if traits_of(model).combination == "consistent":
        pred = model.predict_model(x)
    else:
        pred = predict_with_variance(model, x)
    variance = np.fmax(np.asarray(pred.variance, dtype=np.float64), 0.0)
    return np.asarray(pred.total, dtype=np.float64), variance


class FrozenCalibration:
    """Histograms of a frozen copy's normalized errors on later motion, per output and motion state.

    Args:
        n_outputs: t.
        n_joints: n.
        block_s: Seconds of stamps between two frozen copies (> 0); each is scored on the next block.
        noise_time_constant_s: τ_s > 0 of the per-state noise estimates [s].

    Raises:
        ConfigurationError: For t or n < 1, or a block or τ that is not a finite number > 0.

    Attributes:
        weights: (t, 3, bins) the faded counts of ``ln z`` per output and motion state.
        n_scored: Samples scored since the start (a count, not faded).
        s2: (t, 3) s²_m, the one-step noise variance per output and motion state (NaN before a sample in it).
    """

    def __init__(self, n_outputs: int, n_joints: int, block_s: float,
                 noise_time_constant_s: float = 2.0) -> None:
        if n_outputs < 1 or n_joints < 1:
            raise ConfigurationError(f"calibration needs outputs and joints, got {n_outputs}, {n_joints}")
        block = float(block_s)
        if not (math.isfinite(block) and block > 0.0):
            raise ConfigurationError(f"uncertainty.calibration_block must be a finite number > 0 s, got "
                                     f"{block_s!r}")
        self.n_outputs, self.n_joints, self.block_s = int(n_outputs), int(n_joints), block
        self.noise_time_constant_s = float(noise_time_constant_s)
        self._fade = math.exp(-SCORE_PERIOD_S / MEMORY_S)
        self.reset()

    def reset(self) -> None:
        """Forget the histograms and the frozen copy."""
        self.weights = np.zeros((self.n_outputs, len(STATES), _EDGES.size - 1))
        self.n_scored = 0
        self.s2 = np.full((self.n_outputs, len(STATES)), np.nan)
        self.restart_stream()

    def restart_stream(self) -> None:
        """Drop the frozen copy (a new recording: its stamps say nothing of the copy's age)."""
        self._copy: Any = None
        self._copy_s2: np.ndarray | None = None
        self._copy_stick: np.ndarray | None = None
        self._last_ns: int | None = None
        self._frozen_ns = 0
        self._next_score_ns = 0

    # ------------------------------------------------------------------ learning
    def observe(self, stamp_ns: int, x: np.ndarray, y: np.ndarray, model: Any, error: np.ndarray,
                variance: np.ndarray, stick: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Score the frozen copy on a sample when one is due, and freeze a new copy when a block is over.

        Called after the model learned the sample. The copy is frozen only once the model predicts with a
        residual (a model still in its warm-up is not what is served).

        Args:
            stamp_ns: The sample's stamp [ns].
            x: Its state ``[q, q̇, q̈]`` (checked by the caller).
            y: Its measured output.
            model: The live learner (copied, never changed).
            error: The model's one-step a-priori error at the sample (its fast correction left out).
            variance: The relative posterior variance v of that prediction (t,).
            stick: The stick friction's feature φ at the sample and its coefficient c now (joint torques
                with friction that remembers: the copy predicts with its c, frozen with it), or None.
        """
        states = motion_states(x[None, :], self.n_joints, self.n_outputs)[0]
        self._update_noise(stamp_ns, states, error, variance)
        age = (stamp_ns - self._frozen_ns) * 1e-9
        if self._copy is not None and (age < 0.0 or age >= 2.0 * self.block_s):
            self.restart_stream()  # stamps that went back, or a gap: the copy's age is unknown
        if self._copy is None or age >= self.block_s:
            if _predicts_with_residual(model):
                self._copy, self._copy_s2 = model.copy(), self.s2.copy()
                self._copy_stick = None if stick is None else stick[1].copy()
                self._frozen_ns = stamp_ns
                self._next_score_ns = stamp_ns + round(0.25 * self.block_s * 1e9)
            return
        if stamp_ns < self._next_score_ns:
            return
        self._next_score_ns = stamp_ns + round(SCORE_PERIOD_S * 1e9)
        assert self._copy_s2 is not None  # set with the copy
        total, v = model_alone(self._copy, x)
        if stick is not None and self._copy_stick is not None:
            total = total + self._copy_stick * stick[0]
        sigma = np.sqrt(self._copy_s2[np.arange(self.n_outputs), states] * (1.0 + v))
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.abs(y - total) / sigma
        self.add(x[None, :], np.where(np.isfinite(z) & (sigma > 0.0), z, np.nan)[None, :])

    def _update_noise(self, stamp_ns: int, states: np.ndarray, error: np.ndarray,
                      variance: np.ndarray) -> None:
        """Move each output's s²_m of its state m towards e²/(1 + v) (time counted in that state only)."""
        last, self._last_ns = self._last_ns, stamp_ns
        v = np.fmax(np.asarray(variance, dtype=np.float64), 0.0)
        e2 = np.asarray(error, dtype=np.float64) ** 2 / (1.0 + v)
        outputs = np.arange(self.n_outputs)
        current = self.s2[outputs, states]
        step = 0.0 if last is None or stamp_ns <= last else (stamp_ns - last) * 1e-9
        alpha = -math.expm1(-step / self.noise_time_constant_s)
        new = np.where(np.isnan(current), e2, current + alpha * (e2 - current))
        self.s2[outputs, states] = np.where(np.isfinite(new), new, current)

    def add(self, X: np.ndarray, Z: np.ndarray, weight: float = 1.0) -> None:
        """Add normalized errors ``z = |e| / σ`` (N, t) at states X (N, 3n); NaN entries are skipped.

        Each row fades the weights by one score period first (rows are taken as :data:`SCORE_PERIOD_S`
        apart), then adds ``weight`` to its bins.
        """
        states = motion_states(X, self.n_joints, self.n_outputs)
        lnz = np.log(np.clip(Z, math.exp(_EDGES[0]), math.exp(_EDGES[-1])))
        bins = np.clip(np.searchsorted(_EDGES, lnz, side="right") - 1, 0, _EDGES.size - 2)
        outputs = np.arange(self.n_outputs)
        for row in range(Z.shape[0]):
            self.weights *= self._fade
            ok = np.isfinite(Z[row])
            self.weights[outputs[ok], states[row, ok], bins[row, ok]] += weight
            self.n_scored += 1

    # ------------------------------------------------------------------ serving
    def scales(self) -> np.ndarray:
        """Return the scale c per output and motion state, (t, 3): ``q₉₅(z) / 2``.

        NaN for an output with fewer than :data:`MIN_WEIGHT` scores (no scale: the one-step σ is served).
        """
        out = np.full((self.n_outputs, len(STATES)), np.nan)
        for k in range(self.n_outputs):
            pooled = self.weights[k].sum(axis=0)
            if pooled.sum() < MIN_WEIGHT:
                continue
            fallback = _quantile(pooled) / 2.0
            for s in range(len(STATES)):
                w = self.weights[k, s]
                out[k, s] = _quantile(w) / 2.0 if w.sum() >= MIN_WEIGHT else fallback
        return out

    # ------------------------------------------------------------------ checkpoint
    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the histograms as arrays (the frozen copy is not kept: the next block freezes another)."""
        return {f"{prefix}weights": self.weights.copy(),
                f"{prefix}n_scored": np.array(self.n_scored, dtype=np.int64),
                f"{prefix}s2": self.s2.copy()}

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Replace the histograms by those of :meth:`state_dict` (validated before anything changes).

        Raises:
            KeyError: A key is missing.
            ValueError: Wrong shape, negative or non-finite weights, or a negative count.
        """
        weights = np.asarray(state[f"{prefix}weights"], dtype=np.float64)
        n = int(np.asarray(state[f"{prefix}n_scored"]))
        s2 = np.asarray(state[f"{prefix}s2"], dtype=np.float64)
        if weights.shape != self.weights.shape or not np.isfinite(weights).all() or (weights < 0).any():
            raise ValueError(f"calibration weights must be {self.weights.shape} finite values >= 0, got "
                             f"{weights.shape}")
        if n < 0:
            raise ValueError(f"calibration count must be >= 0, got {n}")
        if s2.shape != self.s2.shape or np.isinf(s2).any() or (s2 < 0).any():
            raise ValueError(f"calibration s2 must be {self.s2.shape} values >= 0 or NaN, got {s2.shape}")
        self.weights = weights.copy()
        self.n_scored = n
        self.s2 = s2.copy()
        self.restart_stream()


def _predicts_with_residual(model: Any) -> bool:
    """Whether the learner's residual is past its warm-up (P has none: ready once it learned)."""
    npm = getattr(model, "nonparametric", None)
    if npm is None:
        npm = model if hasattr(model, "standardizer") else None
    if npm is None:
        return int(getattr(model, "n_samples_seen", 0)) > 0
    return bool(npm.standardizer.ready)


def _quantile(weights: np.ndarray) -> float:
    """Return the :data:`COVERAGE` quantile of z from a histogram of ln z (interpolated in the bin)."""
    cumulative = np.cumsum(weights)
    target = COVERAGE * cumulative[-1]
    i = int(np.searchsorted(cumulative, target, side="left"))
    before = cumulative[i - 1] if i > 0 else 0.0
    frac = (target - before) / weights[i] if weights[i] > 0 else 1.0
    return float(math.exp(_EDGES[i] + frac * (_EDGES[i + 1] - _EDGES[i])))
