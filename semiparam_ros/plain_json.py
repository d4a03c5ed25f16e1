"""Reports as JSON: plain Python types out of records, arrays and paths; written atomically.

>>> import numpy as np
>>> to_plain({"rmse": np.float64(0.5), "curve": np.array([1.0, np.nan])})
{'rmse': 0.5, 'curve': [1.0, None]}
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from semiparam_ros.atomic import atomic_write_text

__all__ = ["to_plain", "write_json"]

_SCALAR_LIST = re.compile(r"\[((?:\s*[^\[\]{}\s][^\[\]{}]*?)?)\s*\]")


def to_plain(value: Any) -> Any:
    """Convert a report (or any nesting of mappings, sequences, arrays) to JSON-ready Python types.

    Records with ``to_json`` are converted through it; non-finite floats become ``None``.
    """
    if hasattr(value, "to_json"):
        return to_plain(value.to_json())
    if isinstance(value, Mapping):
        return {str(k): to_plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_plain(value.tolist())
    if isinstance(value, np.generic):
        return to_plain(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def write_json(report: Any, path: str | Path) -> None:
    """Write a report (a record with ``to_json`` or a mapping) as JSON, atomically.

    Non-finite floats are written as ``null`` (JSON has no NaN); lists of scalars stay on one line.

    Args:
        report: The report.
        path: Destination file (parent directories are created).

    Raises:
        OSError: If the file cannot be written (it is then unchanged).
    """
    text = json.dumps(to_plain(report), indent=1)
    text = _SCALAR_LIST.sub(lambda m: "[" + re.sub(r"\s*\n\s*", " ", m.group(1)).strip() + "]", text)
    atomic_write_text(path, text + "\n")
