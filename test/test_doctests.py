"""Run the ``>>>`` examples of the public core classes and of the shared helpers (they are documentation
that must stay true)."""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import numpy as np
import pytest

import semiparam_ros

#: Modules whose examples need more than a test process can give them (a Dask cluster spawning workers).
NOT_RUN = {"semiparam_ros.jobs.cluster"}


def _modules_with_examples() -> list[str]:
    """Every module of the package whose source holds a ``>>>`` example (rclpy ones included)."""
    root = Path(semiparam_ros.__file__).parent
    names = []
    for path in sorted(root.rglob("*.py")):
        if ">>>" in path.read_text(encoding="utf-8"):
            parts = path.relative_to(root.parent).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            if name not in NOT_RUN:
                names.append(name)
    return names


MODULES = _modules_with_examples()


def test_every_module_with_examples_is_run():
    """The discovery finds the modules (a broken walk would run nothing and pass)."""
    assert len(MODULES) >= 40
    assert "semiparam_ros.core.config" in MODULES and "semiparam_ros.serving.feedforward" in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_examples_run(name):
    module = importlib.import_module(name)
    with np.printoptions(legacy=False):
        result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
                                 raise_on_error=False, verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed in {name}"
    assert result.attempted > 0, f"no examples in {name}"
