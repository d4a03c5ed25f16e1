"""Link inertials a user can load: what the data did not determine stays at the URDF's values.

The consistent projection (:func:`~semiparam_ros.core.rigid_body.identification.consistent_parameters`)
fits the base parameters — the combinations the data determine — and is physically consistent link by
link, but a single link's mass and centre of mass are rarely determined on their own: a 25 s log of a
KUKA LWR4+ gave ``lwr_6_link`` 0.018 kg (URDF 1 kg) with its centre of mass 1.45 m from its frame, which
predicts the logged torques well and is nonsense as a URDF. :func:`plausible_links` checks every link
against its URDF values:

- **mass** within ``[1/`` :data:`MASS_RATIO` ``,`` :data:`MASS_RATIO` ``]`` × the URDF's — except that the
  distal body may be heavier: beyond :data:`PAYLOAD_RATIO` × its URDF mass it **carries a payload** (a
  tool or a load the URDF does not know), named as such;
- **centre of mass** within ``max(`` :data:`COM_DISTANCE_M` ``, 1.5 |c_urdf|)`` of the link's frame.

A link outside either bound is **not determined by the data**: it is held at its URDF values and the
projection re-solved with it held (the other links take what they can of the data), until every link
passes. What that costs is measured, not hidden: :attr:`PlausibleLinks.torque_change_rms` is the RMS over
random states of the joint torques (or wrench) the exported links predict minus those of the consistent
estimate. Each link's quantities are labelled as coming from the data or from the URDF
(:attr:`LinkOrigin.from_data`) for the warning and the exported file's comments.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.core.rigid_body.identification import (
    ConsistentEstimate,
    consistent_parameters,
    link_of,
    prior_weights,
    random_state_regressor,
)

__all__ = ["COM_DISTANCE_M", "MASS_RATIO", "PAYLOAD_RATIO", "LinkOrigin", "PlausibleLinks", "check_link",
           "plausible_links"]

#: A link's mass is plausible within this factor of its URDF mass, either way (the distal body: below only).
MASS_RATIO = 4.0
#: A link's centre of mass is plausible within this distance of its frame [m] (or 1.5 × the URDF's).
COM_DISTANCE_M = 0.25
#: The distal body is named as carrying a payload when its mass exceeds this factor of its URDF mass.
PAYLOAD_RATIO = 1.5
#: Relative change below which a quantity is taken as the URDF's (the projection's solver tolerance).
_SAME = 1e-3


@dataclass(frozen=True)
class LinkOrigin:
    """Where one link's exported inertial comes from.

    Attributes:
        body: The link (the body's name).
        mass: Exported mass [kg]; ``urdf_mass`` the URDF's.
        com_distance: Distance of the exported centre of mass from the link frame [m].
        from_data: The quantities the data moved from the URDF's values: a subset of ``mass``,
            ``centre of mass``, ``inertia`` (empty: all the URDF's).
        reason: Why the data left the link implausible, so that it was held at its URDF values ('' when
            it was not: :attr:`held`).
        payload: Mass carried beyond the URDF [kg] (the distal body only; 0 elsewhere).
    """

    body: str
    mass: float
    urdf_mass: float
    com_distance: float
    from_data: tuple[str, ...]
    reason: str = ""
    payload: float = 0.0

    @property
    def held(self) -> bool:
        """Whether the link was held at its URDF values (the data left it implausible)."""
        return bool(self.reason)


@dataclass(frozen=True)
class PlausibleLinks:
    """Per-link inertials to export (see the module docstring).

    Attributes:
        estimate: The consistent estimate with the held links at their URDF values (``full`` per link;
            ``estimate.base`` is what it predicts).
        links: Each body's :class:`LinkOrigin`, in the order of ``estimate.body_names``.
        torque_change_rms: RMS over random states of what the exported links predict minus what the
            consistent estimate predicts (in :attr:`unit`); 0 when no link was held.
        unit: Unit of the output (``N·m`` for joint torques; ``N, N·m`` for a wrench).
    """

    estimate: ConsistentEstimate
    links: tuple[LinkOrigin, ...]
    torque_change_rms: float
    unit: str = "N·m"

    @property
    def held(self) -> tuple[LinkOrigin, ...]:
        """The links held at their URDF values."""
        return tuple(link for link in self.links if link.held)

    def warning(self) -> str:
        """Say which links the data did not determine, and any payload ('' when there is nothing to say)."""
        parts = []
        held = self.held
        if held:
            parts.append("not determined by the data, kept at the URDF's values: " + "; ".join(
                f"{link.body} ({link.reason})" for link in held)
                + f" (the exported links predict {self.torque_change_rms:.3g} {self.unit} RMS away from the "
                  "model's rigid body over random states)")
        parts += [f"{link.body} carries {link.payload:.3g} kg beyond its URDF mass (a tool or payload)"
                  for link in self.links if link.payload > 0.0]
        return "; ".join(parts)

    def comments(self) -> list[str]:
        """One line per link: which quantities came from the data and which from the URDF."""
        lines = []
        for link in self.links:
            if link.held:
                origin = f"all from the URDF (not determined by the data: {link.reason})"
            elif not link.from_data:
                origin = "all from the URDF (the data did not move it)"
            else:
                kept = [q for q in ("mass", "centre of mass", "inertia") if q not in link.from_data]
                origin = "from the data: " + ", ".join(link.from_data) + (
                    "; from the URDF: " + ", ".join(kept) if kept else "")
            payload = f"; carries {link.payload:.3g} kg beyond the URDF" if link.payload > 0.0 else ""
            lines.append(f"{link.body}: {link.mass:.4g} kg (URDF {link.urdf_mass:.4g} kg), {origin}{payload}")
        return lines


def check_link(mass: float, com: np.ndarray, urdf_mass: float, urdf_com: np.ndarray, *,
               distal: bool) -> str:
    """Return why a link's inertial is implausible ('' when it is not).

    Args:
        mass: Mass [kg].
        com: (3,) centre of mass in the link frame [m].
        urdf_mass: The URDF's mass [kg] (a massless URDF link has no mass bound).
        urdf_com: (3,) the URDF's centre of mass [m].
        distal: Whether the link is the distal body (it may carry a payload: no upper mass bound).

    >>> check_link(0.018, np.array([1.05, 0.09, 0.99]), 1.0, np.zeros(3), distal=False)
    'mass 0.018 kg is 0.018 x the URDF 1 kg'
    >>> check_link(5.0, np.array([0.0, 0.0, 0.1]), 0.2, np.zeros(3), distal=True)
    ''
    """
    if urdf_mass > 0.0:
        ratio = mass / urdf_mass
        if ratio < 1.0 / MASS_RATIO or (not distal and ratio > MASS_RATIO):
            return f"mass {mass:.3g} kg is {ratio:.2g} x the URDF {urdf_mass:.3g} kg"
    bound = max(COM_DISTANCE_M, 1.5 * float(np.linalg.norm(urdf_com)))
    distance = float(np.linalg.norm(com))
    if distance > bound:
        return f"centre of mass {distance:.3g} m from its frame (> {bound:.3g} m)"
    return ""


def plausible_links(regressor: RigidBodyRegressor, estimate: ConsistentEstimate, theta: np.ndarray,
                    R: np.ndarray, scale: np.ndarray, lam: float, *,
                    weights: np.ndarray | None = None) -> PlausibleLinks:
    """Hold the links the data left implausible at their URDF values (module docstring).

    Args:
        regressor: The rigid-body regressor (bodies, URDF parameters).
        estimate: The consistent estimate of the learner's state below.
        theta: (n_base,) the learner's estimate in its scaled units (θ = c ⊙ π_b).
        R: (n_base, n_base) upper-triangular factor of its information matrix.
        scale: (n_base,) the column scales c.
        lam: The learner's ridge λ.
        weights: The projection's prior weights (default: its own).

    Returns:
        The links to export; ``estimate`` itself when every link is plausible.

    Raises:
        ConfigurationError: If a re-solve fails.
    """
    urdf = regressor.urdf_parameters()
    distal = regressor.body_index(regressor.distal_body_name)
    weights = prior_weights(regressor) if weights is None else weights  # once for every re-solve
    held: dict[int, str] = {}
    current = estimate
    for _ in range(regressor.n_bodies):
        new = {}
        for i in range(regressor.n_bodies):
            if i in held:
                continue
            mass, com, _ = current.link(i)
            urdf_mass, urdf_com, _ = link_of(urdf, i)
            reason = check_link(mass, com, urdf_mass, urdf_com, distal=i == distal)
            if reason:
                new[i] = reason
        if not new:
            break
        held.update(new)
        current = consistent_parameters(regressor, theta, R, scale, lam, weights=weights,
                                        fixed_bodies=sorted(held))
    change = _prediction_change_rms(regressor, current.full - estimate.full) if held else 0.0
    links = tuple(_origin(current, urdf, i, body, held.get(i, ""), i == distal)
                  for i, body in enumerate(current.body_names))
    return PlausibleLinks(current, links, change, OutputKind(regressor.output).unit)


def _origin(estimate: ConsistentEstimate, urdf: np.ndarray, i: int, body: str, reason: str,
            distal: bool) -> LinkOrigin:
    mass, com, inertia = estimate.link(i)
    urdf_mass, urdf_com, urdf_inertia = link_of(urdf, i)
    moved = []
    if abs(mass - urdf_mass) > _SAME * max(urdf_mass, 1e-3):
        moved.append("mass")
    if float(np.linalg.norm(com - urdf_com)) > _SAME:
        moved.append("centre of mass")
    if float(np.linalg.norm(inertia - urdf_inertia)) > _SAME * max(float(np.linalg.norm(urdf_inertia)), 1e-6):
        moved.append("inertia")
    carries = distal and not reason and mass > PAYLOAD_RATIO * urdf_mass
    payload = mass - urdf_mass if carries else 0.0
    return LinkOrigin(body, mass, urdf_mass, float(np.linalg.norm(com)), tuple(moved), reason, payload)


def _prediction_change_rms(regressor: RigidBodyRegressor, delta: np.ndarray) -> float:
    """RMS of ``Φ δ`` over random states within the joint limits (the projection's column-RMS states)."""
    return float(np.sqrt(np.mean((random_state_regressor(regressor) @ delta) ** 2)))

