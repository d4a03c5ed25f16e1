"""A frozen row of the evaluation is the served model: `learn` → checkpoint → `load_model(...).predict`."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import KUKA, REPO

from semiparam_ros.core.config import load_config
from semiparam_ros.eval.protocol import SampleArrays
from semiparam_ros.eval.replay import load_samples
from semiparam_ros.eval.served import ServedModel, learn_served
from semiparam_ros.report.real_robot import _models
from semiparam_ros.service.learn import learn_bags
from semiparam_ros.service.serving import load_model

needs_kuka = pytest.mark.skipif(not (KUKA / "measurements_1").is_dir(), reason=f"{KUKA} is absent")


@needs_kuka
def test_a_frozen_row_on_the_real_kuka_logs_is_learn_then_load_model(tmp_path):
    """The evaluation learns the samples the node's pipeline made from log 1 through the node's estimator;
    ``learn`` reads the same bag message by message. On log 3's states the two predictions agree to 1e-9
    N·m: the same samples through the same arithmetic, the consistent rigid body included (both solve the
    same projection from the same factor: the solver's tolerance is far below 1e-9 of its inputs' effect)."""
    cfg = load_config(REPO / "config" / "kuka_lwr4.yaml").with_overrides(
        {"robot.urdf": str(KUKA / "kuka_lwr4_cogimon.urdf"), "nonparametric.n_features": 100})
    train, _ = load_samples(KUKA / "measurements_1", cfg)
    test, _ = load_samples(KUKA / "measurements_3", cfg, limit=400)
    served = ServedModel(learn_served(cfg, train))
    ckpt = tmp_path / "model.npz"
    learn_bags([KUKA / "measurements_1"], cfg, checkpoint=ckpt)
    user = load_model(ckpt)
    n = len(cfg["robot.joints"])
    want = user.predict(test.X[:, :n], test.X[:, n:2 * n], test.X[:, 2 * n:])[0]
    got = np.array([served.predict_model(x) for x in test.X])
    np.testing.assert_allclose(got, want, rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(served.predict_many(test.X), want, rtol=0.0, atol=1e-9)
    assert user.config["parametric.consistent"]  # the consistent rigid body is what both serve
    # the real-robot comparison's frozen rows are such served models, never trained further
    prefix = SampleArrays(train.stamps_ns[:600], train.X[:600], train.Y[:600])
    models, frozen, trained = _models(cfg, prefix)
    for name in ("P frozen", "NP frozen", "SP frozen"):
        assert isinstance(models[name], ServedModel) and name in frozen and name in trained
    with pytest.raises(TypeError, match="does not learn"):
        served.learn_one(test.X[0], test.Y[0])
