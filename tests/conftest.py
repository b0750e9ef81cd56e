"""Suite-wide test environment: keep DDS on loopback in a test-private domain, logs in a temp dir.

Set at import time, before any test imports rclpy, so every in-process node and every child process
(which inherits os.environ) sees the same private domain.
"""

import os
import tempfile

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
# A domain per pytest process so parallel sessions on one machine never hear each other (0..101 are
# valid with Fast DDS's default port mapping).
os.environ["ROS_DOMAIN_ID"] = str(os.getpid() % 100 + 1)
_ros_home = tempfile.mkdtemp(prefix="nuturtle-test-ros-")
os.environ["ROS_HOME"] = _ros_home
os.environ["ROS_LOG_DIR"] = os.path.join(_ros_home, "log")

import sys  # noqa: E402

import pytest  # noqa: E402
from rclpy_harness import RosHarness  # noqa: E402

# pytest put this folder on sys.path to import this file, and `python -m pytest` puts the repository root
# there; both hold folders named after the packages (tests/turtlelib, turtlelib/, ...) that Python would
# import as empty namespace packages ahead of the installed ones, so take them off again.
_tests_dir = os.path.dirname(os.path.abspath(__file__))
_shadowing = {_tests_dir, os.path.dirname(_tests_dir)}
sys.path[:] = [entry for entry in sys.path if os.path.abspath(entry or os.curdir) not in _shadowing]


@pytest.fixture
def ros():
    """A private rclpy context + executor for in-process node tests (see rclpy_harness.py)."""
    harness = RosHarness()
    yield harness
    harness.shutdown()
