"""Independent jobs on a Dask cluster: the serial results, progress as jobs finish, lost workers retried.

``--cluster ADDRESS`` of ``tune``, ``evaluate`` and ``learn-fleet`` comes here. ``ADDRESS`` is a running
Dask scheduler (``tcp://host:8786``: start ``dask scheduler`` on one machine and ``dask worker
tcp://host:8786 --nthreads 1`` on each, every worker with this package installed and the bags at the same
paths; docs/scale.md), or ``local:N`` for a :class:`distributed.LocalCluster` of N worker processes on
this machine.

Each job runs ``fn(*args)`` in a worker with one BLAS thread and builds its own seeded learners from its
arguments, so the numbers are those of the serial run bit for bit. Arguments shared by several jobs (a
training stream, a regressor) are sent to the workers once. Results are gathered as jobs finish (a
progress line per job on stderr), so a worker lost mid-run costs only its running jobs, which the
scheduler gives to another worker. A job that raises does not stop the others: when all are done the
failures are raised together, each naming its job (the bag) and the worker it ran on.

>>> with connect("local:1") as client:
...     run_on_cluster(client, pow, [(2, 3), (3, 2)], labels=["2**3", "3**2"])
[8, 9]
"""

from __future__ import annotations

import importlib.util
import logging
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TypeVar

from semiparam_ros.errors import ClusterError
from semiparam_ros.version import __version__

__all__ = ["CONNECT_TIMEOUT_S", "LOCAL_PREFIX", "connect", "run_on_cluster"]

T = TypeVar("T")

#: ``local:N``: a LocalCluster of N worker processes.
LOCAL_PREFIX = "local:"
#: How long a scheduler may take to answer before the run stops with an error [s].
CONNECT_TIMEOUT_S = 10.0
_RETRIES = 2  # a job whose worker died is rescheduled by the scheduler; these retries are for its errors


def _worker_package() -> str | None:
    """Run on a worker: the version of this package there, or None if it is not installed."""
    if importlib.util.find_spec("semiparam_ros") is None:
        return None
    from semiparam_ros.version import __version__ as version

    return version


@contextmanager
def connect(address: str, *, timeout_s: float = CONNECT_TIMEOUT_S) -> Iterator[Any]:
    """Open a Dask client on ``address`` (``local:N`` starts a LocalCluster), closed on exit.

    Args:
        address: A scheduler address (``tcp://host:8786``) or ``local:N``.
        timeout_s: How long to wait for the scheduler [s].

    Yields:
        The ``distributed.Client``.

    Raises:
        ClusterError: An unreachable scheduler (named), a malformed ``local:N``, no worker, or workers
            without this package or with another version of it (named).
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError as err:  # pragma: no cover - pinned in requirements.txt
        raise ClusterError("--cluster needs Dask: pip install distributed (pinned in requirements.txt)"
                           ) from err
    cluster = None
    if address.startswith(LOCAL_PREFIX):
        text = address[len(LOCAL_PREFIX):]
        if not text.isdigit() or int(text) < 1:
            raise ClusterError(f"cluster address {address!r}: 'local:N' needs a number of workers N >= 1")
        cluster = LocalCluster(n_workers=int(text), threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR)
        client = Client(cluster)
    else:
        _probe(address, timeout_s)
        try:
            client = Client(address, timeout=timeout_s)
        except (OSError, TimeoutError, ValueError) as err:
            raise ClusterError(f"cannot reach the Dask scheduler at {address} within {timeout_s:g} s: "
                               f"{err}") from None
    try:
        _check_workers(client, address, timeout_s)
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _probe(address: str, timeout_s: float) -> None:
    """Fail at once on a refused TCP address (Dask would retry it until its timeout)."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme != "tcp" or not parts.hostname or parts.port is None:
        return  # another protocol: Dask's own connection decides
    try:
        with socket.create_connection((parts.hostname, parts.port), timeout=timeout_s):
            pass
    except OSError as err:
        raise ClusterError(f"cannot reach the Dask scheduler at {address} within {timeout_s:g} s: {err}"
                           ) from None


def _check_workers(client: Any, address: str, timeout_s: float) -> None:
    try:
        client.wait_for_workers(1, timeout=timeout_s)
    except (OSError, TimeoutError) as err:
        raise ClusterError(f"the Dask scheduler at {address} has no worker (waited {timeout_s:g} s)") from err
    versions = client.run(_worker_package)
    missing = sorted(w for w, v in versions.items() if v is None)
    if missing:
        raise ClusterError(f"Dask workers without semiparam_ros: {', '.join(missing)} (install the package "
                           f"on every worker: pip install -e . and requirements.txt)")
    other = sorted(f"{w} ({v})" for w, v in versions.items() if v != __version__)
    if other:
        raise ClusterError(f"Dask workers with another semiparam_ros than {__version__}: {', '.join(other)}")


def _job(fn: Callable[..., T], args: tuple[Any, ...], label: str) -> T:
    """Run on a worker: ``fn(*args)`` with one BLAS thread; an error names the job and the worker."""
    from distributed import get_worker
    from threadpoolctl import threadpool_limits

    try:
        with threadpool_limits(limits=1):
            return fn(*args)
    except Exception as err:
        where = get_worker().address
        raise ClusterError(f"{label}: {type(err).__name__}: {err} (on worker {where})") from err


def run_on_cluster(client: Any, fn: Callable[..., T], args: Sequence[tuple[Any, ...]], *,
                   labels: Sequence[str] | None = None, progress: bool = False, unit: str = "job") -> list[T]:
    """Run ``fn(*a)`` for each ``a`` in ``args`` on the client's workers; results in the order of ``args``.

    Args:
        client: A ``distributed.Client`` (:func:`connect`).
        fn: A module-level function (importable on the workers).
        args: One argument tuple per job.
        labels: What each job is, for progress and errors (default ``job 1``, ``job 2``, …).
        progress: Print a line per finished job on stderr.
        unit: Name of a job in the progress lines.

    Returns:
        The results.

    Raises:
        ClusterError: One or more jobs failed (each named with its worker), after every other job finished.
    """
    from distributed import as_completed

    labels = list(labels) if labels is not None else [f"{unit} {i + 1}" for i in range(len(args))]
    shared: dict[int, Any] = {}
    counts: dict[int, int] = {}
    for a in args:
        for value in a:
            counts[id(value)] = counts.get(id(value), 0) + 1
    owners = {id(v): v for a in args for v in a}
    for key, n in counts.items():
        if n > 1 and not isinstance(owners[key], str | int | float | bool | type(None)):
            shared[key] = client.scatter(owners[key], broadcast=True, hash=False)
    futures = {}
    for i, a in enumerate(args):
        sent = tuple(shared.get(id(v), v) for v in a)
        futures[client.submit(_job, fn, sent, labels[i], retries=_RETRIES, pure=False)] = i
    results: list[Any] = [None] * len(args)
    failures: list[str] = []
    start = time.perf_counter()
    for done, future in enumerate(as_completed(futures), start=1):
        i = futures[future]
        status = "done"
        try:
            results[i] = future.result()
        except ClusterError as err:
            failures.append(str(err))
            status = "failed"
        if progress:
            print(f"[{done}/{len(args)} {unit}s, {time.perf_counter() - start:.0f} s] {labels[i]} {status}",
                  file=sys.stderr, flush=True)
    if failures:
        raise ClusterError(f"{len(failures)} of {len(args)} {unit}s failed:\n" + "\n".join(failures))
    return results
