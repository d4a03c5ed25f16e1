"""Warm-up and diagnostics window in seconds, converted at the measured sample rate."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import REPO

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.build import rmse_window_samples, standardizer_warmup_samples
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.estimator.state import fingerprint as fingerprint_of
from semiparam_ros.core.learners.features import Standardizer
from semiparam_ros.core.stream.messages import Sample
from semiparam_ros.core.stream.rate import measured_period_s, samples_in
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.bags.replay import build_models

ROOT = REPO
T0_NS = 1_763_800_000 * 10**9


def ur5(**overrides):
    return load_config(ROOT / "config" / "ur5.yaml").with_overrides(
        {"nonparametric.n_features": 16, **overrides})


def test_defaults_equal_the_former_sample_counts_at_100_hz_and_scale_with_the_rate():
    """2 s and 3 s are the former 200 and 300 samples at 100 Hz; at 1 kHz they are 2000 and 3000; an
    explicit sample count (the old keys) still wins."""
    cfg = ur5()
    assert cfg["nonparametric.standardizer_warmup"] == 0 and cfg["diagnostics.rmse_window"] == 0
    assert (standardizer_warmup_samples(cfg, 0.01), rmse_window_samples(cfg, 0.01)) == (200, 300)
    assert (standardizer_warmup_samples(cfg, 0.001), rmse_window_samples(cfg, 0.001)) == (2000, 3000)
    assert standardizer_warmup_samples(cfg) == 200  # provisional: 100 Hz until measured
    old = ur5(**{"nonparametric.standardizer_warmup": 50, "diagnostics.rmse_window": 70})
    assert (standardizer_warmup_samples(old, 0.001), rmse_window_samples(old, 0.001)) == (50, 70)
    assert samples_in(0.004, 0.005) == 1  # never zero
    with pytest.raises(ConfigurationError):
        samples_in(1.0, 0.0)


def test_measured_period_is_the_median_of_the_first_intervals():
    stamps = T0_NS + np.cumsum([0, 1_000_000, 1_000_000, 5_000_000, 1_000_000, 1_000_000, 1_000_000,
                                1_000_000, 1_000_000, 1_000_000, 9_000_000_000])
    assert measured_period_s(stamps) == pytest.approx(1e-3, rel=1e-12)  # a dropout does not move the median
    assert measured_period_s(stamps[:5]) is None


@pytest.mark.parametrize(("rate_hz", "expected"), [(100.0, 200), (1000.0, 2000)])
def test_the_estimator_converts_the_warm_up_at_the_measured_rate_like_replay(rate_hz, expected):
    """Streaming: after the first 10 samples the standardizer's warm-up is 2 s at the measured rate, and the
    offline models (replay) get the same count from the same stamps; the warm-up then ends exactly there."""
    cfg = ur5()
    est = OnlineEstimator(cfg, kind="SP")
    rng = np.random.default_rng(0)
    period_ns = round(1e9 / rate_hz)
    std = est.model.nonparametric.standardizer
    stamps = []
    for i in range(expected):
        q, dq, ddq = rng.uniform(-1, 1, 6), rng.normal(0, 1, 6), rng.normal(0, 3, 6)
        stamps.append(T0_NS + i * period_ns)
        est.step(Sample(stamps[-1], q, dq, ddq, rng.normal(0, 5, 6)))
        std = est.model.nonparametric.standardizer
        if i == 9:
            assert est.sample_period_s == pytest.approx(1.0 / rate_hz, rel=1e-9)
            assert std.warmup == expected and not std.ready
        if i == expected - 2:
            assert not std.ready
    assert std.ready
    offline = build_models(cfg, ["SP", "NP"], sample_period_s=measured_period_s(stamps))
    assert offline["SP"].nonparametric.standardizer.warmup == expected
    assert offline["NP"].standardizer.warmup == expected
    fingerprint = fingerprint_of(cfg, "SP", est.regressor)
    assert "standardizer_warmup_s" in fingerprint and '"nonparametric.standardizer_warmup"' not in fingerprint


def test_set_warmup_before_the_end_and_finishing_at_once():
    """A shorter warm-up than the samples already fed freezes the statistics of those samples (Welford =
    the batch mean and population std to rounding: rtol 1e-12 for 20 samples of O(1) values)."""
    X = np.random.default_rng(1).normal(size=(20, 3))
    s = Standardizer(3, warmup=100)
    s.partial_fit(X)
    assert not s.ready
    s.set_warmup(15)
    ref = Standardizer(3).fit(X)
    assert s.ready
    np.testing.assert_allclose(s.mean_, ref.mean_, rtol=1e-12)
    np.testing.assert_allclose(s.scale_, ref.scale_, rtol=1e-12)
    with pytest.raises(ValueError, match="ready"):
        s.set_warmup(30)
    with pytest.raises(ConfigurationError):
        Standardizer(3, warmup=5).set_warmup(0)


def test_rmse_window_resize_keeps_the_most_recent_errors():
    """The diagnostics' ring keeps the last min(count, new window) errors: RMSE as computed directly."""
    pytest.importorskip("diagnostic_msgs")
    from semiparam_ros.ros.diagnostics import _RingRMSE

    rng = np.random.default_rng(2)
    errors = rng.normal(size=(23, 2))
    ring = _RingRMSE(10, 2)
    for e in errors:
        ring.add(e)
    ring.resize(4)
    assert ring.count == 4 and ring.window == 4
    assert ring.rmse(slice(0, 2)) == pytest.approx(np.sqrt(np.mean(errors[-4:] ** 2)), rel=1e-12)
    ring.add(errors[0])
    last4 = np.vstack([errors[-3:], errors[:1]])
    assert ring.rmse(slice(0, 2)) == pytest.approx(np.sqrt(np.mean(last4**2)), rel=1e-12)
    ring.resize(50)
    assert ring.count == 4 and ring.window == 50
    assert ring.rmse(slice(0, 2)) == pytest.approx(np.sqrt(np.mean(last4**2)), rel=1e-12)
