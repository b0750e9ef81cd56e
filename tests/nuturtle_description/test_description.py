"""nuturtle_description: the generated URDF and the TurtleBot3 models' constants (expected values from
the notes on the family: ROBOTIS' URDFs, teleop bounds and firmware)."""

from __future__ import annotations

import ast
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nuturtle_description.robot_params import (
    MODEL_ENV,
    RobotParams,
    burger_params,
    model_names,
    model_params,
    models_path,
    resolve_model,
)
from nuturtle_description.urdf import COLORS, robot_urdf
from turtlelib import Transform2D

PACKAGE = Path(__file__).resolve().parents[2] / "nuturtle_description"
TOL = 1e-12
MODELS = ("burger", "waffle", "waffle_pi")
# per model: track width, collision radius, base_scan in base_footprint (m)
GEOMETRY = {
    "burger": (0.16, 0.11, (-0.032, 0.0, 0.182)),
    "waffle": (0.287, 0.22, (-0.064, 0.0, 0.132)),
    "waffle_pi": (0.287, 0.22, (-0.064, 0.0, 0.132)),
}

# ---------------------------------------------------------------------------------------------- URDF


def floats(text: str) -> list[float]:
    return [float(v) for v in text.split()]


class Urdf:
    """Parsed URDF with lookups by link and joint name."""

    def __init__(self, text: str) -> None:
        self.robot = ET.fromstring(text)
        self.links = {link.get("name"): link for link in self.robot.findall("link")}
        self.joints = {joint.get("name"): joint for joint in self.robot.findall("joint")}
        self.materials = {m.get("name"): m for m in self.robot.findall("material")}

    def cylinder(self, link: str, part: str = "collision") -> tuple[float, float]:
        cylinder = self.links[link].find(f"{part}/geometry/cylinder")
        return float(cylinder.get("radius")), float(cylinder.get("length"))

    def position_in_footprint(self, link: str) -> list[float]:
        """Origin of `link` in base_footprint (the fixed chain has no rotations)."""
        xyz = [0.0, 0.0, 0.0]
        while link != "base_footprint":
            (joint,) = [j for j in self.joints.values() if j.find("child").get("link") == link]
            xyz = [a + b for a, b in zip(xyz, floats(joint.find("origin").get("xyz")), strict=True)]
            link = joint.find("parent").get("link")
        return xyz


@pytest.mark.parametrize("model", MODELS)
def test_each_model_s_urdf_has_its_wheel_separation_and_lidar_joint(model):
    track_width, collision_radius, scan_xyz = GEOMETRY[model]
    urdf = Urdf(robot_urdf(model, model_params(model)))
    assert urdf.robot.get("name") == f"turtlebot3_{model}_purple"
    assert set(urdf.links) == {
        "base_footprint",
        "base_link",
        "wheel_left_link",
        "wheel_right_link",
        "base_scan",
    }
    for side, sign in (("left", 1.0), ("right", -1.0)):
        joint = urdf.joints[f"wheel_{side}_joint"]
        assert joint.get("type") == "continuous"
        assert floats(joint.find("axis").get("xyz")) == [0.0, 1.0, 0.0]
        for part in ("visual", "collision"):
            assert urdf.cylinder(f"wheel_{side}_link", part)[0] == pytest.approx(0.033, abs=TOL)
        # wheel centres: on the axle, half the track to each side, one wheel radius above the ground
        assert urdf.position_in_footprint(f"wheel_{side}_link") == pytest.approx(
            [0.0, sign * track_width / 2, 0.033], abs=TOL
        )
    assert urdf.cylinder("base_link")[0] == pytest.approx(collision_radius, abs=TOL)
    assert urdf.joints["scan_joint"].get("type") == "fixed"
    assert urdf.position_in_footprint("base_scan") == pytest.approx(list(scan_xyz), abs=TOL)
    # the body stays below the LiDAR: its top is the LiDAR's base
    body_top = 0.010 + urdf.cylinder("base_link")[1]
    assert body_top == pytest.approx(scan_xyz[2] - urdf.cylinder("base_scan")[1] / 2, abs=TOL)


@settings(max_examples=30)
@given(st.floats(0.01, 0.5), st.floats(0.05, 1.0), st.floats(0.05, 1.0))
def test_urdf_follows_any_robot_parameters(wheel_radius, track_width, collision_radius):
    params = RobotParams(
        wheel_radius=wheel_radius, track_width=track_width, collision_radius=collision_radius
    )
    urdf = Urdf(robot_urdf("burger", params, "green"))
    assert urdf.cylinder("wheel_left_link")[0] == pytest.approx(wheel_radius, rel=1e-11)
    assert urdf.cylinder("base_link")[0] == pytest.approx(collision_radius, rel=1e-11)
    left = urdf.position_in_footprint("wheel_left_link")
    right = urdf.position_in_footprint("wheel_right_link")
    assert left[1] - right[1] == pytest.approx(track_width, rel=1e-11)
    assert left[2] == pytest.approx(wheel_radius, rel=1e-9)
    assert right[2] == pytest.approx(wheel_radius, rel=1e-9)


def test_urdf_is_one_tree_rooted_at_base_footprint():
    urdf = Urdf(robot_urdf("burger", burger_params()))
    children = [joint.find("child").get("link") for joint in urdf.joints.values()]
    parents = [joint.find("parent").get("link") for joint in urdf.joints.values()]
    assert len(children) == len(set(children)), "every link has at most one parent"
    assert set(children) | set(parents) <= set(urdf.links)
    assert set(urdf.links) - set(children) == {"base_footprint"}
    for link in urdf.links:  # every link reaches the root
        urdf.position_in_footprint(link)


@pytest.mark.parametrize("color", sorted(COLORS))
def test_every_colour_tints_the_body(color):
    urdf = Urdf(robot_urdf("burger", burger_params(), color))
    assert urdf.robot.get("name") == f"turtlebot3_burger_{color}"
    assert urdf.links["base_link"].find("visual/material").get("name") == color
    assert floats(urdf.materials[color].find("color").get("rgba")) == list(COLORS[color])
    # every material used is defined
    used = {m.get("name") for m in urdf.robot.iter("material") if m.find("color") is None}
    assert used <= set(urdf.materials)


@pytest.mark.parametrize("color", ["orange", "Red", "", None])
def test_unknown_colour_is_a_value_error(color):
    with pytest.raises(ValueError, match="color must be one of"):
        robot_urdf("burger", burger_params(), color)


def test_load_urdf_launch_offers_exactly_the_urdf_colours():
    tree = ast.parse((PACKAGE / "launch" / "load_urdf.launch.py").read_text())
    (choices,) = [
        keyword.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and getattr(node.func, "id", None) == "DeclareLaunchArgument"
        and node.args
        and node.args[0].value == "color"
        for keyword in node.keywords
        if keyword.arg == "choices"
    ]
    assert sorted(ast.literal_eval(choices)) == sorted(COLORS)


# ------------------------------------------------------------------------------------- RobotParams


def test_each_model_s_constants_are_the_family_s():
    assert model_names() == MODELS
    assert models_path() == PACKAGE / "config" / "models.yaml"
    burger = model_params("burger")
    assert burger == RobotParams(
        wheel_radius=0.033,
        track_width=0.16,
        max_linear_speed=0.22,
        max_angular_speed=2.84,
        motor_cmd_max=265,
        motor_cmd_per_rad_sec=41.6666667,
        encoder_ticks_per_rad=651.8986469,
        collision_radius=0.11,
        lidar_x=-0.032,
        lidar_y=0.0,
        lidar_z=0.182,
        lidar_yaw=0.0,
    )
    assert burger == burger_params()
    waffle = model_params("waffle")
    assert waffle == RobotParams(
        wheel_radius=0.033,
        track_width=0.287,
        max_linear_speed=0.26,
        max_angular_speed=1.82,
        motor_cmd_max=337,
        motor_cmd_per_rad_sec=41.6666667,
        encoder_ticks_per_rad=651.8986469,
        collision_radius=0.22,
        lidar_x=-0.064,
        lidar_y=0.0,
        lidar_z=0.132,
        lidar_yaw=0.0,
    )
    assert model_params("waffle_pi") == waffle  # the same base, motors and LiDAR mount
    assert burger.T_body_scan == Transform2D(-0.032, 0.0, 0.0)
    assert waffle.T_body_scan == Transform2D(-0.064, 0.0, 0.0)
    # the motors: 265 x 0.024 rad/s (XL430, 61 rpm); 337 x 0.024 rad/s (XM430-W210, 77 rpm)
    assert burger.max_wheel_speed == pytest.approx(6.36, abs=1e-8)
    assert waffle.max_wheel_speed == pytest.approx(8.088, abs=1e-8)
    # the fastest wheel: both teleop bounds at once, (v + omega d / 2) / r, beyond either motor limit
    assert burger.wheel_speed_bound == pytest.approx((0.22 + 2.84 * 0.08) / 0.033, rel=1e-12)  # 13.55
    assert waffle.wheel_speed_bound == pytest.approx((0.26 + 1.82 * 0.1435) / 0.033, rel=1e-12)  # 15.79
    assert (waffle.diff_drive().wheel_radius, waffle.diff_drive().track_width) == (0.033, 0.287)
    # the dataclass defaults are the Burger
    for name, value in vars(RobotParams()).items():
        assert getattr(burger, name) == pytest.approx(value, rel=1e-8)


def test_a_model_without_every_constant_is_refused_rather_than_given_the_burger_s(tmp_path, monkeypatch):
    from nuturtle_description import robot_params

    lines = models_path().read_text().splitlines()
    models = tmp_path / "models.yaml"
    models.write_text("\n".join(line for line in lines if not line.startswith("  lidar_z: 0.132")) + "\n")
    monkeypatch.setattr(robot_params, "models_path", lambda: models)
    assert model_params("burger").lidar_z == 0.182  # the other models still load
    with pytest.raises(ValueError, match=r"models.yaml: waffle must give exactly .*; missing \['lidar_z'\]"):
        model_params("waffle")


@pytest.mark.parametrize(
    ("model", "environ", "expected"),
    [
        (None, {}, "burger"),
        (None, {MODEL_ENV: ""}, "burger"),
        (None, {MODEL_ENV: "waffle"}, "waffle"),
        ("waffle_pi", {MODEL_ENV: "waffle"}, "waffle_pi"),  # explicit beats the environment
        ("burger", {MODEL_ENV: "not_a_model"}, "burger"),
    ],
)
def test_the_model_is_the_explicit_one_else_the_environment_s_else_burger(model, environ, expected):
    assert resolve_model(model, environ) == expected


def test_an_unknown_model_is_an_error_naming_the_choices():
    choices = r"\('burger', 'waffle', 'waffle_pi'\)"
    with pytest.raises(ValueError, match=rf"^model must be one of {choices}, got 'waffle_p'$"):
        model_params("waffle_p")
    with pytest.raises(ValueError, match=rf"^model must be one of {choices}, got 'Burger'$"):
        resolve_model("Burger", {})
    with pytest.raises(ValueError, match=rf"^TURTLEBOT3_MODEL .*must be one of {choices}, got 'burger2'$"):
        resolve_model(None, {MODEL_ENV: "burger2"})
    with pytest.raises(ValueError, match=rf"^model must be one of {choices}, got 'waffle_x'$"):
        robot_urdf("waffle_x", burger_params())


@pytest.mark.parametrize(
    "name",
    [
        "wheel_radius",
        "track_width",
        "motor_cmd_max",
        "max_linear_speed",
        "max_angular_speed",
        "motor_cmd_per_rad_sec",
        "encoder_ticks_per_rad",
        "collision_radius",
    ],
)
@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf, "0.1", True, None])
def test_robot_params_reject_invalid_values(name, value):
    with pytest.raises(ValueError, match=name):
        RobotParams(**{name: value})


@pytest.mark.parametrize("name", ["lidar_x", "lidar_y", "lidar_yaw", "lidar_z"])
@pytest.mark.parametrize("value", [math.nan, math.inf, "0.1", True, None])
def test_robot_params_reject_a_non_finite_lidar_mount(name, value):
    with pytest.raises(ValueError, match=name):
        RobotParams(**{name: value})
    if name == "lidar_z":
        with pytest.raises(ValueError, match="lidar_z must be finite and >= 0"):
            RobotParams(lidar_z=-0.1)
