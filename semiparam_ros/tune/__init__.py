"""Hyperparameter selection: hold-out and protocol grids, selection by held-out motion, fleets."""

__all__ = [
    "fleet",
    "held_out",
    "selection",
    "tuning",
]
