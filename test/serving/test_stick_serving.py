"""Friction that remembers, served: learned on a simulated point-to-point arm whose friction is a Dahl
element (the truth), scored on another seed's moves; predict, the per-cycle feed-forward and trajectories
treat states as one path and agree; the checkpoint keeps it; leaving friction out leaves it out."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.point_to_point import served_ur5

from semiparam_ros.core.config import parameter_spec
from semiparam_ros.core.estimator.build import build_pipeline
from semiparam_ros.core.learners.stick import StickState
from semiparam_ros.eval.protocol.slices import motion_slices
from semiparam_ros.serving.feedforward import DesiredState, FeedForward, TrajectoryPoint
from semiparam_ros.serving.learned_model import LearnedModel
from semiparam_ros.sim.arms import arm_spec


def _states(config, messages):
    pipeline = build_pipeline(config)
    samples = [s for msg in messages for s in pipeline.add(msg)]
    return (np.array([s.q for s in samples]), np.array([s.dq for s in samples]),
            np.array([s.ddq for s in samples]), np.array([s.y for s in samples]))


@pytest.fixture(scope="module")
def ur5(tmp_path_factory):
    """A UR5 at 100 Hz, 60 s of point-to-point moves learned with and without the stick state."""
    folder = tmp_path_factory.mktemp("stick")
    default = parameter_spec("parametric.stick_displacement").default
    config, served, test = served_ur5("parametric.stick_displacement", (0.0, default), folder)
    return config, served, _states(config, test), folder


@pytest.mark.slow
def test_held_out_moves_err_less_at_rest_and_c_finds_the_true_coulomb_friction(ur5):
    config, served, (q, dq, ddq, y), _ = ur5
    delta = config["parametric.stick_displacement"]
    assert delta > 0
    n = q.shape[1]
    rest = motion_slices(np.hstack([q, dq, ddq]), n, n, 0.01)["at rest"]
    error = {d: y - model.predict(q, dq, ddq)[0] for d, (_, model) in served.items()}
    rms = {d: float(np.sqrt(np.mean(e**2))) for d, e in error.items()}
    rest_rms = {d: float(np.sqrt(np.mean(e[rest] ** 2))) for d, e in error.items()}
    assert rms[delta] <= 0.6 * rms[0.0]
    assert rest_rms[delta] <= 0.6 * rest_rms[0.0]
    true_coulomb = np.asarray(arm_spec("ur5").friction.coulomb)
    c = served[delta][1].estimator.stick.coefficient
    np.testing.assert_allclose(c, true_coulomb, rtol=0.3)


def test_rows_are_one_path_and_the_feedforward_paths_agree_with_predict(ur5):
    config, served, (q, dq, ddq, _), _ = ur5
    model = served[config["parametric.stick_displacement"]][1]
    rows = slice(200, 260)
    whole = model.predict_parts(q[rows], dq[rows], ddq[rows])
    # one row at a time with the state carried: the same numbers
    history = model.stick_state()
    one_by_one = np.array([model.predict_parts(q[k], dq[k], ddq[k], history=history).total
                           for k in range(rows.start, rows.stop)])
    np.testing.assert_allclose(one_by_one, whole.total, rtol=0, atol=1e-9)
    # a call without history does not move the served state
    np.testing.assert_array_equal(model.predict_parts(q[rows], dq[rows], ddq[rows]).total, whole.total)
    # consecutive per-cycle desired states carry it
    ff = FeedForward(model)
    names = model.joints
    cmds = [ff.compute(DesiredState(0, names, (TrajectoryPoint(0, q[k], dq[k], ddq[k]),)), now_ns=0)
            for k in range(rows.start, rows.stop)]
    np.testing.assert_allclose(np.array([c.tau for c in cmds]), whole.total, rtol=0, atol=1e-9)
    # a trajectory is a path from the measured one
    points = tuple(TrajectoryPoint(int(i * 1e7), q[k], dq[k], ddq[k]) for i, k in enumerate(range(200, 260)))
    effort = FeedForward(model).trajectory(DesiredState(0, names, points))
    assert effort is not None
    np.testing.assert_allclose(effort.effort, whole.total, rtol=0, atol=1e-9)
    # the stick torque is friction: left out with it
    no_friction = model.predict_parts(q[rows], dq[rows], ddq[rows], exclude=("friction",))
    phi = model.estimator.stick.features(q[rows], dq[rows], model.stick_state())
    static = model.friction(dq[rows])
    np.testing.assert_allclose(no_friction.total,
                               whole.total - static - model.estimator.stick.torque(phi), rtol=0, atol=1e-9)


def test_the_checkpoint_keeps_the_coefficients_and_the_path(ur5):
    config, served, (q, dq, ddq, _), _folder = ur5
    est, loaded = served[config["parametric.stick_displacement"]]
    live = LearnedModel(est)
    np.testing.assert_array_equal(loaded.estimator.stick.coefficient, est.stick.coefficient)
    np.testing.assert_array_equal(loaded.stick_state().z, est.stick.state.z)
    np.testing.assert_allclose(loaded.predict(q[:40], dq[:40], ddq[:40])[0],
                               live.predict(q[:40], dq[:40], ddq[:40])[0], rtol=1e-9, atol=1e-9)
    snapshot = live.snapshot()
    before = snapshot.predict(q[:5], dq[:5], ddq[:5])[0]
    est.stick.learn(10**19, np.ones(q.shape[1]), np.full(q.shape[1], 100.0))  # the live one moves on
    est.stick.learn(10**19 + 10**9, np.ones(q.shape[1]), np.full(q.shape[1], 100.0))
    np.testing.assert_array_equal(snapshot.predict(q[:5], dq[:5], ddq[:5])[0], before)
    assert isinstance(loaded.stick_state(), StickState)
