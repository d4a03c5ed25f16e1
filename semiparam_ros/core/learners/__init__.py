"""Learners: recursive least squares, random features and the models built on them.

The parametric, nonparametric and semiparametric models, their contract, forgetting and uncertainty.
"""
