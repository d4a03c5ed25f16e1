"""Forgetting-weighted cross-products of two row streams, added by blocks off the caller's thread.

The consistent semiparametric model keeps, beside its residual learner, the cross-products of the random
features φ_m (D values) with the learned regressor entries e_m (E values) of every learned sample,

    B = Σ_m (Π_{j>m} β_j) φ_m e_mᵀ     (D × E),

where β_j is the forgetting factor of sample j's step (β = 1: no forgetting). One rank-1 update per sample
reads and writes all of B (D·E values, 1.7 MB at D = 1000 on a 7-joint arm); instead the rows are staged and
added :attr:`EntryCrossProducts.ROWS` at a time by one matrix product (BLAS 3),

    B ← (Π_{m ∈ block} β_m) B + Φ_wᵀ E_block,   row m of Φ_w = (Π_{j>m, j ∈ block} β_j) φ_m,

which is the same sum in another order. That product is the largest piece of work of a sample on which it
falls (≈ 0.5 ms at D = 1000). With ``background=True`` it runs on a worker thread (BLAS releases the GIL)
while the caller goes on staging rows into a second buffer: the sample path never waits for it, except when
B itself is read (:meth:`settled`, :meth:`with_pending`, a copy or a pickle), which first waits for the
block in flight. The arithmetic is the same operations on the same arrays in either mode, so both give the
same bits. A worker's exception is raised in the caller at the next wait: an error is never lost.

Example:
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> cp = EntryCrossProducts(5, 3)
    >>> phi, e = rng.standard_normal((70, 5)), rng.standard_normal((70, 3))
    >>> for m in range(70):
    ...     cp.stage(phi[m], e[m], 0.99)
    >>> w = 0.99 ** np.arange(69, -1, -1)  # β^{n−m}
    >>> bool(np.allclose(cp.settled(), (phi * w[:, None]).T @ e))
    True
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np

__all__ = ["EntryCrossProducts"]

_executor: ThreadPoolExecutor | None = None
_executor_pid = -1
_executor_lock = threading.Lock()


def _worker() -> ThreadPoolExecutor:
    """Return the process's one worker thread for blocks (made again in a forked child)."""
    global _executor, _executor_pid
    with _executor_lock:
        if _executor is None or _executor_pid != os.getpid():
            _executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cross-products")
            _executor_pid = os.getpid()
        return _executor


def _add_block(B: np.ndarray, phi: np.ndarray, entries: np.ndarray, beta: np.ndarray, k: int) -> None:
    """``B ← (Π β) B + Φ_wᵀ E`` over the first k staged rows (module docstring), in place."""
    weights = np.ones(k)
    if k > 1:
        weights[:-1] = np.cumprod(beta[1:k][::-1])[::-1]  # row m: Π_{j>m} β_j
    scale = float(weights[0] * beta[0])
    rows = phi[:k]
    if k > 1 and not np.all(weights == 1.0):
        rows = rows * weights[:, None]
    if scale != 1.0:
        B *= scale
    B += rows.T @ entries[:k]


class EntryCrossProducts:
    """``B = Σ_m (Π_{j>m} β_j) φ_m e_mᵀ`` of staged rows, added by blocks of :attr:`ROWS` (module docstring).

    Args:
        n_features: D, the length of φ.
        n_entries: E, the length of e.
        background: Add full blocks on the worker thread (True) or in the caller (False); same bits.
    """

    #: Staged rows added by one matrix product.
    ROWS = 32

    def __init__(self, n_features: int, n_entries: int, *, background: bool = True) -> None:
        self.background = bool(background)
        self._B = np.zeros((int(n_features), int(n_entries)))
        self._buffers = [self._new_buffer(), self._new_buffer()]
        self._current = 0
        self._k = 0
        self._future: Future[None] | None = None

    def _new_buffer(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        D, E = self._B.shape
        return np.empty((self.ROWS, D)), np.empty((self.ROWS, E)), np.empty(self.ROWS)

    @property
    def shape(self) -> tuple[int, int]:
        """(D, E)."""
        return self._B.shape

    def staging(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """Return ``(φ rows, e rows, β, k)``: the buffer the next row goes to (row k), for a compiled stager.

        A full buffer is handed to the worker first. A caller that writes row k itself calls :meth:`staged`
        after it (or :meth:`stage` does both).
        """
        phi, entries, beta = self._buffers[self._current]
        if self._k == self.ROWS:
            self._submit()
            phi, entries, beta = self._buffers[self._current]
        return phi, entries, beta, self._k

    def staged(self) -> None:
        """Count the row written at :meth:`staging`'s k."""
        self._k += 1

    def stage(self, phi: np.ndarray, entries: np.ndarray, beta: float) -> None:
        """Stage one sample's features (D,), entries (E,) and its step's forgetting factor β."""
        buf_phi, buf_entries, buf_beta, k = self.staging()
        buf_phi[k] = phi
        buf_entries[k] = entries
        buf_beta[k] = beta
        self.staged()

    def wait(self) -> None:
        """Wait for the block in flight, if any; its exception is raised here and at every later wait.

        B is not known after a failed block, so it is never read again.
        """
        future = self._future
        if future is not None:
            future.result()
            self._future = None  # cleared once done: a second waiter (under the caller's lock) waits too

    def _submit(self) -> None:
        """Add the current buffer's rows to B (on the worker when in background) and stage into the other."""
        self.wait()  # one block in flight at a time: B and the other buffer are free again
        if self._k == 0:
            return
        phi, entries, beta = self._buffers[self._current]
        if self.background:
            self._future = _worker().submit(_add_block, self._B, phi, entries, beta, self._k)
        else:
            _add_block(self._B, phi, entries, beta, self._k)
        self._current = 1 - self._current
        self._k = 0

    def settled(self) -> np.ndarray:
        """Return B with every staged row added (the object's own array: read it before staging more)."""
        self.wait()
        if self._k:
            phi, entries, beta = self._buffers[self._current]
            _add_block(self._B, phi, entries, beta, self._k)
            self._k = 0
        return self._B

    def with_pending(self) -> np.ndarray:
        """Return a copy of B with the staged rows added, leaving the staging as it is."""
        self.wait()
        out = self._B.copy()
        if self._k:
            phi, entries, beta = self._buffers[self._current]
            _add_block(out, phi, entries, beta, self._k)
        return out

    def reset(self) -> None:
        """Forget everything: B = 0, nothing staged."""
        self.wait()
        self._B[:] = 0.0
        self._k = 0

    def load(self, B: np.ndarray) -> None:
        """Replace B (a copy of a (D, E) array), nothing staged.

        Raises:
            ValueError: B of another shape.
        """
        B = np.asarray(B, dtype=np.float64)
        if B.shape != self._B.shape:
            raise ValueError(f"cross-products of shape {B.shape}, expected {self._B.shape}")
        self.wait()
        self._B = np.ascontiguousarray(B).copy()
        self._k = 0

    def __getstate__(self) -> dict[str, Any]:
        """Wait for the block in flight, then return the state to copy or pickle (a future is not copied)."""
        self.wait()
        return dict(self.__dict__)
