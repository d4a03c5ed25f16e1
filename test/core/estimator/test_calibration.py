"""The served σ calibrated for new motion by frozen copies (core/estimator/calibration.py).

Checked against independent computations: the motion states against a per-joint loop, the scales against
NumPy's quantile of the same errors, the block scheme against the errors a known model must make, and the
served model on a simulated point-to-point arm whose friction remembers (Dahl) against its held-out
motion: the one-step σ covers a fraction of the errors at rest, the calibrated σ what it claims.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers.point_to_point import served_ur5

from semiparam_ros.core.checkpoint import atomic_save_npz, load_npz
from semiparam_ros.core.estimator import calibration
from semiparam_ros.core.estimator.build import build_pipeline
from semiparam_ros.core.estimator.calibration import (
    _EDGES,
    MEMORY_S,
    MIN_WEIGHT,
    REST_VELOCITY,
    REVERSAL_WINDOW_S,
    SCORE_PERIOD_S,
    FrozenCalibration,
    motion_states,
    served_sigma_one,
)
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.errors import CheckpointError, ConfigurationError
from semiparam_ros.eval.protocol.slices import motion_slices
from semiparam_ros.serving.learned_model import CheckpointMigrationWarning, load_model

BIN = math.exp(float(_EDGES[1] - _EDGES[0]))  # one bin of the histogram in z: a quantile read is within it


def test_motion_states_follow_each_joint_for_torques_and_the_arm_for_a_wrench():
    rng = np.random.default_rng(0)
    n, N = 3, 500
    dq = rng.choice([0.0, 0.005, 0.05, 0.5, -0.5], size=(N, n))
    ddq = rng.choice([0.0, 1.0, -5.0], size=(N, n))
    X = np.hstack([rng.normal(size=(N, n)), dq, ddq])
    expected = np.empty((N, n), dtype=int)
    for i in range(N):
        for j in range(n):
            v, a = abs(dq[i, j]), abs(ddq[i, j])
            expected[i, j] = 0 if v < REST_VELOCITY else (1 if v < REVERSAL_WINDOW_S * a else 2)
    np.testing.assert_array_equal(motion_states(X, n, n), expected)
    arm = motion_states(X, n, 6)
    for i in range(N):
        want = 0 if (expected[i] == 0).all() else (1 if (expected[i] == 1).any() else 2)
        assert (arm[i] == want).all()


@pytest.mark.parametrize("t", [3, 6])
def test_the_compiled_served_sigma_is_the_scaled_one_step_sigma_of_each_outputs_state(t):
    """``served_sigma_one`` against the formula with numpy's motion states: ``c_m sqrt(s²_m (1 + v))``,
    the one-step ``sqrt(s² (1 + v))`` where a state has no scale (NaN), +inf without a noise estimate, a
    negative or NaN v counted as 0."""
    rng = np.random.default_rng(4)
    n, N = 3, 400
    dq = rng.choice([0.0, 0.005, 0.05, 0.5, -0.5], size=(N, n))
    ddq = rng.choice([0.0, 1.0, -5.0], size=(N, n))
    X = np.hstack([rng.normal(size=(N, n)), dq, ddq])
    V = rng.uniform(-0.1, 3.0, size=(N, t))
    V[::17, 0] = np.nan
    s2 = rng.uniform(0.1, 2.0, t)
    scales = rng.uniform(0.5, 3.0, (t, 3))
    per_state = rng.uniform(0.1, 2.0, (t, 3))
    scales[0, 0] = np.nan  # output 0 at rest: no scale of its own
    states = motion_states(X, n, t)
    for s2_in in (s2, np.full(t, np.inf)):
        for i in range(N):
            out = np.empty(t)
            served_sigma_one(V[i], X[i], n, s2_in, scales, per_state, out)
            relative = 1.0 + np.fmax(np.nan_to_num(V[i], nan=0.0), 0.0)
            m = states[i]
            want = scales[np.arange(t), m] * np.sqrt(per_state[np.arange(t), m] * relative)
            want = np.where(np.isnan(want), np.sqrt(s2_in * relative), want)
            np.testing.assert_allclose(out, want, rtol=4 * np.finfo(float).eps)


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, q * cumulative[-1])])


def test_scales_are_the_95_percent_quantile_over_two_per_state_with_the_pooled_fallback():
    rng = np.random.default_rng(1)
    cal = FrozenCalibration(n_outputs=2, n_joints=2, block_s=20.0)
    moving = np.tile([0.0, 0.0, 1.0, 1.0, 0.0, 0.0], (3000, 1))
    z_motion = np.abs(rng.standard_t(4, size=(3000, 2))) * np.array([1.0, 3.0])
    cal.add(moving, z_motion)
    rest = np.zeros((60, 6))  # fewer than MIN_WEIGHT at rest: the pooled scale
    assert 60 < MIN_WEIGHT
    z_rest = np.full((60, 2), 10.0)
    cal.add(rest, z_rest)
    scales = cal.scales()
    # each row fades the older ones by exp(−SCORE_PERIOD_S / MEMORY_S)
    age = np.arange(3060)[::-1]
    fade = np.exp(-age * SCORE_PERIOD_S / MEMORY_S)
    for k in range(2):
        want_motion = _weighted_quantile(z_motion[:, k], fade[:3000], 0.95) / 2.0
        assert want_motion / BIN <= scales[k, 2] <= want_motion * BIN
        pooled = _weighted_quantile(np.concatenate([z_motion[:, k], z_rest[:, k]]), fade, 0.95) / 2.0
        assert pooled / BIN <= scales[k, 0] <= pooled * BIN
    assert np.isnan(FrozenCalibration(1, 1, 20.0).scales()).all()
    with pytest.raises(ConfigurationError):
        FrozenCalibration(1, 1, 0.0)


class _KnownModel:
    """A learner stand-in: predicts a value it is told, with v = 0; copies freeze that value."""

    n_samples_seen = 1

    def __init__(self, value: float) -> None:
        self.value = value

    def copy(self) -> _KnownModel:
        return _KnownModel(self.value)


def test_each_copy_is_scored_on_the_next_block_after_a_quarter_of_it_every_score_period(monkeypatch):
    """y = 0; the live model predicts the time in seconds; its one-step error is 0.5 (s² = 0.25). A copy
    frozen at t₀ errs by t₀ on every sample it scores: the scores are known in advance."""
    monkeypatch.setattr(calibration, "model_alone", lambda model, x: (np.array([model.value]), np.zeros(1)))
    block, rate = 4.0, 500.0
    cal = FrozenCalibration(n_outputs=1, n_joints=1, block_s=block)
    model = _KnownModel(0.0)
    x = np.array([0.0, 1.0, 0.0])  # in motion
    frozen_at, scored = [], []
    start_ns = 10**12
    for k in range(int(10 * block * rate)):
        stamp = start_ns + round(k * 1e9 / rate)
        model.value = (stamp - start_ns) * 1e-9
        before = cal.n_scored
        copy_before = cal._copy
        cal.observe(stamp, x, np.zeros(1), model, np.array([0.5]), np.zeros(1))
        if cal._copy is not copy_before:
            frozen_at.append(model.value)
        if cal.n_scored > before:
            scored.append(frozen_at[-1] / 0.5)  # z = |0 − t₀| / sqrt(0.25)
    assert np.allclose(np.diff(frozen_at), block, atol=2 / rate)
    per_block = (0.75 * block) / SCORE_PERIOD_S
    assert len(frozen_at) == 10 and len(scored) == pytest.approx(len(frozen_at) * per_block, rel=0.02)
    want = np.quantile(scored, 0.95) / 2.0
    assert want / BIN <= cal.scales()[0, 2] <= want * BIN
    assert cal.s2[0, 2] == pytest.approx(0.25)
    assert np.isnan(cal.s2[0, :2]).all()  # never at rest or reversing


def _arrays(config, states):
    pipeline = build_pipeline(config)
    samples = [s for msg in states for s in pipeline.add(msg)]
    X = np.array([np.concatenate([s.q, s.dq, s.ddq]) for s in samples])
    Y = np.array([s.y for s in samples])
    return [s.stamp_ns for s in samples], X, Y, samples


@pytest.fixture(scope="module")
def p2p_arm(tmp_path_factory):
    """A UR5 at 100 Hz moving point to point with Dahl friction: 60 s learned, 30 s of other moves held out;
    served with and without the calibration."""
    folder = tmp_path_factory.mktemp("calibration")
    config, served, test = served_ur5("uncertainty.calibration_block", (0.0, 20.0), folder)
    return config, served, _arrays(config, test), folder


@pytest.mark.slow
def test_the_calibrated_sigma_covers_held_out_point_to_point_motion_at_rest_and_in_motion(p2p_arm):
    config, served, (_stamps, X, Y, _), _ = p2p_arm
    n = len(config["robot.joints"])
    masks = motion_slices(X, n, n, 0.01)
    coverage = {}
    for block, (_, model) in served.items():
        total, std = model.predict(X[:, :n], X[:, n:2 * n], X[:, 2 * n:])
        inside = np.abs(Y - total) <= 2.0 * std
        coverage[block] = (float(inside.mean()), float(inside[masks["at rest"]].mean()))
    assert coverage[0.0][1] < 0.5  # the one-step σ: friction's memory at rest is far outside it
    assert 0.80 <= coverage[20.0][0] <= 0.99
    assert coverage[20.0][1] >= 0.75


def test_the_served_sigma_is_the_scale_times_the_state_noise_and_survives_the_checkpoint(p2p_arm):
    config, served, (_, X, _, _), _ = p2p_arm
    est, loaded = served[20.0]
    n = len(config["robot.joints"])
    scales, s2 = loaded.sigma_scales(), est.calibration.s2
    assert np.isfinite(scales).all() and np.isfinite(s2).all()
    np.testing.assert_array_equal(scales, est.calibration.scales())
    parts = loaded.predict_parts(X[:50, :n], X[:50, n:2 * n], X[:50, 2 * n:])
    # v from the model alone (the relative variance predict_parts uses), then σ by hand
    from semiparam_ros.serving.learned_model import LearnedModel

    rows = LearnedModel._model_rows(loaded, X[:50])
    states = motion_states(X[:50], n, n)
    cols = np.arange(n)
    want = np.array([scales[cols, st] * np.sqrt(s2[cols, st] * (1.0 + np.fmax(v, 0.0)))
                     for st, v in zip(states, rows.variance, strict=True)])
    np.testing.assert_allclose(parts.std, want, rtol=1e-12)
    frozen = LearnedModel(est).snapshot()
    before = frozen.predict(X[:5, :n], X[:5, n:2 * n], X[:5, 2 * n:])[1]
    est.calibration.add(X[:500], np.full((500, n), 50.0))  # the live calibration moves on
    np.testing.assert_array_equal(frozen.predict(X[:5, :n], X[:5, n:2 * n], X[:5, 2 * n:])[1], before)


def test_a_checkpoint_without_calibration_serves_the_one_step_sigma_and_says_so(p2p_arm):
    config, _served, (_, X, _, _), folder = p2p_arm
    state = load_npz(folder / "uncertainty.calibration_block_20.npz")
    old = {k: v for k, v in state.items() if not k.startswith("calibration.")}
    old["meta.version"] = np.array(2)
    atomic_save_npz(folder / "v2.npz", old)
    with pytest.warns(CheckpointMigrationWarning, match="calibration of σ"):
        model = load_model(folder / "v2.npz")
    assert any("calibration" in note for note in model.estimator.migration_notes)
    assert any("friction that remembers" in note for note in model.estimator.migration_notes)
    assert np.isnan(model.sigma_scales()).all()
    n = len(config["robot.joints"])
    one_step = load_model(folder / "uncertainty.calibration_block_0.npz")
    s2 = model.estimator.noise.s2
    rows = type(model)._model_rows(model, X[:20])
    np.testing.assert_allclose(model.predict(X[:20, :n], X[:20, n:2 * n], X[:20, 2 * n:])[1],
                               np.sqrt(s2 * (1.0 + np.fmax(rows.variance, 0.0))), rtol=1e-12)
    assert one_step.estimator.calibration is None


@pytest.mark.parametrize("key, value", [
    ("calibration.weights", np.zeros((2, 3))),
    ("calibration.weights", -np.ones((6, 3, _EDGES.size - 1))),
    ("calibration.s2", np.full((6, 3), np.inf)),
    ("calibration.n_scored", np.array(-1)),
])
def test_a_corrupt_calibration_is_refused_and_nothing_changes(p2p_arm, key, value):
    config, _served, _, folder = p2p_arm
    state = load_npz(folder / "uncertainty.calibration_block_20.npz")
    state[key] = value
    atomic_save_npz(folder / "bad.npz", state)
    est = OnlineEstimator(config)
    with pytest.raises(CheckpointError):
        est.load(folder / "bad.npz")
    assert est.calibration is not None and est.calibration.n_scored == 0
