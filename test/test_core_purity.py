"""semiparam_ros.core must stay free of rclpy and ROS message packages (the node is a thin adapter)."""

from __future__ import annotations

import ast
import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import semiparam_ros.core

CORE_DIR = Path(semiparam_ros.core.__file__).parent
FORBIDDEN = (
    "rclpy", "rcl_interfaces", "rosidl_runtime_py", "rosidl_parser", "rmw", "rpyutils",
    "builtin_interfaces", "std_msgs", "std_srvs", "sensor_msgs", "geometry_msgs", "diagnostic_msgs",
    "rosgraph_msgs", "trajectory_msgs", "ament_index_python", "launch", "launch_ros",
)


def forbidden_imports(source: str) -> list[str]:
    """Top-level packages among FORBIDDEN that a module imports (any nesting level, incl. functions)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
            func = node.func
            fname = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if fname not in ("import_module", "__import__") or not isinstance(node.args[0].value, str):
                continue
            names = [node.args[0].value]
        else:
            continue
        found += [n for n in names if n.split(".")[0] in FORBIDDEN]
    return found


def core_modules() -> list[str]:
    return sorted(f"semiparam_ros.core.{m.name}" for m in pkgutil.iter_modules([str(CORE_DIR)]))


def test_scanner_detects_violations():
    bad = "import rclpy\nfrom sensor_msgs.msg import JointState\ndef f():\n    import std_msgs.msg\n" \
          "importlib.import_module('geometry_msgs.msg')\n"
    assert forbidden_imports(bad) == ["rclpy", "sensor_msgs.msg", "std_msgs.msg", "geometry_msgs.msg"]
    assert forbidden_imports("import numpy\nfrom semiparam_ros.core.stream import messages\n") == []


@pytest.mark.parametrize("path", sorted(CORE_DIR.glob("*.py")), ids=lambda p: p.name)
def test_core_source_has_no_ros_imports(path):
    assert forbidden_imports(path.read_text()) == [], f"{path} imports ROS packages"


def test_importing_core_loads_no_ros_module():
    modules = core_modules()
    assert "semiparam_ros.core.estimator.online" in modules or len(modules) >= 3
    code = (
        "import importlib, json, sys\n"
        f"mods = {modules!r}\n"
        "errors = {}\n"
        "for m in mods:\n"
        "    try:\n"
        "        importlib.import_module(m)\n"
        "    except ImportError as err:\n"
        "        errors[m] = str(err)\n"
        f"forbidden = {FORBIDDEN!r}\n"
        "loaded = sorted(n for n in sys.modules if n.split('.')[0] in forbidden)\n"
        "print(json.dumps({'loaded': loaded, 'errors': errors}))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["loaded"] == [], f"importing the core loaded ROS modules: {result['loaded']}"
    # An ImportError of a ROS package would hide a violation; other import errors are someone's WIP.
    ros_errors = {m: e for m, e in result["errors"].items() if any(f in e for f in FORBIDDEN)}
    assert ros_errors == {}


def test_subprocess_check_detects_a_ros_import():
    code = "import sys, rclpy\nprint(sorted(n for n in sys.modules if n.split('.')[0] == 'rclpy')[:1])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert "rclpy" in out.stdout
