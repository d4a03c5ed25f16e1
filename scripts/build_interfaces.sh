#!/usr/bin/env bash
# Build the interface packages semiparam_ros needs that PyPI has no wheel of (control_msgs'
# FollowJointTrajectory, for the node's action proxy) into the project's .venv, when they are missing.
# A ROS 2 Jazzy machine gets them from rosdep (package.xml) instead, and this script then does nothing.
# Idempotent; about 1 min the first time (cmake and a C/C++ compiler from Debian packages if missing).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
venv=$root/.venv
src=$root/resource/interfaces/control_msgs
stamp=$venv/.interfaces.sha256
want=$(cat "$root/requirements-interfaces.txt" "$src"/CMakeLists.txt "$src"/package.xml "$src"/msg/* \
  "$src"/action/* "$root/scripts/cmake/wheel_prefix_fixup.cmake" | sha256sum | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] \
   && "$venv/bin/python" -c "import control_msgs.action" 2>/dev/null; then
  exit 0
fi
if ! command -v cmake >/dev/null || ! command -v c++ >/dev/null || ! command -v make >/dev/null; then
  echo "== installing cmake and a C/C++ compiler (Debian packages)"
  if [ "$(id -u)" = 0 ]; then apt-get update -qq && apt-get install -y -qq cmake g++ make >/dev/null
  else sudo apt-get update -qq && sudo apt-get install -y -qq cmake g++ make >/dev/null; fi
fi
echo "== building control_msgs (FollowJointTrajectory) into .venv"
"$venv/bin/python" -m pip install --quiet -r "$root/requirements-interfaces.txt"
build=$(mktemp -d)
trap 'rm -rf "$build"' EXIT
(
  cd "$build"
  export AMENT_PREFIX_PATH=$venv CMAKE_PREFIX_PATH=$venv PATH=$venv/bin:$PATH
  export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1 LD_LIBRARY_PATH=$venv/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  cmake "$src" -DCMAKE_INSTALL_PREFIX="$venv" -DPython3_EXECUTABLE="$venv/bin/python" -DBUILD_TESTING=OFF \
    -DCMAKE_BUILD_TYPE=Release -DCMAKE_PROJECT_INCLUDE="$root/scripts/cmake/wheel_prefix_fixup.cmake" \
    > cmake.log 2>&1 || { tail -40 cmake.log; exit 1; }
  make -j"$(nproc)" > make.log 2>&1 || { tail -40 make.log; exit 1; }
  make install > install.log 2>&1 || { tail -40 install.log; exit 1; }
)
"$venv/bin/python" -c "import control_msgs.action"
echo "$want" > "$stamp"
