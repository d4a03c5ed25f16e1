"""Prediction after an update: the forward-substitution kernel, the deferred update fused with the next
prediction, and the models' predict_one paths that use them.

Tolerances. A forward substitution with an upper-triangular ``R`` is backward stable: the computed ``v``
solves ``(R + δR)ᵀ v = zᵀ`` with ``|δR| ≤ b·ε·|R|``, so ``‖δv‖ ≤ b·ε·κ₂(R)·‖v‖`` to first order, and a
prediction ``p = v·d`` is off by at most ``‖δv‖·‖d‖``. Every comparison between two computations of the
same ``R`` therefore uses ``tol = 10 · b · ε · κ₂(R) · ‖v‖ · ‖d‖`` (factor 10 as margin); against the closed
form, whose Cholesky solve of ``A = RᵀR`` carries ``κ₂(A) = κ₂(R)²``, ``κ₂(R)`` becomes ``κ₂(A)``.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers.reference_rrls import forward_predict
from helpers.rrls import closed_form, random_steps
from scipy.linalg import cho_factor, cho_solve

from semiparam_ros.core.learners._kernels import solve_predict
from semiparam_ros.core.learners.cascade import SemiparametricModel
from semiparam_ros.core.learners.joint import JointSemiparametricModel
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.errors import RejectedSampleError

EPS = np.finfo(float).eps


def bound(rls: RecursiveRLS, Zq: np.ndarray, kappa: float) -> np.ndarray:
    """Per-row ``10 · b · ε · κ · ‖v‖ · ‖d‖`` (see the module docstring)."""
    _, var = forward_predict(np.hstack([rls.R, rls.d]), Zq)
    return 10 * rls.n_features * EPS * kappa * np.sqrt(var) * np.linalg.norm(rls.d)


@pytest.mark.parametrize("b", [1, 2, 3, 4, 5, 9, 33])
@pytest.mark.parametrize("kq", [1, 3, 8])
def test_solve_kernel_equals_numpy_reference(b, kq):
    rng = np.random.default_rng(b * 10 + kq)
    t = 3
    rls = RecursiveRLS(b, t, 0.5, forgetting=0.99)
    for Z, U in random_steps(rng, 40, 2, b, t):
        rls.update(Z, U)
    M = np.hstack([rls.R, rls.d])
    Zq = rng.standard_normal((kq, b))
    P, var = np.empty((kq, t)), np.empty(kq)
    solve_predict(M, Zq, P, var)
    P_ref, var_ref = forward_predict(M, Zq)
    tol = bound(rls, Zq, rls.condition_number())
    assert np.all(np.abs(P - P_ref) <= tol[:, None])
    assert np.all(np.abs(var - var_ref) <= 10 * b * EPS * rls.condition_number() * var_ref)


@pytest.mark.parametrize("kq", [1, 2, 6, 8, 9])
@pytest.mark.parametrize(("k", "beta"), [(1, 1.0), (1, 0.99), (6, 1.0), (6, 0.97)])
@pytest.mark.parametrize("b", [7, 24])
def test_predict_after_update_equals_closed_form_and_the_weights_path(kq, k, beta, b):
    """Predict right after each update (the fused path for kq ≤ 8) against Z A⁻¹ B and Z W."""
    rng = np.random.default_rng(kq + 10 * k + b)
    t, lam = 4, 0.6
    steps = random_steps(rng, 120, k, b, t)
    rls = RecursiveRLS(b, t, lam, forgetting=beta)
    seen = []
    for n, (Z, U) in enumerate(steps):
        rls.update(Z, U)
        seen.append((Z, U))
        if n % 17 and n != len(steps) - 1:
            continue
        Zq = rng.standard_normal((kq, b))
        P, var = rls.predict(Zq, return_variance=True)
        A, B, _ = closed_form(seen, b, t, lam, beta)
        kappa_A = np.linalg.cond(A)
        tol_cf = bound(rls, Zq, kappa_A)
        assert np.all(np.abs(P - Zq @ cho_solve(cho_factor(A), B)) <= tol_cf[:, None])
        var_cf = np.einsum("ij,ij->i", Zq, cho_solve(cho_factor(A), Zq.T).T)
        assert np.all(np.abs(var - var_cf) <= 10 * b * EPS * kappa_A * var_cf)
        tol = bound(rls, Zq, rls.condition_number())
        assert np.all(np.abs(P - Zq @ rls.weights) <= tol[:, None])


@pytest.mark.parametrize("beta", [1.0, 0.98])
@pytest.mark.parametrize("kq", [1, 5])
def test_deferred_update_leaves_the_same_state_as_an_immediate_one(beta, kq):
    """The rotations fused with a prediction are the update's own: the state is bit-for-bit the same."""
    rng = np.random.default_rng(5)
    b, t = 21, 3
    lazy = RecursiveRLS(b, t, 0.3, forgetting=beta)
    eager = RecursiveRLS(b, t, 0.3, forgetting=beta)
    for Z, U in random_steps(rng, 80, 1, b, t):
        lazy.update(Z, U)
        Zq = rng.standard_normal((kq, b))
        got, got_var = lazy.predict(Zq, return_variance=True)
        eager.predict_update(Z, U)  # runs the rotations at once
        # the fused substitution equals solve_predict on the updated factor (other blocking of the rows)
        P, var = np.empty((kq, t)), np.empty(kq)
        solve_predict(np.hstack([eager.R, eager.d]), Zq, P, var)
        kappa = eager.condition_number()
        assert np.all(np.abs(got - P) <= bound(eager, Zq, kappa)[:, None])
        assert np.all(np.abs(got_var - var) <= 10 * b * EPS * kappa * var)
        assert lazy.n_samples_seen == eager.n_samples_seen and lazy.n_steps == eager.n_steps
    for key, value in eager.state_dict().items():
        assert np.array_equal(value, lazy.state_dict()[key]), key



@pytest.mark.parametrize("beta", [1.0, 0.995])
@pytest.mark.parametrize("b", [64, 131])
def test_fused_query_sweeps_at_vector_lengths(beta, b):
    """Long rows (vectorised loop bodies and their remainders) through every fused sweep of one query row.

    β = 1: the pair sweep (one data row); β < 1: also the two-active-row sweep (data row plus the
    regularizer row, whose coordinate cycles over all b). The state must be bit-for-bit the immediate
    update's; the prediction and variance must equal the pure-numpy dot-product substitution on that
    state within the conditioning bound of the module docstring.
    """
    rng = np.random.default_rng(b + int(1000 * beta))
    t = 6
    lazy = RecursiveRLS(b, t, 0.8, forgetting=beta)
    eager = RecursiveRLS(b, t, 0.8, forgetting=beta)
    for n, (Z, U) in enumerate(random_steps(rng, 2 * b + 7, 1, b, t)):
        lazy.update(Z, U)
        eager.predict_update(Z, U)
        if n % 5 and n < 2 * b:
            continue
        zq = rng.standard_normal(b)
        got, got_var = lazy.predict(zq, return_variance=True)
        M = np.hstack([eager.R, eager.d])
        P_ref, var_ref = forward_predict(M, zq)
        kappa = eager.condition_number()
        assert np.all(np.abs(got - P_ref[0]) <= bound(eager, zq[None, :], kappa)[0])
        assert abs(got_var - var_ref[0]) <= 10 * b * EPS * kappa * var_ref[0]
        for key, value in eager.state_dict().items():
            assert np.array_equal(value, lazy.state_dict()[key]), key

def test_pending_update_is_a_copy_and_counters_move_at_once():
    rng = np.random.default_rng(6)
    b, t = 8, 2
    z, u = rng.standard_normal(b), rng.standard_normal(t)
    a, ref = RecursiveRLS(b, t), RecursiveRLS(b, t)
    a.update(z, u)
    ref.update(z.copy(), u.copy())
    assert a.n_samples_seen == 1 and a.n_steps == 1
    z[:] = 1e3  # the caller reuses its buffers before the rotations have run
    u[:] = -1e3
    assert np.array_equal(a.weights, ref.weights)


def test_rejected_update_raises_at_once_and_keeps_the_pending_one():
    rng = np.random.default_rng(7)
    b, t = 6, 2
    a, ref = RecursiveRLS(b, t), RecursiveRLS(b, t)
    Z, U = rng.standard_normal((2, b)), rng.standard_normal((2, t))
    a.update(Z, U)
    ref.update(Z, U)
    with pytest.raises(ValueError, match="NaN"):
        a.update(np.full(b, np.nan), np.zeros(t))
    with pytest.raises(ValueError, match="NaN"):
        a.predict(np.full(b, np.inf))
    assert a.n_samples_seen == 2
    assert np.array_equal(a.predict(Z), ref.predict(Z))
    for key, value in ref.state_dict().items():
        assert np.array_equal(value, a.state_dict()[key]), key


@pytest.mark.parametrize("beta", [1.0, 0.98])
def test_single_row_fast_path_gives_the_general_paths_bits(beta):
    """One contiguous float64 row (staged update, one-call prediction) against (1, b) blocks, bit for bit.

    The fast path runs the same kernels on the same operands as the general one (``_check_rows`` and
    ``predict(Z, checked=True)`` with k = 1), so predictions, variances and the state must be identical;
    consecutive updates with no prediction between them (the two stage buffers alternating) included.
    """
    rng = np.random.default_rng(11)
    b, t = 37, 4
    fast = RecursiveRLS(b, t, 0.4, forgetting=beta)
    slow = RecursiveRLS(b, t, 0.4, forgetting=beta)
    for n, (Z, U) in enumerate(random_steps(rng, 60, 1, b, t)):
        fast.update(Z[0], U[0])  # (b,), (t,): the staged path
        slow.update(Z, U.copy())  # (1, b), (1, t): _check_rows and a checked copy
        if n % 3 == 2:
            continue  # leave two updates in a row to the next one's flush
        zq = rng.standard_normal(b)
        if n % 2:
            fast.R, slow.R  # noqa: B018 (flush both: the prediction then takes the solve-only kernel)
        got, got_var = fast.predict(zq, return_variance=True)
        want, want_var = slow.predict(zq[None, :], return_variance=True, checked=True)
        assert np.array_equal(got, want[0]) and got_var == want_var[0]
        assert got.shape == (t,) and np.shape(got_var) == ()
        assert fast.n_samples_seen == slow.n_samples_seen and fast.n_steps == slow.n_steps
    for key, value in slow.state_dict().items():
        assert np.array_equal(value, fast.state_dict()[key]), key


@pytest.mark.parametrize("beta", [1.0, 0.98])
def test_refused_single_rows_leave_the_staged_step_pending(beta):
    """A refused row (update or query; NaN, inf or > MAX_ABS_INPUT) raises and changes nothing.

    In particular a staged single-row update stays pending and is applied exactly once, whichever stage
    buffer the refused row was checked in.
    """
    rng = np.random.default_rng(12)
    b, t = 9, 3
    a = RecursiveRLS(b, t, forgetting=beta)
    ref = RecursiveRLS(b, t, forgetting=beta)
    bad = [np.nan, np.inf, -np.inf, 2e150]
    for n, (Z, U) in enumerate(random_steps(rng, 12, 1, b, t)):
        a.update(Z[0], U[0])
        ref.update(Z[0], U[0])  # the same staged path, never shown a refused row
        z_bad, u_bad = Z[0].copy(), U[0].copy()
        if n % 2:
            z_bad[n % b] = bad[n % 4]
        else:
            u_bad[n % t] = bad[n % 4]
        with pytest.raises(RejectedSampleError, match="NaN"):
            a.update(z_bad, u_bad)
        q_bad = rng.standard_normal(b)
        q_bad[(3 * n) % b] = bad[(n + 1) % 4]
        with pytest.raises(RejectedSampleError, match="NaN"):
            a.predict(q_bad)  # with the staged update pending
        assert a.n_samples_seen == ref.n_samples_seen and a.n_steps == ref.n_steps
        if n % 3 == 0:
            zq = rng.standard_normal(b)
            assert np.array_equal(a.predict(zq), ref.predict(zq))  # both run the pending update now
            with pytest.raises(RejectedSampleError, match="NaN"):
                a.predict(q_bad)  # nothing pending: the solve-only kernel refuses it too
    for key, value in ref.state_dict().items():
        assert np.array_equal(value, a.state_dict()[key]), key


def test_single_row_predictions_are_fresh_arrays():
    """Each prediction is a new array: later updates and predictions do not overwrite a returned one."""
    rng = np.random.default_rng(13)
    b, t = 7, 3
    rls = RecursiveRLS(b, t)
    kept = []
    for Z, U in random_steps(rng, 6, 1, b, t):
        rls.update(Z[0], U[0])
        p, v = rls.predict(rng.standard_normal(b), return_variance=True)
        kept.append((p, p.copy(), v, float(v)))
    for p, p0, v, v0 in kept:
        assert np.array_equal(p, p0) and float(v) == v0
    assert not any(np.shares_memory(x[0], y[0]) for i, x in enumerate(kept) for y in kept[i + 1:])


def test_single_row_shapes():
    rls = RecursiveRLS(5, 3)
    rls.update(np.ones(5), np.ones(3))
    assert (rls.predict(np.ones((1, 5)), checked=True), None)[1] is None  # no variance unless asked for
    p, v = rls.predict(np.ones(5), return_variance=True)
    assert p.shape == (3,) and np.shape(v) == ()
    assert rls.predict(np.ones((2, 5))).shape == (2, 3)


def _regressor(x: np.ndarray) -> np.ndarray:
    """A fixed smooth 2 × 5 regressor of a 3-d input (enough to exercise the parametric stage)."""
    q = x[:3]
    return np.array([[1.0, q[0], np.sin(q[1]), q[2] * q[0], 0.0],
                     [0.0, 1.0, q[1], np.cos(q[0]), q[2]]])


@pytest.mark.parametrize("kind", ["P", "NP", "SP", "SPJ"])
def test_models_predict_one_after_learn_one_equals_the_weights(kind):
    """predict_one right after learn_one (fused path) equals the prediction from the formed weights."""
    rng = np.random.default_rng(8)
    n_in, t = 3, 2
    if kind == "P":
        model = ParametricModel(_regressor, 5, t, lam=0.5, forgetting=0.995)
    elif kind == "NP":
        model = NonparametricModel(n_in, t, n_features=40, sigma=1.5, lam=0.5, standardizer_warmup=10)
    elif kind == "SPJ":
        model = JointSemiparametricModel(_regressor, 5, n_in, t, n_features=40, sigma=1.5, forgetting=0.999,
                                         standardizer_warmup=10)
    else:
        model = SemiparametricModel(_regressor, 5, n_in, t, n_features=40, sigma=1.5, standardizer_warmup=10)
    X = rng.uniform(-1, 1, (200, n_in))
    Y = np.column_stack([np.sin(X[:, 0]) + X[:, 1], X[:, 2] ** 2])
    for i in range(199):
        model.learn_one(X[i], Y[i])
        if i % 23:
            continue
        got = model.predict_one(X[i + 1], return_variance=True)
        ref = model.copy()
        rlss = [r for r in (getattr(ref, "rls", None), getattr(getattr(ref, "parametric", None), "rls", None),
                            getattr(getattr(ref, "nonparametric", None), "rls", None)) if r is not None]
        for r in rlss:
            r._flush()  # the copy runs its pending update now: its predictions take the unfused path
        want = ref.predict_one(X[i + 1], return_variance=True)
        assert model.predict_one(X[i + 1]).variance is None
        # well conditioned here (λ = 0.5, ≤ 40 features): 1e-9 is the bound, ≥ 10⁴× the rounding
        np.testing.assert_allclose(got.total, want.total, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(got.variance, want.variance, rtol=1e-9, atol=1e-12)


def test_strided_and_integer_rows_are_accepted_like_contiguous_float_rows():
    rng = np.random.default_rng(9)
    b, t = 6, 2
    a, ref = RecursiveRLS(b, t), RecursiveRLS(b, t)
    X = rng.standard_normal((b, 2 * b))
    U = rng.standard_normal((b, t))
    for i in range(b):
        a.update(X[i, ::2], U[i])  # a strided view
        ref.update(np.ascontiguousarray(X[i, ::2]), U[i].copy())
    zi = np.arange(b)  # integers
    assert np.array_equal(a.predict(zi), ref.predict(zi.astype(float)))
    assert np.array_equal(a.predict(X[0, 1::2]), ref.predict(X[0, 1::2].copy()))
