"""Exception types of :mod:`semiparam_ros.io`."""

from __future__ import annotations

__all__ = ["BagError"]


class BagError(ValueError):
    """A bag cannot be read or written as requested.

    Raised for a missing path, a truncated or corrupt MCAP file, a missing topic, a topic that carries
    an unexpected message type, or an output folder that exists already. The message names the path
    and, where relevant, the topic; the underlying library error is chained as ``__cause__``.
    """
