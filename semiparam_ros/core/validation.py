"""Argument checks shared by the learners, the features and the regressor (scikit-learn's ``check_array``).

Each check names the argument in its message and raises the exception type the caller passes: a
hyperparameter is a :class:`~semiparam_ros.errors.ConfigurationError`, an input sample a
:class:`~semiparam_ros.errors.RejectedSampleError` (which the estimator counts as a drop). Checks run before
any state changes, so a rejected call leaves the model as it was.

>>> check_positive_int("n_features", 3)
3
>>> check_finite_array("x", [1.0, 2.0], (2,)).dtype
dtype('float64')
>>> check_finite_array("x", [1.0, float("nan")], (2,))
Traceback (most recent call last):
    ...
semiparam_ros.errors.RejectedSampleError: x contains NaN, inf or entries larger than 1e+150 in magnitude
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from semiparam_ros.errors import ConfigurationError, RejectedSampleError

__all__ = [
    "MAX_ABS_INPUT",
    "as_float_array",
    "check_finite_array",
    "check_positive_int",
    "check_range",
]

MAX_ABS_INPUT = 1e150
"""Largest magnitude accepted in a learner's input: squares of larger values overflow float64."""


def check_positive_int(name: str, value: Any, minimum: int = 1, *,
                       error: type[ValueError] = ConfigurationError) -> int:
    """Return ``value`` as an ``int`` if it is an integer (not a bool) ``>= minimum``.

    Args:
        name: Argument name, for the message.
        value: The value to check.
        minimum: Smallest allowed value.
        error: Exception type to raise.

    Returns:
        ``int(value)``.

    Raises:
        ConfigurationError: (or ``error``) If ``value`` is not such an integer.
    """
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise error(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def check_range(name: str, value: Any, lo: float | None = None, hi: float | None = None, *,
                lo_inclusive: bool = True, hi_inclusive: bool = True,
                error: type[ValueError] = ConfigurationError) -> float:
    """Return ``value`` as a ``float`` if it is a finite real number within ``[lo, hi]``.

    Args:
        name: Argument name, for the message.
        value: The value to check (bools are refused).
        lo: Lower bound, or None for none.
        hi: Upper bound, or None for none.
        lo_inclusive: Whether ``value == lo`` is allowed.
        hi_inclusive: Whether ``value == hi`` is allowed.
        error: Exception type to raise.

    Returns:
        ``float(value)``.

    Raises:
        ConfigurationError: (or ``error``) If ``value`` is not a finite number in range.
    """
    number = isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
    low_ok = lo is None or (number and (value >= lo if lo_inclusive else value > lo))
    high_ok = hi is None or (number and (value <= hi if hi_inclusive else value < hi))
    if not (number and math.isfinite(value) and low_ok and high_ok):
        left = "(-inf" if lo is None else ("[" if lo_inclusive else "(") + f"{lo:g}"
        right = "inf)" if hi is None else f"{hi:g}" + ("]" if hi_inclusive else ")")
        raise error(f"{name} must be a finite number in {left}, {right}, got {value!r}")
    return float(value)


def as_float_array(name: str, value: Any, *, error: type[ValueError] = RejectedSampleError) -> np.ndarray:
    """``np.asarray(value, dtype=float)`` with an error that names the argument.

    Raises:
        RejectedSampleError: (or ``error``) If ``value`` is not numeric.
    """
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise error(f"{name} must be numeric: {err}") from None


def check_finite_array(name: str, value: Any, shape: tuple[int | None, ...] | None = None, *,
                       max_abs: float = MAX_ABS_INPUT,
                       error: type[ValueError] = RejectedSampleError) -> np.ndarray:
    """Return ``value`` as a C-contiguous float64 array of ``shape`` with every ``|entry| <= max_abs``.

    Args:
        name: Argument name, for the message.
        value: Array-like to check.
        shape: Expected shape; ``None`` entries match any length (but not zero), ``None`` matches any
            shape.
        max_abs: Largest magnitude accepted (default :data:`MAX_ABS_INPUT`; ``inf`` for finiteness only).
        error: Exception type to raise.

    Returns:
        The checked array (a copy only if a conversion was needed).

    Raises:
        RejectedSampleError: (or ``error``) On a non-numeric value, a wrong shape, or NaN/inf/too large
            entries.
    """
    arr = as_float_array(name, value, error=error)
    if shape is not None and (arr.ndim != len(shape) or any(
            n != want if want is not None else n == 0 for n, want in zip(arr.shape, shape, strict=True))):
        dims = ", ".join("n" if s is None else str(s) for s in shape)
        want_text = f"({dims},)" if len(shape) == 1 else f"({dims})"
        raise error(f"{name} must have shape {want_text}, got {arr.shape}")
    # One reduction catches NaN (comparison false), ±inf and values whose squares would overflow.
    if arr.size and not (np.abs(arr).max() <= max_abs):
        raise error(f"{name} contains NaN, inf or entries larger than {max_abs:g} in magnitude")
    return np.ascontiguousarray(arr)
