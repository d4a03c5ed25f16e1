"""The learned model as a function of the state: what a controller's feed-forward term calls.

:func:`load_model` reads a self-contained checkpoint (configuration, URDF text and learned state travel
inside it; see :meth:`OnlineEstimator.checkpoint_state`) and returns a :class:`LearnedModel`:

    τ(q, q̇, q̈) = Φ(q, q̇, q̈) π̂  +  g(x) r(x),          σ(x) = c_m sqrt(s²_m (1 + v(x)))

the identified rigid-body part (base inertial parameters π̂ with friction and offsets) plus the residual
where the data determine it (weight g in [0, 1], 0 in states never seen; see
:mod:`semiparam_ros.core.learners.consistent`), with its predictive standard deviation σ (m each output's
motion state at x — at rest, around a reversal, in motion —, s²_m the one-step noise variance the
estimator measured in that state, v the relative posterior variance at x, c_m the scale that puts 95 % of
a frozen copy's errors on later motion within ±2σ: :mod:`semiparam_ros.core.estimator.calibration`;
before anything was scored, the one-step sqrt(s² (1 + v))). No correction of a recent
measured error enters: the model depends on the state only, so it may be evaluated at a **desired** state,
ahead of the measurement.

Units: q [rad] (m for prismatic joints), q̇ [rad/s], q̈ [rad/s²]; outputs N·m per joint (``robot.output:
joint_torques``, the order of :attr:`LearnedModel.joints`) or the F/T sensor wrench [N, N·m] in the sensor
frame (``wrench``). Sign convention of joint torques: the torque the actuator applies to the child link
about the joint axis (what RNEA returns).

Example:
    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
    >>> from semiparam_ros.core.estimator.online import OnlineEstimator
    >>> est = OnlineEstimator(EstimatorConfig.from_flat(ICUB_RIGHT_ARM))  # iCub arm, F/T wrench
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "icub.npz"
    >>> est.save(path)
    >>> model = load_model(path)
    >>> model.joints
    ('r_shoulder_pitch', 'r_shoulder_roll', 'r_shoulder_yaw', 'r_elbow')
    >>> y, std = model.predict(np.zeros(4), np.zeros(4), np.zeros(4))  # nothing learned: the CAD model
    >>> bool(np.allclose(y, model.cad(np.zeros(4), np.zeros(4), np.zeros(4))))
    True
    >>> Y, S = model.predict(np.zeros((5, 4)), np.zeros((5, 4)), np.zeros((5, 4)))  # five states at once
    >>> Y.shape
    (5, 6)
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from semiparam_ros.core.checkpoint import load_npz
from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.build import Model, build_regressor, rigid_body_part, traits_of
from semiparam_ros.core.estimator.calibration import STATES, motion_states, served_sigma_one
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.estimator.state import learner_kind, read_config
from semiparam_ros.core.learners.consistent import ConsistentSemiparametricModel
from semiparam_ros.core.learners.contract import Prediction
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.core.learners.stick import StickFriction, StickState
from semiparam_ros.core.learners.uncertainty import predict_with_variance
from semiparam_ros.core.rigid_body.identification import ConsistentEstimate, ExcitationReport
from semiparam_ros.core.rigid_body.payload import PayloadEstimate
from semiparam_ros.core.rigid_body.plausible import PlausibleLinks, plausible_links
from semiparam_ros.core.validation import check_finite_array
from semiparam_ros.errors import CheckpointError, ConfigurationError, RejectedSampleError

__all__ = ["EXCLUDABLE", "EXCLUDE_SOURCES", "CheckpointMigrationWarning", "LearnedModel", "ModelPrediction",
           "load_model"]

#: Terms a feed-forward may leave out for a robot that compensates them itself.
EXCLUDABLE = ("gravity", "friction")
#: Whose gravity is left out: the model's own, or the URDF's CAD model (the robot's compensation).
EXCLUDE_SOURCES = ("model", "urdf")


@dataclass(frozen=True)
class ModelPrediction:
    """The model at one state (arrays of shape (t,)) or N states ((N, t)).

    Attributes:
        total: Rigid-body part + residual [N·m, or N and N·m for a wrench].
        rigid_body: The identified rigid-body part ``Φ π̂`` (with friction and offsets when configured).
        residual: The weighted residual ``g r`` (0 where the state was never seen).
        std: Predictive standard deviation σ of ``total`` (noise included; +inf when the checkpoint holds
            no noise estimate yet).
    """

    total: np.ndarray
    rigid_body: np.ndarray
    residual: np.ndarray
    std: np.ndarray


class LearnedModel:
    """A learned inverse-dynamics model, evaluated at any state (read-only; not thread-safe).

    Wraps an :class:`OnlineEstimator` (the node's live one, or one restored by :func:`load_model`) without
    copying it: predictions read the learned state as it is now. :meth:`snapshot` freezes a copy instead
    (what a controller should be served while the estimator goes on learning: a model that changes at
    every sample injects sample-to-sample torque jitter into the loop it drives).

    Args:
        estimator: The estimator whose model is served.
        model: A frozen copy of the estimator's learner to serve instead of the live one (see
            :meth:`snapshot`).
        noise_s2: The noise variance [units of y²] that goes with ``model`` (None: the estimator's).

    Attributes:
        estimator: The wrapped estimator (advanced use: parameters, configuration, further learning).
    """

    def __init__(self, estimator: OnlineEstimator, *, model: Model | None = None,
                 noise_s2: np.ndarray | None = None,
                 calibration: tuple[np.ndarray, np.ndarray | None] | None = None,
                 stick: StickFriction | None = None, solve: bool = True) -> None:
        self.estimator = estimator
        self._frozen = model
        self._frozen_s2 = noise_s2
        self._frozen_calibration = calibration
        self._frozen_stick = stick
        self._scales: tuple[int, np.ndarray] | None = None  # the live calibration's, by scores counted
        self._consistent: tuple[tuple[int, int], ConsistentEstimate] | None = None
        self._attached: ConsistentEstimate | None = None
        self._solve = bool(solve)
        self._weights: np.ndarray | None = None  # the projection's prior weights (cached: 64 regressor rows)
        self._one: tuple[bytes | None, Any] | None = None  # a frozen copy's compiled single state, by rigid
        self._sigma_one: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # its σ's arrays
        #: Software versions that wrote the checkpoint (empty for a live estimator).
        self.versions: dict[str, Any] = {}
        regressor = estimator.regressor
        self._n = len(regressor.joint_names)
        base_names = estimator.parameter_names
        # base parameters that are not inertial: sensor offsets, per-joint friction, offsets, armature
        extra = [i for i, name in enumerate(base_names)
                 if name.startswith("offset_") or name.rsplit(".", 1)[-1] in regressor.extra_kinds]
        self._inertial = np.ones(len(base_names), dtype=bool)
        self._inertial[extra] = False
        friction = {f"{j}.{kind}" for j in regressor.joint_names for kind in ("viscous", "coulomb")}
        self._friction = np.array([name in friction for name in base_names], dtype=bool)
        self._cad_full = regressor.urdf_parameters()

    def snapshot(self) -> LearnedModel:
        """Return a frozen copy: the model as it is now, unaffected by what the estimator learns next.

        A memory copy of the learned state (≈ 0.6 ms for a 7-joint arm at D = 500), sharing the
        regressor: use it from the thread that drives the estimator.
        """
        s2 = self._noise_s2()
        stick = self._stick()
        return LearnedModel(self.estimator, model=self._model().copy(),
                            noise_s2=None if s2 is None else s2.copy(),
                            calibration=self._calibration(copy=True),
                            stick=None if stick is None else stick.copy(),
                            solve=self._solve)

    def attach_consistent(self, estimate: ConsistentEstimate | None) -> None:
        """Use a consistent estimate solved elsewhere (the node's worker process) instead of solving here."""
        self._attached = estimate

    def consistent(self) -> ConsistentEstimate:
        """Return the physically consistent per-link parameters of the rigid-body part (cached).

        The projection of :mod:`semiparam_ros.core.rigid_body.identification` (cvxpy + Clarabel, tens of ms;
        the first call also imports cvxpy): the learner's estimate where the data determine it, the URDF's CAD
        values elsewhere, every body a physical mass distribution, friction ≥ 0.

        Raises:
            ValueError: For a model without a rigid-body part (``NP``).
            ConfigurationError: If the solver fails.
        """
        from semiparam_ros.core.rigid_body.identification import consistent_parameters

        if self._attached is not None:
            return self._attached
        model = self._model()
        par = self._rigid_learner()
        key = (id(model), int(model.n_samples_seen))
        if self._consistent is None or self._consistent[0] != key:
            rls = par.rls
            estimate = consistent_parameters(self.estimator.regressor, par.parameters, rls.R,
                                             self.estimator.column_scale, rls.lam)
            self._consistent = (key, estimate)
        return self._consistent[1]

    def plausible_links(self) -> PlausibleLinks:
        """Return the per-link inertials a user can load into a URDF (what ``export_urdf`` writes).

        The consistent estimate, with every link the data left implausible (a mass far from the URDF's, a
        centre of mass far from its frame) held at its URDF values and the rest re-fitted
        (:mod:`semiparam_ros.core.rigid_body.plausible`); its ``warning()`` names them and any payload.

        Raises:
            ValueError: For a model without a rigid-body part (``NP``).
            ConfigurationError: If the solver fails.
        """
        estimate = self.consistent()
        par = self._rigid_learner()
        return plausible_links(self.estimator.regressor, estimate, par.parameters, par.rls.R,
                               self.estimator.column_scale, par.rls.lam)

    def payload(self) -> PayloadEstimate:
        """Return the payload the distal body carries: mass [kg], centre of mass [m], inertia [kg·m²].

        Since the last tare (:meth:`OnlineEstimator.tare_payload`, the node's ``~/payload/tare``) when one
        was made: the change of the distal body's parameters learned from the samples after it
        (``reference="tare"``). Otherwise beyond the URDF (``reference="urdf"``): the links before the
        distal body held at their CAD values, its ten parameters regressed on what the rigid-body part's
        data leave, σ including the CAD links' assumed accuracy
        (:func:`~semiparam_ros.core.rigid_body.payload.payload_beyond_urdf`; a linear solve, no cone
        program). Each with its standard deviation; the centre of mass in the frame of the distal body
        (the child link of the last configured joint), the inertia about the centre of mass.

        Raises:
            ValueError: For a model without a rigid-body part (``NP``).
        """
        from semiparam_ros.core.rigid_body.identification import full_column_rms
        from semiparam_ros.core.rigid_body.payload import payload_beyond_urdf

        est = self.estimator
        if est.payload is not None:
            return est.payload.estimate()
        par = self._rigid_learner()
        rls = par.rls
        s2 = self._noise_s2()
        noise = float(np.mean(s2)) if s2 is not None and np.all(np.isfinite(s2)) else float("nan")
        if self._weights is None:
            self._weights = full_column_rms(est.regressor)
        return payload_beyond_urdf(est.regressor, par.parameters, rls.R, est.column_scale, rls.lam,
                                   self._weights, noise, est.n_samples_learned)

    def excitation(self) -> ExcitationReport:
        """Return what the data seen so far determine: the rigid-body information matrix's spectrum.

        Raises:
            ValueError: For a model without a rigid-body part (``NP``).
        """
        from semiparam_ros.core.rigid_body.identification import excitation_report

        rls = self._rigid_learner().rls
        return excitation_report(rls.R, self.estimator.column_scale, self.estimator.parameter_names)

    def excited(self, q: Any, dq: Any, ddq: Any) -> np.ndarray:
        """Tell whether the data seen so far determine the rigid-body part at these states.

        False where the rigid-body learner's relative predictive variance ``φ A⁻¹ φᵀ`` exceeds
        :data:`~semiparam_ros.core.rigid_body.identification.OUTSIDE_EXCITED` on some output: a frozen model
        used there extrapolates (the CAD values carry it, or nothing does).

        Args:
            q: Positions (n,) or (N, n) [rad].
            dq: Velocities [rad/s], same shape.
            ddq: Accelerations [rad/s²], same shape.

        Returns:
            A bool, or (N,) bools.

        Raises:
            RejectedSampleError: Wrong shapes or non-finite values.
            ValueError: For a model without a rigid-body part (``NP``).
        """
        from semiparam_ros.core.rigid_body.identification import outside_excited

        X, single = self._states(q, dq, ddq)
        variance = self._rigid_learner().predict_many(X).variance
        assert variance is not None  # predict_many returns it
        inside = ~outside_excited(variance)
        return inside[0] if single else inside

    def _rigid_learner(self) -> ParametricModel:
        """Return the rigid-body learner of the served model.

        Raises:
            ValueError: For a model without one (``NP``).
        """
        par = rigid_body_part(self._model())
        if par is None:
            raise ValueError("this needs a rigid-body part: the model is nonparametric only")
        return par

    def _model(self) -> Model:
        return self.estimator.model if self._frozen is None else self._frozen

    def _noise_s2(self) -> np.ndarray | None:
        return self.estimator.noise.s2 if self._frozen is None else self._frozen_s2

    def _stick(self) -> StickFriction | None:
        return self.estimator.stick if self._frozen is None else self._frozen_stick

    def stick_state(self) -> StickState | None:
        """Return where the measured path left each joint's stick state (a copy), or None without one.

        What a controller's sequence of desired states starts from (``history`` of :meth:`predict_parts`):
        friction that remembers (:mod:`semiparam_ros.core.learners.stick`).
        """
        stick = self._stick()
        return None if stick is None else stick.state.copy()

    def sigma_scales(self) -> np.ndarray:
        """Return the served σ's scale per output and motion state, (t, 3).

        Columns: at rest, around a reversal, in motion
        (:data:`~semiparam_ros.core.estimator.calibration.STATES`).
        σ(x) = c sqrt(s²_m (1 + v(x))), m the output's motion state at x and s²_m its one-step noise: c puts
        95 % of the errors a frozen copy of the model made on later
        motion of the learning stream within ±2σ (:mod:`semiparam_ros.core.estimator.calibration`). NaN
        where nothing was scored (a new model, a checkpoint written before the calibration,
        ``uncertainty.calibration_block: 0``): σ is then the one-step sqrt(s² (1 + v)).
        """
        return self._calibration()[0]

    def _calibration(self, copy: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """Return the scales and s²_m of the served σ, each (t, 3) (a snapshot's, or the estimator's now)."""
        if self._frozen is not None and self._frozen_calibration is not None:
            return self._frozen_calibration
        calibration = self.estimator.calibration
        if calibration is None:
            return np.full((len(self.output_names), len(STATES)), np.nan), None
        if self._scales is None or self._scales[0] != calibration.n_scored:
            self._scales = (calibration.n_scored, calibration.scales())
        s2 = calibration.s2
        if copy:
            return self._scales[1].copy(), s2.copy()
        return self._scales[1], s2

    # ------------------------------------------------------------------ description
    @property
    def joints(self) -> tuple[str, ...]:
        """The joints, in the order of q, q̇, q̈ and of joint-torque outputs."""
        return tuple(self.estimator.regressor.joint_names)

    @property
    def output(self) -> str:
        """``OutputKind.JOINT_TORQUES`` or ``OutputKind.WRENCH``."""
        return str(self.estimator.regressor.output)

    @property
    def output_names(self) -> tuple[str, ...]:
        """Names of the output components (joint names, or ``fx … tz``)."""
        return tuple(self.estimator.regressor.output_names)

    @property
    def n_samples_learned(self) -> int:
        """Samples the model has learned (the estimator's now, for a snapshot too)."""
        return int(self.estimator.n_samples_learned)

    @property
    def config(self) -> EstimatorConfig:
        """The configuration the model was learned with."""
        return self.estimator.config

    @property
    def ready(self) -> bool:
        """Whether the residual is active (its input standardizer finished its warm-up).

        Before that the prediction is the rigid-body part alone (the CAD model before any data).
        """
        model = self._model()
        npm = getattr(model, "nonparametric", None)
        if npm is None:
            return model.n_samples_seen > 0 if traits_of(model).kind == "P" else False
        return bool(npm.standardizer.ready)

    @property
    def parameters(self) -> np.ndarray | None:
        """Identified base parameters in physical units (see :attr:`OnlineEstimator.parameters`)."""
        return self.estimator.physical_parameters(self._model())

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of :attr:`parameters`."""
        return self.estimator.parameter_names

    # ------------------------------------------------------------------ evaluation
    def _states(self, q: Any, dq: Any, ddq: Any) -> tuple[np.ndarray, bool]:
        """``X = [q, q̇, q̈]`` (N, 3n) and whether one state was given; shapes and values checked."""
        n = self._n
        arrays = [check_finite_array(name, v) for name, v in (("q", q), ("dq", dq), ("ddq", ddq))]
        shapes = {a.shape for a in arrays}
        if len(shapes) != 1:
            raise RejectedSampleError(f"q, dq, ddq must have one shape, got {[a.shape for a in arrays]}")
        shape = arrays[0].shape
        if shape == (n,):
            return np.concatenate(arrays)[None, :], True
        if len(shape) == 2 and shape[1] == n and shape[0] > 0:
            return np.concatenate(arrays, axis=1), False
        raise RejectedSampleError(f"q, dq, ddq must have shape ({n},) or (N, {n}) for joints "
                                  f"{list(self.joints)}, got {shape}")

    def _served_rigid(self, model: Model, consistent: bool | None) -> np.ndarray | None:
        """Return the rigid body (learner units) a prediction is asked to use, or None for the model's own."""
        traits = traits_of(model)
        if consistent is None:  # the configuration's choice, where it can be had without solving here
            consistent = (bool(self.config["parametric.consistent"])
                          and (self._attached is not None or self._solve) and traits.takes_rigid)
        if consistent:
            if not traits.takes_rigid:
                raise ValueError("consistent=True needs the consistent SP (the default) or the P learner")
            return self.estimator.column_scale * self.consistent().base
        if traits.kind == "P" and cast(ParametricModel, model).rigid_override is not None:
            return model.parameters  # asked for the learned π̂, not the projection the live P predicts with
        return None

    def _model_rows(self, X: np.ndarray, consistent: bool | None = None) -> Prediction:
        """Return the model (no fast correction) at each row of X with its relative variance, all (N, t)."""
        model = self._model()
        traits = traits_of(model)
        rigid = self._served_rigid(model, consistent)
        if traits.combination == "consistent":
            model = cast(ConsistentSemiparametricModel, model)
            if X.shape[0] == 1 and self._frozen is not None:  # a served copy: one compiled call
                key = None if rigid is None else rigid.tobytes()  # the frozen model itself never changes
                if self._one is None or self._one[0] != key:
                    self._one = (key, model.frozen_model_one(rigid))
                x = X[0]
                yp, r, var = self._one[1](x, model.parametric.phi_fresh(x))
                return Prediction(yp[None], r[None], (yp + r)[None], var[None])
            if X.shape[0] == 1:
                pred = model.predict_model(X[0], rigid)
                return Prediction(pred.parametric[None], pred.residual[None], pred.total[None],
                                  np.asarray(pred.variance)[None])
            return model.predict_model_many(X, rigid)
        if traits.kind == "P" and (X.shape[0] > 1 or rigid is not None):
            return cast(ParametricModel, model).predict_many(X, rigid)
        preds = [predict_with_variance(model, x) for x in X]  # the other learners: one state at a time
        return Prediction(np.array([p.parametric for p in preds]), np.array([p.residual for p in preds]),
                          np.array([p.total for p in preds]), np.array([p.variance for p in preds]))

    def rigid_parameters(self, *, consistent: bool | None = None) -> np.ndarray:
        """Return the base parameters (physical units) of the rigid-body part :meth:`predict` uses.

        The physically consistent projection where the prediction uses it (``consistent``, as in
        :meth:`predict_parts`), the consistent SP's reference θ_ref, else the learned π̂: so that
        :meth:`gravity` and the excluded terms of :meth:`predict` are those of the prediction.

        Raises:
            ValueError: For a model without a rigid-body part (``NP``).
        """
        model = self._model()
        traits = traits_of(model)
        if traits.kind == "NP":
            raise ValueError("this needs a rigid-body part: the model is nonparametric only")
        rigid = self._served_rigid(model, consistent)
        if rigid is None:
            rigid = (cast(ConsistentSemiparametricModel, model).reference_parameters
                     if traits.combination == "consistent" else model.parameters)
        return np.asarray(rigid, dtype=np.float64) / self.estimator.column_scale

    def _std(self, variance: np.ndarray, X: np.ndarray) -> np.ndarray:
        """σ at the rows of X: c_m sqrt(s²_m (1 + v)), m each output's motion state (one-step σ without)."""
        if X.shape[0] == 1 and self._frozen is not None:  # a served copy at one state: one compiled call
            arrays = self._sigma_one
            if arrays is None:
                s2 = self._noise_s2()
                t = variance.shape[1]
                scales, per_state = self._calibration()
                nan = np.full((t, len(STATES)), np.nan)
                arrays = self._sigma_one = (
                    np.full(t, np.inf) if s2 is None else np.array(s2, dtype=np.float64),
                    nan if per_state is None else np.array(scales, dtype=np.float64),
                    nan if per_state is None else np.array(per_state, dtype=np.float64))
            out = np.empty(variance.shape[1])
            served_sigma_one(np.ascontiguousarray(variance[0], dtype=np.float64), X[0], self._n, *arrays, out)
            return out[None]
        relative = 1.0 + np.fmax(variance, 0.0)
        s2 = self._noise_s2()
        one_step = np.full(variance.shape, np.inf) if s2 is None else np.sqrt(s2 * relative)
        scales, per_state = self._calibration()
        if per_state is None or np.isnan(scales).all():
            return one_step
        states = motion_states(X, self._n, scales.shape[0])
        c = np.take_along_axis(scales.T, states, axis=0)
        s2_m = np.take_along_axis(per_state.T, states, axis=0)
        served = c * np.sqrt(s2_m * relative)
        return np.where(np.isnan(served), one_step, served)

    def predict_parts(self, q: Any, dq: Any, ddq: Any, *, consistent: bool | None = None,
                      exclude: Sequence[str] = (), exclude_source: str = "model",
                      history: StickState | None = None) -> ModelPrediction:
        """Return the model and its parts at one state or N states.

        N states are one time sequence: with friction that remembers (joint torques,
        ``parametric.stick_displacement`` > 0) each joint's stick state is carried along the rows, from
        ``history`` or else from where the measured path left it (:meth:`stick_state`), and the torque it
        holds is part of the rigid-body part and the total.

        Args:
            q: Positions (n,) or (N, n) [rad].
            dq: Velocities, same shape [rad/s].
            ddq: Accelerations, same shape [rad/s²].
            consistent: Use the physically consistent rigid-body parameters (:meth:`consistent`) instead
                of the unconstrained estimate; the residual follows them. Better outside the excited range
                (real KUKA, frozen on a faster motion: 2.7× lower error; docs/identification.md). None:
                ``parametric.consistent`` of the configuration (on by default; a model that may not
                solve here — the node's served copy — uses it once its worker's solution is attached).
            exclude: Terms left out of the total and the rigid-body part (:meth:`excluded`): ``gravity``
                and/or ``friction`` (with the torque the stick state holds, :meth:`stick_torque`), for a
                robot that compensates them itself. σ is unchanged.
            exclude_source: Whose gravity is left out: ``model`` or ``urdf`` (:meth:`excluded`).
            history: Where the sequence starts (changed: it ends at the last row), e.g. a controller's
                previous desired state; None: the measured path's state, unchanged.

        Returns:
            Total, rigid-body part, residual and σ, each (t,) or (N, t).

        Raises:
            RejectedSampleError: Wrong shapes, NaN/inf or absurdly large values (nothing is changed).
        """
        X, single = self._states(q, dq, ddq)
        pred = self._model_rows(X, consistent)
        assert pred.variance is not None  # every path returns it
        std = self._std(np.asarray(pred.variance), X)
        total, rigid, residual = pred.total, pred.parametric, pred.residual
        n = self._n
        held = self._stick_torque(X[:, :n], X[:, n:2 * n], history)
        if held is not None and "friction" not in exclude:
            total, rigid = total + held, rigid + held
        if exclude:
            left_out = self.excluded(X[:, :n], X[:, n:2 * n], exclude, source=exclude_source,
                                     consistent=consistent)
            total, rigid = total - left_out, rigid - left_out
        if single:
            return ModelPrediction(total[0].copy(), rigid[0].copy(), residual[0].copy(), std[0].copy())
        return ModelPrediction(total, rigid, residual, std)

    def predict(self, q: Any, dq: Any, ddq: Any, *, consistent: bool | None = None,
                exclude: Sequence[str] = (), exclude_source: str = "model") -> tuple[np.ndarray, np.ndarray]:
        """``(τ, σ)``: the model at one state (n,) → (t,), or N states (N, n) → (N, t).

        Many states in one call are far cheaper per state than single calls (one matrix product and one
        triangular solve for all of them; measured in ``bench/node/bench_serving.py``).

        Args:
            q: Positions (n,) or (N, n) [rad], in the order of :attr:`joints`.
            dq: Velocities [rad/s], same shape.
            ddq: Accelerations [rad/s²], same shape.
            consistent: Use the physically consistent rigid-body parameters (see :meth:`predict_parts`).
            exclude: Terms left out: ``gravity`` and/or ``friction`` (see :meth:`predict_parts`).
            exclude_source: Whose gravity is left out: ``model`` or ``urdf``.

        Returns:
            The prediction [N·m] and its standard deviation [N·m] (σ is the model's, whatever is left out).

        Raises:
            RejectedSampleError: Wrong shapes, NaN/inf or absurdly large values.
        """
        parts = self.predict_parts(q, dq, ddq, consistent=consistent, exclude=exclude,
                                   exclude_source=exclude_source)
        return parts.total, parts.std

    def gravity(self, q: Any, *, consistent: bool | None = None) -> np.ndarray:
        """Gravity torques (or the gravity wrench at the sensor) of the rigid body :meth:`predict` uses.

        ``Φ(q, 0, 0) π`` with the friction, offset and armature columns left out — what holds the arm still
        at q (no residual, no offsets) — with π the parameters of the prediction's rigid-body part
        (:meth:`rigid_parameters`: the consistent projection by default).

        Args:
            q: Positions (n,) or (N, n) [rad].
            consistent: As in :meth:`predict_parts`.

        Returns:
            (t,) or (N, t) [N·m].

        Raises:
            RejectedSampleError: Wrong shape or non-finite q.
            ValueError: For a model without a rigid-body part (``NP``).
        """
        return self._gravity(check_finite_array("q", q), self.rigid_parameters(consistent=consistent))

    def _gravity(self, qa: np.ndarray, params: np.ndarray) -> np.ndarray:
        zeros = np.zeros_like(qa)
        Phi = self.estimator.regressor.base_regressor(qa, zeros, zeros)
        return np.asarray(Phi[..., self._inertial] @ params[self._inertial])

    def friction(self, dq: Any, *, consistent: bool | None = None) -> np.ndarray:
        """Joint friction torques of the rigid body :meth:`predict` uses: viscous and Coulomb, at q̇ [N·m].

        Zero for a model without friction columns (``parametric.friction: false``, a wrench).

        Args:
            dq: Velocities (n,) or (N, n) [rad/s].
            consistent: As in :meth:`predict_parts`.

        Raises:
            RejectedSampleError: Wrong shape or non-finite q̇.
            ValueError: For a model without a rigid-body part (``NP``).
        """
        params = self.rigid_parameters(consistent=consistent)
        return self._friction_torques(check_finite_array("dq", dq), params)

    def _friction_torques(self, dqa: np.ndarray, params: np.ndarray) -> np.ndarray:
        if not self._friction.any():
            return np.zeros((*dqa.shape[:-1], len(self.output_names)))
        zeros = np.zeros_like(dqa)
        Phi = self.estimator.regressor.base_regressor(zeros, dqa, zeros)
        return np.asarray(Phi[..., self._friction] @ params[self._friction])

    def excluded(self, q: Any, dq: Any, exclude: Sequence[str], *, source: str = "model",
                 consistent: bool | None = None) -> np.ndarray:
        """Return the terms ``predict(..., exclude=...)`` leaves out, summed [N·m].

        Args:
            q: Positions (n,) or (N, n) [rad].
            dq: Velocities, same shape [rad/s].
            exclude: A subset of :data:`EXCLUDABLE` (``gravity``, ``friction``).
            source: ``model``: the model's own terms (the rigid body of the prediction); ``urdf``: the
                URDF's CAD gravity (a robot that compensates gravity with its own CAD model; the learned
                difference then stays in the command). Friction is always the model's.
            consistent: As in :meth:`predict_parts`.

        Raises:
            ValueError: An unknown term or source, or a model without a rigid-body part.
        """
        unknown = sorted(set(exclude) - set(EXCLUDABLE))
        if unknown or source not in EXCLUDE_SOURCES:
            raise ValueError(f"exclude must be a subset of {EXCLUDABLE} and source one of {EXCLUDE_SOURCES}; "
                             f"got {list(exclude)}, {source!r}")
        qa = check_finite_array("q", q)
        out = np.zeros((*qa.shape[:-1], len(self.output_names)))
        if "gravity" in exclude and source == "urdf":
            out += self.cad(qa, np.zeros_like(qa), np.zeros_like(qa))
        model_terms = [t for t in exclude if t == "friction" or source == "model"]
        if model_terms:  # the prediction's rigid body, read once for both terms
            params = self.rigid_parameters(consistent=consistent)
            if "gravity" in model_terms:
                out += self._gravity(qa, params)
            if "friction" in model_terms:
                out += self._friction_torques(check_finite_array("dq", dq), params)
        return out

    def stick_torque(self, q: Any, dq: Any, history: StickState | None = None) -> np.ndarray:
        """Return the torque the joints' stick state holds along a path of states [N·m].

        Friction that remembers, ``c_j (z_j − tanh(q̇_j/v_s))`` with z carried along the rows
        (:mod:`semiparam_ros.core.learners.stick`):
        the part of the prediction's friction beyond :meth:`friction`; zeros without it (a wrench,
        ``parametric.stick_displacement: 0``).

        Args:
            q: Positions (n,) or (N, n) in time order [rad].
            dq: Velocities, same shape [rad/s].
            history: Where the path starts (changed: it ends at the last row); None: the measured path's.

        Raises:
            RejectedSampleError: Wrong shapes or non-finite values.
        """
        X, single = self._states(q, dq, dq)  # q and q̇ checked as predict checks them (q̈ is not used)
        n = self._n
        held = self._stick_torque(X[:, :n], X[:, n:2 * n], history)
        out = np.zeros((X.shape[0], len(self.output_names))) if held is None else held
        return out[0] if single else out

    def _stick_torque(self, q: np.ndarray, dq: np.ndarray, history: StickState | None) -> np.ndarray | None:
        stick = self._stick()
        if stick is None:
            return None
        return stick.held(q, dq, history if history is not None else stick.state.copy())

    def cad(self, q: Any, dq: Any, ddq: Any) -> np.ndarray:
        """Return the CAD model: RNEA with the URDF's inertial parameters, no friction or offsets [N·m].

        Args:
            q: Positions (n,) or (N, n) [rad].
            dq: Velocities [rad/s], same shape.
            ddq: Accelerations [rad/s²], same shape.

        Returns:
            (t,) or (N, t).

        Raises:
            RejectedSampleError: Wrong shapes or non-finite values.
        """
        reg = self.estimator.regressor
        Phi = reg.regressor(q, dq, ddq)
        return np.asarray(Phi @ self._cad_full)


def load_model(path: str | os.PathLike[str]) -> LearnedModel:
    """Load a learned model from a self-contained checkpoint (no configuration or URDF file needed).

    Args:
        path: A checkpoint written by the node (``~/save``, periodic, final), by ``learn`` or by
            :meth:`OnlineEstimator.save`.

    Returns:
        The model, ready to predict.

    Raises:
        CheckpointError: Missing, truncated, corrupt or foreign file; a checkpoint of an older version
            without its configuration; a state that does not fit its own configuration.

    Warns:
        CheckpointMigrationWarning: Once, for a checkpoint of an older format (what it lacked, e.g. the
            calibration of σ for new motion, and what is served instead).
    """
    state = load_npz(Path(path).expanduser())
    config, urdf, versions = read_config(path, state)
    try:
        regressor = build_regressor(config, urdf_xml=urdf)
        estimator = OnlineEstimator(config, regressor=regressor, kind=learner_kind(state))
    except (ConfigurationError, OSError) as err:
        raise CheckpointError(f"{path}: cannot rebuild the model it holds: {err}") from err
    estimator.load_state(state, str(path))
    if estimator.migration_notes:  # an older format: what it lacks and what is served instead, once
        warnings.warn("; ".join(estimator.migration_notes), CheckpointMigrationWarning, stacklevel=2)
    model = LearnedModel(estimator)
    model.versions = versions
    return model


class CheckpointMigrationWarning(UserWarning):
    """A checkpoint of an older format was read: the message says what it lacked and what is used instead."""
