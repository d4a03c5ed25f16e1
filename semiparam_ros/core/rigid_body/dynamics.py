"""Rigid-body regressors from a URDF with Pinocchio: six-axis F/T sensor and joint torques.

Inverse dynamics is linear in the inertial parameters, ``y = Φ(q, q̇, q̈) π``. This module builds ``Φ``
for a fixed-base robot described by a URDF, for two kinds of measurement ``y``:

* ``output=OutputKind.WRENCH``: the reading of a six-axis force/torque sensor mounted on a *fixed* URDF joint.
  The reading is the wrench that the **distal** subtree (the links beyond the sensor) exerts on the
  proximal link, expressed in the sensor frame (the child frame of the sensor joint), force first then
  torque: ``[fx, fy, fz, tx, ty, tz]`` in N and N·m (iDynTree's ``child_to_parent`` convention; at rest
  the force is the distal weight and points along gravity).
* ``output=OutputKind.JOINT_TORQUES``: the torques (N·m, or N for prismatic joints) of the moving joints,
  in the caller's joint order.

Pinocchio merges fixed joints into their parent body, which would lump the links beyond the sensor with
the link before it. The sensor joint is therefore turned into a 6-DoF (free-flyer) joint that is always
kept at the identity with zero velocity and acceleration: the kinematics and dynamics are unchanged, the
distal subtree becomes a separate set of bodies, and the six "joint torques" of that joint are exactly the
spatial force transmitted through it, expressed in its frame. Pinocchio's joint-torque regressor then gives
the sensor regressor in one compiled call.

Each body contributes 10 parameters in Pinocchio's order ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz,
Izz]`` (kg, kg·m, kg·m²), with the first moment and the rotational inertia taken about the origin of the
body frame. A "body" is a moving (or sensor) joint together with every link rigidly attached to it after
the locked joints are frozen; it is named after the child link of that joint and its frame is that
joint's frame.

Only some combinations of the parameters are identifiable from ``y``: the base parameters, found
numerically by a rank-revealing QR factorisation of the regressor stacked at many random states.

Joint friction, offsets and armature (``output=OutputKind.JOINT_TORQUES``). Real joint-torque measurements
carry what the rigid-body model lacks; each option appends one column per joint (non-zero only in that joint's
row ``i``), in blocks after the inertial columns, named ``<joint>.<kind>``:

* ``friction``: viscous ``f_v,i · q̇_i`` (``<joint>.viscous``, N·m·s/rad) and Coulomb
  ``f_c,i · tanh(q̇_i / v_s)`` (``<joint>.coulomb``, N·m), a smooth sign with velocity scale ``v_s``
  (``coulomb_velocity``, rad/s);
* ``joint_offsets``: a constant ``o_i`` (``<joint>.offset``, N·m): torque-sensor offset or gravity
  mis-modelling that does not depend on the state;
* ``armature``: ``I_a,i · q̈_i`` (``<joint>.armature``, kg·m²): reflected rotor inertia. For a joint
  whose axis is fixed in the base (the first joint) it duplicates an inertia column and merges into
  that base parameter.

Their URDF value is 0 (the URDF's ``<dynamics damping>`` is not used: it is a simulation setting).
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pinocchio as pin
import scipy.linalg

from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.core.rigid_body.urdf import RegressorSpec, prepare_urdf
from semiparam_ros.core.validation import as_float_array
from semiparam_ros.errors import ConfigurationError, RejectedSampleError

__all__ = [
    "INERTIAL_PARAMETER_NAMES",
    "BaseParameterMap",
    "RigidBodyRegressor",
    "is_physically_consistent",
    "point_mass_parameters",
]

#: Names of the 10 inertial parameters of one body, in Pinocchio's order (about the body frame origin).
INERTIAL_PARAMETER_NAMES: tuple[str, ...] = (
    "m",
    "mcx",
    "mcy",
    "mcz",
    "Ixx",
    "Ixy",
    "Iyy",
    "Ixz",
    "Iyz",
    "Izz",
)

_WRENCH_NAMES: tuple[str, ...] = ("fx", "fy", "fz", "tx", "ty", "tz")

#: Relative rank tolerance of the base-parameter QR (on unit-norm columns). Structural dependencies show
#: up at ~1e-15 relative; identifiable directions of the robots tested here are above ~1e-4.
BASE_RANK_TOLERANCE = 1e-9
#: Columns whose norm is below this fraction of the largest are treated as exactly zero.
_NULL_COLUMN = 1e-10
#: Coefficients of the base-parameter combinations smaller than this are round-off and set to zero.
_COEFFICIENT_ZERO = 1e-10


def point_mass_parameters(mass: float, position: Sequence[float] | np.ndarray) -> np.ndarray:
    """Return the 10 inertial parameters of a point mass, about the origin of the frame it is given in.

    Adding these to a body's slot of :meth:`RigidBodyRegressor.urdf_parameters` models a payload rigidly
    attached to that body.

    Args:
        mass: The mass in kg (≥ 0).
        position: The point's position (3,) in m, in the body frame.

    Returns:
        ``[m, m·cx, m·cy, m·cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (kg, kg·m, kg·m²), with
        ``I = m (‖c‖² 1 − c cᵀ)`` the point's rotational inertia about the frame origin.

    Raises:
        ConfigurationError: If the mass is negative or not finite, or the position is not 3 finite numbers.
    """
    m = float(mass)
    if not math.isfinite(m) or m < 0.0:
        raise ConfigurationError(f"point mass must be finite and >= 0 kg, got {mass!r}")
    c = as_float_array("point-mass position", position, error=ConfigurationError)
    if c.shape != (3,):
        raise ConfigurationError(f"point-mass position must have shape (3,), got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ConfigurationError(f"point-mass position must be finite, got {c}")
    cx, cy, cz = c
    return np.array(
        [
            m,
            m * cx,
            m * cy,
            m * cz,
            m * (cy * cy + cz * cz),
            -m * cx * cy,
            m * (cx * cx + cz * cz),
            -m * cx * cz,
            -m * cy * cz,
            m * (cx * cx + cy * cy),
        ]
    )


def is_physically_consistent(params: Sequence[float] | np.ndarray, *, tol: float = 1e-12) -> bool:
    """Tell whether 10 inertial parameters describe a physical rigid body.

    Checks m > 0 and that the rotational inertia about the centre of mass, ``I_c = I_o − m(‖c‖² 1 − c cᵀ)``
    with ``c = mc/m``, has non-negative principal moments obeying the triangle inequalities
    (``Iᵢ + Iⱼ ≥ Iₖ``, i.e. a non-negative second moment of the mass distribution). Useful to vet a URDF,
    a simulated payload, or an identified full-parameter vector.

    Args:
        params: ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (kg, kg·m, kg·m²) about the body origin.
        tol: Absolute tolerance (kg·m²) on the moment inequalities.

    Returns:
        True if the parameters are physically consistent.

    Raises:
        ConfigurationError: If ``params`` is not 10 finite numbers.
    """
    p = as_float_array("params", params, error=ConfigurationError)
    if p.shape != (10,) or not np.all(np.isfinite(p)):
        raise ConfigurationError(f"params must be 10 finite inertial parameters, got shape {p.shape}")
    m = p[0]
    if m <= 0.0:
        return False
    c = p[1:4] / m
    I_o = np.array([[p[4], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]])
    I_c = I_o - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    moments = np.linalg.eigvalsh(I_c)
    if moments[0] < -tol:
        return False
    # Second moments of the mass distribution along the principal axes: (tr/2 − I_k) ≥ 0.
    return bool(np.all(0.5 * moments.sum() - moments >= -tol))


@dataclass(frozen=True)
class BaseParameterMap:
    """The identifiable (base) parameters as combinations of the full parameters.

    With ``Φ`` the full regressor, ``Φ[:, dependent] = Φ[:, independent] @ coefficients`` on every state,
    so ``Φ π = Φ[:, independent] @ (π[independent] + coefficients @ π[dependent])``.

    Attributes:
        independent: Indices (ascending) of the full-parameter columns kept as the base regressor.
        dependent: Indices (ascending) of the remaining columns (unidentifiable alone or not at all).
        coefficients: (n_base, n_dependent) combination matrix.
        names: Human-readable name of each base parameter, e.g. ``"m_r_upper_arm + 0.068*mcz_r_elbow_1"``.
        projection: (n_base, n_params) matrix ``K`` with ``π_base = K π``.
        singular_ratios: ``|R_ii| / |R_00|`` of the pivoted QR of the column-scaled stacked regressor,
            in pivot order (how clearly the rank was revealed).
        column_rms: (n_base,) RMS of each base-regressor column over the same random states (units of
            y per unit of the parameter): the characteristic magnitude used to scale the columns so that
            one ridge λ acts alike on all parameters; ``None`` if not computed.
    """

    independent: np.ndarray
    dependent: np.ndarray
    coefficients: np.ndarray
    names: tuple[str, ...]
    projection: np.ndarray
    singular_ratios: np.ndarray
    column_rms: np.ndarray | None = None

    @property
    def n_base(self) -> int:
        """Number of base parameters."""
        return int(self.independent.size)


class RigidBodyRegressor:
    """Linear-in-parameters rigid-body model ``y = Φ(q, q̇, q̈) π`` of a fixed-base robot.

    Build it with :meth:`from_urdf`. The object holds one immutable reduced Pinocchio model and one
    preallocated ``pinocchio.Data`` workspace that every call reuses, so it is **not thread-safe** (use
    one instance per thread; ``copy.deepcopy`` gives an independent one). It pickles and deep-copies by
    rebuilding from the stored URDF text and arguments (deterministic, a few ms).

    Attributes:
        joint_names: The moving joints, in the caller's order (the order of q, q̇, q̈).
        output: ``OutputKind.WRENCH`` or ``OutputKind.JOINT_TORQUES``.
        sensor_frame: Name of the F/T sensor joint (its frame is the sensor frame: the child frame of the
            fixed joint, which coincides with the child link's frame), or None.
        body_names: Name (child link of the joint) of each body whose 10 parameters are in ``π``.
        parameter_names: ``"<param>_<body>"`` for each column, then ``"offset_<output>"`` for the
            constant sensor offsets when enabled, then ``"<joint>.<kind>"`` for the per-joint extra
            columns (see the module docstring).
        output_names: ``fx … tz`` for a wrench, the joint names for torques.
        gravity: Gravity (3,) in m/s², in the URDF root frame.
        locked: The position (rad or m) of every locked joint that was given a non-zero value.
        robot_name: The URDF's ``<robot name=…>`` ("" when unnamed).
    """

    def __init__(self, urdf_xml: str, spec: RegressorSpec, *, source: str | None = None) -> None:
        """Build the regressor from URDF text (prefer :meth:`from_urdf`, which reads a file).

        Args:
            urdf_xml: The URDF text.
            spec: What to model: joints, sensor, locked joints, gravity, output and extra columns.
            source: Where the text came from (messages only).

        Raises:
            ConfigurationError: See :meth:`from_urdf`; also when ``spec`` is not a
                :class:`~semiparam_ros.core.rigid_body.urdf.RegressorSpec`.
        """
        if not isinstance(spec, RegressorSpec):
            raise ConfigurationError(f"RigidBodyRegressor takes a RegressorSpec, got {type(spec).__name__} "
                                     "(from_urdf takes the joints with keyword options)")
        self._urdf_xml = urdf_xml
        self.source = source
        self.output = spec.output
        self.extra_kinds: tuple[str, ...] = spec.extra_kinds
        self.coulomb_velocity = spec.coulomb_velocity
        joint_names, ft_sensor, output = spec.joints, spec.ft_sensor, spec.output
        prepared = prepare_urdf(urdf_xml, spec, source)
        self.robot_name = prepared.robot_name
        child_link = prepared.child_link
        locked_values = prepared.locked
        self.sensor_frame: str | None = spec.ft_sensor
        self.locked = dict(locked_values)
        self.gravity = np.array(prepared.gravity, dtype=float)
        #: What this regressor was built from (checked; pickling rebuilds from it and the URDF text).
        self.spec = replace(spec, locked=dict(locked_values), gravity=prepared.gravity)

        try:
            full = pin.buildModelFromXML(prepared.xml)
        except Exception as err:  # Pinocchio raises RuntimeError/ValueError with its own message
            raise ConfigurationError(
                f"Pinocchio could not build a model from the URDF{f' in {source}' if source else ''}: {err}"
            ) from err
        q_ref = pin.neutral(full)
        for name, val in locked_values.items():
            jmodel = full.joints[full.getJointId(name)]
            if jmodel.nq == 1:
                q_ref[jmodel.idx_q] = val
            else:  # continuous joint: (cos, sin)
                q_ref[jmodel.idx_q] = math.cos(val)
                q_ref[jmodel.idx_q + 1] = math.sin(val)
        keep = set(joint_names)
        if ft_sensor is not None:
            keep.add(ft_sensor)
        to_lock = [jid for jid in range(1, full.njoints) if full.names[jid] not in keep]
        model = pin.buildReducedModel(full, to_lock, q_ref) if to_lock else full.copy()
        model.gravity = pin.Motion(self.gravity, np.zeros(3))
        self._model = model
        self._data = model.createData()

        # Joint indexing in the reduced model (caller order).
        self.joint_names: tuple[str, ...] = joint_names
        jids = [model.getJointId(name) for name in joint_names]
        self._jids = np.array(jids, dtype=int)
        self._idx_q = np.array([model.joints[j].idx_q for j in jids], dtype=int)
        self._idx_v = np.array([model.joints[j].idx_v for j in jids], dtype=int)
        self._continuous = np.array([model.joints[j].nq == 2 for j in jids], dtype=bool)
        self._q_index = _as_slice(self._idx_q)
        self._v_index = _as_slice(self._idx_v)
        self._any_continuous = bool(self._continuous.any())

        # Output rows and body columns of Pinocchio's joint-torque regressor.
        if output == OutputKind.WRENCH:
            sid = model.getJointId(ft_sensor)
            v0 = model.joints[sid].idx_v
            self._rows: slice | np.ndarray = slice(v0, v0 + 6)
            body_jids = sorted(int(j) for j in model.subtrees[sid])
            self._sign = -1.0  # Pinocchio gives the force the proximal side applies on the subtree.
            self.output_names: tuple[str, ...] = _WRENCH_NAMES
        else:
            self._rows = _as_slice(self._idx_v)
            body_jids = list(range(1, model.njoints))
            self._sign = 1.0
            self.output_names = joint_names
        self._body_jids = np.array(body_jids, dtype=int)
        cols = np.concatenate([np.arange(10 * (j - 1), 10 * j) for j in body_jids])
        self._cols = _as_slice(cols)
        self.body_names: tuple[str, ...] = tuple(str(child_link[model.names[j]]) for j in body_jids)
        self.n_joints = len(joint_names)
        self.n_outputs = len(self.output_names)
        self.n_bodies = len(body_jids)
        self.sensor_offset = bool(spec.sensor_offset)
        self._n_rigid = 10 * self.n_bodies
        self._n_offset = self.n_outputs if self.sensor_offset else 0
        self.n_params = self._n_rigid + self._n_offset + len(self.extra_kinds) * self.n_joints
        names = [f"{p}_{b}" for b in self.body_names for p in INERTIAL_PARAMETER_NAMES]
        if self.sensor_offset:
            names += [f"offset_{o}" for o in self.output_names]
        names += [f"{j}.{kind}" for kind in self.extra_kinds for j in joint_names]
        self.parameter_names: tuple[str, ...] = tuple(names)
        self._diag = np.arange(self.n_joints)

        # Preallocated state vectors: the sensor free-flyer stays at the identity, v = a = 0.
        self._q = pin.neutral(model)
        self._v = np.zeros(model.nv)
        self._a = np.zeros(model.nv)
        self._eye = np.eye(self.n_outputs)

        lower = model.lowerPositionLimit[self._idx_q].copy()
        upper = model.upperPositionLimit[self._idx_q].copy()
        lower[self._continuous] = -np.inf
        upper[self._continuous] = np.inf
        self._lower, self._upper = lower, upper
        self._vlim = model.velocityLimit[self._idx_v].copy()

        # Distal body: deepest in the tree (ties: the last); it carries the end effector / hand.
        depth = [len(model.supports[j]) for j in body_jids]
        self._distal = max(range(len(body_jids)), key=lambda i: (depth[i], i))

        self._urdf_params = np.zeros(self.n_params)
        for i, jid in enumerate(body_jids):
            self._urdf_params[10 * i : 10 * i + 10] = model.inertias[int(jid)].toDynamicParameters()

        self._base = self.compute_base_parameters(seed=spec.base_seed, n_samples=spec.base_samples)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_urdf(cls, urdf_path: str | pathlib.Path, joints: Sequence[str] | RegressorSpec,
                  **options: Any) -> RigidBodyRegressor:
        """Build the regressor of a fixed-base robot from a URDF file.

        Args:
            urdf_path: Path of the URDF file. The base link is fixed.
            joints: A :class:`~semiparam_ros.core.rigid_body.urdf.RegressorSpec` (the joints, the sensor,
                locked joints, gravity, output and extra columns), or its ``joints`` — the moving joints
                (revolute, continuous or prismatic) in the order of q, q̇, q̈ — with the other fields as
                keywords.
            **options: The other fields of :class:`~semiparam_ros.core.rigid_body.urdf.RegressorSpec`.

        Returns:
            The regressor.

        Raises:
            FileNotFoundError: If ``urdf_path`` is not a file.
            ConfigurationError: For unknown or ill-typed joint/sensor names, non-finite locked positions or
                gravity, an unknown output or option, or a URDF Pinocchio cannot load.
        """
        path = pathlib.Path(urdf_path)
        if not path.is_file():
            raise FileNotFoundError(f"URDF file not found: {path}")
        return cls(path.read_text(encoding="utf-8"), _spec(joints, options), source=str(path))

    @property
    def body_links(self) -> tuple[tuple[str, ...], ...]:
        """For each body of ``π`` (in ``body_names`` order), the URDF links its parameters include.

        The body's own link first, then the links the reduced model merged into it (fixed children, and
        the children of locked joints at their configured positions).
        """
        model = self._model
        out = []
        for body, jid in zip(self.body_names, self._body_jids, strict=True):
            names = [f.name for f in model.frames
                     if f.type == pin.FrameType.BODY and f.parentJoint == int(jid) and f.name != body]
            out.append((body, *names))
        return tuple(out)

    @property
    def urdf_xml(self) -> str:
        """The URDF text this regressor was built from (what a self-contained checkpoint stores)."""
        return self._urdf_xml

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickle/deepcopy by rebuilding from the URDF text and the spec."""
        return (_rebuild, (self._urdf_xml, self.spec, self.source))

    def __repr__(self) -> str:
        return (
            f"RigidBodyRegressor(output={self.output!r}, joints={list(self.joint_names)}, "
            f"sensor={self.sensor_frame!r}, n_params={self.n_params}, n_base={self.n_base})"
        )

    # ------------------------------------------------------------------ input checks
    def _vector(self, name: str, value: Any) -> np.ndarray:
        arr = as_float_array(name, value)
        if arr.shape != (self.n_joints,):
            raise RejectedSampleError(
                f"{name} must have shape ({self.n_joints},) for joints {list(self.joint_names)}, "
                f"got {arr.shape}"
            )
        if not np.isfinite(arr).all():
            bad = [self.joint_names[i] for i in np.flatnonzero(~np.isfinite(arr))]
            raise RejectedSampleError(f"{name} has non-finite values at joint(s) {bad}")
        return arr

    def _batch(self, q: Any, dq: Any, ddq: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        arrays = []
        for name, value in (("q", q), ("dq", dq), ("ddq", ddq)):
            arr = as_float_array(name, value)
            if arr.ndim != 2 or arr.shape[1] != self.n_joints:
                raise RejectedSampleError(
                    f"{name} must have shape (k, {self.n_joints}) for joints {list(self.joint_names)}, "
                    f"got {arr.shape}"
                )
            if not np.isfinite(arr).all():
                cols = sorted({int(c) for c in np.nonzero(~np.isfinite(arr))[1]})
                raise RejectedSampleError(
                    f"{name} has non-finite values at joint(s) {[self.joint_names[c] for c in cols]}"
                )
            arrays.append(arr)
        if not arrays[0].shape == arrays[1].shape == arrays[2].shape:
            raise RejectedSampleError(f"q, dq, ddq have different shapes {[a.shape for a in arrays]}")
        return arrays[0], arrays[1], arrays[2]

    # ------------------------------------------------------------------ regressors
    def _fill(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> None:
        if self._any_continuous:
            for i in range(self.n_joints):
                k = self._idx_q[i]
                if self._continuous[i]:
                    self._q[k] = math.cos(q[i])
                    self._q[k + 1] = math.sin(q[i])
                else:
                    self._q[k] = q[i]
        else:
            self._q[self._q_index] = q
        self._v[self._v_index] = dq
        self._a[self._v_index] = ddq

    def _block(self) -> np.ndarray:
        # Pinocchio returns a fresh (nv, 10·n_bodies) array; the rows/columns of interest are a view.
        Y = pin.computeJointTorqueRegressor(self._model, self._data, self._q, self._v, self._a)
        return Y[self._rows, self._cols] if isinstance(self._rows, slice) else Y[self._rows][:, self._cols]

    def _rigid(self, out: np.ndarray) -> None:
        if self._sign < 0:
            np.negative(self._block(), out=out[:, : self._n_rigid])
        else:
            out[:, : self._n_rigid] = self._block()

    def regressor(self, q: Any, dq: Any, ddq: Any) -> np.ndarray:
        """Return the regressor ``Φ`` with ``y = Φ π`` (a new array).

        Args:
            q: Joint positions (n,) in rad (m for prismatic joints), in the order of ``joint_names``;
                or (k, n) for k states.
            dq: Joint velocities (n,) in rad/s, or (k, n).
            ddq: Joint accelerations (n,) in rad/s², or (k, n).

        Returns:
            (n_outputs, n_params), or (k, n_outputs, n_params) for batched input. For a wrench the rows
            are ``[fx, fy, fz, tx, ty, tz]`` (N, N·m) of the sensor reading in the sensor frame.

        Raises:
            RejectedSampleError: If a vector has the wrong length or non-finite values (named in the
                message).
        """
        q_arr = as_float_array("q", q)
        if q_arr.ndim == 2:
            qs, dqs, ddqs = self._batch(q_arr, dq, ddq)
            out = np.zeros((qs.shape[0], self.n_outputs, self.n_params))
            for i in range(qs.shape[0]):
                self._fill(qs[i], dqs[i], ddqs[i])
                self._rigid(out[i])
                self._extra(out[i], dqs[i], ddqs[i])
            return out
        dq_arr = as_float_array("dq", dq)
        ddq_arr = as_float_array("ddq", ddq)
        n = self.n_joints
        # Hot path (1 kHz): one cheap finiteness test for all three vectors (3 dots ≈ 1 µs instead of
        # 3 isfinite().all() ≈ 4 µs). The sum of squares is finite iff every entry is, except that entries
        # above ~1e154 overflow it (numpy then warns once): those only send us to the exact check below.
        if (
            q_arr.shape != (n,)
            or dq_arr.shape != (n,)
            or ddq_arr.shape != (n,)
            or not math.isfinite(q_arr.dot(q_arr) + dq_arr.dot(dq_arr) + ddq_arr.dot(ddq_arr))
        ):
            q_arr = self._vector("q", q_arr)
            dq_arr = self._vector("dq", dq_arr)
            ddq_arr = self._vector("ddq", ddq_arr)
        self._fill(q_arr, dq_arr, ddq_arr)
        if self.n_params > self._n_rigid:
            out = np.empty((self.n_outputs, self.n_params))
            self._rigid(out)
            self._extra(out, dq_arr, ddq_arr)
            return out
        return -self._block() if self._sign < 0 else self._block().copy()

    def _extra(self, out: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> None:
        """Write the sensor-offset and per-joint extra columns into ``out``.

        One state: ``out`` (t, n_params), ``dq``/``ddq`` (n,); N states: (N, t, n_params) and (N, n).
        """
        c = self._n_rigid
        lead = (slice(None),) * (out.ndim - 1)  # the rows (and states) before the columns
        if self.sensor_offset:
            out[(*lead, slice(c, c + self.n_outputs))] = self._eye
            c += self.n_outputs
        n, d = self.n_joints, self._diag
        diag: tuple[slice | np.ndarray, ...] = (*lead[:-1], d, d)  # each joint's own row and column
        for kind in self.extra_kinds:
            block = out[(*lead, slice(c, c + n))]
            block.fill(0.0)
            if kind == "viscous":
                block[diag] = dq
            elif kind == "coulomb":
                block[diag] = np.tanh(dq / self.coulomb_velocity)
            elif kind == "offset":
                block[diag] = 1.0
            else:  # armature
                block[diag] = ddq
            c += n

    def wrench(self, q: Any, dq: Any, ddq: Any, params: Any = None) -> np.ndarray:
        """Return the model's output ``Φ(q, q̇, q̈) π`` (the sensor wrench, or the joint torques).

        Args:
            q: Joint positions (n,) in rad, or (k, n).
            dq: Joint velocities (n,) in rad/s, or (k, n).
            ddq: Joint accelerations (n,) in rad/s², or (k, n).
            params: Full parameters (n_params,); default :meth:`urdf_parameters`.

        Returns:
            (n_outputs,) or (k, n_outputs): ``[fx, fy, fz, tx, ty, tz]`` in N, N·m for a wrench, torques in
            N·m for ``output=OutputKind.JOINT_TORQUES``.

        Raises:
            RejectedSampleError: On bad state vectors.
            ConfigurationError: On a parameter vector of the wrong length or non-finite.
        """
        pi = self.urdf_parameters() if params is None else self._params("params", params, self.n_params)
        return self.regressor(q, dq, ddq) @ pi

    def urdf_parameters(self) -> np.ndarray:
        """Return the full parameter vector of the URDF's inertias (offsets, if enabled, are 0).

        Returns:
            (n_params,): per body ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (kg, kg·m, kg·m²)
            about the body frame origin, in the order of ``body_names``.
        """
        return self._urdf_params.copy()

    def _params(self, name: str, value: Any, n: int) -> np.ndarray:
        arr = as_float_array(name, value, error=ConfigurationError)
        if arr.shape != (n,):
            raise ConfigurationError(f"{name} must have shape ({n},), got {arr.shape}")
        if not np.isfinite(arr).all():
            bad = [
                self.parameter_names[i] if n == self.n_params else i
                for i in np.flatnonzero(~np.isfinite(arr))
            ]
            raise ConfigurationError(f"{name} has non-finite values at {bad}")
        return arr

    # ------------------------------------------------------------------ base parameters
    def compute_base_parameters(self, *, seed: int = 0, n_samples: int | None = None) -> BaseParameterMap:
        """Find the identifiable parameter combinations numerically.

        The regressor is stacked at ``n_samples`` random states (q uniform within the joint limits, or
        [−π, π] where unlimited; q̇ uniform in ±1.5 rad/s; q̈ uniform in ±10 rad/s²), its columns scaled to
        unit norm, and factorised by QR with column pivoting; the rank is the number of pivots with
        ``|R_ii| > BASE_RANK_TOLERANCE·|R_00|``. The combination matrix solves ``R₁₁ β = R₁₂`` by a
        triangular solve.

        Args:
            seed: Seed of the random states.
            n_samples: Number of states (default ``max(64, 3·n_params)``).

        Returns:
            The map from full to base parameters.
        """
        n = self.n_params
        k = int(n_samples) if n_samples is not None else max(64, 3 * n)
        if k * self.n_outputs < n:
            raise ConfigurationError(f"n_samples={k} gives fewer rows than the {n} parameters")
        rng = np.random.default_rng(seed)
        lo = np.where(np.isfinite(self._lower), self._lower, -math.pi)
        hi = np.where(np.isfinite(self._upper), self._upper, math.pi)
        qs = rng.uniform(lo, hi, size=(k, self.n_joints))
        dqs = rng.uniform(-1.5, 1.5, size=(k, self.n_joints))
        ddqs = rng.uniform(-10.0, 10.0, size=(k, self.n_joints))
        W = self.regressor(qs, dqs, ddqs).reshape(k * self.n_outputs, n)
        scale = np.linalg.norm(W, axis=0)
        # Columns that are zero up to round-off (parameters that never affect y) must not be normalised
        # into unit-norm noise: zero them so they end up dependent with zero coefficients.
        null = scale <= _NULL_COLUMN * max(float(scale.max()), 1e-300)
        W[:, null] = 0.0
        scale[null] = 1.0
        _, R, perm = scipy.linalg.qr(W / scale, mode="economic", pivoting=True)
        diag = np.abs(np.diag(R))
        ratios = diag / diag[0] if diag[0] > 0 else np.zeros_like(diag)
        rank = int(np.count_nonzero(ratios > BASE_RANK_TOLERANCE))
        ind, dep = perm[:rank], perm[rank:]
        rows = W.shape[0]
        beta_s = (
            scipy.linalg.solve_triangular(R[:rank, :rank], R[:rank, rank:])
            if dep.size
            else np.zeros((rank, 0))
        )
        beta = beta_s / scale[ind][:, None] * scale[dep][None, :]
        beta[np.abs(beta) < _COEFFICIENT_ZERO] = 0.0
        oi, od = np.argsort(ind), np.argsort(dep)
        ind, dep, beta = ind[oi], dep[od], beta[oi][:, od]
        projection = np.zeros((rank, n))
        projection[np.arange(rank), ind] = 1.0
        projection[:, dep] = beta
        names = []
        for r in range(rank):
            label = self.parameter_names[ind[r]]
            for c in np.flatnonzero(beta[r]):
                coef = beta[r, c]
                mag = "" if abs(abs(coef) - 1.0) < 1e-9 else f"{abs(coef):.6g}*"
                label += f" {'-' if coef < 0 else '+'} {mag}{self.parameter_names[dep[c]]}"
            names.append(label)
        return BaseParameterMap(
            independent=ind.astype(int),
            dependent=dep.astype(int),
            coefficients=beta,
            names=tuple(names),
            projection=projection,
            singular_ratios=ratios,
            column_rms=scale[ind] / math.sqrt(rows),
        )

    @property
    def base(self) -> BaseParameterMap:
        """The base-parameter map used by :meth:`base_regressor` and :meth:`to_base`."""
        return self._base

    @property
    def n_base(self) -> int:
        """Number of base (identifiable) parameters."""
        return self._base.n_base

    @property
    def base_parameter_names(self) -> tuple[str, ...]:
        """Each base parameter as a combination of full ones, e.g. ``"m_r_upper_arm + 0.068*mcz_…"``."""
        return self._base.names

    def base_regressor(self, q: Any, dq: Any, ddq: Any) -> np.ndarray:
        """Return the base regressor ``Φ_b`` with ``y = Φ_b π_b`` (full column rank on exciting data).

        Args:
            q: Joint positions (n,) in rad, or (k, n).
            dq: Joint velocities (n,) in rad/s, or (k, n).
            ddq: Joint accelerations (n,) in rad/s², or (k, n).

        Returns:
            (n_outputs, n_base), or (k, n_outputs, n_base).

        Raises:
            RejectedSampleError: On bad state vectors.
        """
        return self.regressor(q, dq, ddq)[..., self._base.independent]

    def base_regressor_of_input(self, x: np.ndarray, column_factor: np.ndarray | None = None) -> np.ndarray:
        """Return the base regressor of one learner input ``x = [q, q̇, q̈]``, columns optionally scaled.

        The learners' per-sample path: bit for bit ``base_regressor(q, q̇, q̈) * column_factor``, without
        :meth:`regressor`'s per-vector conversions and checks and with one array fewer.

        Args:
            x: (3n,) float64 ``[q, q̇, q̈]`` [rad, rad/s, rad/s²], values checked by the caller (NaN or inf
                give a non-finite Φ, which the learners refuse).
            column_factor: Optional (n_base,) factors of the columns (``1/c`` of the column scaling).

        Returns:
            (n_outputs, n_base), a new array.

        Raises:
            RejectedSampleError: If x is not a vector of 3n entries.
        """
        n = self.n_joints
        if x.shape != (3 * n,):
            raise RejectedSampleError(f"x must have shape ({3 * n},) for joints {list(self.joint_names)}, "
                                      f"got {x.shape}")
        dq, ddq = x[n : 2 * n], x[2 * n :]
        self._fill(x[:n], dq, ddq)
        if self.n_params > self._n_rigid:
            out = np.empty((self.n_outputs, self.n_params))
            self._rigid(out)
            self._extra(out, dq, ddq)
            Phi = out[:, self._base.independent]
        else:
            Phi = self._block()[:, self._base.independent]
            if self._sign < 0:
                np.negative(Phi, out=Phi)  # exact: the same bits as negating before the selection
        if column_factor is not None:
            Phi *= column_factor
        return Phi

    def base_regressor_of_inputs(self, X: np.ndarray, column_factor: np.ndarray | None = None) -> np.ndarray:
        """Return the base regressors of N learner inputs at once: (N, n_outputs, n_base).

        :meth:`base_regressor_of_input` row by row, but only Pinocchio's regressor is called per row; the
        friction, offset and armature columns, the base selection and the column factors are applied to
        all rows at once (the vectorised prediction of many states). Equal to the row-by-row result to
        the last bit but for ``tanh`` of the Coulomb columns, which numpy may evaluate with other
        rounding on a whole array (≤ 1 ulp).

        Args:
            X: (N, 3n) float64 rows ``[q, q̇, q̈]`` [rad, rad/s, rad/s²], values checked by the caller.
            column_factor: Optional (n_base,) factors of the columns (``1/c`` of the column scaling).

        Returns:
            (N, n_outputs, n_base), a new array.

        Raises:
            RejectedSampleError: If X is not (N, 3n).

        Example:
            >>> from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
            >>> from semiparam_ros.core.estimator.build import build_regressor
            >>> reg = build_regressor(EstimatorConfig.from_flat(
            ...     {**ICUB_RIGHT_ARM, "robot.output": OutputKind.JOINT_TORQUES}))
            >>> X = np.random.default_rng(0).uniform(-1.0, 1.0, (5, 3 * reg.n_joints))
            >>> many = reg.base_regressor_of_inputs(X)
            >>> many.shape == (5, reg.n_outputs, reg.n_base)
            True
            >>> bool(np.allclose(many[2], reg.base_regressor_of_input(X[2]), rtol=1e-15, atol=0.0))
            True
        """
        n = self.n_joints
        if X.ndim != 2 or X.shape[1] != 3 * n:
            raise RejectedSampleError(f"X must have shape (N, {3 * n}) for joints {list(self.joint_names)}, "
                                      f"got {X.shape}")
        out = np.empty((X.shape[0], self.n_outputs, self.n_params))
        for i in range(X.shape[0]):
            self._fill(X[i, :n], X[i, n:2 * n], X[i, 2 * n:])
            self._rigid(out[i])
        if self.n_params > self._n_rigid:
            self._extra(out, X[:, n:2 * n], X[:, 2 * n:])
        Phi = out[:, :, self._base.independent]
        if column_factor is not None:
            Phi *= column_factor
        return Phi

    def to_base(self, pi_full: Any) -> np.ndarray:
        """Map full parameters to base parameters, ``π_b = π[ind] + β π[dep]``.

        Args:
            pi_full: Full parameters (n_params,).

        Returns:
            (n_base,) base parameters.

        Raises:
            ConfigurationError: If ``pi_full`` has the wrong length or non-finite values.
        """
        pi = self._params("pi_full", pi_full, self.n_params)
        return pi[self._base.independent] + self._base.coefficients @ pi[self._base.dependent]

    # ------------------------------------------------------------------ limits and kinematics
    def position_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the (lower, upper) position limits (n,) in rad (m) from the URDF; ±inf if unlimited."""
        return self._lower.copy(), self._upper.copy()

    def velocity_limits(self) -> np.ndarray:
        """Return the velocity limits (n,) in rad/s (m/s) from the URDF."""
        return self._vlim.copy()

    def effort_limits(self) -> np.ndarray:
        """Return the effort limits (n,) in N·m (N) from the URDF (0 where the URDF gives none)."""
        return np.asarray(self._model.effortLimit, dtype=np.float64)[self._idx_v].copy()

    @property
    def distal_body_name(self) -> str:
        """The most distal body (deepest in the tree): the one carrying the end effector.

        For the iCub arm with the wrist locked this is ``r_elbow_1``, into which the forearm and hand are
        lumped.
        """
        return self.body_names[self._distal]

    def body_index(self, name: str) -> int:
        """Return the slot of a body: its parameters are ``π[10·i : 10·i + 10]``.

        Raises:
            ConfigurationError: If ``name`` is not one of ``body_names``.
        """
        try:
            return self.body_names.index(name)
        except ValueError:
            raise ConfigurationError(f"unknown body {name!r}; bodies are {list(self.body_names)}") from None

    @property
    def body_joint_ids(self) -> np.ndarray:
        """Joint id in :attr:`pinocchio_model` of each body of ``π`` (in ``body_names`` order)."""
        return self._body_jids.copy()

    def configuration(self, q: Any) -> np.ndarray:
        """Return the Pinocchio configuration vector of joint positions q (locked joints at their positions).

        Args:
            q: Positions of ``joint_names`` (n,) [rad or m].

        Returns:
            A new (nq,) vector of :attr:`pinocchio_model`.

        Raises:
            RejectedSampleError: On a bad q.
        """
        self._fill(self._vector("q", q), np.zeros(self.n_joints), np.zeros(self.n_joints))
        return self._q.copy()

    @property
    def pinocchio_model(self) -> pin.Model:
        """The reduced Pinocchio model (read only: do not modify it)."""
        return self._model


def _as_slice(indices: np.ndarray) -> slice | np.ndarray:
    """Return a slice for contiguous ascending indices (a view, cheaper than fancy indexing)."""
    indices = np.asarray(indices, dtype=int)
    if indices.size and np.array_equal(indices, np.arange(indices[0], indices[0] + indices.size)):
        return slice(int(indices[0]), int(indices[0]) + indices.size)
    return indices


def _rebuild(urdf_xml: str, spec: RegressorSpec, source: str | None) -> RigidBodyRegressor:
    return RigidBodyRegressor(urdf_xml, spec, source=source)


def _spec(joints: Sequence[str] | RegressorSpec, options: dict[str, Any]) -> RegressorSpec:
    """Return the spec given, or the one ``joints`` and ``options`` describe."""
    if isinstance(joints, RegressorSpec):
        if options:
            raise ConfigurationError(f"give a RegressorSpec or keyword options, not both ({sorted(options)})")
        return joints
    try:
        return RegressorSpec(joints, **options)  # type: ignore[arg-type]  # checked in __post_init__
    except TypeError as err:  # a misspelt option
        raise ConfigurationError(f"unknown regressor option: {err}") from None
