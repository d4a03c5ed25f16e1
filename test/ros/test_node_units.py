"""In-process unit tests of the ROS side: conversions, parameter descriptors and validation, statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from helpers.ros import parameters_names_from_msg
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from semiparam_ros.core.config import ICUB_RIGHT_ARM, PARAMETERS, EstimatorConfig, parameter_spec
from semiparam_ros.core.stream.messages import joint_state_from_msg
from semiparam_ros.errors import RejectedSampleError
from semiparam_ros.ros.conversions import (
    SerializedOutput,
    joint_state_from_cdr,
    joint_torques_msg,
    parameters_msg,
    payload_msgs,
    stamp_msg,
    wrench_from_cdr,
    wrench_from_msg,
    wrench_stamped_msg,
)
from semiparam_ros.ros.diagnostics import NodeStatistics, diagnostic_array
from semiparam_ros.ros.parameters import descriptor_for, make_parameter_validator, runtime_parameter_names


def test_wrench_round_trip_through_cdr():
    w = np.array([1.5, -2.25, 9.81, 0.125, -0.5, 3e-7])
    msg = deserialize_message(serialize_message(wrench_stamped_msg(1_700_000_000_123_456_789, "s", w)),
                              type(wrench_stamped_msg(0, "", w)))
    data = wrench_from_msg(msg)
    assert data.stamp_ns == 1_700_000_000_123_456_789 and data.frame_id == "s"
    np.testing.assert_array_equal(data.wrench, w)
    with pytest.raises(ValueError, match="6 entries"):
        wrench_stamped_msg(0, "s", np.zeros(5))


@pytest.mark.parametrize("frame", ["", "s", "ft", "r_arm_ft_sensor", "a_frame_of_nine_chars"])
def test_serialized_wrench_output_is_what_rclpy_decodes(frame):
    """Patched CDR bytes decode (rclpy's own deserialiser) to the stamp and values given, bit for bit;
    frame lengths cover every string padding (whose bytes rclpy leaves unset, so no byte comparison)."""
    out = SerializedOutput(lambda stamp, w: wrench_stamped_msg(stamp, frame, w), 6)
    assert out.serialized  # x86/ARM: little-endian CDR
    rng = np.random.default_rng(0)
    for stamp in (0, 1_700_000_000_123_456_789, 5_000_000_001, -3, 2**31 * 10**9 - 1):
        w = rng.normal(size=6) * 10.0 ** rng.integers(-300, 300, size=6)
        w[rng.integers(6)] = rng.choice([np.nan, np.inf, -np.inf, -0.0])
        raw = out.fill(stamp, w)
        assert isinstance(raw, bytes)
        assert len(raw) == len(serialize_message(wrench_stamped_msg(stamp, frame, w)))  # (padding bytes vary)
        data = wrench_from_msg(deserialize_message(raw, WrenchStamped))
        assert data.stamp_ns == max(stamp, 0) and data.frame_id == frame
        np.testing.assert_array_equal(data.wrench.view(np.int64), w.view(np.int64))  # bit for bit
    with pytest.raises(ValueError, match="expected 6 values"):
        out.fill(0, np.zeros(5))


@pytest.mark.parametrize("joints", [("a",), ("j1", "joint_2"), ("r_shoulder_pitch", "r_shoulder_roll",
                                                                 "r_shoulder_yaw", "r_elbow", "x")])
def test_serialized_joint_torques_output_is_what_rclpy_decodes(joints):
    out = SerializedOutput(lambda stamp, tau: joint_torques_msg(stamp, joints, tau), len(joints))
    assert out.serialized
    for stamp, tau in ((7, np.arange(len(joints)) - 1.5),
                       (1_700_000_000_000_000_001, np.full(len(joints), 1e-9))):
        raw = out.fill(stamp, tau)
        assert len(raw) == len(serialize_message(joint_torques_msg(stamp, joints, tau)))
        msg = deserialize_message(raw, JointState)
        assert tuple(msg.name) == joints and len(msg.position) == len(msg.velocity) == 0
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == stamp
        np.testing.assert_array_equal(np.asarray(msg.effort), tau)


def test_stamp_conversion_is_exact_and_clamps_negative():
    t = stamp_msg(5_000_000_001)
    assert (t.sec, t.nanosec) == (5, 1)
    t = stamp_msg(-3)
    assert (t.sec, t.nanosec) == (0, 0)


def test_joint_torques_and_joint_state_conversion():
    msg = joint_torques_msg(42, ["a", "b"], np.array([1.0, -2.0]))
    assert list(msg.name) == ["a", "b"] and list(msg.effort) == [1.0, -2.0] and len(msg.position) == 0
    with pytest.raises(ValueError):
        joint_torques_msg(42, ["a"], np.array([1.0, 2.0]))
    js = JointState(name=["x", "y"], position=[0.1, float("nan")], velocity=[1.0, 2.0])
    data = joint_state_from_msg(deserialize_message(serialize_message(js), JointState))
    assert data.names == ("x", "y") and math.isnan(data.position[1])  # kept: the pipeline drops it


def test_parameters_message_names_and_layout():
    """Each value named by a label of its own (commas in names survive); a valid n × 1 × 1 × 1 layout."""
    names = ["m_r_upper_arm", "mcx_r_upper_arm + 0.3*m,x", "Izz"]
    msg = deserialize_message(serialize_message(parameters_msg(names, np.array([1.0, 2.0, 3.0]))),
                              Float64MultiArray)
    assert parameters_names_from_msg(msg) == names
    dims = msg.layout.dim
    expected = [("base_parameters", 3, 3)] + [(n, 1, 1) for n in names]
    assert [(d.label, d.size, d.stride) for d in dims] == expected
    assert dims[0].stride == int(np.prod([d.size for d in dims]))  # the strides of a valid layout
    assert {d.label: v for d, v in zip(dims[1:], msg.data, strict=True)} == dict(zip(names, [1.0, 2.0, 3.0],
                                                                                    strict=True))
    with pytest.raises(ValueError):
        parameters_msg(names, np.zeros(2))


def test_payload_messages_carry_the_estimate_and_its_std_in_the_distal_frame():
    from semiparam_ros.core.rigid_body.dynamics import point_mass_parameters
    from semiparam_ros.core.rigid_body.payload import payload_from_parameters

    delta = point_mass_parameters(1.5, [0.01, -0.02, 0.1])
    delta[4:] += [0.01, 0.0, 0.02, 0.0, 0.0, 0.03]  # plus an inertia of its own (Ixx, Iyy, Izz)
    est = payload_from_parameters(delta, np.diag(np.full(10, 1e-6)), body="link7", n_samples=10,
                                  reference="tare")
    value, std = payload_msgs(est, 1_700_000_000_123_456_789)
    for msg in (value, std):
        assert msg.header.frame_id == "link7"
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert value.inertia.m == pytest.approx(1.5)
    com = (value.inertia.com.x, value.inertia.com.y, value.inertia.com.z)
    assert com == pytest.approx((0.01, -0.02, 0.1))
    assert (value.inertia.ixx, value.inertia.iyy, value.inertia.izz) == pytest.approx((0.01, 0.02, 0.03))
    assert std.inertia.m == pytest.approx(1e-3)  # the std of m is that of δ₀
    assert std.inertia.com.z == pytest.approx(est.com_std[2])


@pytest.mark.parametrize("spec", PARAMETERS, ids=lambda s: s.name)
def test_descriptor_matches_the_table(spec):
    desc = descriptor_for(spec)
    assert desc.name == spec.name and desc.description == spec.description
    assert desc.read_only == spec.read_only
    assert desc.additional_constraints == spec.range_text()
    expected_type = {"double": ParameterType.PARAMETER_DOUBLE, "integer": ParameterType.PARAMETER_INTEGER,
                     "bool": ParameterType.PARAMETER_BOOL, "string": ParameterType.PARAMETER_STRING,
                     "string_array": ParameterType.PARAMETER_STRING_ARRAY,
                     "double_array": ParameterType.PARAMETER_DOUBLE_ARRAY}[spec.type]
    assert desc.type == expected_type
    if spec.type == "integer" and spec.min is not None:
        assert desc.integer_range[0].from_value == int(spec.min) + (1 if spec.min_exclusive else 0)
    if spec.type == "double" and spec.min is not None and not spec.min_exclusive:
        assert desc.floating_point_range[0].from_value == spec.min
        assert desc.floating_point_range[0].to_value == (spec.max if spec.max is not None else math.inf)


def test_runtime_validator():
    config = EstimatorConfig.from_flat(ICUB_RIGHT_ARM)
    validate = make_parameter_validator(lambda: config)
    assert set(runtime_parameter_names()) == {p.name for p in PARAMETERS if not p.read_only}
    assert "learning_enabled" in runtime_parameter_names()
    ok = validate([Parameter("learning_enabled", Parameter.Type.BOOL, False)])
    assert ok.successful
    bad = validate([Parameter("checkpoint.period", Parameter.Type.DOUBLE, -1.0)])
    assert not bad.successful and "checkpoint.period" in bad.reason and parameter_spec(
        "checkpoint.period").range_text() in bad.reason
    ro = validate([Parameter("nonparametric.n_features", Parameter.Type.INTEGER, 10)])
    assert not ro.successful and "read-only" in ro.reason
    other = validate([Parameter("use_sim_time", Parameter.Type.BOOL, True)])  # left to rclpy
    assert other.successful


def test_statistics_windowed_rmse_latency_and_levels():
    stats = NodeStatistics("wrench", 6, rmse_window=3)
    y = np.zeros(6)
    for k, err in enumerate([10.0, 1.0, 2.0, 3.0]):  # the window keeps the last 3
        stats.count_input("joint_states")
        stats.count_input("wrench")
        stats.add_sample(1e-3 * (k + 1), 2e-3, y, np.full(6, err), np.full(6, 2 * err))
    snap = stats.snapshot()
    assert snap["rmse_force_N"] == pytest.approx(math.sqrt((1 + 4 + 9) / 3))
    assert snap["rmse_parametric_force_N"] == pytest.approx(2 * math.sqrt((1 + 4 + 9) / 3))
    assert snap["update_latency_max_ms"] == pytest.approx(4.0)
    assert snap["update_latency_mean_ms"] == pytest.approx(2.5)
    assert snap["joint_states_received"] == 4 and snap["samples_predicted"] == 4
    assert diagnostic_array(stamp_msg(0), "n", "h", snap).status[0].level == DiagnosticStatus.OK
    stats.count_drop("queue_full", 2)
    snap = stats.snapshot()
    assert snap["queue_drops"] == 2 and snap["inputs_in_period"] == 0
    assert math.isnan(snap["update_latency_mean_ms"])  # a new period without samples
    msg = diagnostic_array(stamp_msg(0), "n", "h", snap)
    assert msg.status[0].level == DiagnosticStatus.WARN
    assert diagnostic_array(stamp_msg(0), "n", "h", snap, stalled=True).status[0].level == \
        DiagnosticStatus.ERROR
    values = {kv.key: kv.value for kv in msg.status[0].values}
    assert values["queue_drops"] == "2"


def _same_data(a, b):
    """Equal field by field, floats bit for bit (NaN payloads and -0.0 included)."""
    assert type(a) is type(b) and a.stamp_ns == b.stamp_ns
    for field in ("names", "frame_id"):
        assert getattr(a, field, None) == getattr(b, field, None)
    for field in ("position", "velocity", "effort", "force", "torque"):
        if hasattr(a, field):
            x, y = getattr(a, field), getattr(b, field)
            assert x.dtype == y.dtype == np.float64 and x.shape == y.shape
            assert x.tobytes() == y.tobytes()


def test_cdr_decoders_equal_rclpy_deserialisation(monkeypatch):
    """The fast CDR readers give exactly what rclpy's deserialiser + the message converters give, on random
    messages covering every string/sequence alignment, empty and mismatched arrays, NaN/inf, odd stamps."""
    from semiparam_ros.ros import conversions

    def no_fallback(raw, msg_type):
        raise AssertionError("the fast path fell back to rclpy")

    monkeypatch.setattr(conversions, "_deserialize", no_fallback)  # every message here takes the fast path
    rng = np.random.default_rng(1)

    def text(n):
        return "".join(rng.choice(list("abcxyz_019é")) for _ in range(n))

    def values(n):
        v = rng.normal(size=n) * 10.0 ** rng.integers(-5, 5, size=n)
        if n:
            v[rng.integers(n)] = rng.choice([np.nan, np.inf, -0.0, 1.0])
        return v

    for _ in range(300):
        js = JointState(name=[text(int(rng.integers(0, 10))) for _ in range(int(rng.integers(0, 8)))],
                        position=values(int(rng.integers(0, 8))).tolist(),
                        velocity=values(int(rng.integers(0, 8))).tolist(),
                        effort=values(int(rng.integers(0, 3))).tolist())
        js.header.stamp.sec = int(rng.integers(-2**31, 2**31))
        js.header.stamp.nanosec = int(rng.integers(0, 10**9))
        js.header.frame_id = text(int(rng.integers(0, 12)))
        raw = bytes(serialize_message(js))
        _same_data(joint_state_from_cdr(raw), joint_state_from_msg(deserialize_message(raw, JointState)))
        js.header.stamp.nanosec = (js.header.stamp.nanosec + 1) % 10**9  # same names: the cached ones
        js.position = values(len(js.position)).tolist()
        raw = bytes(serialize_message(js))
        _same_data(joint_state_from_cdr(raw), joint_state_from_msg(deserialize_message(raw, JointState)))
        w = wrench_stamped_msg(int(rng.integers(0, 2**62)), text(int(rng.integers(0, 12))), values(6))
        raw = bytes(serialize_message(w))
        _same_data(wrench_from_cdr(raw), wrench_from_msg(deserialize_message(raw, WrenchStamped)))


def test_cdr_decoders_fall_back_to_rclpy_and_reject_garbage():
    # big-endian CDR, written by hand: not the fast path; rclpy's deserialiser reads it
    import struct

    frame = b"sensor\0"
    body = struct.pack(">iII", 5, 7, len(frame)) + frame
    body += b"\0" * (-len(body) % 8) + struct.pack(">6d", *np.arange(6.0) - 2.5)
    data = wrench_from_cdr(b"\x00\x00\x00\x00" + body)
    assert (data.stamp_ns, data.frame_id) == (5_000_000_007, "sensor")
    np.testing.assert_array_equal(data.wrench, np.arange(6.0) - 2.5)
    for garbage in (b"", b"\x00\x01\x00\x00", b"\x00\x01\x00\x00" + b"\xff" * 13, b"\x07" * 40):
        with pytest.raises(RejectedSampleError):
            wrench_from_cdr(garbage)
        with pytest.raises(RejectedSampleError):
            joint_state_from_cdr(garbage)
