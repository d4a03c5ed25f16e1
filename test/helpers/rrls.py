"""Closed-form ridge references of the recursive least squares: the batch solution of the same rows."""

from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve


def closed_form(steps, b, t, lam, beta=1.0, keep_prior=True):
    """A, B and W = A⁻¹B of the documented scheme, summed directly (independent of the learner)."""
    c = b * (1.0 - beta) * lam if (keep_prior and beta < 1.0) else 0.0
    A = lam * np.eye(b)
    B = np.zeros((b, t))
    for m, (Z, U) in enumerate(steps):
        A = beta * A + Z.T @ Z
        B = beta * B + Z.T @ U
        A[m % b, m % b] += c
    W = cho_solve(cho_factor(A), B)
    return A, B, W


def random_steps(rng, n, k, b, t):
    Z = rng.standard_normal((n * k, b)) * rng.uniform(0.1, 3.0, size=b)
    W_true = rng.standard_normal((b, t))
    U = Z @ W_true + 0.1 * rng.standard_normal((n * k, t))
    return [(Z[i * k:(i + 1) * k], U[i * k:(i + 1) * k]) for i in range(n)]
