"""Integration tests of the one data path: messages → SamplePipeline → OnlineEstimator.step.

The message streams are built here from analytic multi-sine joint trajectories (q, q̇, q̈ in closed form,
100 Hz, realistic epoch stamps, extra joints in shuffled order) and the rigid-body wrench of the iCub
right upper arm computed by :meth:`RigidBodyRegressor.wrench` with the URDF inertias, plus (optionally) a
smooth nonlinear residual and small noise. Independent references:

* a hand-written loop over a second pipeline and a second model (``predict_one`` *before* ``learn_one``);
* the closed-form ridge solution ``(ΦᵀΦ + λI)⁻¹ΦᵀY`` and its bias bound ``λ‖π‖/σ_min(Φ)²``;
* the closed-form gain of the Savitzky–Golay derivative on a sinusoid, which predicts the pipeline's q̈
  estimate exactly and bounds the resulting parameter error.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from helpers.streams import (
    CONFIG_PATH,
    DT_NS,
    EXTRA_JOINTS,
    FRAME,
    JOINTS,
    N_FEATURES,
    T0_NS,
    WARMUP,
    Stream,
    _stream,
    assert_close_state,
    assert_same_state,
    feed,
    make_trajectory,
    paper_config,
    rich_stream,
    snapshot,
)

import semiparam_ros.core.checkpoint as checkpoint_module
from semiparam_ros.core.config import EstimatorConfig, load_config
from semiparam_ros.core.estimator.build import build_model, build_pipeline, build_regressor
from semiparam_ros.core.estimator.online import OnlineEstimator, StepResult
from semiparam_ros.core.learners.stick import StickFriction
from semiparam_ros.core.stream.messages import JointStateData, Sample, WrenchData
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError
from semiparam_ros.io.bags import iter_samples


@pytest.fixture(scope="module")
def config() -> EstimatorConfig:
    return paper_config()


@pytest.fixture(scope="module")
def regressor(config: EstimatorConfig):
    return build_regressor(config)


def rigid_stream() -> Stream:
    """Noise-free rigid-body wrenches stamped like their joint states (3000 steps, 30 s)."""
    return _stream(3000, with_residual=False, noise=0.0, wrench_offset_ns=0, seed=3)




def pipeline_samples(config: EstimatorConfig, messages) -> list[Sample]:
    pipeline = build_pipeline(config)
    samples: list[Sample] = []
    for msg in messages:
        samples.extend(pipeline.add(msg))
    return samples






def assert_same_prediction(p, q) -> None:
    for part in ("parametric", "residual", "total"):
        assert np.array_equal(getattr(p, part), getattr(q, part)), part


def clean_stream_results(config, regressor, n: int | None = None) -> tuple[OnlineEstimator, list[StepResult]]:
    est = OnlineEstimator(config, regressor=regressor)
    msgs = rich_stream().messages
    return est, feed(est, msgs if n is None else msgs[:n])


# ----------------------------------------------------------------------------- 1. one data path
@pytest.mark.parametrize("kind", ["SP", "P", "NP"])
def test_stream_predictions_equal_a_priori_predictions_of_hand_loop(config, regressor, kind):
    stream = rich_stream()
    est = OnlineEstimator(config, regressor=regressor, kind=kind)
    results = feed(est, stream.messages)

    # independent path: a second pipeline and a second model (own regressor), predict BEFORE learn
    samples = pipeline_samples(config, stream.messages)
    model = build_model(config, kind)
    expected = []
    for s in samples:
        expected.append(model.predict_one(s.x))
        model.learn_one(s.x, s.y)

    assert len(results) == len(samples) > 500
    # every wrench is accounted for: a sample, a drop in the q̈ warm-up, or still pending at the end
    pipeline = est.pipeline
    assert len(results) + est.drops["acceleration_warmup"] + pipeline.n_pending_wrenches == stream.n_wrenches
    assert sum(est.drops.values()) == est.drops["acceleration_warmup"] > 0
    for r, s, p in zip(results, samples, expected, strict=True):
        assert r.learned and r.latency_s >= 0
        assert r.sample.stamp_ns == s.stamp_ns
        assert np.array_equal(r.sample.x, s.x) and np.array_equal(r.sample.y, s.y)
        for part in ("parametric", "residual", "total"):
            np.testing.assert_allclose(getattr(r.prediction, part), getattr(p, part), rtol=0, atol=1e-9)
        np.testing.assert_allclose(r.prediction.total, r.prediction.parametric + r.prediction.residual,
                                   rtol=0, atol=1e-12)
    assert est.n_samples_learned == model.n_samples_seen == len(samples)
    n_out = 6
    if kind == "NP":
        assert est.parameters is None and model.parameters is None
        assert est.model_size == N_FEATURES * n_out
    else:
        np.testing.assert_allclose(est.parameters, model.parameters, rtol=0, atol=1e-10)
        assert len(est.parameter_names) == len(est.parameters) == regressor.n_base
        weights = N_FEATURES * n_out if kind == "SP" else 0  # π and the D × t residual weights
        assert est.model_size == est.parameters.size + weights

    # a-priori: the very first prediction is made with zero parameters (0 up to the round-off of the
    # in-rotation prediction), not with the sample's own label; the residual stage starts after its
    # standardizer warm-up and then actually contributes
    assert np.abs(results[0].prediction.total).max() < 1e-12 < np.abs(results[0].sample.y).max()
    # (the residual stage's part: the consistent model's residual also holds its fast tracker's correction,
    # which works from the first sample)
    residuals = np.array([r.prediction.residual - (0 if r.prediction.correction is None
                                                   else r.prediction.correction) for r in results])
    parametric = np.array([r.prediction.parametric for r in results])
    if kind == "P":
        assert np.all(residuals == 0)
    else:
        # 0 in the warm-up (to the rounding of total − parametric − correction: ≤ 1e-15 of ≈ 10 N outputs)
        assert np.abs(residuals[:WARMUP]).max() < 1e-12
        # the residual is in use after the warm-up (its weight is 0 until its errors are measured)
        assert (np.abs(residuals[WARMUP + 1:]).max(axis=1) > 0).mean() > 0.95
    if kind == "NP":
        assert np.all(parametric == 0)

    # samples: configured joint order, q and q̇ of the nearest joint state (2 ms before the wrench), q̈ the
    # closed-form Savitzky–Golay estimate at that stamp, y the wrench at the wrench stamp
    stamps = np.array([r.sample.stamp_ns for r in results])
    t_js = (stamps - 2_000_000 - T0_NS) * 1e-9
    q, dq, _ = stream.traj(t_js)
    X = np.array([r.sample.x for r in results])
    np.testing.assert_array_equal(X[:, :4], q)
    np.testing.assert_array_equal(X[:, 4:8], dq)
    np.testing.assert_allclose(X[:, 8:], stream.traj.savgol_ddq(t_js, config["acceleration.window"], 0.01),
                               rtol=0, atol=1e-8)


# ----------------------------------------------------------------------------- 2. rigid-body convergence
def _ridge(Phi: np.ndarray, Y: np.ndarray, lam: float) -> np.ndarray:
    return np.linalg.solve(Phi.T @ Phi + lam * np.eye(Phi.shape[1]), Phi.T @ Y)


def test_parametric_model_converges_to_urdf_base_parameters_exact_ddq(config, regressor):
    """step(Sample) with the exact q̈: π̂ is the ridge solution, within λ‖π_b‖/σ_min² of the URDF's."""
    stream = rigid_stream()
    q, dq, ddq = stream.traj(stream.t_js)
    y = regressor.wrench(q, dq, ddq)
    est = OnlineEstimator(config, regressor=regressor, kind="P")
    preds = np.array([est.step(Sample(T0_NS + (i + 1) * DT_NS, q[i], dq[i], ddq[i], y[i])).prediction.total
                      for i in range(len(q))])
    pi_b = regressor.to_base(regressor.urdf_parameters())
    Phi = regressor.base_regressor(q, dq, ddq).reshape(-1, regressor.n_base)
    lam = config["parametric.lam"]
    np.testing.assert_allclose(Phi @ pi_b, y.reshape(-1), rtol=0, atol=1e-10)  # base model is exact

    # the recursive estimate is the closed-form ridge solution on all samples
    np.testing.assert_allclose(est.parameters, _ridge(Phi, y.reshape(-1), lam), rtol=0, atol=1e-9)
    # whose bias λ(ΦᵀΦ + λI)⁻¹π_b is at most λ‖π_b‖/σ_min(Φ)²
    sigma_min = np.linalg.svd(Phi, compute_uv=False)[-1]
    bound = lam * np.linalg.norm(pi_b) / sigma_min**2
    err = np.linalg.norm(est.parameters - pi_b)
    assert err <= bound * (1 + 1e-6) + 1e-10
    assert bound < 1e-5 * np.linalg.norm(pi_b)  # the bound itself is tight: a real convergence check
    # a-priori prediction error: total at first (zero parameters), ~0 at the end
    err_pred = np.abs(preds - y).max(axis=1)
    assert err_pred[0] == pytest.approx(np.abs(y[0]).max())
    row_norm = np.linalg.norm(regressor.base_regressor(q[-300:], dq[-300:], ddq[-300:]), ord=2, axis=(1, 2))
    assert err_pred[-300:].max() <= row_norm.max() * bound * (1 + 1e-6) + 1e-9
    assert err_pred[-300:].max() < 1e-5  # N, N·m, against wrenches of ≈ 20 N


def test_parametric_model_converges_through_pipeline_with_estimated_ddq(config, regressor):
    """Messages → pipeline (Savitzky–Golay q̈) → P model.

    The estimated q̈ is the closed-form SG gain times the true one, so y = Φ̂π_b + e with
    e = (Φ(q̈) − Φ(q̂̈))π_b known; then ‖π̂ − π_b‖ ≤ λ‖π_b‖/σ² + ‖e‖/σ (σ = σ_min(Φ̂)), the tolerance
    asserted here, and the a-priori error at the end is ≤ |e| + ‖Φ̂_i‖ ‖π̂ − π_b‖.
    """
    stream = rigid_stream()
    est = OnlineEstimator(config, regressor=regressor, kind="P")
    results = feed(est, stream.messages)
    assert len(results) > 2900
    assert est.drops["acceleration_warmup"] == config["acceleration.window"] // 2
    t = np.array([(r.sample.stamp_ns - T0_NS) * 1e-9 for r in results])
    q, dq, ddq = stream.traj(t)
    X = np.array([r.sample.x for r in results])
    Y = np.array([r.sample.y for r in results])
    ddq_hat = X[:, 8:]
    np.testing.assert_allclose(ddq_hat, stream.traj.savgol_ddq(t, config["acceleration.window"], 0.01),
                               rtol=0, atol=1e-8)
    rel_ddq = np.abs(ddq_hat - ddq).max() / np.abs(ddq).max()
    assert 1e-4 < rel_ddq < 2e-2  # the SG bias is real but small at these frequencies

    pi_b = regressor.to_base(regressor.urdf_parameters())
    Phi_hat = regressor.base_regressor(q, dq, ddq_hat)
    e = (Y - Phi_hat @ pi_b).reshape(-1)
    np.testing.assert_allclose(Y, regressor.wrench(q, dq, ddq), rtol=0, atol=1e-10)
    Phi_flat = Phi_hat.reshape(-1, regressor.n_base)
    lam = config["parametric.lam"]
    np.testing.assert_allclose(est.parameters, _ridge(Phi_flat, Y.reshape(-1), lam), rtol=0, atol=1e-9)
    sigma = np.linalg.svd(Phi_flat, compute_uv=False)[-1]
    bound = lam * np.linalg.norm(pi_b) / sigma**2 + np.linalg.norm(e) / sigma
    err = np.linalg.norm(est.parameters - pi_b)
    assert err <= bound
    assert bound < 0.02 * np.linalg.norm(pi_b)
    # the largest parameters (mass and first moments of the distal subtree) are recovered to < 0.5 %
    big = np.abs(pi_b) > 0.05
    np.testing.assert_allclose(est.parameters[big], pi_b[big], rtol=5e-3)

    preds = np.array([r.prediction.total for r in results])
    tail = slice(-300, None)
    row_norm = np.linalg.norm(Phi_hat[tail], ord=2, axis=(1, 2))
    err_tail = np.linalg.norm(preds[tail] - Y[tail], axis=1)
    e_tail = np.linalg.norm((Y - Phi_hat @ pi_b)[tail], axis=1)
    assert np.all(err_tail <= e_tail + row_norm * err + 1e-9)
    assert np.sqrt(np.mean(err_tail**2)) < 1e-2 * np.sqrt(np.mean(Y**2))


# ----------------------------------------------------------------------------- 3. checkpoints
@pytest.mark.parametrize("kind", ["NP", "SP"])
def test_the_residual_learns_its_warm_up_unless_told_not_to(config, regressor, kind):
    """``nonparametric.learn_warmup`` (default true): the residual's learner has absorbed every learned
    sample, the standardizer warm-up's included; false: all but the warm-up's, and nothing is held."""
    msgs = rich_stream().messages
    seen = {}
    for flag in (True, False):
        cfg = config.with_overrides({"nonparametric.learn_warmup": flag})
        est = OnlineEstimator(cfg, regressor=regressor, kind=kind)
        feed(est, msgs)
        npm = est.model if kind == "NP" else est.model.nonparametric
        assert npm.learn_warmup is flag and npm.standardizer.ready and npm.held_rows == 0
        warm = npm.standardizer.count_
        assert 0 < warm < npm.n_samples_seen
        seen[flag] = npm.rls.n_samples_seen
        assert seen[flag] == npm.n_samples_seen - (0 if flag else warm)
    assert seen[True] > seen[False]


def test_save_load_gives_bit_identical_predictions(config, regressor, tmp_path):
    msgs = rich_stream().messages
    split = int(len(msgs) * 0.6)
    est = OnlineEstimator(config, regressor=regressor)
    feed(est, msgs[:split])
    path = tmp_path / "ckpt.npz"
    est.save(path)
    assert sorted(os.listdir(tmp_path)) == ["ckpt.npz"]  # atomic: no temp file left behind

    loaded = OnlineEstimator(config, regressor=regressor)
    loaded.load(path)
    assert loaded.n_samples_learned == est.n_samples_learned > 0
    assert np.array_equal(loaded.parameters, est.parameters)
    assert_same_state(snapshot(loaded), snapshot(est))

    rest = feed(est, msgs[split:])
    assert len(rest) > 100
    for r in rest:
        assert_same_prediction(loaded.step(r.sample).prediction, r.prediction)
    assert np.array_equal(loaded.parameters, est.parameters)
    assert_same_state(snapshot(loaded), snapshot(est))

    # overwriting an existing checkpoint is fine and still leaves no temp file
    est.save(path)
    assert sorted(os.listdir(tmp_path)) == ["ckpt.npz"]


@pytest.mark.parametrize("overrides, kind", [
    ({"nonparametric.n_features": 32}, "SP"),
    ({"robot.joints": list(JOINTS[:3])}, "SP"),
    ({"robot.locked_joints": ["r_wrist_prosup"], "robot.locked_positions": [0.3]}, "SP"),
    ({"nonparametric.seed": 7}, "SP"),
    ({}, "P"),
    # baked into the learned state (λ in RᵀR = λI + ΦᵀΦ, β in its forgetting, the standardizer's
    # warm-up): loading would silently run the checkpoint's values while the configuration says otherwise
    ({"parametric.lam": 1.0}, "SP"),
    ({"nonparametric.forgetting": 0.99}, "SP"),
    ({"nonparametric.standardizer_warmup": 20}, "SP"),
], ids=["n_features", "joints", "locked_positions", "seed", "kind", "lam", "forgetting", "warmup"])
def test_checkpoint_of_other_structure_is_refused(config, regressor, tmp_path, overrides, kind):
    other_cfg = config.with_overrides(overrides)
    other = OnlineEstimator(other_cfg, kind=kind)
    other_msgs = rich_stream().messages[:400]
    feed(other, other_msgs)
    path = tmp_path / "other.npz"
    other.save(path)

    est, _ = clean_stream_results(config, regressor, 600)
    before = snapshot(est)
    probe = Sample(T0_NS, np.full(4, 0.2), np.full(4, 0.1), np.full(4, -0.3), np.zeros(6))
    pred_before = est.model.predict_one(probe.x)
    with pytest.raises(ValueError, match="another model structure"):
        est.load(path)
    assert_same_state(snapshot(est), before)
    assert_same_prediction(est.model.predict_one(probe.x), pred_before)


def _truncate(src: Path, dst: Path) -> None:
    data = src.read_bytes()
    dst.write_bytes(data[: len(data) // 2])


def _garbage(src: Path, dst: Path) -> None:
    dst.write_bytes(np.random.default_rng(0).bytes(4096))


def _flip_middle(src: Path, dst: Path) -> None:
    data = bytearray(src.read_bytes())
    mid = len(data) // 2
    data[mid: mid + 64] = bytes(b ^ 0xFF for b in data[mid: mid + 64])  # inverted, so surely changed
    dst.write_bytes(bytes(data))


def _missing_meta(src: Path, dst: Path) -> None:
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files if not k.startswith("meta.")}
    with dst.open("wb") as fh:
        np.savez(fh, **arrays)


def _nan_state(src: Path, dst: Path) -> None:
    with np.load(src) as z:
        arrays = {k: z[k].copy() for k in z.files}
    key = next(k for k in arrays if k.startswith("model.parametric.rls.") and arrays[k].ndim == 2)
    arrays[key][0, 0] = np.nan
    with dst.open("wb") as fh:
        np.savez(fh, **arrays)


def _wrong_version(src: Path, dst: Path) -> None:
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["meta.version"] = np.array(99)
    with dst.open("wb") as fh:
        np.savez(fh, **arrays)


def _missing_model_key(src: Path, dst: Path) -> None:
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files if not k.startswith("model.nonparametric.rff.")}
    with dst.open("wb") as fh:
        np.savez(fh, **arrays)


def _tamper(**changes):
    """A valid archive with some arrays replaced (crafted or bit-rotted metadata and counters)."""
    def corrupt(src: Path, dst: Path) -> None:
        with np.load(src) as z:
            arrays = {k: z[k] for k in z.files}
        arrays.update({k.replace("__", "."): v for k, v in changes.items()})
        with dst.open("wb") as fh:
            np.savez(fh, **arrays)
    return corrupt


@pytest.mark.parametrize("corrupt", [
    _truncate, _garbage, _flip_middle, _missing_meta, _nan_state, _wrong_version, _missing_model_key, None,
    _tamper(meta__version=np.arange(3)),
    _tamper(meta__n_samples_learned=np.array([1, 2])),
    _tamper(meta__n_samples_learned=np.array(-5)),
    _tamper(meta__fingerprint=np.array(3.0)),
    _tamper(model__n_samples_seen=np.arange(2)),
], ids=["truncated", "garbage", "flipped_bytes", "missing_meta", "nan_state", "wrong_version",
        "missing_model_key", "missing_file", "version_vector", "n_learned_vector", "n_learned_negative",
        "fingerprint_number", "model_counter_vector"])
def test_corrupt_checkpoint_raises_value_error_and_keeps_state(config, regressor, tmp_path, corrupt):
    est, _ = clean_stream_results(config, regressor, 600)
    good = tmp_path / "good.npz"
    est.save(good)
    bad = tmp_path / "bad.npz"
    if corrupt is not None:
        corrupt(good, bad)
    feed(est, rich_stream().messages[600:700])  # the live state differs from the file
    before = snapshot(est)
    with pytest.raises(CheckpointError):
        est.load(bad)
    assert_same_state(snapshot(est), before)


def test_failed_save_keeps_previous_checkpoint_and_no_temp_file(config, regressor, tmp_path, monkeypatch):
    est, _ = clean_stream_results(config, regressor, 600)
    path = tmp_path / "ckpt.npz"
    est.save(path)
    original = path.read_bytes()
    feed(est, rich_stream().messages[600:700])

    def broken_savez(fh, **arrays):  # writes part of an archive, then the disk "fills up"
        fh.write(b"PK\x03\x04 half an archive")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(checkpoint_module.np, "savez", broken_savez)
    with pytest.raises(OSError):
        est.save(path)
    monkeypatch.undo()
    assert sorted(os.listdir(tmp_path)) == ["ckpt.npz"]
    assert path.read_bytes() == original
    fresh = OnlineEstimator(config, regressor=regressor)
    fresh.load(path)  # still a valid checkpoint
    assert fresh.n_samples_learned < est.n_samples_learned


# ----------------------------------------------------------------------------- 4. learning disabled
def test_learning_disabled_predicts_without_changing_state(config, regressor):
    msgs = rich_stream().messages
    est, _ = clean_stream_results(config, regressor, 700)
    # a step of the measured output the model has not learned yet: its fast correction follows it
    offset = np.linspace(0.5, 1.5, est.model.n_outputs)
    later = pipeline_samples(config, msgs)[-400:]
    for sample in later[:100]:
        est.step(Sample(sample.stamp_ns, sample.q, sample.dq, sample.ddq, sample.y + offset))
    last_ns = later[99].stamp_ns
    before = snapshot(est)  # (reading the state applies a deferred update: copy after it, bit for bit)
    frozen = est.model.copy()
    est.learning_enabled = False
    results = [est.step(Sample(s.stamp_ns, s.q, s.dq, s.ddq, s.y + offset)) for s in later[100:300]]
    # the fast correction fades with the age of the newest learned sample: exp(−a/τ) per output, a = T ×
    # the samples since it less one (recomputed here from the stamps), τ = min(τ_f, ½(1 + c)T) with c the
    # samples its errors stay correlated (a step of the output: correlated, τ_f on some outputs)
    period = est.sample_period_s
    c = frozen.correlation_samples()
    tau = np.minimum(config["semiparametric.tracker_time_constant"], 0.5 * (1.0 + c) * period)
    corrections = []
    for r in results:
        assert not r.learned
        ref = frozen.predict_one(r.sample.x)
        age = period * max(0, round((r.sample.stamp_ns - last_ns) * 1e-9 / period) - 1)
        fade = np.exp(-age / tau)
        assert ref.correction is not None and r.prediction.correction is not None
        np.testing.assert_allclose(r.prediction.correction, fade * ref.correction, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(r.prediction.total, ref.total - (1.0 - fade) * ref.correction,
                                   rtol=1e-12, atol=1e-12)
        assert np.array_equal(r.prediction.parametric, ref.parametric)
        assert np.abs(r.prediction.residual).max() > 0  # both stages still predict
        corrections.append(np.abs(ref.correction).max())
    assert min(corrections[:5]) > 0.1  # there was a correction to fade
    assert_same_state(snapshot(est), before)

    # learning resumes where it stopped
    est.learning_enabled = True
    more = feed(est, msgs[900:1000])
    assert all(r.learned for r in more)
    assert est.n_samples_learned == int(before["n_samples_learned"]) + len(more)

    # the configuration switch is honoured from the start
    off = OnlineEstimator(config.with_overrides({"learning_enabled": False}), regressor=regressor)
    res = feed(off, msgs[:300])
    assert res and not any(r.learned for r in res)
    assert off.n_samples_learned == 0 and np.all(off.parameters == 0)
    assert all(np.all(r.prediction.total == 0) for r in res)


def test_age_counts_the_samples_since_the_newest_learned_one(config, regressor):
    """The age the fast correction fades with: T × (samples since the newest learned one − 1)."""
    est, learned = clean_stream_results(config, regressor, 300)
    period = est.sample_period_s
    assert period is not None
    last = learned[-1].sample.stamp_ns
    step = period * 1e9
    assert est.age_at(last + round(step)) == 0.0            # the next sample
    assert est.age_at(last + round(1.4 * step)) == 0.0      # jitter below half a period
    assert est.age_at(last + round(3.0 * step)) == pytest.approx(2.0 * period, rel=1e-12)
    assert est.age_at(last - round(step)) == 0.0            # a stamp before it
    est.start_recording()                                   # another recording: no age carried over
    assert est.age_at(last + round(100 * step)) == 0.0


def _twins(config, regressor, samples):
    """Two estimators that learned the same samples (the one under test and its reference)."""
    est, ref = OnlineEstimator(config, regressor=regressor), OnlineEstimator(config, regressor=regressor)
    for sample in samples:
        est.step(sample)
        ref.step(sample)
    return est, ref


def test_skipped_learning_predicts_with_the_residual_held_and_leaves_the_learned_state(config, regressor):
    """``step(skip_learning=True)``: what a node that falls behind does with a late sample.

    Reference: a second estimator fed only the samples that were learned. The state is the same to
    rounding (a held prediction learns nothing); the rigid-body part of a held prediction is the full
    model's; its residual is the one of the last full prediction, which at 100 Hz (a residual moving
    10 ms between samples) is within 10 % of the residual's size of the full prediction.
    """
    samples = pipeline_samples(config, rich_stream().messages)
    est, ref = _twins(config, regressor, samples[:300])
    errors, sizes, last = [], [], None
    for i, sample in enumerate(samples[300:]):
        if i % 2 == 0:
            last = est.step(sample).prediction
            ref.step(sample)
            continue
        full = ref.model.copy().predict_one(sample.x, return_variance=True)
        got = est.step(sample, skip_learning=True)
        assert not got.learned and got.verdict is None
        assert got.std is not None and np.all(np.isfinite(got.std))
        np.testing.assert_allclose(got.prediction.parametric, full.parametric, rtol=1e-12, atol=1e-12)
        # the model's residual, held (residual = total − rigid body: equal to the rounding of those sums)
        held = got.prediction.residual - got.prediction.correction
        scale = 1.0 + np.abs(got.prediction.total).max() + np.abs(last.total).max()
        np.testing.assert_allclose(held, last.residual - last.correction, rtol=0, atol=1e-13 * scale)
        errors.append(np.abs(got.prediction.total - full.total).max())
        sizes.append(np.abs(full.residual).max())
    assert est.n_learning_skipped == len(errors) > 100
    assert est.n_samples_learned == ref.n_samples_learned
    # the same state to rounding: a held prediction runs the fast correction's deferred rotations before
    # the next prediction instead of inside it (the same arithmetic in another order, RecursiveRLS)
    assert_close_state(snapshot(est), snapshot(ref))
    assert np.mean(errors) < 0.1 * np.mean(sizes)


def test_a_late_sample_is_predicted_cheaply_with_learning_disabled_too(config, regressor):
    """A node serving a frozen model (``learning_enabled: false``) that falls behind predicts a late sample
    as a learning one does: the rigid-body part at the sample, the residual held from the last full
    prediction, nothing learned, counted; the state stays bit-identical to an estimator that predicted
    every sample in full."""
    samples = pipeline_samples(config, rich_stream().messages)
    est, ref = _twins(config, regressor, samples[:300])
    est.learning_enabled = ref.learning_enabled = False
    last = est.step(samples[300]).prediction
    ref.step(samples[300])
    got = est.step(samples[301], skip_learning=True)
    full = ref.step(samples[301]).prediction
    assert not got.learned and est.n_learning_skipped == 1
    np.testing.assert_allclose(got.prediction.parametric, full.parametric, rtol=1e-12, atol=1e-12)
    held = got.prediction.residual - got.prediction.correction
    scale = 1.0 + np.abs(last.total).max()
    np.testing.assert_allclose(held, last.residual - last.correction, rtol=0, atol=1e-13 * scale)
    assert est.n_samples_learned == ref.n_samples_learned
    assert_close_state(snapshot(est), snapshot(ref))


# ----------------------------------------------------------------------------- 5. reset
@pytest.mark.parametrize("loaded", [False, True], ids=["trained", "trained_and_loaded"])
def test_reset_forgets_everything(config, regressor, tmp_path, loaded):
    msgs = rich_stream().messages
    est, first = clean_stream_results(config, regressor)
    if loaded:  # a warm-started estimator must reset to the configuration, not to the checkpoint
        est.save(tmp_path / "ckpt.npz")
        est = OnlineEstimator(config, regressor=regressor)
        est.load(tmp_path / "ckpt.npz")
    assert np.abs(est.parameters).max() > 0.1 and est.n_samples_learned > 0
    est.reset()
    assert np.all(est.parameters == 0)
    assert est.n_samples_learned == 0 and est.model.n_samples_seen == 0
    # replaying the stream after a reset gives exactly what a fresh estimator gives (the pipeline's
    # streaming state is cleared too: the same q̈ warm-up, the same samples)
    again = feed(est, msgs)
    assert len(again) == len(first)
    for a, b in zip(again, first, strict=True):
        assert a.sample.stamp_ns == b.sample.stamp_ns
        assert_same_prediction(a.prediction, b.prediction)


# ----------------------------------------------------------------------------- 6. bad messages
def _js_like(js: JointStateData, **changes) -> JointStateData:
    fields = {"stamp_ns": js.stamp_ns, "names": js.names, "position": js.position.copy(),
              "velocity": js.velocity.copy(), "effort": js.effort.copy()}
    fields.update(changes)
    return JointStateData(**fields)


def _set_joint(js: JointStateData, field: str, joint: str, value: float) -> JointStateData:
    arr = getattr(js, field).copy()
    arr[js.names.index(joint)] = value
    return _js_like(js, **{field: arr})


def _bad_messages(prev_js: JointStateData, prev_w: WrenchData) -> list[tuple[object, str | None]]:
    """Bad variants injected right after an accepted pair: (message, expected drop reason or None)."""
    s = prev_js.stamp_ns + DT_NS // 2  # between two good stamps: would be accepted if it were clean
    js = _js_like(prev_js, stamp_ns=s)
    w = WrenchData(prev_w.stamp_ns + DT_NS // 2, FRAME, prev_w.force, prev_w.torque)
    keep = [i for i, n in enumerate(js.names) if n != "r_elbow"]
    return [
        (_set_joint(js, "position", "r_elbow", np.nan), "nonfinite_joint_state"),
        (_set_joint(js, "velocity", "r_shoulder_roll", np.inf), "nonfinite_joint_state"),
        (_js_like(js, names=tuple(js.names[i] for i in keep), position=js.position[keep],
                  velocity=js.velocity[keep], effort=js.effort[keep]), "missing_joint"),
        (_js_like(js, stamp_ns=prev_js.stamp_ns - 3 * DT_NS), "joint_state_backwards_stamp"),
        (_js_like(js, stamp_ns=prev_js.stamp_ns), "joint_state_repeated_stamp"),
        (_js_like(js, stamp_ns=0), "joint_state_zero_stamp"),
        (_js_like(js, position=js.position[:-1]), "length_mismatch"),
        (_js_like(js, names=(*js.names[:-1], js.names[0])), "duplicate_joint"),
        (WrenchData(w.stamp_ns, FRAME, [np.nan, 0.0, 0.0], w.torque), "nonfinite_wrench"),
        (WrenchData(w.stamp_ns, FRAME, w.force, [0.0, -np.inf, 0.0]), "nonfinite_wrench"),
        (WrenchData(prev_w.stamp_ns - 3 * DT_NS, FRAME, w.force, w.torque), "wrench_backwards_stamp"),
        (WrenchData(prev_w.stamp_ns, FRAME, w.force, w.torque), "wrench_repeated_stamp"),
        (WrenchData(w.stamp_ns, "l_arm_ft_sensor", w.force, w.torque), "wrong_frame_id"),
        (WrenchData(w.stamp_ns, FRAME, w.force[:2], w.torque), "length_mismatch"),
    ]


def test_bad_messages_are_counted_and_do_not_change_learned_state(config, regressor):
    msgs = rich_stream().messages
    clean, clean_results = clean_stream_results(config, regressor)

    est = OnlineEstimator(config, regressor=regressor)
    results: list[StepResult] = []
    expected: dict[str, int] = {}
    last_js = last_w = None
    injected = 0
    for i, msg in enumerate(msgs):
        if isinstance(msg, JointStateData):
            results.extend(est.process(msg))
            last_js = msg
        else:
            results.extend(est.process(msg))
            last_w = msg
        if i % 97 == 50 and last_js is not None and last_w is not None:
            for bad, reason in _bad_messages(last_js, last_w):
                before = snapshot(est)
                drops_before = est.drops
                assert est.process(bad) == []
                assert_same_state(snapshot(est), before)
                diff = {k: v - drops_before[k] for k, v in est.drops.items() if v != drops_before[k]}
                assert diff == {reason: 1}, (reason, diff)
                expected[reason] = expected.get(reason, 0) + 1
                injected += 1
    assert injected >= 5 * 14

    # the bad messages changed nothing: same samples, predictions and final state — to rounding, because
    # this test's own snapshots of the state run the learners' deferred rotations, so the next prediction
    # is a solve after the update instead of fused with it (RecursiveRLS: the same arithmetic reordered)
    assert len(results) == len(clean_results)
    for a, b in zip(results, clean_results, strict=True):
        assert a.sample.stamp_ns == b.sample.stamp_ns
        for part in ("parametric", "residual", "total"):
            np.testing.assert_allclose(getattr(a.prediction, part), getattr(b.prediction, part),
                                       rtol=1e-9, atol=1e-12, err_msg=part)
    state, clean_state = snapshot(est), snapshot(clean)
    # the residual's aged copies hold W = R⁻¹d: rounding in [R | d] reaches W amplified by up to cond(R)
    W, W_clean = state.pop("aged_copies"), clean_state.pop("aged_copies")
    amplified = 1e-9 * np.linalg.cond(clean.model.nonparametric.rls.R)
    np.testing.assert_allclose(W, W_clean, rtol=0, atol=amplified * float(np.abs(W_clean).max()))
    assert_close_state(state, clean_state)
    for reason, count in expected.items():
        assert est.drops[reason] == count
    assert est.drops["acceleration_warmup"] == clean.drops["acceleration_warmup"]


def test_unused_joint_garbage_is_ignored(config, regressor):
    """NaN in an extra (not configured) joint or in the efforts does not drop a wrench-learning sample."""
    msgs = rich_stream().messages[:400]
    dirty = []
    for msg in msgs:
        if isinstance(msg, JointStateData):
            msg = _set_joint(msg, "position", "neck_pitch", np.nan)
            msg = _js_like(msg, effort=np.full(len(msg.names), np.nan))
        dirty.append(msg)
    a = OnlineEstimator(config, regressor=regressor)
    b = OnlineEstimator(config, regressor=regressor)
    ra, rb = feed(a, msgs), feed(b, dirty)
    assert len(ra) == len(rb) > 180
    for x, y in zip(ra, rb, strict=True):
        assert_same_prediction(x.prediction, y.prediction)
    assert a.drops == b.drops


def test_absurd_finite_values_are_counted_not_raised(config, regressor):
    """A finite but absurd velocity (1e200 rad/s) is dropped by the pipeline's plausibility limits; with
    them switched off it passes the NaN/inf screen and poisons the q̈ window: the learner must reject
    exactly the samples it touches, counted as drops, without raising, and learn every other sample
    exactly as if the bad joint state had been absent."""
    msgs = rich_stream().messages
    window = config["acceleration.window"]
    idx = next(i for i in range(300, len(msgs)) if isinstance(msgs[i], JointStateData))
    js = msgs[idx]
    bad = _set_joint(js, "velocity", "r_elbow", 1e200)
    dirty = (*msgs[:idx], bad, *msgs[idx + 1:])
    # with the shipped plausibility limits the pipeline drops the joint state first
    screened = OnlineEstimator(config, regressor=regressor)
    feed(screened, dirty)
    assert screened.drops["implausible_value"] == 1 and screened.drops["rejected_sample"] == 0
    # without them the glitch check drops it (an increment 1e200 times the running one) ...
    unbounded = OnlineEstimator(config.with_overrides({"limits.max_abs_velocity": 0.0}), regressor=regressor)
    feed(unbounded, dirty)
    assert unbounded.drops["glitch"] == 1 and unbounded.drops["rejected_sample"] == 0
    # ... and without both screens the learner's own check is the last line of defence
    config = config.with_overrides({"limits.max_abs_velocity": 0.0, "limits.glitch_ratio": 0.0})
    est = OnlineEstimator(config, regressor=regressor)
    results = feed(est, dirty)  # must not raise

    # the SG derivative at stamps k-4..k+4 has a nonzero weight on q̇_k (at k itself q̇_k is in x)
    poisoned = {js.stamp_ns + j * DT_NS + 2_000_000 for j in range(-(window // 2), window // 2 + 1)}
    assert est.drops["rejected_sample"] == len(poisoned) == window
    assert {r.sample.stamp_ns for r in results}.isdisjoint(poisoned)

    # reference: the clean stream's samples minus the poisoned ones, stepped one by one
    ref = OnlineEstimator(config, regressor=regressor)
    kept = [s for s in pipeline_samples(config, msgs) if s.stamp_ns not in poisoned]
    assert len(kept) == len(results)
    for r, s in zip(results, kept, strict=True):
        assert r.sample.stamp_ns == s.stamp_ns and np.array_equal(r.sample.x, s.x)
        assert_same_prediction(r.prediction, ref.step(s).prediction)
    assert_same_state(snapshot(est), snapshot(ref))
    assert est.n_samples_learned == len(results)

    est.reset()
    # step() itself keeps its contract: a bad sample is a RejectedSampleError, state unchanged
    before = snapshot(est)
    with pytest.raises(RejectedSampleError):
        est.step(Sample(T0_NS, np.zeros(4), np.full(4, 1e200), np.zeros(4), np.zeros(6)))
    assert_same_state(snapshot(est), before)


@pytest.mark.parametrize("error", [TypeError, IndexError, ValueError], ids=lambda e: e.__name__)
def test_programming_errors_propagate_and_are_not_counted_as_drops(config, regressor, monkeypatch, error):
    """Only RejectedSampleError is a drop: a bug inside the learner (here injected) must surface, with
    the drop counters untouched, and the estimator still works once the bug is gone."""
    msgs = rich_stream().messages
    est = OnlineEstimator(config, regressor=regressor)
    feed(est, msgs[:300])
    drops_before, learned_before = est.drops, est.n_samples_learned
    assert learned_before > 0 and drops_before["rejected_sample"] == 0

    def buggy(x, y):
        raise error("injected bug")

    monkeypatch.setattr(est.model, "predict_learn_one", buggy)
    monkeypatch.setattr(est.model, "learn_ahead_checked", buggy)  # how the consistent SP learns
    with pytest.raises(error, match="injected bug"):
        feed(est, msgs[300:310])
    assert est.drops == drops_before and est.n_samples_learned == learned_before

    # the learner's own refusal, by contrast, is a counted drop and the stream goes on
    def rejecting(x, y):
        raise RejectedSampleError("x contains NaN")

    est = OnlineEstimator(config, regressor=regressor)
    feed(est, msgs[:300])
    monkeypatch.setattr(est.model, "predict_learn_one", rejecting)
    monkeypatch.setattr(est.model, "learn_ahead_checked", rejecting)
    rejected = feed(est, msgs[300:330])
    n_paired = len(pipeline_samples(config, msgs[:330])) - len(pipeline_samples(config, msgs[:300]))
    assert rejected == [] and n_paired > 0
    assert est.drops["rejected_sample"] == n_paired
    assert est.n_samples_learned == learned_before
    assert issubclass(RejectedSampleError, ValueError) and not issubclass(TypeError, RejectedSampleError)


# ----------------------------------------------------------------------------- other outputs and options
def test_joint_torque_stream_one_data_path(config):
    """output = joint_torques: JointState.effort (RNEA torques + residual) is the label, wrenches ignored."""
    import pinocchio as pin

    cfg = config.with_overrides({"robot.output": "joint_torques"})
    est = OnlineEstimator(cfg)
    reg = est.regressor
    assert reg.n_outputs == 4
    assert est.stick is not None  # friction that remembers: composed by hand below
    model, data = reg.pinocchio_model, reg.pinocchio_model.createData()
    traj = make_trajectory(reg, seed=5)
    t = np.arange(1, 401) * DT_NS * 1e-9
    q, dq, ddq = traj(t)
    tau = np.array([pin.rnea(model, data, q[i], dq[i], ddq[i]) for i in range(len(t))])
    tau = tau + 0.3 * np.tanh(3 * dq)  # friction-like residual (N·m)
    rng = np.random.default_rng(5)
    names = JOINTS + EXTRA_JOINTS
    msgs: list[JointStateData | WrenchData] = []
    for i in range(len(t)):
        perm = rng.permutation(len(names))
        pad = np.zeros(len(EXTRA_JOINTS))
        stamp = T0_NS + (i + 1) * DT_NS
        msgs.append(JointStateData(stamp, tuple(names[j] for j in perm), np.concatenate([q[i], pad])[perm],
                                   np.concatenate([dq[i], pad])[perm], np.concatenate([tau[i], pad])[perm]))
        if i % 10 == 0:
            msgs.append(WrenchData(stamp, FRAME, [1.0, 2.0, 3.0], [0.1, 0.2, 0.3]))
    results = feed(est, msgs)
    assert est.drops["wrench_ignored"] == 40

    samples = pipeline_samples(cfg, msgs)
    hand = build_model(cfg, "SP")
    stick = StickFriction(4, cfg["parametric.stick_displacement"], cfg["parametric.coulomb_velocity"],
                          est.stick.time_constant_s)
    assert len(results) == len(samples) > 380
    for r, s in zip(results, samples, strict=True):
        phi = stick.step(s.q, s.dq)
        held = stick.torque(phi)  # joins the rigid-body part; the learner learns y − it
        ahead = hand.predict_ahead(s.x)  # a priori; the stick learns the learned rigid body's error Φπ̂
        p = ahead.prediction
        stick.learn(s.stamp_ns, phi, s.y - ahead.Phi @ hand.parametric.parameters)
        hand.learn_ahead(ahead, s.y - held)
        for part, want in (("parametric", p.parametric + held), ("residual", p.residual),
                           ("total", p.total + held)):
            np.testing.assert_allclose(getattr(r.prediction, part), want, rtol=0, atol=1e-9)
    assert np.abs(stick.coefficient).max() > 0.01
    # labels are the efforts of the configured joints, in the configured order, at the sample stamp
    k = np.array([(r.sample.stamp_ns - T0_NS) // DT_NS - 1 for r in results])
    np.testing.assert_array_equal(np.array([r.sample.y for r in results]), tau[k])
    assert est.model_size == est.parameters.size + N_FEATURES * len(tau[0])  # π and the D × t weights


def test_sensor_offset_is_identified(config):
    """parametric.sensor_offset adds six constant wrench offsets to the base parameters; with exact q̈
    they and the inertial base parameters are recovered within the ridge bias bound."""
    cfg = config.with_overrides({"parametric.sensor_offset": True})
    est = OnlineEstimator(cfg, kind="P")
    reg = est.regressor
    plain = build_regressor(config)
    assert reg.n_base == plain.n_base + 6
    assert est.parameter_names[-6:] == tuple(f"offset_{a}" for a in ("fx", "fy", "fz", "tx", "ty", "tz"))
    offset = np.array([1.5, -0.7, 2.0, 0.05, -0.12, 0.3])  # N, N·m
    traj = make_trajectory(plain, seed=3)
    t = np.arange(1, 2001) * DT_NS * 1e-9
    q, dq, ddq = traj(t)
    y = plain.wrench(q, dq, ddq) + offset  # generated without the offset machinery
    for i in range(len(t)):
        est.step(Sample(T0_NS + i, q[i], dq[i], ddq[i], y[i]))
    pi_full = reg.urdf_parameters()
    pi_full[-6:] = offset
    pi_b = reg.to_base(pi_full)
    Phi = reg.base_regressor(q, dq, ddq).reshape(-1, reg.n_base)
    lam = cfg["parametric.lam"]
    bound = lam * np.linalg.norm(pi_b) / np.linalg.svd(Phi, compute_uv=False)[-1] ** 2
    assert np.linalg.norm(est.parameters - pi_b) <= bound * (1 + 1e-6) + 1e-10
    np.testing.assert_allclose(est.parameters[-6:], offset, rtol=0, atol=1e-4)


def test_bag_replay_gives_the_same_numbers(config, regressor, tmp_path):
    """The stream written to a rosbag2/MCAP bag and read back gives bit-identical results (float64 CDR)."""
    from semiparam_ros.io.bags import BagWriter, read_messages

    msgs = rich_stream().messages[:500]
    bag = tmp_path / "stream"
    with BagWriter(bag) as writer:
        for msg in msgs:  # log time = header stamp: the arrival order of the list
            if isinstance(msg, JointStateData):
                writer.write_joint_state("/joint_states", msg)
            else:
                writer.write_wrench("/wrench", msg)
    live = feed(OnlineEstimator(config, regressor=regressor), msgs)
    replay = feed(OnlineEstimator(config, regressor=regressor), read_messages(bag))
    assert len(replay) == len(live) > 200
    for a, b in zip(replay, live, strict=True):
        assert a.sample.stamp_ns == b.sample.stamp_ns
        assert np.array_equal(a.sample.x, b.sample.x) and np.array_equal(a.sample.y, b.sample.y)
        assert_same_prediction(a.prediction, b.prediction)


def test_warmup_at_rest_does_not_break_the_residual_stage():
    """A robot that sits still while the residual stage's standardization warms up: the warm-up measures
    only sensor noise; the scale floors (nonparametric.min_scale.*) keep later motion in a useful range,
    so the error after the robot starts moving stays close to a warm-up on motion. Without the floors
    the same start costs SP 1.5 times its error (and NP tens of times)."""
    cfg = load_config(CONFIG_PATH).with_overrides(
        {"nonparametric.n_features": 200})
    samples = list(iter_samples(CONFIG_PATH.parents[1] / "bags" / "icub_xy", build_pipeline(cfg)))
    X = np.array([s.x for s in samples])
    Y = np.array([s.y for s in samples])
    n = len(cfg["robot.joints"])
    rng = np.random.default_rng(0)
    x0 = X[0].copy()
    x0[n:] = 0.0  # at rest at the first pose: q̇ = q̈ = 0, plus encoder noise
    rest_x = x0 + rng.normal(0.0, 1e-4, (cfg["nonparametric.standardizer_warmup"], X.shape[1]))
    rest_y = Y[0] + rng.normal(0.0, 0.3, (len(rest_x), 6)) * np.array([1, 1, 1, 0.1, 0.1, 0.1])

    def tail_force_rmse(config, at_rest_first: bool) -> float:
        model = build_model(config, "SP")
        if at_rest_first:
            for x, y in zip(rest_x, rest_y, strict=True):
                model.learn_one(x, y)
        err = np.array([y - model.predict_learn_one(x, y).total for x, y in zip(X, Y, strict=True)])
        return float(np.sqrt(np.mean(err[-1000:, :3] ** 2)))

    moving = tail_force_rmse(cfg, False)
    assert tail_force_rmse(cfg, True) < 1.25 * moving
    no_floor = cfg.with_overrides({f"nonparametric.min_scale.{k}": 0.0
                                   for k in ("position", "velocity", "acceleration", "force", "torque")})
    # (the residual's weight, which follows the rigid-body part's recent error, limits the damage: 1.5×)
    assert tail_force_rmse(no_floor, True) > 1.4 * moving


# ----------------------------------------------------------------------------- 5. joint semiparametric fit
BAG_XY = CONFIG_PATH.parents[1] / "bags" / "icub_xy"


def test_joint_combination_online_equals_offline_model_and_checkpoint_round_trips(config, tmp_path):
    """``semiparametric.combination: joint``: the estimator fed a committed bag's messages predicts exactly
    what a ``build_model(config, "SP")`` joint model driven offline (a second pipeline, predict before
    learn) predicts; its checkpoint restores bit-identical predictions; a cascade estimator refuses it."""
    from itertools import islice

    from semiparam_ros.core.learners.cascade import SemiparametricModel
    from semiparam_ros.core.learners.joint import JointSemiparametricModel
    from semiparam_ros.io.bags import read_messages

    cfg = config.with_overrides({"semiparametric.combination": "joint"})
    msgs = list(islice(read_messages(BAG_XY), 1000))  # the first ≈5 s: joint states and wrenches at 100 Hz
    est = OnlineEstimator(cfg)
    assert isinstance(est.model, JointSemiparametricModel)
    split = 600
    first = feed(est, msgs[:split])
    path = tmp_path / "joint.npz"
    est.save(path)
    rest = feed(est, msgs[split:])
    results = first + rest

    samples = pipeline_samples(cfg, msgs)
    model = build_model(cfg, "SP")
    assert isinstance(model, JointSemiparametricModel)
    assert len(results) == len(samples) > 400 and len(first) > WARMUP and len(rest) > 100
    for r, s in zip(results, samples, strict=True):
        assert r.learned and r.sample.stamp_ns == s.stamp_ns
        assert np.array_equal(r.sample.x, s.x) and np.array_equal(r.sample.y, s.y)
        p = model.predict_one(s.x)
        model.learn_one(s.x, s.y)
        for part in ("parametric", "residual", "total"):
            np.testing.assert_allclose(getattr(r.prediction, part), getattr(p, part), rtol=0, atol=1e-9)
    np.testing.assert_allclose(est.parameters, model.parameters, rtol=0, atol=1e-10)
    assert est.n_samples_learned == model.n_samples_seen == len(samples)
    # both terms contribute: the kernel term after the standardizer warm-up, the rigid-body term throughout
    residuals = np.array([r.prediction.residual for r in results])
    assert np.abs(residuals[WARMUP + 1:]).max() > 0 and np.abs(est.parameters).max() > 0

    loaded = OnlineEstimator(cfg)
    loaded.load(path)
    assert loaded.n_samples_learned == len(first)
    for r in rest:
        assert_same_prediction(loaded.step(r.sample).prediction, r.prediction)
    assert_same_state(snapshot(loaded), snapshot(est))

    cascade = OnlineEstimator(config.with_overrides({"semiparametric.combination": "cascade"}))
    assert isinstance(cascade.model, SemiparametricModel)
    before = snapshot(cascade)
    with pytest.raises(ValueError, match=r"semiparametric_joint|combination|another model structure"):
        cascade.load(path)
    assert_same_state(snapshot(cascade), before)


def test_joint_combination_with_unequal_forgetting_is_refused(config):
    for overrides in ({"parametric.forgetting": 0.99}, {"nonparametric.forgetting": 0.995}):
        with pytest.raises(ValueError, match=r"'parametric\.forgetting' and 'nonparametric\.forgetting'"):
            config.with_overrides({"semiparametric.combination": "joint", **overrides})
    # equal factors below 1 are fine: one data weighting for both terms
    joint = config.with_overrides({"semiparametric.combination": "joint", "parametric.forgetting": 0.99,
                                   "nonparametric.forgetting": 0.99})
    assert OnlineEstimator(joint).model.forgetting == 0.99


def test_a_checkpoint_of_the_former_default_cascade_is_refused_with_the_way_to_load_it(config, tmp_path):
    """Checkpoints written before the consistent learner became the default hold the paper's cascade: the
    default refuses them by name and says which setting loads them; that setting does."""
    cascade_cfg = config.with_overrides({"semiparametric.combination": "cascade"})
    old = OnlineEstimator(cascade_cfg)
    feed(old, rich_stream().messages[:300])
    path = tmp_path / "old.npz"
    old.save(path)
    with pytest.raises(CheckpointError, match=r"semiparametric\.combination: cascade to load it"):
        OnlineEstimator(config).load(path)
    again = OnlineEstimator(cascade_cfg)
    again.load(path)
    assert again.n_samples_learned == old.n_samples_learned


def test_an_inline_projection_that_fails_keeps_the_last_solution_and_loses_no_sample(tmp_path, monkeypatch):
    """Offline, the projection is solved in line; a solver failure or a non-finite solution keeps what the
    model predicted with (here: the learned parameters), and the sample at which it was due is still
    predicted and learned (nothing counted as rejected). A good solution after it is applied."""
    from dataclasses import replace

    from helpers.bags import ur5_config, write_ur5_torque_bag

    import semiparam_ros.core.estimator.online as online
    from semiparam_ros.eval.bags.replay import load_samples

    write_ur5_torque_bag(tmp_path / "log", 6.0, seed=3)
    cfg = ur5_config().with_overrides({"parametric.consistent_period": 1.0})
    data, _ = load_samples(tmp_path / "log", cfg)
    real = online.consistent_parameters
    calls: list[str] = []

    def flaky(*args, **kwargs):
        calls.append("call")
        if len(calls) == 1:
            raise ConfigurationError("the consistent projection failed: solver status infeasible")
        good = real(*args, **kwargs)
        return good if len(calls) > 2 else replace(good, base=np.full_like(good.base, np.nan))

    monkeypatch.setattr(online, "consistent_parameters", flaky)
    est = OnlineEstimator(cfg)
    est.inline_projection = True
    est.learning_enabled = True
    n = len(cfg["robot.joints"])
    learned_at_failures = []
    for stamp, x, y in zip(data.stamps_ns, data.X, data.Y, strict=True):
        before = len(calls)
        result = est.step(Sample(int(stamp), x[:n], x[n:2 * n], x[2 * n:], y))
        if len(calls) > before and len(calls) <= 2:
            learned_at_failures.append(result.learned)
            assert est.model.rigid_override is None  # still the learned parameters
    assert len(calls) >= 3 and learned_at_failures == [True, True]
    assert est.drops["rejected_sample"] == 0
    assert est.model.rigid_override is not None and np.isfinite(est.model.rigid_override).all()


def test_the_rigid_body_model_predicts_with_the_consistent_projection_it_serves(tmp_path):
    """P takes the projection too: after the first solution its predictions are Φ(x)θ with θ the solution
    it was handed, while it keeps learning π̂ unconstrained — equal to a twin that never took one; a new
    solution is the projection of its state in learner units; None and a bad value leave the learned π̂."""
    from helpers.bags import ur5_config, write_ur5_torque_bag

    from semiparam_ros.core.learners.parametric import ParametricModel
    from semiparam_ros.core.rigid_body.identification import consistent_parameters
    from semiparam_ros.eval.bags.replay import load_samples

    write_ur5_torque_bag(tmp_path / "log", 4.0, seed=4)
    cfg = ur5_config().with_overrides({"parametric.consistent_period": 1.0, "gate.enabled": False})
    data, _ = load_samples(tmp_path / "log", cfg)
    est, twin = OnlineEstimator(cfg, kind="P"), OnlineEstimator(cfg, kind="P")
    est.inline_projection = True
    assert isinstance(est.model, ParametricModel) and est.projects
    n = len(cfg["robot.joints"])
    samples = [Sample(int(s), x[:n], x[n:2 * n], x[2 * n:], y)
               for s, x, y in zip(data.stamps_ns, data.X, data.Y, strict=True)]
    for s in samples[:-1]:
        est.step(s)
        twin.step(s)
    theta = est.model.rigid_override
    assert theta is not None
    np.testing.assert_array_equal(est.model.parameters, twin.model.parameters)  # learning unchanged
    last = samples[-1]
    stick = est.stick  # friction that remembers: the torque its state holds joins the rigid body
    c = stick.coefficient.copy()  # as predicted, before the sample is learned
    got = est.step(last).prediction
    Phi = est.model.regressor(np.concatenate([last.q, last.dq, last.ddq]))
    held = c * (stick.state.z - np.tanh(last.dq / stick.coulomb_velocity))
    np.testing.assert_allclose(got.total, Phi @ theta + held, rtol=1e-12, atol=1e-12)
    assert np.abs(got.total - twin.step(last).prediction.total).max() > 1e-6  # not the learned π̂
    # the projection of the final state, solved the same way, is what a new solution would set
    rigid, R, lam = est.rigid_body_state()
    sol = consistent_parameters(est.regressor, rigid, R, est.column_scale, lam)
    est.use_consistent(sol)
    np.testing.assert_allclose(est.model.rigid_override, est.column_scale * np.asarray(sol.base), rtol=1e-15)
    est.use_consistent(None)
    assert est.model.rigid_override is None
    with pytest.raises(RejectedSampleError):
        est.model.use_rigid(np.full(est.model.n_params, np.nan))
    assert est.model.rigid_override is None


def test_a_checkpoint_carries_the_period_it_was_learned_at(tmp_path):
    """A loaded model converts its constants in seconds at the period its state was learned at (not the
    provisional one) until its own stream's period is measured: the consistent SP's correlation window,
    so its served weight and σ, equal the live model's (served predictions to 1e-9). A corrupt stored
    period is refused with the estimator unchanged; a checkpoint without one loads as before."""
    from helpers.bags import ur5_config, write_ur5_torque_bag

    from semiparam_ros import load_model
    from semiparam_ros.core.checkpoint import atomic_save_npz as save_npz
    from semiparam_ros.core.checkpoint import load_npz
    from semiparam_ros.eval.bags.replay import load_samples

    write_ur5_torque_bag(tmp_path / "log", 4.0, seed=5, rate_hz=250.0)
    cfg = ur5_config()
    data, _ = load_samples(tmp_path / "log", cfg)
    est = OnlineEstimator(cfg)
    n = len(cfg["robot.joints"])
    for s, x, y in zip(data.stamps_ns, data.X, data.Y, strict=True):
        est.step(Sample(int(s), x[:n], x[n:2 * n], x[2 * n:], y))
    period = est.sample_period_s
    assert period is not None and abs(period - 0.01) > 1e-3  # another rate than the provisional 100 Hz
    est.save(tmp_path / "a.npz")
    served = load_model(tmp_path / "a.npz")
    np.testing.assert_allclose(served.estimator.model.correlation_samples(), est.model.correlation_samples(),
                               rtol=1e-12)
    X = data.X[::50]
    want = est.model.predict_model_many(X)
    got = served.estimator.model.predict_model_many(X)
    np.testing.assert_allclose(got.total, want.total, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got.variance, want.variance, rtol=1e-9)
    state = load_npz(tmp_path / "a.npz")
    for bad in (np.array(-1.0), np.array(np.nan), np.array("fast")):
        broken = dict(state, **{"meta.sample_period_s": bad})
        save_npz(tmp_path / "b.npz", broken)
        fresh = OnlineEstimator(cfg)
        before = fresh.model.predict_one(data.X[0]).total
        with pytest.raises(CheckpointError, match="sample_period_s"):
            fresh.load(tmp_path / "b.npz")
        np.testing.assert_array_equal(fresh.model.predict_one(data.X[0]).total, before)
    old = {k: v for k, v in state.items() if k != "meta.sample_period_s"}
    save_npz(tmp_path / "c.npz", old)
    OnlineEstimator(cfg).load(tmp_path / "c.npz")  # written before the period was stored: loads


def test_a_version_3_checkpoint_uses_its_residual_on_every_output_and_says_so(config, tmp_path):
    """Format 3 had no test of the residual on an aged copy: migrated, the model uses its residual on every
    output (as it did then), predicts as the model that wrote it with that mask, and says so once; the same
    array missing from a version-4 file is a corrupt file."""
    from semiparam_ros.core.checkpoint import atomic_save_npz as save_npz
    from semiparam_ros.core.checkpoint import load_npz

    est = OnlineEstimator(config)
    feed(est, rich_stream().messages[:400])
    assert est.model.residual_use().shape == (est.model.n_outputs,)
    est.save(tmp_path / "now.npz")
    state = load_npz(tmp_path / "now.npz")
    assert "model.aged" in state
    old = {k: v for k, v in state.items() if k != "model.aged"}
    save_npz(tmp_path / "v3.npz", dict(old, **{"meta.version": np.array(3)}))
    loaded = OnlineEstimator(config)
    loaded.load(tmp_path / "v3.npz")
    assert loaded.model.residual_use().all()
    notes = " ".join(loaded.migration_notes)
    assert "aged copy" in notes and notes.count("aged copy") == 1
    assert loaded.n_samples_learned == est.n_samples_learned
    save_npz(tmp_path / "v4_missing.npz", old)
    with pytest.raises(CheckpointError, match="at an age"):
        OnlineEstimator(config).load(tmp_path / "v4_missing.npz")


def test_a_version_1_checkpoint_is_migrated_and_a_current_one_missing_arrays_is_refused(config, tmp_path):
    """Format 1 wrote no noise estimate, no gate and no robot in early checkpoints: read through the one
    migration, such a file predicts as the model that wrote it, starts σ and the gate afresh, and says what
    it did once. The same arrays missing from a later (version 2) checkpoint are a corrupt file."""
    from semiparam_ros.core.checkpoint import atomic_save_npz as save_npz
    from semiparam_ros.core.checkpoint import load_npz
    from semiparam_ros.core.estimator.state import CHECKPOINT_VERSION

    assert CHECKPOINT_VERSION == 4
    est = OnlineEstimator(config)
    feed(est, rich_stream().messages[:400])
    est.save(tmp_path / "now.npz")
    state = load_npz(tmp_path / "now.npz")
    old = {k: v for k, v in state.items() if not k.startswith(("noise.", "gate.")) and k != "meta.robot"}
    save_npz(tmp_path / "v1.npz", dict(old, **{"meta.version": np.array(1)}))
    loaded = OnlineEstimator(config)
    loaded.load(tmp_path / "v1.npz")
    assert loaded.n_samples_learned == est.n_samples_learned
    x = np.linspace(-0.5, 0.5, 3 * len(config["robot.joints"]))
    np.testing.assert_array_equal(loaded.model.predict_one(x).total, est.model.predict_one(x).total)
    fresh = OnlineEstimator(config)
    np.testing.assert_array_equal(loaded.noise.state_dict()["s2"], fresh.noise.state_dict()["s2"])
    notes = " ".join(loaded.migration_notes)
    assert "version 1" in notes and "noise estimate" in notes and "contact gate" in notes
    assert "names no robot" in notes
    loaded.save(tmp_path / "again.npz")  # written in today's format
    assert int(load_npz(tmp_path / "again.npz")["meta.version"]) == CHECKPOINT_VERSION
    save_npz(tmp_path / "v2_missing.npz", dict(old, **{"meta.version": np.array(2)}))
    with pytest.raises(CheckpointError):
        OnlineEstimator(config).load(tmp_path / "v2_missing.npz")
