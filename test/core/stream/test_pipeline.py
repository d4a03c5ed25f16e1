"""Messages → samples: joint mapping, stamp pairing at different rates, drops by reason, bounded memory."""

from __future__ import annotations

import types

import numpy as np
import pytest
import scipy.signal as ss

from semiparam_ros.core.stream import pipeline as pl
from semiparam_ros.core.stream.acceleration import AccelerationConfig
from semiparam_ros.core.stream.messages import (
    JointStateData,
    Sample,
    WrenchData,
    joint_state_from_msg,
    ns_to_stamp,
    stamp_to_ns,
    wrench_from_msg,
)
from semiparam_ros.core.stream.pipeline import SamplePipeline
from semiparam_ros.io.bags import BagWriter, iter_samples

JOINTS = ("r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow")
EXTRA = ("torso_yaw", "r_wrist_prosup", "l_elbow")
AMP = np.array([0.4, 0.3, 0.5, 0.6])
OMEGA = 2 * np.pi * np.array([0.5, 0.8, 1.0, 0.7])
PHASE = np.array([0.1, 1.0, 2.0, -0.5])
T0 = 1_700_000_000 * 10**9  # a realistic wall-clock stamp (ns)
FRAME = "r_arm_ft_sensor"
MS = 1_000_000


def q_of(t):
    return AMP * np.sin(OMEGA * t + PHASE)


def dq_of(t):
    return AMP * OMEGA * np.cos(OMEGA * t + PHASE)


def ddq_of(t):
    return -AMP * OMEGA**2 * np.sin(OMEGA * t + PHASE)


def wrench_of(t):
    return np.array([np.sin(t), np.cos(t), -9.81 + t, 0.1 * t, -0.2, np.sin(3 * t)])


def secs(stamp_ns):
    return (stamp_ns - T0) * 1e-9


def joint_state(stamp_ns, rng, *, shuffle=True):
    """A JointState of the configured and extra joints in a random order; extra joints may be NaN."""
    t = secs(stamp_ns)
    names = list(JOINTS + EXTRA)
    pos = dict(zip(JOINTS, q_of(t), strict=True))
    vel = dict(zip(JOINTS, dq_of(t), strict=True))
    for name in EXTRA:  # unused joints: arbitrary, sometimes NaN (must not drop the message)
        pos[name] = np.nan if rng.random() < 0.2 else rng.normal()
        vel[name] = rng.normal()
    if shuffle:
        rng.shuffle(names)
    effort = rng.normal(size=len(names))
    return JointStateData(stamp_ns, tuple(names), [pos[n] for n in names], [vel[n] for n in names], effort)


def wrench(stamp_ns, frame=FRAME):
    y = wrench_of(secs(stamp_ns))
    return WrenchData(stamp_ns, frame, y[:3], y[3:])


def clean_events(
    duration_s=3.0, js_rate=100, wrench_rate=10, wrench_offset_ms=3, hole=None, wrench_latency_ms=1, seed=0
):
    """Arrival-ordered (arrival_ns, msg) of both streams; ``hole`` = (start_s, end_s) without joint states."""
    rng = np.random.default_rng(seed)
    events = []
    js_dt = 10**9 // js_rate
    for k in range(round(duration_s * js_rate)):
        stamp = T0 + js_dt + k * js_dt
        if hole is not None and hole[0] <= secs(stamp) < hole[1]:
            continue
        events.append((stamp + MS // 10, joint_state(stamp, rng)))
    w_dt = 10**9 // wrench_rate
    for k in range(round(duration_s * wrench_rate)):
        stamp = T0 + js_dt + k * w_dt + wrench_offset_ms * MS
        events.append((stamp + wrench_latency_ms * MS, wrench(stamp)))
    events.sort(key=lambda e: e[0])
    return events


def feed(pipeline, events):
    samples = []
    for _, msg in events:
        samples.extend(pipeline.add(msg))
    return samples


def nonzero(drops):
    return {k: v for k, v in drops.items() if v}


def expected_pairs(events, tol_ns, half):
    """Independent statement of the pairing rule: the nearest joint state within tolerance that has a
    centred window of ±half joint states; final once no undecided joint state could be as close."""
    js = np.array([m.stamp_ns for _, m in events if isinstance(m, JointStateData)])
    last_decided = js[len(js) - 1 - half]
    pairs, warmup, unpaired = [], 0, 0
    for _, m in events:
        if not isinstance(m, WrenchData):
            continue
        dist = np.abs(js - m.stamp_ns)
        cand = np.flatnonzero(dist <= tol_ns)
        ok = [i for i in cand if half <= i <= len(js) - 1 - half]
        best = min(ok, key=lambda i: (dist[i], i)) if ok else None
        final = m.stamp_ns + tol_ns <= last_decided or (
            best is not None and dist[best] <= last_decided - m.stamp_ns
        )
        if not final:
            continue
        if best is not None:
            pairs.append((m.stamp_ns, js[best]))
        elif len(cand):
            warmup += 1
        else:
            unpaired += 1
    return pairs, warmup, unpaired


def savgol_bound(window, dt):
    """Largest |q̈ error| of the centred SG(window, 2) derivative for the test motion (uniform stamps)."""
    c = ss.savgol_coeffs(window, 2, deriv=1, delta=dt, use="dot")
    k = np.arange(-(window // 2), window // 2 + 1)
    rel = np.array([abs(np.sum(c * np.sin(w * k * dt)) / w - 1) for w in OMEGA])
    return rel * AMP * OMEGA**2


# ---------------------------------------------------------------------------------------------------
# messages
# ---------------------------------------------------------------------------------------------------


def test_messages_normalise_and_freeze():
    pos = [1, 2]
    js = JointStateData(np.int64(5), ["a", "b"], pos, (0.1, 0.2), [])
    assert type(js.stamp_ns) is int and js.names == ("a", "b")
    assert js.position.dtype == np.float64 and js.effort.shape == (0,)
    pos[0] = 99  # copies, not views
    assert js.position[0] == 1.0
    with pytest.raises(ValueError):
        js.position[0] = 3.0  # read-only
    # mismatched content is representable (the pipeline drops it), not rejected
    JointStateData(1, ("a",), [1.0, 2.0], [np.nan])
    w = WrenchData(7, "ft", [1, 2, 3], [4, 5, 6])
    np.testing.assert_array_equal(w.wrench, [1, 2, 3, 4, 5, 6])
    s = Sample(3, [1, 2], [3, 4], [5, 6], w.wrench)
    np.testing.assert_array_equal(s.x, [1, 2, 3, 4, 5, 6])
    assert JointStateData(1, ("a",), [0.0]).velocity.shape == (0,)


@pytest.mark.parametrize("stamp", [0, 1, 999_999_999, 1_000_000_000, 1_700_000_000_123_456_789, -1])
def test_stamp_conversion_round_trip(stamp):
    sec, nanosec = ns_to_stamp(stamp)
    assert 0 <= nanosec < 10**9
    assert stamp_to_ns(sec, nanosec) == stamp


def test_duck_typed_conversion_of_ros_message_objects():
    ns = types.SimpleNamespace
    header = ns(stamp=ns(sec=12, nanosec=5), frame_id=FRAME)
    js = joint_state_from_msg(
        ns(header=header, name=["b", "a"], position=[1.0, 2.0], velocity=[3.0, 4.0], effort=[])
    )
    assert js == js and js.stamp_ns == 12 * 10**9 + 5 and js.names == ("b", "a")
    np.testing.assert_array_equal(js.velocity, [3.0, 4.0])
    w = wrench_from_msg(
        ns(header=header, wrench=ns(force=ns(x=1.0, y=2.0, z=3.0), torque=ns(x=4.0, y=5.0, z=6.0)))
    )
    assert w.frame_id == FRAME and w.stamp_ns == js.stamp_ns
    np.testing.assert_array_equal(w.wrench, [1, 2, 3, 4, 5, 6])


# ---------------------------------------------------------------------------------------------------
# pairing
# ---------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("js_rate", "wrench_rate", "offset_ms", "latency_ms"),
    [
        (100, 10, 3, 1),  # the paper preset: learning at the wrench rate, small delay between streams
        (100, 10, -4, 60),  # wrench stamped before its joint state and delivered 60 ms late
        (100, 100, 0, 0),  # same rate, same stamps
        (500, 100, 1, 2),
    ],
)
def test_pairing_at_different_rates(js_rate, wrench_rate, offset_ms, latency_ms):
    events = clean_events(
        duration_s=2.0,
        js_rate=js_rate,
        wrench_rate=wrench_rate,
        wrench_offset_ms=offset_ms,
        wrench_latency_ms=latency_ms,
    )
    p = SamplePipeline(JOINTS, frame_id=FRAME, sync_tolerance=0.005)
    samples = feed(p, events)
    pairs, warmup, unpaired = expected_pairs(events, 5 * MS, 4)
    assert len(samples) == len(pairs) == p.n_samples > 0
    assert nonzero(p.drops) == nonzero(
        {pl.DROP_ACCELERATION_WARMUP: warmup, pl.DROP_UNPAIRED_WRENCH: unpaired}
    )
    bound = savgol_bound(9, 1 / js_rate)
    for s, (tw, tj) in zip(samples, pairs, strict=True):
        assert s.stamp_ns == tw  # the sample carries the wrench stamp …
        assert s.joint_stamp_ns == tj
        np.testing.assert_array_equal(s.q, q_of(secs(tj)))  # … and the paired joint state, in JOINTS order
        np.testing.assert_array_equal(s.dq, dq_of(secs(tj)))
        np.testing.assert_allclose(s.y, wrench_of(secs(tw)), rtol=0, atol=1e-15)
        assert np.all(np.abs(s.ddq - ddq_of(secs(tj))) <= bound * (1 + 1e-6) + 1e-9)
        assert s.x.shape == (12,)
    # the estimate is delayed by half a window of joint states (no phase lag)
    assert p.acceleration_delay_s == pytest.approx(4 / js_rate, rel=1e-6)


def test_pairing_picks_the_nearest_joint_state_within_tolerance():
    # wrench 7 ms after a joint state = 3 ms before the next: pairs with the next one
    events = clean_events(duration_s=1.0, wrench_offset_ms=7)
    samples = feed(SamplePipeline(JOINTS), events)
    assert samples
    for s in samples:
        np.testing.assert_array_equal(s.q, q_of(secs(s.stamp_ns + 3 * MS)))
    # with a 2 ms tolerance nothing pairs
    p = SamplePipeline(JOINTS, sync_tolerance=0.002)
    assert feed(p, events) == []
    assert p.drops[pl.DROP_UNPAIRED_WRENCH] > 0 and p.n_dropped == p.drops[pl.DROP_UNPAIRED_WRENCH]


def test_finite_difference_pipeline_is_immediate_and_states_its_lag():
    cfg = AccelerationConfig(method="finite_difference", window=3, cutoff_hz=20.0)
    p = SamplePipeline(JOINTS, acceleration=cfg)
    # wrench stamped with its joint state, delivered 1 ms after it
    events = clean_events(duration_s=2.0, wrench_offset_ms=0, wrench_latency_ms=1)
    samples = []
    for _, msg in events:
        out = p.add(msg)
        if isinstance(msg, WrenchData) and secs(msg.stamp_ns) > 0.1:
            assert len(out) == 1  # emitted as soon as the wrench arrives
        samples += out
    lag = p.acceleration_delay_s
    assert lag == pytest.approx(p.estimator.lag_s) and 0.01 < lag < 0.02
    late = [s for s in samples if secs(s.stamp_ns) > 0.5]
    err = max(np.abs(s.ddq - ddq_of(secs(s.stamp_ns) - lag)).max() for s in late)
    assert err < 0.01 * np.max(AMP * OMEGA**2)


# ---------------------------------------------------------------------------------------------------
# drops
# ---------------------------------------------------------------------------------------------------


def dirty_events(seed=0):
    """Clean events (with a joint-state hole) plus injected faults -> (clean, dirty, injected counts)."""
    rng = np.random.default_rng(seed + 100)
    clean = clean_events(duration_s=3.0, hole=(1.5, 1.7), seed=seed)
    dirty, injected = [], dict.fromkeys(pl.DROP_REASONS, 0)
    last_js = last_w = None
    n_wrenches = 0

    def inject(reason, msg):
        dirty.append((dirty[-1][0] + 1, msg))
        injected[reason] += 1

    for i, (arrival, msg) in enumerate(clean):
        dirty.append((arrival, msg))
        if isinstance(msg, JointStateData):
            last_js = msg
            if i < 5 or i % 7:
                continue
            kind = (i // 7) % 10
            between = msg.stamp_ns + 5 * MS  # a fresh stamp between two clean joint states
            good = joint_state(between, rng)
            names, pos, vel = list(good.names), good.position.copy(), good.velocity.copy()
            j = names.index(JOINTS[kind % 4])
            if kind == 0:
                pos[j] = np.nan
                inject(pl.DROP_NONFINITE_JOINT_STATE, JointStateData(between, names, pos, vel))
            elif kind == 1:
                vel[j] = -np.inf
                inject(pl.DROP_NONFINITE_JOINT_STATE, JointStateData(between, names, pos, vel))
            elif kind == 2:
                del names[j]
                inject(
                    pl.DROP_MISSING_JOINT,
                    JointStateData(between, names, np.delete(pos, j), np.delete(vel, j)),
                )
            elif kind == 3:
                inject(pl.DROP_LENGTH_MISMATCH, JointStateData(between, names, pos, vel[:-1]))
            elif kind == 4:
                names[0] = names[1]
                inject(pl.DROP_DUPLICATE_JOINT, JointStateData(between, names, pos, vel))
            elif kind == 5:
                inject(pl.DROP_JOINT_STATE_ZERO_STAMP, JointStateData(0, names, pos, vel))
            elif kind == 8:  # finite but impossible: 1e10 rad/s would poison the q̈ window
                vel[j] = 1e10
                inject(pl.DROP_IMPLAUSIBLE_VALUE, JointStateData(between, names, pos, vel))
            elif kind == 9:
                pos[j] = -1e6
                inject(pl.DROP_IMPLAUSIBLE_VALUE, JointStateData(between, names, pos, vel))
            elif kind == 6:  # same stamp again, other values
                inject(pl.DROP_JOINT_STATE_REPEATED_STAMP, JointStateData(msg.stamp_ns, names, pos, vel))
            else:
                inject(
                    pl.DROP_JOINT_STATE_BACKWARDS_STAMP,
                    JointStateData(msg.stamp_ns - 25 * MS, names, pos, vel),
                )
        else:
            if last_w is not None:
                kind = n_wrenches % 7
                between = msg.stamp_ns + 40 * MS
                y = wrench_of(secs(between))
                if kind == 0:
                    inject(pl.DROP_NONFINITE_WRENCH, WrenchData(between, FRAME, [np.nan, 0, 0], y[3:]))
                elif kind == 1:
                    inject(pl.DROP_WRONG_FRAME_ID, WrenchData(between, "l_arm_ft_sensor", y[:3], y[3:]))
                elif kind == 2:
                    inject(pl.DROP_WRENCH_ZERO_STAMP, WrenchData(0, FRAME, y[:3], y[3:]))
                elif kind == 3:
                    inject(pl.DROP_WRENCH_REPEATED_STAMP, WrenchData(msg.stamp_ns, FRAME, y[:3], y[3:]))
                elif kind == 4:
                    inject(pl.DROP_WRENCH_BACKWARDS_STAMP, WrenchData(last_w.stamp_ns, FRAME, y[:3], y[3:]))
                elif kind == 5:
                    inject(pl.DROP_NONFINITE_WRENCH, WrenchData(between, FRAME, y[:3], [0, np.inf, 0]))
                else:
                    inject(pl.DROP_IMPLAUSIBLE_VALUE, WrenchData(between, FRAME, [0, 0, 3e7], y[3:]))
            last_w = msg
            n_wrenches += 1
    assert last_js is not None
    return clean, dirty, injected


def assert_same_samples(got, ref):
    assert len(got) == len(ref)
    for a, b in zip(got, ref, strict=True):
        assert a.stamp_ns == b.stamp_ns
        for field in ("q", "dq", "ddq", "y"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


@pytest.mark.parametrize("method", ["savgol", "finite_difference"])
def test_dirty_stream_yields_exactly_the_clean_samples_and_counts(method):
    clean, dirty, injected = dirty_events()
    assert sum(injected.values()) > 40 and all(
        injected[r] > 0
        for r in (
            pl.DROP_NONFINITE_JOINT_STATE,
            pl.DROP_MISSING_JOINT,
            pl.DROP_LENGTH_MISMATCH,
            pl.DROP_DUPLICATE_JOINT,
            pl.DROP_JOINT_STATE_ZERO_STAMP,
            pl.DROP_JOINT_STATE_REPEATED_STAMP,
            pl.DROP_JOINT_STATE_BACKWARDS_STAMP,
            pl.DROP_NONFINITE_WRENCH,
            pl.DROP_WRONG_FRAME_ID,
            pl.DROP_WRENCH_ZERO_STAMP,
            pl.DROP_WRENCH_REPEATED_STAMP,
            pl.DROP_WRENCH_BACKWARDS_STAMP,
            pl.DROP_IMPLAUSIBLE_VALUE,
        )
    )
    cfg = AccelerationConfig(method=method, window=5)
    ref_pipe = SamplePipeline(JOINTS, frame_id=FRAME, acceleration=cfg)
    ref = feed(ref_pipe, clean)
    # the clean stream itself loses the first wrench (warm-up) and the two (1.513 s, 1.613 s) inside the
    # joint-state hole [1.5 s, 1.7 s)
    assert nonzero(ref_pipe.drops) == {pl.DROP_ACCELERATION_WARMUP: 1, pl.DROP_UNPAIRED_WRENCH: 2}
    p = SamplePipeline(JOINTS, frame_id=FRAME, acceleration=cfg)
    got = feed(p, dirty)
    assert_same_samples(got, ref)  # a dropped message never touches the estimator or the pairing
    expected = {k: injected[k] + ref_pipe.drops[k] for k in pl.DROP_REASONS}
    assert p.drops == expected
    assert p.n_samples == len(ref)


def test_dirty_bag_through_iter_samples(tmp_path):
    clean, dirty, injected = dirty_events(seed=3)
    bag = tmp_path / "dirty"
    with BagWriter(bag) as writer:
        for arrival, msg in dirty:
            if isinstance(msg, JointStateData):
                writer.write_joint_state("/joint_states", msg, log_time_ns=arrival)
            else:
                writer.write_wrench("/wrench", msg, log_time_ns=arrival)
    ref_pipe = SamplePipeline(JOINTS, frame_id=FRAME)
    ref = feed(ref_pipe, clean)
    p = SamplePipeline(JOINTS, frame_id=FRAME)
    got = list(iter_samples(bag, p))
    assert_same_samples(got, ref)
    assert p.drops == {k: injected[k] + ref_pipe.drops[k] for k in pl.DROP_REASONS}


def test_wrench_checks_frame_only_when_configured():
    events = clean_events(duration_s=1.0)
    relabelled = [(a, wrench(m.stamp_ns, "other") if isinstance(m, WrenchData) else m) for a, m in events]
    strict = SamplePipeline(JOINTS, frame_id=FRAME)
    assert feed(strict, relabelled) == []
    assert strict.drops[pl.DROP_WRONG_FRAME_ID] == 10
    assert len(feed(SamplePipeline(JOINTS, frame_id=""), relabelled)) == len(
        feed(SamplePipeline(JOINTS), events)
    )


# ---------------------------------------------------------------------------------------------------
# joint torques, restarts, memory, configuration
# ---------------------------------------------------------------------------------------------------


def test_joint_torque_output_uses_effort_of_configured_joints():
    rng = np.random.default_rng(5)
    p = SamplePipeline(JOINTS, output="joint_torques")
    msgs = [joint_state(T0 + (k + 1) * 10 * MS, rng) for k in range(50)]
    samples = []
    for m in msgs:
        samples += p.add(m)
    assert p.add(wrench(T0 + 5 * MS)) == []
    # NaN effort of a configured joint drops the message; of an extra joint it does not
    bad = msgs[-1]
    names = list(bad.names)
    eff = bad.effort.copy()
    eff[names.index("r_elbow")] = np.nan
    assert p.add(JointStateData(bad.stamp_ns + 1, names, bad.position, bad.velocity, eff)) == []
    eff = bad.effort.copy()
    eff[names.index("torso_yaw")] = np.nan
    p.add(JointStateData(bad.stamp_ns + 2, names, bad.position, bad.velocity, eff))
    p.add(JointStateData(bad.stamp_ns + 3, names, bad.position, bad.velocity, eff[:-1]))
    assert nonzero(p.drops) == {
        pl.DROP_ACCELERATION_WARMUP: 4,
        pl.DROP_WRENCH_IGNORED: 1,
        pl.DROP_NONFINITE_JOINT_STATE: 1,
        pl.DROP_LENGTH_MISMATCH: 1,
    }
    assert len(samples) == 50 - 4 - 4  # warm-up head and pending tail of the 9-sample window
    for s, m in zip(samples, msgs[4:], strict=False):
        idx = [m.names.index(j) for j in JOINTS]
        assert s.stamp_ns == m.stamp_ns
        np.testing.assert_array_equal(s.y, m.effort[idx])
        np.testing.assert_array_equal(s.q, m.position[idx])


def test_wrench_output_ignores_effort_content():
    events = clean_events(duration_s=1.0)
    no_effort = [
        (a, JointStateData(m.stamp_ns, m.names, m.position, m.velocity, [np.nan]))
        if isinstance(m, JointStateData)
        else (a, m)
        for a, m in events
    ]
    assert_same_samples(feed(SamplePipeline(JOINTS), no_effort), feed(SamplePipeline(JOINTS), events))


def test_clock_restart_recovers_after_backwards_run():
    first = clean_events(duration_s=1.0)
    looped = first + [(a + 10 * 10**9, m) for a, m in first]  # the same stamps again (a bag played in a loop)
    p = SamplePipeline(JOINTS, restart_after=20)
    samples = feed(p, looped)
    once = feed(SamplePipeline(JOINTS), first)
    assert p.n_restarts >= 1
    assert p.drops[pl.DROP_JOINT_STATE_BACKWARDS_STAMP] >= 20
    assert len(once) < len(samples) < 2 * len(once)  # the second pass learns again after the restart
    p.reset()
    assert p.n_samples == 0 and p.n_dropped == 0 and p.n_restarts == 0
    assert len(feed(p, first)) == len(once)


def test_memory_is_bounded():
    p = SamplePipeline(JOINTS, max_buffer=64, buffer_s=0.2)
    rng = np.random.default_rng(0)
    for k in range(500):  # wrenches only: they wait, the oldest are discarded
        p.add(wrench(T0 + (k + 1) * MS))
    assert p.n_pending_wrenches == 64 and p.drops[pl.DROP_BUFFER_OVERFLOW] == 500 - 64
    for k in range(2000):  # 1 kHz joint states for 2 s: at most buffer_s worth are kept
        p.add(joint_state(T0 + 10**9 + k * MS, rng, shuffle=False))
        assert len(p._entries) <= 202
    assert p.n_pending_wrenches == 0


@pytest.mark.parametrize(
    ("args", "kwargs"),
    [
        ((), {}),
        (([],), {}),
        (("r_elbow",), {}),
        ((["a", "a"],), {}),
        ((JOINTS,), {"output": "torque"}),
        ((JOINTS,), {"sync_tolerance": -0.1}),
        ((JOINTS,), {"sync_tolerance": float("nan")}),
        ((JOINTS,), {"buffer_s": 0.0}),
        ((JOINTS,), {"max_buffer": 0}),
        ((JOINTS,), {"acceleration": {"method": "savgol"}}),
        ((JOINTS,), {"max_abs_velocity": 0.0}),
        ((JOINTS,), {"max_abs_position": -1.0}),
        ((JOINTS,), {"max_abs_output": float("nan")}),
        ((JOINTS,), {"max_abs_output": "1e4"}),
    ],
)
def test_invalid_pipeline_settings_raise(args, kwargs):
    with pytest.raises((ValueError, TypeError)):
        SamplePipeline(*args, **kwargs)


def test_implausible_values_are_dropped_by_reason_and_bounds_are_configurable():
    """Each bound separately, both streams, both outputs; NaN still counts as non-finite (screening order);
    a dropped message leaves the state untouched; ``None`` lifts a bound."""
    events = clean_events(duration_s=1.0)
    ref = SamplePipeline(JOINTS, frame_id=FRAME)
    ref_samples = feed(ref, events)
    assert len(ref_samples) > 5

    def js_with(msg, field, name, value):
        arrays = {f: getattr(msg, f).copy() for f in ("position", "velocity", "effort")}
        arrays[field][msg.names.index(name)] = value
        return JointStateData(msg.stamp_ns + MS, msg.names, arrays["position"], arrays["velocity"],
                              arrays["effort"])

    limits = {"max_abs_position": 4.0, "max_abs_velocity": 20.0, "max_abs_output": 50.0}
    p = SamplePipeline(JOINTS, frame_id=FRAME, **limits)
    got, expected = [], {}
    for k, (_, msg) in enumerate(events):
        if isinstance(msg, JointStateData) and k % 5 == 2:
            cases = [
                (js_with(msg, "velocity", "r_elbow", 20.5), pl.DROP_IMPLAUSIBLE_VALUE),
                (js_with(msg, "velocity", "r_shoulder_pitch", -1e10), pl.DROP_IMPLAUSIBLE_VALUE),
                (js_with(msg, "position", "r_shoulder_yaw", 4.01), pl.DROP_IMPLAUSIBLE_VALUE),
                (js_with(js_with(msg, "velocity", "r_elbow", np.nan), "position", "r_elbow", 1e9),
                 pl.DROP_NONFINITE_JOINT_STATE),
            ]
            for bad, reason in cases:
                assert p.add(bad) == []
                expected[reason] = expected.get(reason, 0) + 1
        if isinstance(msg, WrenchData) and k % 3 == 0:
            y = wrench_of(secs(msg.stamp_ns))
            bad_force = WrenchData(msg.stamp_ns + MS, FRAME, [0.0, -50.1, 0.0], y[3:])
            bad_torque = WrenchData(msg.stamp_ns + MS, FRAME, y[:3], [0.0, 0.0, 1e12])
            for bad in (bad_force, bad_torque):
                assert p.add(bad) == []
                expected[pl.DROP_IMPLAUSIBLE_VALUE] = expected.get(pl.DROP_IMPLAUSIBLE_VALUE, 0) + 1
        got.extend(p.add(msg))
    assert_same_samples(got, ref_samples)  # values at the bound or below pass, state untouched
    for reason, count in expected.items():
        assert p.drops[reason] == count > 0
    assert sum(p.drops.values()) == sum(expected.values()) + sum(ref.drops.values())

    # the extra (unconfigured) joints are never screened; the learned efforts are (joint_torques only)
    msg = next(m for _, m in events if isinstance(m, JointStateData))
    huge_extra = js_with(msg, "velocity", EXTRA[0], 1e12)
    for output in ("wrench", "joint_torques"):
        q = SamplePipeline(JOINTS, output=output, **limits)
        q.add(huge_extra)
        assert q.drops[pl.DROP_IMPLAUSIBLE_VALUE] == 0
    torque_pipe = SamplePipeline(JOINTS, output="joint_torques", **limits)
    assert torque_pipe.add(js_with(msg, "effort", "r_elbow", 60.0)) == []
    assert torque_pipe.drops[pl.DROP_IMPLAUSIBLE_VALUE] == 1
    assert SamplePipeline(JOINTS, **limits).add(js_with(msg, "effort", "r_elbow", 60.0)) == []

    # None lifts a bound (inf and NaN are still non-finite)
    free = SamplePipeline(JOINTS, frame_id=FRAME, max_abs_position=None, max_abs_velocity=None,
                          max_abs_output=None)
    free.add(js_with(msg, "velocity", "r_elbow", 1e300))  # stamp + 1 ms
    free.add(WrenchData(msg.stamp_ns, FRAME, [1e300, 0, 0], [0, 0, 0]))
    assert sum(free.drops.values()) == 0
    free.add(js_with(js_with(msg, "velocity", "r_elbow", np.inf), "position", "r_elbow", 0.0))
    free.add(WrenchData(msg.stamp_ns + MS, FRAME, [np.inf, 0, 0], [0, 0, 0]))
    assert free.drops[pl.DROP_NONFINITE_JOINT_STATE] == 1
    assert free.drops[pl.DROP_NONFINITE_WRENCH] == 1
    assert free.drops[pl.DROP_IMPLAUSIBLE_VALUE] == 0


def test_default_bounds_pass_every_plausible_robot_value():
    """Defaults: 100 rad, 100 rad/s, 1e4 N / N·m — generous for any arm, tight enough for garbage."""
    p = SamplePipeline(JOINTS)
    names = JOINTS
    stamps = T0 + np.arange(1, 4) * 10 * MS
    for k, stamp in enumerate(stamps):
        p.add(JointStateData(int(stamp), names, [99.0, -6.3, 0.0, 3.0], [-99.9, 10.0, 0.0, k]))
    p.add(WrenchData(int(stamps[1]), FRAME, [9999.0, -1e4, 0.0], [1e4, 0.0, -5.0]))
    assert p.drops[pl.DROP_IMPLAUSIBLE_VALUE] == 0
    p.add(JointStateData(int(stamps[-1]) + MS, names, np.zeros(4), [0.0, 0.0, 100.001, 0.0]))
    p.add(WrenchData(int(stamps[1]) + MS, FRAME, [0.0, 0.0, 0.0], [0.0, -10000.5, 0.0]))
    assert p.drops[pl.DROP_IMPLAUSIBLE_VALUE] == 2
