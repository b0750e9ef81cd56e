"""A TurtleBot3's URDF (any model), generated from the same constants the nodes use.

One source of truth: the wheel radius, track width, collision radius and LiDAR mount come from `RobotParams`
(a model's in config/models.yaml), so the drawn robot and the kinematics can never disagree. Frames follow
REP 105 and the stock robot: base_footprint → base_link → {wheel_left_link, wheel_right_link,
base_scan}; the wheel joints are named `wheel_left_joint` and `wheel_right_joint`.

`color` tints the body (red = simulator truth, blue = wheel odometry, green = SLAM, purple = other),
so several robots can be shown at once with a frame prefix per colour.
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

from turtlelib.util.validation import one_of

from .robot_params import RobotParams, model_names

COLORS = {
    "red": (0.8, 0.1, 0.1, 1.0),
    "green": (0.1, 0.7, 0.2, 1.0),
    "blue": (0.1, 0.3, 0.9, 1.0),
    "purple": (0.55, 0.2, 0.75, 1.0),
}

# Geometry that the kinematics do not use (m), from the stock robots' descriptions. The body, a cylinder of
# the collision radius, reaches up to the LiDAR's base (at least MIN_BODY_HEIGHT tall).
WHEEL_WIDTH = 0.018
MIN_BODY_HEIGHT = 0.01
# base_link above base_footprint (m)
BASE_LINK_Z = 0.010
LIDAR_RADIUS = 0.035
LIDAR_HEIGHT = 0.04


def _origin(x: float = 0.0, y: float = 0.0, z: float = 0.0, roll: float = 0.0, yaw: float = 0.0) -> str:
    return f'<origin xyz="{x:.12g} {y:.12g} {z:.12g}" rpy="{roll:.12g} 0 {yaw:.12g}"/>'


def _cylinder_link(name: str, radius: float, length: float, origin: str, material: str) -> str:
    geometry = f'<geometry><cylinder radius="{radius:.12g}" length="{length:.12g}"/></geometry>'
    return (
        f'  <link name="{name}">\n'
        f"    <visual>{origin}{geometry}<material name={quoteattr(material)}/></visual>\n"
        f"    <collision>{origin}{geometry}</collision>\n"
        f"  </link>\n"
    )


def _joint(name: str, kind: str, parent: str, child: str, origin: str, axis: str = "") -> str:
    axis_xml = f'<axis xyz="{axis}"/>' if axis else ""
    return (
        f'  <joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f"{origin}{axis_xml}</joint>\n"
    )


def robot_urdf(model: str, params: RobotParams, color: str = "purple") -> str:
    """URDF text of the TurtleBot3 ``model`` (named ``turtlebot3_<model>_<color>``) with the constants
    ``params``, drawn in `color` (one of COLORS); ValueError for another model or colour."""
    one_of("model", model, model_names())
    if not isinstance(color, str) or color not in COLORS:
        raise ValueError(f"color must be one of {sorted(COLORS)}, got {color!r}")
    r, g, b, a = COLORS[color]
    body_height = max(params.lidar_z - BASE_LINK_Z - LIDAR_HEIGHT / 2.0, MIN_BODY_HEIGHT)
    radius = params.wheel_radius
    half_track = params.track_width / 2.0
    materials = (
        f'  <material name="{color}"><color rgba="{r} {g} {b} {a}"/></material>\n'
        '  <material name="dark"><color rgba="0.1 0.1 0.1 1"/></material>\n'
    )
    links = (
        '  <link name="base_footprint"/>\n'
        + _cylinder_link(
            "base_link",
            params.collision_radius,
            body_height,
            _origin(z=body_height / 2.0),
            color,
        )
        + _cylinder_link("wheel_left_link", radius, WHEEL_WIDTH, _origin(roll=1.5707963267948966), "dark")
        + _cylinder_link("wheel_right_link", radius, WHEEL_WIDTH, _origin(roll=1.5707963267948966), "dark")
        + _cylinder_link("base_scan", LIDAR_RADIUS, LIDAR_HEIGHT, _origin(), "dark")
    )
    joints = (
        _joint("base_joint", "fixed", "base_footprint", "base_link", _origin(z=BASE_LINK_Z))
        + _joint(
            "wheel_left_joint",
            "continuous",
            "base_link",
            "wheel_left_link",
            _origin(y=half_track, z=radius - BASE_LINK_Z),
            "0 1 0",
        )
        + _joint(
            "wheel_right_joint",
            "continuous",
            "base_link",
            "wheel_right_link",
            _origin(y=-half_track, z=radius - BASE_LINK_Z),
            "0 1 0",
        )
        + _joint(
            "scan_joint",
            "fixed",
            "base_link",
            "base_scan",
            _origin(
                x=params.lidar_x,
                y=params.lidar_y,
                z=params.lidar_z - BASE_LINK_Z,
                yaw=params.lidar_yaw,
            ),
        )
    )
    return (
        '<?xml version="1.0"?>\n'
        f'<robot name="turtlebot3_{model}_{color}">\n{materials}{links}{joints}</robot>\n'
    )
