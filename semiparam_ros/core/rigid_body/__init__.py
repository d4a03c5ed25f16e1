"""Rigid-body dynamics: URDF, the Pinocchio regressor, consistent identification and the payload."""

__all__ = [
    "dynamics",
    "excitation",
    "identification",
    "payload",
    "urdf",
]
