"""Excitation design: a periodic trajectory whose base regressor is as well conditioned as the limits allow.

Identification is only as good as the motion it sees. Following Swevers et al. (1997), each joint moves on a
truncated Fourier series of period T = 2π/ω (:class:`~semiparam_ros.core.fourier.FourierTrajectory`),

    q_j(t) = c_j + s_j Σₖ [a_jk cos(kωt) + b_jk sin(kωt)],   k = 1 … K,

and the coefficients minimise the condition number κ of the stacked base regressor
``Y = [Φ_b(q(t_i), q̇(t_i), q̈(t_i))]_i`` (rigid-body base parameters with the configured friction and offset
columns, :meth:`~semiparam_ros.core.rigid_body.dynamics.RigidBodyRegressor.base_regressor`) over one
period, under the limits (:class:`ExcitationLimits`):

* **positions, velocities, accelerations** hold by construction: for given coefficients, the scale s_j of
  each joint is the largest for which ``lower ≤ q_j ≤ upper``, ``|q̇_j| ≤ v_j`` and ``|q̈_j| ≤ a_j`` on the
  optimisation grid, and the final trajectory is checked — and shrunk until it holds — at 1 kHz;
* **efforts** (the URDF's rigid-body torques ``Φ(q, q̇, q̈) π_CAD``) enter as a penalty and are checked the
  same way; friction is not known before identification, which the margin covers;
* **rest at t = 0** (and so at every multiple of T): a₁ and b₁ are set from the other harmonics so that
  ``q̇(0) = q̈(0) = 0``, and a ``joint_trajectory_controller`` can start the trajectory from a standstill.

The optimiser is L-BFGS on a smooth upper bound of ``log κ`` with its gradient
(:meth:`_Design.value_and_gradient`: ``∂f/∂Y = U diag(∂f/∂σ) Vᵀ``, and since each sample's rows depend on
that sample's state only, one finite difference of the regressor over the whole grid per joint and per q,
q̇, q̈ gives ``⟨∂Y/∂x, ∂f/∂Y⟩`` at every sample at once). The objective has many local minima: the best
three of a few random draws are optimised for a share of the budget each, the best of them for the rest.
κ is scale-dependent: it is the raw regressor's, in the units of the parameters (kg, kg·m, kg·m²,
N·m·s/rad, N·m), the usual definition of the identification literature.

What the trajectory determines is reported per base parameter as the standard deviation it would have
from ``rate × duration`` samples with 1 N·m of white torque noise: ``σ_i = sqrt([(YᵀY)⁻¹]_ii · N/(rate·T_d))``
(:attr:`Excitation.parameter_std`), computed from the R factor of Y.

Self-collision and the workspace are **not** checked: the position limits are the joints', and a user whose
arm can hit itself or its surroundings inside them must narrow them (``ExcitationLimits`` overrides).

Example:
    >>> import numpy as np
    >>> from semiparam_ros.core.kinds import OutputKind
    >>> from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
    >>> from semiparam_ros.core.rigid_body.urdf import example_robot_data_path
    >>> urdf = example_robot_data_path("robots/ur_description/urdf/ur5_robot.urdf")
    >>> reg = RigidBodyRegressor.from_urdf(urdf,
    ...     ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
    ...      "wrist_3_joint"], output=OutputKind.JOINT_TORQUES, friction=True, joint_offsets=True)
    >>> limits = ExcitationLimits.from_regressor(reg, margin=0.1)
    >>> exc = design_excitation(reg, limits, duration=10.0, n_harmonics=3, iterations=2, n_grid=40)
    >>> bool(exc.condition_number > 1.0), exc.trajectory.n_joints
    (True, 6)
    >>> bool(np.all(np.abs(exc.trajectory.evaluate(0.0)[1]) < 1e-9))  # at rest at t = 0
    True
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import qr, solve_triangular
from scipy.optimize import minimize

from semiparam_ros.core.fourier import MULTISINE_HARMONICS, FourierTrajectory, random_multisine_terms
from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.errors import ConfigurationError

__all__ = [
    "LIMIT_KINDS",
    "Excitation",
    "ExcitationLimits",
    "InfeasibleExcitationError",
    "condition_number",
    "design_excitation",
    "limit_usage",
    "parameter_std",
    "random_multisine",
]

#: The limits an excitation respects, as named in overrides (``JOINT.KIND=VALUE``).
LIMIT_KINDS: tuple[str, ...] = ("lower", "upper", "velocity", "acceleration", "effort")
#: Weight of the squared relative effort excess in the objective (log κ is O(1)–O(10)).
_EFFORT_PENALTY = 100.0
#: Power of the smooth condition number the optimiser minimises (:func:`_soft_log_condition`).
_SOFT_POWER = 8.0
#: Relative decrease of the objective below which a restarted optimiser counts as converged.
_RESTART_GAIN = 1e-4
#: Random draws optimised side by side before the best of them gets the rest of the budget.
_OPTIMISED_STARTS = 3
#: Default wished period (s) and harmonics: frequencies up to 0.6 Hz, the trajectory repeated in 20 s.
#: (10 harmonics, to 1 Hz, lower κ but identify a worse rigid body: docs/identification.md.)
DEFAULT_PERIOD_S = 10.0
DEFAULT_HARMONICS = 6
#: Default optimiser iterations (L-BFGS with the gradient of :meth:`_Design.value_and_gradient`).
DEFAULT_ITERATIONS = 200


class InfeasibleExcitationError(ConfigurationError):
    """The limits and margin leave no trajectory (e.g. gravity alone exceeds an effort limit)."""


@dataclass(frozen=True)
class ExcitationLimits:
    """Per-joint limits an excitation must respect, the margin already applied.

    Attributes:
        joint_names: The joints, in the regressor's order.
        lower: Lowest position (n,) (rad).
        upper: Highest position (n,) (rad).
        velocity: Largest |q̇| (n,) (rad/s).
        acceleration: Largest |q̈| (n,) (rad/s²); ``inf`` where only the efforts bound it.
        effort: Largest |τ| of the CAD rigid-body model (n,) (N·m).
        margin: The fraction kept free: each position range shrunk by ``margin × range`` at both ends,
            velocities, accelerations and efforts multiplied by ``1 − margin``.
        sources: Where each limit came from: per kind ``"URDF"``, ``"given"`` or ``"none (efforts)"``, and
            ``"JOINT.KIND": "given"`` for each override.
    """

    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    effort: np.ndarray
    margin: float = 0.0
    sources: dict[str, str] = field(default_factory=dict)

    @classmethod
    def from_regressor(cls, regressor: RigidBodyRegressor, *, margin: float = 0.1,
                       max_acceleration: float | None = None,
                       overrides: Mapping[str, float] | None = None) -> ExcitationLimits:
        """Read the limits from the URDF (through the regressor's Pinocchio model) and apply a margin.

        Args:
            regressor: The robot's regressor (its joints and URDF limits).
            margin: Fraction in [0, 0.5) kept free (see the attributes).
            max_acceleration: Largest |q̈| of every joint (rad/s²); URDFs carry none. None: bounded by the
                efforts (and the harmonics' frequencies) only.
            overrides: ``{"JOINT.KIND": value}`` replacing or supplying a URDF limit (KIND one of
                :data:`LIMIT_KINDS`; rad, rad/s, rad/s², N·m), e.g. for a joint without limits.

        Returns:
            The limits with the margin applied.

        Raises:
            ConfigurationError: A margin outside [0, 0.5); an override naming an unknown joint or kind or
                a non-finite value; a limit missing from the URDF and not given (the message names the
                joint, the limit and how to give it); lower ≥ upper.
        """
        if not (isinstance(margin, int | float) and 0.0 <= margin < 0.5):
            raise InfeasibleExcitationError(
                f"margin must be in [0, 0.5) (a fraction of each range), got {margin!r}")
        if max_acceleration is not None and not (math.isfinite(max_acceleration) and max_acceleration > 0):
            raise ConfigurationError(
                f"max_acceleration must be a positive number of rad/s², got {max_acceleration!r}")
        joints = regressor.joint_names
        lower, upper = regressor.position_limits()
        values = {
            "lower": lower, "upper": upper, "velocity": regressor.velocity_limits(),
            "effort": regressor.effort_limits(),
            "acceleration": np.full(len(joints),
                                    np.inf if max_acceleration is None else float(max_acceleration)),
        }
        sources = {kind: "URDF" for kind in LIMIT_KINDS}
        sources["acceleration"] = "none (efforts)" if max_acceleration is None else "given"
        for key, value in (overrides or {}).items():
            joint, _, kind = str(key).rpartition(".")
            if joint not in joints or kind not in LIMIT_KINDS:
                raise ConfigurationError(f"limit override {key!r}: expected JOINT.KIND with JOINT one of "
                                         f"{list(joints)} and KIND one of {list(LIMIT_KINDS)}")
            if not math.isfinite(float(value)):
                raise ConfigurationError(f"limit override {key!r} must be finite, got {value!r}")
            values[kind][joints.index(joint)] = float(value)
            sources[f"{joint}.{kind}"] = "given"
        for kind in ("lower", "upper", "velocity", "effort"):
            for j, name in enumerate(joints):
                v = values[kind][j]
                if not math.isfinite(v) or (kind in ("velocity", "effort") and v <= 0.0):
                    raise ConfigurationError(
                        f"joint {name!r} has no {kind} limit in the URDF ({v!r}); give one with "
                        f"--limit {name}.{kind}=VALUE ({_UNITS[kind]})")
        lo, hi = values["lower"], values["upper"]
        bad = np.flatnonzero(hi <= lo)
        if bad.size:
            j = int(bad[0])
            raise ConfigurationError(f"joint {joints[j]!r}: lower limit {lo[j]} ≥ upper limit {hi[j]} rad")
        span = hi - lo
        keep = 1.0 - margin
        return cls(tuple(joints), lo + margin * span, hi - margin * span, keep * values["velocity"],
                   keep * values["acceleration"], keep * values["effort"], float(margin), sources)

    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return len(self.joint_names)

    def as_dict(self) -> dict[str, object]:
        """Plain-Python description (rad, rad/s, rad/s², N·m; the margin applied)."""
        return {
            "margin": self.margin,
            "lower_rad": self.lower.tolist(), "upper_rad": self.upper.tolist(),
            "velocity_rad_per_s": self.velocity.tolist(),
            "acceleration_rad_per_s2": [None if not math.isfinite(a) else a for a in self.acceleration],
            "effort_Nm": self.effort.tolist(),
            "sources": dict(self.sources),
        }


_UNITS = {"lower": "rad", "upper": "rad", "velocity": "rad/s", "acceleration": "rad/s²", "effort": "N·m"}


@dataclass(frozen=True)
class Excitation:
    """A designed excitation and what it determines.

    Attributes:
        trajectory: One period of the trajectory (rad, rad/s, rad/s²), at rest at t = 0.
        periods: How many times the period is repeated; the duration is ``periods × trajectory.period``.
        condition_number: κ of the base regressor over one period (dimensionless).
        parameter_names: The base parameters (with friction and offsets).
        parameter_std: σ of each base parameter after ``rate × duration`` samples with 1 N·m white torque
            noise per joint (the parameters' units per N·m); scale by the sensor's noise.
        cad_values: The base parameters of the URDF (friction and offsets 0).
        usage: Largest fraction of each limit used at 1 kHz, ``{"position"|"velocity"|"acceleration"|
            "effort": (n,)}`` (position: of the half-range about the middle of [lower, upper]).
        limits: The limits respected.
        rate: The sampling rate σ refers to (Hz).
        iterations: Optimiser iterations run.
    """

    trajectory: FourierTrajectory
    periods: int
    condition_number: float
    parameter_names: tuple[str, ...]
    parameter_std: np.ndarray
    cad_values: np.ndarray
    usage: dict[str, np.ndarray]
    limits: ExcitationLimits
    rate: float
    iterations: int

    @property
    def duration(self) -> float:
        """The whole trajectory's length (s)."""
        return self.periods * self.trajectory.period

    def summary(self, n_worst: int = 5) -> str:
        """Return a short text: κ, limit usage, the least determined parameters."""
        lines = [f"condition number of the base regressor: {self.condition_number:.4g} "
                 f"({len(self.parameter_names)} base parameters, {self.trajectory.n_harmonics} harmonics, "
                 f"period {self.trajectory.period:.4g} s × {self.periods})"]
        for kind, used in self.usage.items():
            if kind == "acceleration" and not np.any(np.isfinite(self.limits.acceleration)):
                continue  # no acceleration limit was given
            lines.append(f"  largest use of the {kind} limits: {100 * float(np.max(used)):.0f} %")
        rel = self.parameter_std / np.maximum(np.abs(self.cad_values), 1e-12)
        lines.append(f"least determined base parameters (σ per N·m of noise at {self.rate:g} Hz over "
                     f"{self.duration:g} s):")
        for i in np.argsort(-self.parameter_std)[:n_worst]:
            cad = f", CAD {self.cad_values[i]:.3g} ({100 * rel[i]:.1f} %)" if self.cad_values[i] != 0 else ""
            lines.append(f"  {self.parameter_names[i]}: σ {self.parameter_std[i]:.3g}{cad}")
        return "\n".join(lines)


def _grid(period: float, n: int) -> np.ndarray:
    return np.arange(n, dtype=np.float64) * (period / n)


def condition_number(regressor: RigidBodyRegressor, trajectory: FourierTrajectory, *,
                     n_grid: int = 400) -> float:
    """Return κ of the base regressor stacked over one period sampled at ``n_grid`` uniform times.

    Args:
        regressor: The robot's regressor (its friction and offset columns included).
        trajectory: The trajectory (rad, rad/s, rad/s²).
        n_grid: Samples over the period.

    Returns:
        σ_max/σ_min of Y (``inf`` when Y is rank deficient).
    """
    q, dq, ddq = trajectory.evaluate(_grid(trajectory.period, n_grid))
    Y = regressor.base_regressor(q, dq, ddq).reshape(-1, regressor.n_base)
    s = np.linalg.svd(Y, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else math.inf


def parameter_std(regressor: RigidBodyRegressor, trajectory: FourierTrajectory, *, rate: float,
                  duration: float, n_grid: int = 400) -> np.ndarray:
    """Return σ of each base parameter from ``rate × duration`` samples with 1 N·m white torque noise.

    ``σ_i = sqrt([(YᵀY)⁻¹]_ii · N/(rate · duration))`` with Y the base regressor on ``n_grid`` uniform
    samples of one period: the rows of the inverse R factor of Y (no normal equations are formed).

    Args:
        regressor: The robot's regressor.
        trajectory: The trajectory.
        rate: Sampling rate (Hz).
        duration: Recording length (s).
        n_grid: Samples over the period.

    Returns:
        (n_base,) σ (the parameters' units per N·m); ``inf`` for an unexcited direction.
    """
    q, dq, ddq = trajectory.evaluate(_grid(trajectory.period, n_grid))
    Y = regressor.base_regressor(q, dq, ddq).reshape(-1, regressor.n_base)
    R = qr(Y, mode="r")[0][: Y.shape[1]]
    d = np.abs(np.diag(R))
    if d.min() <= 1e-12 * d.max():
        return np.full(Y.shape[1], np.inf)
    Rinv = solve_triangular(R, np.eye(R.shape[0]))  # rows of R⁻¹: diag((RᵀR)⁻¹) = Σ_j (R⁻¹)_ij²
    return np.sqrt(np.sum(Rinv * Rinv, axis=1) * n_grid / (rate * duration))


def limit_usage(regressor: RigidBodyRegressor, trajectory: FourierTrajectory, limits: ExcitationLimits, *,
                rate: float = 1000.0) -> dict[str, np.ndarray]:
    """Return the largest fraction of each limit used over one period sampled at ``rate``.

    Args:
        regressor: The robot's regressor (CAD rigid-body efforts ``Φ π_CAD``).
        trajectory: The trajectory.
        limits: The limits.
        rate: Sampling rate of the check (Hz).

    Returns:
        ``{"position", "velocity", "acceleration", "effort"}`` → (n,) fractions; ≤ 1 everywhere means
        every limit holds at every sample. Positions: ``max(q − mid)/(upper − mid)`` and the same below.
    """
    t = _grid(trajectory.period, max(math.ceil(trajectory.period * rate), 8))
    q, dq, ddq = trajectory.evaluate(t)
    mid = 0.5 * (limits.lower + limits.upper)
    half = 0.5 * (limits.upper - limits.lower)
    pos = np.maximum((q.max(0) - mid) / half, (mid - q.min(0)) / half)
    effort = _efforts(regressor, q, dq, ddq)
    with np.errstate(divide="ignore", invalid="ignore"):
        acc = np.where(np.isfinite(limits.acceleration), np.abs(ddq).max(0) / limits.acceleration, 0.0)
    return {"position": pos, "velocity": np.abs(dq).max(0) / limits.velocity, "acceleration": acc,
            "effort": np.abs(effort).max(0) / limits.effort}


def _efforts(regressor: RigidBodyRegressor, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray,
             chunk: int = 2000) -> np.ndarray:
    """CAD rigid-body joint torques (N·m) of many states, in chunks (bounded memory)."""
    pi = regressor.urdf_parameters()
    out = np.empty_like(q)
    for s in range(0, q.shape[0], chunk):
        out[s : s + chunk] = regressor.wrench(q[s : s + chunk], dq[s : s + chunk], ddq[s : s + chunk], pi)
    return out


def _soft_log_condition(s: np.ndarray, p: float = _SOFT_POWER) -> tuple[float, np.ndarray]:
    """Return a smooth upper bound of log κ and its derivatives ∂/∂σᵢ.

    p-norm means of σ and of 1/σ in place of max and min: ``log (Σσᵢᵖ)^{1/p} + log (Σσᵢ⁻ᵖ)^{1/p} ≥ log σ_max
    − log σ_min``, and unlike log κ it is differentiable where singular values cross: the optimiser does
    not stall between clustered smallest σ.
    """
    r = s / s[0]
    hi, lo = np.sum(r**p), np.sum(r ** (-p))
    return float(np.log(hi) / p + np.log(lo) / p), (r ** (p - 1) / hi - r ** (-p - 1) / lo) / s[0]


class _Design:
    """The map from free coefficients to a feasible trajectory, and the objective."""

    def __init__(self, regressor: RigidBodyRegressor, limits: ExcitationLimits, period: float,
                 n_harmonics: int, n_grid: int) -> None:
        self.reg, self.limits, self.K, self.n = regressor, limits, n_harmonics, limits.n_joints
        self.omega = 2.0 * math.pi / period
        t = _grid(period, n_grid)
        kw = self.omega * np.arange(1, n_harmonics + 1)
        ph = np.outer(t, kw)
        self.C, self.S, self.kw = np.cos(ph), np.sin(ph), kw
        self.k = np.arange(1, n_harmonics + 1, dtype=np.float64)
        self.mid = 0.5 * (limits.lower + limits.upper)
        self.half = 0.5 * (limits.upper - limits.lower)
        self.pi = regressor.urdf_parameters()
        self.base = regressor.base.independent

    @property
    def size(self) -> int:
        return (2 * (self.K - 1) + 1) * self.n

    def coefficients(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Free variables → (a, b, centre): a₁, b₁ set for rest at t = 0."""
        K, n = self.K, self.n
        z = z.reshape(2 * (K - 1) + 1, n)
        a = np.empty((K, n))
        b = np.empty((K, n))
        a[1:], b[1:] = z[: K - 1], z[K - 1 : 2 * (K - 1)]
        a[0] = -np.sum(self.k[1:, None] ** 2 * a[1:], axis=0)  # q̈(0) = −Σ aₖ(kω)² = 0
        b[0] = -np.sum(self.k[1:, None] * b[1:], axis=0)  # q̇(0) = Σ bₖ kω = 0
        centre = self.mid + 0.999 * self.half * np.tanh(z[-1])
        return a, b, centre

    def _unscaled(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the coefficients' positions about the centre, velocities and accelerations on the grid."""
        C, S, kw = self.C, self.S, self.kw[:, None]
        return C @ a + S @ b, S @ (-kw * a) + C @ (kw * b), -(C @ (kw**2 * a) + S @ (kw**2 * b))

    def scaled(self, z: np.ndarray) -> FourierTrajectory:
        """Return the trajectory of z, each joint scaled to the largest amplitude its grid limits allow."""
        a, b, centre = self.coefficients(z)
        s = self._scales(*self._unscaled(a, b), centre)[0]
        return FourierTrajectory(self.omega, centre, a * s, b * s)

    def _effort_penalty(self, tau: np.ndarray) -> tuple[float, np.ndarray]:
        """Return the penalty on the CAD efforts τ (grid, n) above their limits, and its derivatives ∂/∂τ."""
        cols = np.arange(self.n)
        peak = np.argmax(np.abs(tau), axis=0)
        excess = np.maximum(np.abs(tau[peak, cols]) / self.limits.effort - 1.0, 0.0)
        d_tau = np.zeros_like(tau)  # non-zero at each joint's peak sample only
        d_tau[peak, cols] = 2.0 * _EFFORT_PENALTY * excess * np.sign(tau[peak, cols]) / self.limits.effort
        return float(_EFFORT_PENALTY * np.sum(excess * excess)), d_tau

    #: Step of the per-sample finite differences of the regressor (rad, rad/s, rad/s²), relative to the
    #: largest |value| of each kind over the grid.
    FD_STEP = 1e-7

    def _scales(self, u: np.ndarray, du: np.ndarray, ddu: np.ndarray, centre: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per joint the scale s and its derivatives: ``(s, ∂s/∂centre, which, sample, ∂s/∂value)``.

        s is the smallest of four ratios (upper/lower position room, velocity, acceleration) over the grid;
        ``which`` ∈ {0: u, 1: du, 2: ddu} names the array its active sample (``sample``) is in, and
        ``∂s/∂value`` is the derivative with respect to that one value (a subgradient where two tie).
        """
        tiny = 1e-300
        n = u.shape[1]
        cols = np.arange(n)
        i_max, i_min = np.argmax(u, axis=0), np.argmin(u, axis=0)
        i_dv, i_acc = np.argmax(np.abs(du), axis=0), np.argmax(np.abs(ddu), axis=0)
        umax, umin = np.maximum(u[i_max, cols], tiny), np.maximum(-u[i_min, cols], tiny)
        vmax = np.maximum(np.abs(du[i_dv, cols]), tiny)
        amax = np.maximum(np.abs(ddu[i_acc, cols]), tiny)
        with np.errstate(divide="ignore"):
            ratios = np.stack([(self.limits.upper - centre) / umax, (centre - self.limits.lower) / umin,
                               self.limits.velocity / vmax, self.limits.acceleration / amax])
        active = np.argmin(ratios, axis=0)
        scale = ratios[active, cols]
        d_centre = np.where(active == 0, -1.0 / umax, np.where(active == 1, 1.0 / umin, 0.0))
        which = np.array([0, 0, 1, 2])[active]
        sample = np.choose(active, [i_max, i_min, i_dv, i_acc])
        # s = room/umax: ∂s/∂u = −s/umax; s = room/(−u_min): ∂s/∂u = s/umin; s = v/|du|: −s·sign(du)/|du|
        d_value = np.choose(active, [-scale / umax, scale / umin,
                                     -scale * np.sign(du[i_dv, cols]) / vmax,
                                     -scale * np.sign(ddu[i_acc, cols]) / amax])
        return scale, d_centre, which, sample, d_value

    def value_and_gradient(self, z: np.ndarray) -> tuple[float, np.ndarray]:
        """Return :meth:`objective` at z and its gradient, for the optimiser.

        ``∂f/∂Y = U diag(∂f/∂σ) Vᵀ`` from the thin SVD of the stacked base regressor Y; each sample's
        rows depend on that sample's state only, so ``⟨∂Y/∂x_j, ∂f/∂Y⟩`` for every sample at once is one
        finite difference of the regressor over the whole grid per joint and per q, q̇, q̈ (3n evaluations
        instead of one per coefficient); the effort penalty's gradient comes from the same differences of
        the CAD torques. The chain then runs through the scaling to the limits (the active limit's
        sample), the Fourier maps and the rest constraint on a₁, b₁, exactly.
        """
        a, b, centre = self.coefficients(z)
        C, S, kw = self.C, self.S, self.kw[:, None]
        u, du, ddu = self._unscaled(a, b)
        scale, d_centre, which, sample, d_value = self._scales(u, du, ddu, centre)
        x = [centre + scale * u, scale * du, scale * ddu]  # q, q̇, q̈ on the grid
        full = self.reg.regressor(*x)
        nb, base = self.base.size, self.base
        Y = full[..., base].reshape(-1, nb)
        U, sv, Vt = np.linalg.svd(Y, full_matrices=False)
        if not sv[-1] > 0:
            return 1e3, np.zeros_like(z)
        value, w = _soft_log_condition(sv)  # w = ∂f/∂σ_i
        G = ((U * w) @ Vt).reshape(full.shape[0], full.shape[1], nb)  # ∂f/∂Y per sample
        penalty, d_tau = self._effort_penalty(full @ self.pi)
        value += penalty
        grads = []
        for kind in range(3):
            g = np.empty_like(u)
            h = self.FD_STEP * max(1.0, float(np.max(np.abs(x[kind]))))
            for j in range(self.n):
                moved = [x[0], x[1], x[2]]
                moved[kind] = x[kind].copy()
                moved[kind][:, j] += h
                d_full = (self.reg.regressor(*moved) - full) / h
                g[:, j] = (np.einsum("tok,tok->t", d_full[..., base], G)
                           + np.einsum("to,to->t", d_full @ self.pi, d_tau))
            grads.append(g)
        gq, gdq, gddq = grads
        # q = centre + s u, q̇ = s du, q̈ = s ddu; s = s(u, du, ddu, centre) through its active sample
        d_scale = np.sum(gq * u + gdq * du + gddq * ddu, axis=0)
        g_u, g_du, g_ddu = scale * gq, scale * gdq, scale * gddq
        for j in range(self.n):
            [g_u, g_du, g_ddu][which[j]][sample[j], j] += d_scale[j] * d_value[j]
        g_centre = np.sum(gq, axis=0) + d_scale * d_centre
        g_a = C.T @ g_u - kw * (S.T @ g_du) - kw**2 * (C.T @ g_ddu)
        g_b = S.T @ g_u + kw * (C.T @ g_du) - kw**2 * (S.T @ g_ddu)
        # a₁ = −Σₖ k² aₖ, b₁ = −Σₖ k bₖ (k ≥ 2): the free aₖ, bₖ also move a₁, b₁
        K = self.K
        grad = np.empty((2 * (K - 1) + 1, self.n))
        grad[: K - 1] = g_a[1:] - self.k[1:, None] ** 2 * g_a[0]
        grad[K - 1 : 2 * (K - 1)] = g_b[1:] - self.k[1:, None] * g_b[0]
        zc = z.reshape(2 * (K - 1) + 1, self.n)[-1]
        grad[-1] = g_centre * 0.999 * self.half * (1.0 - np.tanh(zc) ** 2)
        return value, grad.reshape(-1)

    def objective(self, z: np.ndarray) -> float:
        traj = self.scaled(z)
        q, dq, ddq = traj.evaluate(_grid(traj.period, self.C.shape[0]))
        full = self.reg.regressor(q, dq, ddq)
        Y = full[..., self.base].reshape(-1, self.base.size)
        s = np.linalg.svd(Y, compute_uv=False)
        if not s[-1] > 0:
            return 1e3
        return _soft_log_condition(s)[0] + self._effort_penalty(full @ self.pi)[0]


def _shrink_to_limits(regressor: RigidBodyRegressor, traj: FourierTrajectory, limits: ExcitationLimits, *,
                      rate: float, max_rounds: int = 30) -> tuple[FourierTrajectory, dict[str, np.ndarray]]:
    """Shrink the amplitudes until every limit holds at ``rate`` (Hz); raise if even rest exceeds one."""
    for _ in range(max_rounds):
        usage = limit_usage(regressor, traj, limits, rate=rate)
        kin = np.maximum.reduce([usage["position"], usage["velocity"], usage["acceleration"]])
        worst_effort = float(np.max(usage["effort"]))
        if np.all(kin <= 1.0) and worst_effort <= 1.0:
            return traj, usage
        factor = np.where(kin > 1.0, (1.0 - 1e-9) / np.maximum(kin, 1e-300), 1.0)
        if worst_effort > 1.0:
            factor = factor * 0.8
        traj = FourierTrajectory(traj.omega, traj.offset, traj.cos_coef * factor, traj.sin_coef * factor)
    usage = limit_usage(regressor, traj, limits, rate=rate)
    j = int(np.argmax(usage["effort"]))
    raise InfeasibleExcitationError(
        f"no excitation respects the effort limit of joint {limits.joint_names[j]!r} "
        f"({limits.effort[j]:.4g} N·m after the margin): the CAD model needs "
        f"{usage['effort'][j] * limits.effort[j]:.4g} N·m even at small amplitude; lower the margin or "
        f"give a higher --limit {limits.joint_names[j]}.effort")


def _optimise(design: _Design, z: np.ndarray, f: float, iterations: int) -> tuple[float, np.ndarray, int]:
    """L-BFGS from z for at most ``iterations``: ``(objective, z, iterations used)``.

    The objective has kinks (the active limit's sample switches): L-BFGS's line search can stop there long
    before its budget; it is restarted from where it stopped (a fresh curvature memory) while it still
    improves.
    """
    nit = 0
    while nit < iterations:
        result = minimize(design.value_and_gradient, z, jac=True, method="L-BFGS-B",
                          options={"maxiter": iterations - nit, "maxfun": 1_000_000})
        nit += max(int(result.nit), 1)
        improved = result.fun < f - _RESTART_GAIN * abs(f)
        if result.fun < f:
            z, f = result.x, float(result.fun)
        if not improved:
            break
    return f, z, nit


def design_excitation(regressor: RigidBodyRegressor, limits: ExcitationLimits, *, duration: float,
                      period: float = DEFAULT_PERIOD_S, n_harmonics: int = DEFAULT_HARMONICS,
                      iterations: int = DEFAULT_ITERATIONS, n_starts: int = 16, n_grid: int = 100,
                      rate: float = 1000.0,
                      seed: int = 0) -> Excitation:
    """Design a periodic excitation minimising κ of the base regressor under the limits (module docstring).

    Args:
        regressor: The robot's regressor: its joints, URDF (CAD efforts) and the configured friction and
            offset columns (:func:`~semiparam_ros.core.estimator.build.build_regressor`).
        limits: The limits, margin applied (:meth:`ExcitationLimits.from_regressor`).
        duration: Length of the whole trajectory (s).
        period: The wished period (s): the trajectory repeats ``round(duration/period)`` (≥ 1) times, its
            period adjusted to divide the duration. Repetitions average the noise; the period and the
            harmonics set the highest frequency, ``n_harmonics/period``.
        n_harmonics: Harmonics K per joint (≥ 2: the first is spent on starting at rest).
        iterations: L-BFGS iterations (each ~ (2K − 1)·n objective evaluations).
        n_starts: Random draws the best of which starts the optimiser.
        n_grid: Samples per period of the objective.
        rate: Rate of the final limit check and of the reported σ (Hz).
        seed: Seed of the random draws (deterministic).

    Returns:
        The excitation, every limit checked at ``rate``.

    Raises:
        ConfigurationError: A non-positive duration or period, K < 2, a limit set of other joints.
        InfeasibleExcitationError: No trajectory respects the efforts (the message names the joint).
    """
    if not (math.isfinite(duration) and duration > 0):
        raise ConfigurationError(f"duration must be a positive number of seconds, got {duration!r}")
    if not (math.isfinite(period) and period > 0):
        raise ConfigurationError(f"period must be a positive number of seconds, got {period!r}")
    if n_harmonics < 2 or n_grid < 4 * n_harmonics or iterations < 0 or n_starts < 1:
        raise ConfigurationError("n_harmonics ≥ 2, n_grid ≥ 4·n_harmonics, iterations ≥ 0 and n_starts ≥ 1 "
                                 "are required")
    periods = max(1, round(duration / period))
    if tuple(limits.joint_names) != tuple(regressor.joint_names):
        raise ConfigurationError(f"limits are for joints {list(limits.joint_names)}, the regressor's are "
                                 f"{list(regressor.joint_names)}")
    design = _Design(regressor, limits, duration / periods, n_harmonics, n_grid)
    rng = np.random.default_rng(seed)
    decay = np.concatenate([np.repeat(1.0 / design.k[1:], design.n), np.repeat(1.0 / design.k[1:], design.n),
                            np.zeros(design.n)])
    draws = []
    for _ in range(n_starts):
        z0 = rng.standard_normal(design.size) * decay
        z0[-design.n:] = 0.3 * rng.standard_normal(design.n)
        draws.append((design.objective(z0), z0))
    draws.sort(key=lambda d: d[0])
    # the objective has many local minima: the best few draws are optimised for a share of the budget
    # each, the best of them for the rest
    candidates = draws[: max(1, min(_OPTIMISED_STARTS, n_starts))] if iterations > 0 else draws[:1]
    share = iterations // (2 * len(candidates)) if len(candidates) > 1 else iterations
    runs = [_optimise(design, z0, f0, share) for f0, z0 in candidates]
    f, z, _ = min(runs, key=lambda r: r[0])
    nit = sum(r[2] for r in runs)
    if len(candidates) > 1:
        f, z, more = _optimise(design, z, f, iterations - share * len(candidates))
        nit += more
    traj, usage = _shrink_to_limits(regressor, design.scaled(z), limits, rate=rate)
    n_report = max(n_grid, 400)
    return Excitation(
        trajectory=traj, periods=int(periods),
        condition_number=condition_number(regressor, traj, n_grid=n_report),
        parameter_names=regressor.base_parameter_names,
        parameter_std=parameter_std(regressor, traj, rate=rate, duration=duration, n_grid=n_report),
        cad_values=regressor.to_base(regressor.urdf_parameters()),
        usage=usage, limits=limits, rate=float(rate), iterations=nit)


def random_multisine(regressor: RigidBodyRegressor, limits: ExcitationLimits, *, period: float, seed: int,
                     harmonics: tuple[int, ...] = MULTISINE_HARMONICS,
                     rate: float = 1000.0) -> FourierTrajectory:
    """Return the baseline: a random multi-sine as large as the same limits allow.

    Each joint gets the harmonics ``k/period`` with random phases and amplitudes ∝ U(0.5, 1)/k about the
    middle of its range, scaled per joint to the largest amplitude the position, velocity and acceleration
    limits allow on a grid at ``rate``, then shrunk until the CAD efforts hold — the same limits and checks
    as :func:`design_excitation`, without the optimisation.

    Args:
        regressor: The robot's regressor.
        limits: The limits.
        period: Period (s).
        seed: Seed (deterministic).
        harmonics: Harmonic numbers.
        rate: Rate of the limit check (Hz).

    Returns:
        The trajectory.
    """
    rng = np.random.default_rng(seed)
    ks = np.asarray(sorted(set(harmonics)), dtype=np.int64)
    n = limits.n_joints
    a = np.zeros((int(ks[-1]), n))
    b = np.zeros((int(ks[-1]), n))
    amplitudes, phases = random_multisine_terms(rng, ks, n)
    for j in range(n):
        a[ks - 1, j] = amplitudes[j] * np.sin(phases[j])
        b[ks - 1, j] = amplitudes[j] * np.cos(phases[j])
    omega = 2.0 * math.pi / period
    mid = 0.5 * (limits.lower + limits.upper)
    raw = FourierTrajectory(omega, mid, a, b)
    q, dq, ddq = raw.evaluate(_grid(period, max(int(period * rate), 8)))
    u = q - mid
    half = 0.5 * (limits.upper - limits.lower)
    s = np.minimum.reduce([half / np.abs(u).max(0), limits.velocity / np.abs(dq).max(0),
                           limits.acceleration / np.abs(ddq).max(0)]) * (1.0 - 1e-9)
    traj = FourierTrajectory(omega, mid, a * s, b * s)
    return _shrink_to_limits(regressor, traj, limits, rate=rate)[0]
