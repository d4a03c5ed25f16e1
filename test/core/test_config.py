"""The parameter table, the YAML loader and validation (core.config)."""

from __future__ import annotations

import pytest
import yaml
from helpers import REPO

from semiparam_ros.core.config import (
    ICUB_RIGHT_ARM,
    PARAMETERS,
    EstimatorConfig,
    load_config,
    structural_values,
    validate_value,
    write_config,
)
from semiparam_ros.core.estimator.build import build_regressor
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.errors import ConfigurationError

ROOT = REPO
ICUB = ROOT / "config" / "icub_right_arm.yaml"


def test_shipped_config_sets_every_parameter_and_is_valid():
    document = yaml.safe_load(ICUB.read_text())
    block = document["/**"]["ros__parameters"]

    def flatten(tree, prefix=""):
        for key, value in tree.items():
            if isinstance(value, dict):
                yield from flatten(value, f"{prefix}{key}.")
            else:
                yield f"{prefix}{key}"

    assert set(flatten(block)) == {p.name for p in PARAMETERS}
    config = load_config(ICUB)
    assert config["robot.joints"] == ["r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow"]
    assert config.locked == {"r_wrist_prosup": 0.0, "r_wrist_pitch": 0.0, "r_wrist_yaw": 0.0}


def test_defaults_are_valid_and_in_range():
    config = EstimatorConfig.defaults()
    for spec in PARAMETERS:
        if spec.name != "robot.output":  # inferred: below
            assert validate_value(spec.name, spec.default) == config[spec.name]


def test_no_parameter_defaults_to_a_robot():
    """The robot is the user's: no joint, sensor, frame or URDF by default, and the tools say so."""
    config = EstimatorConfig.defaults()
    assert config["robot.joints"] == [] and config["robot.urdf"] == ""
    assert config["robot.ft_sensor"] == "" and config["robot.frame_id"] == ""
    with pytest.raises(ConfigurationError, match=r"robot\.urdf and robot\.joints are not set.*template"):
        config.require_robot()
    named = config.with_overrides({"robot.joints": ["j1"]})
    named.require_robot(urdf=False)
    with pytest.raises(ConfigurationError, match=r"^robot\.urdf is not set"):
        named.require_robot()
    with pytest.raises(ConfigurationError, match=r"robot\.urdf is not set"):
        build_regressor(named)


def test_the_output_is_inferred_from_the_sensor():
    """No robot.output: joint torques, unless an F/T sensor is named; an explicit value wins."""
    assert EstimatorConfig.defaults().output_kind == OutputKind.JOINT_TORQUES
    sensed = EstimatorConfig.from_flat({"robot.ft_sensor": "r_arm_ft_sensor"})
    assert sensed.output_kind == OutputKind.WRENCH and sensed.n_outputs == 6
    explicit = EstimatorConfig.from_flat({"robot.ft_sensor": "s", "robot.output": "joint_torques",
                                          "robot.joints": ["a", "b"]})
    assert explicit.output_kind == OutputKind.JOINT_TORQUES and explicit.n_outputs == 2
    # the resolved value is what a checkpoint's fingerprint names (written before inference existed)
    assert structural_values(sensed, "P")["robot.output"] == "wrench"
    shipped = load_config(ICUB)
    assert {name: shipped[name] for name in ICUB_RIGHT_ARM} == dict(ICUB_RIGHT_ARM)


def test_effort_scale_is_one_per_joint_and_never_zero():
    base = EstimatorConfig.from_flat({"robot.joints": ["a", "b"]})
    assert base.with_overrides({"robot.effort_scale": [2.0, -0.5]})["robot.effort_scale"] == [2.0, -0.5]
    with pytest.raises(ConfigurationError, match="one value per joint"):
        base.with_overrides({"robot.effort_scale": [2.0]})
    with pytest.raises(ConfigurationError, match="must not hold 0"):
        base.with_overrides({"robot.effort_scale": [2.0, 0.0]})


def test_write_then_load_round_trip(tmp_path):
    config = load_config(ICUB).with_overrides({"nonparametric.lam": 0.25, "nonparametric.n_features": 64})
    out = tmp_path / "sub" / "tuned.yaml"
    write_config(config, out, header="tuned by a test")
    assert out.read_text().startswith("# tuned by a test\n")
    assert load_config(out).to_flat() == config.to_flat()


@pytest.mark.parametrize(
    ("name", "value", "fragment"),
    [
        ("parametric.lam", 0.0, "must be > 0"),
        ("parametric.lam", -1.0, "out of range"),
        ("nonparametric.n_features", 0, "must be >= 1"),
        ("nonparametric.n_features", 2.5, "must be an integer"),
        ("nonparametric.sigma", float("nan"), "must be finite"),
        ("nonparametric.forgetting", 1.5, "<= 1"),
        ("robot.output", "joint_angles", "one of '', 'wrench', 'joint_torques'"),
        ("robot.gravity", [0.0, -9.81], "must have 3 values"),
        ("learning_enabled", "yes", "true or false"),
        ("robot.joints", "r_elbow", "must be a list"),
        ("acceleration.polyorder", 0, ">= 1"),
        ("acceleration.polyorder", 11, "<= 10"),
        ("acceleration.max_gap_s", -0.1, ">= 0"),
        ("limits.max_abs_velocity", -1.0, ">= 0"),
        ("limits.max_abs_output", float("inf"), "must be finite"),
        ("limits.max_abs_position", True, "must be a number"),
    ],
)
def test_invalid_values_are_refused_with_the_parameter_named(name, value, fragment):
    with pytest.raises(ValueError, match=fragment) as info:
        EstimatorConfig.defaults().with_overrides({name: value})
    assert name in str(info.value)


def test_cross_parameter_rules():
    base = EstimatorConfig.from_flat(ICUB_RIGHT_ARM)
    with pytest.raises(ValueError, match="duplicate"):
        base.with_overrides({"robot.joints": ["r_elbow", "r_elbow"]})
    with pytest.raises(ValueError, match="same length"):
        base.with_overrides({"robot.locked_joints": ["r_wrist_yaw"]})
    with pytest.raises(ValueError, match="both learned and locked"):
        base.with_overrides({"robot.locked_joints": ["r_elbow"], "robot.locked_positions": [0.0]})
    with pytest.raises(ValueError, match="odd"):
        base.with_overrides({"acceleration.window": 10})
    with pytest.raises(ValueError, match=r"'acceleration\.polyorder' must be below"):
        base.with_overrides({"acceleration.window": 5, "acceleration.polyorder": 5})
    # the finite-difference estimator has no polynomial: any polyorder in range is accepted
    base.with_overrides({"acceleration.method": "finite_difference", "acceleration.window": 4,
                         "acceleration.polyorder": 6})
    with pytest.raises(ValueError, match=r"unknown parameter 'nonparametric\.lambda'"):
        base.with_overrides({"nonparametric.lambda": 1.0})
    with pytest.raises(ValueError, match=r"did you mean 'adaptation\.time_constant'"):
        base.with_overrides({"adaptaton.time_constant": 1.0})


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(ValueError, match="cannot read"):
        load_config(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("estimator: [unclosed")
    with pytest.raises(ValueError, match="not valid YAML"):
        load_config(bad)
    other = tmp_path / "other.yaml"
    other.write_text("some_node:\n  ros__parameters: {}\n")
    with pytest.raises(ValueError, match=r"no '/\*\*: ros__parameters:' \(or 'estimator:'\)"):
        load_config(other)
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text("/**:\n  ros__parameters:\n    parametric:\n      lam: -2.0\n    use_sim_time: true\n")
    with pytest.raises(ValueError, match=r"wrong\.yaml: parameter 'parametric.lam'"):
        load_config(wrong)


def test_build_pipeline_applies_acceleration_and_limit_parameters():
    """Shipped values reach the pipeline; 0 means "never restart" / "no bound"."""
    from semiparam_ros.core.estimator.build import build_pipeline
    from semiparam_ros.core.stream import pipeline as pl
    from semiparam_ros.core.stream.messages import JointStateData, WrenchData

    config = load_config(ICUB)
    assert (config["acceleration.polyorder"], config["acceleration.max_gap_s"]) == (2, 0.1)
    pipe = build_pipeline(config)
    acc = pipe.acceleration
    assert (acc.method, acc.window, acc.polyorder, acc.max_gap_s) == ("savgol", 9, 2, 0.1)
    tuned = build_pipeline(config.with_overrides({"acceleration.polyorder": 3,
                                                  "acceleration.max_gap_s": 0.0}))
    assert (tuned.acceleration.polyorder, tuned.acceleration.max_gap_s) == (3, None)

    joints = config["robot.joints"]
    frame = config["robot.frame_id"]

    def js(stamp, velocity):
        return JointStateData(stamp, joints, [0.1] * 4, [velocity, 0.0, 0.0, 0.0])

    def feed(p):
        p.add(js(10**9, 100.0))  # at the default bound: accepted
        p.add(js(10**9 + 10**7, 100.5))
        p.add(WrenchData(10**9, frame, [0.0, 0.0, 1.5e4], [0.0, 0.0, 0.0]))
        return p.drops[pl.DROP_IMPLAUSIBLE_VALUE]

    assert feed(build_pipeline(config)) == 2
    assert feed(build_pipeline(config.with_overrides({"limits.max_abs_velocity": 0.0,
                                                      "limits.max_abs_output": 0.0}))) == 0
    assert feed(build_pipeline(config.with_overrides({"limits.max_abs_velocity": 1000.0}))) == 1
    assert feed(build_pipeline(config.with_overrides({"limits.max_abs_position": 0.05}))) == 3

    # max_gap_s: a 0.2 s dropout restarts the estimator (warm-up drops) unless it is 0
    def restarts(p):
        for k in range(30):
            p.add(js(10**9 + k * 10**7 + (2 * 10**8 if k >= 15 else 0), 0.0))
        return p.estimator.mean_dt_s

    assert restarts(build_pipeline(config)) == pytest.approx(0.01)  # the dropout is not averaged in
    assert restarts(build_pipeline(config.with_overrides({"acceleration.max_gap_s": 0.0}))) > 0.01


def test_numbers_in_exponent_notation_are_numbers(tmp_path):
    """PyYAML reads ``1e-6`` and ``1.0e5`` as strings (YAML 1.1 wants a dot and a signed exponent): a
    parameter file or ``--set`` written that way gets the number, and other strings stay refused."""
    assert yaml.safe_load("1e-6") == "1e-6"  # the loader's behaviour the rule exists for
    path = tmp_path / "arm.yaml"
    doc = yaml.safe_load(ICUB.read_text())
    text = yaml.safe_dump(doc)
    assert "n_features: 500" in text
    path.write_text(text.replace("n_features: 500", "n_features: 2E+2"))
    loaded = load_config(path).with_overrides({"parametric.lam": "1.0e-3"})
    assert loaded.to_flat()["nonparametric.n_features"] == 200
    assert loaded.to_flat()["parametric.lam"] == float("1.0e-3")
    assert validate_value("nonparametric.sigma", " 2.5e1 ") == 25.0
    for bad, fragment in (("nan", "must be a number"), ("1e-6x", "must be a number"), ("1e999", "finite"),
                          ("2.5e0", "must be an integer")):
        name = "nonparametric.n_features" if bad == "2.5e0" else "nonparametric.sigma"
        with pytest.raises(ValueError, match=fragment):
            validate_value(name, bad)


def test_parameter_descriptions_say_what_a_parameter_does_not_its_history():
    """What `ros2 param describe` shows: no history ("the former…", "no longer…", issue numbers) in the
    descriptions, and every run-time parameter names what takes it."""
    import re

    from semiparam_ros.core.config import PARAMETERS, RUNTIME_TARGETS

    history = re.compile(r"\b(former|formerly|previously|no longer|older|deprecated|issue \d+)\b",
                         re.I)
    assert [p.name for p in PARAMETERS if history.search(p.description)] == []
    assert {p.runtime for p in PARAMETERS} <= {"", *RUNTIME_TARGETS}
    assert {p.name for p in PARAMETERS if not p.read_only} == {p.name for p in PARAMETERS if p.runtime}
