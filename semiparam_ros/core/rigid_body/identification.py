"""Identification-grade parameters: a physically consistent estimate, excitation diagnostics, URDF export.

**Consistent projection.** The online estimate lives in base-parameter space (``π̂_b``, the identifiable
combinations) with the information matrix ``A`` of the rigid-body learner (``A = RᵀR`` in its scaled
units θ = c ⊙ π_b). Per-link parameters ``π`` (10 per body: ``m, mc, I_o`` about the body frame) and
friction are recovered by the convex problem

    min_π  ‖R (c ⊙ K π − θ̂)‖²  +  λ ‖w ⊙ (π − π_CAD)‖²
    s.t.   J_i(π) ⪰ 0 for every body i,    f_v ≥ 0, f_c ≥ 0, armature ≥ 0

with ``K`` the base map (``π_b = K π``), ``J_i = [[½ tr(I_o) 1 − I_o, mc], [mcᵀ, m]]`` the body's pseudo-
inertia (PSD ⇔ a physical mass distribution: ``m ≥ 0``, inertia about the centre of mass with the
triangle inequalities), ``λ`` the learner's own ridge and ``w`` the RMS of each full regressor column over
random states (so the pull toward the URDF's CAD values costs the output it explains, as in the online
learner), divided by :data:`DISTAL_PRIOR_FACTOR` for the distal body's ten: where the data determine a
combination the projection follows them, elsewhere the CAD values. The distal body carries the tools and
payloads a URDF does not know, so it is the body most likely to be far from CAD; with one weight for every
body a payload's mass was spread over the links before it (the base parameters cannot tell them apart),
with the distal body's prior ten times weaker it stays on the distal body.
Solved with cvxpy and Clarabel (an interior-point conic solver), a few tens of ms for a 7-joint arm — off
the 1 kHz path.

**Excitation.** The spectrum of ``A`` in physical units (``A_π = C A C``): its condition number, and the
least-excited directions named by the base parameters (and links) they weigh most.

**URDF export.** The consistent per-link parameters written into the URDF's ``<inertial>`` (centre of mass
and inertia about it; links the reduced model merged into a body — fixed or locked children — get a
negligible inertial, the body carries them all) and the friction into ``<dynamics damping friction>``;
loaded back (same joints, same locked positions) it gives the same rigid-body prediction.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.errors import ConfigurationError

__all__ = ["DISTAL_PRIOR_FACTOR", "OUTSIDE_EXCITED", "ConsistentEstimate", "ExcitationReport",
           "consistent_parameters", "excitation_report", "export_urdf", "full_column_rms", "link_of",
           "outside_excited", "prior_weights", "random_state_regressor"]

#: The distal body's CAD prior is this many times weaker than the other bodies' (module docstring).
DISTAL_PRIOR_FACTOR = 10.0

#: Clarabel's tolerances, tighter than its defaults (1e-8): the weak prior of the distal body leaves its
#: parameters loosely held, and with nothing learned the projection must return CAD (1e-8 N·m, not 1e-6),
#: at the same solve time.
_SOLVER_TOLERANCES = {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10, "tol_ktratio": 1e-8}

#: Mass given to a link the reduced model merged into a body, in the exported URDF (kg): URDF parsers want a
#: positive mass; 1e-9 kg changes no torque beyond 1e-8 N·m.
_NEGLIGIBLE_MASS = 1e-9


def _pseudo_inertia_rows(i: int) -> list[list[tuple[int, float]]]:
    """``J_i`` as sparse rows of (full-parameter index, coefficient) for body slot i."""
    b = 10 * i
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = range(b, b + 10)
    half = 0.5
    return [
        [(iyy, half), (izz, half), (ixx, -half)], [(ixy, -1.0)], [(ixz, -1.0)], [(hx, 1.0)],
        [(ixy, -1.0)], [(ixx, half), (izz, half), (iyy, -half)], [(iyz, -1.0)], [(hy, 1.0)],
        [(ixz, -1.0)], [(iyz, -1.0)], [(ixx, half), (iyy, half), (izz, -half)], [(hz, 1.0)],
        [(hx, 1.0)], [(hy, 1.0)], [(hz, 1.0)], [(m, 1.0)],
    ]


def full_column_rms(regressor: RigidBodyRegressor, *, n_states: int = 64, seed: int = 0) -> np.ndarray:
    """RMS of each full-regressor column over random states (units of y per unit of the parameter).

    States: q uniform within the joint limits (±π where unbounded), |q̇| ≤ 1.5 rad/s, |q̈| ≤ 10 rad/s² —
    the base-parameter search's. Columns that are zero everywhere get 1.

    Args:
        regressor: The rigid-body regressor.
        n_states: Random states.
        seed: Their seed.

    Returns:
        (n_params,) positive.
    """
    rms = np.sqrt(np.mean(random_state_regressor(regressor, n_states=n_states, seed=seed) ** 2, axis=(0, 1)))
    return np.where(rms > 0, rms, 1.0)


def random_state_regressor(regressor: RigidBodyRegressor, *, n_states: int = 64, seed: int = 0) -> np.ndarray:
    """Return the full regressor at random states (the base-parameter search's).

    q uniform within the joint limits (±π where unbounded), |q̇| ≤ 1.5 rad/s, |q̈| ≤ 10 rad/s².

    Args:
        regressor: The rigid-body regressor.
        n_states: Random states.
        seed: Their seed.

    Returns:
        (n_states, t, n_params).
    """
    rng = np.random.default_rng(seed)
    lo, hi = regressor.position_limits()
    lo, hi = np.where(np.isfinite(lo), lo, -np.pi), np.where(np.isfinite(hi), hi, np.pi)
    n = len(regressor.joint_names)
    q = rng.uniform(lo, hi, (n_states, n))
    return regressor.regressor(q, rng.uniform(-1.5, 1.5, (n_states, n)), rng.uniform(-10, 10, (n_states, n)))


@dataclass(frozen=True)
class ConsistentEstimate:
    """A physically consistent parameter estimate.

    Attributes:
        full: (n_params,) per-body ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` about each body frame
            (kg, kg·m, kg·m²), then the extra columns (sensor offsets, friction, offsets, armature).
        base: (n_base,) ``K full``: the consistent base parameters (the unconstrained estimate's units).
        body_names: The bodies, in the order of ``full``.
        solve_s: Wall time of the solve [s].
        status: The solver's status (``"optimal"``).
    """

    full: np.ndarray
    base: np.ndarray
    body_names: tuple[str, ...]
    solve_s: float
    status: str

    def link(self, i: int) -> tuple[float, np.ndarray, np.ndarray]:
        """Return body i: mass [kg], centre of mass [m] in the body frame, inertia about it (3, 3) [kg·m²]."""
        return link_of(self.full, i)


def link_of(full: np.ndarray, i: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Return body i of full parameters: mass [kg], centre of mass [m] (body frame), inertia about it [kg·m²].

    Args:
        full: Per-body ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` about each body frame.
        i: The body's index.

    Returns:
        ``(m, c (3,), I_c (3, 3))``; a massless body has its centre of mass at the origin.
    """
    p = full[10 * i: 10 * i + 10]
    m = float(p[0])
    c = p[1:4] / m if m > 0 else np.zeros(3)
    i_o = np.array([[p[4], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]])
    return m, c, i_o - m * (float(c @ c) * np.eye(3) - np.outer(c, c))


def prior_weights(regressor: RigidBodyRegressor) -> np.ndarray:
    """Return the weights w of the projection's pull toward CAD (module docstring).

    :func:`full_column_rms`, the distal body's ten divided by :data:`DISTAL_PRIOR_FACTOR`.

    Args:
        regressor: The rigid-body regressor.

    Returns:
        (n_params,) weights (units of y per unit of each parameter).
    """
    w = full_column_rms(regressor)
    distal = regressor.body_index(regressor.distal_body_name)
    w[10 * distal: 10 * distal + 10] /= DISTAL_PRIOR_FACTOR
    return w


def consistent_parameters(regressor: RigidBodyRegressor, theta: np.ndarray, R: np.ndarray,
                          scale: np.ndarray, lam: float, *, prior: np.ndarray | None = None,
                          weights: np.ndarray | None = None,
                          fixed_bodies: Sequence[int] = ()) -> ConsistentEstimate:
    """Project an online estimate onto physically consistent per-link parameters (module docstring).

    Args:
        regressor: The rigid-body regressor (its base map ``K`` and body layout).
        theta: (n_base,) the learner's estimate in its scaled units (θ = c ⊙ π_b).
        R: (n_base, n_base) upper-triangular factor of the learner's information matrix (``RᵀR = A``).
        scale: (n_base,) the column scales c (ones without column scaling).
        lam: λ of the pull toward the prior (the learner's ridge).
        prior: (n_params,) full prior (default the URDF's CAD parameters, zero extras).
        weights: (n_params,) per-parameter weights w of the prior term (default :func:`prior_weights`).
        fixed_bodies: Bodies whose ten parameters are held at the prior (the data do not move them; the
            other bodies take what they can of the data).

    Returns:
        The consistent estimate.

    Raises:
        ConfigurationError: Wrong sizes, or the solver failed (its status in the message).
    """
    import time

    import cvxpy as cp

    K = regressor.base.projection
    n_base, n_params = K.shape
    theta = np.asarray(theta, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    scale = np.asarray(scale, dtype=np.float64)
    if theta.shape != (n_base,) or R.shape != (n_base, n_base) or scale.shape != (n_base,):
        raise ConfigurationError(f"theta, R and scale must be ({n_base},), ({n_base}, {n_base}), ({n_base},)")
    prior = regressor.urdf_parameters() if prior is None else np.asarray(prior, dtype=np.float64)
    w = prior_weights(regressor) if weights is None else np.asarray(weights, dtype=np.float64)
    pi = cp.Variable(n_params)
    data = R @ (scale[:, None] * K) @ pi - R @ theta
    cost = cp.sum_squares(data) + lam * cp.sum_squares(cp.multiply(w, pi - prior))
    constraints = []
    for i in range(regressor.n_bodies):
        rows = _pseudo_inertia_rows(i)
        J = cp.bmat([[sum(c * pi[j] for j, c in rows[4 * r + k]) for k in range(4)] for r in range(4)])
        constraints.append(J >> 0)
    names = regressor.parameter_names
    nonneg = [j for j, name in enumerate(names) if name.endswith((".viscous", ".coulomb", ".armature"))]
    if nonneg:
        constraints.append(pi[nonneg] >= 0)
    for i in fixed_bodies:
        constraints.append(pi[10 * i: 10 * i + 10] == prior[10 * i: 10 * i + 10])
    problem = cp.Problem(cp.Minimize(cost), constraints)
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():  # the status says so ("optimal_inaccurate"), kept in the estimate
            warnings.filterwarnings("ignore", message="Solution may be inaccurate")
            problem.solve(solver=cp.CLARABEL, **_SOLVER_TOLERANCES)
    except cp.SolverError as err:
        raise ConfigurationError(f"the consistent projection failed: {err}") from err
    elapsed = time.perf_counter() - start
    if pi.value is None or problem.status not in ("optimal", "optimal_inaccurate"):
        raise ConfigurationError(f"the consistent projection failed: solver status {problem.status}")
    full = np.asarray(pi.value, dtype=np.float64)
    return ConsistentEstimate(full, K @ full, tuple(regressor.body_names), elapsed, str(problem.status))


@dataclass(frozen=True)
class ExcitationReport:
    """What the data seen so far determine (module docstring).

    Attributes:
        eigenvalues: Ascending eigenvalues of the information matrix in physical units (A_π).
        condition: Largest / smallest eigenvalue.
        least_excited: The least-excited directions, weakest first: for each, its eigenvalue and the base
            parameters it weighs most, as ``(name, weight)``.
    """

    eigenvalues: np.ndarray
    condition: float
    least_excited: list[tuple[float, list[tuple[str, float]]]]

    def text(self) -> str:
        """Return a short human-readable summary."""
        lines = [f"information condition number {self.condition:.3g} (eigenvalues {self.eigenvalues[0]:.3g} "
                 f"… {self.eigenvalues[-1]:.3g}, physical units)"]
        for value, names in self.least_excited:
            top = ", ".join(f"{n} ({w:+.2f})" for n, w in names)
            lines.append(f"  weakly excited ({value:.3g}): {top}")
        return "\n".join(lines)


def excitation_report(R: np.ndarray, scale: np.ndarray, names: tuple[str, ...], *, n_directions: int = 3,
                      n_names: int = 3) -> ExcitationReport:
    """Return the spectrum of the information matrix in physical units and its least-excited directions.

    Args:
        R: (p, p) factor of the learner's information matrix (scaled units θ = c ⊙ π_b).
        scale: (p,) column scales c.
        names: (p,) base parameter names.
        n_directions: Directions reported.
        n_names: Names per direction.

    Returns:
        The report.
    """
    B = np.asarray(R) * np.asarray(scale)[None, :]  # A_π = (R C)ᵀ (R C): its singular values squared
    _, s, vt = np.linalg.svd(B)
    order = np.argsort(s)
    eig = s[order] ** 2
    least = []
    for k in order[:n_directions]:
        v = vt[k]
        top = np.argsort(-np.abs(v))[:n_names]
        least.append((float(s[k] ** 2), [(names[j], float(v[j])) for j in top]))
    cond = float(eig[-1] / eig[0]) if eig[0] > 0 else float("inf")
    return ExcitationReport(eig, cond, least)


#: Relative predictive variance of the rigid-body part above which a state is outside the excited range:
#: there the model's own uncertainty exceeds the measurement noise (v = φ A⁻¹ φᵀ > 1, dimensionless).
OUTSIDE_EXCITED = 1.0


def outside_excited(variance: np.ndarray, threshold: float = OUTSIDE_EXCITED) -> np.ndarray:
    """Tell which states lie outside the range the rigid-body learner's data excited.

    Args:
        variance: (N, t) relative predictive variances ``diag(Φ A⁻¹ Φᵀ)`` of the rigid-body part (the
            ``variance`` of :meth:`ParametricModel.predict_many`), dimensionless.
        threshold: The bound (default :data:`OUTSIDE_EXCITED`: the model's uncertainty equals the noise).

    Returns:
        (N,) bool: some output's variance beyond the bound.

    Example:
        >>> outside_excited(np.array([[0.01, 0.2], [0.5, 3.0]])).tolist()
        [False, True]
    """
    return np.asarray(np.max(np.asarray(variance), axis=-1) > threshold)


def export_urdf(regressor: RigidBodyRegressor, estimate: ConsistentEstimate,
                comments: Sequence[str] = ()) -> str:
    """Write the URDF with the consistent per-link inertials and the identified joint friction.

    Each identified body's link gets the body's mass, centre of mass and inertia about it (rpy 0); links
    the reduced model merged into a body (fixed children, locked joints at their configured positions) get
    a negligible inertial, so that the body's parameters are not counted twice. Viscous and Coulomb
    friction go to ``<dynamics damping="f_v" friction="f_c"/>`` of the moving joints.

    Args:
        regressor: The regressor the estimate was made with (its URDF text, bodies, locked joints).
        estimate: The consistent estimate (for a file a user loads: the ``estimate`` of the plausible
            links, :class:`~semiparam_ros.core.rigid_body.plausible.PlausibleLinks`).
        comments: Lines written as an XML comment at the top of the robot element (where each link's
            values came from).

    Returns:
        The URDF text.

    Raises:
        ConfigurationError: If a body's link is missing from the URDF.
    """
    root = ET.fromstring(regressor.urdf_xml)
    links = {link.get("name"): link for link in root.findall("link")}
    merged = {name for links_of_body in regressor.body_links for name in links_of_body[1:]}
    for i, body in enumerate(regressor.body_names):
        if body not in links:
            raise ConfigurationError(f"link {body!r} is not in the URDF")
        m, c, i_c = estimate.link(i)
        _set_inertial(links[body], m, c, i_c)
    for name in merged:
        if name in links:
            _set_inertial(links[name], _NEGLIGIBLE_MASS, np.zeros(3), np.zeros((3, 3)))
    names = regressor.parameter_names
    joints = {j.get("name"): j for j in root.findall("joint")}
    for joint_name in regressor.joint_names:
        viscous = _named(estimate.full, names, f"{joint_name}.viscous")
        coulomb = _named(estimate.full, names, f"{joint_name}.coulomb")
        if viscous is None and coulomb is None:
            continue
        element = joints[joint_name]
        dynamics = element.find("dynamics")
        if dynamics is None:
            dynamics = ET.SubElement(element, "dynamics")
        dynamics.set("damping", repr(float(viscous or 0.0)))
        dynamics.set("friction", repr(float(coulomb or 0.0)))
    if comments:
        text = "\n".join(["", "Inertials identified by semiparam_ros (export_urdf):",
                          *(f"  {line}" for line in comments), ""])
        root.insert(0, ET.Comment(text.replace("--", "- -")))
    return ET.tostring(root, encoding="unicode")


def _named(values: np.ndarray, names: tuple[str, ...], name: str) -> float | None:
    return float(values[names.index(name)]) if name in names else None


def _set_inertial(link: ET.Element, mass: float, com: np.ndarray, inertia: np.ndarray) -> None:
    inertial = link.find("inertial")
    if inertial is not None:
        link.remove(inertial)
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "origin", xyz=" ".join(repr(float(v)) for v in com), rpy="0 0 0")
    ET.SubElement(inertial, "mass", value=repr(float(mass)))
    ET.SubElement(inertial, "inertia", ixx=repr(float(inertia[0, 0])), ixy=repr(float(inertia[0, 1])),
                  ixz=repr(float(inertia[0, 2])), iyy=repr(float(inertia[1, 1])),
                  iyz=repr(float(inertia[1, 2])), izz=repr(float(inertia[2, 2])))
