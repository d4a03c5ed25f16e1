"""One owner of the sample rate: the node and offline replay measure the same period from the same stamps
and convert seconds to the same sample counts and forgetting factors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import REPO

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.learners.adaptation import learners
from semiparam_ros.core.stream.acceleration import (
    AccelerationConfig,
    RateAdaptiveEstimator,
    samples_for_window,
)
from semiparam_ros.core.stream.messages import Sample
from semiparam_ros.core.stream.rate import RATE_SAMPLES, RateMeter, measured_period_s, samples_in
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.bags.replay import build_models
from semiparam_ros.eval.protocol.prequential import SampleArrays

ROOT = REPO
T0_NS = 1_763_800_000 * 10**9


def jittered_stamps(rate_hz: float, n: int, seed: int, repeat: bool = True) -> np.ndarray:
    """Stamps at a rate with ±20 % jitter, a repeated stamp (if asked) and a dropout among the first ones."""
    rng = np.random.default_rng(seed)
    period = 1e9 / rate_hz
    dt = period * (1.0 + rng.uniform(-0.2, 0.2, n - 1))
    if repeat:
        dt[2] = 0.0       # a repeated stamp
    dt[5] = 50 * period   # a dropout
    return T0_NS + np.concatenate([[0], np.cumsum(np.round(dt))]).astype(np.int64)


def independent_period(stamps: np.ndarray, max_gap_s: float | None = None) -> float:
    """The documented rule written out: the median of the positive intervals of the first stamps."""
    dts = np.diff(stamps[:RATE_SAMPLES]).astype(np.float64) * 1e-9
    dts = dts[dts > 0]
    if max_gap_s is not None:
        dts = dts[dts <= max_gap_s]
    return float(np.median(dts))


@pytest.mark.parametrize("rate_hz,seed", [(100.0, 0), (200.0, 1), (1000.0, 2)])
def test_online_and_offline_give_the_same_beta_warm_up_and_windows(rate_hz, seed):
    cfg = load_config(ROOT / "config" / "ur5.yaml").with_overrides({"nonparametric.n_features": 16})
    stamps = jittered_stamps(rate_hz, 40, seed)
    period = independent_period(stamps)
    # offline: replay's measurement of the stream and the models it builds
    assert measured_period_s(stamps) == period
    offline = build_models(cfg, ["SP"], sample_period_s=measured_period_s(stamps))["SP"]
    # online: the node's estimator, one sample at a time
    est = OnlineEstimator(cfg, kind="SP")
    rng = np.random.default_rng(seed)
    for s in stamps[:RATE_SAMPLES]:
        est.step(Sample(int(s), rng.uniform(-1, 1, 6), rng.normal(0, 1, 6), rng.normal(0, 3, 6),
                        rng.normal(0, 5, 6)))
    assert est.sample_period_s == period
    beta = math.exp(-period / cfg["adaptation.time_constant"])
    assert est.forgetting == beta
    assert [r.forgetting for r in learners(est.model)] == [beta, beta]
    assert [r.forgetting for r in learners(offline)] == [beta, beta]
    warm = samples_in(cfg["nonparametric.standardizer_warmup_s"], period)
    assert est.model.nonparametric.standardizer.warmup == warm == offline.nonparametric.standardizer.warmup
    # the evaluation's windows use the same period (a recorded stream has strictly increasing stamps)
    clean = jittered_stamps(rate_hz, 40, seed, repeat=False)
    arrays = SampleArrays(clean, np.zeros((len(clean), 18)), np.zeros((len(clean), 6)))
    assert arrays.sample_period_s == independent_period(clean)


@pytest.mark.parametrize("rate_hz", [100.0, 1000.0])
def test_acceleration_window_uses_the_same_rule_with_the_dropout_bound(rate_hz):
    stamps = jittered_stamps(rate_hz, 40, 3, repeat=False)  # the pipeline drops repeated joint states
    cfg = AccelerationConfig(method="savgol", window_s=0.08, max_gap_s=0.1)
    est = RateAdaptiveEstimator(2, cfg)
    for s in stamps[:RATE_SAMPLES]:
        est.update(int(s), np.zeros(2))
    period = independent_period(stamps, 0.1)
    assert measured_period_s(stamps, 0.1) == period
    assert est._inner is not None
    assert est._inner.config.window == samples_for_window(0.08, period, "savgol", 2)


def test_rate_meter_starts_again_when_no_interval_is_usable():
    meter = RateMeter(max_gap_s=0.01)
    for k in range(RATE_SAMPLES):  # one stamp every second: every interval is a dropout
        assert meter.add(k * 10**9) is None
    base = RATE_SAMPLES * 10**9
    periods = [meter.add(base + k * 10**6) for k in range(RATE_SAMPLES)]
    assert periods[-1] == pytest.approx(1e-3) and meter.period_s == periods[-1]


@pytest.mark.parametrize("bad", [(0.0, 0.01), (1.0, 0.0), (math.nan, 0.01), (1.0, math.inf), ("2", None)])
def test_samples_in_refuses_what_is_not_a_positive_duration_and_period(bad):
    with pytest.raises(ConfigurationError):
        samples_in(*bad)
