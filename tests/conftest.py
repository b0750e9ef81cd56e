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
# The robot model comes from the test, never from the shell that runs it (nodes default to $TURTLEBOT3_MODEL)
os.environ.pop("TURTLEBOT3_MODEL", None)

import importlib.abc  # noqa: E402
import importlib.util  # noqa: E402
import sys  # noqa: E402

import pytest  # noqa: E402

# pytest put this folder on sys.path to import this file, and `python -m pytest` puts the repository root
# there; both hold folders named after the packages (tests/turtlelib, turtlelib/, ...) that Python would
# import as empty namespace packages ahead of the installed ones, so take them off again.
_tests_dir = os.path.dirname(os.path.abspath(__file__))
_shadowing = {_tests_dir, os.path.dirname(_tests_dir)}
sys.path[:] = [entry for entry in sys.path if os.path.abspath(entry or os.curdir) not in _shadowing]


class _TestHelpers(importlib.abc.MetaPathFinder):
    """Finds the helper modules of this folder (``rclpy_harness``) without the folder on sys.path; they
    are imported (rclpy with them) only by the tests that use them."""

    def find_spec(self, name, path, target=None):
        candidate = os.path.join(_tests_dir, f"{name}.py")
        if path is None and os.path.isfile(candidate):
            return importlib.util.spec_from_file_location(name, candidate)
        return None


sys.meta_path.append(_TestHelpers())


@pytest.fixture
def ros():
    """A private rclpy context + executor for in-process node tests (see rclpy_harness.py).

    Imported here, not at the top: turtlelib's tests run where rclpy is not installed.
    """
    from rclpy_harness import RosHarness

    harness = RosHarness()
    yield harness
    harness.shutdown()
