"""Benchmark: per-sample update + predict of the learning core, next to its peers, in one run.

For D ∈ {100, 250, 500, 1000, 2000} features and 6 outputs, the time of one test-then-train step
(a-priori prediction of the sample, then the update with its label) for:

* ``ours β=1``      — ``RecursiveRLS.predict_update`` (compiled Givens kernel, prediction from the rotations),
  including the Python-side validation of every call;
* ``ours β<1``      — the same with prior-keeping forgetting (β = 0.999: scale + one regularizer row a step);
* ``predict, update`` — the library habit (river/scikit-learn): ``predict(z)`` then ``update(z, u)``;
  measured interleaved with ``predict_update`` (alternating short repeats in one run), reported as the
  median of the per-pair ratios (target ≤ 1.3 at D = 500 and 1000);
* ``ours+RFF``      — ``NonparametricModel.predict_learn_one`` on a 12-d input: standardize, random
  features, predict_update (the whole NP budget per sample);
* ``numpy Givens``  — the pure-numpy reference (test/helpers/reference_rrls.py): one Python loop over the
  b rows;
* ``Sherman–Morrison`` — RLS on the inverse ``P = A⁻¹`` with BLAS ``dsymv`` + ``dsyr`` (in place),
  6 outputs sharing P;
* ``padasip``       — ``padasip.filters.FilterRLS`` (1.2.2) ``predict`` + ``adapt``. padasip filters have a
  single output; the column is the time of ONE filter (one output), i.e. a lower bound of the 6-output
  cost (6 independent filters would cost 6×). Its update forms ``R (x xᵀ) R`` with two dense products:
  O(D³);
* ``sklearn refit`` — ``RBFSampler.transform`` of the sample + ``Ridge(alpha).fit`` on the last n = 1000
  samples' features (a sliding window: the cheapest honest way to use a batch learner online).

The machine limit: the update reads and writes the upper triangle of ``[R | d]``, ``2·8·(b(b+1)/2 + 6b)``
bytes; divided by the read+write bandwidth numpy achieves on an array of that footprint
(``np.multiply(a, c, out=a)``) it gives a lower bound of the time per update. Memory is checked to stay
constant in the number of samples (RSS and learner bytes after 1k and 10k updates at D = 1000).

All runs use one BLAS thread (``threadpoolctl.threadpool_limits(1)``). Timings are medians over repeats of
the mean of back-to-back calls (short repeats, so that preemption on the shared machine hits few of them);
the process CPU time per call and the CPU share (CPU time / wall time) are reported next to them. Usage::

    .venv/bin/python bench/learners/bench_core.py [--quick] [--json PATH]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import pathlib
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable

import numba
import numpy as np
import psutil
import scipy
import sklearn
from scipy.linalg.blas import dsymv, dsyr
from sklearn.kernel_approximation import RBFSampler
from sklearn.linear_model import Ridge
from threadpoolctl import threadpool_limits

from semiparam_ros.core.learners.features import Standardizer
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.rrls import RecursiveRLS

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "test"))
from helpers.reference_rrls import ReferenceQRRLS

T_OUT = 6
N_INPUTS = 12
LAM = 1.0
BETA = 0.999
REFIT_WINDOW = 1000
RESULTS = pathlib.Path(__file__).resolve().parent / "results" / "bench_core.json"
RESULTS_PU = RESULTS.with_name("bench_core_predict_update.json")
TARGETS_US = {500: 60.0, 1000: 250.0}
#: the learner before its predict-then-update pass (``--predict-update-only`` runs it side by side;
#: 13c2755 is the code before item 1's work)
KERNEL_BASELINE = "f23efe1"


def time_per_call(step: Callable[[int], object], calls: int, repeats: int) -> dict[str, float]:
    """Median/min/max over repeats of the mean µs per call of ``calls`` back-to-back calls."""
    step(0)  # warm-up (compilation, caches)
    samples, cpu_samples, i = [], [], 1
    wall = cpu = 0.0
    for _ in range(repeats):
        c0 = time.process_time()
        t0 = time.perf_counter()
        for _ in range(calls):
            step(i)
            i += 1
        dt = time.perf_counter() - t0
        dc = time.process_time() - c0
        cpu += dc
        wall += dt
        samples.append(dt / calls * 1e6)
        cpu_samples.append(dc / calls * 1e6)
    # cpu_share < 1 means the process was descheduled (the machine is shared): wall timings are inflated;
    # cpu_median_us (process CPU time per call) is the cost without the time spent descheduled
    return {"median_us": statistics.median(samples), "min_us": min(samples), "max_us": max(samples),
            "cpu_median_us": statistics.median(cpu_samples), "calls": calls, "repeats": repeats,
            "cpu_share": cpu / wall if wall > 0 else float("nan")}


def time_side_by_side(step_a: Callable[[int], object], step_b: Callable[[int], object], calls: int,
                      repeats: int) -> dict[str, object]:
    """Alternate short repeats of a and b; medians of each and the median of the per-pair ratios b/a.

    Wall and process-CPU time are both kept: on a shared machine the CPU-time ratio is the one less
    affected by being descheduled.
    """
    step_a(0)
    step_b(0)
    ta, tb, ca, cb, i = [], [], [], [], 1
    for _ in range(repeats):
        for step, out, cout in ((step_a, ta, ca), (step_b, tb, cb)):
            c0 = time.process_time()
            t0 = time.perf_counter()
            for _ in range(calls):
                step(i)
                i += 1
            out.append((time.perf_counter() - t0) / calls * 1e6)
            cout.append((time.process_time() - c0) / calls * 1e6)
    ratios = [b / a for a, b in zip(ta, tb, strict=True)]
    return {"a_median_us": statistics.median(ta), "b_median_us": statistics.median(tb),
            "ratio_median": statistics.median(ratios),
            "ratio_of_medians": statistics.median(tb) / statistics.median(ta),
            "a_cpu_median_us": statistics.median(ca), "b_cpu_median_us": statistics.median(cb),
            "cpu_ratio_of_medians": statistics.median(cb) / max(statistics.median(ca), 1e-9),
            "calls": calls, "repeats": repeats}


def features_stream(rng: np.random.Generator, n: int, D: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows that look like random Fourier features (√(2/D)·cos) and 6 targets."""
    Z = np.sqrt(2.0 / D) * np.cos(rng.uniform(0, 2 * np.pi, (n, D)))
    U = rng.standard_normal((n, T_OUT))
    return Z, U


def bandwidth_limit_us(D: int, repeats: int) -> dict[str, float]:
    """Lower bound of one update: bytes of [R | d]'s upper triangle read + written over measured bandwidth."""
    n_elem = D * (D + 1) // 2 + T_OUT * D
    a = np.ones(n_elem)
    c = 1.0000001
    np.multiply(a, c, out=a)
    ts = []
    for _ in range(max(repeats, 20)):
        t0 = time.perf_counter()
        np.multiply(a, c, out=a)
        ts.append(time.perf_counter() - t0)
    t = statistics.median(ts)
    bw = 2 * a.nbytes / t
    return {"bytes_per_update": 2 * a.nbytes, "bandwidth_GBps": bw / 1e9, "limit_us": t * 1e6}


class ShermanMorrisonRLS:
    """RLS on P = A⁻¹ (upper triangle, BLAS symv + syr in place), weights W (D, 6) — the classic peer."""

    def __init__(self, D: int, lam: float) -> None:
        self.P = np.asfortranarray(np.eye(D) / lam)
        self.W = np.zeros((D, T_OUT))

    def predict_update(self, z: np.ndarray, u: np.ndarray) -> np.ndarray:
        pred = z @ self.W
        Pz = dsymv(1.0, self.P, z, lower=0)
        g = Pz / (1.0 + z @ Pz)
        self.W += np.outer(g, u - pred)
        dsyr(-1.0 / (1.0 + z @ Pz), Pz, lower=0, a=self.P, overwrite_a=1)
        return pred


def bench_size(D: int, quick: bool, rng: np.random.Generator) -> dict[str, object]:
    n_fast = 400 if quick else 4000
    Z, U = features_stream(rng, n_fast + 1, D)
    # many short repeats (≈2 ms each, below a scheduler time slice): on the shared machine the median
    # then reflects the uncontended cost rather than how often the process was preempted
    rep = 10 if quick else 60
    calls = max(5, min(200, int(2e4 / D)))
    row: dict[str, object] = {"D": D}

    ours = RecursiveRLS(D, T_OUT, LAM)
    row["ours_beta1"] = time_per_call(lambda i: ours.predict_update(Z[i % n_fast], U[i % n_fast]), calls, rep)
    fused = RecursiveRLS(D, T_OUT, LAM)
    habit = RecursiveRLS(D, T_OUT, LAM)

    def predict_then_update(i: int) -> None:
        habit.predict(Z[i % n_fast])
        habit.update(Z[i % n_fast], U[i % n_fast])

    row["predict_then_update"] = time_side_by_side(
        lambda i: fused.predict_update(Z[i % n_fast], U[i % n_fast]), predict_then_update, calls, 2 * rep)
    ours_f = RecursiveRLS(D, T_OUT, LAM, forgetting=BETA)
    row["ours_forgetting"] = time_per_call(
        lambda i: ours_f.predict_update(Z[i % n_fast], U[i % n_fast]), calls, rep)

    X = rng.standard_normal((n_fast + 1, N_INPUTS))
    npm = NonparametricModel(N_INPUTS, T_OUT, n_features=D, sigma=3.0, lam=LAM,
                             standardizer=Standardizer(N_INPUTS).fit(X))
    row["ours_np_model"] = time_per_call(
        lambda i: npm.predict_learn_one(X[i % n_fast], U[i % n_fast]), calls, rep)

    sm = ShermanMorrisonRLS(D, LAM)
    row["sherman_morrison"] = time_per_call(
        lambda i: sm.predict_update(Z[i % n_fast], U[i % n_fast]), calls, rep)

    slow_calls = 3 if quick else (20 if D <= 500 else 5)
    slow_rep = 2 if quick else 5
    ref = ReferenceQRRLS(D, T_OUT, LAM)
    row["numpy_givens"] = time_per_call(lambda i: ref.predict_update(Z[i % n_fast], U[i % n_fast]),
                                        slow_calls, slow_rep)

    if not (quick and D > 500):
        import padasip as pa

        filt = pa.filters.FilterRLS(D, mu=1.0, eps=1.0 / LAM, w="zeros")

        def pada(i: int) -> None:
            z = Z[i % n_fast]
            filt.predict(z)
            filt.adapt(U[i % n_fast, 0], z)

        p_calls = 1 if D >= 1000 else slow_calls
        p_rep = 2 if quick else (3 if D >= 2000 else slow_rep)
        row["padasip_1out"] = time_per_call(pada, p_calls, p_rep)

    if not (quick and D > 500):
        Xw = rng.standard_normal((REFIT_WINDOW, N_INPUTS))
        Yw = rng.standard_normal((REFIT_WINDOW, T_OUT))
        sampler = RBFSampler(gamma=1.0 / (2 * 3.0**2), n_components=D, random_state=0).fit(Xw)
        Fw = sampler.transform(Xw)

        def refit(i: int) -> None:
            x = X[i % n_fast][None, :]
            f = sampler.transform(x)
            Fw[i % REFIT_WINDOW] = f[0]  # slide the window
            Ridge(alpha=LAM).fit(Fw, Yw).predict(f)

        row["sklearn_refit_n1000"] = time_per_call(refit, slow_calls if D <= 500 else 2, slow_rep)

    row["limit"] = bandwidth_limit_us(D, rep)
    return row


def load_old_rrls(rev: str, tmp: pathlib.Path) -> type[RecursiveRLS]:
    """``RecursiveRLS`` of ``core/learners/rrls.py`` and ``core/learners/_kernels.py`` at ``rev`` (Python side
    and kernels).

    Both modules are extracted with ``git show`` into ``tmp`` and imported under other names (the old
    ``rrls.py`` with its kernel import pointing at the old kernels), so old and new run in the same
    process on the same rows.
    """
    root = pathlib.Path(__file__).resolve().parents[2]

    def show(path: str) -> str:
        return subprocess.run(["git", "-C", str(root), "show", f"{rev}:{path}"],
                              check=True, capture_output=True, text=True).stdout

    (tmp / "_old_kernels.py").write_text(show("semiparam_ros/core/learners/_kernels.py"))
    rrls_src = show("semiparam_ros/core/learners/rrls.py")
    marker = "from semiparam_ros.core.learners._kernels import"
    if marker not in rrls_src:
        raise RuntimeError("rrls.py no longer imports the kernels as expected")
    (tmp / "_old_rrls.py").write_text(rrls_src.replace(marker, "from _old_kernels import"))
    sys.path.insert(0, str(tmp))
    try:
        for name in ("_old_kernels", "_old_rrls"):
            spec = importlib.util.spec_from_file_location(name, tmp / f"{name}.py")
            assert spec is not None and spec.loader is not None
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(tmp))
    return sys.modules["_old_rrls"].RecursiveRLS  # type: ignore[no-any-return]


def time_interleaved(steps: dict[str, Callable[[int], object]], calls: int, repeats: int,
                     ) -> dict[str, list[float]]:
    """Wall µs per call of each step, per repeat, the steps alternating in short repeats (one run)."""
    for step in steps.values():
        step(0)
    out: dict[str, list[float]] = {name: [] for name in steps}
    i = 1
    for _ in range(repeats):
        for name, step in steps.items():
            t0 = time.perf_counter()
            for _ in range(calls):
                step(i)
                i += 1
            out[name].append((time.perf_counter() - t0) / calls * 1e6)
    return out


def predict_update_only(path: pathlib.Path, baseline: str = KERNEL_BASELINE) -> int:
    """The predict-then-update comparison (its target), old learner next to new, saved to ``path``.

    For D ∈ {500, 1000} and β ∈ {1 (the target's setting), 0.9995 (the node's: a regularizer row per
    step)}, four steps alternate in short repeats on the same rows: ``predict_update`` and the habit
    (``predict(z)`` — with the variance for β < 1, as the node asks — then ``update(z, u)``), each with
    this tree's learner and with the learner (``rrls.py`` and its kernels) at ``baseline``.
    """
    rng = np.random.default_rng(0)
    load_before = os.getloadavg()
    rows = []
    with tempfile.TemporaryDirectory() as tmp, threadpool_limits(1):
        OldRLS = load_old_rrls(baseline, pathlib.Path(tmp))
        for beta in (1.0, 0.9995):
            for D in (500, 1000):
                Z, U = features_stream(rng, 4001, D)
                learners = {f"{age} {kind}": cls(D, T_OUT, LAM, forgetting=beta)
                            for age, cls in (("old", OldRLS), ("new", RecursiveRLS))
                            for kind in ("predict_update", "habit")}
                want_var = beta < 1.0

                def fused(rls: RecursiveRLS, Z: np.ndarray = Z, U: np.ndarray = U) -> Callable[[int], object]:
                    return lambda i: rls.predict_update(Z[i % 4000], U[i % 4000])

                def habit(rls: RecursiveRLS, Z: np.ndarray = Z, U: np.ndarray = U,
                          want_var: bool = want_var) -> Callable[[int], object]:
                    def step(i: int) -> None:
                        rls.predict(Z[i % 4000], return_variance=want_var)
                        rls.update(Z[i % 4000], U[i % 4000])
                    return step

                steps = {name: (fused if name.endswith("predict_update") else habit)(rls)
                         for name, rls in learners.items()}
                t = time_interleaved(steps, max(5, int(2e4 / D)), 120)
                med = {name: statistics.median(v) for name, v in t.items()}

                def ratio(a: str, b: str, t: dict[str, list[float]] = t) -> float:
                    return statistics.median(y / x for x, y in zip(t[a], t[b], strict=True))

                habit_over_fused = {a: ratio(f"{a} predict_update", f"{a} habit") for a in ("old", "new")}
                new_over_old = {k: ratio(f"old {k}", f"new {k}") for k in ("predict_update", "habit")}
                rows.append({"D": D, "beta": beta, "median_us": med,
                             "ratio_habit_to_predict_update": habit_over_fused, "new_over_old": new_over_old})
    load_after = os.getloadavg()
    print(f"predict(z) then update(z, u) vs predict_update(z, u), µs (median of 120 alternating repeats), "
          f"learner of {baseline} (old) and of this tree (new), same rows, one process\n")
    print("| β | D | predict_update old | predict_update new | habit old | habit new | ratio old | "
          "ratio new | target |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        m, q = r["median_us"], r["ratio_habit_to_predict_update"]
        print(f"| {r['beta']:g} | {r['D']} | {m['old predict_update']:.1f} | {m['new predict_update']:.1f} | "
              f"{m['old habit']:.1f} | {m['new habit']:.1f} | {q['old']:.2f} | {q['new']:.2f} | "
              f"{'≤ 1.3' if r['beta'] == 1.0 else '–'} |")
    print("\n(ratios: median over repeats of habit / predict_update; β < 1: predict with the variance)")
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f}")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"benchmark": "bench_core --predict-update-only", "baseline_kernels": baseline,
                                "rows": rows, "loadavg_before": load_before, "loadavg_after": load_after},
                               indent=2))
    print(f"wrote {path}")
    return 0


def memory_check(D: int = 1000) -> dict[str, object]:
    rng = np.random.default_rng(1)
    proc = psutil.Process()
    model = RecursiveRLS(D, T_OUT, LAM, forgetting=BETA)
    Z, U = features_stream(rng, 1000, D)
    out: dict[str, object] = {"D": D}
    for total in (1000, 10000):
        while model.n_samples_seen < total:
            for z, u in zip(Z, U, strict=True):
                model.predict_update(z, u)
        state_bytes = sum(v.nbytes for v in model.state_dict().values())
        out[f"after_{total}"] = {"rss_MB": proc.memory_info().rss / 1e6, "state_bytes": state_bytes}
    return out


def fmt(cell: object) -> str:
    if isinstance(cell, dict):
        return f"{cell['median_us']:.1f}"
    return "–" if cell is None else str(cell)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer sizes/repeats (smoke run, < 60 s)")
    parser.add_argument("--json", type=pathlib.Path, default=None,
                        help=f"output JSON (default {RESULTS}, or {RESULTS_PU} with --predict-update-only)")
    parser.add_argument("--predict-update-only", action="store_true",
                        help="only predict, update vs predict_update at D = 500, 1000, β = 1 and 0.9995, "
                             "the learner at --baseline next to this tree's (≈ 1 min)")
    parser.add_argument("--baseline", default=KERNEL_BASELINE,
                        help="git revision of the old learner for --predict-update-only")
    args = parser.parse_args(argv)
    if args.predict_update_only:
        return predict_update_only(args.json or RESULTS_PU, args.baseline)
    args.json = args.json or RESULTS
    sizes = [100, 500, 1000] if args.quick else [100, 250, 500, 1000, 2000]
    rng = np.random.default_rng(0)
    load_before = os.getloadavg()
    t_start = time.time()
    with threadpool_limits(1):
        rows = [bench_size(D, args.quick, rng) for D in sizes]
        mem = memory_check(1000 if not args.quick else 500)
    load_after = os.getloadavg()

    cols = [("ours β=1", "ours_beta1"), (f"ours β={BETA}", "ours_forgetting"),
            ("ours NP model (RFF+RLS)", "ours_np_model"), ("numpy Givens", "numpy_givens"),
            ("Sherman–Morrison", "sherman_morrison"), ("padasip RLS (1 output)", "padasip_1out"),
            (f"RBFSampler+Ridge refit (n={REFIT_WINDOW})", "sklearn_refit_n1000")]
    print("Per-sample predict + update, µs (median), 6 outputs, 1 BLAS thread\n")
    header = ["D", *[c for c, _ in cols], "limit (bytes/BW)", "ours β=1 / limit", "target",
              "CPU share (ours β=1)", "ours β=1 CPU µs"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for r in rows:
        lim = r["limit"]["limit_us"]  # type: ignore[index]
        ours = r["ours_beta1"]["median_us"]  # type: ignore[index]
        target = TARGETS_US.get(int(r["D"]))  # type: ignore[arg-type]
        cells = [str(r["D"]), *[fmt(r.get(k)) for _, k in cols], f"{lim:.1f}", f"{ours / lim:.2f}",
                 f"≤ {target:.0f}" if target else "–",
                 f"{r['ours_beta1']['cpu_share']:.2f}",  # type: ignore[index]
                 f"{r['ours_beta1']['cpu_median_us']:.1f}"]  # type: ignore[index]
        print("| " + " | ".join(cells) + " |")
    print("\npredict(z) then update(z, u) vs the fused predict_update(z, u), interleaved, µs (median)\n")
    print("| D | predict_update | predict, update | ratio (median of pairs) | target |")
    print("|---|---|---|---|---|")
    for r in rows:
        sbs = r["predict_then_update"]
        print(f"| {r['D']} | {sbs['a_median_us']:.1f} | {sbs['b_median_us']:.1f} | "  # type: ignore[index]
              f"{sbs['ratio_median']:.2f} | {'≤ 1.3' if r['D'] in (500, 1000) else '–'} |")  # type: ignore[index]
    print(f"\nMemory (D={mem['D']}, β={BETA}): " + ", ".join(
        f"{k}: RSS {v['rss_MB']:.1f} MB, learner state {v['state_bytes'] / 1e6:.2f} MB"
        for k, v in mem.items() if k != "D"))
    print(f"Load average before {load_before[0]:.2f}, after {load_after[0]:.2f} (2 cores, shared); "
          f"wall {time.time() - t_start:.0f} s")

    result = {
        "benchmark": "bench_core",
        "quick": args.quick,
        "machine": {"platform": platform.platform(), "processor": platform.processor(),
                    "cpu_count": os.cpu_count(), "python": platform.python_version(),
                    "numpy": np.__version__, "scipy": scipy.__version__, "numba": numba.__version__,
                    "sklearn": sklearn.__version__,
                    "loadavg_before": load_before, "loadavg_after": load_after},
        "settings": {"outputs": T_OUT, "lam": LAM, "forgetting": BETA, "refit_window": REFIT_WINDOW,
                     "np_model_inputs": N_INPUTS, "blas_threads": 1,
                     "padasip_normalisation": "one FilterRLS = one output (lower bound of 6 outputs)"},
        "targets_us": TARGETS_US,
        "rows": rows,
        "memory": mem,
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
