"""Pure-numpy reference of the QR-RLS Givens update (tests and benchmarks only).

Written differently from the compiled kernel on purpose: the forgetting scale is applied as a separate
multiplication, rows are rotated in one at a time (row order instead of column order), and the a-priori
prediction of a block is computed by a triangular solve before the update, except for single rows, where
it uses the textbook QR-RLS identity ``e_apriori = ε / Π cos θ_i``.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

__all__ = ["ReferenceQRRLS", "givens_row_update"]


def givens_row_update(M: np.ndarray, w: np.ndarray) -> float:
    """Rotate one row ``w = [z | u]`` into ``M = [R | d]`` in place; return the product of the cosines.

    On return ``w[:b]`` is zero and ``w[b:]`` holds the angle-normalised error ``ε``.
    """
    b = M.shape[0]
    gamma = 1.0
    for i in range(b):
        wi = w[i]
        if wi == 0.0:
            continue
        a = M[i, i]
        r = np.hypot(a, wi)
        c, s = a / r, wi / r
        gamma *= c
        Mi = M[i, i:].copy()
        wv = w[i:].copy()
        M[i, i:] = c * Mi + s * wv
        w[i:] = c * wv - s * Mi
        M[i, i] = r
        w[i] = 0.0
    return gamma


class ReferenceQRRLS:
    """Same state and the same forgetting-with-prior scheme as ``RecursiveRLS``, in plain numpy loops."""

    def __init__(self, n_features: int, n_outputs: int, lam: float = 1.0, forgetting: float = 1.0,
                 keep_prior: bool = True) -> None:
        self.b, self.t = n_features, n_outputs
        self.lam, self.beta, self.keep_prior = lam, forgetting, keep_prior
        self.M = np.zeros((n_features, n_features + n_outputs))
        self.M[:, :n_features] = np.sqrt(lam) * np.eye(n_features)
        self.j = 0

    @property
    def R(self) -> np.ndarray:  # noqa: N802
        return self.M[:, : self.b]

    @property
    def weights(self) -> np.ndarray:
        return solve_triangular(self.R, self.M[:, self.b :], lower=False)

    def predict(self, Z: np.ndarray) -> np.ndarray:
        return np.atleast_2d(Z) @ self.weights

    def predict_update(self, Z: np.ndarray, U: np.ndarray) -> np.ndarray:
        """One time step with the rows of Z; returns the a-priori predictions (k, t)."""
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        U = np.atleast_2d(np.asarray(U, dtype=float))
        k = Z.shape[0]
        if k > 1:
            pred = self.predict(Z)
        if self.beta != 1.0:
            self.M *= np.sqrt(self.beta)
        out = np.empty((k, self.t))
        for r in range(k):
            w = np.concatenate([Z[r], U[r]])
            gamma = givens_row_update(self.M, w)
            if k == 1:
                out[0] = U[0] - w[self.b :] / gamma
        if k > 1:
            out = pred
        reg = self.b * (1.0 - self.beta) * self.lam if self.keep_prior else 0.0
        if reg > 0.0:
            w = np.zeros(self.b + self.t)
            w[self.j] = np.sqrt(reg)
            givens_row_update(self.M, w)
        self.j = (self.j + 1) % self.b
        return out

    def update(self, Z: np.ndarray, U: np.ndarray) -> None:
        self.predict_update(Z, U)


def forward_predict(M: np.ndarray, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(Z R⁻¹ d, ‖R⁻ᵀ Zᵀ‖² per row)`` for ``M = [R | d]``, by the textbook dot-product substitution.

    Solves ``Rᵀ v = zᵀ`` one unknown at a time, ``v_i = (z_i − R[:i, i]·v[:i]) / R_ii`` (reading ``R`` by
    columns), where the compiled kernel subtracts each finished ``v_i R[i, i+1:]`` from the remaining
    right-hand side (reading ``R`` by rows, several rows at once).
    """
    b = M.shape[0]
    R, d = M[:, :b], M[:, b:]
    Z = np.atleast_2d(Z)
    V = np.zeros((Z.shape[0], b))
    for r in range(Z.shape[0]):
        for i in range(b):
            V[r, i] = (Z[r, i] - R[:i, i] @ V[r, :i]) / R[i, i]
    return V @ d, np.einsum("ij,ij->i", V, V)
