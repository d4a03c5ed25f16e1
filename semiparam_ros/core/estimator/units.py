"""Are the measured efforts joint torques in N·m? A start-up comparison with the URDF's torques.

Some drivers publish motor currents (A) in ``JointState.effort`` — the UR ROS 2 driver does by default — and
a model learning amperes against a URDF prior in N·m learns nonsense without a word. On the first seconds
of joint states, :class:`EffortUnitsCheck` fits each joint's measured effort ``y`` to the URDF's
rigid-body torque ``τ = RNEA_urdf(q, q̇, q̈)`` through the origin,

    k_j = Σ y τ / Σ τ²,        c_j = Σ y τ / sqrt(Σ y² Σ τ²)   (cosine similarity),

and reports the joints where the two agree in shape (``c_j ≥`` :data:`MIN_COSINE`) but not in scale
(``k_j`` outside ``[1/`` :data:`MAX_RATIO` ``,`` :data:`MAX_RATIO` ``]``, or negative: a flipped sign). A
joint whose URDF torque barely changes over the window (a vertical first axis) says nothing and is not
judged. Unmodelled friction and offsets lower ``c_j``; a currents-for-torques mix-up keeps it near 1, which
is what the check looks for. It reads one sample every :data:`SPACING_S` of stamps (rate-independent)
and concludes after :data:`N_SAMPLES`, so it costs one RNEA per 10 ms of data until then, nothing after.

>>> import numpy as np

from semiparam_ros.errors import RejectedSampleError
>>> class Urdf:  # a stand-in regressor: the URDF torque of two joints is (q0, 2 q1)
...     def wrench(self, q, dq, ddq):
...         return np.array([q[0], 2.0 * q[1]])
>>> check = EffortUnitsCheck(Urdf(), ("a", "b"), n_samples=50)
>>> for k in range(60):
...     q = np.array([np.sin(k), np.cos(k)])
...     _ = check.add(k * 10**7, q, q, q, np.array([q[0], 0.1 * 2.0 * q[1]]))  # b reports a tenth
>>> [(f.joint, round(f.scale, 3)) for f in check.findings]
[('b', 0.1)]
>>> print(check.message())  # doctest: +NORMALIZE_WHITESPACE
measured efforts are not the URDF's joint torques in N·m: b reads 0.1 × the URDF's torque (cosine 1.00);
if the driver reports motor currents or another unit, set robot.effort_scale (N·m per reported unit, one
per joint) or publish torques
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from semiparam_ros.errors import RejectedSampleError

__all__ = ["MAX_RATIO", "MIN_COSINE", "N_SAMPLES", "SPACING_S", "EffortUnitsCheck", "ScaleFinding"]

#: Samples the check collects before it concludes (≈ 4 s of data at :data:`SPACING_S`).
N_SAMPLES = 400
#: Least stamp spacing between two samples the check reads [s].
SPACING_S = 0.01
#: Least cosine similarity of measured and URDF torques for a scale to be meaningful.
MIN_COSINE = 0.9
#: A scale beyond this factor either way (or negative) is reported.
MAX_RATIO = 2.0
#: A joint whose URDF torque RMS is below this fraction of the largest joint's says nothing.
_MIN_RELATIVE_RMS = 0.05


class _UrdfTorques(Protocol):
    def wrench(self, q: Any, dq: Any, ddq: Any) -> np.ndarray: ...


@dataclass(frozen=True)
class ScaleFinding:
    """One joint whose measured efforts are a scaled copy of the URDF's torques.

    Attributes:
        joint: The joint's name.
        scale: Fitted ``k`` in ``effort ≈ k · τ_urdf`` (reported units per N·m).
        cosine: Cosine similarity of the two series (1 = same shape).
    """

    joint: str
    scale: float
    cosine: float


class EffortUnitsCheck:
    """Compare the first seconds of measured efforts with the URDF's torques (see the module docstring).

    Args:
        regressor: The rigid-body regressor of the joint torques (its ``wrench(q, dq, ddq)`` with the URDF's
            parameters is the URDF's torque, N·m).
        joints: Joint names, in the order of the samples.
        n_samples: Samples read before concluding (≥ 10).
        spacing_s: Least stamp spacing between read samples [s].
    """

    def __init__(self, regressor: _UrdfTorques, joints: Sequence[str], *, n_samples: int = N_SAMPLES,
                 spacing_s: float = SPACING_S) -> None:
        self._regressor = regressor
        self._joints = tuple(joints)
        self._n_samples = max(10, int(n_samples))
        self._spacing_ns = int(spacing_s * 1e9)
        n = len(self._joints)
        self._yt, self._yy, self._tt = np.zeros(n), np.zeros(n), np.zeros(n)
        self._count = 0
        self._last_ns: int | None = None
        #: Whether the check has concluded (then :attr:`findings` is final and :meth:`add` does nothing).
        self.done = False
        #: The joints found scaled, once :attr:`done`.
        self.findings: tuple[ScaleFinding, ...] = ()

    def add(self, stamp_ns: int, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, effort: np.ndarray) -> bool:
        """Read one sample (q rad, q̇ rad/s, q̈ rad/s², effort as reported); return True when it concluded.

        Samples closer than the spacing to the last one read, and any sample after the conclusion, are
        ignored. Non-finite URDF torques (a state far outside the model) are skipped.
        """
        if self.done or (self._last_ns is not None and stamp_ns - self._last_ns < self._spacing_ns):
            return False
        self._last_ns = stamp_ns
        try:
            tau = np.asarray(self._regressor.wrench(q, dq, ddq), dtype=np.float64)
        except RejectedSampleError:  # a state the regressor refuses: the learner counts it, not this
            return False
        if not np.isfinite(tau).all():
            return False
        y = np.asarray(effort, dtype=np.float64)
        self._yt += y * tau
        self._yy += y * y
        self._tt += tau * tau
        self._count += 1
        if self._count < self._n_samples:
            return False
        self._conclude()
        return True

    def _conclude(self) -> None:
        self.done = True
        rms = np.sqrt(self._tt / self._count)
        findings = []
        for j, name in enumerate(self._joints):
            if rms[j] <= _MIN_RELATIVE_RMS * rms.max() or self._yy[j] == 0.0:
                continue
            scale = self._yt[j] / self._tt[j]
            cosine = abs(self._yt[j]) / math.sqrt(self._yy[j] * self._tt[j])
            if cosine >= MIN_COSINE and (scale < 0.0 or not 1.0 / MAX_RATIO <= scale <= MAX_RATIO):
                findings.append(ScaleFinding(name, float(scale), float(cosine)))
        self.findings = tuple(findings)

    def message(self) -> str:
        """Return the warning to log ('' when nothing was found or the check has not concluded)."""
        if not self.findings:
            return ""
        joints = "; ".join(f"{f.joint} reads {f.scale:.3g} × the URDF's torque (cosine {f.cosine:.2f})"
                           for f in self.findings)
        return (f"measured efforts are not the URDF's joint torques in N·m: {joints}; if the driver reports "
                "motor currents or another unit, set robot.effort_scale (N·m per reported unit, one per "
                "joint) or publish torques")
