"""Errors by motion state (eval.protocol.slices): masks against a hand-built motion, the horizon report's
slices against a direct computation of the same errors."""

from __future__ import annotations

import math

import numpy as np

from semiparam_ros.eval.protocol.horizon import FROZEN, evaluate_horizons
from semiparam_ros.eval.protocol.prequential import SampleArrays
from semiparam_ros.eval.protocol.slices import SLICES, motion_slices, slice_rmse

T = 0.01  # 100 Hz


def _stream(dq: np.ndarray, y: np.ndarray) -> SampleArrays:
    q = np.cumsum(dq, axis=0) * T
    X = np.hstack([q, dq, np.gradient(dq, T, axis=0)])
    return SampleArrays(np.arange(len(dq), dtype=np.int64) * 10**7 + 10**9, X, y)


def test_masks_follow_each_joints_own_velocity():
    # joint 0: rest, then a slow ramp, then fast, then a reversal; joint 1: always fast, one direction
    dq0 = np.concatenate([np.zeros(100), np.full(100, 0.1), np.full(100, 1.0), np.full(100, -1.0)])
    dq1 = np.full(400, 2.0)
    zero = np.zeros((400, 2))
    X = np.hstack([zero, np.c_[dq0, dq1], zero])
    masks = motion_slices(X, 2, 2, T)
    assert masks["at rest"][:, 0].sum() == 100 and masks["at rest"][:, 1].sum() == 0
    assert masks["slow"][:, 0].sum() == 100 and masks["fast"][:, 0].sum() == 200
    # one sign change (sample 299 → 300), ±0.2 s = ±20 samples around it; none on joint 1
    assert np.flatnonzero(masks["reversals"][:, 0]).tolist() == list(range(280, 320))
    assert not masks["reversals"][:, 1].any()
    # rest → positive is no sign change (0 has no sign)
    assert not masks["reversals"][:120, 0].any()
    # a wrench: every output judged by the fastest joint (joint 1: always fast)
    wrench = motion_slices(X, 2, 6, T)
    assert wrench["fast"].all() and wrench["reversals"].shape == (400, 6) and wrench["reversals"][290].all()


def test_horizon_report_slices_are_the_errors_of_each_state():
    rng = np.random.default_rng(0)
    dq = np.concatenate([np.zeros(200), np.linspace(0.0, 1.0, 400), np.linspace(1.0, -1.0, 400)])[:, None]
    y = rng.normal(size=(1000, 1))
    train, test = _stream(dq, y), _stream(dq, y + rng.normal(size=(1000, 1)))

    class Zero:  # predicts 0 whatever it learned: its error is −y
        def predict_one(self, x):
            return np.zeros(1)

        def learn_one(self, x, y):
            pass

        def copy(self):
            return self

    report = evaluate_horizons({"zero": Zero()}, train, test, horizons=(FROZEN,), fixed=("zero",))
    err = -test.Y[report.horizons[0].delay:]
    masks = motion_slices(test.X, 1, 1, T)
    want = {s: math.sqrt(float(np.mean(err[masks[s][:, 0], 0] ** 2))) for s in SLICES}
    got = report.slices["zero"][FROZEN]
    assert got == {s: want[s] for s in SLICES}
    assert report.slice_share["at rest"] == float(np.mean(masks["at rest"]))
    assert slice_rmse(err, masks) == got
