"""The node serves controllers over DDS: ``~/desired_state`` → ``~/feedforward*``, ``~/gravity_torques``,
and a short closed loop of a simulated torque-controlled Panda driven through it.

Expected values come from :func:`semiparam_ros.load_model` on the checkpoint the node warm-starts from
(the node does not learn in the first test, so both hold one model), and the closed loop is compared with
the same loop run in-process with the CAD model's feed-forward (RNEA on the URDF).
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray
from helpers.bags import learned_panda_checkpoint
from helpers.ros import REPO, NodeProcess, TestClient, diagnostic_values, make_ros_env
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from semiparam_ros import load_model
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
from semiparam_ros.sim.closed_loop import ArmPlant, desired_trajectory, pd_gains, run_loop

pytestmark = pytest.mark.ros

PANDA = REPO / "config" / "panda.yaml"
D = 100


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return learned_panda_checkpoint(tmp_path_factory.mktemp("ff_node"), "panda_ff", seed=0, n_features=D)


@pytest.fixture
def ros_env(tmp_path, monkeypatch):
    return make_ros_env(tmp_path, monkeypatch)


def _trajectory(names, stamp_ns, q, dq=None, ddq=None):
    msg = JointTrajectory()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 10**9)
    msg.joint_names = list(names)
    point = JointTrajectoryPoint(positions=[float(v) for v in q], time_from_start=Duration())
    if dq is not None:
        point.velocities = [float(v) for v in dq]
    if ddq is not None:
        point.accelerations = [float(v) for v in ddq]
    msg.points = [point]
    return msg


def _stamp(msg):
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def _controller(client, node):
    """A controller's publishers (desired states, joint states), once the node listens and answers."""
    desired_pub = client.node.create_publisher(JointTrajectory, "/estimator/desired_state", 10)
    js_pub = client.node.create_publisher(JointState, "/joint_states",
                                          QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    assert client.wait_for_publisher("/estimator/feedforward", timeout=60.0), node.output()
    deadline = time.monotonic() + 30
    while client.node.count_subscribers("/estimator/desired_state") == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    return desired_pub, js_pub


def _node(ros_env, checkpoint, *params):
    return NodeProcess(ros_env, [f"nonparametric.n_features:={D}", f"checkpoint.path:={checkpoint}",
                                 "checkpoint.period:=0.0", "diagnostics.period:=0.2", *params],
                       params_file=PANDA)


def test_feedforward_gravity_and_parts_over_dds(ros_env, checkpoint, tmp_path):
    model = load_model(checkpoint)
    joints = model.joints
    out_order = list(reversed(joints))
    ckpt = tmp_path / "copy.npz"
    ckpt.write_bytes(checkpoint.read_bytes())
    node = _node(ros_env, ckpt, "learning_enabled:=false", "parametric.consistent:=false",
                 "feedforward.joints:=[" + ",".join(out_order) + "]")
    client = TestClient(ros_env)
    try:
        commands = client.collect(Float64MultiArray, "/estimator/feedforward_commands")
        states = client.collect(JointState, "/estimator/feedforward")
        stds = client.collect(JointState, "/estimator/feedforward/std")
        gravity = client.collect(JointState, "/estimator/gravity_torques")
        parametric = client.collect(JointState, "/estimator/predicted_joint_torques/parametric")
        diagnostics = client.collect(DiagnosticArray, "/diagnostics")
        desired_pub, js_pub = _controller(client, node)

        rng = np.random.default_rng(0)
        perm = rng.permutation(7)
        names = [joints[i] for i in perm]
        sent = {}
        for k in range(3):
            q, dq, ddq = rng.uniform(-1, 1, 7), rng.uniform(-1, 1, 7), rng.uniform(-2, 2, 7)
            q[3] = -1.5
            stamp = 10**9 * (k + 1)
            sent[stamp] = (q, dq, ddq)
            desired_pub.publish(_trajectory(names, stamp, q[perm], dq[perm], ddq[perm]))
            time.sleep(0.1)
        # bad ones: an unknown joint, NaN, a short point — counted, never answered
        # (one at a time: the input keeps only the latest desired state, by design)
        for msg in (_trajectory([*names[:-1], "gripper"], 5 * 10**9, np.zeros(7)),
                    _trajectory(names, 6 * 10**9, np.r_[np.nan, np.zeros(6)]),
                    _trajectory(names, 7 * 10**9, np.zeros(6))):
            desired_pub.publish(msg)
            time.sleep(0.1)
        # missing velocities/accelerations: zeros with a counted warning
        q4 = np.r_[0.1, 0.2, 0.3, -1.2, 0.1, 1.0, 0.2]
        sent[8 * 10**9] = (q4, np.zeros(7), np.zeros(7))
        desired_pub.publish(_trajectory(names, 8 * 10**9, q4[perm]))
        # joint states for ~/gravity_torques (at the measured posture) and the parts
        for k in range(40):
            js = JointState()
            js.header.stamp.sec, js.header.stamp.nanosec = 20 + k // 100, (k % 100) * 10_000_000
            js.name = list(joints)
            js.position = [0.1 * np.sin(0.1 * k + i) for i in range(7)]
            js.position[3] -= 1.5
            js.velocity = [0.0] * 7
            js.effort = [1.0] * 7
            js_pub.publish(js)
            time.sleep(0.01)
        assert states.wait_for(lambda m: len(m) >= 4, timeout=10.0), node.output()
        assert gravity.wait_for(lambda m: len(m) >= 10, timeout=10.0), node.output()
        assert parametric.wait_for(lambda m: len(m) >= 10, timeout=10.0), node.output()
        time.sleep(0.5)
        assert diagnostics.wait_for(
            lambda m: diagnostic_values(m[-1]).get("feedforward.published") == str(len(sent)), 10.0)
        diag = diagnostic_values(diagnostics.snapshot()[-1])
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()

    back = [joints.index(j) for j in out_order]
    got = {_stamp(m): m for m in states.snapshot()}
    assert set(got) == set(sent), (sorted(got), sorted(sent))  # the bad ones were never answered
    assert len(commands.snapshot()) == len(stds.snapshot()) == len(sent)
    history = model.stick_state()  # consecutive desired states are one path (friction that remembers)
    for stamp, (q, dq, ddq) in sorted(sent.items()):
        msg = got[stamp]
        expected = model.predict_parts(q, dq, ddq, consistent=False, history=history).total
        assert list(msg.name) == out_order
        scale = 1 + np.abs(expected).max()
        np.testing.assert_allclose(msg.effort, expected[back], rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(msg.position, q[back], rtol=0, atol=0)
    for cmd in commands.snapshot():
        assert np.isfinite(cmd.data).all() and len(cmd.data) == 7
    for g in gravity.snapshot():
        np.testing.assert_allclose(g.effort, model.gravity(_posture(g), consistent=False), rtol=0, atol=1e-9)
    assert diag["feedforward.drops.unknown_joint"] == "1"
    assert diag["feedforward.drops.non_finite"] == "1" and diag["feedforward.drops.wrong_length"] == "1"
    assert int(diag["feedforward.missing_velocities"]) >= 1
    assert diag["feedforward.published"] == str(len(sent))


def _posture(msg):
    """The measured posture the node evaluated ~/gravity_torques at: the joint state of that stamp."""
    k = round((_stamp(msg) - 20 * 10**9) / 10_000_000)
    q = np.array([0.1 * np.sin(0.1 * k + i) for i in range(7)])
    q[3] -= 1.5
    return q


def test_short_closed_loop_through_the_node(ros_env, checkpoint, tmp_path):
    """A 1.5 s loop at 1 kHz in lockstep over DDS: the learned feed-forward beats the CAD one ≥ 2×."""
    rate, seconds = 1000.0, 1.5  # the gains' rule (2 Hz on the CAD diagonal) needs a 1 kHz loop
    plant = ArmPlant("panda", seed=0)
    t, qd, dqd, ddqd = desired_trajectory("panda", 777, seconds, rate)
    kp, kd = pd_gains(plant, qd[0])
    model = load_model(checkpoint)
    cad_ff = model.cad(qd, dqd, ddqd)
    cad = run_loop(plant, t, qd, dqd, ddqd, lambda k, *_: cad_ff[k], kp, kd, seed=2)

    ckpt = tmp_path / "copy.npz"
    ckpt.write_bytes(checkpoint.read_bytes())
    node = _node(ros_env, ckpt)  # learning on: the node goes on learning from the loop's joint states
    client = TestClient(ros_env)
    joints = list(model.joints)
    replies: dict[int, np.ndarray] = {}
    cond = threading.Condition()

    def on_ff(msg):
        with cond:
            replies[_stamp(msg)] = np.asarray(msg.effort)
            cond.notify_all()

    try:
        client.node.create_subscription(JointState, "/estimator/feedforward", on_ff, 100)
        desired_pub, js_pub = _controller(client, node)
        base = 100 * 10**9

        def feed(k, tk, q_m, dq_m, tau):
            js = JointState()
            js.header.stamp.sec, js.header.stamp.nanosec = divmod(base + round(tk * 1e9), 10**9)
            js.name, js.position, js.velocity, js.effort = joints, q_m.tolist(), dq_m.tolist(), tau.tolist()
            js_pub.publish(js)

        def over_dds(k, tk, q, dq, ddq, *_):
            stamp = base + round(tk * 1e9)
            desired_pub.publish(_trajectory(joints, stamp, q, dq, ddq))
            with cond:
                assert cond.wait_for(lambda: stamp in replies, timeout=5.0), node.output()
                return replies[stamp]

        learned = run_loop(plant, t, qd, dqd, ddqd, over_dds, kp, kd, seed=2, measured=feed)
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()
    rms_cad = np.sqrt(np.mean(cad.errors(0.5) ** 2))
    rms_learned = np.sqrt(np.mean(learned.errors(0.5) ** 2))
    assert rms_learned < 0.5 * rms_cad, (rms_learned, rms_cad)


def test_feedforward_uses_the_consistent_projection_solved_in_a_worker(ros_env, checkpoint, tmp_path):
    """With parametric.consistent (the default) the served model predicts with the worker process's
    physically consistent parameters: the same numbers as load_model(ckpt).predict(consistent=True)."""
    pytest.importorskip("cvxpy")
    model = load_model(checkpoint)
    joints = model.joints
    ckpt = tmp_path / "copy.npz"
    ckpt.write_bytes(checkpoint.read_bytes())
    node = _node(ros_env, ckpt, "learning_enabled:=false", "parametric.consistent_period:=0.5")
    client = TestClient(ros_env)
    try:
        from geometry_msgs.msg import InertiaStamped
        from helpers.ros import LATCHED_QOS

        links = client.collect(InertiaStamped, "/estimator/link_inertias",
                               QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE,
                                          durability=LATCHED_QOS.durability))
        states = client.collect(JointState, "/estimator/feedforward")
        diagnostics = client.collect(DiagnosticArray, "/diagnostics")
        desired_pub, _ = _controller(client, node)
        assert diagnostics.wait_for(
            lambda m: bool(m) and diagnostic_values(m[-1]).get("consistent.in_use") == "true", 60.0), \
            node.output()
        time.sleep(1.5)  # the served copy takes the solution at its next refresh (1 s)
        rng = np.random.default_rng(3)
        sent = {}
        for k in range(3):
            q, dq, ddq = rng.uniform(-1, 1, 7), rng.uniform(-1, 1, 7), rng.uniform(-2, 2, 7)
            q[3] = -1.5
            sent[10**9 * (k + 1)] = (q, dq, ddq)
            desired_pub.publish(_trajectory(joints, 10**9 * (k + 1), q, dq, ddq))
            time.sleep(0.1)
        assert states.wait_for(lambda m: len(m) >= 3, timeout=10.0), node.output()
        assert links.wait_for(lambda m: len(m) >= 7, timeout=10.0), node.output()
        reply = client.trigger("/estimator/export_urdf")
        assert reply.success, reply.message
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()
    estimate = model.consistent()
    by_link = {m.header.frame_id: m for m in links.snapshot()}
    assert set(by_link) == set(estimate.body_names)
    for i, link in enumerate(estimate.body_names):
        mass, com, _ = estimate.link(i)
        got = by_link[link].inertia
        assert got.m == pytest.approx(mass, rel=1e-6)
        np.testing.assert_allclose([got.com.x, got.com.y, got.com.z], com, rtol=1e-5, atol=1e-9)
    urdf = tmp_path / "copy_identified.urdf"
    assert urdf.is_file() and "<inertial>" in urdf.read_text() and "dynamics" in urdf.read_text()
    history, twin = model.stick_state(), model.stick_state()  # desired states are one path
    for msg in sorted(states.snapshot(), key=_stamp):
        q, dq, ddq = sent[_stamp(msg)]
        expected = model.predict_parts(q, dq, ddq, consistent=True, history=history).total
        unconstrained = model.predict_parts(q, dq, ddq, consistent=False, history=twin).total
        scale = 1 + np.abs(expected).max()
        np.testing.assert_allclose(msg.effort, expected, rtol=0, atol=1e-6 * scale)
        assert np.abs(np.asarray(msg.effort) - unconstrained).max() > 1e-6 * scale  # not the other one


def test_payload_tare_and_pickup_over_dds(ros_env, checkpoint):
    """``~/payload/tare``, then a pickup of the simulated Panda's preset payload: ``~/payload`` (latched)
    gives its mass and centre of mass in the distal link's frame, ``~/payload/std`` their σ; the truth is
    the simulator's change of the carrying body's parameters. ``~/inertial_parameters`` names its values."""
    from geometry_msgs.msg import InertiaStamped
    from helpers.ros import parameters_names_from_msg

    from semiparam_ros.core.rigid_body.payload import payload_from_parameters
    from semiparam_ros.sim.arms import ARM_ROBOTS, arm_regressor

    rec = simulate_arm(ArmScenarioConfig(name="panda_pickup", robot="panda", duration=10.0, rate=200.0,
                                         seed=0, payload_mass=ARM_ROBOTS["panda"].payload_mass,
                                         payload_time=2.0))
    reg = arm_regressor("panda")
    body = reg.body_index(reg.distal_body_name)
    cols = slice(10 * body, 10 * body + 10)
    truth = payload_from_parameters(rec.parameters_after[cols] - rec.parameters_before[cols],
                                    np.zeros((10, 10)), body=reg.distal_body_name, n_samples=0, reference="t")
    node = _node(ros_env, checkpoint, "overload.max_delay:=0.0",
                 "qos_overrides./joint_states.subscription.reliability:=reliable",
                 "qos_overrides./joint_states.subscription.depth:=10000")
    client = TestClient(ros_env)
    try:
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        payload = client.collect(InertiaStamped, "/estimator/payload", latched)
        payload_std = client.collect(InertiaStamped, "/estimator/payload/std", latched)
        params = client.collect(Float64MultiArray, "/estimator/inertial_parameters", latched)
        _, js_pub = _controller(client, node)
        assert client.trigger("/estimator/payload/tare").success
        for k in range(len(rec.stamps)):
            msg = JointState()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(rec.stamps[k]), 10**9)
            msg.name = list(rec.joint_names)
            msg.position, msg.velocity = rec.q_measured[k].tolist(), rec.dq_measured[k].tolist()
            msg.effort = rec.measured_torques[k].tolist()
            js_pub.publish(msg)
            time.sleep(0.001)
        assert payload.wait_for(lambda m: bool(m) and abs(m[-1].inertia.m - truth.mass) < 0.05 * truth.mass,
                                30.0), (payload.snapshot()[-1:], node.output())
        got = payload.snapshot()[-1]
        assert got.header.frame_id == truth.body
        com = np.array([got.inertia.com.x, got.inertia.com.y, got.inertia.com.z])
        assert np.linalg.norm(com - truth.com) < 0.01
        assert payload_std.wait_for(lambda m: bool(m) and m[-1].inertia.m > 0, 10.0)
        assert params.wait_for(lambda m: bool(m), 10.0)
        names = parameters_names_from_msg(params.snapshot()[-1])
        assert names == list(load_model(checkpoint).parameter_names)
    finally:
        client.close()
        node.stop()


def _jtc_cubic_accelerations(t, p, v):
    """q̈ at each point of the controller's cubic spline through (t, p, v): the segment starting there
    (the last point: the end of the last segment); coefficients as the controller computes them."""
    a = np.zeros_like(p)
    for k in range(len(t) - 1):
        T = t[k + 1] - t[k]
        a2 = (-3 * p[k] + 3 * p[k + 1] - 2 * v[k] * T - v[k + 1] * T) / T**2
        a3 = (2 * p[k] - 2 * p[k + 1] + v[k] * T + v[k + 1] * T) / T**3
        a[k] = 2 * a2
        if k == len(t) - 2:
            a[k + 1] = 2 * a2 + 6 * a3 * T
    return a


def _multi_point(names, t, p, v=None, a=None):
    msg = JointTrajectory()
    msg.joint_names = list(names)
    for k in range(len(t)):
        sec, nsec = divmod(round(t[k] * 1e9), 10**9)
        point = JointTrajectoryPoint(positions=p[k].tolist(), time_from_start=Duration(sec=sec, nanosec=nsec))
        if v is not None:
            point.velocities = v[k].tolist()
        if a is not None:
            point.accelerations = a[k].tolist()
        msg.points.append(point)
    return msg


def test_trajectory_with_effort_over_dds(ros_env, checkpoint, tmp_path):
    """~/trajectory → ~/trajectory_with_effort: each point's effort is load_model(...).predict at the point
    (missing accelerations from the controller's cubic, missing velocities from its linear segments), in the
    message's joint order, clamped to the URDF's effort limits (counted); bad trajectories are counted by
    reason and never published."""
    model = load_model(checkpoint)
    limits = model.estimator.regressor.effort_limits()  # the Panda's URDF gives every joint one
    clamped = 0
    joints = model.joints
    ckpt = tmp_path / "copy.npz"
    ckpt.write_bytes(checkpoint.read_bytes())
    node = _node(ros_env, ckpt, "learning_enabled:=false", "parametric.consistent:=false")
    client = TestClient(ros_env)
    rng = np.random.default_rng(3)
    perm = rng.permutation(7)
    names = [joints[i] for i in perm]
    m = 60
    # a smooth motion sampled at uneven points, times in whole ns as the message carries them (the cubic's
    # q̈ cancels terms ~40× larger than itself: a rounded time moves it by 1e-6 N·m)
    t = np.round(np.cumsum(rng.uniform(0.05, 0.2, m)) * 1e9) / 1e9
    w, phase = rng.uniform(0.5, 2.0, 7), rng.uniform(0, 2 * np.pi, 7)
    p = 0.8 * np.sin(np.outer(t, w) + phase) + np.r_[0, 0, 0, -1.5, 0, 1.0, 0]
    v = 0.8 * w * np.cos(np.outer(t, w) + phase)
    a = -0.8 * w**2 * np.sin(np.outer(t, w) + phase)
    good = [(p, v, a, "full"), (p, v, None, "cubic"), (p, None, None, "linear")]
    try:
        out = client.collect(JointTrajectory, "/estimator/trajectory_with_effort")
        diagnostics = client.collect(DiagnosticArray, "/diagnostics")
        pub = client.node.create_publisher(JointTrajectory, "/estimator/trajectory", 10)
        deadline = time.monotonic() + 60
        while client.node.count_subscribers("/estimator/trajectory") == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        for pk, vk, ak, _ in good:
            pub.publish(_multi_point(names, t, pk[:, perm], None if vk is None else vk[:, perm],
                                     None if ak is None else ak[:, perm]))
        ragged = _multi_point(names, t[:3], p[:3, perm], v[:3, perm])
        ragged.points[1].velocities = [0.0] * 6
        nan = _multi_point(names, t[:3], p[:3, perm])
        nan.points[2].positions[0] = float("nan")
        bad = {"unknown_joint": _multi_point([*names[:-1], "gripper"], t[:3], p[:3]),
               "missing_joint": _multi_point([*names[:-1], names[0]], t[:3], p[:3]),
               "wrong_length": ragged, "non_finite": nan,
               "unordered_time": _multi_point(names, t[:3][::-1], p[:3, perm]),
               "no_point": _multi_point(names, t[:0], p[:0])}
        for msg in bad.values():
            pub.publish(msg)
        assert out.wait_for(lambda got: len(got) >= len(good), timeout=30.0), node.output()
        assert diagnostics.wait_for(lambda d: all(diagnostic_values(d[-1]).get(f"trajectory.drops.{r}") == "1"
                                                  for r in bad), timeout=10.0), node.output()
        time.sleep(0.5)
        diag = diagnostic_values(diagnostics.snapshot()[-1])
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.output()
    got = out.snapshot()
    assert len(got) == len(good)  # the bad ones were never published
    for msg, (pk, vk, ak, kind) in zip(got, good, strict=True):
        if kind == "cubic":
            ak = _jtc_cubic_accelerations(t, pk, vk)
        elif kind == "linear":
            vk = np.vstack([np.diff(pk, axis=0) / np.diff(t)[:, None], np.zeros((1, 7))])
            ak = np.zeros_like(pk)
        unclamped = model.predict(pk, vk, ak, consistent=False)[0]
        clamped += int(np.any(np.abs(unclamped) > limits, axis=1).sum())
        expected = np.clip(unclamped, -limits, limits)
        effort = np.array([pt.effort for pt in msg.points])
        assert list(msg.joint_names) == names and len(msg.points) == m
        scale = 1 + np.abs(expected).max()
        np.testing.assert_allclose(effort, expected[:, perm], rtol=0, atol=1e-9 * scale, err_msg=kind)
        np.testing.assert_array_equal(np.array([pt.positions for pt in msg.points]), pk[:, perm])
        assert all(len(pt.accelerations) == (7 if kind == "full" else 0) for pt in msg.points)
    assert diag["trajectory.published"] == str(len(good)) and diag["trajectory.points"] == str(len(good) * m)
    assert diag["trajectory.fallback_points"] == "0"
    assert diag["trajectory.clamped_points"] == str(clamped) and clamped > 0
