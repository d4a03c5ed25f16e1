"""Atomic ``.npz`` checkpoints.

A checkpoint is one NumPy ``.npz`` archive mapping names to arrays. Writes are atomic
(:func:`semiparam_ros.atomic.atomic_open`): a reader, or a crash, sees the old file or the new one, never
half of one.

Arrays are stored uncompressed and without pickling: loading never executes code from the file.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from semiparam_ros.atomic import atomic_open
from semiparam_ros.errors import CheckpointError

__all__ = ["atomic_save_npz", "load_npz"]


def atomic_save_npz(path: str | os.PathLike[str], arrays: Mapping[str, np.ndarray]) -> None:
    """Write ``arrays`` to one ``.npz`` file atomically (temp file in the same directory + rename).

    Args:
        path: Destination file. Parent directories are created. The name is used as given (NumPy's habit
            of appending ``.npz`` does not apply).
        arrays: Name → array. Names must be non-empty strings; values are converted with
            :func:`numpy.asarray` and must not be object arrays.

    Raises:
        CheckpointError: If a name is not a non-empty string or a value is an object array.
        OSError: If the file cannot be written (the destination is then left as it was).
    """
    path = Path(path)
    converted: dict[str, np.ndarray] = {}
    for name, value in arrays.items():
        if not isinstance(name, str) or not name:
            raise CheckpointError(f"checkpoint array names must be non-empty strings, got {name!r}")
        arr = np.asarray(value)
        if arr.dtype == object:
            raise CheckpointError(f"checkpoint array {name!r} has dtype object, which cannot be saved safely")
        converted[name] = arr
    with atomic_open(path, "wb") as fh:
        np.savez(fh, **converted)  # type: ignore[arg-type]  # numpy's stub reads ** as allow_pickle


#: The first bytes of files a user may hand over instead of a checkpoint, and what they are.
_MAGIC = ((b"\x89MCAP", "an MCAP bag (learn it with `learn`)"),
          (b"SQLite format 3", "a SQLite (.db3) bag (learn it with `learn`)"),
          (b"\x93NUMPY", "a single .npy array"))


def _other_kind_of_file(path: Path) -> str | None:
    """Name what a file is when it is plainly no zip archive (None: a zip, or unrecognised)."""
    with path.open("rb") as fh:
        head = fh.read(512)
    if not head:
        return "empty"
    if head.startswith(b"PK"):
        return None
    for magic, what in _MAGIC:
        if head.startswith(magic):
            return what
    text = head.decode("utf-8", errors="replace").lstrip()
    if "ros__parameters" in text or path.suffix in (".yaml", ".yml"):
        return "a YAML file (a parameter file goes to `learn --config` or the node's --params-file)"
    if text.startswith("<?xml") or "<robot" in text:
        return "an XML/URDF file (robot.urdf in the parameter file names it)"
    if text.startswith(("{", "[")):
        return "a JSON file"
    return None


def load_npz(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Read every array of an ``.npz`` checkpoint into memory.

    Args:
        path: A file written by :func:`atomic_save_npz` (or ``numpy.savez``).

    Returns:
        Name → array (fully loaded; the file is closed on return).

    Raises:
        CheckpointError: If the file does not exist, is not a valid ``.npz`` archive, is truncated or corrupt,
            or contains pickled objects.
    """
    path = Path(path)
    if path.is_dir():
        what = " (a bag folder: learn it with `learn`)" if any(path.glob("*.mcap")) or any(
            path.glob("*.db3")) else ""
        raise CheckpointError(f"checkpoint {str(path)!r} is a folder{what}, not a .npz checkpoint")
    if not path.is_file():
        raise CheckpointError(f"checkpoint {str(path)!r} does not exist or is not a file")
    other = _other_kind_of_file(path)
    if other is not None:
        raise CheckpointError(f"checkpoint {str(path)!r} is {other}, not a .npz checkpoint (written by "
                              "`learn --checkpoint`, the node's ~/save or OnlineEstimator.save)")
    try:
        data = np.load(path, allow_pickle=False)
    except ValueError as err:
        raise CheckpointError(f"checkpoint {str(path)!r} is corrupt or not a plain .npz archive: "
                              f"{err}") from err
    except (OSError, EOFError, zipfile.BadZipFile) as err:
        raise CheckpointError(f"checkpoint {str(path)!r} is corrupt or unreadable: {err}") from err
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise CheckpointError(f"checkpoint {str(path)!r} is a single .npy array, not an .npz archive")
    try:
        with data:
            return {name: np.array(data[name]) for name in data.files}
    except ValueError as err:
        raise CheckpointError(f"checkpoint {str(path)!r} is corrupt or not a plain .npz archive: "
                              f"{err}") from err
    except (OSError, EOFError, zipfile.BadZipFile, KeyError) as err:
        raise CheckpointError(f"checkpoint {str(path)!r} is corrupt or unreadable: {err}") from err
