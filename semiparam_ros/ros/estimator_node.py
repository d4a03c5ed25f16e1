"""The ``estimator`` node: online semiparametric inverse-dynamics learning on live ROS 2 topics.

Run it with::

    ros2 run semiparam_ros estimator --ros-args --params-file config/icub_right_arm.yaml
    python -m semiparam_ros.ros.estimator_node --ros-args --params-file config/icub_right_arm.yaml

The node is a thin adapter over the pure core: messages are converted to
:mod:`semiparam_ros.core.messages` types and fed to :class:`~semiparam_ros.core.estimator.OnlineEstimator`,
the same object offline replay uses, so a bag gives the same numbers either way.

Topics (relative names, remap with ``-r``):

* in ``joint_states`` (``sensor_msgs/JointState``) and ``wrench`` (``geometry_msgs/WrenchStamped``), names
  from ``topics.*``; sensor-data QoS (best effort, volatile) with a history of 100 so a scheduling hiccup
  at 1 kHz loses nothing; reliability/depth can be overridden with
  ``-p qos_overrides./joint_states.subscription.reliability:=reliable`` (standard QoS overrides);
* out ``~/predicted_wrench`` (semiparametric prediction, the input's stamp and frame),
  ``~/predicted_wrench/parametric`` (rigid-body part), ``~/predicted_wrench/nonparametric`` (residual);
  with ``robot.output: joint_torques`` instead ``~/predicted_joint_torques`` (``sensor_msgs/JointState``,
  ``effort`` in N·m) with ``/parametric`` and ``/nonparametric`` (the un-namespaced
  ``predicted_joint_torques`` of earlier releases is still published, deprecated, for one release);
  every prediction is a priori: it was made before its own sample was learned;
* out ``~/predicted_wrench/model`` (or ``~/predicted_joint_torques/model``): the model alone — rigid-body
  part plus the residual where the state is known, without the fast tracker of its recent error
  (``semiparametric.combination: consistent``; the same as the prediction for the other combinations):
  what a feed-forward term or a frozen model gives (:mod:`semiparam_ros.core.semiparametric_consistent`);
* out, for contact detection and control (same stamp and frame as the prediction):
  ``~/external_wrench`` (``WrenchStamped``, measured − predicted: the wrench the model does not explain,
  i.e. external forces at the robot) and ``~/predicted_wrench/std`` (``WrenchStamped`` whose six
  components are the predictive standard deviations σ of the six components [N, N·m], noise included;
  σ is also the standard deviation of ``~/external_wrench`` when nothing touches the robot); with
  ``robot.output: joint_torques`` instead ``~/external_joint_torques`` and
  ``~/predicted_joint_torques/std`` (``JointState``, ``effort`` = external torques / σ [N·m]); σ is +inf
  before the first sample (see :mod:`semiparam_ros.core.uncertainty`); a sample the contact gate
  refuses to learn is still predicted and published (:mod:`semiparam_ros.core.gate`);
* for controllers (``robot.output: joint_torques``; :mod:`semiparam_ros.core.feedforward`): in
  ``~/desired_state`` (``trajectory_msgs/JointTrajectory``, best effort, depth 1: only the latest
  matters), answered at once — before the next queued sample is learned — on ``~/feedforward_commands``
  (``std_msgs/Float64MultiArray``, τ_ff [N·m] in the order of ``feedforward.joints``: a
  ``JointGroupEffortController``'s ``~/commands``), ``~/feedforward`` (``JointState``: stamp = the time
  evaluated, position/velocity = the desired state used, effort = τ_ff) and ``~/feedforward/std``
  (effort = σ); the model is served from a copy refreshed every ``feedforward.refresh_period``; it falls
  back to the rigid-body part while not ready or where σ > ``feedforward.max_std``; drops, fallbacks and
  the age of answered states are in diagnostics (``feedforward.*``); with ``parametric.consistent`` the
  served copy predicts with the physically consistent parameters a worker process re-solves every
  ``parametric.consistent_period`` (:class:`~semiparam_ros.core.identification.ProjectionWorker`,
  ``consistent.*`` in diagnostics), published per link on ``~/link_inertias``
  (``geometry_msgs/InertiaStamped``, frame_id = the link, mass, centre of mass and inertia about it;
  reliable, transient local) and written as a URDF next to the checkpoint by ``~/export_urdf``
  (``std_srvs/Trigger``); out ``~/gravity_torques``
  (``JointState``, effort = gravity torques of the identified inertias at each sample's measured
  posture, N·m);
* out ``~/inertial_parameters`` (``std_msgs/Float64MultiArray``, base parameters in physical units, then
  friction/offset terms such as ``lwr_0_joint.viscous``, names comma-joined in ``layout.dim[0].label``;
  reliable + transient local, depth 1): published once per diagnostics period when learning changed them,
  and after start, reset and load;
* out ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``) every ``diagnostics.period`` (wall time),
  keys listed in :mod:`semiparam_ros.ros.diagnostics`;
* the per-sample outputs (predictions, external wrench/torques, σ) are published only while they have a
  subscriber (no one else can tell), as CDR bytes patched per sample
  (:class:`~semiparam_ros.ros.conversions.SerializedOutput`).

Services (``std_srvs/Trigger``): ``~/save`` writes a checkpoint to ``checkpoint.path`` (atomic; the reply
comes once the file is on disk, or a failure after 5 s if the disk blocks; it is served by a hidden helper
node ``_<name>_save`` in a thread of its own, so learning goes on meanwhile), ``~/reset`` forgets
everything learned.

Threads. One executor thread runs everything that touches the estimator: rclpy's ``EventsExecutor`` by
default (its event queue and timers live in C++: less CPU and lower latency than the classic executor,
measured in docs/performance.md), ``--executor single_threaded`` for the classic
``SingleThreadedExecutor``. A subscription callback converts the message (taken serialised and read by
:func:`~semiparam_ros.ros.conversions.joint_state_from_cdr` / ``wrench_from_cdr``),
appends it to a bounded deque (``queue_size``; when full the oldest entry is dropped and counted), takes
what else is already waiting on that subscription, and runs the estimator on the queue at once (predict,
publish, then learn): no executor round trip lies between receipt and prediction. At most 50 messages are
processed per callback so that inputs, services and timers get their turns; a backlog beyond that is
worked off by a catch-up timer armed only while input is waiting. Overload: a sample that waited longer
than ``overload.max_delay`` (1 ms) — or would wait behind the previous sample's deferred update beyond it
— is predicted at once with the residual held from the last full prediction and not learned
(``learning_skipped``), and the deferred update of a learned sample runs in an idle turn of its own, so
predictions stay fresh whatever the learning load (docs/reliability.md). Why not a learner thread (or a
``MultiThreadedExecutor``): on CPython the executor thread and a learner thread serialise on the GIL, and
every hand-over costs (measured in docs/design-notes.md).
A second thread only writes checkpoints (periodically every ``checkpoint.period`` seconds of wall time,
on ``~/save``, on clean shutdown): it snapshots the learned state under a lock (a memory copy, ~1 ms at
D = 500) and writes outside it, so neither callbacks nor learning ever wait for the disk. A third thread
spins the hidden helper node serving ``~/save``, whose reply waits for that write. On a clean
shutdown (Ctrl-C, SIGTERM) the messages still in the input queue are learned first (without publishing;
at most ``queue_size`` messages, a few hundred ms at D = 500), so the final checkpoint holds everything
received. A node killed with SIGKILL loses at most the samples learned since the last periodic
checkpoint.

Bad input (NaN/inf, unknown or missing joints, wrong frame, out-of-order or zero stamps, samples the
learner rejects) is dropped, counted by reason in ``/diagnostics`` and logged at most every 5 s; it never
stops the node or reaches the model. Any other exception in a callback is a programming error: it is
logged at FATAL level, is not counted as a drop, and propagates out of ``spin``, which ends the process
(see :func:`main`).
"""

from __future__ import annotations

import argparse
import collections
import concurrent.futures
import functools
import gc
import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import InertiaStamped, WrenchStamped
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger
from threadpoolctl import threadpool_limits
from trajectory_msgs.msg import JointTrajectory

from semiparam_ros.atomic import atomic_write_text, remove_stale_temporaries
from semiparam_ros.core.checkpoint import atomic_save_npz
from semiparam_ros.core.config import EstimatorConfig, describe_parameters
from semiparam_ros.core.dynamics import TOPIC_SCHEME
from semiparam_ros.core.estimator import OnlineEstimator, StepResult, build_regressor, rmse_window_samples
from semiparam_ros.core.feedforward import FeedForward
from semiparam_ros.core.gate import Verdict
from semiparam_ros.core.identification import ProjectionWorker, export_urdf
from semiparam_ros.core.messages import JointStateData, WrenchData
from semiparam_ros.core.serving import LearnedModel
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError
from semiparam_ros.ros.conversions import (
    SerializedOutput,
    desired_state_from_msg,
    feedforward_msgs,
    joint_state_from_cdr,
    joint_state_from_msg,
    joint_torques_msg,
    link_inertia_msgs,
    parameters_msg,
    payload_msgs,
    wrench_from_cdr,
    wrench_from_msg,
    wrench_stamped_msg,
)
from semiparam_ros.ros.diagnostics import NodeStatistics, diagnostic_array
from semiparam_ros.ros.parameters import (
    ParameterError,
    declare_parameters,
    make_parameter_validator,
)

__all__ = ["INPUT_QOS", "PARAMETERS_QOS", "EstimatorNode", "StartupError", "main"]

#: Sensor-data QoS of the inputs (best effort, volatile), with a deeper history than the default 5.
INPUT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
#: Latched output of the inertial parameters: a late subscriber gets the latest estimate.
PARAMETERS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
_OUTPUT_QOS = 100
#: The feed-forward answers: reliable (what a JointGroupEffortController's ~/commands expects), shallow.
_FF_QOS = 10
#: Desired states: only the latest matters; best effort accepts reliable and best-effort publishers.
_DESIRED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.VOLATILE)
_LOG_THROTTLE_S = 5.0
_BATCH = 50  # queued messages processed per turn of the executor (≈ 10–20 ms of learning at most)
_SHUTDOWN_BUDGET_S = 10.0  # time allowed to learn the queue at shutdown (1000 messages take ≈ 0.2 s)
_CATCH_UP_PERIOD_S = 1e-4  # the backlog timer fires at every executor turn while armed
_SPIN_TIMEOUT_S = 0.1  # EventsExecutor.spin_once timeout (see spin())
_MAX_DRAIN = 64  # messages taken per subscription callback at most (bounds the executor's time away)
_WARM_UP_MAX_SAMPLES = 2000  # synthetic 1 kHz samples the kernel warm-up feeds at most (_warm_up_kernels)
_SAVE_TIMEOUT_S = 5.0  # ~/save waits this long for the checkpoint thread, then replies failure
_MIN_NAME_BOUND = 1024
_MAX_LOST_PER_EVENT = 100_000  # a larger lost-message count in one event is a middleware counter glitch


_Callback = TypeVar("_Callback", bound=Callable[..., Any])


def _quiet_at_shutdown(method: _Callback) -> _Callback:
    """Let a callback that the shutdown interrupted end quietly.

    SIGTERM and SIGINT invalidate the context asynchronously, from rclpy's signal handler: a callback in
    the middle of a publish then gets a RuntimeError ("publisher's context is invalid"). That is the
    shutdown, not a bug: the callback returns, and ``main`` learns the queue and writes the final
    checkpoint. With the context still valid any exception propagates (a programming error).
    """

    @functools.wraps(method)
    def guarded(self: EstimatorNode, *args: Any) -> Any:
        try:
            return method(self, *args)
        except Exception:
            if self.context.ok():
                raise
            return None

    return guarded  # type: ignore[return-value]


class StartupError(RuntimeError):
    """The node cannot start (invalid parameters, incompatible checkpoint); the message says why."""


class EstimatorNode(Node):
    """ROS 2 node running :class:`OnlineEstimator` on live topics.

    Args:
        node_name: Node name (parameters are read from this name's block of the parameter file).
        deferred: Only declare the parameters; :meth:`_build` makes the rest (the lifecycle node's
            configure, :mod:`semiparam_ros.ros.lifecycle_node`).
        **kwargs: Passed to :class:`rclpy.node.Node` (e.g. ``context``, ``parameter_overrides``).

    Raises:
        StartupError: If a parameter is invalid or the checkpoint to warm start from is incompatible; the
            node is destroyed before raising.
    """

    def __init__(self, node_name: str = "estimator", *, deferred: bool = False, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        #: Whether inputs are processed and outputs published (a lifecycle node: only while active).
        self._active = True
        try:
            self._declare()
            if not deferred:
                self._build()
        except BaseException:
            self._stop_threads(save=False)
            self.destroy_node()
            raise

    # ================================================================== set-up
    def _declare(self) -> None:
        """Declare and validate the parameters (a lifecycle node does this at construction)."""
        self._last_warning: dict[str, float] = {}  # key → monotonic time of the last throttled warning
        self._ckpt_thread: threading.Thread | None = None
        #: Whether the final checkpoint (at shutdown) was written, or none was due; ``main`` exits 1 if not.
        self.final_checkpoint_ok = True
        try:
            self.config: EstimatorConfig = declare_parameters(self)
        except ParameterError as err:
            raise StartupError(f"invalid parameter: {err}") from err

    def _build(self, urdf_xml: str | None = None) -> None:
        """Build the estimator, its entities and threads (a lifecycle node: on configure).

        Args:
            urdf_xml: The URDF text when it came from a topic already (``robot.urdf: topic:…``).
        """
        self._stopping = threading.Event()
        cfg = self.config
        self._output = cfg["robot.output"]
        self._joints = tuple(cfg["robot.joints"])
        # a JointState with more names than this is refused before its names are decoded (a robot lists
        # its joints, perhaps a few hands and grippers more: not thousands)
        self._max_names = max(_MIN_NAME_BOUND, 16 * len(self._joints))
        self._frame_id = cfg["robot.frame_id"]
        self._ckpt_path = Path(cfg["checkpoint.path"]).expanduser() if cfg["checkpoint.path"] else None
        self._ckpt_period = float(cfg["checkpoint.period"])

        if urdf_xml is None and str(cfg["robot.urdf"]).startswith(TOPIC_SCHEME):
            urdf_xml = self._wait_for_description(str(cfg["robot.urdf"])[len(TOPIC_SCHEME):],
                                                  float(cfg["robot.description_timeout"]))
        try:
            regressor = build_regressor(cfg, urdf_xml, source=f"published on {cfg['robot.urdf']}")
            self._estimator = OnlineEstimator(cfg, regressor=regressor)
        except (ConfigurationError, OSError) as err:
            raise StartupError(f"cannot build the estimator: {err}") from err
        self._warm_up_kernels()
        self._warm_start(bool(cfg["checkpoint.load_on_start"]))
        self._estimator.learning_enabled = bool(cfg["learning_enabled"])
        # the model at any state (feed-forward, gravity); never solves the consistent projection here
        self._serving = LearnedModel(self._estimator, solve=False)
        self._projection: ProjectionWorker | None = None
        self._projection_version = -1
        self._ff_solved = -1
        self._feedforward: FeedForward | None = None
        self._desired_sub: Any = None
        self._ff_latency_ms: list[float] = []  # desired state stamped → feed-forward published, this period
        if self._output == "joint_torques":
            try:
                self._feedforward = FeedForward(self._serving, joints=cfg["feedforward.joints"] or None,
                                                max_std=cfg["feedforward.max_std"])
            except ConfigurationError as err:
                raise StartupError(f"invalid parameter: {err}") from err

        # State shared by the executor thread and the checkpoint thread.
        self._model_lock = threading.Lock()
        self._queue: collections.deque[tuple[str, JointStateData | WrenchData, float]] = collections.deque()
        self._queue_size = int(cfg["queue_size"])
        self._max_delay_s = float(cfg["overload.max_delay"])
        self._fused_cost_s = 0.0  # measured cost of a step that also applies a deferred update [s]
        self._version = 0  # bumped whenever the learned state changes (learning, reset)
        self._published_version = -1
        self._ckpt_event = threading.Event()
        self._ckpt_requests: list[concurrent.futures.Future[tuple[bool, str]]] = []
        self._ckpt_lock = threading.Lock()
        self._ckpt_reset_pending = False
        self._saved_version = 0
        self._last_wrench_frame = self._frame_id
        self._last_drop_total = 0
        n_out = 6 if self._output == "wrench" else len(self._joints)
        # in samples; a window given in seconds is converted again once the estimator measured the rate
        self._stats = NodeStatistics(self._output, n_out, rmse_window_samples(cfg))
        self._rmse_window_final = bool(cfg["diagnostics.rmse_window"])

        # Outputs.
        # Outputs carry no event handlers: every handler is one more entity in each executor wait, and at
        # 2 kHz input the wait-set overhead is the executor's main cost.
        def publisher(msg_type: type, topic: str, qos: QoSProfile | int) -> Any:
            return self.create_publisher(msg_type, topic, qos,
                                         event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

        self._out_frame: str | None = None  # frame of self._out_template (wrench output)
        self._out_template = (None if self._output == "wrench" else SerializedOutput(
            lambda stamp, tau: joint_torques_msg(stamp, self._joints, tau), len(self._joints)))
        if self._output == "wrench":
            self._pub_total = publisher(WrenchStamped, "~/predicted_wrench", _OUTPUT_QOS)
            self._pub_param = publisher(WrenchStamped, "~/predicted_wrench/parametric", _OUTPUT_QOS)
            self._pub_resid = publisher(WrenchStamped, "~/predicted_wrench/nonparametric", _OUTPUT_QOS)
            self._pub_model = publisher(WrenchStamped, "~/predicted_wrench/model", _OUTPUT_QOS)
            self._pub_external = publisher(WrenchStamped, "~/external_wrench", _OUTPUT_QOS)
            self._pub_std = publisher(WrenchStamped, "~/predicted_wrench/std", _OUTPUT_QOS)
        else:
            self._pub_total = publisher(JointState, "~/predicted_joint_torques", _OUTPUT_QOS)
            # the name outside ~/ of earlier releases, kept one release (deprecated, logged once)
            self._pub_legacy = publisher(JointState, "predicted_joint_torques", _OUTPUT_QOS)
            self._pub_param = publisher(JointState, "~/predicted_joint_torques/parametric", _OUTPUT_QOS)
            self._pub_resid = publisher(JointState, "~/predicted_joint_torques/nonparametric", _OUTPUT_QOS)
            self._pub_model = publisher(JointState, "~/predicted_joint_torques/model", _OUTPUT_QOS)
            self._pub_external = publisher(JointState, "~/external_joint_torques", _OUTPUT_QOS)
            self._pub_std = publisher(JointState, "~/predicted_joint_torques/std", _OUTPUT_QOS)
            self._pub_gravity = publisher(JointState, "~/gravity_torques", _OUTPUT_QOS)
            self._pub_ff_commands = publisher(Float64MultiArray, "~/feedforward_commands", _FF_QOS)
            self._pub_ff = publisher(JointState, "~/feedforward", _FF_QOS)
            self._pub_ff_std = publisher(JointState, "~/feedforward/std", _FF_QOS)
            self._desired_sub = self.create_subscription(JointTrajectory, "~/desired_state",
                                                         self._on_desired_state, _DESIRED_QOS)
        self._pub_params = publisher(Float64MultiArray, "~/inertial_parameters", PARAMETERS_QOS)
        # the payload the distal body carries (since ~/payload/tare, or beyond the URDF): latched
        self._pub_payload = publisher(InertiaStamped, "~/payload", PARAMETERS_QOS)
        self._pub_payload_std = publisher(InertiaStamped, "~/payload/std", PARAMETERS_QOS)
        self._payload_key: tuple[int, int] | None = None  # (learned version, solutions) last published
        self._excitation: tuple[float, int, dict[str, object]] | None = None  # (time, version, stats)
        self._pub_diag = publisher(DiagnosticArray, "/diagnostics", 10)

        # Inputs: callbacks only convert and enqueue. Messages lost inside DDS (a best-effort history
        # overflowing) are reported by the middleware and counted too.
        overrides = QoSOverridingOptions.with_default_policies()
        self._subscriptions_by_kind: dict[str, Any] = {}
        for msg_type, key, callback in ((JointState, "topics.joint_states", self._on_joint_state),
                                        (WrenchStamped, "topics.wrench", self._on_wrench)):
            topic = cfg[key]
            events = SubscriptionEventCallbacks(
                incompatible_qos=self._incompatible_qos_logger(topic),
                message_lost=self._message_lost_counter(topic),
                use_default_callbacks=False)
            self._subscriptions_by_kind[key.split(".")[1]] = self.create_subscription(
                msg_type, topic, callback, INPUT_QOS, qos_overriding_options=overrides,
                event_callbacks=events, raw=True)  # serialised: conversions.*_from_cdr decode them

        js, wr = (("joint_states", self._subscriptions_by_kind["joint_states"]),
                  ("wrench", self._subscriptions_by_kind["wrench"]))
        self._drain_order = {"joint_states": (wr, js), "wrench": (js, wr)}

        # Services, parameters and timers (wall time, so diagnostics go on when /clock stops).
        # ~/save waits for the file: it is served by a hidden helper node spun in a thread of its own, so
        # the wait blocks neither executor's learning (and needs no coroutine, which the EventsExecutor
        # never awaits). The name is resolved here with this node's remappings; the helper takes it as is.
        self._srv_node = Node(f"_{self.get_name()}_save", namespace=self.get_namespace(),
                              context=self.context, use_global_arguments=False,
                              start_parameter_services=False, enable_rosout=False)
        self._srv_node.create_service(Trigger, self.resolve_service_name("~/save"), self._on_save)
        self._srv_executor: SingleThreadedExecutor | None = SingleThreadedExecutor(context=self.context)
        self._srv_executor.add_node(self._srv_node)
        self._srv_thread = threading.Thread(target=self._spin_save_service, name="estimator-save",
                                            daemon=True)
        self._srv_thread.start()
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(Trigger, "~/payload/tare", self._on_payload_tare)
        self.add_on_set_parameters_callback(make_parameter_validator(lambda: self.config))
        self.add_post_set_parameters_callback(self._on_parameters_set)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._diag_period = float(cfg["diagnostics.period"])
        self._last_diag = -math.inf
        self.create_timer(self._diag_period, self._on_diagnostics_timer, clock=steady)
        # The feed-forward is served from a copy of the model refreshed at a low rate (a model that changes
        # at every sample makes the torque it commands jitter: docs/feedforward.md).
        if self._feedforward is not None and cfg["parametric.consistent"]:
            # the consistent projection for the feed-forward, in a worker process (cvxpy holds the GIL)
            self._projection = ProjectionWorker(cfg.to_flat(), self._estimator.regressor.urdf_xml)
            n_links = self._estimator.regressor.n_bodies
            latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=n_links,
                                 reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self._pub_links = publisher(InertiaStamped, "~/link_inertias", latched)
            self.create_service(Trigger, "~/export_urdf", self._on_export_urdf)
            self._links_published = 0
            self._submit_projection()
            self.create_timer(float(cfg["parametric.consistent_period"]), self._submit_projection,
                              clock=steady)
        self._ff_version = -1
        if self._feedforward is not None and cfg["feedforward.refresh_period"] > 0:
            self._refresh_feedforward()
            self.create_timer(float(cfg["feedforward.refresh_period"]), self._refresh_feedforward,
                              clock=steady)

        # Catch-up of a backlog (more than a batch queued): a timer armed only while input is waiting
        # (timers work with every executor, guard conditions not with the EventsExecutor).
        self._catch_up = self.create_timer(_CATCH_UP_PERIOD_S, self._process_queued, clock=steady)
        self._catch_up.cancel()
        # Idle work (overload.max_delay > 0): the rotations of the last learned sample run in a turn of
        # their own once the input waiting in the executor was served, not inside the next prediction.
        self._idle = self.create_timer(_CATCH_UP_PERIOD_S, self._on_idle, clock=steady)
        self._idle.cancel()
        self._ckpt_thread = threading.Thread(target=self._checkpoint_loop, name="estimator-checkpoint",
                                             daemon=True)
        self._ckpt_thread.start()
        self._publish_parameters(force=True)
        est = self._estimator
        inputs = [self.resolve_topic_name(cfg[k]) for k in ("topics.joint_states", "topics.wrench")]
        self.get_logger().info(
            f"estimating {self._output} of joints {list(self._joints)}: {est.regressor.n_base} base "
            f"parameters, D = {cfg['nonparametric.n_features']} random features; learning "
            f"{'enabled' if est.learning_enabled else 'disabled'}; inputs {', '.join(inputs)}")

    def _warm_start(self, load_on_start: bool) -> None:
        """Remove stale temporaries of the checkpoint, then load it or say why the start is cold.

        Raises:
            StartupError: The checkpoint exists but cannot be loaded (corrupt, another structure or robot,
                absurd values); the message says how to proceed.
        """
        path = self._ckpt_path
        if path is None:
            self.get_logger().info("cold start: checkpoint.path is empty (no checkpoints)")
            return
        for stale in remove_stale_temporaries(path):
            self.get_logger().warning(f"removed {stale}, left by an interrupted checkpoint write")
        if not load_on_start:
            self.get_logger().info("cold start: checkpoint.load_on_start is false")
            return
        if not path.exists():
            self.get_logger().info(f"cold start: no checkpoint at {path} yet (it will be written there)")
            return
        try:
            self._estimator.load(path)
        except CheckpointError as err:
            raise StartupError(
                f"cannot warm start from checkpoint {path}: {err}\n"
                "Delete or move it, point checkpoint.path elsewhere, or set "
                "checkpoint.load_on_start:=false to overwrite it.") from err
        self.get_logger().info(
            f"warm start from {path} ({self._estimator.n_samples_learned} samples learned)")

    def _wait_for_description(self, topic: str, timeout_s: float) -> str:
        """Wait for the URDF text on ``topic`` (robot_state_publisher's transient-local ``std_msgs/String``).

        Logs where it waits, every 5 s until it arrives, and publishes a WARN diagnostic meanwhile.

        Raises:
            StartupError: Nothing arrived within ``timeout_s`` (> 0), or the context shut down.
        """
        received: list[str] = []
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
        def take(msg: String) -> None:
            received.append(msg.data)

        sub = self.create_subscription(String, topic, take, qos)
        diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        name = self.resolve_topic_name(topic)
        executor = SingleThreadedExecutor(context=self.context)
        executor.add_node(self)
        start = time.monotonic()
        next_note = start
        try:
            while not received:
                now = time.monotonic()
                if timeout_s > 0 and now - start > timeout_s:
                    raise StartupError(f"no robot description on {name} within robot.description_timeout = "
                                       f"{timeout_s:g} s (is robot_state_publisher running?)")
                if now >= next_note:
                    next_note = now + 5.0
                    self.get_logger().info(f"waiting for the robot description on {name} (std_msgs/String, "
                                           "transient local, as robot_state_publisher publishes it)")
                    diag.publish(diagnostic_array(self.get_clock().now().to_msg(),
                                                  f"{self.get_name()}: online learning", "",
                                                  {"waiting_for_robot_description": name}, waiting=True))
                executor.spin_once(timeout_sec=0.1)
                if not rclpy.ok(context=self.context):
                    raise StartupError(f"shut down while waiting for the robot description on {name}")
        finally:
            executor.remove_node(self)
            executor.shutdown(timeout_sec=1.0)
            self.destroy_subscription(sub)
            self.destroy_publisher(diag)
        self.get_logger().info(f"robot description received on {name} ({len(received[-1])} characters)")
        return received[-1]

    def _warm_up_kernels(self) -> int:
        """Run every compiled kernel of a step once before input arrives, on a throw-away estimator.

        The same configuration with 4 random features, fed synthetic samples (a slow ramp of every joint,
        zero wrench, 1 ms apart) until three of them went through the whole step: the acceleration
        estimator's warm-up (a Savitzky–Golay window, the Kalman filter's settling time) decides how many
        that takes, at most :data:`_WARM_UP_MAX_SAMPLES`. Compilation depends only on the array types,
        so this loads the machine code the real model runs (without it the first real sample took
        ≈ 20–40 ms instead of ≈ 0.3 ms) without copying a model that can hold hundreds of MB.

        Returns:
            The number of synthetic samples that went through the step (≥ 3 unless the cap was reached).
        """
        cfg = self.config
        # the real estimator's regressor (stateless between calls): the URDF is not parsed a second time
        scratch = OnlineEstimator(cfg.with_overrides({"nonparametric.n_features": 4,
                                                      "nonparametric.standardizer_warmup": 2}),
                                  regressor=self._estimator.regressor)
        joints, n = self._joints, len(self._joints)
        frame = self._frame_id or "warm_up"
        stepped = 0
        for k in range(_WARM_UP_MAX_SAMPLES):
            stamp = 1_000_000_000 + k * 1_000_000
            stepped += len(scratch.process_joint_state(
                JointStateData(stamp, joints, np.full(n, 1e-3 * k), np.full(n, 1.0), np.zeros(n))))
            if self._output == "wrench":
                stepped += len(scratch.process_wrench(WrenchData(stamp, frame, np.zeros(3), np.zeros(3))))
            if stepped >= 3:
                break
        return stepped

    # ================================================================== executor side
    def _enqueue(self, kind: str, item: JointStateData | WrenchData) -> None:
        dropped = len(self._queue) >= self._queue_size
        if dropped:
            self._queue.popleft()
        self._queue.append((kind, item, time.perf_counter()))
        if dropped:
            self._stats.count_drop("queue_full")
            self._warn_throttled("queue_full",
                                 "input queue full: dropping the oldest message (learning cannot keep up)")

    @_quiet_at_shutdown
    def _on_joint_state(self, msg: bytes) -> None:
        if not self._active:  # an inactive lifecycle node: inputs are not taken
            return
        self._intake("joint_states", msg)
        self._drain("joint_states")
        self._process_queued()

    @_quiet_at_shutdown
    def _on_wrench(self, msg: bytes) -> None:
        if not self._active:
            return
        self._intake("wrench", msg)
        self._drain("wrench")
        self._process_queued()

    def _intake(self, kind: str, msg: bytes | Any) -> None:
        """Convert one input (serialised, as the subscriptions deliver it, or a message object); queue it."""
        self._stats.count_input(kind)
        try:
            if isinstance(msg, bytes):
                data = (joint_state_from_cdr(msg, self._max_names) if kind == "joint_states"
                        else wrench_from_cdr(msg))
            else:
                data = joint_state_from_msg(msg) if kind == "joint_states" else wrench_from_msg(msg)
        except RejectedSampleError as err:  # a message the conversion refuses: a counted drop
            self._conversion_failed(kind, err)
            return
        self._enqueue(kind, data)

    def _drain(self, kind: str) -> None:
        """Take the messages already waiting on both subscriptions without another executor wait.

        The executor takes one message per subscription per wait, and building its wait set costs far
        more than taking a message; when input is queued in DDS (a burst, or the learner held the GIL)
        this catches up at the cost of a take each. The two subscriptions are taken alternately (the
        other one first: the callback just took one of ``kind``), at most ``_MAX_DRAIN`` rounds, so
        neither stream runs ahead of the other by more than one message (a joint-state stream far
        ahead would outrun the pipeline's pairing buffer and leave wrenches unpaired).

        Not public rclpy API: rclpy (Jazzy) has no public "take" on a subscription, so this makes the
        call the executor itself makes (``sub.handle.take_message(sub.msg_type, sub.raw)``). Kept because
        it is measured ≈ 8× cheaper per queued message than one executor wait each (bench/bench_drain.py,
        results in bench/results/bench_drain.json); test/test_node_drain.py fails if the call changes.
        """
        order = self._drain_order[kind]
        for _ in range(_MAX_DRAIN):
            took = False
            for sub_kind, sub in order:
                taken = _take(sub)
                if taken is _GONE:
                    return
                if taken is not None:
                    took = True
                    self._intake(sub_kind, taken)
            if not took:
                return

    def _incompatible_qos_logger(self, topic: str) -> Callable[[Any], None]:
        def warn(event: Any) -> None:
            self.get_logger().warning(
                f"a publisher on {self.resolve_topic_name(topic)} offers an incompatible QoS "
                f"({event.last_policy_kind}); its messages will not be received")

        return warn

    def _message_lost_counter(self, topic: str) -> Callable[[Any], None]:
        last = [0]  # the middleware's running total at the last event

        def count(event: Any) -> None:
            # the running total, taken as a delta and checked: one oversized message made Fast DDS report
            # a change of 2**31 (a wrapped 32-bit counter); a loss can never exceed the messages sent
            total = int(event.total_count)
            delta = total - last[0]
            last[0] = max(last[0], total)
            if not 0 <= delta <= _MAX_LOST_PER_EVENT:
                self._warn_throttled(f"lost count {topic}", lambda: (
                    f"the middleware reported an implausible lost-message count on "
                    f"{self.resolve_topic_name(topic)} (total {total}, change {delta}): counted as 1"))
                delta = 1
            self._stats.count_drop("dds_message_lost", delta)
            self._warn_throttled(f"lost {topic}", lambda: (
                f"{delta} messages on {self.resolve_topic_name(topic)} were lost in the middleware "
                "(history overflow: the node is not taking them fast enough)"))

        return count

    def _warn_throttled(self, key: str, text: str | Callable[[], str], *, once: bool = False) -> None:
        """Log a warning at most every ``_LOG_THROTTLE_S`` per ``key`` (``once``: only the first time).

        The text is built only when logged. rclpy's own ``throttle_duration_sec`` inspects the caller's
        frame and source file on every call, logged or not (≈ 0.35 ms): at 1 kHz of bad input that alone
        would stall the node.
        """
        now = time.monotonic()
        last = self._last_warning.get(key, -math.inf)
        if now - last < _LOG_THROTTLE_S or (once and last > -math.inf):
            return
        self._last_warning[key] = now
        self.get_logger().warning(text() if callable(text) else text)

    def _conversion_failed(self, topic: str, err: Exception) -> None:
        self._stats.count_drop("conversion_error")
        self._warn_throttled(f"convert {topic}", lambda: f"cannot convert a {topic} message: {err}")

    def _spin_save_service(self) -> None:
        executor = self._srv_executor
        if executor is None:
            return
        try:
            executor.spin()
        except ExternalShutdownException:
            pass

    def _stop_save_service(self) -> None:
        executor = getattr(self, "_srv_executor", None)
        if executor is None:
            return
        self._srv_executor = None
        executor.shutdown(timeout_sec=1.0)
        self._srv_thread.join(timeout=2 * _SAVE_TIMEOUT_S)
        self._srv_node.destroy_node()

    def destroy_node(self) -> None:
        """Stop the ``~/save`` service thread and its helper node, then destroy the node."""
        self._stop_save_service()
        super().destroy_node()

    def _on_save(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Hand the request to the checkpoint thread and wait (at most ``_SAVE_TIMEOUT_S``) for the file.

        Runs in the save-service thread (see ``_setup``): learning goes on meanwhile, except while the
        checkpoint thread copies the state under the model lock.
        """
        if self._ckpt_path is None:
            response.success, response.message = False, "checkpoint.path is empty: checkpoints are disabled"
            return response
        future: concurrent.futures.Future[tuple[bool, str]] = concurrent.futures.Future()
        with self._ckpt_lock:
            self._ckpt_requests.append(future)
        self._ckpt_event.set()
        try:
            ok, message = future.result(timeout=_SAVE_TIMEOUT_S)
        except concurrent.futures.TimeoutError:
            ok, message = False, (f"checkpoint to {self._ckpt_path} not written within {_SAVE_TIMEOUT_S:g} s "
                                  "(the disk is slow or blocked); the write goes on in the background")
        response.success, response.message = ok, message
        return response

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self._model_lock:
            self._estimator.reset()  # also zeroes the pipeline's drop counts
            self._version += 1
            # the baseline of _process's drop delta: without this the next message sees the counts fall
            # and subtracts the pre-reset drops from the period's (WARN level), logging a bogus drop
            self._last_drop_total = 0
        self._stats.clear_errors()
        self._refresh_feedforward()  # the reset model is served at once
        self._publish_parameters(force=True)
        if self._ckpt_path is not None:
            with self._ckpt_lock:
                self._ckpt_reset_pending = True
            self._ckpt_event.set()  # persist the reset, so a warm start does not bring the old model back
        self.get_logger().info("model reset: everything learned was forgotten")
        response.success, response.message = True, "model reset"
        return response

    def _on_payload_tare(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Take the model as it is as the payload's reference; the next pickup is the payload."""
        with self._model_lock:
            self._estimator.tare_payload()
            self._payload_key = None
        self.get_logger().info("payload tared: a pickup from now on is published on ~/payload")
        response.success, response.message = True, "payload tared"
        return response

    def _publish_payload(self) -> None:
        """Publish the payload when learning or the consistent projection changed it (diagnostics timer).

        Since a tare: the payload learner's estimate (once a pickup was detected). Without one: beyond the
        URDF, from the worker's latest consistent solution (never solved here: cvxpy holds the GIL).
        """
        worker = self._projection
        solved = worker.solved if worker is not None else 0
        key = (self._version, solved)
        if key == self._payload_key:
            return
        with self._model_lock:
            learner = self._estimator.payload
            if learner is not None:
                estimate = learner.estimate() if learner.detected else None
            elif worker is not None and worker.latest is not None:
                estimate = self._serving.payload(worker.latest)
            else:
                estimate = None
        self._payload_key = key
        if estimate is not None:
            value, std = payload_msgs(estimate, self.get_clock().now().nanoseconds)
            self._pub_payload.publish(value)
            self._pub_payload_std.publish(std)

    def _on_parameters_set(self, params: list[Parameter]) -> None:
        changes = {p.name: p.value for p in params}
        known = {k: v for k, v in changes.items() if k in self.config.values}
        if not known:
            return
        self.config = self.config.with_overrides(known)
        if "learning_enabled" in known:
            with self._model_lock:
                self._estimator.learning_enabled = bool(known["learning_enabled"])
            self.get_logger().info(f"learning {'enabled' if known['learning_enabled'] else 'disabled'}")
        if any(name.startswith(("gate.", "uncertainty.")) for name in known):
            with self._model_lock:
                self._estimator.apply_runtime_parameters(self.config)
        if "checkpoint.period" in known:
            self._ckpt_period = float(known["checkpoint.period"])
            self._ckpt_event.set()
        if "overload.max_delay" in known:
            self._max_delay_s = float(known["overload.max_delay"])

    @_quiet_at_shutdown
    def _on_diagnostics_timer(self) -> None:
        # a timer that fell behind (the executor was busy or descheduled) fires again at once: that call
        # would close a period of a few µs with no samples (NaN latencies, a spurious "no input" WARN), so
        # a period shorter than half the configured one goes on into the next
        now = time.monotonic()
        if now - self._last_diag < 0.5 * self._diag_period:
            return
        self._last_diag = now
        stats = self._stats.snapshot()
        with self._model_lock:
            est = self._estimator
            drops = est.drops
            stats["samples_learned"] = est.n_samples_learned
            stats["learning_skipped"] = est.n_learning_skipped
            stats["learning_enabled"] = est.learning_enabled
            stats["model_size"] = est.model_size
            for reason, count in est.not_learned.items():
                stats[f"not_learned.{reason}"] = count
            stats["gate_enabled"] = est.gate_enabled
            stats["gate_in_excursion"] = est.gate.in_excursion
            stats["gate_novel_samples"] = est.gate.counts[Verdict.NOVEL]
            stats["forgetting"] = est.forgetting if est.forgetting is not None else -1.0
        stats.update(self._excitation_stats())
        stats["queue_length"] = len(self._queue)
        stats["queue_size"] = self._queue_size
        stats["acceleration_delay_ms"] = 1e3 * float(getattr(est.pipeline, "acceleration_delay_s", 0.0))
        for reason, count in drops.items():
            key = f"drops.{reason}"
            stats[key] = int(stats.get(key, 0)) + count  # type: ignore[call-overload]
        stats["drops_total"] = int(stats["queue_drops"]) + sum(  # type: ignore[call-overload]
            v for k, v in stats.items() if k.startswith("drops.") and isinstance(v, int))
        stats["checkpoint_path"] = str(self._ckpt_path or "")
        ff = self._feedforward
        if ff is not None:
            for key, count in ff.counts.items():
                stats[f"feedforward.{key}"] = count
            stats["feedforward.ready"] = self._serving.ready
            worker = self._projection
            if worker is not None:  # the consistent projection (parametric.consistent)
                stats["consistent.solutions"] = worker.solved
                stats["consistent.in_use"] = worker.latest is not None
                if worker.latest is not None:
                    stats["consistent.solve_ms"] = 1e3 * worker.latest.solve_s
                stats["consistent.error"] = worker.error or ""
            stats["feedforward.last_error"] = ff.last_error or ""
            latency, self._ff_latency_ms = self._ff_latency_ms, []
            if latency:  # stamped by the controller → published here, over the period
                p50, p99 = np.percentile(latency, (50, 99))
                stats["feedforward.age_p50_ms"] = float(p50)
                stats["feedforward.age_p99_ms"] = float(p99)
                stats["feedforward.age_max_ms"] = float(max(latency))
                stats["feedforward.answered_in_period"] = len(latency)
        msg = diagnostic_array(self.get_clock().now().to_msg(), f"{self.get_name()}: online learning",
                               ",".join(self._joints), stats,
                               stalled=bool(stats["queue_length"]) and not stats["processed_in_period"])
        self._pub_diag.publish(msg)
        self._publish_parameters(force=False)
        self._publish_payload()

    def _excitation_stats(self) -> dict[str, object]:
        """Return what the data determine (:func:`excitation_report`), recomputed at most every 10 s."""
        now = time.monotonic()
        last = self._excitation
        if last is None or (now - last[0] >= 10.0 and last[1] != self._version):
            with self._model_lock:  # an SVD of the p × p factor: well under a ms for a 7-joint arm
                report, version = self._serving.excitation(), self._version
            value, names = report.least_excited[0]
            last = (now, version, {
                "excitation.condition": report.condition,
                "excitation.weakest_eigenvalue": value,
                "excitation.weakest_direction": ", ".join(f"{n} ({w:+.2f})" for n, w in names)})
            self._excitation = last
        return last[2]

    def _publish_parameters(self, *, force: bool) -> None:
        with self._model_lock:
            version = self._version
            if not force and version == self._published_version:
                return
            params = self._estimator.parameters
            names = self._estimator.parameter_names
        if params is None:
            return
        self._pub_params.publish(parameters_msg(names, params))
        self._published_version = version

    # ================================================================== learning (executor thread)
    @_quiet_at_shutdown
    def _process_queued(self) -> None:
        """Run the estimator on queued input: at most a batch, so inputs, services and timers get turns.

        Called right after each input is queued (no executor round trip between receipt and prediction)
        and, while a backlog remains, by the catch-up timer.
        """
        queue = self._queue
        if queue:
            cpu = time.thread_time()  # a system call (≈ 1 µs): once per batch, not per message
            n = min(len(queue), _BATCH)
            for _ in range(n):
                if self._desired_sub is not None:
                    self._serve_waiting_desired_state()  # a controller waits: it goes before learning
                kind, data, t_recv = queue.popleft()
                self._process(kind, data, t_recv, skip_learning=self._late(t_recv))
            self._stats.add_learning_cpu(time.thread_time() - cpu, n)
        if queue:
            if self._catch_up.is_canceled():
                self._catch_up.reset()
        else:
            if not self._catch_up.is_canceled():
                self._catch_up.cancel()
            if self._max_delay_s > 0.0 and self._idle.is_canceled():
                self._idle.reset()

    @_quiet_at_shutdown
    def _on_idle(self) -> None:
        """Apply the learners' deferred update while no input waits (one executor turn after learning)."""
        self._idle.cancel()
        if not self._queue:
            cpu = time.thread_time()
            with self._model_lock:
                self._estimator.apply_pending()
            self._stats.add_learning_cpu(time.thread_time() - cpu, 0)

    def _late(self, t_recv: float) -> bool:
        """Whether the sample received at ``t_recv`` is predicted at once and not learned (overload).

        Late: it waited longer than ``overload.max_delay``, or the learner still holds the deferred update
        of the previous sample (no idle turn applied it: input comes faster than the learner works) and
        a step that applies it as well (its cost measured over the recent such steps) would end beyond
        the budget. So the longest piece of work a prediction waits for is one triangular solve or one
        update, never both, and the learner takes the samples it has time for, spread in time.
        """
        budget = self._max_delay_s
        if budget <= 0.0:
            return False
        age = time.perf_counter() - t_recv
        return age > budget or (self._estimator.has_pending and age + self._fused_cost_s > budget)

    def _process(self, kind: str, data: JointStateData | WrenchData, t_recv: float, *,
                 publish: bool = True, skip_learning: bool = False) -> None:
        est = self._estimator
        try:
            with self._model_lock:
                fused = not skip_learning and est.has_pending  # this step applies the previous update too
                if isinstance(data, WrenchData):
                    results = est.process_wrench(data, skip_learning=skip_learning)
                    if not self._frame_id:
                        self._last_wrench_frame = data.frame_id
                else:
                    results = est.process_joint_state(data, skip_learning=skip_learning)
                for r in results:
                    if r.learned:
                        self._version += 1
                        break
                drop_total = est.n_dropped  # refused samples too: they must raise the level to WARN
        except Exception as err:
            # Bad input never gets here (the pipeline drops it, the estimator counts what the learner
            # rejects): this is a bug. Say so loudly and let it propagate out of spin (see main()).
            self.get_logger().fatal(f"programming error in the estimator on a {kind} message: {err!r}")
            raise
        if fused:
            for r in results:  # the cost of a step that applies the previous update too (EW mean, ~20)
                if r.learned:
                    self._fused_cost_s += 0.05 * (r.latency_s - self._fused_cost_s)
        if drop_total != self._last_drop_total:
            self._stats.count_pipeline_drops(drop_total - self._last_drop_total)
            self._last_drop_total = drop_total
            self._warn_throttled("pipeline drops", lambda: f"dropped input messages: {est.drops}")
        if not self._rmse_window_final and est.sample_period_s is not None:
            self._stats.set_rmse_window(rmse_window_samples(est.config, est.sample_period_s))
            self._rmse_window_final = True
        if not publish:
            return
        for result in results:
            self._publish_result(result)  # a failure here is a bug too (non-finite values publish fine)
            pred = result.prediction
            self._stats.add_sample(result.latency_s, time.perf_counter() - t_recv, result.sample.y,
                                   pred.total, pred.parametric)

    def _publish_result(self, result: StepResult) -> None:
        """Publish one sample's outputs, each only if someone subscribes to it (nobody else can tell)."""
        stamp = result.sample.stamp_ns
        pred = result.prediction
        if self._output == "wrench" and self._out_frame != self._last_wrench_frame:
            frame = self._last_wrench_frame
            self._out_template = SerializedOutput(
                lambda stamp_ns, w: wrench_stamped_msg(stamp_ns, frame, w), 6)
            self._out_frame = frame
        fill = self._out_template.fill  # type: ignore[union-attr]
        pub = self._pub_total
        if pub.get_subscription_count():
            pub.publish(fill(stamp, pred.total))
        pub = self._pub_external
        if pub.get_subscription_count():
            pub.publish(fill(stamp, result.sample.y - pred.total))
        pub = self._pub_model
        if pub.get_subscription_count():  # the model alone: the prediction without the fast correction
            pub.publish(fill(stamp, pred.total if pred.correction is None else pred.total - pred.correction))
        if self._output == "joint_torques":
            self._publish_joint_extras(result)
        for pub, value in ((self._pub_param, pred.parametric), (self._pub_resid, pred.residual),
                           (self._pub_std, result.std)):
            if value is not None and pub is not None and pub.get_subscription_count():
                pub.publish(fill(stamp, value))

    def _publish_joint_extras(self, result: StepResult) -> None:
        """Joint-torque mode: the deprecated un-namespaced prediction and the gravity torques at q."""
        fill = self._out_template.fill  # type: ignore[union-attr]
        stamp = result.sample.stamp_ns
        if self._pub_legacy.get_subscription_count():
            self._warn_throttled("legacy topic", "a subscriber reads predicted_joint_torques outside the "
                                 "node's namespace: deprecated, use ~/predicted_joint_torques", once=True)
            self._pub_legacy.publish(fill(stamp, result.prediction.total))
        if self._pub_gravity.get_subscription_count():  # the node runs SP: it always has a rigid body
            with self._model_lock:
                gravity = self._serving.gravity(result.sample.q)
            self._pub_gravity.publish(fill(stamp, gravity))

    # ================================================================== feed-forward (executor thread)
    @_quiet_at_shutdown
    def _submit_projection(self) -> None:
        """Send the rigid-body learner's state to the projection worker, if learning changed it."""
        worker = self._projection
        if worker is None:
            return
        if self.config["feedforward.refresh_period"] <= 0 and worker.latest is not None:
            self._serving.attach_consistent(worker.latest)  # the live model is served: attach it there
        if self._projection_version == self._version:
            return
        with self._model_lock:
            par = self._estimator.model.parametric  # type: ignore[union-attr]  # SP: always a rigid part
            theta, R, lam = par.parameters.copy(), par.rls.R.copy(), par.rls.lam
            version = self._version
        if worker.submit(theta, R, self._estimator.column_scale, lam):
            self._projection_version = version

    @_quiet_at_shutdown
    def _refresh_feedforward(self) -> None:
        """Serve a fresh copy of the model to the feed-forward, if learning or the projection changed."""
        ff = self._feedforward
        worker = self._projection
        solved = worker.solved if worker is not None else 0
        if ff is None or (self._ff_version == self._version and self._ff_solved == solved):
            return
        with self._model_lock:
            served = self._serving.snapshot()
            if worker is not None:
                served.attach_consistent(worker.latest)
            ff.model = served
            self._ff_version = self._version
            self._ff_solved = solved
        if worker is not None and worker.latest is not None and self._links_published != solved:
            for msg in link_inertia_msgs(worker.latest, self.get_clock().now().nanoseconds):
                self._pub_links.publish(msg)
            self._links_published = solved

    def _on_export_urdf(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Write the URDF with the newest consistent parameters next to the checkpoint (identification)."""
        worker = self._projection
        estimate = None if worker is None else worker.latest
        if estimate is None or self._ckpt_path is None:
            response.success = False
            response.message = ("no consistent estimate yet (the worker solves every "
                                "parametric.consistent_period)" if estimate is None
                                else "checkpoint.path is empty: the URDF is written next to the checkpoint")
            return response
        path = self._ckpt_path.with_name(self._ckpt_path.stem + "_identified.urdf")
        try:
            atomic_write_text(path, export_urdf(self._estimator.regressor, estimate))
        except OSError as err:
            response.success, response.message = False, f"cannot write {path}: {err}"
            return response
        response.success, response.message = True, f"wrote {path}"
        return response

    def _serve_waiting_desired_state(self) -> None:
        """Answer a desired state already waiting in DDS before the next queued sample is learned.

        The same take the executor makes (see :meth:`_drain`): the wait of a controller is bounded by
        one sample's learning instead of a batch of them.
        """
        taken = _take(self._desired_sub)
        if taken is not None and taken is not _GONE:
            self._on_desired_state(taken)

    @_quiet_at_shutdown
    def _on_desired_state(self, msg: JointTrajectory) -> None:
        """Answer a desired state at once with the model's torques (see core.feedforward).

        Its age when answered (node clock at publish − header stamp, for stamped messages: a controller
        stamps what it sends with its time) is reported in diagnostics (``feedforward.age_*``).
        """
        ff = self._feedforward
        assert ff is not None  # subscribed in joint-torque mode only
        if not self._active:
            return
        try:
            desired = desired_state_from_msg(msg)
        except RejectedSampleError as err:
            ff.counts["drops.non_finite"] += 1
            ff.last_error = text = str(err)
            self._warn_throttled("desired state", lambda: f"desired state dropped: {text}")
            return
        now_ns = self.get_clock().now().nanoseconds
        with self._model_lock:
            command = ff.compute(desired, now_ns)
        if command is None:
            self._warn_throttled("desired state", lambda: f"desired state dropped: {ff.last_error}")
            return
        commands, state, std = feedforward_msgs(command, ff.joints)
        for pub, out in ((self._pub_ff_commands, commands), (self._pub_ff, state), (self._pub_ff_std, std)):
            if pub.get_subscription_count():  # each only where someone listens (nobody else can tell)
                pub.publish(out)
        if desired.stamp_ns > 0 and len(self._ff_latency_ms) < 100_000:
            self._ff_latency_ms.append(1e-6 * (self.get_clock().now().nanoseconds - desired.stamp_ns))
        if command.reason is not None:
            self._warn_throttled(f"feedforward {command.reason}", lambda: (
                "feed-forward falls back to the rigid-body part: " + (
                    "the model is not ready (residual warm-up)" if command.reason == "not_ready"
                    else f"its std exceeds feedforward.max_std = {ff.max_std:g} N·m")))

    # ================================================================== checkpoint thread
    def _checkpoint_loop(self) -> None:
        last_periodic = time.monotonic()
        while True:
            period = self._ckpt_period
            timeout = max(last_periodic + period - time.monotonic(), 0.0) if period > 0 else 1.0
            self._ckpt_event.wait(timeout)
            self._ckpt_event.clear()
            stopping = self._stopping.is_set()
            with self._ckpt_lock:
                requests, self._ckpt_requests = self._ckpt_requests, []
                reset_pending, self._ckpt_reset_pending = self._ckpt_reset_pending, False
            now = time.monotonic()
            periodic = period > 0 and now - last_periodic >= period
            if periodic or period <= 0:
                last_periodic = now
            if self._ckpt_path is None:
                result = (False, "checkpoint.path is empty: checkpoints are disabled")
            elif requests or ((stopping or periodic or reset_pending) and self._version_changed()):
                result = self._write_checkpoint()
            else:
                result = (True, f"checkpoint {self._ckpt_path} is up to date")
            for future in requests:
                future.set_result(result)
            if stopping:
                self.final_checkpoint_ok = result[0] or self._ckpt_path is None
                return

    def _version_changed(self) -> bool:
        return self._version != self._saved_version

    def _write_checkpoint(self) -> tuple[bool, str]:
        assert self._ckpt_path is not None
        try:
            with self._model_lock:  # copy under the lock, write outside it: the learner never waits for disk
                state = self._estimator.checkpoint_state()
                version = self._version
                n_learned = self._estimator.n_samples_learned
            atomic_save_npz(self._ckpt_path, state)
        except Exception as err:  # any failure: this thread must live on and answer every ~/save request
            self._stats.mark_checkpoint(False)
            self.get_logger().error(f"checkpoint to {self._ckpt_path} failed: {err}",
                                    throttle_duration_sec=_LOG_THROTTLE_S)
            return False, f"checkpoint failed: {err}"
        self._saved_version = version
        self._stats.mark_checkpoint(True)
        return True, f"saved {n_learned} learned samples to {self._ckpt_path}"

    # ================================================================== shutdown
    def _stop_threads(self, *, save: bool) -> None:
        stopping = getattr(self, "_stopping", None)
        if stopping is None:
            return
        stopping.set()
        worker = getattr(self, "_projection", None)
        if worker is not None:
            worker.close()
            self._projection = None
        thread = getattr(self, "_ckpt_thread", None)
        if thread is not None:
            if not save:
                self._ckpt_path = None
            self._ckpt_event.set()
            thread.join(timeout=30.0)

    def _learn_remaining(self, budget_s: float = _SHUTDOWN_BUDGET_S) -> int:
        """Learn the messages still queued, without publishing (the executor no longer runs).

        Returns:
            The number of queued messages processed (the rest, past the time budget, is dropped).
        """
        queue = getattr(self, "_queue", None)
        if not queue:
            return 0
        deadline = time.monotonic() + budget_s
        n = 0
        while queue and time.monotonic() < deadline:
            kind, data, t_recv = queue.popleft()
            self._process(kind, data, t_recv, publish=False)
            n += 1
        return n

    def abort(self) -> None:
        """Stop the checkpoint thread without learning the queue or writing a final checkpoint.

        For a node whose executor stopped on a programming error: the state it would save is suspect, and
        the last periodic checkpoint stays as it was.
        """
        self._stop_threads(save=False)

    def shutdown(self) -> None:
        """Learn what is still queued, then write the final checkpoint (if configured) and stop the threads.

        Call before ``destroy_node`` (``main`` does), from the thread that ran the executor, once it has
        stopped spinning.
        """
        try:
            n = self._learn_remaining()
            if n:
                self.get_logger().info(f"learned {n} queued messages before the final checkpoint")
        except Exception as err:  # shutting down must always reach the checkpoint
            self.get_logger().error(f"could not learn the queued messages at shutdown: {err!r}")
        self._stop_threads(save=True)

    # Expose a few read-only views for tests and tools running the node in-process.
    @property
    def estimator(self) -> OnlineEstimator:
        """The estimator (driven by the executor thread: hold no reference across samples)."""
        return self._estimator

    def wait_idle(self, timeout: float = 5.0, poll: Callable[[], None] | None = None) -> bool:
        """Wait until the input queue is empty (for in-process tests); returns whether it emptied."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if not self._queue:
                return True
            if poll is not None:
                poll()
            time.sleep(0.005)
        return False


#: Executors ``main`` can spin the node with (``--executor NAME``); the first is the default.
EXECUTORS: dict[str, Callable[..., Executor]] = {
    "events": EventsExecutor,
    "single_threaded": SingleThreadedExecutor,
}


def spin(executor: Executor, stop: threading.Event | None = None) -> None:
    """Spin until ``stop`` is set or the context shuts down.

    rclpy 7.1.6's ``EventsExecutor.spin()`` (and ``spin_once()`` without a timeout) runs no timer
    callback at all; ``spin_once`` with a timeout does, so both executors are driven by that loop, which
    also sees ``stop`` (set by the signal handlers of :func:`main`) within ``_SPIN_TIMEOUT_S``.
    """
    while rclpy.ok(context=executor.context) and not (stop is not None and stop.is_set()):
        executor.spin_once(timeout_sec=_SPIN_TIMEOUT_S)


#: What :func:`_take` returns for a subscription being destroyed.
_GONE: Any = object()


def _take(sub: Any) -> Any:
    """Take one waiting message of a subscription the way the executor does, or None when none waits.

    Returns :data:`_GONE` when the subscription is being destroyed (the executor will notice). Not
    public rclpy API (see :meth:`EstimatorNode._drain`).
    """
    try:
        with sub.handle:
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
    except Exception:
        return _GONE
    return None if taken is None else taken[0]


def _first_line(err: BaseException) -> str:
    """Return the message of an rcl error without its C source locations (``…, at /project/src/…``)."""
    return str(err).split(", at /")[0].strip()


def _stop_on_signals(stop: threading.Event) -> None:
    """SIGINT and SIGTERM only set ``stop``: whatever callback runs finishes, then ``main`` shuts down.

    rclpy's own handlers would invalidate the context under a running callback (its publish fails) and
    Python's SIGINT raises KeyboardInterrupt wherever the main thread is; either reached the executor as
    an exception in a callback (logged FATAL) and could cost the final checkpoint.
    """
    def handler(signum: int, frame: Any) -> None:
        stop.set()

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, handler)


def parse_node_args(args: list[str]) -> argparse.Namespace:
    """Parse the node's own options (those outside ``--ros-args``).

    Args:
        args: The command line without the program name and without ROS arguments.

    Returns:
        The options: ``executor`` (a key of :data:`EXECUTORS`), ``print_defaults``.

    Raises:
        SystemExit: Unknown option or executor name (argparse prints the usage).
    """
    parser = argparse.ArgumentParser(prog="estimator", description="semiparam_ros estimator node")
    parser.add_argument("--executor", choices=tuple(EXECUTORS), default=next(iter(EXECUTORS)),
                        help="rclpy executor spinning the node (default: %(default)s; measured in "
                             "docs/performance.md)")
    parser.add_argument("--lifecycle", action="store_true",
                        help="run as a managed (lifecycle) node: configure, activate, deactivate, cleanup")
    parser.add_argument("--print-defaults", action="store_true",
                        help="print every parameter with its type, range, default and meaning, and exit")
    return parser.parse_args(args)


def main(args: list[str] | None = None) -> int:
    """Run the estimator node until shut down (Ctrl-C, SIGTERM or context shutdown).

    Args:
        args: Command-line arguments (``[--executor NAME] --ros-args ...``); ``sys.argv[1:]`` when None.

    Returns:
        Process exit code: 0 on a clean shutdown, 1 if its final checkpoint could not be written, 2 if the
        node could not start.

    Raises:
        Exception: A programming error inside a callback propagates out of ``spin`` (the ROS habit: the
            process dies with the traceback, and a launch file's ``respawn`` restarts it from the last
            periodic checkpoint); the node is destroyed without learning the queue or saving first.
    """
    argv = sys.argv[1:] if args is None else list(args)
    try:
        options = parse_node_args(rclpy.utilities.remove_ros_args(["estimator", *argv])[1:])
    except RuntimeError as err:  # rcl's RCLInvalidROSArgsError: a missing or unparseable parameter file
        print(f"[estimator] FATAL: invalid ROS arguments or parameter file: {_first_line(err)}",
              file=sys.stderr, flush=True)
        return 2
    if options.print_defaults:
        print(describe_parameters())
        return 0
    stop = threading.Event()
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    _stop_on_signals(stop)
    node: EstimatorNode | None = None
    code = 0
    crashed = False
    try:
        # One BLAS/OpenMP thread: the learner's small dense operations do not profit from more, and on a
        # small machine extra threads only compete with DDS and the checkpoint writer.
        with threadpool_limits(1):
            if options.lifecycle:
                from semiparam_ros.ros.lifecycle_node import LifecycleEstimatorNode

                node = LifecycleEstimatorNode()
            else:
                node = EstimatorNode()
            # Everything built so far (modules, compiled kernels, the model: ≈ 130 000 tracked objects)
            # lives as long as the process: out of the collector's reach, a full collection takes
            # ≈ 0.5 ms instead of ≈ 100 ms (a latency spike every few minutes at 1 kHz).
            gc.freeze()
            executor = EXECUTORS[options.executor]()
            executor.add_node(node)
            spin(executor, stop)
    except StartupError as err:
        print(f"[estimator] FATAL: {err}", file=sys.stderr, flush=True)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as err:
        if node is None or node.context.ok():
            crashed = True
            raise
        # the signal handler invalidated the context under the executor: a shutdown, not a crash
        print(f"[estimator] shutting down (interrupted: {err})", file=sys.stderr, flush=True)
    except BaseException:
        crashed = True
        raise
    finally:
        if node is not None:
            if crashed:
                node.abort()
            else:
                node.shutdown()
                if not node.final_checkpoint_ok:
                    print("[estimator] ERROR: the final checkpoint could not be written (see the log above)",
                          file=sys.stderr, flush=True)
                    code = 1
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
