"""Build the estimator's parts from a configuration: regressor, sample pipeline and learners.

One configuration gives one rigid-body regressor (:func:`build_regressor`, Pinocchio from the URDF), one
message-to-sample pipeline (:func:`build_pipeline`) and one learner (:func:`build_model`: ``P``, ``NP`` or
``SP`` in the configured combination). Lengths the configuration gives in seconds are converted at the
measured sample period by the learner itself (:func:`period_settings`, ``Learner.on_period``); before it
is known, at :data:`NOMINAL_PERIOD_S`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from semiparam_ros.core.config import EstimatorConfig, parameter_spec
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.core.learners.cascade import SemiparametricModel
from semiparam_ros.core.learners.consistent import ConsistentSemiparametricModel
from semiparam_ros.core.learners.contract import PeriodSettings
from semiparam_ros.core.learners.joint import JointSemiparametricModel
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.core.rigid_body.urdf import RegressorSpec
from semiparam_ros.core.stream.acceleration import AccelerationConfig
from semiparam_ros.core.stream.gate import GateConfig
from semiparam_ros.core.stream.pipeline import SamplePipeline
from semiparam_ros.core.stream.rate import samples_in
from semiparam_ros.errors import ConfigurationError

#: The three learners of the paper: rigid body, random features, their combination.
ModelKind = Literal["P", "NP", "SP"]
#: Any learner :func:`build_model` returns.
Model = (ParametricModel | NonparametricModel | SemiparametricModel | JointSemiparametricModel
         | ConsistentSemiparametricModel)


def build_regressor(config: EstimatorConfig, urdf_xml: str | None = None,
                    source: str = "the checkpoint's URDF") -> RigidBodyRegressor:
    """Build the rigid-body regressor described by a configuration.

    With ``robot.output: joint_torques``, ``parametric.friction`` / ``offsets`` / ``armature`` append the
    per-joint friction, offset and armature columns (see :mod:`semiparam_ros.core.rigid_body.dynamics`); with
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
        ConfigurationError: If the URDF or the joints are not set (:meth:`EstimatorConfig.require_robot`), or
            the URDF, joints or sensor are invalid.
    """
    config.require_robot(urdf=urdf_xml is None)
    output = config.output_kind
    if urdf_xml is None:
        path = config.urdf_path()
        if not path.is_file():
            raise FileNotFoundError(f"URDF file not found: {path}")
        urdf_xml, source = path.read_text(encoding="utf-8"), str(path)
    spec = RegressorSpec(
        tuple(config["robot.joints"]),
        ft_sensor=config["robot.ft_sensor"] if output == OutputKind.WRENCH else None,
        locked=config.locked,
        gravity=tuple(config["robot.gravity"]),
        output=output,
        sensor_offset=bool(config["parametric.sensor_offset"]) and output == OutputKind.WRENCH,
        friction=bool(config["parametric.friction"]) and output == OutputKind.JOINT_TORQUES,
        coulomb_velocity=config["parametric.coulomb_velocity"],
        joint_offsets=bool(config["parametric.offsets"]) and output == OutputKind.JOINT_TORQUES,
        armature=bool(config["parametric.armature"]) and output == OutputKind.JOINT_TORQUES,
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
        A function mapping x (3n,) to the base regressor (t × n_base), scaled if asked; its attribute
        ``many`` maps (N, 3n) rows to (N, t, n_base) at once.
    """
    inv = None if scale is None else 1.0 / np.asarray(scale, dtype=np.float64)

    def base_regressor(x: np.ndarray) -> np.ndarray:
        # the learners pass a checked (3n,) float64 x; equal bit for bit to base_regressor(q, dq, ddq) / c
        return regressor.base_regressor_of_input(x, inv)

    def many(X: np.ndarray) -> np.ndarray:
        # (N, 3n) checked rows at once: the vectorised predictions (see ParametricModel.phi_rows)
        return regressor.base_regressor_of_inputs(X, inv)

    base_regressor.many = many  # type: ignore[attr-defined]
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
        effort_scale=config["robot.effort_scale"] or None,
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
        if config.output_kind == OutputKind.WRENCH:
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
            :class:`~semiparam_ros.core.estimator.online.OnlineEstimator` has measured it).

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
    :func:`column_scale` for π̂_b, as
    :attr:`~semiparam_ros.core.estimator.online.OnlineEstimator.parameters` does).

    Args:
        config: Estimator configuration (``parametric.*``, ``nonparametric.*``, ``adaptation.*``).
        kind: ``"P"`` (rigid-body RRLS), ``"NP"`` (random features RRLS) or ``"SP"`` (both; the paper's
            cascade or the joint fit, by ``semiparametric.combination``).
        regressor: Rigid-body regressor to use; built from the configuration when omitted.
        sample_period_s: The stream's sample period [s], when known (offline tools). With
            ``adaptation.time_constant`` τ > 0 both stages then forget with β = exp(−T/τ) instead of the
            configured per-sample factors, and a warm-up given in seconds is converted at it
            (:func:`standardizer_warmup_samples`). ``None``: the configured β, and the warm-up provisionally
            at 100 Hz (:class:`~semiparam_ros.core.estimator.online.OnlineEstimator` measures T itself and
            sets both later).

    Returns:
        The learner.

    Raises:
        ConfigurationError: On an unknown kind.
    """
    if kind not in ("P", "NP", "SP"):
        raise ConfigurationError(f"model kind must be 'P', 'NP' or 'SP', got {kind!r}")
    model = _build_model(config, kind, regressor)
    model.period_settings = period_settings(config)
    residual = model if isinstance(model, NonparametricModel) else getattr(model, "nonparametric", None)
    if isinstance(residual, NonparametricModel):
        residual.learn_warmup = bool(config["nonparametric.learn_warmup"])
    if sample_period_s is not None:
        model.on_period(sample_period_s)
    return model


@dataclass(frozen=True)
class ModelTraits:
    """What the estimator and the served model need to know of a learner's kind: the builder's answer.

    The builder is the one place that knows the learner classes; everything else asks
    :func:`traits_of` (no ``isinstance`` on a learner class elsewhere).

    Attributes:
        kind: ``"P"``, ``"NP"`` or ``"SP"``.
        combination: The SP's ``semiparametric.combination`` (``cascade``, ``joint``, ``consistent``);
            None for P and NP.
        takes_rigid: Whether it predicts with one rigid body that a consistent projection can replace
            (P and the consistent SP: :class:`~semiparam_ros.core.learners.contract.RigidBodyUser`).
        learns_context: Whether learning a sample it just predicted goes through ``learn_ahead`` of that
            prediction's context (the consistent SP, whose a-priori prediction is the one it learns from);
            the others learn with ``predict_learn_one`` (the paper's predict-then-learn, bit for bit).

    >>> traits_of(NonparametricModel(3, 1, n_features=4, standardizer_warmup=0))
    ModelTraits(kind='NP', combination=None, takes_rigid=False, learns_context=False)
    """

    kind: str
    combination: str | None
    takes_rigid: bool
    learns_context: bool


def learner_variants() -> tuple[tuple[ModelKind, str], ...]:
    """Every learner :func:`build_model` makes, as ``(kind, semiparametric.combination)`` pairs.

    P and NP, and SP in each combination the parameter table allows (P and NP ignore the combination).

    >>> learner_variants()
    (('P', 'cascade'), ('NP', 'cascade'), ('SP', 'cascade'), ('SP', 'joint'), ('SP', 'consistent'))
    """
    combinations = parameter_spec("semiparametric.combination").choices or ()
    return (("P", "cascade"), ("NP", "cascade"), *(("SP", c) for c in combinations))


def traits_of(model: object) -> ModelTraits:
    """Return the :class:`ModelTraits` of a learner :func:`build_model` made.

    Raises:
        TypeError: For an object that is not one of the builder's learners.
    """
    if isinstance(model, ConsistentSemiparametricModel):
        return ModelTraits("SP", "consistent", takes_rigid=True, learns_context=True)
    if isinstance(model, JointSemiparametricModel):
        return ModelTraits("SP", "joint", takes_rigid=False, learns_context=False)
    if isinstance(model, SemiparametricModel):
        return ModelTraits("SP", "cascade", takes_rigid=False, learns_context=False)
    if isinstance(model, ParametricModel):
        return ModelTraits("P", None, takes_rigid=True, learns_context=False)
    if isinstance(model, NonparametricModel):
        return ModelTraits("NP", None, takes_rigid=False, learns_context=False)
    raise TypeError(f"not a learner of the builder: {type(model).__name__}")


def rigid_body_part(model: object) -> ParametricModel | None:
    """Return a model's rigid-body learner: P itself, the parametric stage of an SP; None for NP.

    >>> rigid_body_part(NonparametricModel(3, 1, n_features=4, standardizer_warmup=0)) is None
    True
    """
    par = model if isinstance(model, ParametricModel) else getattr(model, "parametric", None)
    return par if isinstance(par, ParametricModel) else None


def period_settings(config: EstimatorConfig) -> PeriodSettings:
    """Return what a learner of this configuration converts at the measured sample period.

    ``adaptation.time_constant`` τ [s] (0: the per-sample factors stay) and the standardizer warm-up
    ``nonparametric.standardizer_warmup_s`` [s] unless ``nonparametric.standardizer_warmup`` gives it in
    samples; the consistent model also converts ``semiparametric.tracker_time_constant`` (its own
    parameter). See :meth:`~semiparam_ros.core.learners.contract.Learner.on_period`.
    """
    warmup_s = None if config["nonparametric.standardizer_warmup"] else \
        float(config["nonparametric.standardizer_warmup_s"])
    return PeriodSettings(time_constant_s=max(0.0, float(config["adaptation.time_constant"])),
                          standardizer_warmup_s=warmup_s)


def _build_model(config: EstimatorConfig, kind: ModelKind,
                 regressor: RigidBodyRegressor | None) -> Model:
    """Build the learner of ``kind`` with the configured per-sample factors and the provisional warm-up."""
    n_joints = len(config["robot.joints"])
    n_inputs = 3 * n_joints
    warmup = standardizer_warmup_samples(config, None)
    if kind == "NP":
        n_outputs = config.n_outputs
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


def gate_config(config: EstimatorConfig) -> GateConfig:
    """Return the contact gate's settings of a configuration (``gate.*``)."""
    return GateConfig(threshold=config["gate.threshold"],
                      max_contact_duration_s=config["gate.max_contact_duration"],
                      warmup_s=config["gate.warmup"], novelty=config["gate.novelty"])
