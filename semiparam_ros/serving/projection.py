"""The consistent projection in a process of its own, off the 1 kHz path.

:class:`ProjectionWorker` solves :func:`~semiparam_ros.core.rigid_body.identification.consistent_parameters`
(cvxpy, tens of ms) for the served model while the learning loop runs on.
"""

from __future__ import annotations

import numpy as np

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.build import build_regressor
from semiparam_ros.core.rigid_body.identification import (
    ConsistentEstimate,
    consistent_parameters,
    prior_weights,
)
from semiparam_ros.core.rigid_body.plausible import PlausibleLinks, plausible_links

__all__ = ["ProjectionWorker"]


class ProjectionWorker:
    """Solve :func:`consistent_parameters` in a separate process, off the 1 kHz path.

    A thread would not do: cvxpy's canonicalisation is Python and would hold the GIL for tens of ms per
    solve, stalling the node's learning. The worker process builds its own regressor from the URDF text and
    configuration once (a few seconds, in the background); :meth:`submit` sends a snapshot of the learner
    and returns at once; :attr:`latest` holds the newest solution.

    Args:
        config_flat: The estimator's configuration as a flat dict (:meth:`EstimatorConfig.to_flat`).
        urdf_xml: The URDF text the estimator's regressor was built from.

    Example:
        >>> from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
        >>> from semiparam_ros.core.estimator.online import OnlineEstimator
        >>> est = OnlineEstimator(EstimatorConfig.from_flat(ICUB_RIGHT_ARM))
        >>> worker = ProjectionWorker(est.config.to_flat(), est.regressor.urdf_xml)
        >>> par = est.model.parametric
        >>> worker.submit(par.parameters, par.rls.R, est.column_scale, par.rls.lam)
        True
        >>> worker.wait(timeout=120.0).status
        'optimal'
        >>> worker.close()
    """

    def __init__(self, config_flat: dict, urdf_xml: str) -> None:
        import multiprocessing
        import threading

        context = multiprocessing.get_context("spawn")
        self._conn, child = context.Pipe()
        self._process = context.Process(target=_worker_main, args=(child, config_flat, urdf_xml),
                                        name="semiparam-projection", daemon=True)
        self._process.start()
        child.close()
        self._lock = threading.Lock()
        self._done = threading.Condition(self._lock)
        self._busy = False
        self._closed = False
        #: The newest solution, or None.
        self.latest: ConsistentEstimate | None = None
        #: The links of the newest solution a user can load (``~/link_inertias``, ``~/export_urdf``), or None.
        self.latest_links: PlausibleLinks | None = None
        #: The newest failure's message, or None.
        self.error: str | None = None
        self._solved = 0
        self._reader = threading.Thread(target=self._read, name="semiparam-projection-reader", daemon=True)
        self._reader.start()

    def submit(self, theta: np.ndarray, R: np.ndarray, scale: np.ndarray, lam: float) -> bool:
        """Send a snapshot to solve; False (nothing sent) while the previous one is being solved."""
        with self._lock:
            if self._busy or self._closed:
                return False
            self._busy = True
        self._conn.send((np.array(theta), np.array(R), np.array(scale), float(lam)))
        return True

    def wait(self, timeout: float) -> ConsistentEstimate | None:
        """Wait for the solution of the last submission (for tools and tests); the newest one or None."""
        with self._done:
            self._done.wait_for(lambda: not self._busy, timeout=timeout)
            return self.latest

    def _read(self) -> None:
        while True:
            try:
                kind, payload = self._conn.recv()
            except (EOFError, OSError):
                with self._done:
                    self._busy = False
                    self._done.notify_all()
                return
            with self._done:
                if kind == "ok":
                    self.latest, self.latest_links = payload
                    self.error = None
                    self._solved += 1
                else:
                    self.error = str(payload)
                self._busy = False
                self._done.notify_all()

    @property
    def solved(self) -> int:
        """Solutions received so far."""
        return self._solved

    def close(self, timeout: float = 5.0) -> None:
        """Stop the worker process (it is a daemon: it also ends with the parent)."""
        with self._lock:
            self._closed = True
        try:
            self._conn.send(None)
        except (OSError, BrokenPipeError):
            pass
        self._process.join(timeout)
        if self._process.is_alive():
            self._process.kill()
            self._process.join(timeout)
        self._conn.close()


def _worker_main(conn: object, config_flat: dict, urdf_xml: str) -> None:  # pragma: no cover - subprocess
    """Run the worker process: build the regressor once, then solve what arrives until ``None``."""
    regressor = build_regressor(EstimatorConfig.from_flat(config_flat), urdf_xml, source="the node's URDF")
    weights = prior_weights(regressor)
    while True:
        try:
            job = conn.recv()  # type: ignore[attr-defined]
        except (EOFError, OSError):
            return
        if job is None:
            return
        theta, R, scale, lam = job
        try:
            estimate = consistent_parameters(regressor, theta, R, scale, lam, weights=weights)
            links = plausible_links(regressor, estimate, theta, R, scale, lam, weights=weights)
            result: tuple[str, object] = ("ok", (estimate, links))
        except Exception as err:  # a solver failure is reported, the worker lives on
            result = ("error", f"{type(err).__name__}: {err}")
        conn.send(result)  # type: ignore[attr-defined]
