"""P, NP and SP on a real arm's joint-torque logs, beside the references a robot user knows.

:func:`compare_on_logs` trains on one log and runs the project's protocol on another
(:func:`~semiparam_ros.eval.protocol.prequential.run_protocol`: the test log in sequential parts, each from a
copy of
the trained model; "at regime" = the second half of each part), for:

- the learners P, NP, SP (the configuration as given) and SPC (the paper's cascade), updated online on
  the test parts (test-then-train) and frozen after training (:data:`FROZEN_SUFFIX`: no test updates, i.e.
  generalization; a learner with a fast correction is used as its model, see
  :func:`~semiparam_ros.eval.protocol.prequential.predict_only`);
- P without friction and offsets (:data:`P_RIGID`), to measure what the friction columns add;
- the CAD model (:data:`CAD`: RNEA with the URDF's parameters, no learning);
- batch identification (:data:`BATCH`: ordinary least squares on the whole training log with the
  configuration's friction/offset columns, then frozen) and the same updated online (:data:`BATCH_ONLINE`);
- persistence (:data:`PERSISTENCE`: the previous measured torque).

It also measures what a model gives that persistence cannot (:func:`injected_torque_recovery`): a constant
external torque added to the measured torques over a window is seen in the residual ``τ − τ̂`` of a model
(fully if frozen, partly if it keeps learning), but only at the window's first sample by persistence.

The result is a typed :class:`RealRobotComparison` (the protocol's
:class:`~semiparam_ros.eval.protocol.report.ProtocolReport` plus acceptance criteria as
:class:`Criterion` records and the :class:`InjectedTorque` measurement); :func:`comparison_markdown`
renders its tables. Units: N·m (errors, torques), s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.bags.replay import load_samples
from semiparam_ros.eval.models.baselines import (
    Persistence,
    batch_least_squares,
    cad_model,
    identification_regressor,
    least_squares_model,
)
from semiparam_ros.eval.models.served import NodeLearner, node_learner, served_model
from semiparam_ros.eval.protocol.horizon import (
    DEFAULT_HORIZONS,
    HorizonReport,
    evaluate_horizons,
    horizon_figure,
    horizon_markdown,
)
from semiparam_ros.eval.protocol.metrics import OutputSpec
from semiparam_ros.eval.protocol.options import DEFAULT_FIRST_S, DEFAULT_SPLITS, DEFAULT_WINDOW_S
from semiparam_ros.eval.protocol.prequential import SampleArrays, predict_only, run_protocol, test_then_train
from semiparam_ros.eval.protocol.report import ProtocolReport, protocol_report
from semiparam_ros.eval.protocol.slices import motion_slices, slice_coverage
from semiparam_ros.report.tables import controller_section

__all__ = [
    "BATCH",
    "BATCH_ONLINE",
    "CAD",
    "FROZEN_SUFFIX",
    "LEARNERS",
    "PERSISTENCE",
    "P_RIGID",
    "SP_NODE",
    "Criterion",
    "InjectedTorque",
    "RealRobotComparison",
    "compare_on_logs",
    "comparison_markdown",
    "evaluate_logs",
    "injected_torque_recovery",
    "run_comparison",
]

CAD = "CAD"
BATCH = "batch LS"
BATCH_ONLINE = "batch LS online"
PERSISTENCE = "persistence"
P_RIGID = "P rigid"
FROZEN_SUFFIX = " frozen"
#: The node's own step (:class:`OnlineEstimator`: contact gate and σ as configured) around the trained SP.
SP_NODE = "SP (node, gate on)"
#: The learners: P, NP, SP (the configured combination, by default the consistent model) and the paper's
#: cascade (``SPC``) beside it.
LEARNERS: tuple[str, ...] = ("P", "NP", "SP", "SPC")


@dataclass(frozen=True)
class Criterion:
    """One acceptance criterion: ``value ≤ limit``.

    Attributes:
        id: Short identifier, e.g. ``SP/min(P,NP)/regime``.
        description: What is compared, for humans.
        value: The measured ratio.
        limit: The threshold.
        passed: ``value <= limit``.
    """

    id: str
    description: str
    value: float
    limit: float
    passed: bool

    @classmethod
    def at_most(cls, id: str, description: str, value: float, limit: float) -> Criterion:
        """Build a ``value ≤ limit`` criterion."""
        return cls(id, description, float(value), float(limit), bool(value <= limit))


@dataclass(frozen=True)
class InjectedTorque:
    """How much of an external torque step each model's residual ``τ − τ̂`` shows.

    Attributes:
        amplitude: The step added to every joint's measured torque [N·m].
        start_s: Its start from the test log's first sample [s].
        duration_s: Its length [s].
        mean_fraction: Per model, the mean over the window and the joints of the residual's change divided
            by the amplitude (1: the external torque is seen whole; 0: not at all).
        end_fraction: The same over the window's last 10 % (what is left once an online learner adapted).
    """

    amplitude: float
    start_s: float
    duration_s: float
    mean_fraction: dict[str, float]
    end_fraction: dict[str, float]


@dataclass(frozen=True)
class ServedTrace:
    """What the served model (frozen) predicts on a test log, beside what was measured.

    Attributes:
        joints: The joints, in the columns' order.
        time_s: (N,) time from the test log's first sample [s].
        measured: (N, n) measured torques [N·m].
        served: (N, n) the served SP's prediction (``load_model(...).predict``) [N·m].
        std: (N, n) its σ [N·m].
        urdf: (N, n) the URDF's rigid body (RNEA with the CAD inertias, no friction) [N·m].
    """

    joints: tuple[str, ...]
    time_s: np.ndarray
    measured: np.ndarray
    served: np.ndarray
    std: np.ndarray
    urdf: np.ndarray


@dataclass(frozen=True)
class RealRobotComparison:
    """Everything :func:`compare_on_logs` measured.

    Attributes:
        report: The protocol report of every model (per joint RMSE at regime and nMSE).
        torque_std: Standard deviation of each joint's measured test torque [N·m].
        friction_joints: Joints the friction criterion is evaluated on.
        criteria: The acceptance criteria.
        injected: The external-torque measurement, or ``None`` if not run.
        horizons: Every model's error by the age of the model (:mod:`semiparam_ros.eval.protocol.horizon`), or
            ``None`` if not run.
        excitation: What the training data excited (:func:`excitation_summary`).
        coverage: Per learner, the fraction of the test log's errors within ±2σ of its served model
            frozen (``load_model(...).predict``), per joint.
        served: The served SP frozen on the test log beside the measured torques and the URDF's rigid
            body (for the figure; not in the JSON), or ``None``.
        coverage_slices: Per learner, its served model's ±2σ coverage by motion state
            (:mod:`~semiparam_ros.eval.protocol.slices`, mean over the joints) and over all samples.
    """

    report: ProtocolReport
    torque_std: dict[str, float]
    friction_joints: tuple[str, ...]
    criteria: tuple[Criterion, ...]
    injected: InjectedTorque | None
    horizons: HorizonReport | None = None
    excitation: dict[str, Any] | None = None
    coverage: dict[str, list[float]] | None = None
    served: ServedTrace | None = None
    coverage_slices: dict[str, dict[str, float]] | None = None

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form."""
        return {
            "protocol": self.report.to_json(),
            "torque_std": self.torque_std,
            "friction_joints": list(self.friction_joints),
            "criteria": [c.__dict__ for c in self.criteria],
            "injected": None if self.injected is None else dict(self.injected.__dict__),
            "horizons": None if self.horizons is None else self.horizons.to_json(),
            "excitation": self.excitation,
            "coverage": self.coverage,
            "coverage_slices": self.coverage_slices,
        }


def _models(config: EstimatorConfig, train: SampleArrays) -> tuple[dict[str, Any], set[str], set[str]]:
    """Models by name, the frozen names and the names already trained (the batch fits)."""
    models: dict[str, Any] = {CAD: cad_model(config)}
    phi, _ = identification_regressor(config)
    fit = batch_least_squares(phi, train.X, train.Y)
    models[BATCH] = least_squares_model(phi, fit)
    models[BATCH_ONLINE] = least_squares_model(phi, fit)
    # each learner online is the node's step (gate, σ, rate meter), and frozen the model a user is served:
    # learned by the node's estimator, saved, loaded
    for k in LEARNERS:
        models[k] = node_learner(config, k)
        models[k + FROZEN_SUFFIX] = served_model(config, k, train)
    rigid = config.with_overrides({"parametric.friction": False, "parametric.offsets": False,
                                   "parametric.armature": False})
    models[P_RIGID] = node_learner(rigid, "P")
    models[PERSISTENCE] = Persistence(train.n_outputs)
    frozen = {CAD, BATCH, *(k + FROZEN_SUFFIX for k in LEARNERS)}
    return models, frozen, {BATCH, BATCH_ONLINE, *(k + FROZEN_SUFFIX for k in LEARNERS)}


def injected_torque_recovery(models: Mapping[str, Any], data: SampleArrays, *, frozen: Sequence[str] = (),
                             gated: Sequence[str] = (), config: EstimatorConfig | None = None,
                             amplitude: float = 1.0, start_s: float = 10.0,
                             duration_s: float = 1.0) -> InjectedTorque:
    """Add a constant external torque to every joint over a window and measure it in each residual.

    Each model (trained; not modified: a copy runs) goes through ``data`` twice, with and without
    ``amplitude`` added to the measured torques over ``[start_s, start_s + duration_s)``; a frozen model
    only predicts. The change of its residual ``τ − τ̂`` between the two runs, over the window, divided by
    the amplitude, is the fraction of the external torque the model would report.

    Args:
        models: Trained models by name.
        data: The stream (joint torques [N·m]).
        frozen: Names of models that do not learn.
        gated: Names of models run through the node's own step (:class:`OnlineEstimator` with
            ``config``: the contact gate decides what is learned, on the stream's stamps).
        config: The configuration of the gated runs (required with ``gated``).
        amplitude: The step [N·m], non-zero.
        start_s: Start from the stream's first sample [s].
        duration_s: Length [s].

    Returns:
        The :class:`InjectedTorque`.

    Raises:
        ConfigurationError: If the amplitude is zero or the window is empty or outside the stream.
    """
    t = (data.stamps_ns - data.stamps_ns[0]) * 1e-9
    window = (t >= start_s) & (t < start_s + duration_s)
    if amplitude == 0.0 or not math.isfinite(amplitude) or window.sum() < 10:
        raise ConfigurationError("the injected torque needs a non-zero amplitude and a window of ≥ 10 "
                                 f"samples inside the stream (it lasts {t[-1]:.1f} s)")
    if gated and config is None:
        raise ConfigurationError("gated models need the configuration of the node's step")
    Y_ext = data.Y + amplitude * window[:, None]
    idx = np.flatnonzero(window)
    end = idx[int(0.9 * len(idx)):]
    mean_fraction: dict[str, float] = {}
    end_fraction: dict[str, float] = {}
    for name, model in models.items():
        if name in gated:
            assert config is not None  # checked above
            base = _node_predictions(model, config, data, data.Y)
            ext = _node_predictions(model, config, data, Y_ext)
        elif name in frozen:
            base = predict_only(model, data.X)[0]
            ext = base  # a frozen model's prediction does not depend on the measured torques
        else:
            base = test_then_train(model.copy(), data.X, data.Y, None, data.stamps_ns)[0]
            ext = test_then_train(model.copy(), data.X, Y_ext, None, data.stamps_ns)[0]
        change = ((Y_ext - ext) - (data.Y - base)) / amplitude
        mean_fraction[name] = float(change[idx].mean())
        end_fraction[name] = float(change[end].mean())
    return InjectedTorque(float(amplitude), float(start_s), float(duration_s), mean_fraction, end_fraction)


def _node_predictions(model: Any, config: EstimatorConfig, data: SampleArrays, Y: np.ndarray) -> np.ndarray:
    """A-priori predictions of the node's step (gate, σ, adaptation as configured) from a copy of a model."""
    est = OnlineEstimator(config)
    learner = getattr(model, "estimator", None)  # a NodeLearner: its estimator's model
    est.model = (model if learner is None else learner.model).copy()
    return test_then_train(NodeLearner(est), data.X, Y, None, data.stamps_ns)[0]


def compare_on_logs(config: EstimatorConfig, train: SampleArrays, test: SampleArrays, *,
                    friction_joints: Sequence[str], splits: int = DEFAULT_SPLITS,
                    window_s: float = DEFAULT_WINDOW_S, first_s: float = DEFAULT_FIRST_S, inject: bool = True,
                    protocol: Mapping[str, Any] | None = None,
                    horizons: Sequence[float | str] | None = DEFAULT_HORIZONS,
                    progress: bool = False) -> RealRobotComparison:
    """Run every model of the module docstring on a joint-torque log pair and check the acceptance.

    Criteria (means over joints of the RMSE at regime): SP ≤ min(P, NP); SP ≤ the online batch
    identification; and on each of ``friction_joints``, P's RMSE ≤ ½ × P's without friction and offsets.

    Args:
        config: Estimator configuration with ``robot.output: joint_torques``.
        train: Training stream (learned whole; the batch fit's data).
        test: Test stream.
        friction_joints: Joint names of the friction criterion (joints whose torque is mostly friction).
        splits: Test parts of the protocol.
        window_s: Sliding window of the error curves [s].
        first_s: Initial segment reported separately [s].
        inject: Also run :func:`injected_torque_recovery`
            (a 1 N·m step for 1 s at the middle of the test log, after the gate's warm-up).
        protocol: Extra settings recorded in the report.
        horizons: Horizons of :func:`~semiparam_ros.eval.protocol.horizon.evaluate_horizons` [s] (0 = one
            step, ``"frozen"``), run on the learners trained by the protocol, the CAD model, the batch fit and
            persistence; ``None`` = not run.
        progress: Progress bar (only on a terminal).

    Returns:
        The :class:`RealRobotComparison`.

    Raises:
        ConfigurationError: If the output is not joint torques or a friction joint is not configured.
    """
    if config.output_kind != OutputKind.JOINT_TORQUES:
        raise ConfigurationError("compare_on_logs needs robot.output: joint_torques")
    joints = list(config["robot.joints"])
    unknown = [j for j in friction_joints if j not in joints]
    if unknown:
        raise ConfigurationError(f"friction joints {unknown} are not among robot.joints {joints}")
    models, frozen, trained = _models(config, train)
    result = run_protocol(models, train, test, output=OutputSpec.from_config(config), splits=splits,
                          window_s=window_s, first_s=first_s, progress=progress, frozen=frozen,
                          trained=trained)
    report = protocol_report(result, config=config.to_flat(), protocol=protocol)
    mean = {k: m.rmse_mean for k, m in report.models.items()}
    criteria = [
        Criterion.at_most("SP/min(P,NP)/regime", "SP / min(P, NP), mean RMSE at regime",
                          mean["SP"] / min(mean["P"], mean["NP"]), 1.0),
        Criterion.at_most(f"SP/{BATCH_ONLINE}/regime",
                          "SP / online batch identification, mean RMSE at regime",
                          mean["SP"] / mean[BATCH_ONLINE], 1.0),
    ]
    for j in friction_joints:
        criteria.append(Criterion.at_most(
            f"P/{P_RIGID}/{j}/regime", f"P / P without friction and offsets, {j} RMSE at regime",
            report.models["P"].components[j].rmse / report.models[P_RIGID].components[j].rmse, 0.5))
    injected = None
    if inject:
        duration = len(test) * test.sample_period_s
        chosen = {k: models[k] for k in ("persistence", "SP frozen", "SP", "P", BATCH_ONLINE)}
        chosen[SP_NODE] = models["SP"]  # the trained SP, run as the node runs it
        gate_on = config.with_overrides({"gate.enabled": True})
        injected = injected_torque_recovery(chosen, test, frozen=sorted(frozen), gated=[SP_NODE],
                                            config=gate_on, amplitude=1.0, start_s=0.5 * duration,
                                            duration_s=1.0)
    horizon = None
    if horizons is not None:
        # the protocol trained every model in place on the training stream
        chosen = {k: models[k] for k in (CAD, BATCH, *LEARNERS, PERSISTENCE)}
        horizon = evaluate_horizons(chosen, train, test, horizons=horizons, fixed=(CAD, BATCH),
                                    components=joints,
                                    frozen_models={k: models[k + FROZEN_SUFFIX] for k in LEARNERS})
    std = dict(zip(joints, (float(s) for s in test.Y.std(axis=0)), strict=True))
    masks = motion_slices(test.X, len(joints), test.n_outputs, test.sample_period_s)
    n = len(joints)
    q, dq, ddq = test.X[:, :n], test.X[:, n:2 * n], test.X[:, 2 * n:]
    served = {k: models[k + FROZEN_SUFFIX].served for k in LEARNERS}
    predicted = {k: model.predict(q, dq, ddq) for k, model in served.items()}  # once per learner
    inside = {k: np.abs(test.Y - total) <= 2.0 * sigma for k, (total, sigma) in predicted.items()}
    coverage = {k: [float(c) for c in v.mean(axis=0)] for k, v in inside.items()}
    by_slice = {k: slice_coverage(v, masks) for k, v in inside.items()}
    total, sigma = predicted["SP"]
    stamps = np.asarray(test.stamps_ns, dtype=np.int64)
    trace = ServedTrace(tuple(joints), (stamps - stamps[0]) * 1e-9, np.asarray(test.Y), total, sigma,
                        served["SP"].cad(q, dq, ddq))
    return RealRobotComparison(report, std, tuple(friction_joints), tuple(criteria), injected, horizon,
                               excitation_summary(config, models["SP"], test), coverage, trace, by_slice)


def excitation_summary(config: EstimatorConfig, model: Any, test: SampleArrays) -> dict[str, Any]:
    """Return what the training data determined of the rigid-body part, and how much of the test lies outside.

    Args:
        config: The configuration the model was built with.
        model: A trained learner with a rigid-body part (``parametric`` stage, or a P learner), or a
            :class:`~semiparam_ros.eval.models.served.NodeLearner` of one.
        test: The test stream.

    Returns:
        ``condition`` (information matrix, physical units), ``least_excited`` (eigenvalue and the base
        parameters each of the three weakest directions weighs most) and ``test_fraction_outside``: the
        fraction of test samples where the rigid-body part's relative predictive variance exceeds
        :data:`~semiparam_ros.core.rigid_body.identification.OUTSIDE_EXCITED` (a frozen model extrapolates
        there).
    """
    from semiparam_ros.core.estimator.build import build_regressor, column_scale
    from semiparam_ros.core.rigid_body.identification import excitation_report, outside_excited

    estimator = getattr(model, "estimator", None)  # a NodeLearner: its estimator's learner
    model = model if estimator is None else estimator.model

    par = getattr(model, "parametric", model)
    regressor = build_regressor(config)
    report = excitation_report(par.rls.R, column_scale(config, regressor),
                               tuple(regressor.base_parameter_names))
    variance = par.predict_many(test.X).variance
    return {"condition": report.condition,
            "least_excited": [{"eigenvalue": value, "weights": dict(names)}
                              for value, names in report.least_excited],
            "test_fraction_outside": float(outside_excited(variance).mean())}


def evaluate_logs(config: EstimatorConfig, train_path: str | Path, test_path: str | Path, *,
                  friction_joints: Sequence[str], splits: int = DEFAULT_SPLITS, inject: bool = True,
                  horizons: Sequence[float | str] | None = DEFAULT_HORIZONS,
                  progress: bool = False) -> RealRobotComparison:
    """Read two joint-torque bags through the node's pipeline and run :func:`compare_on_logs`.

    Args:
        config: Estimator configuration (joint torques).
        train_path: Training bag (folder or ``.mcap``).
        test_path: Test bag.
        friction_joints: Joints of the friction criterion.
        splits: Test parts of the protocol.
        inject: Run the external-torque measurement.
        horizons: Horizons of the age table [s] (see :func:`compare_on_logs`); ``None`` = not run.
        progress: Progress bar (only on a terminal).

    Returns:
        The :class:`RealRobotComparison`.

    Raises:
        ValueError: On unreadable bags or an invalid configuration.
    """
    train, train_drops = load_samples(train_path, config)
    test, test_drops = load_samples(test_path, config)
    info = {"train_bag": str(train_path), "test_bag": str(test_path), "drops_train": train_drops,
            "drops_test": test_drops}
    return compare_on_logs(config, train, test, friction_joints=friction_joints, splits=splits, inject=inject,
                           protocol=info, horizons=horizons, progress=progress)


def _row(name: str, values: Sequence[float], fmt: str) -> str:
    return f"| {name} | " + " | ".join(format(v, fmt) for v in values) + " |"


def comparison_markdown(comparison: RealRobotComparison) -> str:
    """Render the per-joint tables (RMSE and nMSE at regime), the criteria and the injected-torque table.

    Args:
        comparison: A :class:`RealRobotComparison`.

    Returns:
        Markdown.
    """
    report = comparison.report
    joints = list(report.output.components)
    leading = controller_section(comparison.horizons, "N·m", coverage=comparison.coverage_slices)
    head = "| model | " + " | ".join(joints) + " | mean |\n|---" + "|---" * (len(joints) + 1) + "|\n"
    rmse = "".join(_row(k, [*(m.components[j].rmse for j in joints), m.rmse_mean], ".3f") + "\n"
                   for k, m in report.models.items())
    nmse = "".join(_row(k, [*(m.components[j].nmse for j in joints), m.nmse_mean], ".4f") + "\n"
                   for k, m in report.models.items())
    split = report.protocol.get("split_size")
    text = (
        (leading + "## One step ahead (test-then-train, the paper's protocol)\n\n" if leading else "")
        + f"Train: {report.samples_train} samples; test: {report.splits} parts of {split} samples "
        f"({report.samples_test} in all, {report.protocol.get('sample_period_s', float('nan')) * 1e3:.1f} ms "
        "period); at regime = second half of each part.\n\n"
        "RMSE at regime [N·m]:\n\n" + head + rmse
        + "\n" + _row("measured torque std", [comparison.torque_std[j] for j in joints], ".3f") + "\n"
        + "\nnMSE at regime (MSE / variance of the measured torque):\n\n" + head + nmse
        + "\nAcceptance:\n\n| criterion | value | limit | result |\n|---|---|---|---|\n"
        + "".join(f"| {c.description} | {c.value:.3f} | ≤ {c.limit:g} | {'pass' if c.passed else 'FAIL'} |\n"
                  for c in comparison.criteria)
    )
    inj = comparison.injected
    if inj is not None:
        text += (
            f"\nExternal torque of {inj.amplitude:g} N·m on every joint for {inj.duration_s:g} s "
            f"(from {inj.start_s:.1f} s of the test log): fraction of it in the residual τ − τ̂, "
            "mean over joints\n\n"
            + "| model | mean over the window | last 10 % of the window |\n|---|---|---|\n"
            + "".join(f"| {k} | {inj.mean_fraction[k]:.3f} | {inj.end_fraction[k]:.3f} |\n"
                      for k in inj.mean_fraction)
        )
    if comparison.horizons is not None:
        text += "\nBy the age of the model [N·m]. " + horizon_markdown(comparison.horizons)
    if comparison.coverage is not None:
        text += ("\nServed frozen (`load_model(...).predict`): fraction of the test errors within ±2σ\n\n"
                 + head + "".join(_row(k, [*v, float(np.mean(v))], ".3f") + "\n"
                                  for k, v in comparison.coverage.items()))
    exc = comparison.excitation
    if exc is not None:
        weakest = exc["least_excited"][0]
        names = ", ".join(f"{n} ({w:+.2f})" for n, w in weakest["weights"].items())
        text += (f"\nExcitation of the training data: information condition number {exc['condition']:.3g}; "
                 f"least excited: {names}.\n")
        if exc["test_fraction_outside"] > 0:
            share = 100 * exc["test_fraction_outside"]
            text += (f"\n**Warning**: {share:.1f} % of the test samples lie outside the excited range "
                     "(rigid-body uncertainty > noise): ")
            text += "a frozen model extrapolates there.\n"
    return text


#: A URDF shipped beside the logs (the KUKA logs' own), used when none is given.
LOG_URDF = "kuka_lwr4_cogimon.urdf"
#: The KUKA LWR4+'s friction-dominated joints (its logs' README): the friction criterion's default.
KUKA_FRICTION_JOINTS = ("lwr_0_joint", "lwr_4_joint", "lwr_5_joint", "lwr_6_joint")


def run_comparison(*, data: Path, config: Path, train: str = "measurements_1", test: str = "measurements_3",
                   urdf: Path | None = None, overrides: Mapping[str, Any] | None = None,
                   friction_joints: Sequence[str] | None = None, splits: int = DEFAULT_SPLITS,
                   inject: bool = True,
                   horizons: Sequence[float | str] | None = DEFAULT_HORIZONS,
                   json_path: Path | None = None, markdown_path: Path | None = None,
                   figure_path: Path | None = None, served_figure_path: Path | None = None,
                   progress: bool = True) -> str:
    """Run the ``real_robots`` command: load, compare, write the JSON and markdown, return the text.

    Args:
        data: Folder holding the training and test bags.
        config: Parameter file (joint torques).
        train: Training bag, relative to ``data``.
        test: Test bag, relative to ``data``.
        urdf: URDF overriding ``robot.urdf`` (``None``: the logs' own :data:`LOG_URDF` in ``data`` when
            present, as the KUKA logs ship it, else the configuration's).
        overrides: Further parameter overrides (dotted names).
        friction_joints: Joints of the friction criterion (``None``: :data:`KUKA_FRICTION_JOINTS`).
        splits: Test parts.
        inject: Run the external-torque measurement.
        horizons: Horizons of the age table [s] (0 = one step, ``"frozen"``); ``None`` = not run.
        json_path: Destination of the JSON (``None``: not written).
        markdown_path: Destination of the tables (``None``: not written).
        figure_path: Destination of the age figure (PNG; ``None`` or no horizons: not drawn).
        served_figure_path: Destination of the served model against the measured torques (PNG; ``None``:
            not drawn).
        progress: Progress bar (only on a terminal).

    Returns:
        The markdown tables.

    Raises:
        ValueError: On a missing data folder, bad configuration or unreadable bags.
    """
    from semiparam_ros.atomic import atomic_write_text
    from semiparam_ros.core.config import load_evaluation_config
    from semiparam_ros.plain_json import write_json

    if not Path(data).is_dir():
        raise ConfigurationError(f"data folder {data} does not exist")
    over = dict(overrides or {})
    if friction_joints is None:
        friction_joints = KUKA_FRICTION_JOINTS
    if urdf is None and (Path(data) / LOG_URDF).is_file():
        urdf = Path(data) / LOG_URDF
    if urdf is not None:
        over["robot.urdf"] = str(urdf)
    cfg = load_evaluation_config(config, over)
    comparison = evaluate_logs(cfg, Path(data) / train, Path(data) / test, friction_joints=friction_joints,
                               splits=splits, inject=inject, horizons=horizons, progress=progress)
    text = comparison_markdown(comparison)
    if figure_path is not None and comparison.horizons is not None:
        horizon_figure(comparison.horizons, figure_path, title=f"{train} → {test}")
    if served_figure_path is not None and comparison.served is not None:
        from semiparam_ros.report.figures import plot_served

        plot_served(comparison.served, served_figure_path,
                    title=f"SP learned on {train}, served frozen on {test}: measured vs predicted")
    if json_path is not None:
        write_json(comparison.to_json(), json_path)
    if markdown_path is not None:
        atomic_write_text(markdown_path, text)
    return text
