"""What every callback of the node shares: ending quietly when shutdown interrupts it."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["quiet_at_shutdown"]

_Callback = TypeVar("_Callback", bound=Callable[..., Any])


def quiet_at_shutdown(method: _Callback) -> _Callback:
    """Let a callback the shutdown interrupted (the context invalidated under a publish) end quietly.

    The decorated method's object has a ``context`` (an rclpy ``Context``); while that context is valid,
    any exception propagates (a programming error ends the process).
    """

    @functools.wraps(method)
    def guarded(self: Any, *args: Any) -> Any:
        try:
            return method(self, *args)
        except Exception:
            if self.context.ok():
                raise
            return None

    return guarded  # type: ignore[return-value]
