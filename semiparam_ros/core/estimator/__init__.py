"""The online estimator: building it from a configuration, streaming samples, the checkpoint format."""

__all__ = [
    "build",
    "online",
    "state",
]
