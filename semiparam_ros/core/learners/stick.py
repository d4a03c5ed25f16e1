"""Friction that remembers: a per-joint stick state and the torque it holds beyond the static model.

The learners are static maps of (q, q̇, q̈): at rest their Coulomb friction ``f_c tanh(q̇/v_s)`` is 0,
while a real joint holds whatever friction its approach left (pre-sliding, stiction): after a move in the
positive direction the friction at rest still opposes it. Each joint j carries a normalized Dahl state
z_j ∈ [−1, 1] of its path,

    z ← s + (z − s) · exp(−|Δq| / δ),        s = sgn(Δq),

(δ the pre-sliding displacement ``parametric.stick_displacement`` [rad]; exact per step of positions,
so it does not depend on the rate; unchanged where q does not move). In motion z → sgn(q̇) within a few
δ of travel, as the static column does; at rest it keeps the last direction. The feature is what the
static model misses,

    φ_j = z_j − tanh(q̇_j / v_s),

0 in steady motion, ±1 at rest after a move. The torque it holds, ``c_j φ_j`` [N·m], is added to the
prediction of joint j; c_j is a ridge regression of the model's a-priori error on φ_j, weighted by time
(the same at any rate) with the learners' memory τ and a prior c_j = 0 worth :data:`PRIOR_S` seconds:

    a_j ← e^{−Δt/τ} a_j + Δt φ_j²,   b_j ← e^{−Δt/τ} b_j + Δt φ_j e_j,   c_j = b_j / (a_j + PRIOR_S).

The learners learn ``y − c φ``. A prediction over a sequence of states carries z along the rows from a
starting state (the measured path's, or a controller's previous desired state): :meth:`StickState.advance`.

>>> stick = StickFriction(n_joints=1, displacement=1e-3, coulomb_velocity=0.05, time_constant_s=20.0)
>>> state = StickState.fresh(1)
>>> phi = stick.features(np.array([[0.0], [0.01], [0.01]]), np.array([[0.0], [0.5], [0.0]]), state)
>>> [round(float(p), 3) + 0.0 for p in phi[:, 0]]  # start: no history; moving up: ≈ 0; at rest: +1
[0.0, 0.0, 1.0]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from semiparam_ros.core.learners.contract import Prediction
from semiparam_ros.errors import ConfigurationError

__all__ = ["PRIOR_S", "StickFriction", "StickState", "with_held"]

#: Weight of the prior c = 0, in seconds of samples with |φ| = 1.
PRIOR_S = 0.5


@dataclass
class StickState:
    """Where a path left each joint's stick state: z (n,) and the last position (n,) [rad] (None: none)."""

    z: np.ndarray
    q: np.ndarray | None = None

    @classmethod
    def fresh(cls, n_joints: int) -> StickState:
        """Return the state before any motion (z = 0, no position)."""
        return cls(np.zeros(n_joints))

    def copy(self) -> StickState:
        """Return an independent copy."""
        return StickState(self.z.copy(), None if self.q is None else self.q.copy())

    def advance(self, q: np.ndarray, displacement: float) -> np.ndarray:
        """Move to the positions q (n,) [rad] and return the new z (also stored)."""
        if self.q is not None:
            step = q - self.q
            s = np.sign(step)
            self.z = np.where(step != 0.0, s + (self.z - s) * np.exp(-np.abs(step) / displacement), self.z)
        self.q = np.array(q, dtype=np.float64)
        return self.z


class StickFriction:
    """The per-joint torque the stick state holds: ``c_j φ_j`` (module docstring).

    Args:
        n_joints: n.
        displacement: δ > 0, the pre-sliding displacement [rad].
        coulomb_velocity: v_s > 0 of the static Coulomb column [rad/s].
        time_constant_s: τ > 0, the memory of c [s].

    Raises:
        ConfigurationError: For n < 1 or a δ, v_s or τ that is not a finite number > 0.

    Attributes:
        coefficient: (n,) c [N·m].
        state: The measured path's :class:`StickState`.
    """

    def __init__(self, n_joints: int, displacement: float, coulomb_velocity: float,
                 time_constant_s: float) -> None:
        values = (float(displacement), float(coulomb_velocity), float(time_constant_s))
        if n_joints < 1 or not all(math.isfinite(v) and v > 0.0 for v in values):
            raise ConfigurationError(f"stick friction needs joints and finite δ, v_s, τ > 0, got {n_joints}, "
                                     f"{values}")
        self.n_joints = int(n_joints)
        self.displacement, self.coulomb_velocity, self.time_constant_s = values
        self.reset()

    def reset(self) -> None:
        """Forget c and the path."""
        self._a = np.zeros(self.n_joints)
        self._b = np.zeros(self.n_joints)
        self.coefficient = np.zeros(self.n_joints)
        self.state = StickState.fresh(self.n_joints)
        self._last_ns: int | None = None

    def restart_stream(self) -> None:
        """Begin a new recording: the path is unknown (z = 0), c is kept."""
        self.state = StickState.fresh(self.n_joints)
        self._last_ns = None

    def features(self, q: np.ndarray, dq: np.ndarray, state: StickState) -> np.ndarray:
        """Return φ at each row of a sequence (N, n), advancing ``state`` along it.

        Args:
            q: (N, n) positions in time order [rad].
            dq: (N, n) velocities [rad/s].
            state: Where the path starts (changed: it ends at the last row).
        """
        q2 = np.atleast_2d(np.asarray(q, dtype=np.float64))
        static = np.tanh(np.atleast_2d(np.asarray(dq, dtype=np.float64)) / self.coulomb_velocity)
        z = np.empty_like(q2)
        for i in range(q2.shape[0]):
            z[i] = state.advance(q2[i], self.displacement)
        return z - static

    def step(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """Advance the measured path by one sample and return its φ (n,)."""
        return self.features(q[None, :], dq[None, :], self.state)[0]

    def torque(self, phi: np.ndarray) -> np.ndarray:
        """Return ``c φ`` [N·m] for φ of shape (n,) or (N, n)."""
        return self.coefficient * phi

    def held(self, q: np.ndarray, dq: np.ndarray, state: StickState) -> np.ndarray:
        """Return the torque held along a sequence (N, n) [N·m], advancing ``state`` (:meth:`features`)."""
        return self.torque(self.features(q, dq, state))

    def learn(self, stamp_ns: int, phi: np.ndarray, error: np.ndarray) -> None:
        """Regress the model's a-priori error e (n,) [N·m] on φ (n,) at a stamp [ns] (module docstring)."""
        last, self._last_ns = self._last_ns, stamp_ns
        if last is None or stamp_ns <= last or not np.all(np.isfinite(error)):
            return
        dt = min((stamp_ns - last) * 1e-9, self.time_constant_s)
        fade = math.exp(-dt / self.time_constant_s)
        self._a = fade * self._a + dt * phi * phi
        self._b = fade * self._b + dt * phi * error
        self.coefficient = self._b / (self._a + PRIOR_S)

    def copy(self) -> StickFriction:
        """Return an independent copy (coefficient, statistics and the path)."""
        twin = StickFriction(self.n_joints, self.displacement, self.coulomb_velocity, self.time_constant_s)
        twin._a, twin._b, twin.coefficient = self._a.copy(), self._b.copy(), self.coefficient.copy()
        twin.state, twin._last_ns = self.state.copy(), self._last_ns
        return twin

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return c's statistics and the path's state as arrays."""
        return {f"{prefix}a": self._a.copy(), f"{prefix}b": self._b.copy(), f"{prefix}z": self.state.z.copy(),
                f"{prefix}q": np.array([] if self.state.q is None else self.state.q, dtype=np.float64)}

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Replace the statistics and the path by those of :meth:`state_dict` (validated first).

        Raises:
            KeyError: A key is missing.
            ValueError: Wrong sizes, non-finite values, a negative ``a`` or |z| > 1.
        """
        n = self.n_joints
        a, b, z = (np.asarray(state[f"{prefix}{k}"], dtype=np.float64).reshape(-1) for k in ("a", "b", "z"))
        q = np.asarray(state[f"{prefix}q"], dtype=np.float64).reshape(-1)
        if not (a.shape == b.shape == z.shape == (n,) and q.size in (0, n)):
            raise ValueError(f"stick friction arrays must hold {n} values each")
        finite = all(np.isfinite(v).all() for v in (a, b, z, q))
        if not (finite and (a >= 0).all() and (np.abs(z) <= 1.0).all()):
            raise ValueError("stick friction arrays hold non-finite values, a negative weight or |z| > 1")
        self._a, self._b = a.copy(), b.copy()
        self.coefficient = b / (a + PRIOR_S)
        self.state = StickState(z.copy(), q.copy() if q.size else None)
        self._last_ns = None


def with_held(prediction: Prediction, held: np.ndarray | None) -> Prediction:
    """Return a prediction with the held torque added to its rigid-body part and total (None: unchanged)."""
    if held is None:
        return prediction
    return Prediction(prediction.parametric + held, prediction.residual, prediction.total + held,
                      prediction.variance, prediction.correction)
