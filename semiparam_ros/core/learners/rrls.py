"""Recursive regularized least squares with Givens (QR/Cholesky) updates and bounded forgetting.

The learner solves ``W = argmin Σ_m β^{n−m}‖Z_m W − U_m‖² + (prior) ‖W‖²`` recursively. Its state is
the upper-triangular factor ``R`` (``RᵀR = A``, ``R₀ = √λ·I``) and ``d = R⁻ᵀB`` (``B`` the right-hand
side), stored side by side as ``M = [R | d]`` and rotated together: keeping ``d`` rather than ``B``
makes ``W = R⁻¹d`` one triangular solve and is far more accurate when ``A`` is ill-conditioned
(the measurement is in ``docs/design-notes.md``). A time step
appends its k rows with Givens rotations in O(k·b²); there is no refactorization, no explicit inverse
and no Sherman–Morrison update. The a-priori prediction ``Z W_old``
of the new rows falls out of the same rotations (:meth:`RecursiveRLS.predict_update`), so
test-then-train costs one pass over ``R``.

Forgetting that keeps the prior
-------------------------------
Plain exponential forgetting, ``A ← βA + ZᵀZ``, decays the regularizer as ``λβⁿ``: directions the data
do not excite lose all information and ``cond(A)`` grows like ``β⁻ⁿ`` until the solution winds up or the
factor underflows. This module instead keeps the prior at strength ``λ`` on average with an amortized,
exact-in-closed-form variant of ``A ← βA + (1−β)λI + ZᵀZ``: at time step m (one call of :meth:`update`)

    A_m = β A_{m−1} + Z_mᵀZ_m + c · e_{j_m} e_{j_m}ᵀ,     B_m = β B_{m−1} + Z_mᵀU_m,
    c = b (1 − β) λ,     j_m = (m − 1) mod b          (m = 1, 2, …),

i.e. every step scales ``[R | d]`` by ``√β`` (folded into the rotations) and rotates in one extra row
``√c·e_j`` with zero target, the coordinate j cycling over the b features. In closed form

    A_n = βⁿ λ I + Σ_{m=1}^{n} β^{n−m} (Z_mᵀZ_m + c e_{j_m} e_{j_m}ᵀ),   B_n = Σ_{m=1}^{n} β^{n−m} Z_mᵀU_m,

and ``W_n = A_n⁻¹ B_n`` (the tests check exactly this). Each direction receives ``c`` once every b steps;
in the steady state its prior weight oscillates between ``c·β^{b−1}/(1−β^b)`` and ``c/(1−β^b)`` around the
mean λ, so ``λ_min(A) ≥ λ·b(1−β)β^{b−1}/(1−β^b)`` (≈ λ·e^{−b(1−β)} for small 1−β) and
``λ_max(A) ≤ λ·b(1−β)/(1−β^b) + max‖Z_m‖²/(1−β)``: the condition number stays bounded whatever the data
excite. The extra row is zero left of column j, so it costs ≈ b²/6 flops per step on average and is
applied in the same sweep over ``R`` as the data row. With ``forgetting == 1`` nothing is scaled and
no extra row is added (plain recursive ridge regression). ``keep_prior=False`` gives plain exponential
forgetting (provided for comparison; it is not bounded).

Time steps: one call of :meth:`update` / :meth:`predict_update` is one time step, whatever its number of
rows (e.g. the 6 rows of one wrench sample); :meth:`update_steps` runs many steps in one call.

Prediction after an update
--------------------------
``W = R⁻¹d`` costs ``t·b²`` flops, so :meth:`predict` never forms it for a few rows: ``z W = (z R⁻¹) d``
is one forward substitution ``Rᵀv = zᵀ`` (``k·b²``), and ``‖v‖² = z A⁻¹ zᵀ`` is the predictive variance
of the same sweep. Better still, :meth:`update` is *deferred*: its rows are validated and copied at once,
and the rotations run when the state is next needed. A :meth:`predict` that finds an update pending runs
the rotations and its own forward substitution in the same sweep over ``R`` (each row of ``R`` is final as
soon as its column is rotated, which is the order the substitution reads them), so the learn-then-predict
habit costs about one update (see docs/performance.md). Every other read of the state (:attr:`R`,
:attr:`d`, :attr:`weights`, :meth:`state_dict`, …) applies the pending update first; the observable
results are those of an immediate update.
"""

from __future__ import annotations

import math
import os
from typing import Any, Literal, overload

import numpy as np
from scipy.linalg import solve_triangular

from semiparam_ros.core.checkpoint import atomic_save_npz, load_npz
from semiparam_ros.core.learners._kernels import (
    back_substitute,
    checked_copies,
    predict_row,
    predict_row_pending,
    qr_rls_steps,
    solve_predict,
    stage_row,
    values_within,
    within,
)
from semiparam_ros.core.validation import MAX_ABS_INPUT, check_positive_int, check_range
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError

__all__ = ["MAX_ABS_INPUT", "RecursiveRLS"]

#: Blocks with more rows than this are predicted by a triangular solve (the in-rotation prediction
#: tracks a k×k block and costs O(b·k²)).
_MAX_TRACKED_ROWS = 32
#: Factors up to this size are solved by the compiled back-substitution (no scipy call overhead).
_SMALL_SOLVE = 64
#: Query blocks up to this many rows are predicted by forward substitution (fused with a pending update);
#: larger blocks through the weights.
_MAX_SOLVED_ROWS = 8
_STATE_VERSION = 1
_F64 = np.dtype(np.float64)  # builtin dtypes are singletons: ``a.dtype is _F64`` is the fast exact test


class RecursiveRLS:
    """Recursive ridge regression ``U ≈ Z W`` with Givens updates of ``R`` (``RᵀR = A``) and ``d = R⁻ᵀB``.

    Args:
        n_features: b, the number of columns of Z (regressor columns or random features).
        n_outputs: t, the number of columns of U.
        lam: λ > 0, the ridge regularizer (prior precision of the weights, in units of Z²).
        forgetting: β ∈ (0, 1], the forgetting factor per time step (1 = no forgetting).
        keep_prior: With β < 1, keep the regularizer at strength λ (bounded; see the module docstring).
            ``False`` gives plain exponential forgetting, whose regularizer decays as λβⁿ.

    Raises:
        ConfigurationError: For b < 1, t < 1, λ ≤ 0 or non-finite, β ∉ (0, 1].

    Attributes:
        n_samples_seen: Number of data rows absorbed so far.
        n_steps: Number of time steps (update calls, or steps of :meth:`update_steps`).

    Example:
        >>> import numpy as np
        >>> rls = RecursiveRLS(n_features=2, n_outputs=1, lam=1e-9)
        >>> Z = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
        >>> rls.update(Z, Z @ np.array([[2.0], [-1.0]]))  # U = Z W with W = [2, -1]ᵀ
        >>> np.round(rls.weights.ravel(), 6)
        array([ 2., -1.])
    """

    def __init__(
        self, n_features: int, n_outputs: int, lam: float = 1.0, *, forgetting: float = 1.0,
        keep_prior: bool = True,
    ) -> None:
        check_positive_int("n_features", n_features)
        check_positive_int("n_outputs", n_outputs)
        lam = check_range("lam", lam, 0.0, lo_inclusive=False)
        forgetting = check_range("forgetting", forgetting, 0.0, 1.0, lo_inclusive=False)
        self.n_features = int(n_features)
        self.n_outputs = int(n_outputs)
        self.lam = lam
        self.forgetting = forgetting
        self.keep_prior = bool(keep_prior)
        self._scale = math.sqrt(forgetting)
        bounded = self.keep_prior and forgetting < 1.0
        self._reg = self.n_features * (1.0 - forgetting) * lam if bounded else 0.0
        self._M = np.empty((self.n_features, self.n_features + self.n_outputs))
        self._no_pred = np.empty((0, self.n_outputs))
        self._no_query = np.empty((0, self.n_features))
        self._row_shape = (self.n_features,)
        self._out_shape = (self.n_outputs,)
        # the single-row update is staged in one of these (checked and copied by one compiled call): two,
        # so that a row is staged, and may be refused, while the previous one is still pending in the other
        self._stages = tuple((np.empty((1, self.n_features)), np.empty((1, self.n_outputs)))
                             for _ in range(2))
        self._no_var = np.empty(0)
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget everything: ``R = √λ·I``, ``d = 0``, counters to zero."""
        b = self.n_features
        self._M[:] = 0.0
        self._M[:, :b] = math.sqrt(self.lam) * np.eye(b)
        self.n_samples_seen = 0
        self.n_steps = 0
        self._j = 0
        self._W: np.ndarray | None = None
        # a validated, copied (Z, U) step whose rotations have not run yet (see "Prediction after an update")
        self._pending: tuple[np.ndarray, np.ndarray] | None = None

    def _flush(self) -> None:
        """Run the rotations of the pending update, if any."""
        if self._pending is not None:
            Z, U = self._pending
            self._pending = None
            self._run(Z, U, Z.shape[0], self._no_pred, self._no_pred, self._no_query, self._no_pred,
                      self._no_var)

    @property
    def has_pending(self) -> bool:
        """Whether a deferred update waits to be applied (by the next prediction or :meth:`apply_pending`)."""
        return self._pending is not None

    def apply_pending(self) -> bool:
        """Run the rotations of a deferred update now (in idle time) instead of inside the next prediction.

        The learned state is the same bit for bit either way; the next prediction is then one triangular
        solve instead of the fused update and solve (its value may differ in the last bits).

        Returns:
            Whether an update was pending.
        """
        pending = self._pending is not None
        self._flush()
        return pending

    def set_forgetting(self, forgetting: float) -> None:
        """Change β from the next time step on, keeping the learned state.

        The recursion of the module docstring simply continues with the new β (and the prior row's
        ``c = b(1 − β)λ``): the past keeps the weights it had, the future is weighted by the new β.

        Args:
            forgetting: β ∈ (0, 1].

        Raises:
            ConfigurationError: For β ∉ (0, 1] (the learner is unchanged).
        """
        forgetting = float(forgetting)
        if not (0.0 < forgetting <= 1.0):
            raise ConfigurationError(f"forgetting must be in (0, 1], got {forgetting!r}")
        self._flush()  # a deferred update belongs to the time step with the old β
        self.forgetting = forgetting
        self._scale = math.sqrt(forgetting)
        bounded = self.keep_prior and forgetting < 1.0
        self._reg = self.n_features * (1.0 - forgetting) * self.lam if bounded else 0.0

    def factor_copy(self) -> np.ndarray:
        """Return a C-contiguous copy of ``[R | d]`` (b, b + t), a pending update applied first.

        What a copy frozen for serving keeps: ``solve_predict`` predicts from it, ``z W = (z R⁻¹) d``
        and ``z A⁻¹ zᵀ = ‖R⁻ᵀ zᵀ‖²``, without the learner.
        """
        self._flush()
        return self._M.copy()

    @property
    def R(self) -> np.ndarray:  # noqa: N802 (the factor's name in the literature)
        """The upper-triangular factor (b, b), ``RᵀR = A`` (read-only view)."""
        self._flush()
        v = self._M[:, : self.n_features]
        v.flags.writeable = False
        return v

    @property
    def d(self) -> np.ndarray:
        """``d = R⁻ᵀB`` (b, t) (read-only view)."""
        self._flush()
        v = self._M[:, self.n_features :]
        v.flags.writeable = False
        return v

    @property
    def weights(self) -> np.ndarray:
        """The ridge solution ``W = R⁻¹d = A⁻¹B`` (b, t), cached until the next update (read-only)."""
        self._flush()
        if self._W is None:
            if self.n_features <= _SMALL_SOLVE:
                W = back_substitute(self._M)
            else:
                b = self.n_features
                W = solve_triangular(self._M[:, :b], self._M[:, b:], lower=False, check_finite=False)
            W.flags.writeable = False
            self._W = W
        return self._W

    def shift_rhs(self, G: Any) -> None:
        """Subtract G from the right-hand side ``B = Σ_m β^{n−m} Z_mᵀU_m``: ``d ← d − R⁻ᵀG`` (O(b²t)).

        The learner is then the one that learned targets changed by ΔU_m with ``Σ_m β^{n−m} Z_mᵀΔU_m = −G``
        (the factor is unchanged): e.g. targets ``y − Φθ`` of a new reference θ, given the cross-products
        of the features with Φ. One triangular solve with t right-hand sides.

        Args:
            G: (b, t) in units of Z·U.

        Raises:
            RejectedSampleError: A wrong shape or a non-finite value (the learner is unchanged).

        Example:
            >>> import numpy as np
            >>> rls = RecursiveRLS(n_features=2, n_outputs=1, lam=1e-9)
            >>> Z = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
            >>> rls.update(Z, np.ones((3, 1)))
            >>> rls.shift_rhs(Z.T @ np.ones((3, 1)))  # as if the targets had been 0
            >>> np.round(rls.weights.ravel(), 9) + 0.0
            array([0., 0.])
        """
        G2 = np.asarray(G, dtype=np.float64)
        if G2.shape != (self.n_features, self.n_outputs) or not np.isfinite(G2).all():
            raise RejectedSampleError(f"G must be ({self.n_features}, {self.n_outputs}) finite values, "
                                      f"got shape {G2.shape}")
        self._flush()
        b = self.n_features
        self._M[:, b:] -= self._solve_rt(G2)
        self._W = None

    #: Rows of R per block of :meth:`_solve_rt`.
    SOLVE_BLOCK = 128

    def _solve_rt(self, G: np.ndarray) -> np.ndarray:
        """``R⁻ᵀG`` (b, t) by blocks of rows of R, in place of the factor (no copy of R).

        R is a strided view of ``[R | d]``, which a triangular solve of the whole would copy first (8 MB at
        b = 1000); by blocks, each diagonal block is solved (a small copy) and the rest of G updated by one
        matrix product with the block's rows (BLAS 3, reading R in place): ``X_i = R_iiᵀ⁻¹ G_i``,
        ``G_j ← G_j − R_ijᵀ X_i`` for the blocks j after i.
        """
        b, nb = self.n_features, self.SOLVE_BLOCK
        R = self._M[:, :b]
        X = np.array(G, dtype=np.float64, order="C")
        for i0 in range(0, b, nb):
            i1 = min(i0 + nb, b)
            X[i0:i1] = solve_triangular(R[i0:i1, i0:i1], X[i0:i1], trans="T", lower=False, check_finite=False)
            if i1 < b:
                X[i1:] -= R[i0:i1, i1:].T @ X[i0:i1]
        return X

    def condition_number(self) -> float:
        """``cond₂(R)`` (= √cond(A)), from the singular values of R (O(b³): diagnostics only)."""
        self._flush()
        s = np.linalg.svd(self._M[:, : self.n_features], compute_uv=False)
        return float(s[0] / s[-1]) if s[-1] > 0 else math.inf

    # ------------------------------------------------------------------ learning
    def update(self, Z: np.ndarray, U: np.ndarray, *, checked: bool = False) -> None:
        """Absorb one time step of k ≥ 1 rows in O(k·b²).

        The rows are checked and copied now; the rotations run at the next use of the state, fused with
        the next :meth:`predict` if that comes first (see the module docstring).

        Args:
            Z: (k, b) rows, or (b,) for one row.
            U: (k, t) targets, or (t,) for one row.
            checked: Z and U are C-contiguous float64 (k, b) / (k, t) arrays of the right shapes, as a
                combination of learners passes them after validating its input once (their values are
                still checked).

        Raises:
            RejectedSampleError: Wrong shapes, or non-finite / absurdly large (> 1e150) entries; the
                learner is left unchanged.
        """
        if checked:
            self._defer(Z, U)
            return
        if (type(Z) is np.ndarray and type(U) is np.ndarray and Z.shape == self._row_shape
                and U.shape == self._out_shape and Z.dtype is _F64 and U.dtype is _F64
                and Z.flags.c_contiguous and U.flags.c_contiguous):
            # the common single-row step: one compiled call checks and copies into a stage buffer that the
            # pending step (if any) does not use; a refused row leaves that step pending
            stage = self._stages[1] if self._pending is self._stages[0] else self._stages[0]
            if not stage_row(Z, U, stage[0], stage[1], MAX_ABS_INPUT):
                raise RejectedSampleError(
                    f"Z or U contains NaN, inf or entries larger than {MAX_ABS_INPUT:g} in magnitude")
            if self._pending is not None:
                self._flush()
            self._pending = stage
            self._W = None
            self.n_steps += 1
            self.n_samples_seen += 1
            return
        Z2, U2, _ = self._check_rows(Z, U)
        self._defer(Z2, U2)

    def _defer(self, Z2: np.ndarray, U2: np.ndarray) -> None:
        """Validate the values of one step and leave a copy of it pending."""
        self.defer_step(self.checked_step(Z2, U2))

    @staticmethod
    def checked_step(Z2: np.ndarray, U2: np.ndarray, *,
                      owned: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Check the values of one step's (k, b) / (k, t) rows and return copies (the learner is untouched).

        With :meth:`defer_step`, the two halves of :meth:`_defer`: a caller updating several learners
        checks every learner's rows first, so that a refused value leaves all of them unchanged. With
        ``owned`` the arrays themselves are kept (no copy): for arrays nobody writes to afterwards.

        Raises:
            RejectedSampleError: On NaN, inf or entries larger than :data:`MAX_ABS_INPUT` in magnitude.
        """
        if owned:
            ok, Zc, Uc = values_within(Z2, U2, MAX_ABS_INPUT), Z2, U2
        else:
            ok, Zc, Uc = checked_copies(Z2, U2, MAX_ABS_INPUT)  # copies: the caller may reuse its arrays
        if not ok:
            raise RejectedSampleError(f"Z or U contains NaN, inf or entries larger than {MAX_ABS_INPUT:g} "
                                      "in magnitude")
        return Zc, Uc

    def defer_step(self, step: tuple[np.ndarray, np.ndarray]) -> None:
        """Leave one step checked and copied by :meth:`checked_step` pending (cannot fail)."""
        self._flush()
        self._pending = step
        self._W = None
        self.n_steps += 1
        self.n_samples_seen += step[0].shape[0]

    def predict_update(self, Z: np.ndarray, U: np.ndarray, *, checked: bool = False) -> np.ndarray:
        """Predict the rows with the current weights, then absorb them as one time step (one pass).

        The a-priori prediction ``Z W_old`` comes out of the update's rotations; it equals
        ``predict(Z)`` called just before the update (to rounding).

        Args:
            Z: (k, b) rows, or (b,) for one row.
            U: (k, t) targets, or (t,) for one row.
            checked: Z and U are already validated C-contiguous float64 (k, b) / (k, t) arrays.

        Returns:
            The a-priori prediction, (k, t) or (t,) like U.

        Raises:
            RejectedSampleError: As :meth:`update`; the learner is left unchanged.
        """
        if checked:
            return self._predict_update_rows(Z, U)
        Z2, U2, single = self._check_rows(Z, U)
        P = self._predict_update_rows(Z2, U2)
        return P[0] if single else P

    def _predict_update_rows(self, Z2: np.ndarray, U2: np.ndarray) -> np.ndarray:
        """:meth:`predict_update` of validated C-contiguous float64 (k, b) / (k, t) arrays."""
        k = Z2.shape[0]
        if k > _MAX_TRACKED_ROWS:
            P = Z2 @ self.weights
            self._step(Z2, U2, k, self._no_pred)
        else:
            P = np.empty((k, self.n_outputs))
            self._step(Z2, U2, k, P)
        return P

    def update_steps(self, Z: np.ndarray, U: np.ndarray, rows_per_step: int = 1, *,
                     predict: bool = False) -> np.ndarray | None:
        """Run ``len(Z) // rows_per_step`` consecutive time steps in one compiled call.

        Equivalent to calling :meth:`update` (or :meth:`predict_update`) on consecutive blocks of
        ``rows_per_step`` rows, without the per-call overhead (offline replay, long streams).

        Args:
            Z: (n, b) rows, n a multiple of ``rows_per_step``.
            U: (n, t) targets.
            rows_per_step: Rows per time step (1 ≤ rows_per_step ≤ 32 when ``predict``).
            predict: Also return the a-priori predictions of every row.

        Returns:
            (n, t) a-priori predictions if ``predict``, else None.

        Raises:
            RejectedSampleError: Wrong shapes, n not a multiple of ``rows_per_step``, non-finite entries;
                the learner is left unchanged.
        """
        check_positive_int("rows_per_step", rows_per_step)
        if predict and rows_per_step > _MAX_TRACKED_ROWS:
            raise ConfigurationError(f"rows_per_step must be <= {_MAX_TRACKED_ROWS} with predict=True")
        Z2, U2, _ = self._check_rows(Z, U)
        if Z2.shape[0] % rows_per_step:
            raise RejectedSampleError(f"the number of rows ({Z2.shape[0]}) is not a multiple of "
                                      f"rows_per_step ({rows_per_step})")
        P = np.empty((Z2.shape[0], self.n_outputs)) if predict else self._no_pred
        self._step(Z2, U2, rows_per_step, P)
        return P if predict else None

    @property
    def rows_out_per_step(self) -> int:
        """Rows rotated out per time step besides the data rows: 1 with the prior-keeping row, else 0."""
        return 1 if self._reg > 0.0 else 0

    def predict_update_rows_out(self, Z2: np.ndarray, U2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One time step that also returns the rows the rotations leave below ``[R | d]``.

        For validated C-contiguous float64 (k, b) / (k, t) arrays with k ≤ 32. The returned ``E``
        ((k + :attr:`rows_out_per_step`), t) satisfies ``S_new = β·S_old + EᵀE`` where
        ``S = Σ β^{n−m} U_mᵀU_m − dᵀd`` is the minimum of the (weighted, regularized) least-squares
        cost per pair of output columns: it is what the outputs keep unexplained by ``Z W``, the
        quantity a second learner needs to fit a joint model on top of this one (profiling W out).

        Returns:
            ``(P, E)``: the a-priori prediction ``Z W_old`` (k, t) and the rotated-out rows.
        """
        k = Z2.shape[0]
        if k > _MAX_TRACKED_ROWS:
            raise ValueError(f"at most {_MAX_TRACKED_ROWS} rows per step")
        P = np.empty((k, self.n_outputs))
        E = np.empty((k + self.rows_out_per_step, self.n_outputs))
        self._step(Z2, U2, k, P, E)
        return P, E

    def _step(self, Z: np.ndarray, U: np.ndarray, rows_per_step: int, P: np.ndarray,
              E: np.ndarray | None = None) -> None:
        self._flush()
        E = self._no_pred if E is None else E
        if not self._run(Z, U, rows_per_step, P, E, self._no_query, self._no_pred, self._no_var):
            raise RejectedSampleError(f"Z or U contains NaN, inf or entries larger than {MAX_ABS_INPUT:g} in "
                             "magnitude")
        n_steps = Z.shape[0] // rows_per_step
        self.n_steps += n_steps
        self.n_samples_seen += Z.shape[0]

    def _run(self, Z: np.ndarray, U: np.ndarray, rows_per_step: int, P: np.ndarray, E: np.ndarray,
             Q: np.ndarray, QP: np.ndarray, Qvar: np.ndarray) -> bool:
        """Call the kernel; False (state untouched) if a value was rejected. Counters are the caller's."""
        # the kernel checks every value (NaN, inf, > MAX_ABS_INPUT) before it touches the state
        j = int(qr_rls_steps(self._M, Z, U, rows_per_step, self._scale, self._reg, self._j, P, MAX_ABS_INPUT,
                             E, Q, QP, Qvar))
        if j < 0:
            return False
        self._W = None
        self._j = j
        return True

    # ------------------------------------------------------------------ prediction
    @overload
    def predict(self, Z: np.ndarray, *, return_variance: Literal[False] = False,
                checked: bool = False) -> np.ndarray: ...

    @overload
    def predict(self, Z: np.ndarray, *, return_variance: Literal[True],
                checked: bool = False) -> tuple[np.ndarray, np.ndarray]: ...

    @overload
    def predict(self, Z: np.ndarray, *, return_variance: bool,
                checked: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]: ...

    def predict(self, Z: np.ndarray, *, return_variance: bool = False,
                checked: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """``Z W``, and optionally ``z A⁻¹ zᵀ`` per row, without forming ``W`` for a few rows.

        Up to 8 rows are predicted by one forward substitution ``Rᵀv = zᵀ`` (``z W = v·d``,
        ``z A⁻¹ zᵀ = ‖v‖²``, O(k·b²)), fused with the rotations of a pending :meth:`update` when there is
        one; more rows use the cached weights, ``Z W``. The path depends on k only, so equal states give
        bit-equal predictions; both give ``Z A⁻¹ B`` up to rounding (≈ cond(R)·ε relative).

        Args:
            Z: (k, b) rows or (b,) for one row.
            return_variance: Also return ``z A⁻¹ zᵀ`` per row (see :meth:`variance`).
            checked: Z is an already validated C-contiguous float64 (k, b) array (a combination of
                learners validates its input once); the result is (k, t) (and (k,)).

        Returns:
            (k, t), or (t,) for one row; with ``return_variance`` the pair ``(prediction, variance)``,
            the variance (k,) or of shape () for one row.

        Raises:
            RejectedSampleError: Wrong shape or non-finite entries.
        """
        if checked:
            P, var = self._predict_rows(Z, return_variance)
            return (P, var) if return_variance else P  # type: ignore[return-value]
        if (type(Z) is np.ndarray and Z.shape == self._row_shape and Z.dtype is _F64
                and Z.flags.c_contiguous):
            return self._predict_row(Z, return_variance)
        Z2, single = self._check_features(Z)
        P, var = self._predict_rows(Z2, return_variance)
        if single:
            return (P[0], var[0]) if return_variance else P[0]  # type: ignore[index]
        return (P, var) if return_variance else P  # type: ignore[return-value]

    def _predict_row(self, z: np.ndarray, want_variance: bool) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """:meth:`predict` of one C-contiguous float64 (b,) row: the kernels check its values.

        The same kernels and operations as :meth:`_predict_rows` with k = 1 (so the same bits), in one
        compiled call that checks the row before it touches the state.
        """
        P = np.empty(self.n_outputs)
        pending = self._pending
        if pending is not None:
            j, var = predict_row_pending(self._M, pending[0], pending[1], self._scale, self._reg, self._j,
                                         z, P, MAX_ABS_INPUT)
            if j < 0:
                if j == -1:  # the pending rows were checked when they were staged
                    raise RuntimeError("a pending update was refused by the kernel")
                raise RejectedSampleError(
                    f"Z contains NaN, inf or entries larger than {MAX_ABS_INPUT:g} in magnitude")
            self._pending = None
            self._W = None
            self._j = j
        else:
            var = predict_row(self._M, z, P, MAX_ABS_INPUT)
            if var < 0.0:
                raise RejectedSampleError(
                    f"Z contains NaN, inf or entries larger than {MAX_ABS_INPUT:g} in magnitude")
        # the variance is a () scalar, as var[0] of the general path
        return (P, np.float64(var)) if want_variance else P  # type: ignore[return-value]

    def _predict_rows(self, Z2: np.ndarray, want_variance: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`predict` of a validated C-contiguous float64 (k, b) array: ``(Z W, var or None)``."""
        k = Z2.shape[0]
        # the path depends on k only (not on what is cached), so equal states give bit-equal predictions
        if k <= _MAX_SOLVED_ROWS:
            P = np.empty((k, self.n_outputs))
            var = np.empty(k)
            if self._pending is not None:
                Zp, Up = self._pending
                self._pending = None
                self._run(Zp, Up, Zp.shape[0], self._no_pred, self._no_pred, Z2, P, var)
            else:
                solve_predict(self._M, Z2, P, var)
            return P, (var if want_variance else None)
        P = Z2 @ self.weights
        return P, (self._variance_rows(Z2) if want_variance else None)

    def variance(self, Z: np.ndarray, *, checked: bool = False) -> np.ndarray:
        """``z A⁻¹ zᵀ`` per row by one triangular solve (``‖R⁻ᵀzᵀ‖²``).

        Multiply by the noise variance σ² for the predictive variance of each output; with forgetting,
        ``A`` holds the forgetting-weighted data.

        Args:
            Z: (k, b) rows or (b,) for one row.
            checked: Z is an already validated C-contiguous float64 (k, b) array; the result is (k,).

        Returns:
            (k,) non-negative values, or a float array of shape () for one row.

        Raises:
            RejectedSampleError: Wrong shape or non-finite entries.
        """
        if checked:
            return self._variance_rows(Z)
        Z2, single = self._check_features(Z)
        out = self._variance_rows(Z2)
        return out[0] if single else out

    def _variance_rows(self, Z2: np.ndarray) -> np.ndarray:
        """Return the relative predictive variance of validated rows Z2 (no pending update left behind)."""
        self._flush()
        if Z2.shape[0] <= _MAX_SOLVED_ROWS:
            P = np.empty((Z2.shape[0], self.n_outputs))
            out = np.empty(Z2.shape[0])
            solve_predict(self._M, Z2, P, out)
            return out
        V = solve_triangular(self._M[:, : self.n_features], Z2.T, trans="T", lower=False, check_finite=False)
        return np.einsum("ij,ij->j", V, V)

    # ------------------------------------------------------------------ validation
    def _check_features(self, Z: Any, values: bool = True) -> tuple[np.ndarray, bool]:
        if (type(Z) is np.ndarray and Z.shape == self._row_shape and Z.dtype == np.float64
                and Z.flags.c_contiguous):
            Z2 = Z.reshape(1, -1)  # the common case, one contiguous float64 row: a (1, b) view
            if values and not within(Z2, MAX_ABS_INPUT):
                raise RejectedSampleError(
                    f"Z contains NaN, inf or entries larger than {MAX_ABS_INPUT:g} in magnitude")
            return Z2, True
        Z2 = np.asarray(Z, dtype=np.float64)
        single = Z2.ndim == 1
        if single:
            Z2 = Z2[None, :]
        if Z2.ndim != 2 or Z2.shape[1] != self.n_features:
            raise RejectedSampleError(f"Z must have shape (k, {self.n_features}) or ({self.n_features},), "
                             f"got {np.shape(Z)}")
        if Z2.shape[0] == 0:
            raise RejectedSampleError("Z has no rows")
        Z2 = np.ascontiguousarray(Z2)
        if values and not within(Z2, MAX_ABS_INPUT):
            raise RejectedSampleError(
                f"Z contains NaN, inf or entries larger than {MAX_ABS_INPUT:g} in magnitude")
        return Z2, single

    def _check_rows(self, Z: Any, U: Any) -> tuple[np.ndarray, np.ndarray, bool]:
        Z2, single = self._check_features(Z, values=False)  # values are checked in the kernel
        U2 = np.asarray(U, dtype=np.float64)
        t = self.n_outputs
        if single:
            if U2.shape != (t,):
                raise RejectedSampleError(f"U must have shape ({t},) for a single row, got {np.shape(U)}")
            U2 = U2[None, :]
        elif U2.shape != (Z2.shape[0], t):
            raise RejectedSampleError(f"U must have shape ({Z2.shape[0]}, {t}), got {np.shape(U)}")
        return Z2, np.ascontiguousarray(U2), single

    # ------------------------------------------------------------------ persistence
    def copy(self) -> RecursiveRLS:
        """Return an independent deep copy (same hyperparameters and learned state)."""
        return RecursiveRLS.from_state_dict(self.state_dict())

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the whole learner as arrays (keys start with ``prefix``), for :func:`atomic_save_npz`."""
        self._flush()
        return {
            f"{prefix}version": np.array(_STATE_VERSION),
            f"{prefix}n_features": np.array(self.n_features),
            f"{prefix}n_outputs": np.array(self.n_outputs),
            f"{prefix}lam": np.array(self.lam),
            f"{prefix}forgetting": np.array(self.forgetting),
            f"{prefix}keep_prior": np.array(self.keep_prior),
            f"{prefix}M": self._M.copy(),
            f"{prefix}n_samples_seen": np.array(self.n_samples_seen),
            f"{prefix}n_steps": np.array(self.n_steps),
            f"{prefix}j": np.array(self._j),
        }

    @classmethod
    def from_state_dict(cls, state: dict[str, np.ndarray], prefix: str = "") -> RecursiveRLS:
        """Rebuild a learner from :meth:`state_dict` output.

        Raises:
            CheckpointError: Missing keys, wrong version, inconsistent shapes or non-finite state.
        """
        try:
            version = int(state[f"{prefix}version"])
            if version != _STATE_VERSION:
                raise CheckpointError(f"unsupported RecursiveRLS state version {version}")
            obj = cls(int(state[f"{prefix}n_features"]), int(state[f"{prefix}n_outputs"]),
                      float(state[f"{prefix}lam"]), forgetting=float(state[f"{prefix}forgetting"]),
                      keep_prior=bool(state[f"{prefix}keep_prior"]))
            M = np.asarray(state[f"{prefix}M"], dtype=np.float64)
            n_samples_seen = int(state[f"{prefix}n_samples_seen"])
            n_steps = int(state[f"{prefix}n_steps"])
            j = int(state[f"{prefix}j"])
        except KeyError as err:
            raise CheckpointError(f"RecursiveRLS state is missing key {err}") from err
        except (TypeError, ValueError) as err:
            raise CheckpointError(f"invalid RecursiveRLS state: {err}") from err
        if M.shape != obj._M.shape:
            raise CheckpointError(f"RecursiveRLS state M has shape {M.shape}, expected {obj._M.shape}")
        if not np.isfinite(M).all():
            raise CheckpointError("RecursiveRLS state M is not finite")
        R = M[:, : obj.n_features]
        if np.any(np.tril(R, -1) != 0.0) or np.any(np.diag(R) < 0.0):
            raise CheckpointError("RecursiveRLS state R is not upper triangular with a non-negative diagonal")
        if obj.keep_prior and np.any(np.diag(R) == 0.0):
            # with the prior kept A ⪰ (min over the cycle of the regularizer)·I > 0, so a zero pivot can only
            # come from a damaged file, and every later solve would fail
            raise CheckpointError("RecursiveRLS state R is singular (zero on the diagonal)")
        if not (0 <= j < obj.n_features) or n_samples_seen < 0 or n_steps < 0:
            raise CheckpointError("RecursiveRLS state counters are out of range")
        obj._M[:] = M
        obj.n_samples_seen, obj.n_steps, obj._j = n_samples_seen, n_steps, j
        return obj

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the learner to one ``.npz`` file atomically (temp file + rename)."""
        atomic_save_npz(path, self.state_dict())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> RecursiveRLS:
        """Read a learner written by :meth:`save`; predictions are reproduced bit for bit.

        Raises:
            CheckpointError: Missing, corrupt or inconsistent file.
        """
        return cls.from_state_dict(load_npz(path))

    def __repr__(self) -> str:
        return (f"RecursiveRLS(n_features={self.n_features}, n_outputs={self.n_outputs}, lam={self.lam}, "
                f"forgetting={self.forgetting}, keep_prior={self.keep_prior}, "
                f"n_samples_seen={self.n_samples_seen})")
