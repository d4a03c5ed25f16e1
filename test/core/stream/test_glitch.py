"""The pipeline's glitch check: one-sample outliers inside the plausibility bounds are dropped and counted.

References: a plain-numpy re-implementation of the rule (the running mean increment and resolution per
signal, the ratio test, the suspect held and decided by the next state) whose decisions must equal the
pipeline's; the prediction errors of the estimator on the same stream without the glitch; clean logs
(real KUKA, simulated point-to-point with rests and quantized encoders) that must lose < 0.05 %.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from helpers import REPO
from helpers.streams import CONFIG_PATH, JOINTS, PAPER, rich_stream

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.messages import JointStateData
from semiparam_ros.core.stream.pipeline import SamplePipeline
from semiparam_ros.io.bags import read_messages
from semiparam_ros.sim.arms import ARM_ROBOTS, arm_regressor
from semiparam_ros.sim.encoders import encoder_readings
from semiparam_ros.sim.trajectories import PointToPoint

RATIO, TAU = 50.0, 0.05
FLOOR_Q, FLOOR_DQ = 1e-6, 1e-4
WARMUP = 5


def reference_glitches(stamps_ns: np.ndarray, X: np.ndarray, ratio: float, tau: float) -> np.ndarray:
    """Which rows of ``X = [q, q̇]`` (one per joint state, stamps in ns) the rule drops, in plain numpy.

    Signals: q, q̇ and the drift q − q_ref − (q̇ + q̇_ref)Δt/2 per joint. A row with a signal beyond
    ``ratio · max(running mean, floor, resolution)`` of the last accepted row is held; the next row
    decides: back (closer to the reference than to the held row on every q/q̇ that fired; a drift marks
    its q when neither its q nor its q̇ fired) and not consistent (Δq agreeing with q̇ within two counts)
    → dropped, else accepted. The resolution is the smallest non-zero q or q̇ increment accepted so far
    (the drift uses its q's).
    """
    n = X.shape[1] // 2
    floor = np.r_[np.full(n, FLOOR_Q), np.full(n, FLOOR_DQ), np.full(n, FLOOR_Q)]
    dropped = np.zeros(len(X), bool)
    ref, ref_stamp, scale, seen, mean_dt = X[0], stamps_ns[0], np.zeros(3 * n), 0, 0.0
    res = np.full(2 * n, np.inf)
    held = None  # (row, alpha, fired)

    def increments(x: np.ndarray, dt_s: float) -> np.ndarray:
        d = x - ref
        return np.abs(np.r_[d, d[:n] - 0.5 * (x[n:] + ref[n:]) * dt_s])

    def bound() -> np.ndarray:
        known = np.where(np.isinf(res), 0.0, res)
        return ratio * np.maximum(np.maximum(scale, floor), np.r_[known, known[:n]])

    def take(k: int, alpha: float) -> None:
        nonlocal ref, ref_stamp, scale, res, seen
        r = increments(X[k], 1e-9 * (stamps_ns[k] - ref_stamp))
        res = np.where((r[:2 * n] > 0) & (r[:2 * n] < res), r[:2 * n], res)
        if seen >= WARMUP:
            r = np.minimum(r, bound())
        scale = scale + alpha * (r - scale)
        ref, ref_stamp, seen = X[k], stamps_ns[k], seen + 1

    for k in range(1, len(X)):
        if held is not None:
            h, h_alpha, fired = held
            held = None
            gone = mean_dt > 0 and stamps_ns[k] - stamps_ns[h] > 3.0 * mean_dt
            back = np.abs(X[k] - ref) < np.abs(X[k] - X[h])
            # consistent: on the joints that fired, Δq agrees with q̇ (backward or trapezoid) to 2 counts
            dt = 1e-9 * (stamps_ns[h] - ref_stamp)
            step = X[h, :n] - ref[:n]
            mismatch = np.minimum(np.abs(step - X[h, n:] * dt),
                                  np.abs(step - 0.5 * (X[h, n:] + ref[n:]) * dt))
            joints = fired[:n] | fired[n:]
            consistent = np.all(mismatch[joints] <= 2.0 * np.where(np.isinf(res[:n]), 0.0, res[:n]) + FLOOR_Q)
            if gone or (back[fired].all() and not consistent):
                dropped[h] = True
            else:
                take(h, h_alpha)
        dt = stamps_ns[k] - ref_stamp
        gap = mean_dt > 0 and dt > 3.0 * mean_dt
        mean_dt = float(dt) if mean_dt == 0 else mean_dt + 0.1 * (min(dt, 3.0 * mean_dt) - mean_dt)
        if gap:  # a dropout: a new reference, nothing checked
            ref, ref_stamp = X[k], stamps_ns[k]
            continue
        alpha = 1.0 if seen == 0 else 1.0 - math.exp(-dt / (tau * 1e9))
        over = increments(X[k], 1e-9 * dt) > bound()
        fired = over[:2 * n].copy()
        fired[:n] |= over[2 * n:] & ~(over[:n] | over[n:2 * n])  # a drift alone marks its position
        if seen >= WARMUP and fired.any():
            held = (k, alpha, fired)
            continue
        take(k, alpha)
    return dropped


def _joint_states(hz: float, seconds: float, seed: int, noise: float) -> list[JointStateData]:
    rng = np.random.default_rng(seed)
    t = np.arange(1, int(hz * seconds) + 1) / hz
    w = 2 * np.pi * np.array([0.3, 0.5, 0.7, 0.9])
    q = 0.5 * np.sin(np.outer(t, w)) + noise * 1e-2 * rng.standard_normal((t.size, 4))
    dq = 0.5 * w * np.cos(np.outer(t, w)) + noise * rng.standard_normal((t.size, 4))
    stamps = (10**18 + np.round(t * 1e9)).astype(np.int64)
    return [JointStateData(int(s), JOINTS, qi, dqi, np.zeros(4))
            for s, qi, dqi in zip(stamps, q, dq, strict=True)]


def _glitched(states: list[JointStateData], where: dict[int, tuple[int, float]]) -> list[JointStateData]:
    out = list(states)
    for k, (joint, value) in where.items():
        vel = out[k].velocity.copy()
        vel[joint] = value
        out[k] = replace(out[k], velocity=vel)
    return out


@pytest.mark.parametrize("hz", [100.0, 1000.0])
def test_decisions_equal_the_reference_and_clean_streams_lose_nothing(hz):
    clean = _joint_states(hz, 20.0, seed=1, noise=0.01)
    # spikes (isolated), a spike on two consecutive states, and a real step of one velocity that stays
    n = len(clean)
    spikes = {n // 5: (0, 99.0), n // 3: (2, -40.0), n // 2: (1, 5.0), n // 2 + 1: (1, 5.0)}
    states = _glitched(clean, spikes)
    step = 2 * n // 3
    for k in range(step, n):
        vel = states[k].velocity.copy()
        vel[3] += 3.0
        states[k] = replace(states[k], velocity=vel)
    # a dropout of 0.3 s: the signals moved on, nothing to compare across it
    states = states[: n // 4] + states[n // 4 + round(0.3 * hz):]
    shift = round(0.3 * hz)
    spikes = {(k - shift if k > n // 4 else k): v for k, v in spikes.items()}
    step -= shift
    n = len(states)
    pipe = SamplePipeline(JOINTS, output="joint_torques", glitch_ratio=RATIO, glitch_time_constant=TAU)
    got = np.zeros(n, bool)
    for k, msg in enumerate(states):
        before = pipe.drops["glitch"]
        pipe.add(msg)
        got[k - 1] = pipe.drops["glitch"] > before  # a suspect is decided (and counted) by the next state
    X = np.array([np.r_[m.position, m.velocity] for m in states])
    expected = reference_glitches(np.array([m.stamp_ns for m in states]), X, RATIO, TAU)
    assert np.array_equal(got, expected)
    # each isolated spike dropped; the step that stays loses nothing (its first state is held, then the
    # next goes on from it); a spike two states long is not a one-sample glitch and is kept
    dropped = set(np.flatnonzero(got).tolist())
    single_a, single_b, _, _ = sorted(spikes)
    assert dropped == {single_a, single_b}

    # the same clean stream, and a clean noise-free one: nothing dropped
    for stream in (clean, _joint_states(hz, 20.0, seed=2, noise=0.0)):
        pipe = SamplePipeline(JOINTS, output="joint_torques", glitch_ratio=RATIO, glitch_time_constant=TAU)
        for msg in stream:
            pipe.add(msg)
        assert pipe.drops["glitch"] == 0


@pytest.mark.parametrize("ratio", [50.0, 0.0], ids=["check_on", "check_off"])
def test_a_velocity_glitch_does_not_reach_the_outputs(ratio):
    """A 99 rad/s velocity (inside the 100 rad/s bound) in one joint state of a learned stream.

    With the check, no prediction error around it exceeds 3× the median error of the stream (the
    issue's target); without it (ratio 0) the glitch enters the q̈ window of several samples and their
    errors are many times the median — what a contact detector would report.
    """
    config = load_config(CONFIG_PATH).with_overrides(
        {"nonparametric.n_features": 64, "nonparametric.standardizer_warmup": 50, **PAPER,
         "limits.glitch_ratio": ratio})
    messages = list(rich_stream().messages)
    js_index = [i for i, m in enumerate(messages) if isinstance(m, JointStateData)]
    k = js_index[450]
    vel = messages[k].velocity.copy()
    vel[list(messages[k].names).index("r_elbow")] = 99.0
    messages[k] = replace(messages[k], velocity=vel)
    est = OnlineEstimator(config)
    errors: dict[int, float] = {}
    for msg in messages:
        results = est.process(msg)
        for r in results:
            errors[r.sample.stamp_ns] = float(np.abs(r.external).max())
    glitch_stamp = messages[k].stamp_ns
    stamps = np.array(sorted(errors))
    late = stamps[stamps > stamps[len(stamps) // 2]]
    median = np.median([errors[s] for s in late])
    near = [errors[s] for s in late if abs(s - glitch_stamp) <= 200_000_000]  # ±20 samples
    assert len(near) > 30
    if ratio:
        assert est.drops["glitch"] == 1
        assert max(near) <= 3.0 * median
    else:
        assert est.drops["glitch"] == 0
        assert max(near) > 10.0 * median


# ------------------------------------------------------------------ clean logs lose nothing
KUKA = REPO.parent / "shared" / "data" / "kuka_lwr4"
MAX_FALSE_DROPS = 5e-4  # the bound: under 0.05 % of a clean log


def _glitch_drops(joints: tuple[str, ...], states: list[JointStateData]) -> tuple[int, set[int]]:
    """Glitch drops of the default pipeline on ``states``: count and the dropped states' indices."""
    pipe = SamplePipeline(joints, output="joint_torques")
    where = set()
    for k, msg in enumerate(states):
        before = pipe.drops["glitch"]
        pipe.add(msg)
        if pipe.drops["glitch"] > before:
            where.add(k - 1)  # decided by the next state
    return pipe.drops["glitch"], where


@pytest.mark.parametrize("robot", ["panda", "ur5"])
@pytest.mark.parametrize("hz", [100.0, 1000.0])
@pytest.mark.parametrize("velocity", ["exact", "differentiated"])
def test_point_to_point_with_rests_and_quantized_encoders_lose_nothing_spikes_still_go(robot, hz, velocity):
    """Moves at the URDF's velocity limits (acceleration steps), rests, positions in 1e-4 rad counts,
    stamps jittered ±10 %; q̇ the controller's or the backward difference of the logged positions."""
    reg = arm_regressor(robot)
    lower, upper = reg.position_limits()
    traj = PointToPoint.random(lower, upper, reg.velocity_limits(), seed=11, moves=40)
    joints = tuple(ARM_ROBOTS[robot].joints)
    states = encoder_readings(traj, joints, rate_hz=hz, resolution=1e-4, seed=5, velocity=velocity,
                              duration=30.0)
    count, _ = _glitch_drops(joints, states)
    assert count <= MAX_FALSE_DROPS * len(states)
    # the same log with one-sample spikes at rest and in motion: each dropped, nothing else
    rng = np.random.default_rng(1)
    spiked = list(states)
    where = set(rng.choice(np.arange(100, len(states) - 100, 13), 6, replace=False).tolist())
    for i, k in enumerate(sorted(where)):
        vel, pos = spiked[k].velocity.copy(), spiked[k].position.copy()
        if i % 2:
            vel[i % len(joints)] += 60.0
        else:
            pos[i % len(joints)] += 0.8
        spiked[k] = replace(spiked[k], velocity=vel, position=pos)
    assert _glitch_drops(joints, spiked)[1] == where


@pytest.mark.skipif(not (KUKA / "measurements_1").is_dir(), reason=f"{KUKA} is absent")
@pytest.mark.parametrize("log", [1, 2, 3])
def test_the_real_kuka_logs_lose_nothing(log):
    msgs = [m for m in read_messages(KUKA / f"measurements_{log}", joint_states_topic="/robot/joint_states",
                                     wrench_topic=None) if isinstance(m, JointStateData)]
    joints = tuple(f"lwr_{i}_joint" for i in range(7))
    count, _ = _glitch_drops(joints, msgs)
    assert count <= MAX_FALSE_DROPS * len(msgs)
