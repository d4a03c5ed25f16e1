"""Friction that remembers (core/learners/stick.py): the stick state against the simulator's Dahl element,
the coefficient against a closed-form weighted ridge, the same answer at any rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from semiparam_ros.core.learners.stick import PRIOR_S, StickFriction, StickState
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.sim.point_to_point import dahl_friction


def _path(rate_hz: float, seconds: float = 20.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two joints moving back and forth with rests, positions quantized to 1e-4 rad."""
    t = np.arange(round(seconds * rate_hz)) / rate_hz
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * np.pi, 2)
    raw = 0.3 * np.clip(1.5 * np.sin(np.outer(t, [0.7, 1.1]) + phase), -1.0, 1.0)  # flat tops: rests
    q = np.round(raw / 1e-4) * 1e-4
    dq = np.gradient(raw, t, axis=0)
    return t, q, dq


def test_the_stick_state_is_the_simulators_dahl_element_normalized():
    _, q, dq = _path(500.0)
    stick = StickFriction(2, 2e-3, 0.05, 20.0)
    phi = stick.features(q, dq, StickState.fresh(2))
    z = phi + np.tanh(dq / 0.05)
    np.testing.assert_allclose(z, dahl_friction(q, np.ones(2), 2e-3), rtol=0, atol=1e-12)
    moved = np.cumsum(np.abs(np.diff(q, axis=0, prepend=q[:1])), axis=0) > 0.05  # after a first move
    at_rest = (np.abs(dq) < 1e-9) & moved
    assert at_rest.any() and np.all(np.abs(phi[at_rest]) > 0.9)  # the last direction is held


def test_a_sequence_split_in_two_carries_its_state():
    _, q, dq = _path(200.0)
    stick = StickFriction(2, 1e-3, 0.05, 20.0)
    whole = stick.features(q, dq, StickState.fresh(2))
    state = StickState.fresh(2)
    parts = np.vstack([stick.features(q[:700], dq[:700], state), stick.features(q[700:], dq[700:], state)])
    np.testing.assert_array_equal(parts, whole)


def test_the_coefficient_is_the_time_weighted_ridge_and_does_not_depend_on_the_rate():
    coefficients = {}
    for rate in (100.0, 1000.0):
        t, q, dq = _path(rate)
        stick = StickFriction(2, 1e-3, 0.05, 20.0)
        rng = np.random.default_rng(1)
        stamps = (1e9 + t * 1e9).astype(np.int64)
        a = np.zeros(2)
        b = np.zeros(2)
        for k in range(len(t)):
            phi = stick.step(q[k], dq[k])
            error = np.array([0.7, -1.2]) * phi + 0.05 * rng.standard_normal(2)
            stick.learn(int(stamps[k]), phi, error)
            if k:  # the closed form: sums weighted by Δt, faded by exp(−Δt/τ)
                dt = (stamps[k] - stamps[k - 1]) * 1e-9
                a = math.exp(-dt / 20.0) * a + dt * phi**2
                b = math.exp(-dt / 20.0) * b + dt * phi * error
        np.testing.assert_allclose(stick.coefficient, b / (a + PRIOR_S), rtol=1e-10)
        coefficients[rate] = stick.coefficient
        assert np.allclose(stick.coefficient, [0.7, -1.2], rtol=0.1)
    np.testing.assert_allclose(coefficients[100.0], coefficients[1000.0], rtol=0.03)


def test_bad_state_arrays_and_parameters_are_refused():
    stick = StickFriction(2, 1e-3, 0.05, 20.0)
    good = stick.state_dict()
    for key, value in (("a", -np.ones(2)), ("z", np.array([0.0, 1.5])), ("b", np.full(2, np.nan)),
                       ("q", np.zeros(3))):
        with pytest.raises(ValueError):
            stick.load_state_dict({**good, key: value})
    with pytest.raises(ConfigurationError):
        StickFriction(2, 0.0, 0.05, 20.0)
