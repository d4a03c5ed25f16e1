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

import numpy as np

from semiparam_ros.core.rrls import RecursiveRLS
from semiparam_ros.errors import ConfigurationError

__all__ = ["PeriodEstimator", "forgetting_factor", "learners"]


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


class PeriodEstimator:
    """Median stamp step of the first ``n_samples`` samples.

    Args:
        n_samples: Samples to observe (≥ 2): the median is over ``n_samples − 1`` steps.

    Attributes:
        period_s: The measured period [s], or None until ``n_samples`` samples with increasing stamps
            were seen.
    """

    def __init__(self, n_samples: int) -> None:
        if isinstance(n_samples, bool) or not isinstance(n_samples, int | np.integer) or n_samples < 2:
            raise ConfigurationError(f"n_samples must be an integer >= 2, got {n_samples!r}")
        self.n_samples = int(n_samples)
        self.reset()

    def reset(self) -> None:
        """Forget the observed stamps."""
        self._steps: list[int] = []
        self._last: int | None = None
        self.period_s: float | None = None

    def add(self, stamp_ns: int) -> float | None:
        """Observe one sample stamp [ns]; return the period [s] once it is measured, else None.

        Steps that are not positive (a repeated or backward stamp) are not counted.
        """
        if self.period_s is not None:
            return self.period_s
        if self._last is not None and stamp_ns > self._last:
            self._steps.append(stamp_ns - self._last)
        self._last = stamp_ns
        if len(self._steps) >= self.n_samples - 1:
            self.period_s = float(np.median(self._steps)) * 1e-9
            self._steps = []
        return self.period_s


def learners(model: object) -> Iterator[RecursiveRLS]:
    """Iterate over the recursive least-squares learners of a model (P, NP, or either SP combination).

    Args:
        model: A learner of :mod:`semiparam_ros.core.semiparametric` or
            :mod:`semiparam_ros.core.semiparametric_joint`.

    Yields:
        Each :class:`RecursiveRLS` of the model, parametric stage first.
    """
    for stage in (model, getattr(model, "parametric", None), getattr(model, "nonparametric", None)):
        rls = getattr(stage, "rls", None)
        if isinstance(rls, RecursiveRLS):
            yield rls
