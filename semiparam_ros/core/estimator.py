"""The online estimator: one configuration → regressor, sample pipeline and learners.

This is the single data path shared by the live node and offline replay: messages go through
:class:`~semiparam_ros.core.pipeline.SamplePipeline` (joint mapping, stamp pairing, acceleration
estimate, drops counted by reason) and every paired sample goes through :meth:`OnlineEstimator.step`,
which first predicts (a priori: the prediction never saw its own label) and then learns — the
rigid-body stage first, then the residual. The same bag therefore gives the same numbers whichever way it
is fed.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from semiparam_ros.core._step_kernels import joined_within
from semiparam_ros.core.acceleration import AccelerationConfig
from semiparam_ros.core.adaptation import forgetting_factor, learners
from semiparam_ros.core.checkpoint import atomic_save_npz, load_npz
from semiparam_ros.core.config import EstimatorConfig, structural_values
from semiparam_ros.core.dynamics import RigidBodyRegressor
from semiparam_ros.core.gate import ContactGate, GateConfig, Verdict
from semiparam_ros.core.messages import JointStateData, Sample, WrenchData
from semiparam_ros.core.payload import PayloadLearner
from semiparam_ros.core.pipeline import SamplePipeline
from semiparam_ros.core.rate import RATE_SAMPLES, RateMeter, measured_period_s, samples_in
from semiparam_ros.core.semiparametric import (
    NonparametricModel,
    ParametricModel,
    Prediction,
    SemiparametricModel,
    rigid_body_part,
)
from semiparam_ros.core.semiparametric_consistent import ConsistentSemiparametricModel
from semiparam_ros.core.semiparametric_joint import JointSemiparametricModel
from semiparam_ros.core.uncertainty import NoiseScale
from semiparam_ros.core.urdf import RegressorSpec
from semiparam_ros.core.validation import MAX_ABS_INPUT
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError

__all__ = [
    "DROP_REJECTED_SAMPLE",
    "NOMINAL_PERIOD_S",
    "NOT_LEARNED_GATED_CONTACT",
    "RATE_SAMPLES",
    "ModelKind",
    "OnlineEstimator",
    "StepResult",
    "build_model",
    "build_pipeline",
    "build_regressor",
    "column_scale",
    "measured_period_s",
    "parametric_prior",
    "regressor_function",
    "rmse_window_samples",
    "samples_in",
    "standardizer_min_scale",
    "standardizer_warmup_samples",
]

ModelKind = Literal["P", "NP", "SP"]
Model = (ParametricModel | NonparametricModel | SemiparametricModel | JointSemiparametricModel
         | ConsistentSemiparametricModel)

DROP_REJECTED_SAMPLE = "rejected_sample"
"""Key of :attr:`OnlineEstimator.drops`: a paired sample the learner refused (values beyond its input
bound or a regressor overflow), typically after a finite but absurd joint state passed the pipeline."""

NOT_LEARNED_GATED_CONTACT = "gated_contact"
"""Key of :attr:`OnlineEstimator.not_learned`: a sample predicted but not learned because its residual
was implausibly large for less than ``gate.max_contact_duration`` (see :mod:`semiparam_ros.core.gate`);
not an input drop."""

_CHECKPOINT_VERSION = 1
# Parameters that fix the shape or meaning of the learned state: a checkpoint is only loaded when these
# match. The learners' hyperparameters are part of it: λ is baked into the factor (RᵀR = λI + ΦᵀΦ), and a
# loaded RecursiveRLS/Standardizer keeps the checkpoint's λ, β and warm-up (even through reset()), so
# accepting a checkpoint written with other values would silently run those while the configuration
# says otherwise. Run-time switches (learning_enabled, checkpoint.*, diagnostics.*) may change.


def build_regressor(config: EstimatorConfig, urdf_xml: str | None = None,
                    source: str = "the checkpoint's URDF") -> RigidBodyRegressor:
    """Build the rigid-body regressor described by a configuration.

    With ``robot.output: joint_torques``, ``parametric.friction`` / ``offsets`` / ``armature`` append the
    per-joint friction, offset and armature columns (see :mod:`semiparam_ros.core.dynamics`); with
    ``wrench``, ``parametric.sensor_offset`` appends the six sensor offsets.

    Args:
        config: Estimator configuration (``robot.*`` and ``parametric.*``).
        urdf_xml: URDF text to use instead of the file ``robot.urdf`` names (a checkpoint's own copy, or
            what a robot_description topic published).
        source: Where ``urdf_xml`` came from, for messages.

    Returns:
        The regressor of the F/T sensor wrench or of the joint torques.

    Raises:
        FileNotFoundError: If ``robot.urdf`` names no file (and no ``urdf_xml`` is given).
        ConfigurationError: If the URDF, joints or sensor are invalid.
    """
    output = config["robot.output"]
    if urdf_xml is None:
        path = config.urdf_path()
        if not path.is_file():
            raise FileNotFoundError(f"URDF file not found: {path}")
        urdf_xml, source = path.read_text(encoding="utf-8"), str(path)
    spec = RegressorSpec(
        tuple(config["robot.joints"]),
        ft_sensor=config["robot.ft_sensor"] if output == "wrench" else None,
        locked=config.locked,
        gravity=tuple(config["robot.gravity"]),
        output=output,
        sensor_offset=bool(config["parametric.sensor_offset"]) and output == "wrench",
        friction=bool(config["parametric.friction"]) and output == "joint_torques",
        coulomb_velocity=config["parametric.coulomb_velocity"],
        joint_offsets=bool(config["parametric.offsets"]) and output == "joint_torques",
        armature=bool(config["parametric.armature"]) and output == "joint_torques",
    )
    return RigidBodyRegressor(urdf_xml, spec, source=source)


def regressor_function(regressor: RigidBodyRegressor,
                       scale: np.ndarray | None = None) -> Callable[[np.ndarray], np.ndarray]:
    """Adapt a regressor to the learners' flat input ``x = [q, dq, ddq]``.

    Args:
        regressor: Rigid-body regressor of n joints.
        scale: Optional column scales ``c`` (n_base,): the function then returns ``Φ_b diag(1/c)``, the
            regressor of the scaled parameters ``θ = c ⊙ π_b`` (see :func:`column_scale`).

    Returns:
        A function mapping x (3n,) to the base regressor (t × n_base), scaled if asked.
    """
    inv = None if scale is None else 1.0 / np.asarray(scale, dtype=np.float64)

    def base_regressor(x: np.ndarray) -> np.ndarray:
        # the learners pass a checked (3n,) float64 x; equal bit for bit to base_regressor(q, dq, ddq) / c
        return regressor.base_regressor_of_input(x, inv)

    return base_regressor


def column_scale(config: EstimatorConfig, regressor: RigidBodyRegressor) -> np.ndarray:
    """Characteristic magnitude ``c_j`` of each base-regressor column (ones without column scaling).

    With ``parametric.column_scaling`` the learners see ``Φ_b diag(1/c)`` and learn ``θ = c ⊙ π_b``, where
    ``c_j`` is the RMS of column j over the random states of the base-parameter search (q within the
    limits, |q̇| ≤ 1.5 rad/s, |q̈| ≤ 10 rad/s²; :attr:`BaseParameterMap.column_rms`). ``θ_j`` is then
    parameter j's typical contribution to y (N, N·m): the ridge ``λ‖θ − θ₀‖²`` penalizes every parameter
    by the output it explains, so one λ means the same for a link mass (kg), an inertia (kg·m²), a viscous
    coefficient (N·m·s/rad) and an offset (N·m), on any robot. ``π_b = θ / c``.

    Args:
        config: Estimator configuration (``parametric.column_scaling``).
        regressor: The rigid-body regressor.

    Returns:
        (n_base,) positive scales (units of y per unit of the parameter).
    """
    rms = regressor.base.column_rms
    if not config["parametric.column_scaling"] or rms is None:
        return np.ones(regressor.n_base)
    return np.asarray(rms, dtype=np.float64).copy()


def parametric_prior(config: EstimatorConfig, regressor: RigidBodyRegressor) -> np.ndarray:
    """Return the base parameters the rigid-body stage is regularized toward, in unscaled units.

    Args:
        config: Estimator configuration (``parametric.prior``).
        regressor: The rigid-body regressor.

    Returns:
        (n_base,): ``'urdf'`` the URDF's base parameters (zero for sensor offsets, friction, joint offsets
        and armature), so that before any data the prediction is RNEA with the URDF's inertias;
        ``'zero'`` zeros (the paper's protocol).
    """
    if config["parametric.prior"] == "zero":
        return np.zeros(regressor.n_base)
    return regressor.to_base(regressor.urdf_parameters())


def build_pipeline(config: EstimatorConfig) -> SamplePipeline:
    """Build the message-to-sample pipeline described by a configuration.

    Args:
        config: Estimator configuration (``robot.*``, ``sync.*``, ``acceleration.*``, ``limits.*``); a
            zero ``acceleration.max_gap_s`` or ``limits.*`` means "never restart" / "no bound".

    Returns:
        A fresh pipeline.
    """

    def bound(name: str) -> float | None:
        return config[name] or None

    return SamplePipeline(
        config["robot.joints"],
        output=config["robot.output"],
        frame_id=config["robot.frame_id"] or None,
        sync_tolerance=config["sync.tolerance"],
        acceleration=AccelerationConfig(
            method=config["acceleration.method"],
            window=config["acceleration.window"] or 9,
            window_s=None if config["acceleration.window"] else config["acceleration.window_s"],
            polyorder=config["acceleration.polyorder"],
            cutoff_hz=config["acceleration.cutoff_hz"],
            bandwidth_hz=config["acceleration.bandwidth_hz"],
            kalman_model=config["acceleration.kalman_model"],
            max_gap_s=bound("acceleration.max_gap_s"),
        ),
        max_abs_position=bound("limits.max_abs_position"),
        max_abs_velocity=bound("limits.max_abs_velocity"),
        max_abs_output=bound("limits.max_abs_output"),
        glitch_ratio=config["limits.glitch_ratio"],
        glitch_time_constant=config["limits.glitch_time_constant"],
    )


def standardizer_min_scale(config: EstimatorConfig, *, with_outputs: bool) -> np.ndarray:
    """Floors of the residual stage's standardization scales, in the units of its inputs.

    Args:
        config: Estimator configuration (``nonparametric.min_scale.*``, ``robot.*``).
        with_outputs: Append the ŷ block (SP's residual input ``[x, ŷ]``) to the x block.

    Returns:
        One floor per input: q [rad], q̇ [rad/s], q̈ [rad/s²] per joint, then forces [N] and torques
        [N·m] of a wrench (``min_scale.force``/``torque``), or joint torques [N·m] per joint
        (``min_scale.joint_torque``: the wrench floors never apply to joint torques).
    """
    n = len(config["robot.joints"])
    floors = [np.full(n, config[f"nonparametric.min_scale.{name}"])
              for name in ("position", "velocity", "acceleration")]
    if with_outputs:
        if config["robot.output"] == "wrench":
            floors += [np.full(3, config["nonparametric.min_scale.force"]),
                       np.full(3, config["nonparametric.min_scale.torque"])]
        else:
            floors.append(np.full(n, config["nonparametric.min_scale.joint_torque"]))
    return np.concatenate(floors)


#: Sample period [s] at which seconds-based lengths are converted before the rate is measured (100 Hz: the
#: rate at which the former sample-count defaults were chosen).
NOMINAL_PERIOD_S = 0.01
#: ``semiparametric.*`` parameters of the consistent SP, named as its constructor's keywords.
_CONSISTENT_KEYS = ("novelty_scale", "tracker", "tracker_position_scale", "tracker_velocity_scale",
                    "tracker_samples", "tracker_time_constant")


def standardizer_warmup_samples(config: EstimatorConfig, sample_period_s: float | None = None) -> int:
    """Length of the residual stage's standardizer warm-up [samples].

    Args:
        config: ``nonparametric.standardizer_warmup`` (samples; wins when > 0) or
            ``nonparametric.standardizer_warmup_s`` [s].
        sample_period_s: Measured sample period [s]; ``None``: :data:`NOMINAL_PERIOD_S` (provisional, until
            :class:`OnlineEstimator` has measured it).

    Returns:
        The warm-up length, ≥ 1.
    """
    if config["nonparametric.standardizer_warmup"]:
        return int(config["nonparametric.standardizer_warmup"])
    return samples_in(config["nonparametric.standardizer_warmup_s"], sample_period_s or NOMINAL_PERIOD_S)


def rmse_window_samples(config: EstimatorConfig, sample_period_s: float | None = None) -> int:
    """Length of the diagnostics' running RMSE window [samples].

    Args:
        config: ``diagnostics.rmse_window`` (samples; wins when > 0) or ``diagnostics.rmse_window_s`` [s].
        sample_period_s: Measured sample period [s]; ``None``: :data:`NOMINAL_PERIOD_S`.

    Returns:
        The window length, ≥ 1.
    """
    if config["diagnostics.rmse_window"]:
        return int(config["diagnostics.rmse_window"])
    return samples_in(config["diagnostics.rmse_window_s"], sample_period_s or NOMINAL_PERIOD_S)


def build_model(config: EstimatorConfig, kind: ModelKind = "SP",
                regressor: RigidBodyRegressor | None = None, *,
                sample_period_s: float | None = None) -> Model:
    """Build one of the paper's three learners.

    The rigid-body stage works on the scaled base parameters ``θ = c ⊙ π_b`` (:func:`column_scale`) and
    starts from (and is regularized toward) :func:`parametric_prior`; its ``parameters`` are θ̂ (divide by
    :func:`column_scale` for π̂_b, as :attr:`OnlineEstimator.parameters` does).

    Args:
        config: Estimator configuration (``parametric.*``, ``nonparametric.*``, ``adaptation.*``).
        kind: ``"P"`` (rigid-body RRLS), ``"NP"`` (random features RRLS) or ``"SP"`` (both; the paper's
            cascade or the joint fit, by ``semiparametric.combination``).
        regressor: Rigid-body regressor to use; built from the configuration when omitted.
        sample_period_s: The stream's sample period [s], when known (offline tools). With
            ``adaptation.time_constant`` τ > 0 both stages then forget with β = exp(−T/τ) instead of the
            configured per-sample factors, and a warm-up given in seconds is converted at it
            (:func:`standardizer_warmup_samples`). ``None``: the configured β, and the warm-up provisionally
            at 100 Hz (:class:`OnlineEstimator` measures T itself and sets both later).

    Returns:
        The learner.

    Raises:
        ConfigurationError: On an unknown kind.
    """
    if kind not in ("P", "NP", "SP"):
        raise ConfigurationError(f"model kind must be 'P', 'NP' or 'SP', got {kind!r}")
    model = _build_model(config, kind, regressor)
    if sample_period_s is not None:
        apply_sample_period(model, config, sample_period_s)
    return model


def apply_sample_period(model: Model, config: EstimatorConfig, sample_period_s: float) -> float | None:
    """Convert what the configuration gives in seconds for a learner, at the measured sample period.

    The one route by which the rate reaches a learner, online (:class:`OnlineEstimator`, once its
    :class:`~semiparam_ros.core.rate.RateMeter` has measured the period) and offline (:func:`build_model`
    with ``sample_period_s``): the standardizer warm-up given in seconds becomes samples
    (:func:`standardizer_warmup_samples`, if it is still running), the consistent model's fast correction
    takes its memory ``semiparametric.tracker_time_constant``, and with ``adaptation.time_constant`` τ > 0
    every learner (the slow ones) forgets with β = exp(−T/τ).

    Args:
        model: A learner (not yet past its warm-up for the warm-up to change).
        config: Its configuration.
        sample_period_s: The measured period T [s].

    Returns:
        β if the time constant set it, else ``None``.
    """
    if not config["nonparametric.standardizer_warmup"]:
        model.set_standardizer_warmup(standardizer_warmup_samples(config, sample_period_s))
    if isinstance(model, ConsistentSemiparametricModel):
        model.set_sample_period(sample_period_s)  # the fast correction's memory in seconds
    tau = float(config["adaptation.time_constant"])
    if tau <= 0.0:
        return None
    beta = forgetting_factor(tau, sample_period_s)
    for rls in learners(model):
        rls.set_forgetting(beta)
    return beta


def _build_model(config: EstimatorConfig, kind: ModelKind,
                 regressor: RigidBodyRegressor | None) -> Model:
    """Build the learner of ``kind`` with the configured per-sample factors and the provisional warm-up."""
    n_joints = len(config["robot.joints"])
    n_inputs = 3 * n_joints
    warmup = standardizer_warmup_samples(config, None)
    if kind == "NP":
        n_outputs = 6 if config["robot.output"] == "wrench" else n_joints
        return NonparametricModel(
            n_inputs,
            n_outputs,
            n_features=config["nonparametric.n_features"],
            sigma=config["nonparametric.sigma"],
            lam=config["nonparametric.lam"],
            forgetting=config["nonparametric.forgetting"],
            seed=config["nonparametric.seed"],
            standardizer_warmup=warmup,
            standardizer_min_scale=standardizer_min_scale(config, with_outputs=False),
        )
    regressor = regressor if regressor is not None else build_regressor(config)
    scale = column_scale(config, regressor)
    phi = regressor_function(regressor, scale if config["parametric.column_scaling"] else None)
    prior = scale * parametric_prior(config, regressor)
    if kind == "P":
        return ParametricModel(
            phi,
            regressor.n_base,
            regressor.n_outputs,
            lam=config["parametric.lam"],
            forgetting=config["parametric.forgetting"],
            prior=prior,
        )
    shared = dict(
        lam_parametric=config["parametric.lam"],
        lam_nonparametric=config["nonparametric.lam"],
        n_features=config["nonparametric.n_features"],
        sigma=config["nonparametric.sigma"],
        seed=config["nonparametric.seed"],
        standardizer_warmup=warmup,
    )
    if config["semiparametric.combination"] == "joint":
        # the configuration guarantees equal forgetting factors for the joint fit
        return JointSemiparametricModel(
            phi, regressor.n_base, n_inputs, regressor.n_outputs, **shared,
            forgetting=config["parametric.forgetting"],
            standardizer_min_scale=standardizer_min_scale(config, with_outputs=False),
            prior=prior,
        )
    # the rigid-body stage first and alone, each stage with its own forgetting: the cascade and the
    # consistent model
    two_stage = dict(forgetting_parametric=config["parametric.forgetting"],
                     forgetting_nonparametric=config["nonparametric.forgetting"], prior=prior)
    if config["semiparametric.combination"] == "consistent":
        return ConsistentSemiparametricModel(
            phi, regressor.n_base, n_inputs, regressor.n_outputs, **shared, **two_stage,
            standardizer_min_scale=standardizer_min_scale(config, with_outputs=False),
            # the constructor's keywords are the parameters' names
            **{name: config[f"semiparametric.{name}"] for name in _CONSISTENT_KEYS},
            sample_period_s=NOMINAL_PERIOD_S,
        )
    return SemiparametricModel(
        phi, regressor.n_base, n_inputs, regressor.n_outputs, **shared, **two_stage,
        standardizer_min_scale=standardizer_min_scale(config, with_outputs=True),
    )

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
        >>> from semiparam_ros.core.config import EstimatorConfig
        >>> est = OnlineEstimator(EstimatorConfig.defaults())  # iCub right arm, F/T sensor wrench
        >>> est.regressor.n_base
        17
        >>> est.process_joint_state(JointStateData(10**9, ("r_elbow",), [0.1]))  # joints missing
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
        self._scale = column_scale(config, self.regressor)
        self.learning_enabled = bool(config["learning_enabled"])
        self._n_joints = len(config["robot.joints"])
        self.n_samples_learned = 0
        #: Samples predicted without learning because the caller fell behind (``skip_learning``).
        self.n_learning_skipped = 0
        #: The payload learner since the last :meth:`tare_payload` (None before one).
        self.payload: PayloadLearner | None = None
        self._rejected = 0
        self.noise = NoiseScale(self.model.n_outputs, config["uncertainty.noise_time_constant"])
        self.gate = ContactGate(_gate_config(config))
        self.gate_enabled = bool(config["gate.enabled"])
        self.forgetting: float | None = None  # β from adaptation.time_constant, once the rate is measured
        #: Sample period [s] measured from the first :data:`RATE_SAMPLES` samples (None until then).
        self.sample_period_s: float | None = None
        self._rate = RateMeter()  # the rule of offline replay's measured_period_s(stamps)

    # ------------------------------------------------------------------ streaming
    def process_joint_state(self, msg: JointStateData, *, skip_learning: bool = False) -> list[StepResult]:
        """Feed a joint state; return the results of the samples it completed (often none or one).

        Never raises on bad data: the pipeline drops and counts bad messages, and a sample the learner
        rejects (:class:`~semiparam_ros.errors.RejectedSampleError`) is counted under ``rejected_sample``
        in :attr:`drops` (the learned state is unchanged). Any other exception is a programming error: it
        propagates and no drop is counted.

        Args:
            msg: The joint state.
            skip_learning: Predict the completed samples cheaply without learning them (see :meth:`step`).
        """
        return self._step_all(self.pipeline.add_joint_state(msg), skip_learning)

    def process_wrench(self, msg: WrenchData, *, skip_learning: bool = False) -> list[StepResult]:
        """Feed an F/T reading; return the results of the samples it completed (never raises on bad data)."""
        return self._step_all(self.pipeline.add_wrench(msg), skip_learning)

    def _step_all(self, samples: list[Sample], skip_learning: bool = False) -> list[StepResult]:
        # The pipeline drops NaN/inf and values beyond limits.*, but those bounds can be switched off (0)
        # or be loose: a finite but absurd value (e.g. a velocity of 1e200 rad/s) then poisons the q̈
        # window, and the learners refuse those samples with a RejectedSampleError (state untouched).
        # Streaming counts that as a drop rather than abort the message and lose the other samples it
        # completed. Any other exception is a bug and propagates, with the counters untouched.
        results: list[StepResult] = []
        for sample in samples:
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
        :attr:`n_learning_skipped`.

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
        start = time.perf_counter()
        x, y = self._check_sample(sample)
        model = self.model
        if skip_learning and self.learning_enabled:
            prediction = model.predict_held(x)
            assert prediction.variance is not None  # a held prediction carries it
            std = self.noise.std(prediction.variance)
            self.noise.skip(sample.stamp_ns)
            self.n_learning_skipped += 1
            return StepResult(sample, prediction, time.perf_counter() - start, False, std, None)
        # a priori, with the relative variance v = z A⁻¹ zᵀ of each output (the state is not changed)
        ahead = model.predict_ahead_checked(x)
        prediction = ahead.prediction
        variance = prediction.variance
        assert variance is not None  # a context always carries it
        verdict = None
        if self.learning_enabled and self.gate_enabled:
            error = y - prediction.total
            std = self.noise.std(variance)
            verdict = self.gate.decide(sample.stamp_ns, error, std, float(variance.max()))
            learned = verdict.learn
            if learned:
                model.learn_ahead_checked(ahead, y)
                self.n_samples_learned += 1
        else:
            # gate off: exactly the paper's predict-then-learn (bit-identical predictions)
            learned = self.learning_enabled
            if learned:
                prediction = model.predict_learn_one(x, y)
                self.n_samples_learned += 1
            std = self.noise.std(variance)
            error = y - prediction.total
        if learned and self.payload is not None:
            self.payload.update(sample.q, sample.dq, sample.ddq, y)
        if learned or verdict is None:
            # σ is the model's: a fast correction of the recent error (the consistent SP's) makes one-step
            # errors far smaller than those of a model that stops learning, e.g. through a contact
            correction = prediction.correction
            self.noise.update(sample.stamp_ns, error if correction is None else error + correction, variance)
        else:
            self.noise.skip(sample.stamp_ns)
        return StepResult(sample, prediction, time.perf_counter() - start, learned, std, verdict)

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
        :mod:`semiparam_ros.core.payload`). Tare before a pickup, with nothing carried.

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

    def _apply_forgetting(self, beta: float) -> None:
        for rls in learners(self.model):
            rls.set_forgetting(beta)
        self.forgetting = beta

    def apply_runtime_parameters(self, config: EstimatorConfig) -> None:
        """Take the run-time gate and noise parameters (``gate.*``, ``uncertainty.*``) of a configuration.

        Args:
            config: A validated configuration (only its run-time gate/uncertainty entries are read).

        Raises:
            ValueError: On an invalid gate parameter (nothing is changed then).
        """
        gate_config = _gate_config(config)
        self.noise.set_time_constant(config["uncertainty.noise_time_constant"])
        self.gate.config = gate_config
        self.gate_enabled = bool(config["gate.enabled"])

    def _measure_rate(self, stamp_ns: int) -> None:
        """Feed the rate meter; once the period is known, convert what is given in seconds.

        The seconds-based warm-up becomes samples, and with ``adaptation.time_constant`` τ > 0 every
        learner forgets with β = exp(−T/τ) from then on (:func:`apply_sample_period`, as offline).
        """
        period = self._rate.add(stamp_ns)
        if period is None:
            return
        self.sample_period_s = period
        beta = apply_sample_period(self.model, self.config, period)
        if beta is not None:
            self.forgetting = beta

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

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget everything learned and restart the pipeline (configuration kept)."""
        self.model.reset()
        self.pipeline.reset()
        self.n_samples_learned = 0
        self.n_learning_skipped = 0
        self.payload = None
        self._rejected = 0
        self.noise.reset()
        self.gate.reset()

    def _fingerprint(self) -> str:
        # the parameters the parameter table flags as structural (core.config.structural_values), the
        # learner kind and the base parameters (friction, offsets and armature show in their names)
        structure = structural_values(self.config, self.kind)
        structure["kind"] = self.kind
        structure["base_parameters"] = list(self.parameter_names)
        return json.dumps(structure, sort_keys=True)

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
        state.update(self.gate.state_dict("gate."))
        if self.payload is not None:
            state.update(self.payload.state_dict("payload."))
        state["meta.version"] = np.array(_CHECKPOINT_VERSION)
        state["meta.fingerprint"] = np.array(self._fingerprint())
        state["meta.n_samples_learned"] = np.array(self.n_samples_learned)
        state["meta.config"] = np.array(json.dumps(self.config.to_flat(), sort_keys=True))
        state["meta.urdf"] = np.array(self.regressor.urdf_xml)
        state["meta.robot"] = np.array(json.dumps(self._robot_identity(), sort_keys=True))
        state["meta.versions"] = np.array(json.dumps(software_versions(), sort_keys=True))
        state["meta.sample_period_s"] = np.array(
            np.nan if self.sample_period_s is None else self.sample_period_s)
        return state

    def _robot_identity(self) -> dict[str, Any]:
        """Return the robot a checkpoint is learned on: URDF robot name and CAD base parameters (rounded)."""
        reg = self.regressor
        cad = reg.to_base(reg.urdf_parameters())
        return {"name": reg.robot_name, "cad_base_parameters": [float(f"{v:.9g}") for v in cad]}

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

    def load_state(self, state: dict[str, np.ndarray], path: str | Path = "checkpoint") -> None:
        """Restore the learned state from the arrays of a checkpoint already read (see :meth:`load`).

        Args:
            state: Checkpoint arrays (:func:`~semiparam_ros.core.checkpoint.load_npz`).
            path: Where they came from, for messages.

        Raises:
            CheckpointError: As :meth:`load`.
        """
        try:
            version = _scalar(state["meta.version"], int)
            fingerprint = _scalar(state["meta.fingerprint"], str)
            n_learned = _scalar(state["meta.n_samples_learned"], int)
        except KeyError as err:
            raise CheckpointError(f"{path}: not a semiparam_ros checkpoint (missing {err})") from err
        except (TypeError, ValueError) as err:
            raise CheckpointError(f"{path}: corrupt checkpoint metadata: {err}") from err
        if version != _CHECKPOINT_VERSION:
            raise CheckpointError(f"{path}: checkpoint version {version}, expected {_CHECKPOINT_VERSION}")
        if fingerprint != self._fingerprint():
            raise CheckpointError(f"{path}: checkpoint was written for another model structure: "
                                  f"{_fingerprint_difference(fingerprint, self._fingerprint())}")
        if n_learned < 0:
            raise CheckpointError(f"{path}: corrupt checkpoint: {n_learned} samples learned")
        if "meta.robot" in state:  # checkpoints written before they were self-contained have none
            self._check_robot(path, state["meta.robot"])
        model = self.model.copy()
        noise = NoiseScale(self.model.n_outputs, self.noise.time_constant_s)
        gate = ContactGate(self.gate.config)
        payload = None
        try:
            model.load_state_dict(state, "model.")
            if "noise.s2" in state:  # checkpoints written before they carried σ and the gate have neither
                noise.load_state_dict(state, "noise.")
            if "gate.warm" in state:
                gate.load_state_dict(state, "gate.")
            if "payload.reference" in state:  # a tare was made
                payload = PayloadLearner.from_state_dict(self.regressor, state, "payload.")
        except CheckpointError as err:
            raise CheckpointError(f"{path}: {err}") from err
        except (TypeError, KeyError, IndexError, OverflowError, ValueError) as err:
            # e.g. a counter stored as a vector: the learners' checks expect scalars; still a bad file
            raise CheckpointError(f"{path}: corrupt checkpoint: {type(err).__name__}: {err}") from err
        _check_magnitudes(path, state)
        try:  # a probe: a state that loads but cannot predict would refuse every sample afterwards
            probe = model.predict_one(np.zeros(3 * self._n_joints))
            finite = bool(np.isfinite(probe.total).all())
        except RejectedSampleError:
            finite = False
        if not finite:
            raise CheckpointError(f"{path}: corrupt checkpoint: its model's prediction at q = q̇ = q̈ = 0 is "
                                  "not finite")
        self.model = model
        self.noise = noise
        self.gate = gate
        self.payload = payload
        self.n_samples_learned = n_learned
        if self.forgetting is not None:
            self._apply_forgetting(self.forgetting)

    def _check_robot(self, path: str | Path, saved: np.ndarray) -> None:
        """Refuse a checkpoint learned on another robot (other URDF name or CAD inertial parameters)."""
        try:
            identity = json.loads(_scalar(saved, str))
            name, cad = identity["name"], np.asarray(identity["cad_base_parameters"], dtype=np.float64)
        except (TypeError, ValueError, KeyError) as err:
            raise CheckpointError(f"{path}: corrupt checkpoint metadata meta.robot: {err}") from err
        mine = self._robot_identity()
        ours = np.asarray(mine["cad_base_parameters"])
        if name != mine["name"]:
            raise CheckpointError(f"{path}: checkpoint was learned on robot {name!r}, this configuration's "
                                  f"URDF describes {mine['name']!r}")
        if cad.shape != ours.shape or not np.allclose(cad, ours, rtol=1e-6, atol=1e-9):
            raise CheckpointError(f"{path}: checkpoint was learned on a URDF of {name!r} with other inertial "
                                  "parameters (its CAD prior differs from this configuration's URDF); use "
                                  "the URDF it was learned with, or start afresh")


def software_versions() -> dict[str, str]:
    """Versions of the software a checkpoint is written with (semiparam_ros, Python, NumPy, Pinocchio)."""
    import platform

    import pinocchio

    from semiparam_ros.version import __version__

    return {"semiparam_ros": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "pinocchio": str(pinocchio.__version__)}


def _check_magnitudes(path: str | Path, state: dict[str, np.ndarray]) -> None:
    """Refuse a checkpoint whose learned numbers are NaN, inf or beyond ±MAX_ABS_INPUT.

    Raises:
        CheckpointError: Naming the first such array.
    """
    for key, value in state.items():
        arr = np.asarray(value)
        if key.startswith(("model.", "noise.")) and arr.dtype.kind == "f" and arr.size:
            if not np.abs(arr).max() <= MAX_ABS_INPUT:
                raise CheckpointError(f"{path}: corrupt checkpoint: {key} holds NaN, inf or values beyond "
                                      f"{MAX_ABS_INPUT:g}")


def _gate_config(config: EstimatorConfig) -> GateConfig:
    return GateConfig(threshold=config["gate.threshold"],
                      max_contact_duration_s=config["gate.max_contact_duration"],
                      warmup_s=config["gate.warmup"], novelty=config["gate.novelty"])


def _scalar(value: np.ndarray, kind: type[int] | type[str]) -> Any:
    """Read a 0-d array of a checkpoint as an int or a str.

    Raises:
        ValueError: If the array is not 0-d or not of that kind.
    """
    arr = np.asarray(value)
    if arr.ndim != 0:
        raise ValueError(f"expected a scalar, got an array of shape {arr.shape}")
    if kind is int:
        if arr.dtype.kind not in "iu":
            raise ValueError(f"expected an integer, got dtype {arr.dtype}")
        return int(arr)
    if arr.dtype.kind != "U":
        raise ValueError(f"expected a string, got dtype {arr.dtype}")
    return str(arr)


def _fingerprint_difference(saved: str, current: str) -> str:
    """Name the entries that differ between two fingerprints (for the error message)."""
    try:
        a, b = json.loads(saved), json.loads(current)
    except ValueError:
        return f"unreadable fingerprint {saved!r}"
    if not isinstance(a, dict):
        return f"unreadable fingerprint {saved!r}"
    names = sorted(set(a) | set(b))
    text = "; ".join(f"{k} = {a.get(k)!r} in the checkpoint, {b.get(k)!r} now" for k in names
                     if a.get(k) != b.get(k))
    key = "semiparametric.combination"
    if "kind" in a and a.get(key) is None and b.get(key) not in (None, "cascade"):
        # a fingerprint without the key was written by the paper's cascade, the default until the
        # consistent learner became it
        text += (f" (a checkpoint without {key} holds the paper's cascade: set {key}: cascade to load "
                 "it, or start the new default learner afresh)")
    return text
