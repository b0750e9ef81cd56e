"""Suite-wide test environment: keep DDS on loopback in a test-private domain, logs in a temp dir.

Nothing here imports rclpy: `pytest tests/turtlelib` runs with only numpy, scipy, pytest and hypothesis.

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

import importlib.util  # noqa: E402
import sys  # noqa: E402

import pytest  # noqa: E402

# pytest put this folder on sys.path to import this file, and `python -m pytest` puts the repository root
# there; both hold folders named after the packages (tests/turtlelib, turtlelib/, ...) that Python would
# import as empty namespace packages ahead of the installed ones, so take them off again.
_tests_dir = os.path.dirname(os.path.abspath(__file__))
_shadowing = {_tests_dir, os.path.dirname(_tests_dir)}
sys.path[:] = [entry for entry in sys.path if os.path.abspath(entry or os.curdir) not in _shadowing]

# The rclpy test harness stays importable as `rclpy_harness` without this folder on sys.path, and is only
# executed (importing rclpy) when a test first uses it.
_spec = importlib.util.spec_from_file_location("rclpy_harness", os.path.join(_tests_dir, "rclpy_harness.py"))
_spec.loader = importlib.util.LazyLoader(_spec.loader)
sys.modules["rclpy_harness"] = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sys.modules["rclpy_harness"])


@pytest.fixture
def ros():
    """A private rclpy context + executor for in-process node tests (see rclpy_harness.py).

    Imported here, not at the top: turtlelib's tests run where rclpy is not installed.
    """
    from rclpy_harness import RosHarness

    harness = RosHarness()
    yield harness
    harness.shutdown()
