"""RecursiveRLS against closed-form ridge regression, the pure-numpy reference and its own invariants."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from helpers.reference_rrls import ReferenceQRRLS
from helpers.rrls import closed_form, random_steps
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import cho_factor, cho_solve, solve_triangular

from semiparam_ros.core import checkpoint
from semiparam_ros.core.learners.rrls import RecursiveRLS


def rel(a, b):
    return np.abs(a - b).max() / np.abs(b).max()




@pytest.mark.parametrize("k", [1, 6])
@pytest.mark.parametrize(("beta", "keep_prior"), [(1.0, True), (0.995, True), (0.995, False)])
def test_matches_closed_form_after_5000_updates(k, beta, keep_prior):
    rng = np.random.default_rng(k)
    b, t, lam = 24, 3, 0.7
    steps = random_steps(rng, 5000 // k if k == 6 else 5000, k, b, t)
    rls = RecursiveRLS(b, t, lam, forgetting=beta, keep_prior=keep_prior)
    for Z, U in steps:
        rls.update(Z if k > 1 else Z[0], U if k > 1 else U[0])
    A, _, W = closed_form(steps, b, t, lam, beta, keep_prior)
    assert rls.n_samples_seen == len(steps) * k
    assert rls.n_steps == len(steps)
    assert rel(rls.weights, W) < 1e-9
    R = rls.R
    assert np.allclose(np.tril(R, -1), 0.0)
    assert rel(R.T @ R, A) < 1e-12
    if beta == 1.0:
        Zall = np.vstack([Z for Z, _ in steps])
        assert rel(R.T @ R, Zall.T @ Zall + lam * np.eye(b)) < 1e-12


@pytest.mark.parametrize("k", [1, 6])
@pytest.mark.parametrize("beta", [1.0, 0.97])
def test_kernel_equals_numpy_reference(k, beta):
    rng = np.random.default_rng(10 + k)
    b, t, lam = 15, 2, 0.3
    steps = random_steps(rng, 300 // k, k, b, t)
    rls = RecursiveRLS(b, t, lam, forgetting=beta)
    ref = ReferenceQRRLS(b, t, lam, beta)
    for Z, U in steps:
        p = rls.predict_update(Z, U)
        p_ref = ref.predict_update(Z, U)
        np.testing.assert_allclose(p, p_ref, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.hstack([rls.R, rls.d]), ref.M, rtol=1e-11, atol=1e-12)


@pytest.mark.parametrize("k", [1, 6, 40])
def test_predict_update_returns_the_a_priori_prediction(k):
    rng = np.random.default_rng(20 + k)
    b, t = 30, 6
    rls = RecursiveRLS(b, t, 0.5, forgetting=0.99)
    for Z, U in random_steps(rng, 60, k, b, t):
        before = rls.predict(Z)
        W_before = rls.weights.copy()
        got = rls.predict_update(Z, U)
        np.testing.assert_allclose(got, before, rtol=1e-9, atol=1e-11)
        np.testing.assert_allclose(got, Z @ W_before, rtol=1e-9, atol=1e-11)
    z = rng.standard_normal(b)
    u = rng.standard_normal(t)
    assert rls.predict_update(z, u).shape == (t,)


def test_apply_pending_gives_the_same_state_as_the_fused_prediction():
    """A deferred update applied in idle time (``apply_pending``) leaves the factor bit for bit as the
    fused update-and-predict does; the prediction after it equals the closed-form ridge to rounding."""
    rng = np.random.default_rng(7)
    b, t = 40, 3
    fused, idle = RecursiveRLS(b, t, 0.5), RecursiveRLS(b, t, 0.5)
    Zs, Us = rng.standard_normal((50, b)), rng.standard_normal((50, t))
    for z, u in zip(Zs, Us, strict=True):
        for rls in (fused, idle):
            rls.defer_step(RecursiveRLS.checked_step(z[None].copy(), u[None].copy()))
        assert idle.has_pending and idle.apply_pending() and not idle.has_pending
        assert not idle.apply_pending()  # nothing left
        q = rng.standard_normal(b)
        p_fused, p_idle = fused.predict(q), idle.predict(q)
        np.testing.assert_allclose(p_idle, p_fused, rtol=1e-10, atol=1e-12)
        assert np.array_equal(fused.R, idle.R) and np.array_equal(fused.d, idle.d)
    ridge = np.linalg.solve(Zs.T @ Zs + 0.5 * np.eye(b), Zs.T @ Us)
    np.testing.assert_allclose(idle.weights, ridge, rtol=1e-8, atol=1e-10)


def test_factor_copy_is_the_factor_with_the_pending_update_applied():
    """``factor_copy``: ``[R | d]`` after a deferred update, bit for bit the factor of a learner that applied
    it; predictions from it alone (``solve_predict``) are the closed-form ridge's, and it is a copy."""
    from semiparam_ros.core.learners._kernels import solve_predict

    rng = np.random.default_rng(8)
    b, t = 20, 3
    rls, ref = RecursiveRLS(b, t, 0.5), RecursiveRLS(b, t, 0.5)
    Zs, Us = rng.standard_normal((30, b)), rng.standard_normal((30, t))
    for z, u in zip(Zs, Us, strict=True):
        for learner in (rls, ref):
            learner.defer_step(RecursiveRLS.checked_step(z[None].copy(), u[None].copy()))
    assert rls.has_pending
    M = rls.factor_copy()
    ref.apply_pending()
    assert M.flags.c_contiguous and np.array_equal(M, np.hstack([ref.R, ref.d]))
    q = rng.standard_normal((2, b))
    P, var = np.empty((2, t)), np.empty(2)
    solve_predict(M, q, P, var)
    A = Zs.T @ Zs + 0.5 * np.eye(b)
    np.testing.assert_allclose(P, q @ np.linalg.solve(A, Zs.T @ Us), rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(var, np.einsum("ij,ji->i", q, np.linalg.solve(A, q.T)), rtol=1e-8)
    M[:] = 0.0
    assert np.array_equal(rls.R, ref.R)  # a copy


def test_update_steps_is_bitwise_equal_to_repeated_calls():
    rng = np.random.default_rng(3)
    b, t, k = 12, 2, 6
    steps = random_steps(rng, 100, k, b, t)
    a = RecursiveRLS(b, t, 0.4, forgetting=0.98)
    b_ = RecursiveRLS(b, t, 0.4, forgetting=0.98)
    preds = [a.predict_update(Z, U) for Z, U in steps]
    P = b_.update_steps(np.vstack([Z for Z, _ in steps]), np.vstack([U for _, U in steps]), k, predict=True)
    assert np.array_equal(np.vstack(preds), P)
    for key, value in a.state_dict().items():
        assert np.array_equal(value, b_.state_dict()[key]), key


def test_variance_is_z_ainv_zt():
    rng = np.random.default_rng(4)
    b, t, lam = 10, 1, 0.2
    steps = random_steps(rng, 50, 1, b, t)
    rls = RecursiveRLS(b, t, lam)
    for Z, U in steps:
        rls.update(Z, U)
    A, _, _ = closed_form(steps, b, t, lam)
    Zq = rng.standard_normal((7, b))
    expected = np.einsum("ij,ij->i", Zq, np.linalg.solve(A, Zq.T).T)
    np.testing.assert_allclose(rls.variance(Zq), expected, rtol=1e-10)
    assert np.isclose(rls.variance(Zq[0]), expected[0], rtol=1e-10)


def few_direction_stream(rng, n, b, n_dirs, t, aligned=False):
    """Rows exciting only n_dirs directions: a random subspace, or the first coordinates (aligned)."""
    if aligned:
        basis = np.eye(b)[:n_dirs]
    else:
        basis = np.linalg.qr(rng.standard_normal((b, n_dirs)))[0].T  # (n_dirs, b) orthonormal rows
    W_true = rng.standard_normal((b, t))
    G = rng.standard_normal((n, n_dirs)) * 3.0
    Z = np.ascontiguousarray(G @ basis)
    U = np.ascontiguousarray(Z @ W_true + 0.01 * rng.standard_normal((n, t)))
    return Z, U


def diag_ratio(R):
    """max|R_ii| / min|R_ii|, a lower bound of cond₂(R) for triangular R (exact SVDs saturate at 1e16)."""
    dg = np.abs(np.diag(R))
    return np.inf if dg.min() == 0 else dg.max() / dg.min()


def prior_bounds(b, lam, beta, zmax2):
    """Eigenvalue bounds of A in the steady state (module docstring), with a safety factor 0.5 / 2."""
    lo = lam * b * (1 - beta) * beta ** (b - 1) / (1 - beta**b)
    hi = lam * b * (1 - beta) / (1 - beta**b) + zmax2 / (1 - beta)
    return 0.5 * lo, 2.0 * hi


def test_condition_number_bounded_with_prior_but_not_with_plain_forgetting():
    rng = np.random.default_rng(5)
    b, t, lam, beta = 20, 2, 1.0, 0.99
    Z, U = few_direction_stream(rng, 20000, b, 2, t)
    ours = RecursiveRLS(b, t, lam, forgetting=beta)
    plain = RecursiveRLS(b, t, lam, forgetting=beta, keep_prior=False)
    lo, hi = prior_bounds(b, lam, beta, float(np.max(np.sum(Z**2, axis=1))))
    conds_ours, conds_plain = [], []
    for chunk in range(10):
        sl = slice(chunk * 2000, (chunk + 1) * 2000)
        ours.update_steps(Z[sl], U[sl])
        plain.update_steps(Z[sl], U[sl])
        conds_ours.append(ours.condition_number())
        conds_plain.append(diag_ratio(plain.R))
        s = np.linalg.svd(ours.R, compute_uv=False) ** 2  # eigenvalues of A
        assert lo <= s.min() and s.max() <= hi
    assert max(conds_ours) < np.sqrt(hi / lo)
    # plain forgetting: unexcited directions decay like λβⁿ → cond(R) ~ β^{-n/2} grows until rounding
    # noise of the rotations (~1e-16·|z| per step) floors it near 1/eps; ours stays ~10²
    assert conds_plain[0] > 10 * max(conds_ours)
    assert conds_plain[-1] > 1e14 and conds_plain[-1] > 1e6 * max(conds_ours)
    assert np.all(np.isfinite(ours.weights))


def test_one_million_updates_stay_finite_and_bounded():
    rng = np.random.default_rng(6)
    b, t, lam, beta = 20, 2, 1.0, 0.999
    ours = RecursiveRLS(b, t, lam, forgetting=beta)
    plain = RecursiveRLS(b, t, lam, forgetting=beta, keep_prior=False)
    Z, U = few_direction_stream(rng, 100_000, b, 3, t, aligned=True)
    lo, hi = prior_bounds(b, lam, beta, float(np.max(np.sum(Z**2, axis=1))))
    for _ in range(10):  # 10⁶ single-row time steps, the same 10⁵-sample stream replayed
        ours.update_steps(Z, U)
        plain.update_steps(Z, U)
        assert np.isfinite(ours.R).all() and np.isfinite(ours.weights).all()
        assert ours.condition_number() < np.sqrt(hi / lo)
    assert ours.n_steps == 1_000_000
    # the regularizer of plain forgetting underflowed: βⁿλ = e^{-1000} → unexcited diagonal entries are 0
    assert diag_ratio(plain.R) > 1e100
    # the excited subspace is still fitted: held-out error close to the noise level
    Zt, Ut = few_direction_stream(np.random.default_rng(6), 1000, b, 3, t, aligned=True)
    assert np.sqrt(np.mean((ours.predict(Zt) - Ut) ** 2)) < 0.05


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), cuts=st.lists(st.integers(1, 59), max_size=8))
def test_blocking_and_order_invariance(seed, cuts):
    rng = np.random.default_rng(seed)
    b, t, lam, n = 8, 2, 0.5, 60
    Z = rng.standard_normal((n, b))
    U = rng.standard_normal((n, t))
    whole = RecursiveRLS(b, t, lam)
    whole.update(Z, U)
    blocked = RecursiveRLS(b, t, lam)
    edges = [0, *sorted(set(cuts)), n]
    for lo_, hi_ in itertools.pairwise(edges):
        blocked.update(Z[lo_:hi_], U[lo_:hi_])
    perm = rng.permutation(n)
    shuffled = RecursiveRLS(b, t, lam)
    for i in perm:
        shuffled.update(Z[i], U[i])
    W = cho_solve(cho_factor(Z.T @ Z + lam * np.eye(b)), Z.T @ U)
    for model in (whole, blocked, shuffled):
        assert rel(model.weights, W) < 1e-10
        assert rel(model.R.T @ model.R, Z.T @ Z + lam * np.eye(b)) < 1e-12
        assert model.n_samples_seen == n


def test_save_load_round_trip_bit_for_bit(tmp_path):
    rng = np.random.default_rng(7)
    b, t = 16, 3
    rls = RecursiveRLS(b, t, 0.3, forgetting=0.995)
    steps = random_steps(rng, 200, 1, b, t)
    for Z, U in steps[:100]:
        rls.update(Z, U)
    path = tmp_path / "sub" / "rls.npz"
    rls.save(path)
    assert [p.name for p in path.parent.iterdir()] == ["rls.npz"]  # no temp file left behind
    loaded = RecursiveRLS.load(path)
    Zq = rng.standard_normal((5, b))
    assert np.array_equal(loaded.predict(Zq), rls.predict(Zq))
    for Z, U in steps[100:]:
        assert np.array_equal(loaded.predict_update(Z, U), rls.predict_update(Z, U))
    assert np.array_equal(loaded.weights, rls.weights)
    assert loaded.n_samples_seen == rls.n_samples_seen == 200
    state = rls.state_dict("p.")
    assert np.array_equal(RecursiveRLS.from_state_dict(state, "p.").predict(Zq), rls.predict(Zq))
    # a damaged state with a zero pivot is refused (with the prior kept, A is bounded away from singular)
    state["p.M"][3, 3] = 0.0
    with pytest.raises(ValueError, match="singular"):
        RecursiveRLS.from_state_dict(state, "p.")


def test_copy_is_independent_and_reset_restores_prior():
    rng = np.random.default_rng(8)
    rls = RecursiveRLS(6, 2, 2.0, forgetting=0.9)
    Z, U = rng.standard_normal((10, 6)), rng.standard_normal((10, 2))
    rls.update(Z, U)
    twin = rls.copy()
    rls.update(Z, U)
    assert twin.n_samples_seen == 10 and rls.n_samples_seen == 20
    assert not np.array_equal(twin.weights, rls.weights)
    rls.reset()
    assert rls.n_samples_seen == 0 and np.array_equal(rls.R, np.sqrt(2.0) * np.eye(6))
    assert np.array_equal(rls.weights, np.zeros((6, 2)))


def snapshot(rls):
    return {k: v.copy() for k, v in rls.state_dict().items()}


@pytest.mark.parametrize(
    ("Z", "U"),
    [
        (np.ones(5), np.ones(2)),  # wrong b
        (np.ones(4), np.ones(3)),  # wrong t
        (np.ones((3, 4)), np.ones((2, 2))),  # row count mismatch
        (np.ones((3, 4)), np.ones(2)),  # 1-D target for a block
        (np.ones((0, 4)), np.ones((0, 2))),  # empty
        (np.ones((2, 2, 4)), np.ones((2, 2))),  # 3-D
        (np.array([1.0, np.nan, 0.0, 0.0]), np.ones(2)),
        (np.ones(4), np.array([np.inf, 0.0])),
        (np.array([[1.0, 2.0, 3.0, 4.0], [1.0, 2.0, -np.inf, 4.0]]), np.ones((2, 2))),
        (np.array([1e200, 0.0, 0.0, 0.0]), np.ones(2)),
    ],
)
def test_rejected_input_leaves_learner_unchanged(Z, U):
    rng = np.random.default_rng(9)
    rls = RecursiveRLS(4, 2, 1.0, forgetting=0.99)
    rls.update(rng.standard_normal((8, 4)), rng.standard_normal((8, 2)))
    before = snapshot(rls)
    W_before = rls.weights.copy()
    for method in (rls.update, rls.predict_update):
        with pytest.raises(ValueError):
            method(Z, U)
    with pytest.raises(ValueError):
        rls.update_steps(np.atleast_2d(Z), np.atleast_2d(U))
    after = snapshot(rls)
    for key in before:
        assert np.array_equal(before[key], after[key]), key
    assert np.array_equal(rls.weights, W_before)


def test_update_steps_rejects_partial_steps_unchanged():
    rls = RecursiveRLS(4, 1)
    before = snapshot(rls)
    with pytest.raises(ValueError, match="multiple"):
        rls.update_steps(np.ones((7, 4)), np.ones((7, 1)), rows_per_step=6)
    assert all(np.array_equal(v, snapshot(rls)[k]) for k, v in before.items())


@pytest.mark.parametrize(
    "kwargs",
    [dict(lam=0.0), dict(lam=-1.0), dict(lam=np.nan), dict(lam=np.inf), dict(forgetting=0.0),
     dict(forgetting=1.01), dict(forgetting=np.nan), dict(n_features=0), dict(n_outputs=0),
     dict(n_features=2.5)],
)
def test_invalid_hyperparameters(kwargs):
    args = dict(n_features=3, n_outputs=1, lam=1.0, forgetting=1.0) | kwargs
    with pytest.raises(ValueError):
        RecursiveRLS(args.pop("n_features"), args.pop("n_outputs"), args.pop("lam"), **args)


def test_predict_rejects_bad_input():
    rls = RecursiveRLS(3, 1)
    for bad in (np.ones(4), np.array([np.nan, 0, 0]), np.ones((2, 2))):
        with pytest.raises(ValueError):
            rls.predict(bad)
        with pytest.raises(ValueError):
            rls.variance(bad)


def test_checkpoint_errors(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        checkpoint.load_npz(tmp_path / "missing.npz")
    good = tmp_path / "good.npz"
    checkpoint.atomic_save_npz(good, {"a": np.arange(4.0)})
    raw = good.read_bytes()
    (tmp_path / "trunc.npz").write_bytes(raw[: len(raw) // 2])
    (tmp_path / "junk.npz").write_bytes(b"not a zip file at all")
    for name in ("trunc.npz", "junk.npz"):
        with pytest.raises(ValueError, match="corrupt"):
            checkpoint.load_npz(tmp_path / name)
        with pytest.raises(ValueError):
            RecursiveRLS.load(tmp_path / name)
    with pytest.raises(ValueError, match="missing key"):
        RecursiveRLS.load(good)
    with pytest.raises(ValueError):
        checkpoint.atomic_save_npz(tmp_path / "obj.npz", {"o": np.array([object()], dtype=object)})
    assert not (tmp_path / "obj.npz").exists()
    # overwrite is atomic and complete
    checkpoint.atomic_save_npz(good, {"b": np.ones(2)})
    assert list(checkpoint.load_npz(good)) == ["b"]
    rls = RecursiveRLS(3, 1)
    state = rls.state_dict()
    state["M"] = np.ones((2, 2))
    with pytest.raises(ValueError, match="shape"):
        RecursiveRLS.from_state_dict(state)
    state["M"] = np.ones((3, 4))
    with pytest.raises(ValueError, match="triangular"):
        RecursiveRLS.from_state_dict(state)


@pytest.mark.parametrize("k", [1, 2, 3, 6])
@pytest.mark.parametrize("beta", [1.0, 0.98])
def test_sparse_rows_exercise_every_kernel_path(k, beta):
    """Structural zeros (as in rigid-body regressors) select the kernel's skip, pair and fused paths."""
    rng = np.random.default_rng(30 + k)
    b, t, lam = 13, 2, 0.6
    steps = random_steps(rng, 400 // k, k, b, t)
    steps = [(Z * (rng.random(Z.shape) < 0.5), U) for Z, U in steps]
    rls = RecursiveRLS(b, t, lam, forgetting=beta)
    for Z, U in steps:
        before = rls.predict(Z)
        np.testing.assert_allclose(rls.predict_update(Z, U), before, rtol=1e-9, atol=1e-11)
    A, _, W = closed_form(steps, b, t, lam, beta)
    assert rel(rls.weights, W) < 1e-9
    assert rel(rls.R.T @ rls.R, A) < 1e-12
    assert np.all(np.diag(rls.R) > 0)


@pytest.mark.parametrize("b", [1, 2, 3])
@pytest.mark.parametrize("k", [1, 2, 7])
def test_tiny_problems(b, k):
    rng = np.random.default_rng(40 + 10 * b + k)
    steps = random_steps(rng, 50, k, b, 2)
    rls = RecursiveRLS(b, 2, 0.3, forgetting=0.9)
    for Z, U in steps:
        before = rls.predict(Z)
        np.testing.assert_allclose(rls.predict_update(Z, U), before, rtol=1e-9, atol=1e-12)
    A, _, W = closed_form(steps, b, 2, 0.3, 0.9)
    assert rel(rls.weights, W) < 1e-9
    assert rel(rls.R.T @ rls.R, A) < 1e-12


@pytest.mark.parametrize("k", [1, 6])
@pytest.mark.parametrize("beta", [1.0, 0.98])
def test_rows_out_update_the_residual_matrix(k, beta):
    """EᵀE = S_new − β·S_old, S = Σ β^{n−m} UᵀU − BᵀA⁻¹B (the minimum of the ridge cost), summed directly."""
    rng = np.random.default_rng(11)
    b, t = 7, 4
    steps = random_steps(rng, 40, k, b, t)
    rls = RecursiveRLS(b, t, 0.3, forgetting=beta)
    C = np.zeros((t, t))
    S_old = np.zeros((t, t))
    for n, (Z, U) in enumerate(steps):
        P, E = rls.predict_update_rows_out(np.ascontiguousarray(Z), np.ascontiguousarray(U))
        assert E.shape == (k + (1 if beta < 1 else 0), t)
        C = beta * C + U.T @ U
        _, B, W = closed_form(steps[: n + 1], b, t, 0.3, beta)
        S_new = C - B.T @ W
        np.testing.assert_allclose(E.T @ E, S_new - beta * S_old, rtol=1e-8, atol=1e-10)
        _, _, W_old = closed_form(steps[:n], b, t, 0.3, beta) if n else (None, None, np.zeros((b, t)))
        np.testing.assert_allclose(P, Z @ W_old, rtol=1e-8, atol=1e-10)
        S_old = S_new


@pytest.mark.parametrize(("b", "t"), [(1, 1), (17, 1), (64, 6), (65, 3)])
def test_weights_equal_a_lapack_triangular_solve(b, t):
    """Small factors use the compiled back-substitution, larger ones LAPACK: both equal scipy's solve."""
    rng = np.random.default_rng(b)
    rls = RecursiveRLS(b, t, 0.5)
    for Z, U in random_steps(rng, 3 * b, 2, b, t):
        rls.update(Z, U)
    expect = solve_triangular(np.array(rls.R), np.array(rls.d), lower=False)
    np.testing.assert_allclose(rls.weights, expect, rtol=1e-12, atol=1e-14)


def test_shift_rhs_is_learning_the_changed_targets():
    """Learning targets U with forgetting (prior kept), then ``shift_rhs(Σ_m β^{n−m} Z_mᵀ(U_m − U'_m))``,
    gives the learner that learned U' (the same factor): the right-hand side's recursion B ← βB + ZᵀU."""
    rng = np.random.default_rng(5)
    b, t, beta = 6, 2, 0.97
    a, c = RecursiveRLS(b, t, 0.1, forgetting=beta), RecursiveRLS(b, t, 0.1, forgetting=beta)
    G = np.zeros((b, t))
    for _ in range(40):
        Z = rng.normal(size=(2, b))
        U, U2 = rng.normal(size=(2, t)), rng.normal(size=(2, t))
        a.update(Z, U)
        c.update(Z, U2)
        G = beta * G + Z.T @ (U - U2)
    a.shift_rhs(G)
    np.testing.assert_allclose(a.weights, c.weights, rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(a.R, c.R)
    from semiparam_ros.errors import RejectedSampleError

    with pytest.raises(RejectedSampleError):
        a.shift_rhs(np.full((b, t), np.nan))


def test_shift_rhs_by_blocks_equals_one_triangular_solve():
    """Several blocks of R (the last one partial): ``d`` moves by ``R⁻ᵀG`` as one solve on a copy of R
    gives, to the rounding bound of a triangular solve, ``b·ε·cond(R)`` relative."""
    rng = np.random.default_rng(6)
    b, t = 2 * RecursiveRLS.SOLVE_BLOCK + 44, 3
    rls = RecursiveRLS(b, t, 0.5, forgetting=0.99)
    for _ in range(60):
        rls.update(rng.normal(size=(8, b)), rng.normal(size=(8, t)))
    R, d0 = np.array(rls.R), np.array(rls.d)
    G = rng.normal(size=(b, t))
    rls.shift_rhs(G)
    expect = d0 - solve_triangular(R, G, trans="T", lower=False)
    bound = b * np.finfo(float).eps * np.linalg.cond(R) * np.abs(solve_triangular(R, G, trans="T")).max()
    assert np.abs(np.array(rls.d) - expect).max() <= bound
    np.testing.assert_array_equal(rls.R, R)
