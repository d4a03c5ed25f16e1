"""Joint semiparametric learner: rigid-body parameters and kernel residual fitted as one ridge problem.

The paper's semiparametric model (:class:`~semiparam_ros.core.learners.cascade.SemiparametricModel`) is
a
cascade: the rigid-body stage is fitted alone and the kernel stage learns what it leaves over, from
``[x, ŷ]``. This module fits instead the partially linear model ``y = Φ(x) π + Wᵀφ(s(x)) + ε`` as a whole,

    (π̂, Ŵ) = argmin Σ_m β^{n−m} ‖y_m − Φ(x_m) π − Wᵀφ_m‖² + λ_P ‖π‖² + λ_NP ‖W‖²       (1)

(with β < 1 both priors are kept, as in :mod:`semiparam_ros.core.learners.rrls`). It is kernel ridge
regression with the kernel ``k(x, x′)/λ_NP + Φ(x)Φ(x′)ᵀ/λ_P``, i.e. a Gaussian process with the rigid-body
model as explicit basis functions (Rasmussen & Williams 2006, §2.7; the "semiparametric kernel" of
Nguyen-Tuong & Peters 2010). Differences from the cascade: no stage's targets go stale while the other one
keeps learning, the rigid-body term extrapolates wherever the kernel has no data, and the kernel input is
``x`` alone (``ŷ`` would make (1) nonlinear in π).

Incremental solution in O(D²) per sample (no O(b³) step): profile ``W`` out of (1). For fixed π, the
optimal W is ridge regression of the columns ``y_k − Φ_k π`` (k = output) on φ, linear in π. So one
random-feature :class:`RecursiveRLS` regresses the ``t(1+p)`` columns ``U = [y, Φ_1, …, Φ_t]`` (``Φ_k`` the
k-th row of the regressor, p = n_params) on φ; its factor stays ``[R | d_y | G]``. What it leaves
unexplained, ``S = Σ β^{n−m} UᵀU − [d_y|G]ᵀ[d_y|G]``, grows each step by ``EᵀE`` where ``E`` are the rows
its rotations push out (:meth:`RecursiveRLS.predict_update_rows_out`). The profiled objective in π is
``Σ_k [1, −πᵀ] S_kk [1, −πᵀ]ᵀ + λ_P ‖π‖²`` (``S_kk`` the block of output k), i.e. ordinary recursive ridge
regression of the ``y``-part of each rotated-out row on its ``Φ_k``-part: a second, p-dimensional
RecursiveRLS with the t rows ``(E[:, t + kp : t + (k+1)p], E[:, k])`` per rotated-out row. Its weights are
the exact π̂ of (1); then ``Ŵ_k = R⁻¹(d_k − G_k π̂)``. The a-priori prediction for x needs no solve:

    ỹ_k = p_k + (Φ_k − P_k) π̂,   [p | P] = φᵀ R⁻¹ [d_y | G] (from the rotations of the update),

the rigid-body prediction where the kernel predicts nothing (``P_k = 0``) and the kernel's where ``Φ_k``
is fully explained by it. Cost: the random-feature learner carries ``t·p`` more output columns (102 for the
iCub wrench); the π learner is O(t·p²).

The price of fitting everything jointly: (1) explains the samples before a change of the inertial
parameters (a payload) with the new π as well, so its kernel term must absorb ``Φ(π_old − π_new)`` on the
old samples, which it cannot tell from the new ones by x alone; only forgetting (β < 1) lets it recover,
whereas the cascade's residual targets stay relative to the π̂ of their time and its ŷ input moves with the
payload. The paper's cascade therefore stays the default; the measured comparison (first seconds on an
unseen trajectory, regime, recovery after a pickup) is in ``docs/design-notes.md``.

Parts reported in :class:`Prediction`: ``parametric = Φ(x) π̂`` (the rigid-body term of (1)),
``residual = total − parametric``. Units: x = [q, q̇, q̈] (rad, rad/s, rad/s²), y in N and N·m (wrench in
the sensor frame) or N·m (joint torques).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from semiparam_ros.core.learners.base import Regressor
from semiparam_ros.core.learners.contract import Prediction, PredictionContext
from semiparam_ros.core.learners.features import Standardizer
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.core.learners.two_stage import TwoStageModel
from semiparam_ros.errors import CheckpointError

__all__ = ["JointSemiparametricModel"]


class JointSemiparametricModel(TwoStageModel):
    """Rigid-body parameters and a random-feature residual fitted jointly (exact ridge solution of (1)).

    Args:
        regressor: Maps x to ``Φ(x)`` (n_outputs, n_params).
        n_params: p, number of (base) parameters.
        n_inputs: Length of x.
        n_outputs: t, length of y.
        lam_parametric: λ_P > 0, prior precision of π (units of Φ²).
        lam_nonparametric: λ_NP > 0, prior precision of the random-feature weights.
        n_features: D random features of the kernel term (input: the standardized x).
        sigma: Kernel width in standardized units of x.
        forgetting: β ∈ (0, 1] per sample, shared by both terms (one data weighting in (1)); the priors are
            kept at λ_P and λ_NP (see :mod:`semiparam_ros.core.learners.rrls`).
        seed: Seed of the random features.
        standardizer: Optional fitted :class:`Standardizer` for x.
        standardizer_warmup: Online warm-up length of the standardizer if none is given (0 = identity).
            During the warm-up the kernel term is zero and the samples are learned by the rigid-body term
            alone (they enter (1) with ``φ = 0``); they are also held, and once the statistics are ready
            the rigid-body term starts again from its prior and the held samples are learned jointly, in
            their order, with their features (:meth:`learn_held`): the state is then that of (1) over
            every sample.
        standardizer_min_scale: Floor of the warm-up's scales (scalar or one per input, units of x).
        prior: Prior mean π₀ of π (n_params,), default zero: (1) then penalizes ``λ_P‖π − π₀‖²``, solved as
            (1) in ``δ = π − π₀`` with targets ``y − Φπ₀`` (so bounded forgetting keeps π̂ around π₀, and
            before any data the prediction is ``Φπ₀``).

    Raises:
        ConfigurationError: Invalid sizes or hyperparameters.

    Example:
        >>> import numpy as np
        >>> line = lambda x: np.array([[x[0], 1.0]])
        >>> model = JointSemiparametricModel(line, 2, 1, 1, lam_parametric=1e-9, lam_nonparametric=1e-3,
        ...                                  n_features=300, sigma=0.5)
        >>> for x in np.linspace(-1.0, 1.0, 400):
        ...     model.learn_one([x], [3.0 * x + 1.0 + 0.2 * np.sin(3.0 * x)])
        >>> bool(abs(model.predict_one([0.3]).total[0] - (1.9 + 0.2 * np.sin(0.9))) < 0.01)
        True
    """

    _kind = "semiparametric_joint"

    def __init__(self, regressor: Regressor, n_params: int, n_inputs: int, n_outputs: int, *,
                 lam_parametric: float = 1.0, lam_nonparametric: float = 1.0, n_features: int = 500,
                 sigma: float = 1.0, forgetting: float = 1.0, seed: int = 0,
                 standardizer: Standardizer | None = None, standardizer_warmup: int = 0,
                 standardizer_min_scale: Any = 0.0, prior: Any = None) -> None:
        # the π learner: a ParametricModel gives the regressor checks; its RLS is fed profiled rows (of δ)
        self.parametric = ParametricModel(regressor, n_params, n_outputs, lam=lam_parametric,
                                          forgetting=forgetting, prior=prior)
        p, t = self.parametric.n_params, self.parametric.n_outputs
        self.nonparametric = NonparametricModel(int(n_inputs), t * (1 + p), n_features=n_features,
                                                sigma=sigma, lam=lam_nonparametric, forgetting=forgetting,
                                                seed=seed, standardizer=standardizer,
                                                standardizer_warmup=standardizer_warmup,
                                                standardizer_min_scale=standardizer_min_scale)
        self.n_inputs = int(n_inputs)
        self.n_outputs = t
        self.n_params = p
        self.n_samples_seen = 0

    @property
    def forgetting(self) -> float:
        """β, the forgetting factor per sample shared by both terms."""
        return self.parametric.rls.forgetting

    def _combine(self, Phi: np.ndarray, pk: np.ndarray,
                 pi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Φπ̂, p + (Φ − P)π̂, Φ − P)`` from the kernel's prediction ``pk = [p | P_1 … P_t]`` of U."""
        t, p = self.n_outputs, self.n_params
        eU = Phi - pk[t:].reshape(t, p)
        return Phi @ pi, pk[:t] + eU @ pi, eU

    def predict_one(self, x: Any, *, return_variance: bool = False) -> Prediction:
        """Predict ``Φπ̂ + Ŵᵀφ`` (the rigid-body term alone during the standardizer warm-up).

        Args:
            x: The input ``[q, q̇, q̈]``.
            return_variance: Also return the relative posterior variance of (1) per output,
                ``φA⁻¹φᵀ + (Φ_k − P_k) S⁻¹ (Φ_k − P_k)ᵀ`` (two triangular solves; multiply by the noise
                variance of y).

        Raises:
            RejectedSampleError: Bad x or regressor output.
        """
        xv, _, Phi = self._check(x)
        pred, _ = self.predict_checked(xv, Phi, return_variance)
        return pred

    def predict_checked(self, xv: np.ndarray, Phi: np.ndarray,
                       return_variance: bool) -> tuple[Prediction, np.ndarray | None]:
        """:meth:`predict_one` for a validated x and its regressor; also returns the features (or None)."""
        pi = self.parametric.rls.weights[:, 0]
        npm = self.nonparametric
        t, p = self.n_outputs, self.n_params
        phi = None
        if npm.standardizer.ready:
            phi = npm.features_of(xv)
            # one forward substitution (O(D²)) instead of the t(1+p)-column weights (O(t(1+p)·D²))
            P, v = (npm.rls.predict(phi, return_variance=True, checked=True) if return_variance
                    else (npm.rls.predict(phi, checked=True), None))
            pk = P[0]
            var_k = float(v[0]) if v is not None else 0.0
        else:
            pk = np.zeros(t * (1 + p))
            var_k = 0.0
        par, total, eU = self._combine(Phi, pk, pi)
        y0 = self.parametric.prior_output(Phi)
        if y0 is not None:
            par, total = par + y0, total + y0
        var = var_k + self.parametric.rls.variance(eU, checked=True) if return_variance else None
        return Prediction(par, total - par, total, var), phi

    def predict_ahead_checked(self, xv: np.ndarray) -> PredictionContext:
        """Do :meth:`predict_ahead` for an input already checked (finite, the model's shape) and copied."""
        Phi = self.parametric.phi_fresh(xv)
        pred, phi = self.predict_checked(xv, Phi, True)
        return PredictionContext(pred, self, xv, Phi, phi)

    def learn_ahead_checked(self, context: PredictionContext, yv: np.ndarray) -> None:
        """Do :meth:`learn_ahead` for an output already checked (finite, ``n_outputs`` values)."""
        Phi = self._take(context).Phi
        assert Phi is not None  # a two-stage context always holds the regressor
        self._learn_valid(context.x, yv, Phi, context.phi)

    def _learn(self, x: Any, y: Any, want_prediction: bool) -> Prediction:
        xv, yv, Phi = self._check(x, y)
        assert yv is not None
        phi = self.nonparametric.features_of(xv) if self.nonparametric.standardizer.ready else None
        return self._learn_valid(xv, yv, Phi, phi)

    def _learn_valid(self, xv: np.ndarray, yv: np.ndarray, Phi: np.ndarray,
                     phi: np.ndarray | None) -> Prediction:
        """Learn validated (x, y) with its regressor and features (None in the warm-up).

        Returns:
            The a-priori prediction, from the rotations.
        """
        t, p = self.n_outputs, self.n_params
        pi = self.parametric.rls.weights[:, 0]  # δ̂ = π̂ − π₀
        npm = self.nonparametric
        measured = yv
        y0 = self.parametric.prior_output(Phi)
        if y0 is not None:
            yv = yv - y0  # (1) in δ: the targets are what the prior leaves over
        if phi is None:
            # warm-up: φ = 0 in (1), so the kernel learner's rotations would push the row [0 | y, Φ] out
            # unchanged; feed it to the π learner directly (with β < 1 the kernel learner's clock starts
            # after the warm-up: until then it holds only its prior, which is left undecayed)
            npm.hold_warmup(xv, xv, measured.copy())  # learned jointly once the statistics are ready
            par = Phi @ pi
            self.parametric.rls.update(Phi, yv.reshape(-1, 1), checked=True)
            if y0 is not None:
                par = par + y0
            pred = Prediction(par, np.zeros(t), par.copy())
        else:
            u = np.concatenate([yv, Phi.reshape(-1)]).reshape(1, -1)
            pk, E = npm.rls.predict_update_rows_out(phi, u)
            par, total, _ = self._combine(Phi, pk[0], pi)
            # every rotated-out row gives t rows (Φ_k part, y_k part) of the profiled problem in π; they are
            # finite (an orthogonal transform of finite, validated rows), so this update cannot be refused
            # after the kernel learner's has been made
            Zp = np.ascontiguousarray(E[:, t:].reshape(-1, p))
            Up = np.ascontiguousarray(E[:, :t].reshape(-1, 1))
            self.parametric.rls.update(Zp, Up, checked=True)
            if y0 is not None:
                par, total = par + y0, total + y0
            pred = Prediction(par, total - par, total)
        self.parametric.n_samples_seen += 1
        npm.n_samples_seen += 1
        self.n_samples_seen += 1
        if phi is None:
            self.learn_held()
        return pred

    def learn_held(self) -> None:
        """Learn the warm-up's samples jointly, in their order, once the standardizer is ready.

        During the warm-up the rigid-body term alone learned them (``φ = 0`` in (1)); that learner, which
        has learned nothing else (the warm-up starts with the model), returns to its prior and every held
        sample is learned again with its features, so the state is that of (1) over all the samples, as if
        the statistics had been known from the first one. One joint step per held sample (a one-off
        O(N·t(1 + p)·D²)). Nothing happens while the warm-up runs or nothing is held.
        """
        npm, par = self.nonparametric, self.parametric
        held = npm.take_held()
        if held is None:
            return
        X, Y = held
        counts = (par.n_samples_seen, npm.n_samples_seen, self.n_samples_seen)
        par.rls.reset()
        for x, y in zip(X, Y, strict=True):
            self._learn_valid(x, y, par.phi_fresh(x), npm.features_of(x))
        par.n_samples_seen, npm.n_samples_seen, self.n_samples_seen = counts

    @property
    def parameters(self) -> np.ndarray:
        """π̂ of (1), the rigid-body parameters fitted jointly with the residual (n_params,)."""
        return self.parametric.parameters

    def _check_loaded(self, parametric: ParametricModel, nonparametric: NonparametricModel) -> None:
        if parametric.rls.forgetting != nonparametric.rls.forgetting:
            raise CheckpointError("state has different forgetting factors in its two learners")
