"""ROS 2 parameters of the estimator node, declared from the single table ``core.config.PARAMETERS``.

Every parameter gets a ``ParameterDescriptor`` with its type, description, allowed range
(``FloatingPointRange`` / ``IntegerRange`` for scalars, the range text in ``additional_constraints``
otherwise) and ``read_only`` for the ones that fix the structure of the model (joints, URDF, number of
features…): changing those needs a restart, and rclpy refuses them at run time on its own. The run-time
parameters — those the table gives a ``runtime`` target (:func:`runtime_parameter_names`: the learning
switch, the contact gate, the noise estimate's memory, the overload budget and the checkpoint period) —
are checked by an on-set-parameters callback with ``core.config.validate_value``, which refuses invalid
values with the same message the offline tools give; the node hands an accepted change to its target.

Start-up values come from ``--params-file`` / ``-p`` overrides; the whole set is validated once by
:meth:`EstimatorConfig.from_flat` (cross-parameter rules such as matching locked joint/position lengths).

Empty lists: ROS 2 parameter files cannot type an empty list (``[]`` arrives as "not set"), so an array
parameter that is not set reads as ``[]``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from semiparam_ros.core.config import (
    PARAMETERS,
    EstimatorConfig,
    ParameterSpec,
    parameter_spec,
    unknown_parameter_message,
    validate_value,
)
from semiparam_ros.errors import ConfigurationError

__all__ = [
    "ParameterError",
    "declare_parameters",
    "descriptor_for",
    "make_parameter_validator",
    "runtime_parameter_names",
]

_ROS_TYPES: dict[str, int] = {
    "string": ParameterType.PARAMETER_STRING,
    "string_array": ParameterType.PARAMETER_STRING_ARRAY,
    "double": ParameterType.PARAMETER_DOUBLE,
    "double_array": ParameterType.PARAMETER_DOUBLE_ARRAY,
    "integer": ParameterType.PARAMETER_INTEGER,
    "bool": ParameterType.PARAMETER_BOOL,
}

# rclpy's range check is inclusive; an exclusive bound (λ > 0) is enforced by validate_value instead and
# the descriptor shows the nearest representable inclusive range only through additional_constraints.
_INT_LIMIT = 2**63 - 1


class ParameterError(ConfigurationError):
    """A start-up parameter value is invalid (the message names the parameter and the allowed range)."""


def runtime_parameter_names() -> tuple[str, ...]:
    """Return the parameters that may change while the node runs (the others are read-only)."""
    return tuple(p.name for p in PARAMETERS if not p.read_only)


def descriptor_for(spec: ParameterSpec) -> ParameterDescriptor:
    """Build the ROS parameter descriptor of one table entry.

    Args:
        spec: The parameter's specification.

    Returns:
        Descriptor with type, description, read-only flag, range and constraint text.
    """
    desc = ParameterDescriptor(
        name=spec.name,
        type=_ROS_TYPES[spec.type],
        description=spec.description,
        additional_constraints=spec.range_text(),
        read_only=spec.read_only,
        dynamic_typing=False,
    )
    if spec.type == "double" and not spec.min_exclusive and (spec.min is not None or spec.max is not None):
        desc.floating_point_range = [FloatingPointRange(
            from_value=float(spec.min) if spec.min is not None else -math.inf,
            to_value=float(spec.max) if spec.max is not None else math.inf,
            step=0.0,
        )]
    elif spec.type == "integer" and (spec.min is not None or spec.max is not None):
        low = int(spec.min) + (1 if spec.min_exclusive else 0) if spec.min is not None else -_INT_LIMIT
        desc.integer_range = [IntegerRange(
            from_value=low,
            to_value=int(spec.max) if spec.max is not None else _INT_LIMIT,
            step=0,
        )]
    return desc


def _read(node: Node, spec: ParameterSpec) -> Any:
    try:
        value = node.get_parameter(spec.name).value
    except ParameterUninitializedException:
        value = None
    if value is None:
        if spec.type.endswith("_array"):
            return []
        raise ParameterError(f"parameter {spec.name!r} has no value (expected {spec.type})")
    if spec.type.endswith("_array"):
        return list(value)
    return value


def declare_parameters(node: Node, specs: Iterable[ParameterSpec] = PARAMETERS) -> EstimatorConfig:
    """Declare every estimator parameter on ``node`` and return the validated configuration.

    Must be called before any on-set-parameters callback is added (declaration runs those callbacks).

    Args:
        node: The node (its overrides come from ``--params-file`` and ``-p``).
        specs: Parameter table (defaults to :data:`core.config.PARAMETERS`).

    Returns:
        The configuration made of the declared values.

    Raises:
        ParameterError: If an override has the wrong type, is out of range, or the set is inconsistent;
            the message names the parameter and the allowed values.
    """
    specs = tuple(specs)
    for spec in specs:
        desc = descriptor_for(spec)
        default: Any = spec.default
        if isinstance(default, list | tuple) and not default:
            default = Parameter.Type(_ROS_TYPES[spec.type])  # typed but unset: rclpy cannot type []
        elif isinstance(default, tuple):
            default = list(default)
        try:
            node.declare_parameter(spec.name, default, desc)
        except InvalidParameterTypeException as err:
            raise ParameterError(
                f"parameter {spec.name!r} has the wrong type: expected {spec.type} "
                f"({spec.range_text()}); {err}") from err
        except InvalidParameterValueException as err:
            raise ParameterError(
                f"parameter {spec.name!r} is out of range: must be {spec.range_text()}; {err}") from err
    _refuse_unknown_overrides(node, {spec.name for spec in specs})
    flat = {spec.name: _read(node, spec) for spec in specs}
    try:
        return EstimatorConfig.from_flat(flat)
    except ConfigurationError as err:
        raise ParameterError(str(err)) from err


#: Parameters rclpy itself reads (besides ``qos_overrides.*``): not ours, not misspellings.
_ROS_OWN = frozenset({"use_sim_time", "start_type_description_service"})


def _refuse_unknown_overrides(node: Node, declared: set[str]) -> None:
    """Refuse a start-up value (parameter file or ``-p``) for a parameter the node does not have.

    rclpy keeps such values silently (a misspelt ``adaptaton.time_constant`` would leave the default in
    force); the node reads them from ``Node._parameter_overrides`` (rclpy has no public accessor) and
    stops with the closest known names.

    Raises:
        ParameterError: Naming the first unknown parameter and its closest known names.
    """
    overrides = getattr(node, "_parameter_overrides", {})
    unknown = sorted(name for name in overrides if name not in declared and name not in _ROS_OWN
                     and not name.startswith("qos_overrides."))
    if unknown:
        more = f" (and {len(unknown) - 1} more: {unknown[1:]})" if len(unknown) > 1 else ""
        raise ParameterError(unknown_parameter_message(unknown[0]) + more)


def make_parameter_validator(
    current: Callable[[], EstimatorConfig],
) -> Callable[[list[Parameter]], SetParametersResult]:
    """Build an on-set-parameters callback that refuses invalid run-time values.

    Parameters outside the estimator table (``use_sim_time``, QoS overrides…) are left to rclpy.

    Args:
        current: Returns the configuration in force (used to check cross-parameter rules).

    Returns:
        A callback for :meth:`rclpy.node.Node.add_on_set_parameters_callback`.
    """

    def validate(params: list[Parameter]) -> SetParametersResult:
        overrides: dict[str, Any] = {}
        for param in params:
            try:
                spec = parameter_spec(param.name)
            except ConfigurationError:
                continue
            if spec.read_only:
                return SetParametersResult(
                    successful=False,
                    reason=f"parameter {param.name!r} is read-only: it fixes the model structure; "
                           "restart the node to change it")
            value = param.value
            if value is None and spec.type.endswith("_array"):
                value = []
            try:
                overrides[param.name] = validate_value(param.name, value)
            except ConfigurationError as err:
                return SetParametersResult(successful=False, reason=str(err))
        if overrides:
            try:
                current().with_overrides(overrides)
            except ConfigurationError as err:
                return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    return validate
