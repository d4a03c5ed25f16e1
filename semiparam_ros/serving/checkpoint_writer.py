"""A thread that writes checkpoints: periodically, on request, after a reset and at shutdown.

The state is copied under the learner's lock by the ``snapshot`` callable (a memory copy, ≈ 1 ms at
D = 500) and written outside it (:func:`~semiparam_ros.core.checkpoint.atomic_save_npz`: a temporary file,
fsync, rename), so neither the learning thread nor a service ever waits for the disk. Plain Python: the
node (:mod:`semiparam_ros.ros.estimator_node`) wires its ``~/save`` service and its parameters to it.

>>> import tempfile, pathlib, numpy as np
>>> path = pathlib.Path(tempfile.mkdtemp()) / "model.npz"
>>> writer = CheckpointWriter(path, period_s=0.0, snapshot=lambda: ({"x": np.ones(2)}, 1, 7))
>>> writer.start()
>>> writer.save(timeout_s=5.0)
(True, 'saved 7 learned samples to ...model.npz')
>>> writer.stop(save=True)
True
"""

from __future__ import annotations

import concurrent.futures
import os
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from semiparam_ros.atomic import remove_stale_temporaries
from semiparam_ros.core.checkpoint import atomic_save_npz, load_npz
from semiparam_ros.errors import CheckpointError

if TYPE_CHECKING:
    from semiparam_ros.core.config import EstimatorConfig
    from semiparam_ros.core.estimator.online import OnlineEstimator

__all__ = ["CheckpointWriter", "Snapshot", "default_checkpoint_path", "move_aside", "warm_start"]

#: ``() -> (state, version, samples learned)``, called in the writer's thread; it takes the learner's lock.
Snapshot = Callable[[], tuple[Mapping[str, np.ndarray], int, int]]


class CheckpointWriter:
    """Write the learned state to ``path`` from a thread of its own.

    Args:
        path: The checkpoint file; None disables checkpoints (a request is answered with a failure).
        period_s: Write every ``period_s`` seconds of wall time when the state changed; ≤ 0: never
            periodically (on request, after a reset and at shutdown only).
        snapshot: Copies the state (see :data:`Snapshot`); its version tells whether anything changed
            since the last write.
        version: Returns the current learned version cheaply (without copying); a periodic or final write
            happens only when it differs from the version last written (at first: the version at
            construction); None: always write.
        on_result: Called after every write attempt with ``(ok, message)`` (in the writer's thread).
    """

    def __init__(self, path: Path | None, *, period_s: float, snapshot: Snapshot,
                 version: Callable[[], int] | None = None,
                 on_result: Callable[[bool, str], None] | None = None) -> None:
        self.path = path
        self._period_s = float(period_s)
        self._snapshot = snapshot
        self._version = version
        self._on_result = on_result
        self._event = threading.Event()
        self._lock = threading.Lock()
        self._requests: list[concurrent.futures.Future[tuple[bool, str]]] = []
        self._reset_pending = False
        self._stopping = False
        self._saved_version: int | None = None if version is None else version()
        self._thread: threading.Thread | None = None
        #: Whether the final checkpoint (at :meth:`stop`) was written, or none was due.
        self.final_ok = True

    @property
    def period_s(self) -> float:
        """The period of the periodic write [s]; setting it wakes the thread to take the new period."""
        return self._period_s

    @period_s.setter
    def period_s(self, value: float) -> None:
        self._period_s = float(value)
        self._event.set()

    def apply_runtime_parameters(self, config: EstimatorConfig) -> None:
        """Take the run-time parameters of the ``checkpoints`` target (``checkpoint.period`` [s])."""
        self.period_s = float(config["checkpoint.period"])

    def start(self) -> None:
        """Start the writer thread (a daemon: it never keeps the process alive)."""
        self._thread = threading.Thread(target=self._run, name="estimator-checkpoint", daemon=True)
        self._thread.start()

    def request_reset(self) -> None:
        """Persist a reset soon, so a warm start does not bring the forgotten model back."""
        if self.path is None:
            return
        with self._lock:
            self._reset_pending = True
        self._event.set()

    def save(self, timeout_s: float) -> tuple[bool, str]:
        """Write now and wait at most ``timeout_s`` [s] for the file; returns ``(ok, message)``."""
        if self.path is None:
            return False, "checkpoint.enabled is false: no checkpoint is kept"
        future: concurrent.futures.Future[tuple[bool, str]] = concurrent.futures.Future()
        with self._lock:
            self._requests.append(future)
        self._event.set()
        try:
            return future.result(timeout=timeout_s)
        except concurrent.futures.TimeoutError:
            return False, (f"checkpoint to {self.path} not written within {timeout_s:g} s (the disk is slow "
                           "or blocked); the write goes on in the background")

    def stop(self, *, save: bool) -> bool:
        """Stop the thread, writing a final checkpoint first if ``save`` and the state changed.

        Returns:
            :attr:`final_ok`.
        """
        if not save:
            self.path = None
        self._stopping = True
        self._event.set()
        if self._thread is not None:
            self._thread.join(timeout=30.0)
            self._thread = None
        return self.final_ok

    def _changed(self) -> bool:
        return self._version is None or self._version() != self._saved_version

    def _run(self) -> None:
        last_periodic = time.monotonic()
        while True:
            period = self._period_s
            timeout = max(last_periodic + period - time.monotonic(), 0.0) if period > 0 else 1.0
            self._event.wait(timeout)
            self._event.clear()
            stopping = self._stopping
            with self._lock:
                requests, self._requests = self._requests, []
                reset_pending, self._reset_pending = self._reset_pending, False
            now = time.monotonic()
            periodic = period > 0 and now - last_periodic >= period
            if periodic or period <= 0:
                last_periodic = now
            if self.path is None:
                result = (False, "checkpoint.enabled is false: no checkpoint is kept")
            elif requests or ((stopping or periodic or reset_pending) and self._changed()):
                result = self._write(self.path)
            else:
                result = (True, f"checkpoint {self.path} is up to date")
            for future in requests:
                future.set_result(result)
            if stopping:
                self.final_ok = result[0] or self.path is None
                return

    def _write(self, path: Path) -> tuple[bool, str]:
        try:
            state, version, n_learned = self._snapshot()
            atomic_save_npz(path, state)
        except Exception as err:  # any failure: this thread must live on and answer every request
            result = (False, f"checkpoint failed: {err}")
        else:
            self._saved_version = version
            result = (True, f"saved {n_learned} learned samples to {path}")
        if self._on_result is not None:
            self._on_result(*result)
        return result


def warm_start(estimator: OnlineEstimator, path: Path | None, *, load: bool, default: bool = False
               ) -> list[str]:
    """Remove stale temporaries of the checkpoint at ``path``, then load it into ``estimator`` if ``load``.

    Args:
        estimator: The estimator to warm start (unchanged on a cold start).
        path: The checkpoint; None: no checkpoints (``checkpoint.enabled`` false).
        load: ``checkpoint.load_on_start``.
        default: ``path`` is the default file under ``$ROS_HOME`` (``checkpoint.path`` empty): a file that
            was not learned on this very URDF text and structure, or that cannot be loaded, is moved aside
            (never deleted or overwritten) and the start is cold, instead of refused.

    Returns:
        What happened, one line each (the removed temporaries, then why the start is cold or warm).

    Raises:
        CheckpointError: A configured checkpoint exists but cannot be loaded (corrupt, another structure
            or robot, absurd values); the message says how to proceed.
    """
    if path is None:
        return ["cold start: checkpoint.enabled is false (nothing learned is kept)"]
    notes = [f"removed {stale}, left by an interrupted checkpoint write"
             for stale in remove_stale_temporaries(path)]
    if not load:
        return [*notes, "cold start: checkpoint.load_on_start is false"]
    if not path.exists():
        return [*notes, f"cold start: no checkpoint at {path} yet (it will be written there)"]
    try:
        state = load_npz(path)
        if default:
            _check_same_robot(state, estimator, path)
        estimator.load_state(state, path)
    except CheckpointError as err:
        if default:
            aside = move_aside(path)
            return [*notes, f"cold start: the checkpoint at {path} does not fit this node ({err}); moved "
                            f"aside to {aside}"]
        raise CheckpointError(f"cannot warm start from checkpoint {path}: {err}\nDelete or move it, point "
                              "checkpoint.path elsewhere, or set checkpoint.load_on_start:=false to "
                              "overwrite it.") from err
    return [*notes, *estimator.migration_notes,
            f"warm start from {path} ({estimator.n_samples_learned} samples learned)"]


def _check_same_robot(state: dict[str, np.ndarray], estimator: OnlineEstimator, path: Path) -> None:
    """Refuse a checkpoint of another URDF text (the fingerprint covers joints, output and structure)."""
    urdf = state.get("meta.urdf")
    if urdf is None or str(np.asarray(urdf)) != estimator.regressor.urdf_xml:
        raise CheckpointError(f"{path}: learned on another URDF")


def default_checkpoint_path(node_name: str) -> Path:
    """Return the default checkpoint of a node: ``$ROS_HOME/semiparam_ros/<namespace>/<node>.npz``.

    ``ROS_HOME`` is ``~/.ros`` when unset (as ROS 2 itself).

    Args:
        node_name: The node's fully qualified name (``/arm/estimator``).

    >>> import os
    >>> os.environ["ROS_HOME"] = "/tmp/home"
    >>> str(default_checkpoint_path("/arm/estimator"))
    '/tmp/home/semiparam_ros/arm/estimator.npz'
    """
    home = Path(os.environ.get("ROS_HOME") or Path.home() / ".ros").expanduser()
    parts = [p for p in node_name.split("/") if p] or ["estimator"]
    return home.joinpath("semiparam_ros", *parts[:-1], f"{parts[-1]}.npz")


def move_aside(path: Path) -> Path:
    """Rename a checkpoint to ``<stem>.aside-<UTC time>[-k].npz`` beside it (never over another file)."""
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    for k in range(1000):
        aside = path.with_name(f"{path.stem}.aside-{stamp}{f'-{k}' if k else ''}{path.suffix}")
        if not aside.exists():
            try:
                path.rename(aside)
            except OSError as err:
                raise CheckpointError(f"{path}: cannot move it aside: {err}") from err
            return aside
    raise CheckpointError(f"{path}: cannot move it aside (1000 files beside it already)")
