"""Learners: recursive least squares, random features and the models built on them.

The parametric, nonparametric and semiparametric models, their contract, forgetting and uncertainty.
"""

__all__ = [
    "adaptation",
    "base",
    "cascade",
    "consistent",
    "contract",
    "cross_products",
    "features",
    "joint",
    "nonparametric",
    "parametric",
    "rrls",
    "two_stage",
    "uncertainty",
]
