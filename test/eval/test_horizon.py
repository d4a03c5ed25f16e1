"""The evaluation by the age of the model: the delay line against stored snapshots, persistence held h."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import REPO

from semiparam_ros.core.learners.cascade import SemiparametricModel
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.models.baselines import Persistence
from semiparam_ros.eval.protocol.horizon import (
    FROZEN,
    delayed_predictions,
    evaluate_horizons,
    horizon_markdown,
    inside_training_range,
    parse_horizons,
)
from semiparam_ros.eval.protocol.prequential import SampleArrays, train


def line(x: np.ndarray) -> np.ndarray:
    return np.array([[x[0], np.sin(x[1]), 1.0], [x[1], x[2], 1.0]])


def stream(n: int, seed: int, period_ns: int = 10_000_000) -> SampleArrays:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * period_ns * 1e-9
    X = np.column_stack([np.sin(1.3 * t + seed), np.cos(0.7 * t), np.sin(2.1 * t)])
    X += 0.01 * rng.normal(size=(n, 3))
    Y = np.column_stack([2 * X[:, 0] + np.sin(X[:, 1]) + 0.3 * np.cos(3 * X[:, 0]),
                         X[:, 1] - X[:, 2] + 1.0]) + 0.01 * rng.normal(size=(n, 2))
    return SampleArrays(np.arange(n, dtype=np.int64) * period_ns + 1, X, Y)


def models():
    return {
        "P": ParametricModel(line, 3, 2, lam=1e-3, forgetting=0.999),
        "NP": NonparametricModel(3, 2, n_features=50, sigma=1.0, lam=1e-2, forgetting=0.999,
                                 standardizer_warmup=20),
        "SP": SemiparametricModel(line, 3, 3, 2, lam_parametric=1e-3, lam_nonparametric=1e-2, n_features=50,
                                  sigma=1.0, forgetting_parametric=0.999, forgetting_nonparametric=0.999,
                                  standardizer_warmup=20),
    }


@pytest.mark.parametrize("kind", ["P", "NP", "SP"])
@pytest.mark.parametrize("delay", [1, 3, 17])
def test_delay_line_equals_snapshots_taken_every_sample(kind, delay):
    """The model predicting sample i through the delay line is the online model's snapshot after learning
    sample i − d (copies stored along a test-then-train pass): the same learns in the same order, so the
    same state — the predictions agree to rounding of the deferred update (≪ 1e-12 relative here)."""
    train_data, test = stream(300, 0), stream(120, 1)
    model = models()[kind]
    train(model, train_data)
    online = model.copy()
    snapshots = [online.copy()]  # snapshots[k]: after learning k test samples
    for x, y in zip(test.X, test.Y, strict=True):
        online.learn_one(x, y)
        snapshots.append(online.copy())
    got = delayed_predictions(model.copy(), test.X, test.Y, delay)
    want = np.array([snapshots[max(0, i - delay + 1)].predict_one(test.X[i]).total for i in range(len(test))])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    frozen = delayed_predictions(model.copy(), test.X, test.Y, 0)
    np.testing.assert_allclose(frozen, [snapshots[0].predict_one(x).total for x in test.X], rtol=1e-13)


def test_persistence_through_the_delay_line_is_persistence_held_h():
    data = stream(200, 3)
    p = Persistence(2)
    train(p, stream(10, 4))
    last = stream(10, 4).Y[-1]
    for d in (1, 5, 50):
        got = delayed_predictions(p.copy(), data.X, data.Y, d)
        np.testing.assert_array_equal(got[d:], data.Y[:-d])
        np.testing.assert_array_equal(got[:d], np.tile(last, (d, 1)))


def test_evaluate_horizons_scores_every_horizon_on_the_same_samples():
    train_data, test = stream(400, 0), stream(600, 1)
    ms = models()
    for m in ms.values():
        train(m, train_data)
    ms["persistence"] = Persistence(2)
    train(ms["persistence"], train_data)
    report = evaluate_horizons(ms, train_data, test, horizons=[0, 0.05, 1.0, FROZEN], components=["a", "b"])
    assert [h.label for h in report.horizons] == ["1 step", "0.05 s", "1 s", FROZEN]
    assert [h.delay for h in report.horizons] == [1, 5, 100, 0]
    assert report.n_scored == 500  # from the largest delay on
    # an independent computation of one entry: persistence held 1 s on the scored samples
    err = test.Y[100:] - test.Y[:-100]
    np.testing.assert_allclose(report.rmse["persistence"]["1 s"], np.sqrt(np.mean(err ** 2, axis=0)))
    # the frozen P entry: the trained model's predictions only
    pred = np.array([ms["P"].predict_one(x).total for x in test.X[100:]])
    np.testing.assert_allclose(report.rmse["P"][FROZEN], np.sqrt(np.mean((pred - test.Y[100:]) ** 2, axis=0)))
    # the models handed in were not modified (each horizon ran a copy)
    assert ms["P"].n_samples_seen == len(train_data)
    inside = inside_training_range(train_data.X, test.X[100:])
    assert report.n_inside == int(inside.sum())
    assert "Ratio to persistence" in horizon_markdown(report)
    assert math.isfinite(report.mean("SP", "1 step"))


def test_inside_training_range_needs_every_position_and_velocity_inside():
    train_X = np.array([[0.0, 0.0, -1.0, -1.0, 0.0, 0.0], [1.0, 2.0, 1.0, 1.0, 0.0, 0.0]])
    X = np.array([[0.5, 1.0, 0.0, 0.0, 50.0, -50.0],   # accelerations do not count
                  [0.5, 2.5, 0.0, 0.0, 0.0, 0.0],      # q of joint 2 above
                  [0.5, 1.0, 0.0, -1.5, 0.0, 0.0]])    # dq of joint 2 below
    assert inside_training_range(train_X, X).tolist() == [True, False, False]


@pytest.mark.parametrize("bad", [-1.0, math.nan, "soon"])
def test_parse_horizons_refuses_bad_values(bad):
    with pytest.raises(ConfigurationError):
        parse_horizons([bad], 0.01)


def test_horizons_longer_than_the_stream_are_left_out_or_refused():
    train_data, test = stream(100, 0), stream(100, 1)
    p = models()["P"]
    report = evaluate_horizons({"P": p}, train_data, test, horizons=[0, 10.0])
    assert [h.label for h in report.horizons] == ["1 step"]
    with pytest.raises(ConfigurationError):
        evaluate_horizons({"P": p}, train_data, test, horizons=[10.0])


def test_evaluate_cli_reports_horizons_in_text_json_and_figure(tmp_path):
    """`evaluate --horizons` on the committed bags: the text, the JSON and the figure carry the table, and
    its numbers are those of the library run on the same samples."""
    import json

    from semiparam_ros.cli.evaluate import main

    root = REPO
    out = tmp_path / "r.json"
    fig = tmp_path / "h.png"
    code = main(["paper", "--train", str(root / "bags" / "icub_xy"), "--test", str(root / "bags" / "icub_xz"),
                 "--config", str(root / "config" / "icub_right_arm.yaml"),
                 "--set", "nonparametric.n_features=40",
                 "--train-limit", "800", "--test-limit", "900", "--splits", "2", "--models", "P", "SP",
                 "--horizons", "0", "1", "frozen", "--horizon-plot", str(fig), "--json", str(out),
                 "--no-progress"])
    assert code == 0
    doc = json.loads(out.read_text())
    h = doc["protocol"]["horizons"]
    assert [x["label"] for x in h["horizons"]] == ["1 step", "1 s", FROZEN]
    assert set(h["mean"]) == {"CAD", "P", "SP", "persistence"}
    # persistence held 1 s, recomputed from the bag's samples
    from semiparam_ros.core.config import load_config
    from semiparam_ros.eval.bags.replay import load_samples

    cfg = load_config(root / "config" / "icub_right_arm.yaml")
    test, _ = load_samples(root / "bags" / "icub_xz", cfg, limit=900)
    d = h["horizons"][1]["delay"]
    err = test.Y[d:] - test.Y[:-d]
    np.testing.assert_allclose(h["mean"]["persistence"]["1 s"], np.mean(np.sqrt(np.mean(err ** 2, axis=0))),
                               rtol=1e-12)
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the frozen column is the served model: the node's estimator on the training samples, its checkpoint,
    # load_model(...).predict on the scored test states
    from semiparam_ros.eval.models.served import served_model

    train, _ = load_samples(root / "bags" / "icub_xy", cfg, limit=800)
    served = served_model(cfg.with_overrides({"nonparametric.n_features": 40}), "SP", train)
    assert served is not None
    start = max(x["delay"] for x in h["horizons"])
    err = served.predict_many(test.X)[start:] - test.Y[start:]
    want = np.mean(np.sqrt(np.mean(err ** 2, axis=0)))
    np.testing.assert_allclose(h["mean"]["SP"][FROZEN], want, rtol=1e-9)
