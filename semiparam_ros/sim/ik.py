"""Closed-loop inverse kinematics (CLIK) of the iCub right arm, and its converged periodic orbit.

The hand (frame ``r_hand_dh_frame``, the palm) tracks a Cartesian reference with the four joints
``r_shoulder_pitch, r_shoulder_roll, r_shoulder_yaw, r_elbow``; every other joint (torso, wrist, head, legs,
left arm) is locked at a fixed position. The 3-D position task leaves one redundant degree of freedom,
resolved by a posture term in the null space:

    q̇ = J⁺(ẋ_d + K_p (x_d − x)) + (I − J⁺J) k_n (q_rest − q),    J⁺ = Jᵀ(JJᵀ + λ²I)⁻¹

(damped least squares, J the 3×4 translational Jacobian in the root frame). Integrated with a fine step
over several periods of a periodic reference, the joint motion converges to a periodic orbit; one period of
it, sampled on a uniform grid, is fitted by a Fourier series (:class:`~semiparam_ros.sim.trajectories.
FourierTrajectory`) whose q, q̇, q̈ are then exactly consistent. Joint limits are checked on the orbit
(with a margin): a reference the arm cannot follow inside its limits raises ``ValueError``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from semiparam_ros.core.config import ICUB_RIGHT_ARM
from semiparam_ros.sim.trajectories import CartesianCircle, FourierTrajectory

__all__ = [
    "ARM_JOINTS",
    "ArmKinematics",
    "ClikResult",
    "clik_periodic_orbit",
]

#: The four joints the paper's arm model uses (shoulder pitch, roll, yaw, elbow): the estimator's iCub.
ARM_JOINTS: tuple[str, ...] = tuple(ICUB_RIGHT_ARM["robot.joints"])


class ArmKinematics:
    """Forward kinematics and Jacobian of the hand for a subset of joints of a URDF (others locked).

    Args:
        urdf_path: Path of the robot's URDF.
        joints: The active joints, in the order of q.
        locked: Positions (rad) of the locked joints; joints not listed are locked at 0 (or at the
            nearest limit when 0 is outside it).
        end_effector: Name of the frame whose origin tracks the reference.

    Raises:
        ValueError: If a joint or the frame is not in the URDF, or a locked position is outside its limits.
    """

    def __init__(
        self,
        urdf_path: str | Path,
        joints: Sequence[str] = ARM_JOINTS,
        *,
        locked: Mapping[str, float] | None = None,
        end_effector: str = "r_hand_dh_frame",
    ) -> None:
        full = pin.buildModelFromUrdf(str(urdf_path))
        names = list(full.names)[1:]
        missing = [j for j in joints if j not in names]
        if missing:
            raise ValueError(f"joints not in the URDF: {missing}")
        locked = dict(locked or {})
        unknown = [j for j in locked if j not in names]
        if unknown:
            raise ValueError(f"locked joints not in the URDF: {unknown}")
        q_full = pin.neutral(full)
        locked_positions: dict[str, float] = {}
        for name in names:
            if name in joints:
                continue
            jid = full.getJointId(name)
            idx = full.joints[jid].idx_q
            lo, hi = full.lowerPositionLimit[idx], full.upperPositionLimit[idx]
            value = float(locked.get(name, min(max(0.0, lo), hi)))
            if not (lo - 1e-12 <= value <= hi + 1e-12):
                raise ValueError(f"locked position of {name} = {value} rad is outside [{lo}, {hi}]")
            q_full[idx] = value
            locked_positions[name] = value
        lock_ids = [full.getJointId(n) for n in names if n not in joints]
        reduced = pin.buildReducedModel(full, lock_ids, q_full)
        reduced_names = list(reduced.names)[1:]
        self._perm = np.array([reduced_names.index(j) for j in joints])
        if not reduced.existFrame(end_effector):
            raise ValueError(f"frame {end_effector!r} not in the URDF")
        self.model = reduced
        self.data = reduced.createData()
        self.frame_id = reduced.getFrameId(end_effector)
        self.joint_names: tuple[str, ...] = tuple(joints)
        self.locked_positions: dict[str, float] = locked_positions
        self.lower = reduced.lowerPositionLimit[self._perm].copy()
        self.upper = reduced.upperPositionLimit[self._perm].copy()

    @property
    def n_joints(self) -> int:
        """Number of active joints."""
        return len(self.joint_names)

    def _to_model(self, q: np.ndarray) -> np.ndarray:
        qm = np.empty(self.model.nq)
        qm[self._perm] = q
        return qm

    def position(self, q: np.ndarray) -> np.ndarray:
        """Hand position in the root frame (m) for joint positions ``q`` (rad, configured order)."""
        pin.framesForwardKinematics(self.model, self.data, self._to_model(np.asarray(q, dtype=np.float64)))
        return self.data.oMf[self.frame_id].translation.copy()

    def frame_poses(self, q: np.ndarray, frames: Sequence[str]) -> list[tuple[np.ndarray, np.ndarray]]:
        """Poses of URDF frames (links or joints) in the root frame.

        Args:
            q: Joint positions (rad), configured order.
            frames: Frame names.

        Returns:
            One ``(R, p)`` per frame: rotation (3×3) and origin (3,) in m, root frame.

        Raises:
            ValueError: If a frame is unknown.
        """
        ids = []
        for name in frames:
            if not self.model.existFrame(name):
                raise ValueError(f"frame {name!r} not in the URDF")
            ids.append(self.model.getFrameId(name))
        pin.framesForwardKinematics(self.model, self.data, self._to_model(np.asarray(q, dtype=np.float64)))
        return [(self.data.oMf[i].rotation.copy(), self.data.oMf[i].translation.copy()) for i in ids]

    def frame_acceleration(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, frame: str) -> np.ndarray:
        """Classical linear acceleration (m/s²) of a frame origin in the root frame.

        Args:
            q: Joint positions (rad), configured order.
            dq: Joint velocities (rad/s).
            ddq: Joint accelerations (rad/s²).
            frame: Frame name.

        Returns:
            (3,) acceleration of the frame origin, root-frame axes.

        Raises:
            ValueError: If the frame is unknown.
        """
        if not self.model.existFrame(frame):
            raise ValueError(f"frame {frame!r} not in the URDF")
        args = (self._to_model(np.asarray(v, dtype=np.float64)) for v in (q, dq, ddq))
        pin.forwardKinematics(self.model, self.data, *args)
        fid = self.model.getFrameId(frame)
        acc = pin.getFrameClassicalAcceleration(self.model, self.data, fid, pin.LOCAL_WORLD_ALIGNED)
        return acc.linear.copy()

    def position_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Hand position (m) and its 3×n Jacobian (m/rad) in the root frame, columns in configured order."""
        qm = self._to_model(np.asarray(q, dtype=np.float64))
        pin.computeJointJacobians(self.model, self.data, qm)
        pin.updateFramePlacements(self.model, self.data)
        J = pin.getFrameJacobian(self.model, self.data, self.frame_id, pin.LOCAL_WORLD_ALIGNED)
        return self.data.oMf[self.frame_id].translation.copy(), J[:3, self._perm]


@dataclass(frozen=True)
class ClikResult:
    """The converged periodic orbit of CLIK.

    Attributes:
        trajectory: Fourier series of one period of the orbit (analytic q, q̇, q̈).
        grid_positions: ``(N, n)`` orbit samples on the uniform grid of one period (rad).
        periodicity_error: max |q(t + T) − q(t)| between the last two simulated periods (rad).
        fit_error: max |series − grid samples| (rad).
        tracking_error: max hand position error of the fitted series over the grid (m).
        min_limit_margin: Smallest distance of the series' positions to a joint limit (rad).
    """

    trajectory: FourierTrajectory
    grid_positions: np.ndarray
    periodicity_error: float
    fit_error: float
    tracking_error: float
    min_limit_margin: float


def _dls_step(J: np.ndarray, damping: float) -> np.ndarray:
    """Damped pseudo-inverse Jᵀ(JJᵀ + λ²I)⁻¹ via a symmetric solve (no explicit inverse)."""
    A = J @ J.T + (damping * damping) * np.eye(J.shape[0])
    return np.linalg.solve(A, J).T


def clik_periodic_orbit(
    kin: ArmKinematics,
    reference: CartesianCircle,
    q_rest: np.ndarray,
    *,
    grid: int = 512,
    substeps: int = 8,
    gain: float = 200.0,
    posture_gain: float = 4.0,
    damping: float = 1e-3,
    max_periods: int = 40,
    tol: float = 1e-9,
    n_harmonics: int = 48,
    limit_margin: float = 0.02,
    posture_weights: np.ndarray | None = None,
    limit_gain: float = 0.0,
    progress: Callable[[int], None] | None = None,
) -> ClikResult:
    """Run CLIK on a periodic reference until the joint motion is periodic; fit one period.

    Starts from ``q_rest`` refined onto the reference's initial point, integrates with the explicit Euler
    step ``T/(grid·substeps)`` and stops when two consecutive periods agree within ``tol``.

    Args:
        kin: Arm kinematics.
        reference: The hand's periodic reference (period T).
        q_rest: Posture the null-space term pulls towards (rad), shape ``(n,)``.
        grid: Samples per period kept for the Fourier fit.
        substeps: Integration steps per grid interval.
        gain: Task-space error gain K_p (1/s).
        posture_gain: Null-space posture gain k_n (1/s).
        damping: Damping λ of the least-squares inverse (m).
        max_periods: Give up after this many periods.
        tol: Periodicity tolerance (rad).
        n_harmonics: Harmonics kept in the fit.
        limit_margin: Required clearance from every joint limit (rad).
        posture_weights: Per-joint weights of the posture term (default: (mean range / range)², which
            makes it the gradient of the normalised distance to ``q_rest``, so narrow joints are held
            closer to their rest position).
        limit_gain: Gain of the joint-limit barrier k_l in the null space: adds
            k_l·(1/(q − q_min) − 1/(q_max − q)) (rad/s), which pushes the redundant motion away from the
            nearer limit.
        progress: Optional callback called with 1 after each simulated period.

    Returns:
        The :class:`ClikResult`.

    Raises:
        ValueError: If the orbit does not converge, or leaves the joint limits minus the margin.
    """
    q = np.asarray(q_rest, dtype=np.float64).reshape(-1).copy()
    q_rest = q.copy()
    if q.shape != (kin.n_joints,):
        raise ValueError(f"q_rest must have shape ({kin.n_joints},)")
    rng_ = kin.upper - kin.lower
    weights = (np.mean(rng_) / rng_) ** 2 if posture_weights is None else np.asarray(posture_weights, float)
    W = posture_gain * weights
    lo, hi = kin.lower, kin.upper
    T = reference.period
    dt = T / (grid * substeps)
    eye = np.eye(kin.n_joints)
    # Converge onto the starting point of the reference first (static IK, same posture term).
    x0 = reference.position(0.0)[0]
    for _ in range(2000):
        x, J = kin.position_jacobian(q)
        Jp = _dls_step(J, damping)
        q = q + Jp @ (x0 - x) + (eye - Jp @ J) @ (0.05 * (q_rest - q))
        if np.linalg.norm(x0 - x) < 1e-12:
            break
    previous = None
    for _period_index in range(max_periods):
        samples = np.empty((grid, kin.n_joints))
        t_grid = T * np.arange(grid) / grid
        xd_all = reference.position(T * np.arange(grid * substeps) / (grid * substeps))
        vd_all = reference.velocity(T * np.arange(grid * substeps) / (grid * substeps))
        for i in range(grid * substeps):
            if i % substeps == 0:
                samples[i // substeps] = q
            x, J = kin.position_jacobian(q)
            Jp = _dls_step(J, damping)
            dq = Jp @ (vd_all[i] + gain * (xd_all[i] - x)) + (eye - Jp @ J) @ (
                W * (q_rest - q) + limit_gain * (1.0 / (q - lo) - 1.0 / (hi - q))
            )
            q = q + dt * dq
        if progress is not None:
            progress(1)
        if not np.all(np.isfinite(q)):
            raise ValueError("CLIK diverged")
        if previous is not None:
            err = float(np.max(np.abs(samples - previous)))
            if err < tol:
                break
        previous = samples
    else:
        raise ValueError(f"CLIK did not converge to a periodic orbit within {max_periods} periods")
    traj = FourierTrajectory.fit_periodic(samples, T, n_harmonics)
    q_fit, _, _ = traj.evaluate(t_grid)
    fit_error = float(np.max(np.abs(q_fit - samples)))
    x_ref = reference.position(t_grid)
    tracking = max(float(np.linalg.norm(kin.position(qi) - xi)) for qi, xi in zip(q_fit, x_ref, strict=True))
    # Limits on a finer grid of the analytic series (it interpolates between the CLIK samples).
    q_fine, _, _ = traj.evaluate(np.linspace(0.0, T, 8 * grid, endpoint=False))
    margin = float(min(np.min(q_fine - kin.lower), np.min(kin.upper - q_fine)))
    if margin < limit_margin:
        raise ValueError(
            f"the reference needs joint positions within {margin:.4f} rad of a limit (required clearance "
            f"{limit_margin} rad): move the circle centre or reduce the radius"
        )
    return ClikResult(traj, samples, err, fit_error, tracking, margin)
