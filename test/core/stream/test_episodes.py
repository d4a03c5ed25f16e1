"""Per-episode contact-detection scoring against counts made by hand on a small timeline."""

from __future__ import annotations

import numpy as np
import pytest

from semiparam_ros.core.stream.episodes import flag_samples, score_episodes


def test_flags_any_component_beyond_threshold_sigma():
    ext = np.array([[0.0, 2.9], [0.0, 3.1], [-5.0, 0.0], [np.inf, 0.0]])
    std = np.array([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [np.inf, 1.0]])
    np.testing.assert_array_equal(flag_samples(ext, std, 3.0), [False, True, True, False])
    with pytest.raises(ValueError):
        flag_samples(ext, std[:2], 3.0)
    with pytest.raises(ValueError):
        flag_samples(ext, std, 0.0)


def test_score_recall_delay_and_false_alarm_runs():
    t = np.arange(0, 60.0, 0.1)  # one minute at 10 Hz
    f = np.zeros(t.shape, dtype=bool)
    f[(t >= 10.3) & (t < 11.0)] = True    # episode 1 [10, 11): detected 0.3 s late
    f[(t >= 30.0) & (t < 30.35)] = True   # a false alarm run (4 samples: one alarm)
    f[(t >= 40.0) & (t < 40.15)] = True   # a second false alarm run
    f[(t >= 21.05) & (t < 21.15)] = True  # just after episode 2 [20, 21): inside a 0.2 s tolerance
    episodes = np.array([[10.0, 11.0], [20.0, 21.0], [50.0, 52.0]])  # the third is missed
    s = score_episodes(t, f, episodes, tolerance_s=0.2)
    np.testing.assert_array_equal(s.detected, [True, True, False])
    np.testing.assert_allclose(s.delays_s[:2], [0.3, 1.1], atol=1e-9)
    assert np.isnan(s.delays_s[2])
    assert s.recall == pytest.approx(2 / 3)
    assert s.false_alarms == 2
    # time outside the episodes (each extended by 0.2 s, counted in samples): 59.9 s − 0.1 s·(n near)
    near = sum(((t >= a) & (t <= b + 0.2)).sum() for a, b in episodes)
    assert s.false_alarms_per_minute == pytest.approx(2 / ((59.9 - 0.1 * near) / 60.0), rel=1e-9)
    # without the tolerance the flags after episode 2 are a false alarm and episode 2 is missed
    s0 = score_episodes(t, f, episodes)
    np.testing.assert_array_equal(s0.detected, [True, False, False])
    assert s0.false_alarms == 3
