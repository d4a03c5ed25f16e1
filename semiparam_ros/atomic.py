"""Atomic file writes: the one helper every writer of the package uses.

A file is written (with the permissions the process umask gives a new file) to a temporary file in the
destination's directory, flushed and ``fsync``-ed, then moved over the destination with
:func:`os.replace`; the directory is ``fsync``-ed too where the platform allows, so a reader (or a crash,
or a power cut after the call returned) sees either the old file or the new one, never half of one. On
any exception the temporary file is removed and the destination is left as it was.

>>> import tempfile, pathlib
>>> out = pathlib.Path(tempfile.mkdtemp()) / "sub" / "hello.txt"
>>> atomic_write_text(out, "hi")
>>> out.read_text()
'hi'
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import IO, Any

__all__ = ["atomic_open", "atomic_savefig", "atomic_write_bytes", "atomic_write_text",
           "remove_stale_temporaries"]


def atomic_open(path: str | os.PathLike[str], mode: str = "w") -> AbstractContextManager[IO[Any]]:
    """Open ``path`` for an atomic write (a context manager yielding the open file).

    Args:
        path: Destination file; parent directories are created.
        mode: ``"w"`` (text, UTF-8) or ``"wb"`` (binary).

    Returns:
        A context manager; the destination is replaced when the ``with`` block exits without an exception.

    Raises:
        ValueError: If ``mode`` is not ``"w"`` or ``"wb"``.
        OSError: If the file cannot be written (the destination is then unchanged).
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open mode must be 'w' or 'wb', got {mode!r}")
    return _atomic(Path(path), mode)


@contextmanager
def _atomic(path: Path, mode: str) -> Iterator[IO[Any]]:
    path.parent.mkdir(parents=True, exist_ok=True)
    # Not mkstemp: its 0600 would make every written file private; O_EXCL with a random name is as safe
    # and lets the process umask decide, as for any file the user writes.
    tmp_name = str(path.parent / f".{path.name}.{secrets.token_hex(8)}.tmp")
    fd = os.open(tmp_name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        fh: IO[Any] = os.fdopen(fd, mode, encoding="utf-8") if mode == "w" else os.fdopen(fd, mode)
        with fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp_name, path)
    except BaseException:
        try:
            os.unlink(tmp_name)
        except FileNotFoundError:
            pass
        raise
    _fsync_dir(path.parent)


def remove_stale_temporaries(path: str | os.PathLike[str]) -> list[Path]:
    """Delete the temporary files that interrupted atomic writes of ``path`` left behind.

    A process killed between creating ``.<name>.<random>.tmp`` and renaming it (SIGKILL, power loss)
    leaves the temporary file; the destination itself is intact. Call at start-up, before writing.

    Args:
        path: The destination whose temporaries to remove.

    Returns:
        The files removed.
    """
    path = Path(path)
    removed = []
    for stale in path.parent.glob(f".{path.name}.*.tmp"):
        if len(stale.name) == len(path.name) + 22:  # ".", name, ".", 16 hex digits, ".tmp"
            try:
                stale.unlink()
                removed.append(stale)
            except OSError:  # gone meanwhile, or not ours to delete: leave it
                pass
    return removed


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see the module docstring).

    Raises:
        OSError: If the file cannot be written (the destination is then unchanged).
    """
    with atomic_open(path, "wb") as fh:
        fh.write(data)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (see the module docstring).

    Raises:
        OSError: If the file cannot be written (the destination is then unchanged).
    """
    with atomic_open(path, "w") as fh:
        fh.write(text)


def atomic_savefig(fig: Any, path: str | os.PathLike[str], *, dpi: int = 100, fmt: str | None = None) -> Path:
    """Write a matplotlib figure to ``path`` atomically (format: ``fmt``, else the suffix's).

    The parent folder is created. The figure is not closed (the caller owns it).

    Args:
        fig: A ``matplotlib.figure.Figure`` (anything with ``savefig(file, dpi=, format=)``).
        path: Destination.
        dpi: Resolution [dots per inch].
        fmt: Image format (``None``: the suffix's, PNG without one).

    Returns:
        The destination.

    Raises:
        OSError: If the file cannot be written (the destination is then unchanged).
    """
    dest = Path(path)
    dest.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(dest, "wb") as fh:
        fig.savefig(fh, dpi=dpi, format=fmt or dest.suffix.lstrip(".").lower() or "png")
    return dest


def _fsync_dir(directory: Path) -> None:
    """Make a rename in ``directory`` durable; skipped where directories cannot be opened."""
    try:
        dir_fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dir_fd)
    except OSError:
        pass
    finally:
        os.close(dir_fd)
