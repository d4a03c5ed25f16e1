"""The ``estimator`` node: ROS entities wired to the plain-Python learning loop.

Run it with ``ros2 run semiparam_ros estimator --ros-args --params-file config/icub_right_arm.yaml`` (or
``python -m semiparam_ros.ros.main …``: the command line lives in :mod:`semiparam_ros.ros.main`). Its topics,
services, QoS and threads are documented in docs/node.md. The work is done by parts that never import
rclpy: :class:`~semiparam_ros.serving.learning_loop.LearningLoop` (input queue, overload policy, the
estimator offline replay uses too, so a bag gives the same numbers either way),
:class:`~semiparam_ros.serving.model_service.ModelService` (feed-forward, gravity, payload, link inertias)
and :class:`~semiparam_ros.serving.checkpoint_writer.CheckpointWriter` (the checkpoint thread). This module
converts messages, hands them on, and publishes what comes back.

The parts are assembled by :func:`~semiparam_ros.serving.assembly.assemble`. One executor thread runs
everything that touches the estimator. A subscription callback converts its message (taken serialised),
queues it, takes what else already waits on both subscriptions, and drains the loop at once
(:meth:`~semiparam_ros.serving.learning_loop.LearningLoop.drain`: predict, publish, then learn): at most
``_BATCH`` inputs per turn, a catch-up timer for a backlog, an idle timer for the deferred update. Bad
input is dropped and counted by reason in ``/diagnostics``; any other exception in a callback is a
programming error: logged FATAL, it propagates out of ``spin`` and ends the process.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger

from semiparam_ros.core.config import EstimatorConfig, runtime_targets
from semiparam_ros.core.estimator.build import rmse_window_samples
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.kinds import InputKind, OutputKind
from semiparam_ros.core.rigid_body.urdf import TOPIC_SCHEME
from semiparam_ros.errors import ConfigurationError, DescriptionTimeoutError, StartupError
from semiparam_ros.ros.callbacks import quiet_at_shutdown
from semiparam_ros.ros.description import wait_for_description
from semiparam_ros.ros.diagnostics import NodeStatistics, diagnostic_array, estimator_statistics
from semiparam_ros.ros.feedforward_endpoints import FeedForwardEndpoints, endpoint_names
from semiparam_ros.ros.inputs import INPUT_QOS, DropReporter, InputStreams, ThrottledWarnings
from semiparam_ros.ros.outputs import PARAMETERS_QOS, Outputs
from semiparam_ros.ros.parameter_files import parameter_files, unmatched_files_message
from semiparam_ros.ros.parameters import ParameterError, declare_parameters, make_parameter_validator
from semiparam_ros.ros.save_service import SaveService
from semiparam_ros.serving.assembly import assemble, checkpoint_path
from semiparam_ros.serving.checkpoint_writer import CheckpointWriter
from semiparam_ros.serving.learning_loop import Input, Stepped
from semiparam_ros.serving.model_service import ModelService

__all__ = ["INPUT_QOS", "PARAMETERS_QOS", "EstimatorNode", "StartupError"]

_LOG_THROTTLE_S = 5.0
_BATCH = 50  # queued messages processed per turn of the executor (≈ 10–20 ms of learning at most)
_SHUTDOWN_BUDGET_S = 10.0  # time allowed to learn the queue at shutdown (1000 messages take ≈ 0.2 s)
_CATCH_UP_PERIOD_S = 1e-4  # the backlog timer fires at every executor turn while armed
_SAVE_TIMEOUT_S = 5.0  # ~/save waits this long for the checkpoint thread, then replies failure


class EstimatorNode(Node):
    """ROS 2 node running :class:`OnlineEstimator` on live topics (docs/node.md).

    Args:
        node_name: Node name (parameters are read from the blocks of the parameter files whose keys match
            the fully qualified name: ``/**`` as the shipped files, or the name itself).
        deferred: Only declare the parameters; :meth:`_build` makes the rest (the lifecycle node's
            configure, :mod:`semiparam_ros.ros.lifecycle_node`).
        params_files: The ``--params-file`` files of the process's command line (``main`` passes them;
            those of ``cli_args`` are found there): when none has a key for this node, it does not start.
        **kwargs: Passed to :class:`rclpy.node.Node` (e.g. ``context``, ``parameter_overrides``).

    Raises:
        StartupError: If no parameter file given applies to the node (the message names their keys and
            the node's name), ``robot.urdf`` is not set, a parameter is invalid or the checkpoint to warm
            start from is incompatible; the node is destroyed before raising.
    """

    def __init__(self, node_name: str = "estimator", *, deferred: bool = False,
                 params_files: Sequence[Path] = (), **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._active = True  # whether inputs are taken and outputs published (lifecycle: while active)
        self._checkpoints: CheckpointWriter | None = None
        self.feedforward: FeedForwardEndpoints | None = None
        self._service: ModelService | None = None
        self._save: SaveService | None = None
        #: Whether the final checkpoint (at shutdown) was written, or none was due; ``main`` exits 1 if not.
        self.final_checkpoint_ok = True
        try:
            files = [*params_files, *parameter_files(kwargs.get("cli_args") or ())]
            unmatched = unmatched_files_message(files, self.get_fully_qualified_name())
            if unmatched is not None:
                raise StartupError(unmatched)
            self.config: EstimatorConfig = declare_parameters(self)
            try:
                self.config.require_robot()
            except ConfigurationError as err:
                raise StartupError(str(err)) from None
            if not deferred:
                self._build()
        except BaseException as err:
            self._stop_threads(save=False)
            self.destroy_node()
            if isinstance(err, ParameterError):
                raise StartupError(f"invalid parameter: {err}") from err
            raise

    # ================================================================== set-up
    def _build(self, urdf_xml: str | None = None) -> None:
        """Build the loop, its services, entities and threads (a lifecycle node: on configure)."""
        cfg = self.config
        output, self._joints = cfg.output_kind, tuple(cfg["robot.joints"])
        self._frame_id = cfg["robot.frame_id"]
        self._ckpt_path, default_ckpt = checkpoint_path(cfg, self.get_fully_qualified_name())
        spec = str(cfg["robot.urdf"])
        try:
            if urdf_xml is None and spec.startswith(TOPIC_SCHEME):
                urdf_xml = wait_for_description(self, spec[len(TOPIC_SCHEME):],
                                                float(cfg["robot.description_timeout"]))
        except DescriptionTimeoutError as err:
            raise StartupError(str(err)) from err
        parts = assemble(cfg, urdf_xml, source=f"published on {spec}", checkpoint=self._ckpt_path,
                         default_checkpoint=default_ckpt)
        for note in parts.notes:
            self.get_logger().info(note)
        self.loop, self._service = parts.loop, parts.model
        est = self.loop.estimator
        self._published_version = -1
        self._stats = NodeStatistics(output, cfg.n_outputs, rmse_window_samples(cfg),
                                     rmse_window_final=bool(cfg["diagnostics.rmse_window"]))
        self._warn = ThrottledWarnings(self.get_logger(), _LOG_THROTTLE_S)
        self._drops = DropReporter(self.get_logger(), self._warn)
        projection = self._service.projection
        self.outputs = Outputs(self, () if output == OutputKind.WRENCH else self._joints,
                               n_links=0 if projection is None else est.regressor.n_bodies)
        self.inputs = InputStreams(self, {k: cfg[k.topic_parameter] for k in output.inputs},
                                   {k: functools.partial(self._on_input, k) for k in output.inputs},
                                   loop=self.loop, stats=self._stats, warn=self._warn,
                                   n_joints=len(self._joints))
        if self._service.feedforward is not None:
            names = endpoint_names(self, str(cfg["feedforward.controller_action"]))
            self.feedforward = FeedForwardEndpoints(self, names, self._service, self._warn,
                                                    lambda: self._active)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(Trigger, "~/payload/tare", self._on_payload_tare)
        self.add_on_set_parameters_callback(make_parameter_validator(lambda: self.config))
        self.add_post_set_parameters_callback(self._on_parameters_set)
        # wall-time timers, so diagnostics go on when /clock stops
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._diag_period, self._last_diag = float(cfg["diagnostics.period"]), -math.inf
        self.create_timer(self._diag_period, self._on_diagnostics_timer, clock=steady)
        self.create_timer(1.0, self._check_inputs, clock=steady)
        if projection is not None:
            self.create_service(Trigger, "~/export_urdf", self._on_export_urdf)
            submit = self._service.submit_projection
            submit()
            self.create_timer(cfg["parametric.consistent_period"], submit, clock=steady)
        if self._service.feedforward is not None and cfg["feedforward.refresh_period"] > 0:
            self._refresh_feedforward()
            self.create_timer(cfg["feedforward.refresh_period"], self._refresh_feedforward, clock=steady)
        # a backlog's catch-up, and the idle turn applying a deferred update: armed only when needed
        self._catch_up = self.create_timer(_CATCH_UP_PERIOD_S, self._process_queued, clock=steady)
        self._catch_up.cancel()
        self._idle = self.create_timer(_CATCH_UP_PERIOD_S, self._on_idle, clock=steady)
        self._idle.cancel()
        self._checkpoints = CheckpointWriter(self._ckpt_path, period_s=cfg["checkpoint.period"],
                                             snapshot=self.loop.snapshot, version=lambda: self.loop.version,
                                             on_result=self._checkpoint_written)
        self._checkpoints.start()
        self._save = SaveService(self, self._on_save, join_timeout_s=2 * _SAVE_TIMEOUT_S)
        self._publish_parameters(force=True)
        inputs = [self.resolve_topic_name(cfg[k.topic_parameter]) for k in output.inputs]
        self.get_logger().info(
            f"estimating {output} of joints {list(self._joints)}: {est.regressor.n_base} base "
            f"parameters, D = {cfg['nonparametric.n_features']} random features; learning "
            f"{'enabled' if est.learning_enabled else 'disabled'}; inputs {', '.join(inputs)}")

    # ================================================================== inputs (executor thread)
    @quiet_at_shutdown
    def _on_input(self, kind: InputKind, msg: bytes) -> None:
        if self._active:  # an inactive lifecycle node takes no input
            self.inputs.intake(kind, msg)
            self.inputs.drain(kind)
            self._process_queued()

    # ================================================================== learning (executor thread)
    @quiet_at_shutdown
    def _process_queued(self) -> None:
        """Run the loop on queued input: at most a batch, so inputs, services and timers get turns."""
        if self.loop.queue:
            cpu = time.thread_time()  # a system call (≈ 1 µs): once per batch, not per message
            serve = None if self.feedforward is None else self.feedforward.serve_waiting
            try:  # a controller waiting goes first (serve), then one input at a time
                n = self.loop.drain(_BATCH, before_each=serve, on_step=self._publish_step)
            except Exception as err:  # bad input never gets here (dropped and counted): this is a bug
                self.get_logger().fatal(f"programming error in the estimator: {err!r}")
                raise
            self._stats.add_learning_cpu(time.thread_time() - cpu, n)
        if self.loop.queue:
            if self._catch_up.is_canceled():
                self._catch_up.reset()
        else:
            if not self._catch_up.is_canceled():
                self._catch_up.cancel()
            if self.loop.max_delay_s > 0.0 and self._idle.is_canceled():
                self._idle.reset()

    @quiet_at_shutdown
    def _on_idle(self) -> None:
        """Apply the learners' deferred update while no input waits (one executor turn after learning)."""
        self._idle.cancel()
        cpu = time.thread_time()
        if self.loop.apply_pending():
            self._stats.add_learning_cpu(time.thread_time() - cpu, 0)

    def _publish_step(self, data: Input, stepped: Stepped, t_recv: float) -> None:
        """Count and publish what one input produced (bad input was dropped and counted by the loop)."""
        est = self.loop.estimator
        gravity = self._service.gravity if self._service is not None else None
        frame = self._frame_id or est.pipeline.last_frame_id
        for result in stepped.results:
            self.outputs.publish_sample(result, frame, gravity)  # a failure: a bug too
        self._stats.add_step(stepped, est, t_recv)
        if stepped.new_drops:
            self._drops.report(est.drops)
        if est.warnings:  # once each (the effort units check)
            for text in est.warnings:
                self.get_logger().warning(text)
            est.warnings.clear()

    # ================================================================== services, parameters, timers
    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.loop.reset()  # also zeroes the pipeline's drop counts
        self._stats.clear_errors()
        self._refresh_feedforward()  # the reset model is served at once
        self._publish_parameters(force=True)
        if self._checkpoints is not None:
            self._checkpoints.request_reset()  # persisted, so a warm start does not bring it back
        self.get_logger().info("model reset: everything learned was forgotten")
        response.success, response.message = True, "model reset"
        return response

    def _on_payload_tare(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self._service.tare_payload()  # type: ignore[union-attr]
        self.get_logger().info("payload tared: a pickup from now on is published on ~/payload")
        response.success, response.message = True, "payload tared"
        return response

    def _on_export_urdf(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Write the URDF with the newest consistent parameters next to the checkpoint (identification)."""
        path = None if self._ckpt_path is None else self._ckpt_path.with_name(
            self._ckpt_path.stem + "_identified.urdf")
        response.success, response.message = self._service.export_urdf(path)  # type: ignore[union-attr]
        return response

    def _on_parameters_set(self, params: list[Parameter]) -> None:
        """Hand changed run-time parameters to what takes them (the table's ``runtime`` targets)."""
        known = {p.name: p.value for p in params if p.name in self.config.values}
        if not known:
            return
        self.config = self.config.with_overrides(known)
        targets = runtime_targets(known)
        self.loop.apply_runtime_parameters(self.config, targets)
        if "checkpoints" in targets and self._checkpoints is not None:
            self._checkpoints.apply_runtime_parameters(self.config)
        self.get_logger().info("parameters set: " + ", ".join(f"{k} = {v!r}" for k, v in known.items()))

    @quiet_at_shutdown
    def _check_inputs(self) -> None:
        """Name a configured input topic that stays silent on the console (the graph's candidates too)."""
        if self._active:
            stats = self._stats
            self.inputs.check_silence({InputKind.JOINT_STATES: stats.joint_states_received,
                                       InputKind.WRENCH: stats.wrench_received})

    @quiet_at_shutdown
    def _on_diagnostics_timer(self) -> None:
        # a timer that fell behind fires again at once: that would close a period of a few µs with no
        # samples (NaN latencies, a spurious "no input" WARN), so a short period goes on into the next
        now = time.monotonic()
        if now - self._last_diag < 0.5 * self._diag_period:
            return
        self._last_diag = now
        service = self._service
        assert service is not None
        stats = estimator_statistics(self._stats.snapshot(), self.loop)
        stats.update(service.excitation_statistics())
        stats["checkpoint_path"] = str(self._ckpt_path or "")
        stats.update(service.statistics())
        msg = diagnostic_array(self.get_clock().now().to_msg(), f"{self.get_name()}: online learning",
                               ",".join(self._joints), stats,
                               stalled=bool(stats["queue_length"]) and not stats["processed_in_period"])
        self.outputs.diagnostics.publish(msg)
        self._publish_parameters(force=False)
        payload = service.payload()
        if payload is not None:
            self.outputs.publish_payload(payload, self.get_clock().now().nanoseconds)

    def _publish_parameters(self, *, force: bool) -> None:
        with self.loop.lock:
            version = self.loop.version
            if not force and version == self._published_version:
                return
            params, names = self.loop.estimator.parameters, self.loop.estimator.parameter_names
        if params is not None:
            self.outputs.publish_parameters(names, params)
            self._published_version = version

    def _on_save(self) -> tuple[bool, str]:
        """``~/save`` (in the save-service thread): hand the request to the checkpoint thread and wait."""
        writer = self._checkpoints
        if writer is None:
            return False, "the node is shutting down: the final checkpoint is being written"
        return writer.save(_SAVE_TIMEOUT_S)

    def _checkpoint_written(self, ok: bool, message: str) -> None:
        self._stats.mark_checkpoint(ok)
        if not ok:
            self.get_logger().error(f"{message} (writing {self._ckpt_path})",
                                    throttle_duration_sec=_LOG_THROTTLE_S)

    # ================================================================== feed-forward (executor thread)
    @quiet_at_shutdown
    def _refresh_feedforward(self) -> None:
        """Serve a fresh copy of the model; publish the link inertias of a new consistent solution."""
        estimate = self._service.refresh()  # type: ignore[union-attr]
        if estimate is not None:
            self.outputs.publish_links(estimate, self.get_clock().now().nanoseconds)

    # ================================================================== shutdown
    def _stop_threads(self, *, save: bool) -> None:
        if self._service is not None:
            self._service.close()
        if self._checkpoints is not None:
            self.final_checkpoint_ok = self._checkpoints.stop(save=save) or not save
            self._checkpoints = None

    def _stop_save_service(self) -> None:
        """Stop the helper nodes' threads: ``~/save`` and the feed-forward endpoints."""
        if self._save is not None:
            self._save.close()
            self._save = None
        if self.feedforward is not None:
            self.feedforward.close()
            self.feedforward = None

    def destroy_node(self) -> None:
        """Stop the helper nodes' threads (``~/save``, feed-forward), then destroy the node."""
        self._stop_save_service()
        super().destroy_node()

    def abort(self) -> None:
        """Stop the threads without learning the queue or writing a final checkpoint (a crashed executor)."""
        self._stop_threads(save=False)

    def shutdown(self) -> None:
        """Learn what is still queued, then write the final checkpoint (if configured) and stop the threads.

        Call before ``destroy_node`` (``main`` does), from the thread that ran the executor once it has
        stopped spinning.
        """
        try:
            loop = getattr(self, "loop", None)
            n = 0 if loop is None else loop.learn_remaining(_SHUTDOWN_BUDGET_S)
            if n:
                self.get_logger().info(f"learned {n} queued messages before the final checkpoint")
        except Exception as err:  # shutting down must always reach the checkpoint
            self.get_logger().error(f"could not learn the queued messages at shutdown: {err!r}")
        self._stop_threads(save=True)

    @property
    def estimator(self) -> OnlineEstimator:
        """The estimator (driven by the executor thread: hold no reference across samples)."""
        return self.loop.estimator
