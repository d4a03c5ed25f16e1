"""Estimator configuration: one parameter table shared by the ROS node and the offline tools.

Configuration is data: one YAML file per robot in the ROS 2 parameter-file form, keyed ``/**`` so that
it applies to the node under any namespace and name (a key ``estimator:`` would match ``/estimator``
only)::

    /**:
      ros__parameters:
        robot:
          joints: [r_shoulder_pitch, ...]
        nonparametric:
          n_features: 500

Nested keys become dotted parameter names (``nonparametric.n_features``), exactly as ``rclpy`` flattens
them. :data:`PARAMETERS` lists every parameter once, with its type, default, allowed range and
description: the node declares its ROS parameters from it, and ``evaluate``/``tune`` read the same file
through :func:`load_config`. Values are validated once, here, with messages that name the parameter and
the allowed range.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import yaml

from semiparam_ros.atomic import atomic_open
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.errors import ConfigurationError

__all__ = [
    "ICUB_RIGHT_ARM",
    "INFERRED_OUTPUT",
    "PARAMETERS",
    "RUNTIME_TARGETS",
    "EstimatorConfig",
    "ParameterSpec",
    "default_config_path",
    "describe_parameters",
    "load_config",
    "load_evaluation_config",
    "parameter_spec",
    "runtime_targets",
    "structural_values",
    "unknown_parameter_message",
    "validate_value",
    "write_config",
]


@dataclass(frozen=True)
class ParameterSpec:
    """One configuration parameter.

    Attributes:
        name: Dotted parameter name (``group.key``).
        type: One of ``string``, ``string_array``, ``double``, ``double_array``, ``integer``, ``bool``.
        default: Default value.
        description: What the parameter means, with its unit.
        min: Inclusive lower bound for numbers (for arrays: of each element), or ``None``.
        max: Inclusive upper bound for numbers, or ``None``.
        choices: Allowed values of a string parameter, or ``None``.
        min_exclusive: Whether ``min`` itself is excluded (e.g. a regularization λ > 0).
        length: Required length of an array parameter, or ``None``.
        runtime: What takes a change of the value while the node runs: ``"estimator"`` (the learner,
            its gate and noise estimate: ``OnlineEstimator.apply_runtime_parameters``), ``"loop"`` (the
            learning loop's overload policy), ``"checkpoints"`` (the checkpoint writer); empty = the value
            is read at start-up only (:attr:`read_only`).
        structural: Whether the value is part of the learned model's structure: a checkpoint names it in
            its fingerprint and loads only into a model built with the same value
            (:func:`structural_values`).
        kinds: The learner kinds (``P``, ``NP``, ``SP``) whose structure the value is part of.
        unless: A value with which checkpoints written before the parameter existed agree: the value is
            left out of the fingerprint when equal to it, so those still load (default: always named).
        unless_as: The same, compared with the value of this other parameter.
        only_if: ``(name, value)`` pairs that must all hold for the value to be named.
    """

    name: str
    type: str
    default: Any
    description: str
    min: float | None = None
    max: float | None = None
    choices: tuple[str, ...] | None = None
    min_exclusive: bool = False
    length: int | None = None
    runtime: str = ""
    structural: bool = False
    kinds: tuple[str, ...] = ("P", "NP", "SP")
    unless: Any = None
    unless_as: str | None = None
    only_if: tuple[tuple[str, Any], ...] = ()

    @property
    def read_only(self) -> bool:
        """Whether the value can only be set at start-up (no :attr:`runtime` target)."""
        return not self.runtime

    def range_text(self) -> str:
        """Return the allowed range as text for error messages and parameter descriptors."""
        if self.choices is not None:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        parts = []
        if self.min is not None:
            parts.append(f"{'>' if self.min_exclusive else '>='} {self.min:g}")
        if self.max is not None:
            parts.append(f"<= {self.max:g}")
        text = " and ".join(parts) if parts else "any value"
        if self.length is not None:
            text = f"{self.length} values, each {text}"
        return text


#: Value of ``robot.output`` that leaves it to ``robot.ft_sensor``: the wrench when a sensor is named,
#: else the joint torques (:attr:`EstimatorConfig.output_kind`).
INFERRED_OUTPUT = ""

#: The ``robot.*`` values of the paper's iCub right arm (``config/icub_right_arm.yaml``: the F/T sensor in
#: the upper arm, the wrist locked), for examples and the demo; no parameter defaults to them.
ICUB_RIGHT_ARM: Mapping[str, Any] = MappingProxyType({
    "robot.urdf": "example-robot-data://robots/icub_description/robots/icub.urdf",
    "robot.joints": ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"],
    "robot.locked_joints": ["r_wrist_prosup", "r_wrist_pitch", "r_wrist_yaw"],
    "robot.locked_positions": [0.0, 0.0, 0.0],
    "robot.ft_sensor": "r_arm_ft_sensor",
    "robot.output": "wrench",
    "robot.frame_id": "r_arm_ft_sensor",
})

PARAMETERS: tuple[ParameterSpec, ...] = (
    # robot
    ParameterSpec("robot.urdf", "string", "",
                  "required: the robot's URDF, a file path, package://<package>/<path> (the ament index, "
                  "then the pip prefixes), example-robot-data://<path>, or topic:<name> (the node waits for "
                  "robot_state_publisher's transient-local std_msgs/String, e.g. topic:/robot_description); "
                  "the node and learn stop when it is empty"),
    ParameterSpec("robot.description_timeout", "double", 0.0,
                  "with robot.urdf: 'topic:<name>', how long the node waits for the URDF on that topic at "
                  "start-up [s]; 0 = as long as it takes", min=0.0, max=1e6),
    ParameterSpec("robot.joints", "string_array", [],
                  "required: moving joints used for learning, in this order (q [rad], dq [rad/s], ddq "
                  "[rad/s^2]); names of the URDF and of JointState.name; the node and learn stop when it is "
                  "empty", structural=True),
    ParameterSpec("robot.locked_joints", "string_array", [],
                  "names of other joints given a fixed position (all others are locked at 0 rad)",
                  structural=True),
    ParameterSpec("robot.locked_positions", "double_array", [],
                  "positions of robot.locked_joints [rad], same length", structural=True),
    ParameterSpec("robot.ft_sensor", "string", "",
                  "fixed URDF joint of a six-axis F/T sensor whose WrenchStamped is learned; empty = no "
                  "sensor (the joint torques of JointState.effort are learned)", structural=True),
    ParameterSpec("robot.output", "string", INFERRED_OUTPUT,
                  "learned quantity: 'joint_torques' (JointState.effort) or 'wrench' (the F/T sensor's "
                  "WrenchStamped); empty = inferred: wrench when robot.ft_sensor names a sensor, else "
                  "joint_torques",
                  choices=(INFERRED_OUTPUT, *(k.value for k in OutputKind)), structural=True),
    ParameterSpec("robot.frame_id", "string", "",
                  "expected frame_id of the WrenchStamped input; empty accepts any"),
    ParameterSpec("robot.effort_scale", "double_array", [],
                  "N·m per unit of JointState.effort, one per robot.joints joint, applied on input (a driver "
                  "that reports motor currents: the torque constant times the gear ratio); empty = all 1 "
                  "(efforts are joint torques in N·m)", min=-1e6, max=1e6),
    ParameterSpec("robot.gravity", "double_array", [0.0, 0.0, -9.81],
                  "gravity in the robot base frame [m/s^2]", min=-100.0, max=100.0, length=3),
    # topics
    ParameterSpec("topics.joint_states", "string", "joint_states", "sensor_msgs/JointState input topic"),
    ParameterSpec("topics.wrench", "string", "wrench", "geometry_msgs/WrenchStamped input topic"),
    # pairing and acceleration
    ParameterSpec("sync.tolerance", "double", 0.005,
                  "largest stamp difference when pairing a wrench with a joint state [s]", min=0.0, max=1.0),
    ParameterSpec("acceleration.method", "string", "savgol",
                  "joint acceleration estimator from velocities: centred local polynomial (delayed by half "
                  "a window, no phase lag), causal filtered finite difference, or causal constant-jerk "
                  "Kalman filter (no delay, no low-frequency lag, noisier; see acceleration.bandwidth_hz)",
                  choices=("savgol", "finite_difference", "kalman")),
    ParameterSpec("acceleration.window_s", "double", 0.12,
                  "length of the acceleration estimator window [s], converted to samples at the joint-state "
                  "rate measured on the first 20 stamps (savgol: 2·round(window_s/(2Δt)) + 1 samples; the "
                  "estimate is window_s/2 late: 60 ms by default; 0.12 s = 13 samples at 100 Hz, 121 at "
                  "1 kHz)",
                  min=0.0, max=10.0, min_exclusive=True),
    ParameterSpec("acceleration.window", "integer", 0,
                  "window in samples (odd for savgol), overriding acceleration.window_s; 0 = use window_s "
                  "(a fixed sample count means a different time span at every rate: prefer window_s)",
                  min=0, max=2001),
    ParameterSpec("acceleration.polyorder", "integer", 3,
                  "polynomial degree of the savgol estimator (< the window in samples); 3 is exact for "
                  "constant snap over the window, and its q̈ has no gain bias of order (ω·window_s/2)²/10 "
                  "at frequency ω, which a degree of 2 (or 1) has and a learner cannot average away",
                  min=1, max=10),
    ParameterSpec("acceleration.cutoff_hz", "double", 20.0,
                  "low-pass cut-off of the finite-difference estimator [Hz]", min=0.0, max=10000.0,
                  min_exclusive=True),
    ParameterSpec("acceleration.bandwidth_hz", "double", 6.0,
                  "bandwidth of the kalman estimator [Hz]: its steady state is a Butterworth loop (order 4 "
                  "for snap, 3 for jerk) at this frequency at any joint-state rate; higher follows faster "
                  "motion with less bias, lower passes less velocity noise (∝ bandwidth_hz^1.5)",
                  min=0.0, max=10000.0, min_exclusive=True),
    ParameterSpec("acceleration.kalman_model", "string", "snap",
                  "process model of the kalman estimator: constant jerk (state q̇, q̈, jerk) or constant snap "
                  "(one derivative more: q̈ bias ≈ 2.6(f/bandwidth_hz)^3 instead of 2(f/bandwidth_hz)^2, "
                  "more noise at one bandwidth)", choices=("jerk", "snap")),
    ParameterSpec("acceleration.max_gap_s", "double", 0.1,
                  "restart the acceleration estimator when consecutive joint states are further apart than "
                  "this, instead of fitting across the dropout [s]; 0 = never restart", min=0.0, max=3600.0),
    # plausibility bounds (finite but impossible values are dropped as 'implausible_value')
    ParameterSpec("limits.max_abs_position", "double", 100.0,
                  "largest plausible |joint position| of a learned joint [rad]; 0 = no bound (unwrapped "
                  "continuous joints)", min=0.0, max=1e12),
    ParameterSpec("limits.max_abs_velocity", "double", 100.0,
                  "largest plausible |joint velocity| of a learned joint [rad/s]; 0 = no bound",
                  min=0.0, max=1e12),
    ParameterSpec("limits.max_abs_output", "double", 1e4,
                  "largest plausible |component| of the learned output: wrench force [N] and torque [N m], "
                  "or joint effort [N m]; 0 = no bound", min=0.0, max=1e12),
    ParameterSpec("limits.glitch_ratio", "double", 50.0,
                  "a joint state whose position, velocity or drift increment on a learned joint exceeds this "
                  "many times its running mean increment and its resolution is held; dropped as 'glitch' if "
                  "the next state comes back (a one-sample outlier), else accepted; 0 = off",
                  min=0.0, max=1e12),
    ParameterSpec("limits.glitch_time_constant", "double", 0.05,
                  "memory of the running mean increment of the glitch check [s]", min=0.0, min_exclusive=True,
                  max=1e4),
    # parametric stage
    ParameterSpec("parametric.lam", "double", 1e-2,
                  "ridge regularization of the rigid-body (base inertial parameter) stage; with "
                  "parametric.column_scaling it acts on dimensionless parameters (see core.estimator)",
                  min=0.0, min_exclusive=True, max=1e12, structural=True),
    ParameterSpec("parametric.consistent", "bool", True,
                  "predict at desired states (feed-forward, load_model) with the physically consistent "
                  "rigid-body parameters, projected from the online estimate in a worker process every "
                  "parametric.consistent_period (docs/identification.md: real KUKA, frozen on a faster "
                  "motion, 2.7x lower error); false = the unconstrained estimate"),
    ParameterSpec("parametric.consistent_period", "double", 10.0,
                  "how often the node re-solves the consistent projection when learning changed the "
                  "model [s]", min=0.1, max=1e6),
    ParameterSpec("parametric.prior", "string", "urdf",
                  "what the rigid-body stage is regularized toward (and predicts before any data): 'urdf' = "
                  "the URDF's base parameters (RNEA with the URDF; zero friction and offsets), 'zero' = all "
                  "zero, the paper's protocol", choices=("urdf", "zero"),
                  structural=True, kinds=("P", "SP"), unless="zero"),
    ParameterSpec("parametric.column_scaling", "bool", True,
                  "scale each regressor column by its RMS over random states, so that one parametric.lam "
                  "means the same for parameters of very different magnitudes (false = the paper's raw "
                  "columns)", structural=True, kinds=("P", "SP"), unless=False),
    ParameterSpec("parametric.friction", "bool", True,
                  "joint_torques: learn per-joint viscous [N·m·s/rad] and Coulomb [N·m] friction, "
                  "f_v·dq + f_c·tanh(dq/v_s)"),
    ParameterSpec("parametric.coulomb_velocity", "double", 0.05,
                  "velocity scale v_s of the smooth Coulomb sign tanh(dq/v_s) [rad/s]: a few times the "
                  "velocity noise, so that noise at rest does not flip the sign", min=0.0,
                  min_exclusive=True, max=10.0,
                  structural=True, kinds=("P", "SP"),
                  only_if=(("parametric.friction", True), ("robot.output", "joint_torques"))),
    ParameterSpec("parametric.stick_displacement", "double", 3e-3,
                  "friction that remembers: pre-sliding displacement delta of each joint's stick state, a "
                  "Dahl element of its path (core/learners/stick.py) [rad]; the torque it holds beyond the "
                  "static Coulomb column (at rest after a move) is learned per joint and added to the "
                  "prediction; 0 = a static model of (q, dq, ddq) only", min=0.0, max=1.0,
                  only_if=(("robot.output", "joint_torques"),)),
    ParameterSpec("parametric.offsets", "bool", True,
                  "joint_torques: learn a constant torque offset per joint [N·m]"),
    ParameterSpec("parametric.armature", "bool", False,
                  "joint_torques: learn a motor armature inertia per joint (a ddq_i column) [kg·m^2]"),
    ParameterSpec("parametric.forgetting", "double", 1.0,
                  "forgetting factor of the rigid-body stage (1 = no forgetting; the regularizer is kept)",
                  min=0.9, max=1.0, min_exclusive=False, structural=True),
    ParameterSpec("parametric.sensor_offset", "bool", False,
                  "add the six constant F/T sensor offsets as extra parameters", structural=True),
    # nonparametric stage
    ParameterSpec("nonparametric.lam", "double", 1e-3,
                  "ridge regularization of the random-feature residual stage", min=0.0, min_exclusive=True,
                  max=1e12, structural=True),
    ParameterSpec("nonparametric.n_features", "integer", 500,
                  "number D of random Fourier features (the factor takes 8·D² bytes: 200 MB at D = 5000; "
                  "D = 500 keeps a 1 kHz loop on two cores)", min=1, max=5000, structural=True),
    ParameterSpec("nonparametric.sigma", "double", 6.0,
                  "Gaussian kernel width on standardized inputs", min=0.0, min_exclusive=True, max=1e6,
                  structural=True),
    ParameterSpec("nonparametric.forgetting", "double", 1.0,
                  "forgetting factor of the residual stage (1 = no forgetting; the regularizer is kept)",
                  min=0.9, max=1.0, structural=True),
    ParameterSpec("nonparametric.seed", "integer", 0, "seed of the random features", min=0, max=2**31 - 1,
                  structural=True),
    ParameterSpec("nonparametric.standardizer_warmup", "integer", 0,
                  "samples used to estimate the input standardization (held, and learned by the residual "
                  "stage once it is ready), overriding nonparametric.standardizer_warmup_s; 0 = use "
                  "standardizer_warmup_s",
                  min=0, max=10**7, structural=True, unless=0),
    ParameterSpec("nonparametric.standardizer_warmup_s", "double", 2.0,
                  "duration of the input standardization's warm-up [s], converted to samples at the measured "
                  "sample rate (200 samples at 100 Hz); its samples are held and learned by "
                  "the residual stage once the statistics are ready", min=0.0, min_exclusive=True,
                  max=1e5, structural=True, only_if=(("nonparametric.standardizer_warmup", 0),)),
    ParameterSpec("nonparametric.learn_warmup", "bool", True,
                  "hold the standardization warm-up's samples and learn them once it is ready (one long step "
                  "then: about 0.3 s at 1 kHz with D = 500 on a 7-joint arm); false = the residual learns "
                  "only the samples after the warm-up"),
    ParameterSpec("nonparametric.min_scale.position", "double", 0.05,
                  "floor of the standardization scale of joint positions [rad] (a warm-up at rest measures "
                  "only sensor noise)", min=0.0, max=1e3, structural=True),
    ParameterSpec("nonparametric.min_scale.velocity", "double", 0.1,
                  "floor of the standardization scale of joint velocities [rad/s]", min=0.0, max=1e4,
                  structural=True),
    ParameterSpec("nonparametric.min_scale.acceleration", "double", 1.0,
                  "floor of the standardization scale of joint accelerations [rad/s^2]", min=0.0, max=1e5,
                  structural=True),
    ParameterSpec("nonparametric.min_scale.force", "double", 1.0,
                  "wrench output: floor of the standardization scale of predicted forces [N] (residual-stage "
                  "input of SP)",
                  min=0.0, max=1e5, structural=True),
    ParameterSpec("nonparametric.min_scale.torque", "double", 0.05,
                  "wrench output: floor of the standardization scale of predicted torques [N·m] (SP)",
                  min=0.0, max=1e5, structural=True),
    ParameterSpec("nonparametric.min_scale.joint_torque", "double", 0.05,
                  "joint_torques output: floor of the standardization scale of predicted joint torques "
                  "[N·m] (SP); only a warm-up whose torques barely move reaches it (the arm at rest)",
                  min=0.0, max=1e5,
                  structural=True, kinds=("NP", "SP"),
                  only_if=(("robot.output", "joint_torques"),), unless_as="nonparametric.min_scale.torque"),
    # how the two stages are combined
    ParameterSpec("semiparametric.combination", "string", "consistent",
                  "SP model: 'cascade' = the paper's (rigid-body stage alone first, residual stage on "
                  "[x, y_hat]); 'joint' = rigid-body parameters and kernel residual (on x) fitted as one "
                  "ridge problem, which needs parametric.forgetting == nonparametric.forgetting; "
                  "'consistent' = rigid-body stage alone first, a residual on x that stays consistent with "
                  "the current parameters and falls back to zero where x is novel (the model), plus a fast "
                  "tracker of the model's error (one step ahead); see core/learners/consistent.py",
                  choices=("cascade", "joint", "consistent"),
                  structural=True, kinds=("SP",), unless="cascade"),
    ParameterSpec("semiparametric.novelty_scale", "double", 1.0,
                  "'consistent': the residual is weighted per output by S/(S + sigma^2 v/novelty_scale), "
                  "S = s^2 (1 - nu), s^2 the rigid-body part's recent systematic error variance, nu the "
                  "residual's prior variance left at the state, sigma^2 v its predictive variance "
                  "(dimensionless; larger = trust the residual further from its data)",
                  min=0.0, min_exclusive=True, max=1e6),
    ParameterSpec("semiparametric.tracker", "bool", True,
                  "'consistent': add the fast tracker of the model's error to the prediction (false = the "
                  "model alone)"),
    ParameterSpec("semiparametric.tracker_position_scale", "double", 0.05,
                  "'consistent': joint-position distance [rad] over which the tracked error fades "
                  "(weight exp(-d^2/2) in units of these scales)", min=0.0, min_exclusive=True, max=1e3),
    ParameterSpec("semiparametric.tracker_velocity_scale", "double", 0.5,
                  "'consistent': joint-velocity distance [rad/s] over which the tracked error fades",
                  min=0.0, min_exclusive=True, max=1e4),
    ParameterSpec("semiparametric.tracker_time_constant", "double", 0.3,
                  "'consistent': memory of the fast rigid-body correction of the model's error [s] (what "
                  "follows a payload or a parameter drift at once), converted at the measured rate; at "
                  "least 10 rows per parameter are kept whatever the rate",
                  min=0.0, min_exclusive=True, max=1e6),
    ParameterSpec("semiparametric.tracker_samples", "integer", 50,
                  "'consistent': learned samples over which the local tracker compares its error smoothers "
                  "and estimates the noise (a statistical sample size, not a time)", min=2, max=10**7),
    # adaptation, uncertainty and the contact-aware learning gate (core/learners/adaptation.py,
    # core/learners/uncertainty.py,
    # core/stream/gate.py; measurements in docs/adaptation.md)
    ParameterSpec("adaptation.time_constant", "double", 20.0,
                  "memory of both learners [s]: when > 0 it replaces parametric.forgetting and "
                  "nonparametric.forgetting by beta = exp(-T/tau), T the sample period measured (median "
                  "step) over the first samples (until then, and in tools that do not know the rate, the "
                  "per-sample factors apply); 0 = use the per-sample forgetting factors only",
                  min=0.0, max=1e9, structural=True, unless=0.0),
    ParameterSpec("uncertainty.noise_time_constant", "double", 2.0,
                  "time constant of the running estimate of the noise scale s^2 per output [s]; the "
                  "published std is sqrt(s^2 (1 + z A^-1 z^T)); with the consistent SP, s^2 is of the "
                  "model's errors (its fast correction left out)", min=0.0, min_exclusive=True, max=1e9,
                  runtime="estimator"),
    ParameterSpec("uncertainty.calibration_block", "double", 20.0,
                  "seconds between the frozen copies of the model that calibrate the served std for new "
                  "motion: each copy is scored on the next block of the learning stream and the served std "
                  "(load_model, the feed-forward) is scaled per output and motion state so that 95 % of "
                  "those errors lie within +-2 std (core/estimator/calibration.py); 0 = the one-step std",
                  min=0.0, max=1e9),
    ParameterSpec("gate.enabled", "bool", True,
                  "contact-aware learning gate: a sample whose residual exceeds gate.threshold standard "
                  "deviations is predicted but not learned, unless the excursion outlasts "
                  "gate.max_contact_duration (false = learn every sample, the paper's behaviour)",
                  runtime="estimator"),
    ParameterSpec("gate.threshold", "double", 5.0,
                  "residual beyond which a sample is not learned, in predictive standard deviations of "
                  "any one output component", min=0.0, min_exclusive=True, max=1e6, runtime="estimator"),
    ParameterSpec("gate.max_contact_duration", "double", 3.0,
                  "an excursion beyond the threshold that lasts longer than this is a new normal (a "
                  "payload) and is learned [s]; longer than the longest expected contact",
                  min=0.0, max=1e6, runtime="estimator"),
    ParameterSpec("gate.warmup", "double", 10.0,
                  "time from the first sample during which every sample is learned and the noise "
                  "estimate settles before the gate engages [s]", min=0.0, max=1e6, runtime="estimator"),
    ParameterSpec("gate.novelty", "double", 1.0,
                  "relative predictive variance z A^-1 z^T (dimensionless: the model's own uncertainty in "
                  "units of the noise variance) above which an outlier is motion the model has not seen, "
                  "learned, not a contact; 0 = every outlier is a contact", min=0.0, max=1e12,
                  runtime="estimator"),
    # feed-forward at desired states (joint torques; serving/feedforward.py)
    ParameterSpec("feedforward.joints", "string_array", [],
                  "joint order of ~/feedforward_commands and ~/feedforward (a JointGroupEffortController's "
                  "joints); empty = robot.joints"),
    ParameterSpec("feedforward.max_std", "double", 0.0,
                  "predictive std [N m] on any joint above which the feed-forward falls back to the "
                  "rigid-body part; 0 = never (the residual already abstains in states never seen)",
                  min=0.0, max=1e9),
    ParameterSpec("feedforward.refresh_period", "double", 1.0,
                  "the feed-forward is served from a copy of the model refreshed this often [s] while "
                  "learning goes on; 0 = the live model (it changes at every sample, which makes the "
                  "commanded torque jitter: docs/feedforward.md)",
                  min=0.0, max=1e6),
    ParameterSpec("feedforward.exclude", "string_array", [],
                  "terms left out of every feed-forward output (~/feedforward, ~/feedforward_commands, "
                  "~/trajectory_with_effort, ~/follow_joint_trajectory): a subset of gravity, friction, "
                  "for a torque-controlled arm that compensates them itself (Franka FCI, KUKA FRI, UR "
                  "direct torque: docs/controllers.md); the predictive std is unchanged"),
    ParameterSpec("feedforward.exclude_source", "string", "model",
                  "whose gravity feedforward.exclude leaves out: 'model' = the learned rigid body's (the "
                  "one the prediction uses), 'urdf' = the URDF's CAD gravity, when the robot compensates "
                  "with its own CAD model (the learned difference then stays in the command)",
                  choices=("model", "urdf")),
    ParameterSpec("feedforward.controller_action", "string",
                  "joint_trajectory_controller/follow_joint_trajectory",
                  "control_msgs/FollowJointTrajectory action that ~/follow_joint_trajectory forwards goals "
                  "to, with every point's effort filled (relative names resolve in the node's namespace)"),
    # run time
    ParameterSpec("learning_enabled", "bool", True, "learn online (false = predict only)",
                  runtime="estimator"),
    ParameterSpec("overload.max_delay", "double", 0.001,
                  "a sample that waited longer than this in the node's input queue [s] is predicted at once "
                  "(residual held from the last full prediction) and not learned, so predictions stay fresh "
                  "when learning cannot keep up; counted as learning_skipped; 0 = learn every sample, "
                  "however late", min=0.0, max=1e6, runtime="loop"),
    ParameterSpec("queue_size", "integer", 1000,
                  "bounded input queue of the node; the oldest message is dropped and counted beyond it",
                  min=1, max=10**6),
    ParameterSpec("checkpoint.enabled", "bool", True,
                  "keep what is learned: write checkpoints (periodically, on ~/save and at shutdown) and "
                  "warm start from them; false = everything learned is lost when the node stops"),
    ParameterSpec("checkpoint.path", "string", "",
                  "checkpoint file (.npz; ~ is expanded); empty = one file per node under $ROS_HOME "
                  "(~/.ros when unset): semiparam_ros/<namespace>/<node>.npz, loaded only when it was "
                  "learned on the same URDF, joints, output and learner structure (otherwise moved aside, "
                  "never overwritten); a path given here is refused instead when it does not fit"),
    ParameterSpec("checkpoint.period", "double", 60.0,
                  "period of automatic checkpoints [s]; 0 disables them", min=0.0, max=1e7,
                  runtime="checkpoints"),
    ParameterSpec("checkpoint.load_on_start", "bool", True, "warm start from an existing checkpoint"),
    ParameterSpec("diagnostics.period", "double", 1.0, "period of /diagnostics [s]", min=0.01, max=3600.0),
    ParameterSpec("diagnostics.rmse_window", "integer", 0,
                  "samples in the running RMSE window reported in diagnostics, overriding "
                  "diagnostics.rmse_window_s; 0 = use rmse_window_s", min=0, max=10**6),
    ParameterSpec("diagnostics.rmse_window_s", "double", 3.0,
                  "duration of the running RMSE window reported in diagnostics [s], converted to samples at "
                  "the measured sample rate (300 samples at 100 Hz)", min=0.0,
                  min_exclusive=True, max=1e5),
)

_SPECS: Mapping[str, ParameterSpec] = MappingProxyType({p.name: p for p in PARAMETERS})


def parameter_spec(name: str) -> ParameterSpec:
    """Return the specification of a parameter.

    Args:
        name: Dotted parameter name.

    Returns:
        Its :class:`ParameterSpec`.

    Raises:
        ConfigurationError: If no such parameter exists.
    """
    try:
        return _SPECS[name]
    except KeyError:
        raise ConfigurationError(unknown_parameter_message(name)) from None


def unknown_parameter_message(name: str) -> str:
    """Say that ``name`` is no parameter and name the closest ones (a misspelling is the usual cause).

    Example:
        >>> unknown_parameter_message("adaptaton.time_constant").split("?")[0]
        "unknown parameter 'adaptaton.time_constant': did you mean 'adaptation.time_constant' or ..."
    """
    import difflib

    close = difflib.get_close_matches(name, list(_SPECS), n=3, cutoff=0.6)
    hint = (f"did you mean {' or '.join(repr(c) for c in close)}?" if close
            else f"known groups: {', '.join(sorted({n.split('.')[0] for n in _SPECS}))}")
    return f"unknown parameter {name!r}: {hint} (every parameter: the node's --print-defaults)"


def describe_parameters() -> str:
    """Return every parameter with its type, range, default and meaning, one line each (``--print-defaults``).

    Example:
        >>> print(describe_parameters().splitlines()[0])
        robot.urdf (string, default ''): required: the robot's URDF, a file path, ...
    """
    lines = []
    for spec in PARAMETERS:
        rng = spec.range_text()
        kind = spec.type if rng == "any value" else f"{spec.type}, {rng}"
        runtime = "" if spec.read_only else ", settable at run time"
        lines.append(f"{spec.name} ({kind}, default {spec.default!r}{runtime}): {spec.description}")
    return "\n".join(lines)


#: A number in exponent notation that YAML 1.1 (PyYAML) reads as a string: ``1e-6``, ``1.0e5``, ``2E+3``.
_EXPONENT_LITERAL = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)[eE][-+]?\d+")


def _number(name: str, value: Any, integer: bool) -> float | int:
    if isinstance(value, str) and _EXPONENT_LITERAL.fullmatch(value.strip()):
        value = float(value)  # what the user wrote is a number; only the YAML version disagrees
    if isinstance(value, bool) or not isinstance(value, int | float):
        kind = "an integer" if integer else "a number"
        raise ConfigurationError(f"parameter {name!r} must be {kind}, got {value!r}")
    if integer and isinstance(value, float):
        if not value.is_integer():
            raise ConfigurationError(f"parameter {name!r} must be an integer, got {value!r}")
        value = int(value)
    if not math.isfinite(value):
        raise ConfigurationError(f"parameter {name!r} must be finite, got {value!r}")
    return int(value) if integer else float(value)


def _check_range(spec: ParameterSpec, value: float) -> None:
    low_bad = spec.min is not None and (value <= spec.min if spec.min_exclusive else value < spec.min)
    high_bad = spec.max is not None and value > spec.max
    if low_bad or high_bad:
        raise ConfigurationError(f"parameter {spec.name!r} = {value!r} is out of range: must be "
                                 f"{spec.range_text()}")


def validate_value(name: str, value: Any) -> Any:
    """Check one parameter value and return it normalized (ints for integers, lists for arrays).

    Args:
        name: Dotted parameter name.
        value: Candidate value.

    Returns:
        The normalized value.

    Raises:
        ConfigurationError: Naming the parameter and the allowed range or type when the value is invalid.
    """
    spec = parameter_spec(name)
    if spec.type == "string":
        if not isinstance(value, str):
            raise ConfigurationError(f"parameter {name!r} must be a string, got {value!r}")
        value = str(value)  # a string enum (an OutputKind) is kept as its plain value
        if spec.choices is not None and value not in spec.choices:
            raise ConfigurationError(f"parameter {name!r} = {value!r} is invalid: must be "
                                     f"{spec.range_text()}")
        return value
    if spec.type == "bool":
        if not isinstance(value, bool):
            raise ConfigurationError(f"parameter {name!r} must be true or false, got {value!r}")
        return value
    if spec.type in ("double", "integer"):
        number = _number(name, value, spec.type == "integer")
        _check_range(spec, number)
        return number
    if isinstance(value, str | bytes) or not isinstance(value, Iterable):
        raise ConfigurationError(f"parameter {name!r} must be a list, got {value!r}")
    items = list(value)
    if spec.length is not None and len(items) != spec.length:
        raise ConfigurationError(f"parameter {name!r} must have {spec.length} values, got {len(items)}")
    if spec.type == "string_array":
        if not all(isinstance(v, str) for v in items):
            raise ConfigurationError(f"parameter {name!r} must be a list of strings, got {value!r}")
        return items
    numbers = [_number(name, v, False) for v in items]
    for v in numbers:
        _check_range(spec, v)
    return numbers


@dataclass(frozen=True)
class EstimatorConfig:
    """A complete, validated set of estimator parameters.

    Read values with ``config["nonparametric.lam"]`` or ``config.get(...)``. Instances are immutable; use
    :meth:`with_overrides` to derive a changed copy.
    """

    values: Mapping[str, Any]

    def __post_init__(self) -> None:
        checked = {name: validate_value(name, value) for name, value in self.values.items()}
        missing = [p.name for p in PARAMETERS if p.name not in checked]
        if missing:
            raise ConfigurationError(f"missing parameters: {', '.join(missing)}")
        joints = checked["robot.joints"]
        if len(set(joints)) != len(joints):
            raise ConfigurationError(f"parameter 'robot.joints' has duplicate names: {joints}")
        if len(checked["robot.locked_joints"]) != len(checked["robot.locked_positions"]):
            raise ConfigurationError("parameters 'robot.locked_joints' and 'robot.locked_positions' must "
                                     "have the same length")
        overlap = set(joints) & set(checked["robot.locked_joints"])
        if overlap:
            raise ConfigurationError(f"joints both learned and locked: {sorted(overlap)}")
        if checked["robot.output"] == INFERRED_OUTPUT:
            checked["robot.output"] = (OutputKind.WRENCH if checked["robot.ft_sensor"]
                                       else OutputKind.JOINT_TORQUES).value
        scale = checked["robot.effort_scale"]
        if scale and len(scale) != len(joints):
            raise ConfigurationError(f"parameter 'robot.effort_scale' must have one value per joint of "
                                     f"robot.joints ({len(joints)}), got {len(scale)}")
        if any(v == 0.0 for v in scale):
            raise ConfigurationError("parameter 'robot.effort_scale' must not hold 0 (N·m per reported unit)")
        if checked["robot.output"] == OutputKind.WRENCH and not checked["robot.ft_sensor"]:
            raise ConfigurationError("parameter 'robot.ft_sensor' must name the F/T sensor joint when "
                                     "robot.output is 'wrench'")
        window = checked["acceleration.window"]
        if window and window < (3 if checked["acceleration.method"] == "savgol" else 2):
            raise ConfigurationError(f"parameter 'acceleration.window' = {window} is too small: 0 (use "
                                     "acceleration.window_s), or >= 3 for savgol, >= 2 for finite_difference")
        if window and checked["acceleration.method"] == "savgol" and window % 2 == 0:
            raise ConfigurationError("parameter 'acceleration.window' must be odd for the savgol method, got "
                                     f"{checked['acceleration.window']}")
        if window and checked["acceleration.method"] == "savgol" and (
            checked["acceleration.polyorder"] >= window
        ):
            raise ConfigurationError("parameter 'acceleration.polyorder' must be below "
                                     "'acceleration.window' for the savgol method, got "
                                     f"{checked['acceleration.polyorder']} >= "
                                     f"{checked['acceleration.window']}")
        if checked["semiparametric.combination"] == "joint" and (
            checked["parametric.forgetting"] != checked["nonparametric.forgetting"]
        ):
            fp, fn = checked["parametric.forgetting"], checked["nonparametric.forgetting"]
            raise ConfigurationError("parameters 'parametric.forgetting' and 'nonparametric.forgetting' "
                                     "must be equal with semiparametric.combination 'joint' (one data "
                                     f"weighting for both terms), got {fp} and {fn}")
        object.__setattr__(self, "values", MappingProxyType(checked))

    @classmethod
    def defaults(cls) -> EstimatorConfig:
        """Return the configuration made of every parameter's default."""
        return cls({p.name: p.default for p in PARAMETERS})

    @classmethod
    def from_flat(cls, flat: Mapping[str, Any]) -> EstimatorConfig:
        """Build a configuration from dotted names; missing parameters take their defaults.

        Args:
            flat: Mapping of dotted parameter names to values.

        Returns:
            The validated configuration.

        Raises:
            ConfigurationError: On an unknown name or an invalid value (the message names the parameter).
        """
        values = {p.name: p.default for p in PARAMETERS}
        for name, value in flat.items():
            parameter_spec(name)
            values[name] = value
        return cls(values)

    def to_flat(self) -> dict[str, Any]:
        """Return the values as a plain dict of dotted names."""
        return {name: (list(v) if isinstance(v, list) else v) for name, v in self.values.items()}

    def with_overrides(self, overrides: Mapping[str, Any]) -> EstimatorConfig:
        """Return a copy with some values replaced.

        Args:
            overrides: Dotted names to new values.

        Returns:
            The new validated configuration.

        Raises:
            ConfigurationError: On an unknown name or an invalid value.
        """
        values = self.to_flat()
        for name, value in overrides.items():
            parameter_spec(name)
            values[name] = value
        return EstimatorConfig(values)

    def __getitem__(self, name: str) -> Any:
        if name not in self.values:
            parameter_spec(name)
        return self.values[name]

    def get(self, name: str) -> Any:
        """Return the value of a parameter (same as ``config[name]``)."""
        return self[name]

    @property
    def output_kind(self) -> OutputKind:
        """What the estimator learns (``robot.output``): an F/T sensor's wrench or the joint torques."""
        return OutputKind(self["robot.output"])

    @property
    def n_outputs(self) -> int:
        """Width of the learned output: 6 for a wrench, one per joint of ``robot.joints`` for torques."""
        return self.output_kind.n_outputs(len(self["robot.joints"]))

    @property
    def locked(self) -> dict[str, float]:
        """Return the positions of the locked joints [rad] by name."""
        return dict(zip(self["robot.locked_joints"], self["robot.locked_positions"], strict=True))

    def require_robot(self, urdf: bool = True) -> None:
        """Check that the robot is named: ``robot.joints`` (and ``robot.urdf`` when ``urdf``) set.

        No parameter defaults to a robot; the node, ``learn`` and every tool that builds the rigid body call
        this first.

        Raises:
            ConfigurationError: Naming the missing parameters and where they are set.

        >>> EstimatorConfig.defaults().require_robot()
        Traceback (most recent call last):
        ...
        semiparam_ros.errors.ConfigurationError: robot.urdf and robot.joints are not set: ...
        """
        missing = [name for name, needed in (("robot.urdf", urdf), ("robot.joints", True))
                   if needed and not self[name]]
        if missing:
            raise ConfigurationError(
                f"{' and '.join(missing)} {'is' if len(missing) == 1 else 'are'} not set: name your robot's "
                "URDF (a file path, package://…, example-robot-data://… or topic:/robot_description) and its "
                "moving joints in a parameter file keyed '/**:', as config/template.yaml does (the paper's "
                "iCub: config/icub_right_arm.yaml)")

    def urdf_path(self) -> Path:
        """Return the URDF path that ``robot.urdf`` names (``urdf.resolve_urdf``)."""
        from semiparam_ros.core.rigid_body.urdf import resolve_urdf

        return resolve_urdf(self["robot.urdf"])


#: What takes a run-time parameter's change (:attr:`ParameterSpec.runtime`).
RUNTIME_TARGETS = ("estimator", "loop", "checkpoints")


def runtime_targets(names: Iterable[str]) -> set[str]:
    """Return the run-time targets of the named parameters (read-only ones have none).

    >>> sorted(runtime_targets(["gate.threshold", "checkpoint.period", "robot.joints"]))
    ['checkpoints', 'estimator']
    """
    return {spec.runtime for spec in map(parameter_spec, names) if spec.runtime}


def structural_values(config: EstimatorConfig, kind: str) -> dict[str, Any]:
    """Return the structural parameters of a learner of ``kind`` (the checkpoint fingerprint's entries).

    A parameter is named when its spec is ``structural``, ``kind`` is among its ``kinds``, every
    ``only_if`` condition holds and its value differs from ``unless`` (or from the value of ``unless_as``).

    Args:
        config: The configuration.
        kind: ``P``, ``NP`` or ``SP``.

    Returns:
        Parameter names to values.

    >>> cfg = EstimatorConfig.defaults()
    >>> values = structural_values(cfg, "SP")
    >>> values["nonparametric.n_features"], values["semiparametric.combination"]
    (500, 'consistent')
    >>> "semiparametric.combination" in structural_values(cfg, "P"), "sync.tolerance" in values
    (False, False)
    """
    out: dict[str, Any] = {}
    for spec in PARAMETERS:
        if not spec.structural or kind not in spec.kinds:
            continue
        if any(config[name] != value for name, value in spec.only_if):
            continue
        value = config[spec.name]
        legacy = config[spec.unless_as] if spec.unless_as is not None else spec.unless
        if legacy is not None and value == legacy:
            continue
        out[spec.name] = value
    return out


def _flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def _parameters_block(document: Any, node_name: str, path: Path) -> Mapping[str, Any]:
    if not isinstance(document, Mapping):
        raise ConfigurationError(f"{path}: expected a ROS 2 parameter file (a mapping at the top)")
    for key in (node_name, f"/{node_name}", "/**"):
        block = document.get(key)
        if isinstance(block, Mapping) and isinstance(block.get("ros__parameters"), Mapping):
            return block["ros__parameters"]
    raise ConfigurationError(f"{path}: no '/**: ros__parameters:' (or '{node_name}:') block found")


_ROS_ONLY = frozenset({"use_sim_time"})


def load_config(path: str | Path, node_name: str = "estimator") -> EstimatorConfig:
    """Read a ROS 2 parameter file into a validated configuration.

    Args:
        path: YAML file in the ROS 2 parameter-file form.
        node_name: Node whose ``ros__parameters`` block is read (``/**`` is accepted too).

    Returns:
        The validated configuration (missing parameters take their defaults).

    Raises:
        ConfigurationError: If the file is missing, is not valid YAML, has no parameter block, or holds an
            unknown parameter or an invalid value (the message names the file and the parameter).
    """
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except OSError as err:
        raise ConfigurationError(f"cannot read config file {path}: {err}") from err
    except yaml.YAMLError as err:
        raise ConfigurationError(f"config file {path} is not valid YAML: {err}") from err
    flat = {k: v for k, v in _flatten(_parameters_block(document, node_name, path)).items()
            if k not in _ROS_ONLY}
    try:
        return EstimatorConfig.from_flat(flat)
    except ConfigurationError as err:
        raise ConfigurationError(f"{path}: {err}") from err


def write_config(config: EstimatorConfig, path: str | Path, node_name: str = "/**",
                 header: str = "") -> None:
    """Write a configuration as a ROS 2 parameter file that the node and the tools accept.

    Args:
        config: Configuration to write.
        path: Destination YAML file (parent directories are created).
        node_name: Key of the parameter block (default ``/**``: any node, any namespace).
        header: Optional comment lines put at the top of the file.

    Raises:
        OSError: If the file cannot be written (written atomically: the destination is then unchanged).
    """
    tree: dict[str, Any] = {}
    for name, value in config.to_flat().items():
        node = tree
        *groups, key = name.split(".")
        for group in groups:
            node = node.setdefault(group, {})
        node[key] = value
    text = yaml.safe_dump({node_name: {"ros__parameters": tree}}, sort_keys=False)
    if header:
        text = "".join(f"# {line}\n" for line in header.splitlines()) + text
    with atomic_open(path, "w") as fh:
        fh.write(text)


def default_config_path() -> Path | None:
    """Return the shipped ``icub_right_arm.yaml``: the source tree's, else the installed share copy.

    Returns:
        The path, or ``None`` when neither exists (the parameter defaults are then used).
    """
    candidates = [
        Path(__file__).resolve().parents[2] / "config" / "icub_right_arm.yaml",
        Path(sys.prefix) / "share" / "semiparam_ros" / "config" / "icub_right_arm.yaml",
    ]
    return next((c for c in candidates if c.is_file()), None)


def load_evaluation_config(
    path: str | Path | None, overrides: Mapping[str, Any] | None = None
) -> EstimatorConfig:
    """Load a parameter file and apply overrides.

    Args:
        path: ROS 2 parameter file, or ``None`` for the shipped ``icub_right_arm.yaml`` (the parameter
            defaults if it cannot be found).
        overrides: Dotted names to values.

    Returns:
        The validated configuration.

    Raises:
        ValueError: On a bad file, unknown parameter or invalid value.
    """
    if path is None:
        path = default_config_path()
    config = load_config(path) if path is not None else EstimatorConfig.defaults()
    return config.with_overrides(dict(overrides)) if overrides else config
