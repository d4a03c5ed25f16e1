"""Forgetting expressed as a memory time in seconds, converted at the measured sample rate.

A forgetting factor β per sample gives old data the weight ``β^n`` after n samples, i.e. a memory of
``τ = −T / ln β`` seconds at the sample period T: the same β means 10 s at 100 Hz and 5 s at 200 Hz. The
estimator is therefore configured with the time constant τ (``adaptation.time_constant``) and converts it
with the period measured on the stream itself:

    β = exp(−T / τ),

which weights a sample of age a seconds by ``exp(−a / τ)`` whatever the rate. The period is the median of
the stamp steps of the first few paired samples (robust to a dropout or a duplicated stamp); until it is
known the learners run with the configured per-sample factors (``parametric.forgetting``,
``nonparametric.forgetting``; the shipped configuration sets them to the same τ at the iCub's 100 Hz, so
tools that never see stamps, e.g. the paper's protocol on arrays, still adapt).
"""

from __future__ import annotations

import math
from collections.abc import Iterator

from semiparam_ros.core.learners.contract import Learner
from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.errors import ConfigurationError

__all__ = ["forgetting_factor", "learners"]


def forgetting_factor(time_constant_s: float, period_s: float) -> float:
    """Return the per-sample forgetting factor of a memory time constant.

    Args:
        time_constant_s: τ > 0, the memory [s] (data of age τ weigh e⁻¹).
        period_s: T > 0, the sample period [s].

    Returns:
        β = exp(−T/τ) in (0, 1).

    Raises:
        ConfigurationError: If τ or T is not a finite number > 0.
    """
    tau, period = float(time_constant_s), float(period_s)
    if not (math.isfinite(tau) and tau > 0.0):
        raise ConfigurationError(f"time constant must be a finite number > 0 s, got {time_constant_s!r}")
    if not (math.isfinite(period) and period > 0.0):
        raise ConfigurationError(f"sample period must be a finite number > 0 s, got {period_s!r}")
    return math.exp(-period / tau)


def learners(model: Learner) -> Iterator[RecursiveRLS]:
    """Iterate over the learners of a model whose forgetting the memory time sets.

    Args:
        model: A :class:`~semiparam_ros.core.learners.contract.Learner` (P, NP, or any SP combination).

    Yields:
        Each :class:`RecursiveRLS` of :meth:`~semiparam_ros.core.learners.contract.Learner.adaptive_stages`,
        parametric stage first.
    """
    yield from model.adaptive_stages()
