"""URDF sources and the checks a URDF passes before a regressor is built from it.

:func:`resolve_urdf` turns a ``robot.urdf`` value (a path, ``package://``, ``example-robot-data://``) into
a file; :class:`RegressorSpec` is what a rigid-body regressor is built from besides the URDF (the moving
joints, the sensor, the locked joints, the extra columns), checked once; :func:`prepare_urdf` checks the
URDF text against it and splits the model at the F/T sensor (see
:mod:`semiparam_ros.core.rigid_body.dynamics`). Nothing here needs Pinocchio.

>>> spec = RegressorSpec(("j1",), output=OutputKind.JOINT_TORQUES, friction=True)
>>> spec.extra_kinds
('viscous', 'coulomb')
>>> urdf = ('<robot name="r"><link name="a"/><link name="b"/><joint name="j1" type="revolute">'
...         '<parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint></robot>')
>>> prepare_urdf(urdf, spec).child_link
{'j1': 'b'}
>>> RegressorSpec(("j1", "j1"), output=OutputKind.JOINT_TORQUES)
Traceback (most recent call last):
...
semiparam_ros.errors.ConfigurationError: joints lists ['j1'] more than once
"""

from __future__ import annotations

import math
import os
import pathlib
import site
import sys
import sysconfig
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.errors import ConfigurationError

__all__ = [
    "EXAMPLE_ROBOT_DATA_SCHEME",
    "EXTRA_COLUMN_KINDS",
    "MOVING_TYPES",
    "PACKAGE_SCHEME",
    "TOPIC_SCHEME",
    "PreparedUrdf",
    "RegressorSpec",
    "example_robot_data_path",
    "icub_urdf_path",
    "package_file",
    "prepare_urdf",
    "resolve_urdf",
]

#: Joint types that move (the others are fixed, or floating at the sensor).
MOVING_TYPES = ("revolute", "continuous", "prismatic")
#: Suffixes of the per-joint extra columns, in their block order.
EXTRA_COLUMN_KINDS: tuple[str, ...] = ("viscous", "coulomb", "offset", "armature")
_ERD_PREFIX = pathlib.Path("cmeel.prefix", "share", "example-robot-data")
_ICUB_RELATIVE = "robots/icub_description/robots/icub.urdf"
#: Prefix of a ``robot.urdf`` value that names a file of the installed example-robot-data wheel.
EXAMPLE_ROBOT_DATA_SCHEME = "example-robot-data://"
#: ``robot.urdf`` prefix of a file inside a ROS package (``package://<package>/<path>``).
PACKAGE_SCHEME = "package://"
#: ``robot.urdf`` prefix naming a topic that publishes the URDF text (``topic:/robot_description``).
TOPIC_SCHEME = "topic:"


@dataclass(frozen=True)
class RegressorSpec:
    """What a rigid-body regressor is built from besides the URDF (checked at construction).

    Attributes:
        joints: The moving joints (revolute, continuous or prismatic), in the order of q, q̇, q̈.
        ft_sensor: Name of the fixed joint that holds the F/T sensor (iCub right arm:
            ``"r_arm_ft_sensor"``). Required for ``output=OutputKind.WRENCH``; with joint torques it
            only splits the bodies at the sensor.
        locked: Position (rad or m) of joints that are not moving; every joint that is neither in
            ``joints`` nor the sensor is locked, at 0 unless given here.
        gravity: Gravity (3,) in m/s², in the URDF root (base) frame.
        output: :class:`~semiparam_ros.core.kinds.OutputKind` (or its value): the wrench (6 outputs: the
            sensor reading) or the joint torques (one per joint).
        sensor_offset: Append ``n_outputs`` identity columns: constant offsets of the measurement
            (F/T sensors drift). Their URDF value is 0.
        friction: Append per-joint viscous and Coulomb friction columns (``output=OutputKind.JOINT_TORQUES``).
        coulomb_velocity: Velocity scale v_s of the Coulomb term ``tanh(q̇ / v_s)`` (rad/s, > 0).
        joint_offsets: Append a constant torque offset per joint (``output=OutputKind.JOINT_TORQUES``).
        armature: Append a motor-armature column ``q̈_i`` per joint (``output=OutputKind.JOINT_TORQUES``).
        base_seed: Seed of the random states used to find the base parameters.
        base_samples: Number of random states used to find the base parameters (default
            ``max(64, 3·n_params)``).

    Raises:
        ConfigurationError: An unknown output, extra columns without joint torques, a bad Coulomb
            velocity, or joint names that are not distinct strings.
    """

    joints: tuple[str, ...]
    ft_sensor: str | None = None
    locked: Mapping[str, float] | None = None
    gravity: Sequence[float] | np.ndarray = (0.0, 0.0, -9.81)
    output: OutputKind = OutputKind.WRENCH
    sensor_offset: bool = False
    friction: bool = False
    coulomb_velocity: float = 0.05
    joint_offsets: bool = False
    armature: bool = False
    base_seed: int = 0
    base_samples: int | None = None
    extra_kinds: tuple[str, ...] = field(init=False, default=())

    def __post_init__(self) -> None:
        object.__setattr__(self, "output", OutputKind.parse(self.output))
        flags = (self.friction, self.friction, self.joint_offsets, self.armature)
        extras = tuple(kind for kind, on in zip(EXTRA_COLUMN_KINDS, flags, strict=True) if on)
        if extras and self.output != OutputKind.JOINT_TORQUES:
            raise ConfigurationError("friction, joint_offsets and armature need joint-torque output "
                                     "(a wrench has sensor_offset instead)")
        cv = self.coulomb_velocity
        vs = float(cv) if not isinstance(cv, bool) else math.nan
        if self.friction and not (math.isfinite(vs) and vs > 0.0):
            raise ConfigurationError(f"coulomb_velocity must be a finite number > 0 (rad/s), got {cv!r}")
        joints = self.joints
        if isinstance(joints, str) or not isinstance(joints, Sequence):
            raise ConfigurationError(f"joints must be a sequence of joint names, got {joints!r}")
        names = tuple(joints)
        if not names:
            raise ConfigurationError("joints is empty: give at least one moving joint")
        for name in names:
            if not isinstance(name, str):
                raise ConfigurationError(f"joint names must be strings, got {name!r}")
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ConfigurationError(f"joints lists {duplicates} more than once")
        object.__setattr__(self, "joints", names)
        object.__setattr__(self, "extra_kinds", extras)
        object.__setattr__(self, "coulomb_velocity", vs)


@dataclass(frozen=True)
class PreparedUrdf:
    """A URDF checked against a :class:`RegressorSpec`.

    Attributes:
        xml: The URDF text to build the model from (the sensor joint turned into a free-flyer).
        robot_name: The URDF's ``<robot name=…>`` ("" when unnamed).
        child_link: Child link of every joint, by joint name.
        locked: The checked positions of the locked joints given (rad or m).
        gravity: Gravity (3,) in m/s².
    """

    xml: str
    robot_name: str
    child_link: dict[str, str]
    locked: dict[str, float]
    gravity: tuple[float, float, float]


def prepare_urdf(urdf_xml: str, spec: RegressorSpec, source: str | None = None) -> PreparedUrdf:
    """Check a URDF against a spec and split the model at the F/T sensor.

    Pinocchio merges fixed joints into their parent body; the sensor joint is therefore turned into a
    free-flyer kept at the identity, so that the bodies beyond it stay separate (see
    :mod:`semiparam_ros.core.rigid_body.dynamics`).

    Args:
        urdf_xml: The URDF text.
        spec: The joints, sensor and locked joints to check.
        source: Where the text came from, for messages.

    Returns:
        The checked URDF.

    Raises:
        ConfigurationError: Invalid XML, unknown or ill-typed joints, sensor or locked joints, non-finite
            locked positions or gravity.
    """
    where = f" in {source}" if source else ""
    joint_names, ft_sensor, locked, gravity, output = (spec.joints, spec.ft_sensor, spec.locked, spec.gravity,
                                                      spec.output)
    try:
        root = ET.fromstring(urdf_xml)
    except ET.ParseError as err:
        raise ConfigurationError(f"URDF{where} is not valid XML: {err}") from err
    if root.tag != "robot":
        raise ConfigurationError(f"URDF{where} has root element <{root.tag}>, expected <robot>")
    robot_name = str(root.get("name") or "")
    # Only direct children: <transmission> blocks also contain <joint> elements.
    urdf_joints = {j.get("name"): j for j in root.findall("joint")}
    child_link = {
        name: (child.get("link") if (child := j.find("child")) is not None else name)
        for name, j in urdf_joints.items()
    }

    missing = [name for name in joint_names if name not in urdf_joints]
    if missing:
        moving = [n for n, j in urdf_joints.items() if j.get("type") in MOVING_TYPES]
        raise ConfigurationError(f"unknown joint {missing[0]!r}" + (f" (and {missing[1:]})" if missing[1:]
                                 else "") + f": not a joint of the URDF{where}; its moving joints: "
                                 f"{moving}")
    for name in joint_names:
        jtype = urdf_joints[name].get("type")
        if jtype not in MOVING_TYPES:
            raise ConfigurationError(
                f"joint {name!r} has type {jtype!r}; moving joints must be one of {MOVING_TYPES}"
            )

    if ft_sensor is None:
        if output == OutputKind.WRENCH:
            raise ConfigurationError("output=OutputKind.WRENCH needs ft_sensor (the name of the fixed sensor "
                                     "joint)")
    else:
        if not isinstance(ft_sensor, str) or ft_sensor not in urdf_joints:
            raise ConfigurationError(f"unknown sensor joint {ft_sensor!r}: not a joint of the "
                                     f"URDF{where}")
        if ft_sensor in joint_names:
            raise ConfigurationError(f"sensor joint {ft_sensor!r} is also listed in joints")
        element = urdf_joints[ft_sensor]
        if element.get("type") != "fixed":
            raise ConfigurationError(
                f"sensor joint {ft_sensor!r} has type {element.get('type')!r}; an F/T sensor must be a "
                "fixed joint"
            )
        # Split the model at the sensor: a free-flyer joint kept at the identity.
        element.set("type", "floating")
        for tag in ("axis", "limit", "dynamics", "mimic", "calibration", "safety_controller"):
            for sub in element.findall(tag):
                element.remove(sub)

    locked_values: dict[str, float] = {}
    if locked is not None:
        if not isinstance(locked, Mapping):
            raise ConfigurationError(
                f"locked must be a mapping joint name -> position, got {type(locked).__name__}"
            )
        for name, value in locked.items():
            if name not in urdf_joints:
                raise ConfigurationError(f"unknown locked joint {name!r}: not a joint of the URDF{where}")
            if name in joint_names:
                raise ConfigurationError(f"joint {name!r} is both moving (joints) and locked")
            if name == ft_sensor:
                raise ConfigurationError(f"the sensor joint {name!r} cannot be locked")
            if urdf_joints[name].get("type") not in MOVING_TYPES:
                raise ConfigurationError(
                    f"locked joint {name!r} has type {urdf_joints[name].get('type')!r}: no position"
                )
            try:
                val = float(value)
            except (TypeError, ValueError) as err:
                raise ConfigurationError(
                    f"locked position of {name!r} is not a number: {value!r}") from err
            if not math.isfinite(val):
                raise ConfigurationError(f"locked position of {name!r} is not finite: {value!r}")
            locked_values[name] = val

    try:
        g = np.asarray(gravity, dtype=float) if not isinstance(gravity, str) else np.array([np.nan])
    except (TypeError, ValueError):
        g = np.array([np.nan])
    if g.shape != (3,) or not np.all(np.isfinite(g)):
        raise ConfigurationError(f"gravity must be 3 finite numbers (m/s²), got {gravity!r}")
    return PreparedUrdf(ET.tostring(root, encoding="unicode"), robot_name, {str(k): str(v) for k, v in
                        child_link.items()}, locked_values, (float(g[0]), float(g[1]), float(g[2])))


def icub_urdf_path() -> pathlib.Path:
    """Return the path of the iCub URDF shipped in the ``example-robot-data`` wheel.

    Returns:
        The absolute path of ``icub.urdf``.

    Raises:
        FileNotFoundError: If no installed ``example-robot-data`` provides the file.
    """
    return example_robot_data_path(_ICUB_RELATIVE)


def example_robot_data_path(relative: str) -> pathlib.Path:
    """Return the absolute path of a file of the installed ``example-robot-data`` wheel.

    The wheel installs its files under ``<site-packages>/cmeel.prefix/share/example-robot-data/``.

    Args:
        relative: Path below that folder, e.g. ``"robots/panda_description/urdf/panda.urdf"``.

    Returns:
        The absolute, resolved path.

    Raises:
        FileNotFoundError: If no installed ``example-robot-data`` provides the file.
    """
    candidates: list[pathlib.Path] = []
    for key in ("purelib", "platlib"):
        site_dir = sysconfig.get_paths().get(key)
        if site_dir:
            candidates.append(pathlib.Path(site_dir))
    try:
        candidates.extend(pathlib.Path(p) for p in site.getsitepackages())
    except AttributeError:  # pragma: no cover - virtualenvs without getsitepackages
        pass
    candidates.extend(pathlib.Path(p) for p in sys.path if p)
    # Pinocchio from PyPI lives inside the same cmeel prefix: walk up from its module as a last resort.
    import pinocchio as pin  # lazy: resolving a path needs no dynamics library otherwise

    for parent in pathlib.Path(pin.__file__).resolve().parents:
        if parent.name == "cmeel.prefix":
            candidates.append(parent.parent)
            break
    seen: set[pathlib.Path] = set()
    for base in candidates:
        if base in seen:
            continue
        seen.add(base)
        path = base / _ERD_PREFIX / relative
        if path.is_file():
            return path.resolve()
    raise FileNotFoundError(
        f"{relative} not found under {_ERD_PREFIX} in {len(seen)} site-packages/sys.path entries; "
        "install the 'example-robot-data' wheel (requirements.txt) or give the URDF path explicitly"
    )


def package_file(package: str, relative: str) -> pathlib.Path:
    """Return a file of a ROS package: its share folder from the ament index, else a pip prefix's.

    Tried in order: the ament index — for each prefix of ``AMENT_PREFIX_PATH`` (a sourced ROS install or
    colcon workspace), the package is there when ``share/ament_index/resource_index/packages/<package>``
    exists, and its share folder is ``share/<package>`` (what ``ament_index_python`` reads, read here
    without importing ROS packages into the core) — then ``share/<package>`` under ``sys.prefix`` and
    under each site-packages' ``cmeel.prefix`` (where PyPI wheels such as example-robot-data put theirs).

    Args:
        package: ROS package name.
        relative: Path below its share folder.

    Returns:
        The absolute path of the existing file.

    Raises:
        FileNotFoundError: Naming every place tried.
    """
    tried: list[str] = []
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    if not prefixes:
        tried.append("the ament index (AMENT_PREFIX_PATH is not set)")
    for prefix in prefixes:
        marker = pathlib.Path(prefix, "share", "ament_index", "resource_index", "packages", package)
        if marker.is_file():
            path = pathlib.Path(prefix, "share", package, relative)
            if path.is_file():
                return path.resolve()
            tried.append(str(path))
            break  # the first prefix that has the package is the one in use (ament's overlay order)
    else:
        if prefixes:
            tried.append(f"the ament index (no package {package!r} in AMENT_PREFIX_PATH)")
    bases = [pathlib.Path(sys.prefix) / "share" / package]
    for key in ("purelib", "platlib"):
        site_dir = sysconfig.get_paths().get(key)
        base = pathlib.Path(site_dir) / "cmeel.prefix" / "share" / package if site_dir else None
        if base is not None and base not in bases:
            bases.append(base)
    for base in bases:
        path = base / relative
        if path.is_file():
            return path.resolve()
        tried.append(str(path))
    raise FileNotFoundError(f"package://{package}/{relative} not found; tried {'; '.join(tried)}")


def resolve_urdf(spec: str) -> pathlib.Path:
    """Return the URDF file that a ``robot.urdf`` value names.

    Args:
        spec: ``"package://<package>/<path>"`` for a file
            of a ROS package (:func:`package_file`: the ament index, then the pip prefixes);
            ``"example-robot-data://<relative>"`` for a file of example-robot-data (the ROS package if
            installed, else the wheel; e.g. ``example-robot-data://robots/panda_description/urdf/
            panda.urdf``); anything else is a file path (``~`` expanded; relative paths are taken from the
            current folder). ``"topic:<name>"`` (the URDF published on a topic) is resolved by the node.

    Returns:
        The path (not checked for existence when it is a plain file path).

    Raises:
        FileNotFoundError: If a package or example-robot-data file is named and not found.
        ConfigurationError: For an empty value (no robot is assumed) or a ``topic:`` value (offline tools
            need a file).
    """
    if not spec:
        raise ConfigurationError("robot.urdf is not set: name your robot's URDF (a file path, package://…, "
                                 "example-robot-data://…)")
    if spec.startswith(TOPIC_SCHEME):
        raise ConfigurationError(f"robot.urdf = {spec!r} names a topic: only the node can read it; give "
                                 "offline tools the URDF file (e.g. ros2 param get /robot_state_publisher "
                                 "robot_description)")
    if spec.startswith(PACKAGE_SCHEME):
        package, _, relative = spec[len(PACKAGE_SCHEME):].partition("/")
        if not package or not relative:
            raise FileNotFoundError(f"robot.urdf = {spec!r}: expected package://<package>/<path>")
        return package_file(package, relative)
    if spec.startswith(EXAMPLE_ROBOT_DATA_SCHEME):
        relative = spec[len(EXAMPLE_ROBOT_DATA_SCHEME):]
        try:
            return package_file("example-robot-data", relative)
        except FileNotFoundError:
            return example_robot_data_path(relative)
    return pathlib.Path(spec).expanduser()
