"""Every dependency key of every package.xml resolves for ``rosdep install``: a package of this workspace, a
ROS 2 Jazzy package, or a rosdep key, both checked against ros/rosdistro (lists below); a Python module
without a rosdep key is installed by the README's pip step instead."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

from workspace import PIP_ONLY, ROOT, THIRD_PARTY, packages

# Checked by hand against ros/rosdistro at commit 8468e88ccd523427f9131e39d2af0938f1c298b2 (2026-08-22):
# released in jazzy/distribution.yaml ...
JAZZY_PACKAGES = frozenset(
    {
        "ament_index_python", "builtin_interfaces", "diagnostic_msgs", "geometry_msgs",
        "joint_state_publisher", "launch", "launch_ros", "nav_msgs", "rcl_interfaces", "rclpy",
        "robot_state_publisher",
        "rosgraph_msgs", "rviz2", "sensor_msgs", "std_msgs", "std_srvs", "teleop_twist_keyboard", "tf2_msgs",
        "tf2_ros", "visualization_msgs",
    }
)  # fmt: skip
# ... and keys of rosdep/python.yaml (python3-*) and rosdep/base.yaml (xterm). Not a key there:
# python3-foxglove-sdk-pip, python3-foxglove-sdk, python3-mcap-pip, python3-mcap (both pip only: PIP_ONLY).
ROSDEP_KEYS = frozenset(
    {
        "python3-numpy", "python3-scipy", "python3-yaml", "python3-matplotlib", "python3-tqdm",
        "python3-rosbags-pip", "python3-pytest", "python3-hypothesis", "xterm",
    }
)  # fmt: skip
DEPEND_TAGS = ("depend", "build_depend", "buildtool_depend", "exec_depend", "test_depend")


def test_every_dependency_key_of_every_package_xml_resolves():
    unknown = {}
    for name, package in packages().items():
        root = ET.parse(package.folder / "package.xml").getroot()
        keys = {element.text.strip() for tag in DEPEND_TAGS for element in root.iter(tag)}
        missing = keys - packages().keys() - JAZZY_PACKAGES - ROSDEP_KEYS
        if missing:
            unknown[name] = sorted(missing)
    assert not unknown, f"keys that rosdep cannot resolve: {unknown}"


def test_the_third_party_keys_are_rosdep_keys_and_the_rest_has_a_pip_step_in_the_readme():
    assert {key for key, _ in THIRD_PARTY.values()} <= ROSDEP_KEYS
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    pip_lines = [line for line in readme.splitlines() if re.search(r"\bpip install\b", line)]
    for distribution in PIP_ONLY.values():
        assert any(distribution in line.split() for line in pip_lines), (
            f"README: no pip step for {distribution}"
        )
