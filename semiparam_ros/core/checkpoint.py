"""Atomic ``.npz`` checkpoints.

A checkpoint is one NumPy ``.npz`` archive mapping names to arrays. Writes are atomic: the archive is
written to a temporary file in the destination directory, flushed and ``fsync``-ed, then moved over the
destination with :func:`os.replace`, so a reader (or a crash) never sees a half-written file. The parent
directory is fsync-ed too (where the platform allows) so the rename itself is durable.

Arrays are stored uncompressed and without pickling: loading never executes code from the file.
"""

from __future__ import annotations

import os
import tempfile
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

__all__ = ["atomic_save_npz", "load_npz"]


def atomic_save_npz(path: str | os.PathLike[str], arrays: Mapping[str, np.ndarray]) -> None:
    """Write ``arrays`` to one ``.npz`` file atomically (temp file in the same directory + rename).

    Args:
        path: Destination file. Parent directories are created. The name is used as given (NumPy's habit
            of appending ``.npz`` does not apply).
        arrays: Name → array. Names must be non-empty strings; values are converted with
            :func:`numpy.asarray` and must not be object arrays.

    Raises:
        ValueError: If a name is not a non-empty string or a value is an object array.
        OSError: If the file cannot be written (the destination is then left as it was).
    """
    path = Path(path)
    converted: dict[str, np.ndarray] = {}
    for name, value in arrays.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"checkpoint array names must be non-empty strings, got {name!r}")
        arr = np.asarray(value)
        if arr.dtype == object:
            raise ValueError(f"checkpoint array {name!r} has dtype object, which cannot be saved safely")
        converted[name] = arr
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **converted)
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


def _fsync_dir(directory: Path) -> None:
    """Make a rename in ``directory`` durable; silently skipped where directories cannot be opened."""
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


def load_npz(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Read every array of an ``.npz`` checkpoint into memory.

    Args:
        path: A file written by :func:`atomic_save_npz` (or ``numpy.savez``).

    Returns:
        Name → array (fully loaded; the file is closed on return).

    Raises:
        ValueError: If the file does not exist, is not a valid ``.npz`` archive, is truncated or corrupt,
            or contains pickled objects.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"checkpoint {str(path)!r} does not exist or is not a file")
    try:
        data = np.load(path, allow_pickle=False)
    except ValueError as err:
        raise ValueError(f"checkpoint {str(path)!r} is corrupt or not a plain .npz archive: {err}") from err
    except (OSError, EOFError, zipfile.BadZipFile) as err:
        raise ValueError(f"checkpoint {str(path)!r} is corrupt or unreadable: {err}") from err
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError(f"checkpoint {str(path)!r} is a single .npy array, not an .npz archive")
    try:
        with data:
            return {name: np.array(data[name]) for name in data.files}
    except ValueError as err:
        raise ValueError(f"checkpoint {str(path)!r} is corrupt or not a plain .npz archive: {err}") from err
    except (OSError, EOFError, zipfile.BadZipFile, KeyError) as err:
        raise ValueError(f"checkpoint {str(path)!r} is corrupt or unreadable: {err}") from err
