"""``package.xml`` declares a valid rosdep key for every library the package and its tests import.

The keys are checked against a snapshot of the rosdep database (ros/rosdistro at commit 8468e88:
``jazzy/distribution.yaml`` for ROS packages, ``rosdep/python.yaml`` for Python libraries); libraries with
no rosdep key must be named as pip dependencies in ``requirements.txt`` and in the README.
"""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET

from helpers import REPO

#: Keys of the rosdep database used here (ros/rosdistro 8468e88ccd523427f9131e39d2af0938f1c298b2).
VALID_KEYS = frozenset({
    "rclpy", "builtin_interfaces", "rcl_interfaces", "sensor_msgs", "geometry_msgs", "std_msgs", "std_srvs",
    "diagnostic_msgs", "rosgraph_msgs", "trajectory_msgs", "lifecycle_msgs", "launch", "launch_ros",
    "pinocchio", "python3-numpy", "python3-scipy", "python3-numba", "python3-yaml", "python3-matplotlib",
    "python3-tqdm", "python3-joblib", "python3-rosbags-pip", "python3-pytest", "python3-hypothesis",
    "python3-sklearn", "python3-psutil", "python3-cvxpy-pip",
    "control_msgs", "action_msgs",  # jazzy/distribution.yaml: ros-controls/control_msgs, rcl_interfaces
})
#: Import name → rosdep key.
KEY_OF = {
    "rclpy": "rclpy", "builtin_interfaces": "builtin_interfaces", "rcl_interfaces": "rcl_interfaces",
    "sensor_msgs": "sensor_msgs", "geometry_msgs": "geometry_msgs", "std_msgs": "std_msgs",
    "std_srvs": "std_srvs", "diagnostic_msgs": "diagnostic_msgs", "rosgraph_msgs": "rosgraph_msgs",
    "trajectory_msgs": "trajectory_msgs", "lifecycle_msgs": "lifecycle_msgs",
    "pinocchio": "pinocchio", "numpy": "python3-numpy", "scipy": "python3-scipy", "numba": "python3-numba",
    "yaml": "python3-yaml", "matplotlib": "python3-matplotlib", "tqdm": "python3-tqdm",
    "joblib": "python3-joblib", "rosbags": "python3-rosbags-pip", "pytest": "python3-pytest",
    "hypothesis": "python3-hypothesis", "sklearn": "python3-sklearn", "cvxpy": "python3-cvxpy-pip",
    "psutil": "python3-psutil", "control_msgs": "control_msgs", "action_msgs": "action_msgs",
}
#: Import name → pip distribution, for libraries without a rosdep key.
PIP_ONLY = {"threadpoolctl": "threadpoolctl", "zstandard": "zstandard", "lz4": "lz4",
            "example_robot_data": "example-robot-data", "mcap": "mcap", "mcap_ros2": "mcap-ros2-support",
            "distributed": "distributed", "cloudpickle": "cloudpickle"}
#: Keys needed without a Python import of ours: the launch file's packages; rclpy.lifecycle's messages.
NOT_IMPORTED = {"launch", "launch_ros", "lifecycle_msgs"}
LOCAL = {"semiparam_ros", "helpers", "__future__", "docs"}  # docs: docs/tools


def _imports(folder: str) -> set[str]:
    names: set[str] = set()
    for path in (REPO / folder).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names.update(a.name.split(".")[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module.split(".")[0])
    tests = {p.stem for p in (REPO / "test").rglob("*.py")} | {"helpers"}
    return {n for n in names if n not in sys.stdlib_module_names and n not in LOCAL and n not in tests}


def test_package_xml_keys_cover_the_imports_and_are_rosdep_keys():
    root = ET.parse(REPO / "package.xml").getroot()
    exec_keys = {e.text for e in root.findall("exec_depend")}
    test_keys = {e.text for e in root.findall("test_depend")}
    assert exec_keys | test_keys <= VALID_KEYS, (exec_keys | test_keys) - VALID_KEYS
    runtime, tests = _imports("semiparam_ros"), _imports("test")
    for name in runtime | tests:
        assert name in KEY_OF or name in PIP_ONLY, f"{name} is imported but has no rosdep key or pip route"
    for name in runtime:
        if name in KEY_OF:
            assert KEY_OF[name] in exec_keys, f"{name}: {KEY_OF[name]} missing from exec_depend"
    for name in tests - runtime:
        if name in KEY_OF:
            assert KEY_OF[name] in exec_keys | test_keys, f"{name}: {KEY_OF[name]} missing from test_depend"
    needed = {KEY_OF[n] for n in runtime | tests if n in KEY_OF} | NOT_IMPORTED
    assert exec_keys | test_keys <= needed, f"declared but not used: {(exec_keys | test_keys) - needed}"
    requirements = (REPO / "requirements.txt").read_text()
    readme = (REPO / "README.md").read_text()
    for name in (runtime | tests) & set(PIP_ONLY):
        assert f"{PIP_ONLY[name]}==" in requirements, PIP_ONLY[name]
        assert PIP_ONLY[name] in readme, f"the README does not name the pip route of {PIP_ONLY[name]}"
