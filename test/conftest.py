"""Test-suite set-up: ``test/`` on the import path, so every test module imports the shared ``helpers``."""

import sys
from pathlib import Path

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)


def pytest_configure(config):
    """Give the test process (and the nodes it starts) a ROS_HOME of its own: a node keeps its checkpoint
    under $ROS_HOME by default, which must never be the user's ~/.ros."""
    import os
    import tempfile

    os.environ["ROS_HOME"] = tempfile.mkdtemp(prefix="semiparam_ros_test_home_")
