"""The simulator's one entry and one preset table: which bags ``simulate`` writes, for any robot.

:data:`SCENARIOS` names the scenarios of each robot — the iCub's F/T-sensor circles (``xy``, ``xz``,
``payload``, ``multisine``, ``contacts``, at the rates of :data:`ICUB_PRESETS`) and the joint-torque arms'
(``excitation``, ``payload``, ``contacts``, :data:`~semiparam_ros.sim.arms.ARM_ROBOTS`).
:func:`preset_configs` returns the recording configurations of a robot's scenarios;
:func:`options_configs` turns the ``simulate`` command's options into them (defaults, options that do
not apply to the robot, ``--samples``), and :func:`simulate_bags` simulates and writes them
(:func:`generate`, with a progress bar; :func:`simulate_recording` simulates one recording with its robot's
measurement model, the F/T sensor's wrench or joint torques).

>>> [c.name for c in preset_configs("panda", ("excitation",), rate=100.0, duration=1.0)]
['panda_excitation_100hz']
>>> [c.name for c in preset_configs("icub", ("xy", "xz"))]
['icub_xy', 'icub_xz']
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from semiparam_ros.io.trajectory_files import read_excitation
from semiparam_ros.sim.arms import (
    ARM_ROBOTS,
    ARM_SCENARIOS,
    DEFAULT_DURATION_S,
    ArmRecording,
    ArmRobot,
    ArmScenarioConfig,
    ParameterPerturbation,
    arm_from_urdf,
    arm_spec,
)
from semiparam_ros.sim.contacts import ContactConfig, contacts_timing
from semiparam_ros.sim.effects import DEFAULT_EFFECTS, EffectParameters
from semiparam_ros.sim.recording import RecordingConfig
from semiparam_ros.sim.scenario import (
    DEFAULT_VARIABILITY,
    ScenarioConfig,
    SimulatedRecording,
    TrajectoryVariability,
)
from semiparam_ros.sim.writer import write_recording

__all__ = ["ICUB_PRESETS", "SCENARIOS", "SimulationOptions", "generate", "options_configs", "preset_configs",
           "simulate_bags", "simulate_recording"]


def simulate_recording(config: RecordingConfig, *,
                       progress: Callable[[int], None] | None = None) -> SimulatedRecording | ArmRecording:
    """Simulate one recording: the iCub's F/T sensor or an arm's joint torques, as the configuration says.

    Args:
        config: The scenario.
        progress: Called with the count of finished samples (F/T recordings; the arms report none).

    Returns:
        The stamped true and measured signals.

    Raises:
        ValueError: If the trajectory cannot be tracked within the joint limits.
    """
    return config.record(progress=progress)


def generate(
    out_dir: str | Path,
    configs: Sequence[RecordingConfig],
    *,
    overwrite: bool = False,
    compress: bool = True,
    progress: bool = True,
) -> list[Path]:
    """Simulate every scenario and write it as ``out_dir/<name>`` (bag folder with ``scenario.yaml``).

    Args:
        out_dir: Parent folder (created if missing).
        configs: The recordings, of any robot (:func:`semiparam_ros.sim.generate.preset_configs`).
        overwrite: Replace existing bag folders of the same names.
        compress: zstd-compress the MCAP chunks.
        progress: Show a tqdm progress bar on stderr (only when stderr is a terminal).

    Returns:
        The bag folders, in the order of ``configs``.

    Raises:
        ValueError: On an invalid scenario, an existing folder without ``overwrite`` (checked for all
            bags before anything is simulated), or a circle the arm cannot track.
    """
    show = bool(progress) and sys.stderr.isatty()  # a bar redrawn into a log or a pipe leaves frames
    out = Path(out_dir)
    names = [c.name for c in configs]
    if len(set(names)) != len(names):
        raise ValueError(f"scenario names must be unique, got {names}")
    if not overwrite:
        existing = [str(out / n) for n in names if (out / n).exists()]
        if existing:
            raise ValueError(f"bag folders exist already (use overwrite): {existing}")
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for config in configs:
        count, unit = config.progress_units()
        with tqdm(total=count, desc=config.name, unit=unit, disable=not show, leave=True) as bar:
            recording = simulate_recording(config, progress=bar.update)
            paths.append(write_recording(recording, out / config.name, overwrite=overwrite, compress=compress,
                                         progress=bar.update))
        if isinstance(recording, ArmRecording):
            write_parameter_file(recording.robot, paths[-1] / PARAMETER_FILE)
    return paths


#: The parameter file written beside an arm's bag (``learn BAG --config BAG/params.yaml``).
PARAMETER_FILE = "params.yaml"


def write_parameter_file(robot: ArmRobot, path: Path) -> None:
    """Write the node's parameter file for a simulated arm's bags: its URDF (absolute), joints and topic.

    Everything else takes its default, as for the user's own arm (config/template.yaml).

    Raises:
        OSError: If the file cannot be written (atomically: nothing is left half-written).
    """
    import yaml

    from semiparam_ros.atomic import atomic_open
    from semiparam_ros.core.kinds import InputKind
    from semiparam_ros.core.rigid_body.urdf import resolve_urdf

    values: dict[str, object] = {"urdf": str(resolve_urdf(robot.urdf).resolve()),
                                 "joints": list(robot.joints)}
    topics = {InputKind.JOINT_STATES.value: "/joint_states"}
    if robot.ft_sensor is not None:  # the sensor's wrench is learned (robot.output is inferred from it)
        values.update(ft_sensor=robot.ft_sensor, frame_id=robot.ft_sensor)
        topics[InputKind.WRENCH.value] = "/wrench"
    tree = {"/**": {"ros__parameters": {"robot": values, "topics": topics}}}
    learned = "joint torques" if robot.ft_sensor is None else f"the wrench of F/T sensor {robot.ft_sensor}"
    header = (f"# semiparam_ros estimator: the simulated {robot.name} of the bag beside this file "
              f"({learned}).\n#   learn <this bag> --config <this file> --checkpoint model.npz\n")
    with atomic_open(path, "w") as fh:
        fh.write(header + yaml.safe_dump(tree, sort_keys=False))


#: The iCub's presets: stream rates and length of the bags ``simulate --preset`` writes.
ICUB_PRESETS: dict[str, dict[str, float]] = {
    "default": {"joint_rate": 100.0, "wrench_rate": 100.0, "duration": 60.0},
    # The paper's logs: 10 000 wrench samples at 10 Hz; joint states at 100 Hz for the q̈ estimate.
    "paper": {"joint_rate": 100.0, "wrench_rate": 10.0, "duration": 1000.0},
}

_SCENARIO_NAMES = {
    "xy": "icub_xy",
    "xz": "icub_xz",
    "payload": "icub_payload",
    "multisine": "icub_multisine",
    "contacts": "icub_contacts",
}


def _icub_preset(preset: str) -> dict[str, float]:
    """Return the rates and length of an iCub preset.

    Raises:
        ValueError: On an unknown preset.
    """
    if preset not in ICUB_PRESETS:
        raise ValueError(f"preset must be one of {sorted(ICUB_PRESETS)}, got {preset!r}")
    return ICUB_PRESETS[preset]


def _icub_configs(
    preset: str = "default",
    scenarios: tuple[str, ...] = ("xy", "xz", "payload"),
    *,
    effects: EffectParameters = DEFAULT_EFFECTS,
    payload_mass: float = 0.5,
    payload_trajectory: str = "xy",
    contacts: ContactConfig | None = None,
    **overrides: Any,
) -> list[ScenarioConfig]:
    """Return the iCub scenario configurations of a preset (scenarios checked by :func:`preset_configs`).

    Args:
        preset: ``"default"`` (60 s, both streams 100 Hz) or ``"paper"`` (1000 s, wrench 10 Hz, joint
            states 100 Hz).
        scenarios: Any of ``"xy"``, ``"xz"``, ``"payload"``, ``"multisine"``, ``"contacts"``; bag names
            are ``icub_<scenario>``. ``contacts`` is the payload scenario with contact episodes at the hand
            before the pickup: :data:`CONTACTS_DURATION_S` long unless a duration is given, contacts in
            ``[0.15, 0.65]·T``, pickup at ``0.75·T`` unless ``payload_time`` is given.
        effects: Effect parameters (already scaled).
        payload_mass: Payload of the ``payload`` scenario (kg).
        payload_trajectory: Trajectory of the ``payload`` and ``contacts`` scenarios.
        contacts: How the ``contacts`` scenario draws its episodes (default :class:`ContactConfig`).
        **overrides: Any :class:`ScenarioConfig` field (duration, rates, delay, radius, speed, seed,
            payload_time, start_ns); None values are ignored.

    Returns:
        One configuration per scenario.

    Raises:
        ValueError: On an unknown preset or scenario, or invalid values.
    """
    base: dict[str, Any] = dict(_icub_preset(preset))
    base.update({k: v for k, v in overrides.items() if v is not None})
    out = []
    for scenario in scenarios:
        kwargs = dict(base)
        if scenario == "payload":
            kwargs.update(trajectory=payload_trajectory, payload_mass=payload_mass)
        elif scenario == "contacts":
            given = overrides.get("duration") or None
            duration, pickup = contacts_timing(given, overrides.get("payload_time"))
            kwargs.update(
                trajectory=payload_trajectory,
                payload_mass=payload_mass,
                duration=duration,
                payload_time=pickup,
                contacts=contacts if contacts is not None else ContactConfig(),
            )
        else:
            kwargs.update(trajectory=scenario, payload_mass=0.0)
        out.append(replace(ScenarioConfig(name=_SCENARIO_NAMES[scenario]), effects=effects, **kwargs))
    return out


def _rate_label(rate: float) -> str:
    return f"{int(rate)}hz" if float(rate).is_integer() else f"{rate:g}hz".replace(".", "p")


def _arm_configs(
    robot: str | ArmRobot,
    scenarios: tuple[str, ...] = ("excitation", "payload"),
    *,
    rate: float = 1000.0,
    duration: float | None = None,
    payload_mass: float | None = None,
    payload_time: float | None = None,
    contacts: ContactConfig | None = None,
    perturbation: ParameterPerturbation | None = ParameterPerturbation(),  # noqa: B008 - frozen
    **overrides: Any,
) -> list[ArmScenarioConfig]:
    """Return an arm's scenario configurations; bag names ``<robot>_<scenario>_<rate>hz``.

    The robot and the scenarios are checked by :func:`preset_configs`.

    Args:
        robot: Key of :data:`ARM_ROBOTS`, or any arm (:func:`~semiparam_ros.sim.arms.arm_from_urdf`).
        scenarios: Any of :data:`ARM_SCENARIOS`.
        rate: Joint-state rate (Hz).
        duration: Length (s); default 60 s (``contacts``: 120 s).
        payload_mass: Payload of ``payload`` and ``contacts`` (kg); default the robot's.
        payload_time: Pickup time (s); default the middle (``contacts``: 0.75·T).
        contacts: How ``contacts`` draws its episodes (default :class:`ContactConfig`).
        perturbation: True parameters vs the URDF's (None: the URDF's exactly).
        **overrides: Other :class:`ArmScenarioConfig` fields (seed, friction_scale,
            armature, noise_scale, start_ns); None values are ignored.

    Returns:
        One configuration per scenario.

    Raises:
        ValueError: On invalid values.
    """
    spec = arm_spec(robot)
    mass = spec.payload_mass if payload_mass is None else float(payload_mass)
    extra = {k: v for k, v in overrides.items() if v is not None}
    out = []
    for scenario in scenarios:
        kwargs: dict[str, Any] = dict(extra)
        if scenario == "contacts":
            length, pickup = contacts_timing(duration, payload_time)
            kwargs.update(
                payload_mass=mass,
                payload_time=pickup,
                contacts=contacts if contacts is not None else ContactConfig(),
            )
        else:
            length = float(duration) if duration is not None else DEFAULT_DURATION_S
            if scenario == "payload":
                kwargs.update(payload_mass=mass, payload_time=payload_time)
        name = f"{spec.name}_{scenario}_{_rate_label(rate)}"
        out.append(
            ArmScenarioConfig(
                name=name, robot=robot, duration=length, rate=float(rate), perturbation=perturbation, **kwargs
            )
        )
    return out


#: Each robot's scenarios, the defaults first (what ``simulate`` writes when none is named).
SCENARIOS: dict[str, tuple[str, ...]] = {
    "icub": tuple(_SCENARIO_NAMES),
    **{robot: ARM_SCENARIOS for robot in ARM_ROBOTS},
}
_DEFAULT_SCENARIOS = {"icub": ("xy", "xz", "payload"), **{r: ("excitation", "payload") for r in ARM_ROBOTS}}
#: Joint-state rate of the arms when none is given [Hz].
ARM_DEFAULT_RATE_HZ = 1000.0


def preset_configs(robot: str | ArmRobot = "icub", scenarios: tuple[str, ...] | None = None, *,
                   preset: str = "default", **overrides: Any) -> list[RecordingConfig]:
    """Return the recording configurations of a robot's scenarios.

    Args:
        robot: ``"icub"`` (F/T sensor wrench), a key of :data:`~semiparam_ros.sim.arms.ARM_ROBOTS` or any arm
            (:func:`~semiparam_ros.sim.arms.arm_from_urdf`) (joint torques).
        scenarios: Names of :data:`SCENARIOS` ``[robot]``; ``None``: the robot's defaults.
        preset: The iCub's :data:`ICUB_PRESETS` key (the arms have ``"default"`` only).
        **overrides: Fields of the robot's configuration and its builder's options (iCub: ``effects``,
            ``payload_mass``, ``payload_trajectory``, ``contacts``, rates, ``duration``, …; arms: ``rate``,
            ``duration``, ``payload_mass``, ``perturbation``, ``friction_scale``, …); None values are
            ignored.

    Returns:
        One configuration per scenario (bag names ``icub_<scenario>``, ``<robot>_<scenario>_<rate>hz``).

    Raises:
        ValueError: An unknown robot, preset or scenario, or an invalid value.
    """
    key = robot if isinstance(robot, str) else "panda"  # any arm has the arms' scenarios
    if key not in SCENARIOS:
        raise ValueError(f"robot must be one of {sorted(SCENARIOS)}, got {robot!r}")
    chosen = _DEFAULT_SCENARIOS[key] if scenarios is None else tuple(scenarios)
    unknown = [s for s in chosen if s not in SCENARIOS[key]]
    if unknown:
        raise ValueError(f"scenarios {unknown} are not {key}'s: it has {', '.join(SCENARIOS[key])}")
    if robot == "icub":
        return list(_icub_configs(preset, chosen, **overrides))
    if preset != "default":
        raise ValueError(f"preset {preset!r} is the iCub's; the arms take a rate and a duration")
    return list(_arm_configs(robot, chosen, **overrides))


@dataclass(frozen=True)
class SimulationOptions:
    """The ``simulate`` command's options, as given (``None``/``False``: not given).

    Attributes mirror the command line (see ``simulate --help``): ``robot`` (default ``icub``), or ``urdf``
    with ``joints`` (and ``end_effector``, ``ft_sensor``) for any arm, ``preset``, ``scenario``,
    ``duration`` [s], ``samples``, ``rate``/``joint_rate``/``wrench_rate`` [Hz], ``delay`` [s],
    ``radius`` [m], ``speed`` [m/s], ``seed``, the payload, trajectory variability, effects, contact, arm
    and noise options.
    """

    robot: str | None = None
    urdf: str | None = None
    joints: tuple[str, ...] | None = None
    end_effector: str | None = None
    ft_sensor: str | None = None
    preset: str = "default"
    scenario: tuple[str, ...] | None = None
    duration: float | None = None
    samples: int | None = None
    rate: float | None = None
    joint_rate: float | None = None
    wrench_rate: float | None = None
    delay: float | None = None
    radius: float | None = None
    speed: float | None = None
    seed: int | None = None
    payload_mass: float | None = None
    payload_time: float | None = None
    payload_trajectory: str = "xy"
    speed_variation: float | None = None
    centre_wander: float | None = None
    radius_wander: float | None = None
    no_variability: bool = False
    effects_scale: float = 1.0
    noise_scale: float = 1.0
    no_effects: bool = False
    contact_rate: float | None = None
    contact_force: tuple[float, float] | None = None
    contact_duration: tuple[float, float] | None = None
    contact_window: tuple[float, float] | None = None
    friction_scale: float | None = None
    armature: float | None = None
    perturbation: tuple[float, float, float] | None = None
    no_perturbation: bool = False
    no_noise: bool = False
    trajectory: str | None = None


_ICUB_ONLY = ("joint_rate", "wrench_rate", "delay", "radius", "speed", "speed_variation", "centre_wander",
              "radius_wander", "no_variability")
_ARM_ONLY = ("friction_scale", "armature", "perturbation", "no_perturbation", "trajectory")


def options_configs(options: SimulationOptions) -> list[RecordingConfig]:
    """Return the recording configurations the ``simulate`` options describe.

    Args:
        options: The options as given.

    Returns:
        One configuration per scenario.

    Raises:
        ValueError: An option that does not apply to the robot (named), an unknown scenario or preset,
            a non-positive ``samples``, or an invalid value.
    """
    o = options
    if o.urdf is not None:
        if o.robot is not None:
            raise ValueError("--robot and --urdf: give one (--urdf simulates the arm of that URDF)")
        if not o.joints:
            raise ValueError("--urdf needs --joints: the moving joints, in the order they are published")
        robot: str | ArmRobot = arm_from_urdf(o.urdf, o.joints, end_effector=o.end_effector,
                                              ft_sensor=o.ft_sensor)
    else:
        if o.joints or o.end_effector or o.ft_sensor:
            raise ValueError("--joints, --end-effector and --ft-sensor go with --urdf")
        robot = o.robot or "icub"
    label = robot if isinstance(robot, str) else f"--urdf {o.urdf}"
    inapplicable = _ARM_ONLY if robot == "icub" else _ICUB_ONLY
    given = ["--" + n.replace("_", "-") for n in inapplicable if getattr(o, n) not in (None, False)]
    if given:
        raise ValueError(f"{', '.join(given)}: not applicable to {label}")
    if o.samples is not None and o.samples <= 0:
        raise ValueError("--samples must be positive")
    contacts = _contacts(o)
    if robot == "icub":
        wrench_rate = o.wrench_rate if o.wrench_rate is not None else o.rate
        duration = o.duration
        if o.samples is not None:
            duration = o.samples / (wrench_rate or _icub_preset(o.preset)["wrench_rate"])
        return preset_configs(
            "icub", o.scenario, preset=o.preset,
            effects=DEFAULT_EFFECTS.scaled(0.0 if o.no_effects else o.effects_scale,
                                           0.0 if o.no_noise else o.noise_scale),
            payload_mass=0.5 if o.payload_mass is None else o.payload_mass,
            payload_trajectory=o.payload_trajectory, contacts=contacts, duration=duration,
            joint_rate=o.joint_rate if o.joint_rate is not None else o.rate, wrench_rate=wrench_rate,
            delay=o.delay, radius=o.radius, speed=o.speed, seed=o.seed, payload_time=o.payload_time,
            variability=_variability(o))
    if o.effects_scale != 1.0:
        raise ValueError("--effects-scale is for the iCub; use --friction-scale for the arms")
    rate = ARM_DEFAULT_RATE_HZ if o.rate is None else o.rate
    duration = o.duration if o.samples is None else o.samples / rate
    if o.no_perturbation:
        perturbation = None
    else:
        perturbation = ParameterPerturbation(*o.perturbation) if o.perturbation is not None else \
            ParameterPerturbation()
    friction_scale = 1.0 if o.friction_scale is None else o.friction_scale
    trajectory = None
    if o.trajectory is not None:
        described = read_excitation(o.trajectory)
        joints = arm_spec(robot).joints
        if described.joint_names != joints:
            raise ValueError(f"--trajectory {o.trajectory}: its joints {list(described.joint_names)} are not "
                             f"{label}'s {list(joints)}")
        trajectory = described.trajectory
    return preset_configs(
        robot, o.scenario, preset=o.preset, rate=rate, duration=duration, payload_mass=o.payload_mass,
        payload_time=o.payload_time, contacts=contacts, seed=o.seed, perturbation=perturbation,
        friction_scale=0.0 if o.no_effects else friction_scale, armature=o.armature,
        noise_scale=0.0 if o.no_noise else o.noise_scale, trajectory=trajectory)


def simulate_bags(options: SimulationOptions, out: str | Path, *, overwrite: bool = False,
                  compress: bool = True, progress: bool = True) -> list[Path]:
    """Simulate the bags the ``simulate`` options describe and write them under ``out``.

    Args:
        options: The options.
        out: Parent folder of the bag folders.
        overwrite: Replace existing bag folders of the same names.
        compress: zstd-compress the MCAP chunks.
        progress: Show a progress bar (on a terminal).

    Returns:
        The bag folders.

    Raises:
        ValueError: See :func:`options_configs` and :func:`~semiparam_ros.sim.generate.generate`.
        OSError: A folder or file that cannot be written.
    """
    return generate(out, options_configs(options), overwrite=overwrite, compress=compress, progress=progress)


def _contacts(o: SimulationOptions) -> ContactConfig:
    kwargs: dict[str, object] = {}
    if o.contact_rate is not None:
        kwargs["rate"] = o.contact_rate
    if o.contact_force is not None:
        kwargs["force_range"] = tuple(o.contact_force)
    if o.contact_duration is not None:
        kwargs["duration_range"] = tuple(o.contact_duration)
    if o.contact_window is not None:
        kwargs["window"] = tuple(o.contact_window)
    return ContactConfig(**kwargs)  # type: ignore[arg-type]


def _variability(o: SimulationOptions) -> TrajectoryVariability:
    if o.no_variability:
        return TrajectoryVariability(speed=0.0, centre=0.0, radius=0.0)
    d = DEFAULT_VARIABILITY
    return TrajectoryVariability(
        speed=d.speed if o.speed_variation is None else o.speed_variation,
        centre=d.centre if o.centre_wander is None else o.centre_wander,
        radius=d.radius if o.radius_wander is None else o.radius_wander,
        min_period=d.min_period, max_period=d.max_period, components=d.components)
