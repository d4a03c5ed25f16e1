"""Error metrics of the paper's protocol: component-averaged RMSE, over a segment and over a sliding window.

The paper (Camoriano et al., ICRA 2016, Fig. 3) reports "the average RMSE of the predicted force (torque)
components, averaged over a 3-seconds sliding window". We read that as: for every component c of a group
(fx, fy, fz for the force; tx, ty, tz for the torque), the RMSE of c over the window, then the mean over
the components of the group. The window is trailing (causal: the value at sample i uses samples
``max(0, i - w + 1) .. i``), so during the first ``w - 1`` samples of a split it covers every sample seen
so far — the initial transient the paper's log-time axis shows.

Which components form a group is decided by the configured output kind (:class:`OutputSpec`, from
``robot.output``), never by the number of outputs: a 6-joint arm's joint torques are six torques, not a
wrench. Units follow the errors: N for forces, N·m for torques (wrench torques and joint torques).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.core.stream.rate import samples_in

__all__ = [
    "GROUP_UNITS",
    "WRENCH_COMPONENTS",
    "Group",
    "OutputSpec",
    "component_rmse",
    "group_rmse",
    "window_samples",
    "windowed_rmse",
]

#: Component names of a wrench ``[fx, fy, fz, tx, ty, tz]`` (N, N·m), in the order of the output vector.
WRENCH_COMPONENTS: tuple[str, ...] = ("fx", "fy", "fz", "tx", "ty", "tz")

@dataclass(frozen=True)
class Group:
    """A group of output components whose errors are averaged together.

    Attributes:
        name: Group name used in report fields (``force``, ``torque``).
        unit: Unit of the components' errors (``N`` or ``N·m``).
        columns: Indices of the group's components in the output vector.
        label: Human name for tables and axis labels (e.g. ``joint torque``).
    """

    name: str
    unit: str
    columns: tuple[int, ...]
    label: str


@dataclass(frozen=True)
class OutputSpec:
    """What the learned output is, decided by ``robot.output`` (never by the number of outputs).

    A wrench ``[fx, fy, fz, tx, ty, tz]`` has the groups ``force`` [N] (columns 0–2) and ``torque`` [N·m]
    (columns 3–5) and one component per axis. Joint torques have one group, ``torque`` [N·m] over all
    joints (its RMSE is the mean over joints of each joint's RMSE), and one component per joint.

    Attributes:
        kind: The output kind (a string such as ``robot.output``'s value is converted).
        components: Component names: the wrench axes or the joint names, in output order.

    Raises:
        ValueError: On an unknown kind, no component, or a wrench without exactly six components.
    """

    kind: OutputKind
    components: tuple[str, ...]

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "kind", OutputKind(self.kind))
        except ValueError:
            raise ValueError(f"output kind must be one of {[k.value for k in OutputKind]}, "
                             f"got {self.kind!r}") from None
        if not self.components:
            raise ValueError("an output needs at least one component")
        if self.kind == OutputKind.WRENCH and tuple(self.components) != WRENCH_COMPONENTS:
            raise ValueError(f"a wrench has the components {WRENCH_COMPONENTS}, got {self.components}")
        object.__setattr__(self, "components", tuple(self.components))

    @classmethod
    def wrench(cls) -> OutputSpec:
        """Return the F/T-sensor wrench output."""
        return cls(OutputKind.WRENCH, WRENCH_COMPONENTS)

    @classmethod
    def joint_torques(cls, joints: Sequence[str]) -> OutputSpec:
        """Return the joint-torque output of the given joints (N·m each)."""
        return cls(OutputKind.JOINT_TORQUES, tuple(joints))

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> OutputSpec:
        """Return the output of an estimator configuration (``robot.output``, ``robot.joints``).

        Args:
            config: An :class:`~semiparam_ros.core.config.EstimatorConfig` or a flat mapping of it.

        Returns:
            The output specification.

        Raises:
            ValueError: If ``robot.output`` is not a known kind.
        """
        kind = OutputKind(config["robot.output"])
        return cls.wrench() if kind == OutputKind.WRENCH else cls.joint_torques(tuple(config["robot.joints"]))

    @property
    def n_outputs(self) -> int:
        """Number of output components t."""
        return len(self.components)

    @property
    def groups(self) -> dict[str, Group]:
        """The component groups, by name, in report order."""
        if self.kind == OutputKind.WRENCH:
            return {"force": Group("force", "N", (0, 1, 2), "force"),
                    "torque": Group("torque", "N·m", (3, 4, 5), "torque")}
        return {"torque": Group("torque", "N·m", tuple(range(self.n_outputs)), "joint torque")}

    @property
    def units(self) -> tuple[str, ...]:
        """Unit of each component's errors, in output order."""
        units = [""] * self.n_outputs
        for group in self.groups.values():
            for c in group.columns:
                units[c] = group.unit
        return tuple(units)

    def check(self, n_outputs: int) -> None:
        """Raise ``ValueError`` if a stream with ``n_outputs`` components does not fit this output."""
        if n_outputs != self.n_outputs:
            raise ValueError(f"the {self.kind} output has {self.n_outputs} components "
                             f"({', '.join(self.components)}), the samples have {n_outputs}")


#: Unit of each wrench group's errors, for tables and axis labels.
GROUP_UNITS: dict[str, str] = {g.name: g.unit for g in OutputSpec.wrench().groups.values()}


def _as_errors(errors: np.ndarray) -> np.ndarray:
    arr = np.asarray(errors, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise ValueError(f"errors must be (n_samples, n_components), got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError("errors must hold at least one sample")
    if not np.all(np.isfinite(arr)):
        raise ValueError("errors contain NaN or inf")
    return arr


def component_rmse(errors: np.ndarray) -> np.ndarray:
    """RMSE of each component over all samples.

    Args:
        errors: Prediction errors, shape ``(n_samples, n_components)`` (or ``(n_samples,)``).

    Returns:
        ``sqrt(mean(e_c**2))`` per component, shape ``(n_components,)``.

    Raises:
        ValueError: On an empty, non-finite or wrongly shaped input.
    """
    arr = _as_errors(errors)
    return np.sqrt(np.mean(arr * arr, axis=0))


def group_rmse(errors: np.ndarray) -> float:
    """Component-averaged RMSE of a segment: the mean over components of each component's RMSE.

    Args:
        errors: Prediction errors of one group, shape ``(n_samples, n_components)``.

    Returns:
        ``mean_c sqrt(mean_i e_ic**2)`` (same unit as the errors).

    Raises:
        ValueError: On an empty, non-finite or wrongly shaped input.
    """
    return float(np.mean(component_rmse(errors)))


def windowed_rmse(errors: np.ndarray, window: int) -> np.ndarray:
    """Component-averaged RMSE over a trailing sliding window, at every sample.

    Value ``i`` is ``mean_c sqrt(mean_{j in W_i} e_jc**2)`` with ``W_i = max(0, i - window + 1) .. i``.
    Computed in O(n · components) with cumulative sums of the squared errors.

    Args:
        errors: Prediction errors, shape ``(n_samples, n_components)`` (or ``(n_samples,)``).
        window: Window length in samples (>= 1).

    Returns:
        Array of shape ``(n_samples,)``.

    Raises:
        ValueError: If ``window < 1`` or on an empty, non-finite or wrongly shaped input.
    """
    if int(window) != window or window < 1:
        raise ValueError(f"window must be a positive integer number of samples, got {window!r}")
    window = int(window)
    arr = _as_errors(errors)
    n = arr.shape[0]
    csum = np.zeros((n + 1, arr.shape[1]))
    np.cumsum(arr * arr, axis=0, out=csum[1:])
    end = np.arange(1, n + 1)
    start = np.maximum(0, end - window)
    mse = (csum[end] - csum[start]) / (end - start)[:, None]
    # cumulative-sum differences can come out a hair below zero when the errors are tiny
    return np.mean(np.sqrt(np.maximum(mse, 0.0)), axis=1)


def window_samples(window_s: float, sample_period_s: float) -> int:
    """Convert a window length in seconds to a number of samples at the actual sample rate.

    Args:
        window_s: Window length [s] (> 0).
        sample_period_s: Sample period [s] (> 0), e.g. the median stamp difference of the samples.

    Returns:
        ``max(1, round(window_s / sample_period_s))``.

    Raises:
        ValueError: If either argument is not a positive finite number.
    """
    for name, value in (("window_s", window_s), ("sample_period_s", sample_period_s)):
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return samples_in(window_s, sample_period_s)  # the one conversion of seconds to samples
