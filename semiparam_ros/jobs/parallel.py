"""Independent offline jobs (grid points, models, robots) on every core, or on a Dask cluster.

:func:`run_jobs` calls ``fn(*args)`` for every argument tuple and returns the results in order. With
``jobs == 1`` it is a plain loop in this process; otherwise joblib's default process backend (loky) runs
them; with ``cluster`` (a Dask scheduler address or ``local:N``) the workers of that cluster do
(:mod:`semiparam_ros.jobs.cluster`). Every job runs with one BLAS thread in each case (``threadpoolctl``),
and builds its own seeded learners from its arguments, so the results are the same numbers whatever runs
them.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

__all__ = ["resolve_jobs", "run_jobs"]

T = TypeVar("T")


def resolve_jobs(jobs: int) -> int:
    """Return the number of workers for ``jobs``: itself if positive, all cores for ``-1`` (or ``0``).

    Raises:
        ValueError: If ``jobs < -1``.
    """
    if jobs < -1:
        raise ValueError(f"jobs must be >= 1, or -1 / 0 for all cores, got {jobs}")
    return jobs if jobs >= 1 else (os.cpu_count() or 1)


def run_jobs(
    fn: Callable[..., T],
    args: Sequence[tuple[Any, ...]],
    *,
    jobs: int = 1,
    progress: bool = False,
    unit: str = "job",
    cluster: str | None = None,
    labels: Sequence[str] | None = None,
) -> list[T]:
    """Run ``fn(*a)`` for each ``a`` in ``args``; results in the order of ``args``.

    Args:
        fn: A module-level function (picklable for the process backend).
        args: One argument tuple per job.
        jobs: Workers (1 = serial in this process; -1 or 0 = all cores); ignored with ``cluster``.
        progress: Progress on stderr (a bar for serial runs, a line per finished job on a cluster; joblib
            reports nothing).
        unit: Unit name for the bar.
        cluster: A Dask scheduler address or ``local:N`` (:func:`~semiparam_ros.jobs.cluster.connect`).
        labels: What each job is, for the cluster's progress lines and errors.

    Returns:
        The results.

    Raises:
        ValueError: If ``jobs < -1``. Whatever ``fn`` raises is re-raised (on a cluster: every failure
            together, as a :class:`~semiparam_ros.errors.ClusterError` naming each job and its worker).
    """
    if cluster is not None:
        from semiparam_ros.jobs.cluster import connect, run_on_cluster

        with connect(cluster) as client:
            return run_on_cluster(client, fn, args, labels=labels, progress=progress, unit=unit)
    n = resolve_jobs(jobs)
    if n == 1 or len(args) <= 1:
        items: Any = args
        if progress and sys.stderr.isatty():  # a bar redrawn into a log or a pipe leaves frames
            from tqdm import tqdm

            items = tqdm(args, unit=unit)
        return [_one_thread(fn, *a) for a in items]
    from joblib import Parallel, delayed

    return list(Parallel(n_jobs=min(n, len(args)))(delayed(_one_thread)(fn, *a) for a in args))


def _one_thread(fn: Callable[..., T], *args: Any) -> T:
    """Call ``fn(*args)`` with one BLAS/OpenMP thread (the same arithmetic in every worker and here)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return fn(*args)
