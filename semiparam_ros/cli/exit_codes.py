"""The exit-code policy shared by the command-line tools."""

from __future__ import annotations

import sys

__all__ = ["error_exit"]


def error_exit(prog: str, err: ValueError | OSError) -> int:
    """Print ``<prog>: error: <message>`` on stderr (no traceback) and return the exit status.

    Args:
        prog: Name of the command.
        err: A ``ValueError`` (invalid input: arguments, configuration, bag contents) or an ``OSError``
            (a file or folder that cannot be read or written).

    Returns:
        2 for invalid input, 1 for an I/O failure.
    """
    print(f"{prog}: error: {err}", file=sys.stderr)
    return 2 if isinstance(err, ValueError) else 1
