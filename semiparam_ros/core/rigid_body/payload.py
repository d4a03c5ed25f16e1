"""Payload identification: the mass, centre of mass and inertia a robot's distal body carries.

A payload changes only the parameters of the body that carries it — the distal body of the configured
chain (the child link of the last configured joint, with every link fixed to it). Its ten inertial
parameters ``δ = [m, mc_x, mc_y, mc_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz]`` (kg, kg·m, kg·m², about
the body frame) are estimated in one of two ways:

* **beyond the URDF** (:func:`payload_beyond_urdf`): the links before the distal body held at their CAD
  values, the distal body's ten parameters regressed (friction and offsets free) on what the rigid-body
  learner's data leave; its covariance the data's plus the CAD links' uncertainty propagated to it, so
  that a URDF whose other links are wrong gives a wide σ rather than a confident wrong mass. (Projecting
  every link toward CAD with one weight instead spread the payload over the links before it: 0.48 kg
  of 1.2 on the simulated Panda.)
* **since a tare** (:class:`PayloadLearner`): after ``tare``, a ten-parameter recursive least squares on
  ``r = y − Φ_b(x) π̂_b,ref``, the measured output minus the rigid-body model at the tare (friction and
  offsets included), regressed on the distal body's ten columns of the full regressor ``Φ(x)``. It sees
  only what changed since the tare — a pickup — whatever the model's errors before it. Learning starts
  at the **detected pickup**: the first ``DETECT_BASELINE`` samples after the tare measure the RMS ``s``
  of r per output (the model's error and the noise, nothing carried); the pickup is the first run of
  ``DETECT_RUN`` samples with ``|r| > DETECT_RATIO · s`` on some output, and those samples are the first
  learned. Samples between the tare and the pickup carry no payload; learning them would pull the
  estimate toward none (measured on the simulated Panda: 0.2 s of them among 10 s after the pickup
  moved the centre of mass by 9 mm). Covariance ``s² A⁻¹`` (A = ZᵀZ + λI of the regression, s² the mean
  squared a-priori error of its fit).

A :class:`PayloadEstimate` reports the payload's mass m = δ₀ (kg), centre of mass c = h/m (m, in the
distal body's frame) and inertia about c, ``I_c = I_o − (‖h‖² E − h hᵀ)/m`` (kg·m², body axes), each with
its standard deviation by first-order propagation of the covariance of δ.

Example:
    >>> import numpy as np
    >>> from semiparam_ros.core.rigid_body.dynamics import point_mass_parameters
    >>> delta = point_mass_parameters(2.0, [0.0, 0.01, 0.05])  # 2 kg, 5 cm along z
    >>> est = payload_from_parameters(delta, 1e-8 * np.eye(10), body="link7", n_samples=1000,
    ...                               reference="tare")
    >>> round(est.mass, 6), np.round(est.com, 6).tolist()
    (2.0, [0.0, 0.01, 0.05])
    >>> bool(np.abs(est.inertia).max() < 1e-9)  # a point mass has no inertia about its centre
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular

from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.core.rigid_body.dynamics import INERTIAL_PARAMETER_NAMES, RigidBodyRegressor
from semiparam_ros.errors import CheckpointError, ConfigurationError

__all__ = [
    "CAD_COM_STD_M", "CAD_INERTIA_RELATIVE_STD", "CAD_MASS_RELATIVE_STD", "DETERMINED_MASS_FRACTION",
    "MAX_COM_STD_M",
    "PayloadEstimate", "PayloadLearner",
    "cad_parameter_std", "payload_beyond_urdf", "payload_from_parameters", "undetermined_reason",
]

_I = ((0, 1, 3), (1, 2, 4), (3, 4, 5))  # [Ixx, Ixy, Iyy, Ixz, Iyz, Izz] → 3×3


@dataclass(frozen=True)
class PayloadEstimate:
    """A payload: mass, centre of mass and inertia, each with its standard deviation.

    Attributes:
        mass: m [kg]; ``mass_std`` its standard deviation.
        com: (3,) centre of mass [m] in the frame of the distal body (the child link of the last
            configured joint); ``com_std`` per axis.
        inertia: (3, 3) inertia about the centre of mass [kg·m²], body axes; ``inertia_std`` per entry.
        body: The distal body's name.
        n_samples: Samples the estimate rests on (since the detected pickup; all learned samples beyond
            the URDF).
        reference: ``"tare"`` or ``"urdf"`` (what the payload is counted beyond).
        detected: Whether a pickup was detected since the tare (False: nothing carried yet, the estimate
            is zero with the prior's standard deviations); always True beyond the URDF.
        missing: Empty when the payload is determined; else why not and which excitation is missing
            (beyond the URDF: the data's part of the mass σ, without the CAD links' uncertainty, above
            :data:`DETERMINED_MASS_FRACTION` of the distal body's CAD mass plus the estimate). The numbers
            are still given, with their σ.
    """

    mass: float
    mass_std: float
    com: np.ndarray
    com_std: np.ndarray
    inertia: np.ndarray
    inertia_std: np.ndarray
    body: str
    n_samples: int
    reference: str
    detected: bool = True
    missing: str = ""

    @property
    def determined(self) -> bool:
        """Whether the data determine the payload (:attr:`missing` is empty)."""
        return not self.missing


def _payload_values(delta: np.ndarray) -> np.ndarray:
    """``[m, c (3), I_c (6: xx, xy, yy, xz, yz, zz)]`` of the ten parameters δ (module docstring)."""
    m, h = float(delta[0]), delta[1:4]
    i_o = delta[4:10]
    if abs(m) < 1e-12:
        return np.concatenate([[m], np.zeros(3), i_o])
    shift = (float(h @ h) * np.eye(3) - np.outer(h, h)) / m
    shift6 = np.array([shift[0, 0], shift[0, 1], shift[1, 1], shift[0, 2], shift[1, 2], shift[2, 2]])
    return np.concatenate([[m], h / m, i_o - shift6])


def payload_from_parameters(delta: np.ndarray, covariance: np.ndarray, *, body: str, n_samples: int,
                            reference: str, detected: bool = True, missing: str = "") -> PayloadEstimate:
    """Turn the change δ of a body's ten parameters and its covariance into a payload estimate.

    Args:
        delta: (10,) ``[m, mc (3), I_o (6)]`` [kg, kg·m, kg·m²] about the body frame.
        covariance: (10, 10) covariance of δ.
        body: The body's name.
        n_samples: Samples behind the estimate.
        reference: What the payload is counted beyond (``"tare"`` or ``"urdf"``).
        detected: Whether a pickup was detected (see :class:`PayloadEstimate`).
        missing: Why the payload is not determined ("" when it is).

    Returns:
        The estimate; its standard deviations by first-order propagation (central differences).

    Raises:
        ConfigurationError: Wrong shapes.
    """
    delta = np.asarray(delta, dtype=np.float64)
    covariance = np.asarray(covariance, dtype=np.float64)
    if delta.shape != (10,) or covariance.shape != (10, 10):
        raise ConfigurationError(f"delta must be (10,) and covariance (10, 10), got {delta.shape} and "
                                 f"{covariance.shape}")
    values = _payload_values(delta)
    jac = np.empty((10, 10))
    for j in range(10):
        step = 1e-6 * max(1.0, abs(delta[j]))
        hi, lo = delta.copy(), delta.copy()
        hi[j] += step
        lo[j] -= step
        jac[:, j] = (_payload_values(hi) - _payload_values(lo)) / (2 * step)
    std = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", jac, covariance, jac), 0.0))
    inertia = np.array([[values[4 + k] for k in row] for row in _I])
    inertia_std = np.array([[std[4 + k] for k in row] for row in _I])
    mass, mass_std, com_std = float(values[0]), float(std[0]), std[1:4].copy()
    if not missing:
        missing = undetermined_reason(mass, mass_std, com_std)
    return PayloadEstimate(mass, mass_std, values[1:4].copy(), com_std, inertia, inertia_std, body,
                           int(n_samples), reference, bool(detected), missing)


#: A payload whose centre-of-mass σ exceeds this on an axis is not determined [m].
MAX_COM_STD_M = 0.5


def undetermined_reason(mass: float, mass_std: float, com_std: np.ndarray) -> str:
    """Say why a payload estimate determines nothing ("" when it does).

    Not determined when the mass σ is not below the mass (nothing is carried, or the distal body was not
    excited: the estimate is noise around zero) or a centre-of-mass σ exceeds :data:`MAX_COM_STD_M`.

    Args:
        mass: Estimated mass [kg].
        mass_std: Its standard deviation [kg].
        com_std: (3,) standard deviations of the centre of mass [m].

    >>> undetermined_reason(-0.006, 0.267, np.array([18.0, 17.0, 96.0]))
    'not determined: the mass σ 0.267 kg is not below the mass -0.006 kg (nothing carried, ...)'
    >>> undetermined_reason(1.5, 0.01, np.array([0.01, 0.01, 0.02]))
    ''
    """
    if not mass_std < abs(mass):
        return (f"not determined: the mass σ {mass_std:.3g} kg is not below the mass {mass:.3g} kg (nothing "
                "carried, or the distal body not excited)")
    worst = float(np.max(com_std))
    if not worst <= MAX_COM_STD_M:
        return (f"not determined: a centre-of-mass σ of {worst:.3g} m exceeds {MAX_COM_STD_M:g} m (the "
                "motion does not separate the payload's position)")
    return ""


#: Assumed accuracy of a URDF's CAD inertial parameters for the links before the payload (one standard
#: deviation): relative mass, centre-of-mass position [m], relative inertia about the centre of mass.
CAD_MASS_RELATIVE_STD = 0.1
CAD_COM_STD_M = 0.01
CAD_INERTIA_RELATIVE_STD = 0.1
#: A payload beyond the URDF is determined when the data's part of its mass σ (excitation and noise; the
#: CAD links' uncertainty is in σ but is not what more data would fix) is at most this fraction of the
#: distal body's CAD mass plus the estimated payload mass.
DETERMINED_MASS_FRACTION = 0.1


def cad_parameter_std(params: np.ndarray, *, mass_relative: float = CAD_MASS_RELATIVE_STD,
                      com_m: float = CAD_COM_STD_M,
                      inertia_relative: float = CAD_INERTIA_RELATIVE_STD) -> np.ndarray:
    """Return standard deviations of per-body CAD parameters from a mass, COM and inertia accuracy.

    Per body ``[m, h = mc, I_o]`` (10 values, about the body frame): σ_m = ρ_m m;
    ``σ_h,k = √((m σ_c)² + (h_k ρ_m)²)``; every entry of I_o gets ``ρ_I tr(I_o)/3 + 2‖h‖σ_c`` (the inertia
    about the centre of mass, and the shift of the origin term when c moves). A diagonal approximation:
    what matters is the scale with which other links can absorb a payload.

    Args:
        params: (10·b,) per-body parameters [kg, kg·m, kg·m²] (e.g. the URDF's).
        mass_relative: ρ_m, relative standard deviation of a mass.
        com_m: σ_c [m], standard deviation of a centre of mass per axis.
        inertia_relative: ρ_I, relative standard deviation of an inertia.

    Returns:
        (10·b,) positive standard deviations.

    Example:
        >>> from semiparam_ros.core.rigid_body.dynamics import point_mass_parameters
        >>> cad_parameter_std(point_mass_parameters(2.0, [0.0, 0.0, 0.1]))[:4].round(4).tolist()
        [0.2, 0.02, 0.02, 0.0283]
    """
    p = np.asarray(params, dtype=np.float64).reshape(-1, 10)
    m, h, i_o = np.abs(p[:, :1]), p[:, 1:4], p[:, 4:]
    trace = np.abs(i_o[:, 0] + i_o[:, 2] + i_o[:, 5])[:, None]
    std = np.empty_like(p)
    std[:, :1] = mass_relative * m
    std[:, 1:4] = np.hypot(m * com_m, h * mass_relative)
    std[:, 4:] = inertia_relative * trace / 3.0 + 2.0 * np.linalg.norm(h, axis=1)[:, None] * com_m
    return np.maximum(std, 1e-9).reshape(-1)


def payload_beyond_urdf(regressor: RigidBodyRegressor, theta: np.ndarray, R: np.ndarray, scale: np.ndarray,
                        lam: float, weights: np.ndarray, noise_s2: float, n_samples: int, *,
                        cad_std: np.ndarray | None = None) -> PayloadEstimate:
    """Estimate the distal body's change beyond the URDF, the links before it held at their CAD values.

    The rigid-body learner's data define the quadratic ``‖M π − Rθ‖²`` over full parameters π
    (``M = R·diag(c)·K``, K the base map: the same data term as the consistent projection). With the
    bodies before the distal one at their CAD values π₀, the distal body's ten parameters δ and the
    extra columns ξ (friction, offsets, …) are its least-squares solution,

        [δ̂; ξ̂] = argmin ‖M_d δ + M_x ξ − (Rθ − M π₀)‖² + λ‖w ⊙ [δ; ξ]‖²,

    a ten-plus-extras linear solve (no cone program: the payload itself is not constrained). Its
    covariance adds to the data's ``s² H⁻¹`` the CAD links' uncertainty, propagated linearly:
    ``J Σ_o Jᵀ`` with ``J = −H⁻¹ [M_d M_x]ᵀ M_o`` the estimate's sensitivity to the other bodies'
    parameters and ``Σ_o = diag(cad_std²)``. Where the data tell the payload apart from the other links
    (a well-excited arm), J is small and the estimate is as accurate as the URDF; where they cannot, σ
    says so (a large mass σ is a payload that is not determined).

    Args:
        regressor: The rigid-body regressor (base map K, body layout, CAD values).
        theta: (n_base,) the rigid-body learner's coefficients (scaled units, θ = c ⊙ π_b).
        R: (n_base, n_base) its factor (``RᵀR = A``, scaled units).
        scale: (n_base,) its column scales c.
        lam: The learner's λ (a weak pull of δ and ξ toward zero, as in the projection).
        weights: (n_params,) per-parameter weights w of that pull (:func:`full_column_rms`).
        noise_s2: Noise variance of y [(N·m)²], averaged over the outputs.
        n_samples: Samples learned.
        cad_std: (10·n_bodies,) standard deviations of the CAD parameters (default
            :func:`cad_parameter_std` of the URDF's).

    Returns:
        The payload beyond the URDF (``reference="urdf"``).

    Raises:
        ConfigurationError: Wrong sizes.
    """
    K = regressor.base.projection
    n_base, n_params = K.shape
    theta, R, scale = (np.asarray(a, dtype=np.float64) for a in (theta, R, scale))
    if theta.shape != (n_base,) or R.shape != (n_base, n_base) or scale.shape != (n_base,):
        raise ConfigurationError(f"theta, R and scale must be ({n_base},), ({n_base}, {n_base}), ({n_base},)")
    prior = regressor.urdf_parameters()
    n_rigid = 10 * regressor.n_bodies
    std = cad_parameter_std(prior[:n_rigid]) if cad_std is None else np.asarray(cad_std, dtype=np.float64)
    if std.shape != (n_rigid,):
        raise ConfigurationError(f"cad_std must be ({n_rigid},), got {std.shape}")
    body = regressor.body_index(regressor.distal_body_name)
    distal = np.arange(10 * body, 10 * body + 10)
    free = np.concatenate([distal, np.arange(n_rigid, n_params)])       # δ, then the extras ξ
    held = np.setdiff1d(np.arange(n_rigid), distal)                      # the links before: at CAD
    M = R @ (scale[:, None] * K)
    Mf = M[:, free]
    H = Mf.T @ Mf + lam * np.diag(np.asarray(weights, dtype=np.float64)[free] ** 2)
    factor = cho_factor(H)
    solution = cho_solve(factor, Mf.T @ (R @ theta - M @ prior))
    sensitivity = -cho_solve(factor, Mf.T @ M[:, held])[:10]             # ∂δ̂/∂π_o
    cad_cov = (sensitivity * std[held] ** 2) @ sensitivity.T
    data_cov = float(noise_s2) * cho_solve(factor, np.eye(free.size)[:, :10])[:10]
    cov = data_cov + cad_cov
    estimate = payload_from_parameters(solution[:10], 0.5 * (cov + cov.T), body=regressor.distal_body_name,
                                       n_samples=n_samples, reference="urdf")
    limit = DETERMINED_MASS_FRACTION * (float(prior[10 * body]) + abs(estimate.mass))
    data_mass_std = math.sqrt(max(float(data_cov[0, 0]), 0.0))
    if data_mass_std <= limit:
        return estimate
    return replace(estimate, missing=_what_is_missing(data_cov, std[distal], data_mass_std, limit))


def _what_is_missing(data_cov: np.ndarray, unit: np.ndarray, mass_std: float, limit: float) -> str:
    """Say which of the distal body's parameters the data leave least determined (in CAD-accuracy units)."""
    scale = 1.0 / np.maximum(unit, 1e-12)
    data_n = scale[:, None] * data_cov * scale[None, :]
    _, vectors = np.linalg.eigh(0.5 * (data_n + data_n.T))
    direction = vectors[:, -1]
    top = np.argsort(-np.abs(direction))[:3]
    names = ", ".join(f"{INERTIAL_PARAMETER_NAMES[i]} ({direction[i]:+.2f})" for i in top)
    return (f"not determined: the data alone give the mass a σ of {mass_std:.3g} kg (> {limit:.3g} kg); they "
            f"leave the distal body's {names} unexcited: move the arm through more poses and the last joints "
            "faster")


class PayloadLearner:
    """The change of the distal body's ten parameters since a tare, learned online (module docstring).

    Args:
        regressor: The rigid-body regressor.
        reference: (n_base,) base parameters at the tare, physical units (friction and offsets included).
        lam: Ridge λ of the ten-parameter regression (toward no payload).

    Raises:
        ConfigurationError: A reference of the wrong size.

    Example:
        >>> import numpy as np
        >>> from semiparam_ros.core.kinds import OutputKind
        >>> from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor, point_mass_parameters
        >>> from semiparam_ros.core.rigid_body.urdf import resolve_urdf
        >>> urdf_path = resolve_urdf("example-robot-data://robots/panda_description/urdf/panda.urdf")
        >>> joints = [f"panda_joint{i}" for i in range(1, 8)]
        >>> reg = RigidBodyRegressor.from_urdf(urdf_path, joints, output=OutputKind.JOINT_TORQUES)
        >>> urdf = reg.urdf_parameters()
        >>> learner = PayloadLearner(reg, reg.to_base(urdf))
        >>> body = reg.body_index(reg.distal_body_name)
        >>> carried = urdf.copy()
        >>> carried[10 * body: 10 * body + 10] += point_mass_parameters(1.5, [0.0, 0.0, 0.1])
        >>> rng = np.random.default_rng(0)
        >>> for k in range(500):  # 150 samples with nothing carried, then the pickup
        ...     q, dq, ddq = rng.uniform(-1, 1, (3, 7))
        ...     params = urdf if k < 150 else carried
        ...     y = reg.regressor(q, dq, ddq) @ params + 0.01 * rng.standard_normal(7)
        ...     learner.update(q, dq, ddq, y)
        >>> est = learner.estimate()
        >>> est.detected, est.n_samples
        (True, 350)
        >>> round(est.mass, 2), (np.round(est.com, 2) + 0.0).tolist()
        (1.5, [0.0, 0.0, 0.1])
    """

    #: Samples after the tare that measure the RMS of r before a pickup can be detected.
    DETECT_BASELINE = 100
    #: A pickup: this many consecutive samples with |r| beyond ``DETECT_RATIO`` × that RMS on some output.
    DETECT_RUN = 5
    DETECT_RATIO = 6.0

    def __init__(self, regressor: RigidBodyRegressor, reference: np.ndarray, lam: float = 1e-6) -> None:
        reference = np.asarray(reference, dtype=np.float64)
        if reference.shape != (regressor.n_base,):
            raise ConfigurationError(f"reference must have the {regressor.n_base} base parameters, got "
                                     f"{reference.shape}")
        self.regressor = regressor
        self.reference = reference.copy()
        self.body = regressor.distal_body_name
        index = regressor.body_index(self.body)
        self._cols = slice(10 * index, 10 * index + 10)
        self._independent = regressor.base.independent
        self.rls = RecursiveRLS(10, 1, lam)
        self.n_samples = 0
        self._sq_error = 0.0  # sum of squared a-priori errors (per output entry) after the first samples
        self._n_error = 0
        self.detected = False
        self._baseline_sq = np.zeros(regressor.n_outputs)  # Σ r² per output before the pickup
        self._baseline_n = 0
        self._run: list[tuple[np.ndarray, np.ndarray]] = []  # the current run of outliers (≤ DETECT_RUN)

    def update(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, y: np.ndarray) -> None:
        """Learn one sample: q [rad], q̇ [rad/s], q̈ [rad/s²] (n,), y the measured output (t,) [N·m or N].

        Raises:
            RejectedSampleError: Non-finite or absurd values (the learner is unchanged).
        """
        Phi = self.regressor.regressor(q, dq, ddq)
        r = np.asarray(y, dtype=np.float64) - Phi[:, self._independent] @ self.reference
        Z = np.ascontiguousarray(Phi[:, self._cols])
        if not self.detected:
            self._watch(Z, r)
            return
        self._learn(Z, r)

    def _watch(self, Z: np.ndarray, r: np.ndarray) -> None:
        """Before the pickup: measure the RMS of r, then look for a run of outliers (module docstring)."""
        if not np.all(np.isfinite(r)):
            return
        if self._baseline_n < self.DETECT_BASELINE:
            self._baseline_sq += r * r
            self._baseline_n += 1
            return
        rms = np.sqrt(self._baseline_sq / self._baseline_n)
        if np.any(np.abs(r) > self.DETECT_RATIO * np.maximum(rms, 1e-12)):
            self._run.append((Z, r))
            if len(self._run) >= self.DETECT_RUN:
                self.detected = True
                for z_k, r_k in self._run:
                    self._learn(z_k, r_k)
                self._run = []
        else:
            self._run = []

    def _learn(self, Z: np.ndarray, r: np.ndarray) -> None:
        prior = self.rls.predict_update(Z, r[:, None])
        if self.n_samples >= 10:  # the first errors are those of an empty model
            self._sq_error += float(np.sum((r - prior[:, 0]) ** 2))
            self._n_error += r.size
        self.n_samples += 1

    def noise_s2(self) -> float:
        """Mean squared a-priori error of the fit per output [(N·m)²] (NaN before 10 samples)."""
        return self._sq_error / self._n_error if self._n_error else float("nan")

    def estimate(self) -> PayloadEstimate:
        """Return the payload since the tare (``reference="tare"``)."""
        delta = self.rls.weights[:, 0]
        Rinv = solve_triangular(self.rls.R, np.eye(10), lower=False)  # 10×10, off the sample path
        s2 = self.noise_s2()
        cov = (0.0 if np.isnan(s2) else s2) * (Rinv @ Rinv.T)
        if not self.detected:
            missing = "not determined: no pickup detected since the tare"
        elif np.isnan(s2):
            missing = "not determined: too few samples since the pickup for a σ"
        else:
            missing = ""
        return payload_from_parameters(delta, cov, body=self.body, n_samples=self.n_samples, reference="tare",
                                       detected=self.detected, missing=missing)

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return the learner's state as arrays (for checkpoints)."""
        state = self.rls.state_dict(f"{prefix}rls.")
        state[f"{prefix}reference"] = self.reference.copy()
        state[f"{prefix}counts"] = np.array([self.n_samples, self._n_error, int(self.detected),
                                             self._baseline_n], dtype=np.int64)
        state[f"{prefix}sq_error"] = np.array(self._sq_error)
        state[f"{prefix}baseline_sq"] = self._baseline_sq.copy()
        return state

    @classmethod
    def from_state_dict(cls, regressor: RigidBodyRegressor, state: dict[str, np.ndarray],
                        prefix: str = "") -> PayloadLearner:
        """Rebuild a learner from :meth:`state_dict` arrays.

        Raises:
            CheckpointError: Missing keys, wrong sizes or non-finite values.
        """
        try:
            reference = np.asarray(state[f"{prefix}reference"], dtype=np.float64)
            counts = np.asarray(state[f"{prefix}counts"], dtype=np.int64)
            sq_error = float(np.asarray(state[f"{prefix}sq_error"]))
            baseline_sq = np.asarray(state[f"{prefix}baseline_sq"], dtype=np.float64)
        except KeyError as err:
            raise CheckpointError(f"payload state is missing {err}") from err
        if (reference.shape != (regressor.n_base,) or counts.shape != (4,)
                or baseline_sq.shape != (regressor.n_outputs,)
                or not (np.all(np.isfinite(reference)) and np.all(np.isfinite(baseline_sq)))):
            raise CheckpointError("payload state does not fit this robot")
        learner = cls(regressor, reference)
        learner.rls = RecursiveRLS.from_state_dict(state, f"{prefix}rls.")
        if learner.rls.n_features != 10:
            raise CheckpointError("payload state does not hold ten parameters")
        learner.n_samples, learner._n_error = int(counts[0]), int(counts[1])
        learner.detected, learner._baseline_n = bool(counts[2]), int(counts[3])
        learner._sq_error, learner._baseline_sq = sq_error, baseline_sq
        return learner
