"""Write config/template.yaml from the parameter table (run from the repository root after changing it).

    PYTHONPATH=$PWD .venv/bin/python bench/sim/make_template_config.py

Every parameter but the three a user must give is listed commented, with its description, range and
default; test/core/rigid_body/test_real_arms.py checks that uncommenting them gives exactly the defaults.
"""

import textwrap

import yaml

from semiparam_ros.core.config import PARAMETERS

lines = """# semiparam_ros estimator: template for any fixed-base URDF arm with joint-torque sensing.
# Only the three uncommented values are needed; every other parameter has a robot- and rate-independent
# default, listed (commented) below with its meaning and range. Units: rad, rad/s, rad/s^2, N, N·m, s.
#   evaluate paper --train log_a --test log_b --config config/template.yaml
#   ros2 run semiparam_ros estimator --ros-args --params-file config/template.yaml
# robot.urdf: a file path (relative paths from the folder the command runs in; ~ expanded) or
# "example-robot-data://<path in that package>". The joint names are those of the URDF and of the
# sensor_msgs/JointState messages (any order, extra joints ignored); JointState.effort is the target.
# The rigid-body stage starts from the URDF (RNEA with its inertias) and learns per-joint friction and
# offsets (parametric.prior, .friction, .offsets); q̈ comes from a 80 ms window at the measured rate.
/**:
  ros__parameters:
    robot:
      urdf: "path/to/your_robot.urdf"
      joints: [joint_1, joint_2, joint_3, joint_4, joint_5, joint_6]
      output: joint_torques""".splitlines()
required = {"robot.urdf", "robot.joints", "robot.output"}
current = ["robot"]
overrides = {"robot.ft_sensor": "", "robot.frame_id": ""}
for p in PARAMETERS:
    *groups, key = p.name.split(".")
    if p.name in required:
        continue
    depth = 0
    while depth < min(len(groups), len(current)) and groups[depth] == current[depth]:
        depth += 1
    for d in range(depth, len(groups)):
        lines.append("    " + "  " * d + f"# {groups[d]}:")
    current = groups
    ind = "    " + "  " * len(groups)
    val = overrides.get(p.name, p.default)
    v = yaml.safe_dump(val, default_flow_style=True).strip()
    if v.endswith("..."):
        v = v[:-3].strip()
    text = p.description
    if p.choices or p.min is not None:
        text += f" [{p.range_text()}]"
    for part in textwrap.wrap(text, 96):
        lines.append(ind + "#   " + part)
    lines.append(ind + f"# {key}: {v}")
open("config/template.yaml", "w").write("\n".join(lines) + "\n")
