"""The cross-products kept beside the consistent residual, added by blocks on a worker thread.

Checked against the sum they stand for, computed independently in one pass (``Σ_m β^{n−m} φ_m e_mᵀ``), and
against themselves without the worker (the same operations: the same bits).
"""

from __future__ import annotations

import copy
import multiprocessing
import pickle

import numpy as np
import pytest

from semiparam_ros.core.learners import cross_products
from semiparam_ros.core.learners.cross_products import EntryCrossProducts


def _stream(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    beta = np.where(rng.random(n) < 0.5, 0.995, 1.0)  # a forgetting factor that changes between steps
    return rng.standard_normal((n, 40)), rng.standard_normal((n, 9)), beta


def _direct(phi: np.ndarray, e: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """Σ_m (Π_{j>m} β_j) φ_m e_mᵀ, one weight per row."""
    w = np.append(np.cumprod(beta[:0:-1])[::-1], 1.0)
    return (phi * w[:, None]).T @ e


@pytest.mark.parametrize("n", [1, 31, 32, 33, 64, 100, 257])
def test_blocks_on_the_worker_equal_the_sum_and_the_caller_s_blocks_bit_for_bit(n):
    phi, e, beta = _stream(n)
    worker, caller = EntryCrossProducts(40, 9), EntryCrossProducts(40, 9, background=False)
    for m in range(n):
        worker.stage(phi[m], e[m], beta[m])
        caller.stage(phi[m], e[m], beta[m])
        if m % 45 == 44:  # a read in the middle of a block leaves the staging as it was
            np.testing.assert_array_equal(worker.with_pending(), caller.with_pending())
    expected = _direct(phi, e, beta)
    bound = 1e-12 * np.abs(phi).max() * np.abs(e).max() * n  # n products of O(1) values, summed
    np.testing.assert_allclose(worker.with_pending(), expected, rtol=0, atol=bound)
    np.testing.assert_array_equal(worker.with_pending(), caller.with_pending())
    np.testing.assert_array_equal(worker.settled(), caller.settled())


def test_a_copy_or_pickle_with_a_block_in_flight_carries_it():
    phi, e, beta = _stream(70, seed=1)
    cp = EntryCrossProducts(40, 9)
    for m in range(33):  # the 33rd row sends the first 32 to the worker
        cp.stage(phi[m], e[m], beta[m])
    copied, pickled = copy.deepcopy(cp), pickle.loads(pickle.dumps(cp))
    for other in (cp, copied, pickled):
        for m in range(33, 70):
            other.stage(phi[m], e[m], beta[m])
    for other in (copied, pickled):
        np.testing.assert_array_equal(other.settled(), cp.settled())


def test_an_error_on_the_worker_is_raised_in_the_caller(monkeypatch):
    cp = EntryCrossProducts(40, 9)
    phi, e, beta = _stream(33, seed=2)

    def broken(*args):
        raise RuntimeError("a programming error in the block")

    monkeypatch.setattr(cross_products, "_add_block", broken)
    for m in range(33):
        cp.stage(phi[m], e[m], beta[m])
    with pytest.raises(RuntimeError, match="programming error"):
        cp.settled()
    with pytest.raises(RuntimeError, match="programming error"):  # B is not known after it: every read fails
        pickle.dumps(cp)


def test_reset_and_load():
    phi, e, beta = _stream(40, seed=3)
    cp = EntryCrossProducts(40, 9)
    for m in range(40):
        cp.stage(phi[m], e[m], beta[m])
    cp.reset()
    np.testing.assert_array_equal(cp.settled(), 0.0)
    B = _direct(phi, e, beta)
    cp.load(B)
    np.testing.assert_array_equal(cp.settled(), B)
    with pytest.raises(ValueError, match="shape"):
        cp.load(B[:, :-1])


def _child(queue) -> None:  # pragma: no cover - runs in the forked process
    phi, e, beta = _stream(100, seed=4)
    cp = EntryCrossProducts(40, 9)
    for m in range(100):
        cp.stage(phi[m], e[m], beta[m])
    queue.put(cp.settled())


def test_a_forked_process_gets_its_own_worker():
    """A process forked after the worker thread started has no thread: it starts its own (no hang)."""
    phi, e, beta = _stream(100, seed=4)
    cp = EntryCrossProducts(40, 9)
    for m in range(100):
        cp.stage(phi[m], e[m], beta[m])
    expected = cp.settled()  # the parent's worker has run
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    proc = ctx.Process(target=_child, args=(queue,))
    proc.start()
    got = queue.get(timeout=60)
    proc.join(timeout=60)
    assert proc.exitcode == 0
    np.testing.assert_array_equal(got, expected)
