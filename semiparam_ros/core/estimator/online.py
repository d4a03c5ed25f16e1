"""The online estimator: pipeline + learner, driven one message at a time.

This is the single data path shared by the live node and offline replay: messages go through
:class:`~semiparam_ros.core.stream.pipeline.SamplePipeline` (joint mapping, stamp pairing, acceleration
estimate, drops counted by reason) and every paired sample goes through :meth:`OnlineEstimator.step`,
which first predicts (a priori: the prediction never saw its own label) and then learns — the
rigid-body stage first, then the residual. The same bag therefore gives the same numbers whichever way it
is fed. The checkpoint format is :mod:`semiparam_ros.core.estimator.state`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np

from semiparam_ros.core.checkpoint import atomic_save_npz, load_npz
from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.build import (
    Model,
    ModelKind,
    build_model,
    build_pipeline,
    build_regressor,
    column_scale,
    gate_config,
    rigid_body_part,
    traits_of,
)
from semiparam_ros.core.estimator.calibration import FrozenCalibration
from semiparam_ros.core.estimator.migration import migrate
from semiparam_ros.core.estimator.state import (
    CHECKPOINT_VERSION,
    check_magnitudes,
    meta_arrays,
    read_meta,
    read_period,
    read_version,
)
from semiparam_ros.core.estimator.units import EffortUnitsCheck
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.core.learners._step_kernels import joined_within
from semiparam_ros.core.learners.contract import Prediction, PredictionContext, RigidBodyUser
from semiparam_ros.core.learners.stick import StickFriction, with_held
from semiparam_ros.core.learners.uncertainty import NoiseScale
from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.core.rigid_body.identification import ConsistentEstimate, consistent_parameters
from semiparam_ros.core.rigid_body.payload import PayloadLearner
from semiparam_ros.core.stream.gate import ContactGate, Verdict
from semiparam_ros.core.stream.messages import InputMessage, Sample
from semiparam_ros.core.stream.rate import RateMeter
from semiparam_ros.core.validation import MAX_ABS_INPUT
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError

DROP_REJECTED_SAMPLE = "rejected_sample"
"""Key of :attr:`OnlineEstimator.drops`: a paired sample the learner refused (values beyond its input
bound or a regressor overflow), typically after a finite but absurd joint state passed the pipeline."""

NOT_LEARNED_GATED_CONTACT = "gated_contact"
"""Key of :attr:`OnlineEstimator.not_learned`: a sample predicted but not learned because its residual
was implausibly large for less than ``gate.max_contact_duration`` (see :mod:`semiparam_ros.core.stream.gate`);
not an input drop."""


@dataclass(frozen=True)
class StepResult:
    """What one paired sample produced.

    Attributes:
        sample: The sample (stamp [ns], q [rad], dq [rad/s], ddq [rad/s²], measured y).
        prediction: The a-priori prediction of y (parametric, residual and total parts; N, N·m for a
            wrench, N·m for joint torques), made before the sample was learned.
        latency_s: Wall time of predict + learn for this sample [s].
        learned: Whether the sample was learned (false when learning is disabled or the gate refused it).
        std: Predictive standard deviation of each component of y, noise included (units of y; +inf
            before the first sample): also the σ of the external wrench/torques ``y − prediction.total``.
        verdict: The contact gate's verdict, or None when the gate is off or learning is disabled.
    """

    sample: Sample
    prediction: Prediction
    latency_s: float
    learned: bool
    std: np.ndarray | None = None
    verdict: Verdict | None = None

    @property
    def external(self) -> np.ndarray:
        """``y − prediction.total``, what the model does not explain.

        The external wrench (N, N·m) or joint torques (N·m) when something touches the robot, noise
        otherwise (σ = :attr:`std`).
        """
        return self.sample.y - self.prediction.total


class OnlineEstimator:
    """Pipeline + semiparametric learner, driven one message at a time.

    Args:
        config: Validated configuration.
        regressor: Prebuilt regressor (to share one between estimators); built when omitted.
        kind: Learner to run; the node runs ``"SP"``, whose prediction carries all three parts.

    Example:
        >>> from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
        >>> from semiparam_ros.core.stream.messages import JointStateData
        >>> est = OnlineEstimator(EstimatorConfig.from_flat(ICUB_RIGHT_ARM))  # iCub arm, F/T wrench
        >>> est.regressor.n_base
        17
        >>> est.process(JointStateData(10**9, ("r_elbow",), [0.1]))  # joints missing
        []
        >>> est.n_dropped
        1
    """

    def __init__(self, config: EstimatorConfig, *, regressor: RigidBodyRegressor | None = None,
                 kind: ModelKind = "SP") -> None:
        self.config = config
        self.kind: ModelKind = kind
        self.regressor = regressor if regressor is not None else build_regressor(config)
        self.pipeline = build_pipeline(config)
        self.model = build_model(config, kind, self.regressor)
        #: What the estimator needs to know of its learner's kind (the builder's answer).
        self.traits = traits_of(self.model)
        #: What reading the last loaded checkpoint of an older format did (one line per step; empty if none).
        self.migration_notes: list[str] = []
        self._scale = column_scale(config, self.regressor)
        self.learning_enabled = bool(config["learning_enabled"])
        self._n_joints = len(config["robot.joints"])
        self.n_samples_learned = 0
        #: Samples predicted without learning because the caller fell behind (``skip_learning``).
        self.n_learning_skipped = 0
        #: The payload learner since the last :meth:`tare_payload` (None before one).
        self.payload: PayloadLearner | None = None
        self._rejected = 0
        self._last_learned_ns: int | None = None  # stamp of the newest learned sample
        self.noise = NoiseScale(self.model.n_outputs, config["uncertainty.noise_time_constant"])
        #: What a frozen copy of the model scored on later motion: the served σ's scale per output and
        #: motion state (None with ``uncertainty.calibration_block: 0``).
        self.calibration = _calibration(config, self.model.n_outputs)
        #: Friction that remembers: each joint's stick state and the torque it holds (joint torques with
        #: ``parametric.stick_displacement`` > 0, else None).
        self.stick = _stick(config)
        self.gate = ContactGate(gate_config(config))
        self.gate_enabled = bool(config["gate.enabled"])
        self.forgetting: float | None = None  # β from adaptation.time_constant, once the rate is measured
        #: Sample period [s] measured from the first :data:`RATE_SAMPLES` samples (None until then).
        self.sample_period_s: float | None = None
        self._rate = RateMeter()  # the rule of offline replay's measured_period_s(stamps)
        #: Solve the consistent projection in line, on the node's schedule in the samples' time (``learn``
        #: and offline replay; the node solves it in a worker process instead): see :meth:`projects`.
        self.inline_projection = False
        self._projected_at: int | None = None  # stamp [ns] the schedule counts from (None: next sample)
        self._projected_learned = 0  # n_samples_learned at the last solution
        #: Whether the first seconds of measured efforts look like the URDF's torques in N·m (joint torques
        #: only; fed by :meth:`process`): see :mod:`~semiparam_ros.core.estimator.units`.
        self.units_check = (EffortUnitsCheck(self.regressor, config["robot.joints"])
                            if config.output_kind == OutputKind.JOINT_TORQUES else None)
        #: Warnings about the input for the user, appended once each (the node logs and clears them).
        self.warnings: list[str] = []

    # ------------------------------------------------------------------ streaming
    def process(self, msg: InputMessage, *, skip_learning: bool = False) -> list[StepResult]:
        """Feed one input message; return the results of the samples it completed (often none or one).

        The one entry for messages (a :class:`JointStateData` or a :class:`WrenchData`, as the node,
        ``learn`` and replay read them). Never raises on bad data: the pipeline drops and counts bad
        messages, and a sample the learner rejects (:class:`~semiparam_ros.errors.RejectedSampleError`) is
        counted under ``rejected_sample`` in :attr:`drops` (the learned state is unchanged). Any other
        exception is a programming error: it propagates and no drop is counted.

        Args:
            msg: The message.
            skip_learning: Predict the completed samples cheaply without learning them (see :meth:`step`).
        """
        return self._step_all(self.pipeline.add(msg), skip_learning)

    def _step_all(self, samples: list[Sample], skip_learning: bool = False) -> list[StepResult]:
        # The pipeline drops NaN/inf and values beyond limits.*, but those bounds can be switched off (0)
        # or be loose: a finite but absurd value (e.g. a velocity of 1e200 rad/s) then poisons the q̈
        # window, and the learners refuse those samples with a RejectedSampleError (state untouched).
        # Streaming counts that as a drop rather than abort the message and lose the other samples it
        # completed. Any other exception is a bug and propagates, with the counters untouched.
        results: list[StepResult] = []
        check = self.units_check
        for sample in samples:
            if check is not None and not check.done and check.add(sample.stamp_ns, sample.q, sample.dq,
                                                                   sample.ddq, sample.y):
                if check.findings:
                    self.warnings.append(check.message())
            try:
                results.append(self.step(sample, skip_learning=skip_learning))
            except RejectedSampleError:
                self._rejected += 1
        return results

    def step(self, sample: Sample, *, skip_learning: bool = False) -> StepResult:
        """Predict y for a sample, then learn it (unless learning is disabled or the gate refuses it).

        The sample is validated once (sizes; NaN, inf or beyond ±1e150); with the gate on, the model's
        :meth:`predict_ahead` context (regressor, parametric prediction, random features) is learned from
        directly, so nothing is computed twice. With the gate off the step is the paper's
        ``predict_learn_one``, bit for bit.

        With ``skip_learning`` (a node that fell behind its input) the sample is predicted by the model's
        cheap ``predict_held`` (the consistent SP holds its residual from the last full prediction) and
        not learned; the noise estimate skips it, the gate does not see it, and it is counted in
        :attr:`n_learning_skipped`. So too with learning disabled: a late sample is predicted cheaply.

        Args:
            sample: A clean sample from the pipeline.
            skip_learning: Predict cheaply and do not learn.

        Returns:
            The a-priori prediction and the time it took.

        Raises:
            RejectedSampleError: If the learner rejects the sample (wrong sizes, non-finite or absurdly
                large values, regressor overflow); the learned state, the gate and the noise estimate are
                then unchanged.
        """
        if self.sample_period_s is None:
            self._measure_rate(sample.stamp_ns)
        if self.inline_projection:
            self._project_if_due(sample.stamp_ns)
        start = time.perf_counter()
        x, y = self._check_sample(sample)
        model = self.model
        model.prediction_age_s = self.age_at(sample.stamp_ns)
        stick = self.stick
        phi: np.ndarray | None = None
        held: np.ndarray | None = None  # the torque the stick state holds
        if stick is not None:
            phi = stick.step(sample.q, sample.dq)
            held = stick.torque(phi)
        target = y if held is None else y - held  # what the learners learn
        if skip_learning:
            prediction = with_held(model.predict_held(x), held)
            assert prediction.variance is not None  # a held prediction carries it
            std = self.noise.std(prediction.variance)
            self.noise.skip(sample.stamp_ns)
            self.n_learning_skipped += 1
            return StepResult(sample, prediction, time.perf_counter() - start, False, std, None)
        # a priori, with the relative variance v = z A⁻¹ zᵀ of each output (the state is not changed)
        ahead = model.predict_ahead_checked(x)
        prediction = with_held(ahead.prediction, held)
        variance = prediction.variance
        # the stick torque is regressed on the learned rigid body's error (a residual memorizes each rest's
        # torque at its position within samples and would leave nothing; the learned π̂, not the served
        # projection, so that what the learners learn does not depend on when a projection was solved)
        rigid_error = None if stick is None else y - _learned_rigid(model, ahead)
        assert variance is not None  # a context always carries it
        verdict = None
        if self.learning_enabled and self.gate_enabled:
            error = y - prediction.total
            std = self.noise.std(variance)
            verdict = self.gate.decide(sample.stamp_ns, error, std, float(variance.max()))
            learned = verdict.learn
            if learned:
                model.learn_ahead_checked(ahead, target)
                self.n_samples_learned += 1
        else:
            # gate off: exactly the paper's predict-then-learn (bit-identical predictions); the consistent
            # SP's predict-then-learn is the a-priori prediction above, then learning it
            learned = self.learning_enabled
            if learned:
                if self.traits.learns_context:
                    model.learn_ahead_checked(ahead, target)
                else:
                    prediction = with_held(model.predict_learn_one(x, target), held)
                self.n_samples_learned += 1
            std = self.noise.std(variance)
            error = y - prediction.total
        if learned:
            self._last_learned_ns = sample.stamp_ns
        if learned and self.payload is not None:
            self.payload.update(sample.q, sample.dq, sample.ddq, y)
        if learned or verdict is None:
            # σ is the model's: a fast correction of the recent error (the consistent SP's) makes one-step
            # errors far smaller than those of a model that stops learning, e.g. through a contact
            correction = prediction.correction
            model_error = error if correction is None else error + correction
            self.noise.update(sample.stamp_ns, model_error, variance)
            if learned and stick is not None and phi is not None and rigid_error is not None:
                stick.learn(sample.stamp_ns, phi, rigid_error)
            if learned and self.calibration is not None:
                self.calibration.observe(sample.stamp_ns, x, y, model, model_error, variance,
                                         None if stick is None or phi is None else (phi, stick.coefficient))
        else:
            self.noise.skip(sample.stamp_ns)
        return StepResult(sample, prediction, time.perf_counter() - start, learned, std, verdict)

    def age_at(self, stamp_ns: int) -> float:
        """Age [s] of the learned state at a stamp: T × (samples since the newest learned one − 1).

        What the model's fast correction fades with (``prediction_age_s``). The samples are counted as
        Δt/T rounded, so the age is 0 when the previous sample was learned, whatever the jitter below T/2;
        it is 0 before the period T is known and at the first sample of a recording.

        Args:
            stamp_ns: The predicted sample's stamp [ns].

        Returns:
            The age [s], ≥ 0.
        """
        last, period = self._last_learned_ns, self.sample_period_s
        if last is None or period is None:
            return 0.0
        missed = round((stamp_ns - last) * 1e-9 / period) - 1
        return missed * period if missed > 0 else 0.0

    def _check_sample(self, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """``(x, y)`` of a sample, sizes and values checked once for every stage after it.

        Raises:
            RejectedSampleError: On a wrong size, or NaN, inf or an entry beyond ±MAX_ABS_INPUT.
        """
        n, t = self._n_joints, self.model.n_outputs
        q, dq, ddq, y = sample.q, sample.dq, sample.ddq, sample.y
        if not (q.shape == dq.shape == ddq.shape == (n,) and y.shape == (t,)):
            raise RejectedSampleError(f"sample must have q, dq, ddq of {n} joints and y of {t} values, got "
                                      f"{q.shape}, {dq.shape}, {ddq.shape} and {y.shape}")
        # one pass catches NaN (comparison false), ±inf and values whose squares would overflow
        bad, xy = joined_within(q, dq, ddq, y, MAX_ABS_INPUT)
        if bad:
            raise RejectedSampleError(f"{'x' if bad == 1 else 'y'} contains NaN, inf or entries larger than "
                                      f"{MAX_ABS_INPUT:g} in magnitude")
        return xy[: 3 * n], xy[3 * n :]

    def tare_payload(self) -> None:
        """Start counting a payload from now: the rigid-body model as it is becomes the reference.

        From the next learned sample on, :attr:`payload` learns the change of the distal body's ten
        inertial parameters that explains ``y − Φ_b π̂_b`` (π̂_b frozen now; see
        :mod:`semiparam_ros.core.rigid_body.payload`). Tare before a pickup, with nothing carried.

        Raises:
            ValueError: For a learner without a rigid-body part (``NP``).
        """
        params = self.parameters
        if params is None:
            raise ValueError("a payload needs a rigid-body part: this learner is nonparametric only")
        self.payload = PayloadLearner(self.regressor, params)

    def apply_pending(self) -> bool:
        """Apply the learners' deferred updates now (idle time; see :meth:`RecursiveRLS.apply_pending`).

        A node calls this when no input waits, so that the next sample's prediction is only a triangular
        solve: the longest uninterruptible piece of work per learned sample is then about half as long.

        Returns:
            Whether any update was pending.
        """
        return self.model.apply_pending()

    @property
    def has_pending(self) -> bool:
        """Whether a learner holds a deferred update (see :meth:`apply_pending`)."""
        return self.model.has_pending()

    def rigid_body_state(self) -> tuple[np.ndarray, np.ndarray, float]:
        """Copy what the consistent projection needs of the rigid-body learner.

        Returns:
            ``(θ, R, λ)``: the parametric learner's coefficients (scaled columns), a copy of its upper
            triangular factor and its regularization.

        Raises:
            ConfigurationError: The model has no rigid-body part (``NP``).
        """
        par = rigid_body_part(self.model)
        if par is None:
            raise ConfigurationError("the model has no rigid-body part to project")
        return par.parameters.copy(), par.rls.R.copy(), par.rls.lam

    @property
    def projects(self) -> bool:
        """Whether this estimator's model predicts with a consistent projection once one is solved.

        The node's rule: ``parametric.consistent`` on, joint torques, and a model that predicts with one
        rigid body: the consistent SP (the default) or the rigid-body model P.
        """
        return (bool(self.config["parametric.consistent"])
                and self.config.output_kind == OutputKind.JOINT_TORQUES
                and self.traits.takes_rigid)

    def _project_if_due(self, stamp_ns: int) -> None:
        """Solve the consistent projection if the node's schedule, in the samples' time, says it is due.

        As the node: a solution every ``parametric.consistent_period`` [s] when learning changed the
        rigid-body learner, and one at once when a recording begins with something learned but no
        solution (a warm start from a checkpoint); a solver failure keeps the last solution. Nothing is
        solved before the first learned sample (the projection of the prior is the prior).
        """
        if not self.projects:
            return
        model = cast(RigidBodyUser, self.model)
        last = self._projected_at
        if last is not None and stamp_ns - last < self.config["parametric.consistent_period"] * 1e9:
            return
        self._projected_at = stamp_ns
        learned = self.n_samples_learned
        if learned == 0 or (learned == self._projected_learned and model.rigid_override is not None):
            return
        theta, R, lam = self.rigid_body_state()
        try:
            self.use_consistent(consistent_parameters(self.regressor, theta, R, self._scale, lam))
        except (ConfigurationError, RejectedSampleError):
            return  # the solver failed or gave non-finite values: keep the last solution, as the node does
        self._projected_learned = learned

    def use_consistent(self, estimate: ConsistentEstimate | None) -> bool:
        """Predict with a consistent projection's rigid body from now on (consistent SP, P; None: learned).

        Where ``parametric.consistent`` is on, the node hands each new solution of its projection worker
        to the model it predicts with, so that its per-sample predictions, the feed-forward and
        ``load_model`` all use one rigid body (see
        :meth:`~semiparam_ros.core.learners.consistent.ConsistentSemiparametricModel.use_rigid`).

        Args:
            estimate: A solution of
                :func:`~semiparam_ros.core.rigid_body.identification.consistent_parameters` for this
                estimator's rigid-body learner, or None to predict with the learned parameters.

        Returns:
            Whether the model took it (False for the cascade, the joint fit and NP, which always predict
            with their learned parameters: the cascade's residual learned the errors of those).

        Raises:
            RejectedSampleError: An estimate of another size or with non-finite values (model unchanged).
        """
        if not self.traits.takes_rigid:
            return False
        rigid = None if estimate is None else self._scale * np.asarray(estimate.base)
        cast(RigidBodyUser, self.model).use_rigid(rigid)
        return True

    def apply_runtime_parameters(self, config: EstimatorConfig) -> None:
        """Take the run-time parameters: ``learning_enabled``, ``gate.*``, ``uncertainty.*``.

        Args:
            config: A validated configuration (only its run-time entries of the ``estimator`` target are
                read: :attr:`~semiparam_ros.core.config.ParameterSpec.runtime`).

        Raises:
            ValueError: On an invalid gate parameter (nothing is changed then).
        """
        gate = gate_config(config)
        self.noise.set_time_constant(config["uncertainty.noise_time_constant"])
        self.gate.config = gate
        self.gate_enabled = bool(config["gate.enabled"])
        self.learning_enabled = bool(config["learning_enabled"])

    def _measure_rate(self, stamp_ns: int) -> None:
        """Feed the rate meter; once the period is known, announce it to the learner (once).

        The learner converts what its configuration gives in seconds at it
        (:meth:`~semiparam_ros.core.learners.contract.Learner.on_period`): the standardizer warm-up, the
        fast correction's memory and, with ``adaptation.time_constant`` τ > 0, β = exp(−T/τ) — as
        offline, where :func:`~semiparam_ros.core.estimator.build.build_model` is given the period.
        """
        period = self._rate.add(stamp_ns)
        if period is None:
            return
        self.sample_period_s = period
        self.forgetting = self.model.on_period(period)

    # ------------------------------------------------------------------ inspection
    @property
    def drops(self) -> dict[str, int]:
        """Input messages dropped so far, by reason (the pipeline's reasons and ``rejected_sample``)."""
        drops = dict(self.pipeline.drops)
        drops[DROP_REJECTED_SAMPLE] = self._rejected
        return drops

    @property
    def not_learned(self) -> dict[str, int]:
        """Samples predicted but deliberately not learned, by reason (``gated_contact``); not drops."""
        return {NOT_LEARNED_GATED_CONTACT: self.gate.counts[Verdict.GATED]}

    @property
    def n_dropped(self) -> int:
        """Total of :attr:`drops` (every reason, ``rejected_sample`` included), without building the dict."""
        return self.pipeline.n_dropped + self._rejected

    @property
    def parameters(self) -> np.ndarray | None:
        """Current estimate of the base parameters π̂_b in physical units (None for the NP learner).

        Inertial combinations (kg, kg·m, kg·m²), then sensor offsets (N, N·m) or per-joint viscous
        (N·m·s/rad), Coulomb (N·m), offset (N·m) and armature (kg·m²) terms, named by
        :attr:`parameter_names`.
        """
        return self.physical_parameters(self.model)

    @property
    def column_scale(self) -> np.ndarray:
        """The column scales c of the rigid-body learner (θ = c ⊙ π_b; ones without column scaling)."""
        return self._scale.copy()

    def physical_parameters(self, model: Model) -> np.ndarray | None:
        """Return the base parameters of a model of this estimator (its own or a copy) in physical units.

        Args:
            model: A learner built for this estimator's configuration (e.g. ``est.model.copy()``).

        Returns:
            π̂_b = θ / c (see :attr:`parameters`), or None for the NP learner.
        """
        theta = model.parameters
        return None if theta is None else theta / self._scale

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the base parameters, as combinations of the URDF parameters."""
        return tuple(self.regressor.base_parameter_names)

    @property
    def model_size(self) -> int:
        """Number of learned coefficients: the base parameters π̂ plus the D × t residual weights.

        The same for both SP combinations (the joint fit's random-feature factor carries t·p extra
        columns, but the model it encodes is π and the D × t weights of the residual).
        """
        n_out = self.regressor.n_outputs
        size = 0
        if self.kind in ("P", "SP"):
            size += self.regressor.n_base
        if self.kind in ("NP", "SP"):
            size += int(self.config["nonparametric.n_features"]) * n_out
        return size

    def start_recording(self) -> None:
        """Begin another recording (another bag): keep what was learned, restart the time-based state.

        The pipeline (pairing buffers, acceleration window, stamp order) starts afresh, the noise estimate
        and the contact gate take the next stamp as a new beginning (a warm-up already over stays over),
        so a later recording whose stamps lie before the previous one's is learned, not dropped.
        """
        self.pipeline.reset(keep_counts=True)
        self.noise.restart_stream()
        self.gate.restart_stream()
        if self.calibration is not None:
            self.calibration.restart_stream()
        if self.stick is not None:
            self.stick.restart_stream()
        self._last_learned_ns = None
        self._projected_at = None

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget everything learned and restart the pipeline (configuration kept)."""
        self.model.reset()
        self.pipeline.reset()
        self.n_samples_learned = 0
        self.n_learning_skipped = 0
        self.payload = None
        self._rejected = 0
        self._last_learned_ns = None
        self._projected_at = None
        self._projected_learned = 0
        self.noise.reset()
        if self.calibration is not None:
            self.calibration.reset()
        if self.stick is not None:
            self.stick.reset()
        self.gate.reset()

    def save(self, path: str | Path) -> None:
        """Write the learned state to one ``.npz`` file atomically (temp file + rename).

        Args:
            path: Destination file.
        """
        atomic_save_npz(Path(path).expanduser(), self.checkpoint_state())

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        """Return what :meth:`save` writes, as arrays that share no memory with the live learner.

        The node takes this snapshot under its model lock (a memory copy) and writes it from another
        thread with :func:`~semiparam_ros.core.checkpoint.atomic_save_npz`, so learning never waits for disk.

        A checkpoint is self-contained: besides the learned state (``model.*``), the noise estimate behind
        σ (``noise.*``) and the contact gate's state (``gate.*``: its warm-up over, its counts; so neither
        σ nor the gate warms up again after a restart) it holds the whole configuration (``meta.config``,
        JSON), the URDF text (``meta.urdf``), the robot's identity (``meta.robot``: its name and CAD base
        parameters) and the versions that wrote it (``meta.versions``), so
        :func:`semiparam_ros.load_model` needs nothing else.

        Returns:
            Checkpoint arrays by key (``model.*`` learned state, ``noise.*``, ``meta.*``).
        """
        state = {key: np.array(value, copy=True) for key, value in self.model.state_dict("model.").items()}
        state.update(self.noise.state_dict("noise."))
        if self.calibration is not None:
            state.update(self.calibration.state_dict("calibration."))
        if self.stick is not None:
            state.update(self.stick.state_dict("stick."))
        state.update(self.gate.state_dict("gate."))
        if self.payload is not None:
            state.update(self.payload.state_dict("payload."))
        state.update(meta_arrays(self.config, self.kind, self.regressor, self.n_samples_learned,
                                 self.sample_period_s))
        return state

    def load(self, path: str | Path) -> None:
        """Restore the learned state written by :meth:`save`.

        Args:
            path: Checkpoint file.

        Raises:
            CheckpointError: If the file is missing or corrupt, was written for another model structure
                (joints, output, features…) or another robot (URDF name or CAD inertial parameters); the
                current state is then left untouched.
        """
        self.load_state(load_npz(Path(path).expanduser()), path)

    def _fresh_state(self) -> dict[str, np.ndarray]:
        """Return the checkpoint arrays of a new estimator of this configuration (a migration fills in)."""
        return OnlineEstimator(self.config, regressor=self.regressor, kind=self.kind).checkpoint_state()

    def load_state(self, state: dict[str, np.ndarray], path: str | Path = "checkpoint") -> None:
        """Restore the learned state from the arrays of a checkpoint already read (see :meth:`load`).

        Args:
            state: Checkpoint arrays (:func:`~semiparam_ros.core.checkpoint.load_npz`).
            path: Where they came from, for messages.

        Raises:
            CheckpointError: As :meth:`load`.
        """
        state, notes = migrate(state, read_version(state, path), CHECKPOINT_VERSION, self._fresh_state, path)
        n_learned = read_meta(state, path, self.config, self.kind, self.regressor)
        model = self.model.copy()
        noise = NoiseScale(self.model.n_outputs, self.noise.time_constant_s)
        gate = ContactGate(self.gate.config)
        calibration = _calibration(self.config, self.model.n_outputs)
        stick = _stick(self.config)
        payload = None
        try:
            model.load_state_dict(state, "model.")
            noise.load_state_dict(state, "noise.")
            if calibration is not None and "calibration.weights" in state:
                calibration.load_state_dict(state, "calibration.")
            if stick is not None and "stick.a" in state:
                stick.load_state_dict(state, "stick.")
            gate.load_state_dict(state, "gate.")
            if "payload.reference" in state:  # a tare was made
                payload = PayloadLearner.from_state_dict(self.regressor, state, "payload.")
        except CheckpointError as err:
            raise CheckpointError(f"{path}: {err}") from err
        except (TypeError, KeyError, IndexError, OverflowError, ValueError) as err:
            # e.g. a counter stored as a vector: the learners' checks expect scalars; still a bad file
            raise CheckpointError(f"{path}: corrupt checkpoint: {type(err).__name__}: {err}") from err
        check_magnitudes(path, state)
        try:  # a probe: a state that loads but cannot predict would refuse every sample afterwards
            probe = model.predict_one(np.zeros(3 * self._n_joints))
            finite = bool(np.isfinite(probe.total).all())
        except RejectedSampleError:
            finite = False
        if not finite:
            raise CheckpointError(f"{path}: corrupt checkpoint: its model's prediction at q = q̇ = q̈ = 0 is "
                                  "not finite")
        saved_period = read_period(state, path)
        if self.sample_period_s is not None:  # the restored learner takes the stream's period too
            model.on_period(self.sample_period_s)
        elif saved_period is not None:  # else the period it learned at (measured again once data come)
            model.on_period(saved_period)
        self.model = model
        self.traits = traits_of(model)
        self.migration_notes = notes
        self.noise = noise
        self.calibration = calibration
        self.stick = stick
        self.gate = gate
        self.payload = payload
        self.n_samples_learned = n_learned


def _calibration(config: EstimatorConfig, n_outputs: int) -> FrozenCalibration | None:
    """Return the served σ's calibration of a configuration (None with a block of 0: the one-step σ)."""
    block = float(config["uncertainty.calibration_block"])
    if block <= 0.0:
        return None
    return FrozenCalibration(n_outputs, len(config["robot.joints"]), block,
                             config["uncertainty.noise_time_constant"])


def _stick(config: EstimatorConfig) -> StickFriction | None:
    """Return the stick friction of a configuration (joint torques with a displacement > 0, else None)."""
    displacement = float(config["parametric.stick_displacement"])
    if config.output_kind != OutputKind.JOINT_TORQUES or displacement <= 0.0:
        return None
    memory = float(config["adaptation.time_constant"])
    return StickFriction(len(config["robot.joints"]), displacement, config["parametric.coulomb_velocity"],
                         memory if memory > 0.0 else 20.0)


def _learned_rigid(model: Model, ahead: PredictionContext) -> np.ndarray:
    """Return the learned rigid body Φ(x) π̂ at a context's state (NP: its whole prediction)."""
    par = rigid_body_part(model)
    if par is None or ahead.Phi is None:
        return np.asarray(ahead.prediction.total)
    return np.asarray(ahead.Phi @ par.parameters)
