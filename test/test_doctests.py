"""Run the ``>>>`` examples of the public core classes and of the shared helpers (they are documentation
that must stay true)."""

from __future__ import annotations

import doctest
import importlib

import numpy as np
import pytest

MODULES = [
    "semiparam_ros.atomic",
    "semiparam_ros.core.estimator.online",
    "semiparam_ros.serving.feedforward",
    "semiparam_ros.core.learners.features",
    "semiparam_ros.core.stream.pipeline",
    "semiparam_ros.core.stream.rate",
    "semiparam_ros.core.learners.rrls",
    "semiparam_ros.core.learners.base",
    "semiparam_ros.core.learners.cascade",
    "semiparam_ros.core.learners.parametric",
    "semiparam_ros.core.learners.nonparametric",
    "semiparam_ros.core.estimator.build",
    "semiparam_ros.core.kinds",
    "semiparam_ros.serving.assembly",
    "semiparam_ros.core.learners.consistent",
    "semiparam_ros.serving.learned_model",
    "semiparam_ros.core.learners.joint",
    "semiparam_ros.core.validation",
    "semiparam_ros.eval.protocol.horizon",
]


@pytest.mark.parametrize("name", MODULES)
def test_examples_run(name):
    module = importlib.import_module(name)
    with np.printoptions(legacy=False):
        result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
                                 raise_on_error=False, verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed in {name}"
    assert result.attempted > 0, f"no examples in {name}"
