"""`colcon build` of the package installs what `ros2 run semiparam_ros estimator` looks for."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import REPO

COLCON = Path(sys.executable).parent / "colcon"


def _copy_package(dst: Path) -> Path:
    pkg = dst / "semiparam_ros"
    pkg.mkdir(parents=True)
    for name in ("package.xml", "setup.py", "setup.cfg"):
        shutil.copy2(REPO / name, pkg / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in ("resource", "semiparam_ros", "config"):
        shutil.copytree(REPO / name, pkg / name, ignore=ignore)
    return pkg


@pytest.mark.slow
@pytest.mark.skipif(not COLCON.exists(), reason="colcon is not installed in this environment")
def test_colcon_build_installs_entry_point_and_ament_marker(tmp_path):
    src = tmp_path / "src"
    _copy_package(src)
    env = dict(os.environ, COLCON_HOME=str(tmp_path / "colcon_home"))
    cmd = [str(COLCON), "--log-base", str(tmp_path / "log"), "build", "--base-paths", str(src),
           "--build-base", str(tmp_path / "build"), "--install-base", str(tmp_path / "install"),
           "--merge-install", "--event-handlers", "console_direct-"]
    out = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]

    install = tmp_path / "install"
    script = install / "lib" / "semiparam_ros" / "estimator"
    assert script.is_file(), sorted(str(p.relative_to(install)) for p in install.rglob("*"))[:50]
    assert os.access(script, os.X_OK)
    assert "'console_scripts', 'estimator'" in script.read_text() or "ros.main" in script.read_text()
    entry_points = list(install.glob("lib/python3*/site-packages/semiparam_ros*-info/entry_points.txt"))
    assert entry_points and "estimator = semiparam_ros.ros.main:main" in entry_points[0].read_text()
    marker = install / "share" / "ament_index" / "resource_index" / "packages" / "semiparam_ros"
    assert marker.is_file()
    assert (install / "share" / "semiparam_ros" / "package.xml").is_file()
    assert (install / "share" / "semiparam_ros" / "config" / "icub_right_arm.yaml").is_file()
    site = list(install.glob("lib/python3*/site-packages"))
    assert site and (site[0] / "semiparam_ros" / "ros" / "estimator_node.py").is_file()

    # The installed entry point runs: an invalid parameter makes it exit at once with a clear message.
    # PYTHONPATH as `source install/setup.bash` would set it.
    run_env = dict(os.environ, ROS_LOG_DIR=str(tmp_path / "ros_log"),
                   ROS_DOMAIN_ID=str(100 - os.getpid() % 50),
                   ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                   PYTHONPATH=os.pathsep.join([str(site[0]), os.environ.get("PYTHONPATH", "")]))
    run = subprocess.run([str(script), "--ros-args", "-p", "nonparametric.n_features:=0"], env=run_env,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2, run.stdout + run.stderr
    assert "nonparametric.n_features" in run.stderr
