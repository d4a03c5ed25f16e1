"""Exception types of semiparam_ros: one root, one subclass per concern.

Callers catch what they mean: :class:`ConfigurationError` for invalid parameters, :class:`RejectedSampleError`
for one bad input sample (the estimator counts it as a drop and goes on), :class:`CheckpointError` for a
checkpoint that cannot be read or does not fit the model, :class:`BagError` for a bag that cannot be read
or written, :class:`ClusterError` for a Dask cluster that cannot run the jobs, :class:`StartupError` and
:class:`DescriptionTimeoutError` for a node that cannot start. The data errors also derive from
:class:`ValueError` (the node's from :class:`RuntimeError`), so code written against the earlier
``ValueError`` contract keeps working. Anything else raised inside the package (``TypeError``,
``IndexError``, a plain ``ValueError`` from NumPy, …) is a programming error and is never counted as a
drop.
"""

from __future__ import annotations

__all__ = [
    "BagError",
    "CheckpointError",
    "ClusterError",
    "ConfigurationError",
    "DescriptionTimeoutError",
    "RejectedSampleError",
    "SemiparamError",
    "StartupError",
]


class SemiparamError(Exception):
    """Root of every exception that semiparam_ros raises on purpose."""


class ConfigurationError(SemiparamError, ValueError):
    """A parameter or a combination of parameters is invalid; the message names the parameter."""


class RejectedSampleError(SemiparamError, ValueError):
    """One input sample (or message) cannot be learned or predicted: wrong shape, NaN/inf, out of range.

    The model's state is unchanged when this is raised.
    """


class CheckpointError(SemiparamError, ValueError):
    """A checkpoint is missing, corrupt, or was written for another model structure or hyperparameters."""


class BagError(SemiparamError, ValueError):
    """A bag cannot be read or written as requested.

    Raised for a missing path, a corrupt MCAP file that yields no message, a missing topic, a topic that
    carries an unexpected message type, or an output folder that exists already. The message names the
    path and, where relevant, the topic; the underlying library error is chained as ``__cause__``.
    """


class ClusterError(SemiparamError, ValueError):
    """A Dask cluster cannot be used, or jobs on it failed.

    Raised for an unreachable scheduler, workers without the package, or failed jobs; the message names the
    scheduler, the workers, or each failed job and the worker it ran on.
    """


class StartupError(SemiparamError, RuntimeError):
    """The node cannot start (invalid parameters, incompatible checkpoint); the message says why."""


class DescriptionTimeoutError(SemiparamError, RuntimeError):
    """No robot description arrived in time, or the context shut down meanwhile."""
