"""Bag I/O: BagWriter → read_messages round trip, cross-checked with the independent mcap_ros2 decoder;
streaming memory; broken bags raise BagError."""

from __future__ import annotations

import re
import shutil
import struct
import tracemalloc

import mcap_ros2.decoder
import numpy as np
import pytest
from mcap.reader import make_reader

from semiparam_ros.core.stream.messages import JointStateData, WrenchData, stamp_to_ns
from semiparam_ros.core.stream.pipeline import SamplePipeline
from semiparam_ros.io.bags import (
    JOINT_STATE_TYPE,
    JOINT_TRAJECTORY_TYPE,
    WRENCH_STAMPED_TYPE,
    BagError,
    BagRecoveryWarning,
    BagWriter,
    iter_raw,
    iter_samples,
    read_messages,
    read_topic_arrays,
    topic_info,
)

T0 = 1_700_000_000 * 10**9
JOINTS = ("r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow")
ALL = (*JOINTS, "torso_pitch", "r_wrist_prosup", "neck_yaw")
FRAME = "r_arm_ft_sensor"


def make_messages(n_js=200, js_dt_ms=10, wrench_every=10, seed=0):
    """Joint states (shuffled names, NaN in an unused joint now and then) and wrenches, with log times."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n_js):
        stamp = T0 + k * js_dt_ms * 1_000_000 + int(rng.integers(0, 1000))  # sub-µs jitter in the stamps
        names = list(ALL)
        rng.shuffle(names)
        pos = rng.normal(size=len(names))
        if k % 17 == 0:
            pos[names.index("neck_yaw")] = np.nan
        js = JointStateData(
            stamp, tuple(names), pos, rng.normal(size=len(names)), rng.normal(size=len(names))
        )
        out.append(("/joint_states", js, stamp + 200_000))
        if k % wrench_every == 3:
            w = WrenchData(stamp + 2_000_000, FRAME, rng.normal(size=3) * 10, rng.normal(size=3))
            out.append(("/wrench", w, w.stamp_ns + 500_000))
    out.sort(key=lambda e: e[2])
    return out


def write_bag(path, messages, *, compress=False, ground_truth=True):
    with BagWriter(path, compress=compress) as bag:
        for topic, msg, log_time in messages:
            if isinstance(msg, JointStateData):
                bag.write_joint_state(topic, msg, log_time_ns=log_time)
                if ground_truth:
                    idx = [msg.names.index(j) for j in JOINTS]
                    bag.write_joint_trajectory_point(
                        "/ground_truth/joint_accelerations",
                        msg.stamp_ns,
                        JOINTS,
                        msg.position[idx],
                        msg.velocity[idx],
                        -msg.position[idx],
                        log_time_ns=log_time + 1,
                    )
            else:
                bag.write_wrench(topic, msg, log_time_ns=log_time)
    return bag


def decode_with_mcap_ros2(mcap_file, topics=None):
    """The independent decoder: mcap + mcap_ros2 (schemas from the file, not from rosbags)."""
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[mcap_ros2.decoder.DecoderFactory()])
        return [
            (channel.topic, schema.name, message.log_time, decoded)
            for schema, channel, message, decoded in reader.iter_decoded_messages(
                topics=topics, log_time_order=True
            )
        ]


def assert_js_equal(a: JointStateData, b: JointStateData):
    assert a.stamp_ns == b.stamp_ns and a.names == b.names
    for f in ("position", "velocity", "effort"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))  # NaN == NaN here


# ---------------------------------------------------------------------------------------------------
# round trip and cross-check
# ---------------------------------------------------------------------------------------------------


def test_round_trip_and_independent_decoder(tmp_path):
    messages = make_messages()
    bag = tmp_path / "arm"
    writer = write_bag(bag, messages)
    assert sorted(p.name for p in bag.iterdir()) == ["arm.mcap", "metadata.yaml"]
    assert writer.counts == {"/joint_states": 200, "/ground_truth/joint_accelerations": 200, "/wrench": 20}

    # rosbags reader: same objects back, in log-time order
    got = list(read_messages(bag))
    want = [m for _, m, _ in messages]
    assert len(got) == len(want) == 220
    for a, b in zip(got, want, strict=True):
        assert type(a) is type(b)
        if isinstance(a, JointStateData):
            assert_js_equal(a, b)
        else:
            assert (a.stamp_ns, a.frame_id) == (b.stamp_ns, b.frame_id)
            np.testing.assert_array_equal(a.wrench, b.wrench)

    # independent decoder: types, counts, stamps, values, monotonic log times
    decoded = decode_with_mcap_ros2(bag / "arm.mcap")
    by_topic = {}
    for topic, schema, log_time, msg in decoded:
        by_topic.setdefault(topic, []).append((schema, log_time, msg))
    assert {t: len(v) for t, v in by_topic.items()} == writer.counts
    assert {t: {s for s, _, _ in v} for t, v in by_topic.items()} == {
        "/joint_states": {JOINT_STATE_TYPE},
        "/wrench": {WRENCH_STAMPED_TYPE},
        "/ground_truth/joint_accelerations": {JOINT_TRAJECTORY_TYPE},
    }
    log_times = [lt for _, _, lt, _ in decoded]
    assert log_times == sorted(log_times)
    js_ref = [m for t, m, _ in messages if t == "/joint_states"]
    for (_, log_time, msg), ref, (_, _, ref_log) in zip(
        by_topic["/joint_states"], js_ref, [e for e in messages if e[0] == "/joint_states"], strict=True
    ):
        assert stamp_to_ns(msg.header.stamp.sec, msg.header.stamp.nanosec) == ref.stamp_ns
        assert log_time == ref_log
        assert tuple(msg.name) == ref.names
        np.testing.assert_array_equal(np.asarray(msg.position), ref.position)
        np.testing.assert_array_equal(np.asarray(msg.velocity), ref.velocity)
        np.testing.assert_array_equal(np.asarray(msg.effort), ref.effort)
    w_ref = [m for t, m, _ in messages if t == "/wrench"]
    for (_, _, msg), ref in zip(by_topic["/wrench"], w_ref, strict=True):
        assert msg.header.frame_id == FRAME
        assert stamp_to_ns(msg.header.stamp.sec, msg.header.stamp.nanosec) == ref.stamp_ns
        f, t = msg.wrench.force, msg.wrench.torque
        np.testing.assert_array_equal([f.x, f.y, f.z, t.x, t.y, t.z], ref.wrench)
    # the stored rate: 100 Hz joint states, 10 Hz wrench
    js_stamps = np.array([m.stamp_ns for m in js_ref])
    assert np.all(np.diff(js_stamps) > 0)
    assert np.median(np.diff(js_stamps)) == pytest.approx(1e7, rel=1e-3)

    # the ground-truth topic as arrays, decoded independently too
    gt = read_topic_arrays(bag, "/ground_truth/joint_accelerations")
    assert gt.names == JOINTS and len(gt) == 200 and gt.msgtype == JOINT_TRAJECTORY_TYPE
    np.testing.assert_array_equal(gt.stamp_ns, js_stamps)
    points = np.array(
        [np.asarray(m.points[0].accelerations) for _, _, m in by_topic["/ground_truth/joint_accelerations"]]
    )
    np.testing.assert_array_equal(gt.fields["accelerations"], points)
    assert set(gt.fields) == {"positions", "velocities", "accelerations"}  # empty effort left out
    # reordered columns
    rev = read_topic_arrays(bag, "/ground_truth/joint_accelerations", joints=JOINTS[::-1])
    np.testing.assert_array_equal(rev.fields["accelerations"], points[:, ::-1])
    wr = read_topic_arrays(bag, "/wrench")
    np.testing.assert_array_equal(wr.fields["wrench"], np.array([m.wrench for m in w_ref]))
    assert wr.frame_id == FRAME
    js_arr = read_topic_arrays(bag, "/joint_states", joints=JOINTS)
    idx = [[m.names.index(j) for j in JOINTS] for m in js_ref]
    np.testing.assert_array_equal(
        js_arr.fields["velocity"], np.array([m.velocity[i] for m, i in zip(js_ref, idx, strict=True)])
    )

    info = topic_info(bag)
    assert {t: (i.msgtype, i.count) for t, i in info.items()} == {
        "/joint_states": (JOINT_STATE_TYPE, 200),
        "/wrench": (WRENCH_STAMPED_TYPE, 20),
        "/ground_truth/joint_accelerations": (JOINT_TRAJECTORY_TYPE, 200),
    }


def test_bare_mcap_compressed_and_topic_selection(tmp_path):
    messages = make_messages(n_js=60)
    bag = tmp_path / "z"
    write_bag(bag, messages, compress=True)
    bare = tmp_path / "copy.mcap"
    shutil.copy(bag / "z.mcap", bare)
    from_folder = list(read_messages(bag))
    from_file = list(read_messages(bare))
    assert len(from_folder) == len(from_file) == 66
    for a, b in zip(from_folder, from_file, strict=True):
        assert a.stamp_ns == b.stamp_ns and type(a) is type(b)
    assert len(decode_with_mcap_ros2(bare)) == 126  # zstd chunks decode independently too
    only_js = list(read_messages(bag, wrench_topic=None))
    assert len(only_js) == 60 and all(isinstance(m, JointStateData) for m in only_js)
    only_w = list(read_messages(bag, joint_states_topic=None))
    assert len(only_w) == 6 and all(isinstance(m, WrenchData) for m in only_w)
    # a folder copied without metadata.yaml is read through its single .mcap
    (bag / "metadata.yaml").unlink()
    assert len(list(read_messages(bag))) == 66


def test_iter_raw_gives_cdr_bytes_for_replay(tmp_path):
    messages = make_messages(n_js=50)
    bag = tmp_path / "raw"
    write_bag(bag, messages)
    raw = list(iter_raw(bag, ["/wrench", "/joint_states"]))
    assert len(raw) == 55
    assert [lt for _, _, lt, _ in raw] == sorted(lt for _, _, lt in messages)
    # the CDR bytes decode (with the independent decoder's view of the same file) to the same messages
    decoded = decode_with_mcap_ros2(bag / "raw.mcap", topics=["/wrench", "/joint_states"])
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    for (topic, msgtype, log_time, data), (d_topic, d_schema, d_log, d_msg) in zip(raw, decoded, strict=True):
        assert isinstance(data, bytes)
        assert (topic, msgtype, log_time) == (d_topic, d_schema, d_log)
        msg = store.deserialize_cdr(data, msgtype)
        assert msg.header.stamp.nanosec == d_msg.header.stamp.nanosec


def test_iter_samples_uses_the_pipeline(tmp_path):
    messages = make_messages(n_js=300)
    bag = tmp_path / "s"
    write_bag(bag, messages, ground_truth=False)
    p = SamplePipeline(JOINTS, frame_id=FRAME)
    samples = list(iter_samples(bag, p))
    # same as feeding the messages by hand
    q = SamplePipeline(JOINTS, frame_id=FRAME)
    ref = []
    for _, m, _ in messages:
        ref += q.add(m)
    assert len(samples) == len(ref) == 29  # 30 wrenches, the first one in the estimator's warm-up
    for a, b in zip(samples, ref, strict=True):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_array_equal(a.x, b.x)
        np.testing.assert_array_equal(a.y, b.y)
    assert p.drops == q.drops
    # joint-torque learning needs no wrench topic
    tq = list(iter_samples(bag, SamplePipeline(JOINTS, output="joint_torques")))
    assert len(tq) == 300 - 8


# ---------------------------------------------------------------------------------------------------
# writer behaviour
# ---------------------------------------------------------------------------------------------------


def test_writer_refuses_existing_folder_and_conflicting_types(tmp_path):
    bag = tmp_path / "b"
    write_bag(bag, make_messages(n_js=5))
    with pytest.raises(BagError, match="exists already"):
        BagWriter(bag).open()
    write_bag_over = BagWriter(bag, overwrite=True)
    with write_bag_over as w:
        w.write_wrench("/wrench", WrenchData(T0, FRAME, [1, 2, 3], [4, 5, 6]))
    assert len(list(read_messages(bag, joint_states_topic=None))) == 1
    other = tmp_path / "not_a_bag"
    other.mkdir()
    (other / "notes.txt").write_text("keep me")
    with pytest.raises(BagError, match="not a bag folder"):
        BagWriter(other, overwrite=True).open()
    assert (other / "notes.txt").exists()
    with pytest.raises(BagError, match="already carries"), BagWriter(tmp_path / "c") as w:
        w.write_wrench("/x", WrenchData(T0, FRAME, [1, 2, 3], [4, 5, 6]))
        w.write_joint_state("/x", JointStateData(T0, ("a",), [0.0]))
    with pytest.raises(BagError, match="not open"):
        BagWriter(tmp_path / "d").write_wrench("/w", WrenchData(T0, FRAME, [1, 2, 3], [4, 5, 6]))
    with pytest.raises(ValueError, match="3 components"), BagWriter(tmp_path / "e") as w:
        w.write_wrench("/w", WrenchData(T0, FRAME, [1, 2], [4, 5, 6]))


def test_generic_message_and_faulty_content_round_trip(tmp_path):
    bag = tmp_path / "g"
    with BagWriter(bag) as w:
        types = w.typestore.types
        arr = types["std_msgs/msg/Float64MultiArray"](
            layout=types["std_msgs/msg/MultiArrayLayout"](
                dim=[types["std_msgs/msg/MultiArrayDimension"](label="a,b", size=2, stride=2)], data_offset=0
            ),
            data=np.array([1.5, -2.0]),
        )
        w.write_message("/params", "std_msgs/msg/Float64MultiArray", arr, log_time_ns=T0)
        # malformed content is stored as given, for fault-injection bags
        w.write_joint_state("/joint_states", JointStateData(T0, ("a", "b"), [1.0], [np.inf, 2.0, 3.0]))
    ((_topic, schema, _, msg),) = decode_with_mcap_ros2(bag / "g.mcap", topics=["/params"])
    assert schema == "std_msgs/msg/Float64MultiArray" and list(msg.data) == [1.5, -2.0]
    (js,) = list(read_messages(bag, wrench_topic=None))
    assert js.position.shape == (1,) and np.isinf(js.velocity[0])


# ---------------------------------------------------------------------------------------------------
# broken bags
# ---------------------------------------------------------------------------------------------------


@pytest.fixture
def good_bag(tmp_path):
    bag = tmp_path / "good"
    write_bag(bag, make_messages(n_js=100), ground_truth=False)
    return bag


def test_missing_path_topic_and_wrong_type(tmp_path, good_bag):
    with pytest.raises(BagError, match="does not exist"):
        read_messages(tmp_path / "nope")
    with pytest.raises(BagError, match=r"'/joint_states_typo'.*topics: /joint_states"):
        read_messages(good_bag, joint_states_topic="/joint_states_typo")
    with pytest.raises(
        BagError, match="topic '/joint_states' carries 'sensor_msgs/msg/JointState', expected"
    ):
        read_messages(good_bag, wrench_topic="/joint_states", joint_states_topic=None)
    with pytest.raises(BagError, match="no topic"):
        iter_raw(good_bag, ["/missing"])
    with pytest.raises(BagError, match="no topic"):
        read_topic_arrays(good_bag, "/missing")
    with pytest.raises(BagError, match="lacks joints"):
        read_topic_arrays(good_bag, "/joint_states", joints=["r_elbow", "l_elbow"])
    assert issubclass(BagError, ValueError)


def test_garbage_files_and_folders_raise(tmp_path, good_bag):
    for name, content in [
        ("garbage.mcap", b"not an mcap file" * 100),
        ("empty.mcap", b""),
        ("magic_only.mcap", (good_bag / "good.mcap").read_bytes()[:8]),
    ]:
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(BagError, match=re.escape(name)) as info:
            list(read_messages(path))
        assert info.value.__cause__ is not None
    folder = tmp_path / "no_mcap"
    shutil.copytree(good_bag, folder)
    (folder / "good.mcap").unlink()
    with pytest.raises(BagError, match="no_mcap") as info:
        read_messages(folder)
    assert info.value.__cause__ is not None
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(BagError, match=r"not an \.mcap"):
        read_messages(tmp_path / "notes.txt")


# ---------------------------------------------------------------------------------------------------
# truncated and corrupt bags: read what is there
# ---------------------------------------------------------------------------------------------------

BIG_NAMES = tuple(f"joint_{i:03d}" for i in range(120))


@pytest.fixture(scope="module", params=[False, True], ids=["uncompressed", "zstd"])
def multi_chunk_bag(request, tmp_path_factory):
    """≈2.5 MB of joint states and wrenches: three MCAP chunks (rosbags closes a chunk past 1 MiB)."""
    bag = tmp_path_factory.mktemp("multi") / "multi"
    rng = np.random.default_rng(3)
    with BagWriter(bag, compress=request.param) as w:
        for k in range(540):
            stamp = T0 + k * 10**7
            w.write_joint_state("/joint_states", JointStateData(
                stamp, BIG_NAMES, rng.normal(size=120), rng.normal(size=120), rng.normal(size=120)))
            if k % 5 == 0:
                w.write_wrench("/wrench", WrenchData(stamp + 1000, FRAME, rng.normal(size=3),
                                                     rng.normal(size=3)))
    mcap_file = bag / "multi.mcap"
    with open(mcap_file, "rb") as f:
        summary = make_reader(f).get_summary()
    assert len(summary.chunk_indexes) >= 3
    return mcap_file, request.param, summary


def _reference_messages(mcap_file):
    """The independent decoder's view of the intact file: (topic, log time, data, record end offset).

    Messages come from the mcap library (indexed reader); the byte offset where each message record ends
    is found by searching its record header + data in the raw file (uncompressed chunks hold records
    verbatim), so the expected set for a cut does not come from the code under test.
    """
    blob = mcap_file.read_bytes()
    out = []
    with open(mcap_file, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            pattern = struct.pack("<HIQQ", message.channel_id, message.sequence, message.log_time,
                                  message.publish_time) + message.data
            at = blob.find(pattern)
            end = at + len(pattern) if at >= 0 else None  # None: inside a compressed chunk
            out.append((channel.topic, message.log_time, bytes(message.data), end))
    return out


def _chunk_ends(summary):
    return sorted(c.chunk_start_offset + c.chunk_length for c in summary.chunk_indexes)


def _read_all(path):
    """read_messages + iter_raw of a damaged bag, with the recovery warning it must give."""
    with pytest.warns(BagRecoveryWarning, match=r"recovered \d+ messages .* spanning") as record:
        decoded = list(read_messages(path))
    with pytest.warns(BagRecoveryWarning):
        raw = [(t, lt, bytes(data)) for t, _m, lt, data in iter_raw(path, ["/joint_states", "/wrench"])]
    return decoded, raw, str(record[0].message)


def test_truncated_bag_recovers_every_complete_message(tmp_path, multi_chunk_bag):
    mcap_file, compressed, summary = multi_chunk_bag
    reference = _reference_messages(mcap_file)
    intact = list(read_messages(mcap_file))  # the normal (rosbags) path, for the decoded values
    assert len(intact) == len(reference)
    data = mcap_file.read_bytes()
    ends = _chunk_ends(summary)
    first_chunk = min(c.chunk_start_offset for c in summary.chunk_indexes)
    cuts = sorted({
        first_chunk + 300_000,  # inside the first chunk (past two 128 kB zstd blocks)
        ends[0],  # exactly at a chunk boundary
        ends[0] + 777,  # just inside the second chunk
        (ends[1] + ends[2]) // 2,  # mid third chunk
        ends[-1] + 3,  # after the data, inside the message indexes
        len(data) - 20,  # inside the summary/footer
    })
    for cut in cuts:
        path = tmp_path / f"cut_{cut}.mcap"
        path.write_bytes(data[:cut])
        decoded, raw, warning = _read_all(path)
        if compressed:
            # zstd chunks: every message of each chunk wholly before the cut, then at most the head of
            # the chunk the cut falls in (what its stream decodes to); chunks do not overlap in time here
            whole_end = max((c.message_end_time for c in summary.chunk_indexes
                             if c.chunk_start_offset + c.chunk_length <= cut), default=-1)
            started_end = max((c.message_end_time for c in summary.chunk_indexes
                               if c.chunk_start_offset < cut), default=-1)
            n_whole = sum(m[1] <= whole_end for m in reference)
            n_started = sum(m[1] <= started_end for m in reference)
            assert n_whole <= len(raw) <= n_started, (cut, n_whole, len(raw), n_started)
            expected = reference[: len(raw)]
        else:
            expected = [m for m in reference if m[3] <= cut]
            assert expected == reference[: len(expected)]  # a prefix in file order
            assert len(raw) == len(expected), (cut, len(raw), len(expected))
        key = lambda m: (m[1], m[0])  # noqa: E731
        assert sorted(raw, key=key) == sorted(((t, lt, d) for t, lt, d, _ in expected), key=key)
        assert len(decoded) == len(raw)
        for got, want in zip(decoded, intact[: len(decoded)], strict=True):
            assert type(got) is type(want)
            if isinstance(want, JointStateData):
                assert_js_equal(got, want)
            else:
                assert (got.stamp_ns, got.frame_id) == (want.stamp_ns, want.frame_id)
                np.testing.assert_array_equal(got.wrench, want.wrench)
        span = (expected[-1][1] - expected[0][1]) * 1e-9
        assert f"recovered {len(expected)} messages" in warning and f"{span:.3f} s" in warning
        # the other entry points agree
        with pytest.warns(BagRecoveryWarning):
            info = topic_info(path)
        assert sum(i.count for i in info.values()) == len(expected)


def test_corrupt_chunk_in_the_middle_is_skipped(tmp_path, multi_chunk_bag):
    mcap_file, compressed, summary = multi_chunk_bag
    reference = _reference_messages(mcap_file)
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    bad_chunk = chunks[1]
    data = bytearray(mcap_file.read_bytes())
    records = bad_chunk.chunk_start_offset + 1 + 8 + 8 + 8 + 8 + 4 + 4 + len(bad_chunk.compression) + 8
    if compressed:
        middle = records + bad_chunk.compressed_size // 2
        data[middle : middle + 64] = b"\xff" * 64  # the zstd stream no longer decodes
    else:
        data[records : records + 16] = b"\xff" * 16  # the first inner record: an impossible length
    for name, content in [("corrupt.mcap", bytes(data)),  # summary intact: found while reading
                          ("corrupt_cut.mcap", bytes(data[: chunks[-1].chunk_start_offset + 50]))]:
        path = tmp_path / name
        path.write_bytes(content)
        decoded, raw, warning = _read_all(path)
        in_bad = [bad_chunk.message_start_time <= m[1] <= bad_chunk.message_end_time for m in reference]
        last_start = chunks[-1].message_start_time if name == "corrupt_cut.mcap" else None
        expected = [(t, lt, d) for (t, lt, d, _), bad in zip(reference, in_bad, strict=True)
                    if not bad and (last_start is None or lt < last_start)]
        assert 0 < len(expected) < len(reference)
        assert raw == expected, (name, len(raw), len(expected))
        assert len(decoded) == len(raw)
        assert f"at byte {bad_chunk.chunk_start_offset}" in warning, warning


# ---------------------------------------------------------------------------------------------------
# streaming
# ---------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_reading_streams_instead_of_loading_the_file(tmp_path):
    names = tuple(f"joint_{i:03d}" for i in range(200))
    bag = tmp_path / "big"
    rng = np.random.default_rng(0)
    with BagWriter(bag) as w:
        for k in range(1600):  # ≈ 7.7 kB per message → ≈ 12 MB
            w.write_joint_state(
                "/joint_states",
                JointStateData(
                    T0 + k * 10**7, names, rng.normal(size=200), rng.normal(size=200), np.zeros(200)
                ),
            )
            if k % 10 == 0:
                w.write_wrench("/wrench", WrenchData(T0 + k * 10**7, FRAME, [1, 2, 3], [4, 5, 6]))
    size = (bag / "big.mcap").stat().st_size
    assert size > 10e6
    tracemalloc.start()
    try:
        iterator = read_messages(bag)
        first = next(iterator)
        _, peak_first = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        n = 1
        for _ in iterator:  # several 1 MB chunks further on
            n += 1
            if n == 300:
                break
        _, peak_more = tracemalloc.get_traced_memory()
        iterator.close()
    finally:
        tracemalloc.stop()
    assert first.stamp_ns == T0
    # one MCAP chunk (≈1 MB) plus its decoded copy is in memory, never the file
    assert peak_first < 0.3 * size, (peak_first, size)
    assert peak_more < 0.3 * size, (peak_more, size)
    assert n == 300
    assert sum(1 for _ in read_messages(bag)) == 1600 + 160


def test_read_messages_is_lazy(good_bag, monkeypatch):
    # nothing is decoded until iteration: a generator that yields the first message before the rest
    import semiparam_ros.io.bags as bags

    calls = []
    real = bags.joint_state_from_msg
    monkeypatch.setattr(bags, "joint_state_from_msg", lambda m: calls.append(1) or real(m))
    iterator = read_messages(good_bag)
    assert calls == []
    next(iterator)
    assert len(calls) == 1
    iterator.close()


def test_an_overwrite_that_cannot_finish_keeps_the_previous_bag(tmp_path, monkeypatch):
    """The new bag is renamed into place only when finished; if that rename fails, the previous bag is
    put back whole (same files, same messages) and no hidden staging folder is left behind."""
    import os

    bag = tmp_path / "bag"
    with BagWriter(bag) as w:
        w.write_joint_state("/joint_states", JointStateData(T0, ("a",), [1.0]))
    files = sorted(p.name for p in bag.iterdir())
    real, calls = os.replace, []

    def replace_failing_the_new_bag(src, dst):
        calls.append((src, dst))
        if len(calls) == 2:  # 1: the previous bag set aside, 2: the new one into place
            raise OSError("no space left on device")
        return real(src, dst)

    monkeypatch.setattr(os, "replace", replace_failing_the_new_bag)
    with pytest.raises(BagError, match="no space left"):
        with BagWriter(bag, overwrite=True) as w:
            w.write_joint_state("/joint_states", JointStateData(T0 + 10**9, ("a",), [2.0]))
    monkeypatch.undo()
    assert sorted(p.name for p in bag.iterdir()) == files
    assert [m.stamp_ns for m in read_messages(bag, wrench_topic=None)] == [T0]
    assert [p.name for p in tmp_path.iterdir()] == ["bag"]
