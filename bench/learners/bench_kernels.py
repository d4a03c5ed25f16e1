"""Benchmark: the compiled QR-RLS kernels alone, old (``git show REV``) next to new, in one process.

Per call of ``qr_rls_steps`` with one data row (6 outputs) on a factor that has seen 300 rows:

* ``update``          — the rotations only (what a deferred ``update`` costs when it is flushed);
* ``update+tracker``  — with the a-priori prediction of the row (``predict_update``);
* ``update+query``    — with one query row predicted with the new factor in the same sweep (what
  ``predict`` costs after ``update``: the learn-then-predict habit, and the node's step);
* ``solve``           — ``solve_predict`` of one row (read-only forward substitution, no pending update).

β = 1 (no regularizer row) and β = 0.9995 (the node's: scale + one regularizer row per step, so the
columns right of its coordinate carry two active rows). The four kernels of old and new alternate in
short repeats; medians of the mean µs per call. The ratio ``update+query / update+tracker`` is the
kernel's share of the predict-then-update target (the Python side adds ≈ 2–4 µs to the habit).
One BLAS thread. Usage::

    PYTHONPATH=$PWD .venv/bin/python bench/learners/bench_kernels.py [--baseline REV] [--json PATH]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time
import types
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

import semiparam_ros.core.learners._kernels as new_kernels
from semiparam_ros.core.learners.rrls import RecursiveRLS

ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "bench_kernels.json"
T_OUT = 6


def load_old(rev: str, tmp: pathlib.Path) -> types.ModuleType:
    """``core/learners/_kernels.py`` at ``rev``, extracted to ``tmp`` and imported as ``_old_kernels``."""
    for where in ("core/learners/_kernels.py", "core/_kernels.py"):  # its place since, and before, the rooms
        shown = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:semiparam_ros/{where}"],
                               capture_output=True, text=True)
        if shown.returncode == 0:
            break
    shown.check_returncode()
    source = shown.stdout
    path = tmp / "_old_kernels.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("_old_kernels", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["_old_kernels"] = module
    spec.loader.exec_module(module)
    return module


def cases(mod: types.ModuleType, D: int, beta: float, rng: np.random.Generator,
          ) -> dict[str, Callable[[int], object]]:
    """The four kernel calls of ``mod`` on a factor of ``D`` features that has seen 300 rows."""
    rls = RecursiveRLS(D, T_OUT, 1.0, forgetting=beta)
    Z = np.sqrt(2.0 / D) * np.cos(rng.uniform(0, 2 * np.pi, (364, D)))
    U = rng.standard_normal((364, T_OUT))
    rls.update_steps(Z[:300], U[:300], 1)
    M0 = np.ascontiguousarray(np.hstack([rls.R, rls.d]))
    Z, U = Z[300:], U[300:]
    scale, reg = rls._scale, rls._reg
    no, noq, nov = np.empty((0, T_OUT)), np.empty((0, D)), np.empty(0)
    P, QP, Qv = np.empty((1, T_OUT)), np.empty((1, T_OUT)), np.empty(1)
    Ms = [M0.copy() for _ in range(4)]

    def rows(i: int) -> tuple[np.ndarray, np.ndarray]:
        return Z[i % 64 : i % 64 + 1], U[i % 64 : i % 64 + 1]

    return {
        "update": lambda i: mod.qr_rls_steps(Ms[0], *rows(i), 1, scale, reg, i % D, no, 1e150, no, noq, no,
                                             nov),
        "update+tracker": lambda i: mod.qr_rls_steps(Ms[1], *rows(i), 1, scale, reg, i % D, P, 1e150, no, noq,
                                                     no, nov),
        "update+query": lambda i: mod.qr_rls_steps(Ms[2], *rows(i), 1, scale, reg, i % D, no, 1e150, no,
                                                   rows(i + 1)[0], QP, Qv),
        "solve": lambda i: mod.solve_predict(Ms[3], rows(i)[0], QP, Qv),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--baseline", default="13c2755", help="git revision of the old kernels")
    parser.add_argument("--json", type=pathlib.Path, default=RESULTS)
    parser.add_argument("--repeats", type=int, default=60)
    args = parser.parse_args(argv)
    load_before = os.getloadavg()
    rows = []
    with tempfile.TemporaryDirectory() as tmp, threadpool_limits(1):
        old = load_old(args.baseline, pathlib.Path(tmp))
        for beta in (1.0, 0.9995):
            for D in (500, 1000):
                steps = {f"{age} {name}": f for age, mod in (("old", old), ("new", new_kernels))
                         for name, f in cases(mod, D, beta, np.random.default_rng(D)).items()}
                calls = max(5, int(2e4 / D))
                for f in steps.values():
                    f(0)
                t: dict[str, list[float]] = {k: [] for k in steps}
                for _ in range(args.repeats):
                    for k, f in steps.items():
                        t0 = time.perf_counter()
                        for i in range(1, calls + 1):
                            f(i)
                        t[k].append((time.perf_counter() - t0) / calls * 1e6)
                med = {k: statistics.median(v) for k, v in t.items()}
                rows.append({"beta": beta, "D": D, "median_us": med})
    load_after = os.getloadavg()
    print(f"Compiled kernels alone, µs per call (median of {args.repeats} alternating repeats), "
          f"old = {args.baseline}, new = this tree\n")
    print("| β | D | update old / new | update+tracker old / new | update+query old / new | "
          "solve old / new | query ÷ tracker old / new |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        m = r["median_us"]

        def pair(name: str, m: dict[str, float] = m) -> str:
            return f"{m['old ' + name]:.1f} / {m['new ' + name]:.1f}"

        ro = m["old update+query"] / m["old update+tracker"]
        rn = m["new update+query"] / m["new update+tracker"]
        print(f"| {r['beta']:g} | {r['D']} | {pair('update')} | {pair('update+tracker')} | "
              f"{pair('update+query')} | {pair('solve')} | {ro:.2f} / {rn:.2f} |")
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"benchmark": "bench_kernels", "baseline": args.baseline, "rows": rows,
                                     "loadavg_before": load_before, "loadavg_after": load_after}, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
