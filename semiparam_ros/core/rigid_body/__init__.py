"""Rigid-body dynamics: URDF, the Pinocchio regressor, consistent identification and the payload."""
