"""Benchmark: blocked (BLAS-3) updates of the RLS factor against the sample-by-sample Givens sweep.

What a block of k rows costs per row, side by side in one run, for the factor ``M = [R | d]`` of
:class:`~semiparam_ros.core.learners.rrls.RecursiveRLS` (b = D features, t right-hand sides: 7 for the
cascade's residual on a 7-joint arm, 218 for the consistent SP's on the Panda):

* ``givens single``: the package's kernel, one time step per row (``update_steps``, β = 1);
* ``givens k-row``: the same kernel rotating k rows per sweep of the factor (``rows_per_step = k``);
* ``lapack tpqrt``: LAPACK's blocked triangular-pentagonal QR (``dtpqrt``, block nb = min(k, 32)) of
  ``[R | d]`` over the k rows, on Fortran-ordered copies (the conversions are not timed: a lower bound);
* ``compact WY``: a blocked Householder update written for this benchmark (panels of 32 columns
  factorised by a compiled level-2 loop, the trailing columns updated by the panel's compact WY
  reflector ``I − Y T Yᵀ`` with two matrix products per panel).

Every blocked result is checked against ``numpy.linalg.qr`` of the stacked matrix (relative error
printed). One and two BLAS threads. Reported: µs per row (median of ``--repeats``), GFlop/s of the
Householder count (4 flops per entry of the trapezoid per row), and the ratio to ``givens single``.

    PYTHONPATH=$PWD .venv/bin/python bench/learners/bench_blocked_update.py [--repeats 3] [--quick]

Writes ``bench/results/bench_blocked_update.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import platform
import statistics
import time

import numpy as np
from numba import njit
from scipy.linalg import lapack
from threadpoolctl import threadpool_limits

from semiparam_ros.core.learners.rrls import RecursiveRLS

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "bench_blocked_update.json"
PANEL = 32


@njit(cache=True, fastmath={"contract"})
def _panel(M: np.ndarray, X: np.ndarray, j0: int, j1: int, V: np.ndarray, tau: np.ndarray) -> None:
    """Householder reflectors (non-negative diagonal, LAPACK's dlarfgp) of columns j0..j1 of [M; X]."""
    k = X.shape[0]
    for i in range(j0, j1):
        p = i - j0
        alpha = M[i, i]
        xn2 = 0.0
        for r in range(k):
            xn2 += X[r, i] * X[r, i]
        if xn2 == 0.0:
            tau[p] = 0.0
            for r in range(k):
                V[r, p] = 0.0
            continue
        beta = math.sqrt(alpha * alpha + xn2)
        amb = -xn2 / (alpha + beta)  # alpha − beta without cancellation (alpha ≥ 0)
        t = -amb / beta
        tau[p] = t
        inv = 1.0 / amb
        for r in range(k):
            V[r, p] = X[r, i] * inv
            X[r, i] = 0.0
        M[i, i] = beta
        Mi = M[i]
        for c in range(i + 1, j1):
            w = Mi[c]
            for r in range(k):
                w += V[r, p] * X[r, c]
            w *= t
            Mi[c] -= w
            for r in range(k):
                X[r, c] -= V[r, p] * w


@njit(cache=True)
def _triangle(V: np.ndarray, tau: np.ndarray, T: np.ndarray) -> None:
    """T of the compact WY form ``H_0 ⋯ H_{nb−1} = I − Y T Yᵀ`` (Y = [I; V], LAPACK's dlarft)."""
    nb = tau.shape[0]
    k = V.shape[0]
    T[:, :] = 0.0
    z = np.empty(nb)
    for i in range(nb):
        T[i, i] = tau[i]
        for a in range(i):
            s = 0.0
            for r in range(k):
                s += V[r, a] * V[r, i]
            z[a] = s
        for a in range(i):
            s = 0.0
            for c in range(a, i):
                s += T[a, c] * z[c]
            T[a, i] = -tau[i] * s


def compact_wy_update(M: np.ndarray, X: np.ndarray) -> None:
    """Replace M by the R factor of [M; X] (M upper trapezoidal, C order), in place; X is overwritten."""
    b, bt = M.shape
    k = X.shape[0]
    V = np.empty((k, PANEL))
    tau = np.empty(PANEL)
    T = np.empty((PANEL, PANEL))
    for j0 in range(0, b, PANEL):
        j1 = min(b, j0 + PANEL)
        w = j1 - j0
        _panel(M, X, j0, j1, V, tau)
        if j1 < bt:
            Vp = np.ascontiguousarray(V[:, :w])
            Tp = T[:w, :w]
            _triangle(Vp, tau[:w], Tp)
            Xt = X[:, j1:]
            W = Tp.T @ (M[j0:j1, j1:] + Vp.T @ Xt)
            M[j0:j1, j1:] -= W
            Xt -= Vp @ W


def reference(M: np.ndarray, X: np.ndarray) -> np.ndarray:
    """R of [M; X] by numpy's QR, rows signed to a non-negative diagonal."""
    b = M.shape[0]
    R = np.linalg.qr(np.vstack([M, X]), mode="r")[:b]
    sign = np.where(np.diag(R) < 0.0, -1.0, 1.0)
    return R * sign[:, None]


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def case(D: int, t: int, k: int, threads: int, repeats: int, rng: np.random.Generator) -> dict[str, float]:
    rls = RecursiveRLS(D, t, 1.0)
    Z = rng.standard_normal((400 + 2 * k, D))
    U = rng.standard_normal((400 + 2 * k, t))
    rls.update_steps(Z[:400], U[:400])
    state = rls.state_dict()
    M0 = np.array(state["M"])
    X0 = np.ascontiguousarray(np.hstack([Z[400:400 + k], U[400:400 + k]]))
    flops = 4.0 * k * (D * D / 2 + D * t)  # Householder: two passes of 2 flops per trapezoid entry per row

    def fresh() -> RecursiveRLS:
        return RecursiveRLS.from_state_dict(state)

    out: dict[str, float] = {}
    with threadpool_limits(threads):
        learners = [fresh() for _ in range(repeats)]
        it = iter(learners)
        out["givens single"] = _median_time(lambda: next(it).update_steps(X0[:, :D], X0[:, D:]), repeats) / k
        learners = [fresh() for _ in range(repeats)]
        it = iter(learners)
        out["givens k-row"] = _median_time(
            lambda: next(it).update_steps(X0[:, :D], X0[:, D:], rows_per_step=k), repeats) / k
        nb = min(k, 32)
        pairs = [(np.asfortranarray(M0), np.asfortranarray(X0)) for _ in range(repeats)]
        it2 = iter(pairs)

        def tpqrt() -> None:
            A, B = next(it2)
            # dtpqrt takes A square: [R | d] is run as R with d's columns in B's trailing block
            lapack.dtpqrt(0, nb, np.asfortranarray(A[:, :D]), np.asfortranarray(B[:, :D]),
                          overwrite_a=1, overwrite_b=1)

        out["lapack tpqrt (R only)"] = _median_time(tpqrt, repeats) / k
        copies = [(M0.copy(), X0.copy()) for _ in range(repeats + 1)]
        compact_wy_update(*copies[-1])  # compile
        it3 = iter(copies[:-1])
        out["compact WY"] = _median_time(lambda: compact_wy_update(*next(it3)), repeats) / k
    M, X = M0.copy(), X0.copy()
    compact_wy_update(M, X)
    want = reference(M0, X0)
    out["compact WY relative error"] = float(np.abs(M - want).max() / np.abs(want).max())
    out["gflops compact WY"] = flops / k / out["compact WY"] / 1e9
    out["gflops givens single (its 6 flops per entry)"] = 1.5 * flops / k / out["givens single"] / 1e9
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="D = 500 only, k = 16 and 64")
    ap.add_argument("--json", type=pathlib.Path, default=RESULTS)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    rows = []
    dims = [(500, 7)] if args.quick else [(500, 7), (1000, 7), (1000, 218)]
    ks = (16, 64) if args.quick else (16, 64, 128)
    print("| D | t | k | BLAS threads | givens single µs/row | givens k-row | lapack tpqrt (R only) | "
          "compact WY | compact WY / givens single | GFlop/s WY / Givens | WY rel. error |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for D, t in dims:
        for k in ks:
            for threads in (1, 2):
                r = case(D, t, k, threads, args.repeats, rng)
                r.update({"D": D, "t": t, "k": k, "threads": threads})
                rows.append(r)
                g = r["givens single"]
                print(f"| {D} | {t} | {k} | {threads} | {g * 1e6:.0f} | {r['givens k-row'] * 1e6:.0f} | "
                      f"{r['lapack tpqrt (R only)'] * 1e6:.0f} | {r['compact WY'] * 1e6:.0f} | "
                      f"{r['compact WY'] / g:.2f} | {r['gflops compact WY']:.1f} / "
                      f"{r['gflops givens single (its 6 flops per entry)']:.1f} | "
                      f"{r['compact WY relative error']:.1e} |", flush=True)
    meta = {"machine": platform.machine(), "python": platform.python_version(), "cpus": os.cpu_count(),
            "load_average": os.getloadavg(), "time": time.strftime("%Y-%m-%d %H:%M:%S"),
            "command": "PYTHONPATH=$PWD .venv/bin/python bench/learners/bench_blocked_update.py"}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
