"""Error metrics of the paper's protocol: component-averaged RMSE, over a segment and over a sliding window.

The paper (Camoriano et al., ICRA 2016, Fig. 3) reports "the average RMSE of the predicted force (torque)
components, averaged over a 3-seconds sliding window". We read that as: for every component c of a group
(fx, fy, fz for the force; tx, ty, tz for the torque), the RMSE of c over the window, then the mean over
the components of the group. The window is trailing (causal: the value at sample i uses samples
``max(0, i - w + 1) .. i``), so during the first ``w - 1`` samples of a split it covers every sample seen
so far — the initial transient the paper's log-time axis shows.

Units follow the errors: N for forces, N·m for torques.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "GROUP_UNITS",
    "WRENCH_GROUPS",
    "component_rmse",
    "group_rmse",
    "groups_for",
    "window_samples",
    "windowed_rmse",
]

#: Component groups of a wrench ``[fx, fy, fz, tx, ty, tz]``: force (N) and torque (N·m).
WRENCH_GROUPS: dict[str, slice] = {"force": slice(0, 3), "torque": slice(3, 6)}

#: Unit of each group's errors, for tables and axis labels.
GROUP_UNITS: dict[str, str] = {"force": "N", "torque": "N·m"}


def groups_for(n_outputs: int) -> dict[str, slice]:
    """Return the component groups evaluated for an output of ``n_outputs`` components.

    Args:
        n_outputs: 6 for an F/T-sensor wrench, n for joint torques.

    Returns:
        ``{"force": 0:3, "torque": 3:6}`` for a wrench, ``{"torque": all}`` otherwise.

    Raises:
        ValueError: If ``n_outputs < 1``.
    """
    if n_outputs < 1:
        raise ValueError(f"n_outputs must be >= 1, got {n_outputs}")
    if n_outputs == 6:
        return dict(WRENCH_GROUPS)
    return {"torque": slice(0, n_outputs)}


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
    return max(1, round(window_s / sample_period_s))
