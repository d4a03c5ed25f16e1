"""Hyperparameter selection: hold-out and protocol grids, selection by held-out motion, fleets."""
