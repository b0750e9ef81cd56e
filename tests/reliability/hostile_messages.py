"""Hypothesis strategies of hostile input messages for the nodes' fuzz tests (test_fuzz_nodes.py), and the
clean messages those tests drive the nodes with, built by hand from geometry.

Hostile means well-formed (every message serialises and reaches the node) but with values no sane sender
produces: extreme finite floats (+-1e300, +-max, 1e-300, subnormals), NaN and +-inf, negative zero, arrays of
the wrong length, empty or huge (up to 10,000 joint names or markers, 100,000 ranges), missing, repeated or
unknown joint names, wrong frame ids, stamps with a negative sec or a nanosec >= 1e9 (up to the uint32
maximum), stamps that repeat, go backwards or jump far ahead; quaternions that are zero, not unit or not
finite; LaserScan layouts whose angle_min, angle_max, angle_increment and len(ranges) disagree, range_min >=
range_max; landmarks 1 nm from the sensor.

Two kinds of strategies:

* ``hostile_*``: anything, accepted or refused (the liveness tests: the node lives, publishes finite values
  and recovers);
* ``refused_*``: messages a node must refuse in the context they are drawn for (its last accepted wheel
  sample, the robot's pose, the landmarks it has mapped), so that a node fed them besides a clean stream ends
  with the clean stream's estimate. They follow the nodes' input contract (see ``CONTRACT`` below).

Every strategy draws `Sent` items: a topic, the family of the value (for the reports) and the message, with a
short repr (hypothesis prints the falsifying draws, and a 10,000-marker array must not fill the report).

Huge arrays are built from a few drawn parameters (a size and a fill), never element by element, and the
largest ones are of layouts the nodes can refuse or handle in bounded time whatever they accept: an estimator
that accepted 10,000 distinct landmarks would need a 20,000 x 20,000 covariance.
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseWithCovarianceStamped, Quaternion, Twist, Vector3
from hypothesis import strategies as st
from nav_msgs.msg import Odometry
from ros_test_messages import (
    INT32_MAX,
    INT32_MIN,
    LDS01,
    cylinder_array,
    cylinder_marker,
    float32_array,
    relative,
    scan_message,
    stamp,
)
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, LaserScan
from visualization_msgs.msg import Marker, MarkerArray

from nuturtle_description.robot_params import burger_params
from nuturtle_ros_common.conversions import QUATERNION_NORM_TOLERANCE
from nuturtle_ros_common.wheel_stream import ENCODER_SLACK_TICKS
from turtlelib import (
    SampleGateConfig,
    SlamConfig,
    TimelineConfig,
    Transform2D,
    arena_walls,
    simulate_scan,
)

S = 1_000_000_000  # ns per s
UINT32_MAX = 2**32 - 1

ROBOT = burger_params()
DRIVE = ROBOT.diff_drive()
WHEELS = ("wheel_left_joint", "wheel_right_joint")
T_BODY_SENSOR = ROBOT.T_body_scan  # base_scan in base_footprint (the LDS-01 at lidar_x)
TICK_RAD = 1.0 / ROBOT.encoder_ticks_per_rad


@dataclass(frozen=True)
class Contract:
    """What the nodes refuse (the reliability issue's input contract, at the nodes' default parameters; the
    ``refused_*`` strategies draw values beyond these limits with a margin, so that ``>`` or ``>=`` in a node
    makes no difference)."""

    # joint_states more than this after the last accepted one
    max_jump_ns: int = round(SampleGateConfig().max_sample_gap * S)
    # wheel increments beyond factor x wheel_speed_bound x dt ...
    max_speed_factor: float = 1.0 + SampleGateConfig().speed_margin
    increment_ticks: float = ENCODER_SLACK_TICKS  # ... + this many encoder ticks
    # consecutive, mutually consistent refused samples restart the node from them
    restart_after: int = SampleGateConfig().restart_samples
    min_range_m: float = SlamConfig().min_range  # observations nearer than this to the sensor
    max_observations: int = SlamConfig().max_observations  # observation arrays with more entries
    # observations stamped this long after the newest joint_states
    max_observation_lead_ns: int = round(TimelineConfig().max_observation_lead * S)
    quaternion_tolerance: float = QUATERNION_NORM_TOLERANCE  # | |q| - 1 | beyond this (or non-finite)

    def max_increment_rad(self, dt_ns: int) -> float:
        return self.max_speed_factor * ROBOT.wheel_speed_bound * dt_ns / S + self.increment_ticks * TICK_RAD


CONTRACT = Contract()


class Sent:
    """One message for one topic (a topic name relative to the rig's namespace), drawn from ``family``.

    A plain class with a short repr: hypothesis prints the falsifying draws with it (a dataclass it would
    print field by field, a 10,000-marker array in full)."""

    __slots__ = ("family", "msg", "topic")

    def __init__(self, topic: str, family: str, msg: Any) -> None:
        self.topic, self.family, self.msg = topic, family, msg

    def __repr__(self) -> str:
        return f"Sent({self.topic}, {self.family}: {summary(self.msg)})"


JOINT_STATE_FAMILIES = (
    "negative sec",
    "nanosec >= 1e9",
    "plausible instant, nanosec >= 1e9",
    "exact duplicate",
    "repeated stamp",
    "backwards",
    "jump > 0.5 s",
    "increment too large",
    "non-finite angle",
    "bad names",
    "lengths differ",
)
OBSERVATION_FAMILIES = (
    "too near",
    "too many",
    "too far ahead",
    "stale",
    "non-finite",
    "unknown frame",
    "frames differ",
    "stamps differ",
    "repeated ids",
    "empty",
    "outside the gate",  # known association, once the landmarks are mapped
)
POSE_FAMILIES = ("bad quaternion", "non-finite position", "other frame")


# --- summaries ----------------------------------------------------------------------------------------------


def _values(values: Sequence, limit: int = 4) -> str:
    shown = ", ".join(repr(float(v)) if isinstance(v, float) else repr(v) for v in list(values[:limit]))
    return f"[{shown}{', ...' if len(values) > limit else ''}] ({len(values)})"


def _vector(v: Vector3) -> str:
    return f"({v.x!r}, {v.y!r}, {v.z!r})"


def _stamp(t: Time) -> str:
    return f"({t.sec}, {t.nanosec})"


def summary(msg: Any) -> str:
    """A one-line description of a message (its stamps, frames and the first few values of its arrays)."""
    if isinstance(msg, JointState):
        return (
            f"JointState(stamp={_stamp(msg.header.stamp)}, name={_values(msg.name)}, "
            f"position={_values(msg.position)}, velocity={_values(msg.velocity)})"
        )
    if isinstance(msg, LaserScan):
        return (
            f"LaserScan(stamp={_stamp(msg.header.stamp)}, frame={msg.header.frame_id!r}, "
            f"angle_min={msg.angle_min!r}, angle_max={msg.angle_max!r}, angle_increment="
            f"{msg.angle_increment!r}, range_min={msg.range_min!r}, range_max={msg.range_max!r}, "
            f"ranges={_values(msg.ranges)}, intensities={len(msg.intensities)})"
        )
    if isinstance(msg, MarkerArray):
        head = [
            f"{m.header.frame_id!r} {_stamp(m.header.stamp)} id={m.id} action={m.action} "
            f"({m.pose.position.x!r}, {m.pose.position.y!r})"
            for m in msg.markers[:3]
        ]
        more = " ..." if len(msg.markers) > 3 else ""
        return f"MarkerArray({len(msg.markers)} markers: {'; '.join(head)}{more})"
    if isinstance(msg, Clock):
        return f"Clock({_stamp(msg.clock)})"
    if isinstance(msg, (PoseWithCovarianceStamped, Odometry)):
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        child = f" -> {msg.child_frame_id!r}" if isinstance(msg, Odometry) else ""
        return (
            f"{type(msg).__name__}(stamp={_stamp(msg.header.stamp)}, frame={msg.header.frame_id!r}{child}, "
            f"position=({p.x!r}, {p.y!r}, {p.z!r}), orientation=({q.x!r}, {q.y!r}, {q.z!r}, {q.w!r}))"
        )
    if isinstance(msg, Twist):
        return f"Twist(linear={_vector(msg.linear)}, angular={_vector(msg.angular)})"
    text = repr(msg)
    return text if len(text) <= 400 else text[:400] + " ..."


# --- clean messages -----------------------------------------------------------------------------------------


def stamp_key(t: Time) -> tuple[int, int]:
    return t.sec, t.nanosec


def joint_state(t_ns: int, positions: Sequence[float], names: Sequence[str] = WHEELS) -> JointState:
    msg = JointState(name=list(names), position=[float(p) for p in positions])
    msg.header.stamp = stamp(t_ns)
    return msg


def wheel_command(left_rad_s: float, right_rad_s: float) -> JointState:
    return JointState(name=list(WHEELS), velocity=[float(left_rad_s), float(right_rad_s)])


def quaternion_from_yaw(yaw: float, norm: float = 1.0) -> Quaternion:
    return Quaternion(z=norm * math.sin(yaw / 2.0), w=norm * math.cos(yaw / 2.0))


def pose_stamped(T: Transform2D, frame_id: str, t_ns: int = 0) -> PoseWithCovarianceStamped:
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp(t_ns)
    msg.pose.pose.position = Point(x=T.x, y=T.y)
    msg.pose.pose.orientation = quaternion_from_yaw(T.theta)
    return msg


def twist(vx: float = 0.0, omega: float = 0.0) -> Twist:
    return Twist(linear=Vector3(x=float(vx)), angular=Vector3(z=float(omega)))


@functools.cache
def cylinder_scan_ranges() -> tuple[float, ...]:
    """An exact LDS-01 scan from a sensor off the centre of a 5 m arena: one cylinder (r = 5 cm) at (1.0,
    0.3) in the sensor frame, and the walls."""
    walls = (Transform2D(0.4, -0.3, 0.2).inverse() @ arena_walls(5.0, 5.0).reshape(-1, 2)).reshape(-1, 4)
    circles = np.array([[1.0, 0.3, 0.05]])
    return tuple(simulate_scan(Transform2D(), circles, walls, LDS01).tolist())


SCAN_CYLINDER_XY = (1.0, 0.3)


# --- floats, stamps, names, frames --------------------------------------------------------------------------

F64_MAX = sys.float_info.max
F32_MAX = float(np.finfo(np.float32).max)
F32_SUBNORMAL = float(np.finfo(np.float32).smallest_subnormal)
SPECIAL_FLOAT64 = (
    0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 5e-324, -5e-324, sys.float_info.min, 1e300, -1e300,
    F64_MAX, -F64_MAX, math.nan, -math.nan, math.inf, -math.inf, 1e-9, 1e9,
)  # fmt: skip
SPECIAL_FLOAT32 = (
    0.0, -0.0, 1.0, -1.0, F32_SUBNORMAL, -F32_SUBNORMAL, float(np.finfo(np.float32).tiny), F32_MAX,
    -F32_MAX, math.nan, math.inf, -math.inf, 1e-9, 1e9,
)  # fmt: skip


def float64s() -> st.SearchStrategy[float]:
    """Any double, the special ones often."""
    return st.one_of(st.sampled_from(SPECIAL_FLOAT64), st.floats())


def float32s() -> st.SearchStrategy[float]:
    """Any float32 (what a LaserScan can carry), the special ones often."""
    return st.one_of(st.sampled_from(SPECIAL_FLOAT32), st.floats(width=32))


def invalid_stamps() -> st.SearchStrategy[Time]:
    """Stamps no clock gives: a negative sec, or a nanosec >= 1e9 (up to the uint32 maximum)."""
    return st.one_of(
        st.builds(Time, sec=st.integers(INT32_MIN, -1), nanosec=st.integers(0, UINT32_MAX)),
        st.builds(Time, sec=st.integers(INT32_MIN, INT32_MAX), nanosec=st.integers(S, UINT32_MAX)),
    )


def encoded_with_large_nanosec(t_ns: int, carries: int) -> Time:
    """``t_ns`` written with ``carries`` whole seconds moved into nanosec (>= 1e9): the same instant if one
    computes ``sec * 1e9 + nanosec``, an invalid stamp all the same."""
    sec, nanosec = divmod(t_ns, S)
    return Time(sec=sec - carries, nanosec=nanosec + carries * S)


def hostile_stamps(t_ref_ns: int) -> st.SearchStrategy[Time]:
    """Stamps around a reference time ``t_ref_ns`` (the last sample a node accepted): invalid ones,
    repeated, just before or after, more than 0.5 s after, back to 0, far ahead, the ends of Time's range."""
    return st.one_of(
        invalid_stamps(),
        st.sampled_from([0, -1, 1, -S // 20, S // 20, S // 2, S // 2 + 1, 10 * S]).map(
            lambda d: stamp(t_ref_ns + d)
        ),
        st.integers(-t_ref_ns, 10**6 * S).map(lambda d: stamp(t_ref_ns + d)),
        st.integers(1, 3).map(lambda k: encoded_with_large_nanosec(t_ref_ns + S // 20, k)),
        st.sampled_from(
            [(0, 0), (INT32_MAX, S - 1), (INT32_MAX, UINT32_MAX), (INT32_MIN, 0), (0, UINT32_MAX)]
        ).map(lambda sn: Time(sec=sn[0], nanosec=sn[1])),
    )


def plausible_stamps(t_ref_ns: int) -> st.SearchStrategy[Time]:
    """Valid stamps up to 0.5 s after the reference."""
    return st.integers(1, S // 2).map(lambda d: stamp(t_ref_ns + d))


FRAME_IDS = (
    "", "odom", "map", "base_footprint", "base_scan", "base_link", "nusim/world", "world", "/odom", " odom",
    "odom\n", "\u00f6dom", "x" * 1000,
)  # fmt: skip


def frame_ids() -> st.SearchStrategy[str]:
    return st.one_of(st.sampled_from(FRAME_IDS), _texts())


def other_frame_ids(*excluded: str) -> st.SearchStrategy[str]:
    """Frame ids other than ``excluded`` (and never empty): built, not filtered."""
    return st.one_of(
        st.sampled_from([f for f in FRAME_IDS if f not in excluded and f]), _texts().map(lambda t: "~" + t)
    )


def _texts() -> st.SearchStrategy[str]:
    # no NUL: a C string ends there, and no surrogates: they cannot be encoded
    return st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=12)


_L, _R = WHEELS
JOINT_NAME_LISTS = (
    (_L, _R), (_R, _L), (_L,), (_R,), (), (_L, _L, _R), (_L, _R, _R), ("left", "right"), ("", ""),
    (_L, _R, "caster_joint"), (_L.upper(), _R), (_L + " ", _R), (_R, _R),
)  # fmt: skip
MANY_JOINTS = tuple(f"joint_{i}" for i in range(9_998)) + WHEELS  # 10,000 names, the wheels last


def many_joints(t_ns: int, field: str = "position", wheels: Sequence[float] = (0.0, 0.0)) -> JointState:
    """A JointState of 10,000 joints, the wheels last (at ``wheels``), the others at 0."""
    msg = JointState(name=list(MANY_JOINTS))
    setattr(msg, field, [0.0] * (len(MANY_JOINTS) - 2) + [float(w) for w in wheels])
    msg.header.stamp = stamp(t_ns)
    return msg


def joint_name_lists() -> st.SearchStrategy[list[str]]:
    return st.one_of(
        st.sampled_from(JOINT_NAME_LISTS).map(list),
        st.lists(_texts(), max_size=4),
        st.just(MANY_JOINTS).map(list),
    )


# --- geometry -----------------------------------------------------------------------------------------------

SPECIAL_QUATERNIONS = (
    (0.0, 0.0, 0.0, 0.0), (-0.0, -0.0, -0.0, -0.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0, -1.0),
    (0.0, 0.0, 0.0, 0.5), (0.0, 0.0, 0.0, 2.0), (0.0, 0.0, 1.0, 1.0), (0.0, 0.0, 0.0, 1.005),
    (0.0, 0.0, 0.0, 1.02), (1.0, 0.0, 0.0, 0.0), (math.nan, 0.0, 0.0, 1.0), (0.0, 0.0, math.inf, 1.0),
    (0.0, 0.0, 0.0, 1e300), (0.0, 0.0, 0.0, 1e-300), (0.0, 0.0, 5e-324, 0.0), (0.0, 0.0, math.nan, math.nan),
    (0.0, 0.0, F64_MAX, F64_MAX),
)  # fmt: skip


def quaternions() -> st.SearchStrategy[Quaternion]:
    """Zero, non-unit, non-finite, tilted and unit quaternions."""
    return st.one_of(
        st.sampled_from(SPECIAL_QUATERNIONS).map(lambda q: Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])),
        st.builds(Quaternion, x=float64s(), y=float64s(), z=float64s(), w=float64s()),
        st.builds(
            quaternion_from_yaw,
            st.floats(-10.0, 10.0),
            st.sampled_from([1.0, 1.0 + 1e-3, 1.0 - 5e-3, 1.011, 0.98, 10.0, 1e-3]),
        ),
    )


def bad_quaternions() -> st.SearchStrategy[Quaternion]:
    """Quaternions the contract refuses: non-finite, or a norm further from 1 than the tolerance (with a
    margin)."""
    # four doubles, one of them (at least) replaced by a non-finite value: built, not filtered
    non_finite = st.tuples(
        st.tuples(float64s(), float64s(), float64s(), float64s()),
        st.integers(0, 3),
        st.sampled_from([math.nan, math.inf, -math.inf]),
    ).map(lambda drawn: tuple(drawn[2] if i == drawn[1] else v for i, v in enumerate(drawn[0])))
    margin = CONTRACT.quaternion_tolerance + 0.005
    off_norm = st.tuples(
        st.floats(-10.0, 10.0),
        st.one_of(st.floats(0.0, 1.0 - margin), st.floats(1.0 + margin, 1e6), st.sampled_from([1e300])),
    ).map(lambda yn: (0.0, 0.0, yn[1] * math.sin(yn[0] / 2), yn[1] * math.cos(yn[0] / 2)))
    zero = st.sampled_from([(0.0, 0.0, 0.0, 0.0), (-0.0, 0.0, -0.0, 0.0), (0.0, 0.0, 5e-324, 0.0)])
    return st.one_of(non_finite, off_norm, zero).map(lambda q: Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]))


def coordinates() -> st.SearchStrategy[float]:
    return st.one_of(float64s(), st.floats(-3.0, 3.0))


def poses(orientations: st.SearchStrategy[Quaternion] | None = None) -> st.SearchStrategy[Pose]:
    return st.builds(
        Pose,
        position=st.builds(Point, x=coordinates(), y=coordinates(), z=coordinates()),
        orientation=quaternions() if orientations is None else orientations,
    )


def covariances() -> st.SearchStrategy[list[float]]:
    return st.one_of(
        st.just([0.0] * 36),
        float64s().map(lambda v: [v] * 36),
        st.lists(float64s(), min_size=36, max_size=36),
    )


def vectors() -> st.SearchStrategy[Vector3]:
    component = st.one_of(float64s(), st.floats(-1.0, 1.0), st.just(0.0))
    return st.builds(Vector3, x=component, y=component, z=component)


# --- joint states -------------------------------------------------------------------------------------------


def increments(dt_ns: int = S // 20) -> st.SearchStrategy[float]:
    """Wheel-angle increments: plausible, at the contract's bound and beyond, any double."""
    bound = CONTRACT.max_increment_rad(dt_ns)
    return st.one_of(
        st.floats(-0.2, 0.2),
        st.sampled_from([bound * 0.99, -bound * 0.99, bound * 1.01, -bound * 1.01, 2 * TICK_RAD, 1e300]),
        float64s(),
    )


@st.composite
def joint_state_arrays(draw, names: list[str], reference: Sequence[float], near: st.SearchStrategy[float]):
    """Values for a JointState array of joints ``names``: the right length or not, the wheels' values near
    ``reference`` (left, right) or anything."""
    n = len(names)
    length = draw(st.one_of(st.just(n), st.sampled_from(sorted({0, 1, max(n - 1, 0), n + 1}))))
    if length > 16:
        values = [draw(st.one_of(float64s(), st.floats(-10.0, 10.0)))] * length
    else:
        values = draw(
            st.lists(st.one_of(float64s(), st.floats(-10.0, 10.0)), min_size=length, max_size=length)
        )
    if length == n and draw(st.booleans()):
        for side, joint in enumerate(WHEELS):
            if joint in names:
                values[names.index(joint)] = reference[side] + draw(near)
    return values


@st.composite
def hostile_joint_states(
    draw,
    t_ref_ns: int,
    phi_ref: Sequence[float] = (0.0, 0.0),
    field: str = "position",
    topic: str = "joint_states",
):
    """A JointState of any names, lengths, values (``field``: wheel angles near ``phi_ref`` or anything) and
    stamp (around ``t_ref_ns``, the node's last accepted sample, or invalid)."""
    names = draw(joint_name_lists())
    msg = JointState(name=names)
    setattr(msg, field, draw(joint_state_arrays(names, phi_ref, increments())))
    for other in ("position", "velocity", "effort"):
        if other != field:
            setattr(msg, other, draw(st.lists(float64s(), max_size=3)))
    msg.header.stamp = draw(st.one_of(hostile_stamps(t_ref_ns), plausible_stamps(t_ref_ns)))
    msg.header.frame_id = draw(frame_ids())
    return Sent(topic, "joint_states", msg)


@st.composite
def consistent_bursts(draw, t_ref_ns: int, phi_ref: Sequence[float], topic: str = "joint_states"):
    """3 to 5 mutually consistent samples (50 ms apart, plausible increments) of another time base: back in
    time, at 0, or far ahead (a restarted simulator, a looped recording, a clock that jumped)."""
    base_ns = draw(
        st.one_of(
            st.just(0), st.integers(0, max(t_ref_ns - S, 0)), st.integers(t_ref_ns + S, t_ref_ns + 10**6 * S)
        )
    )
    phi0 = draw(st.one_of(st.just(tuple(phi_ref)), st.tuples(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4))))
    speeds = draw(st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)))
    count = draw(st.integers(3, 5))
    dt_s = 0.05
    return [
        Sent(
            topic,
            "consistent burst",
            joint_state(
                base_ns + k * S // 20, (phi0[0] + speeds[0] * k * dt_s, phi0[1] + speeds[1] * k * dt_s)
            ),
        )
        for k in range(count)
    ]


@st.composite
def refused_joint_states(
    draw,
    t_last_ns: int,
    phi_last: Sequence[float],
    t_next_ns: int,
    topic: str = "joint_states",
    families: Sequence[str] = JOINT_STATE_FAMILIES,
):
    """A JointState the contract refuses after the accepted sample ``(t_last_ns, phi_last)`` (the next clean
    one comes at ``t_next_ns``): an invalid stamp (also one that encodes a plausible instant), a stamp not
    after the last (an exact duplicate is ignored), a jump of more than 0.5 s, an increment beyond 1.5 x the
    robot's top wheel speed x dt + 2 ticks, non-finite angles, or names and positions that do not fit."""
    family = draw(st.sampled_from(families))
    small = st.floats(-0.1, 0.1)
    angles = [phi_last[0] + draw(small), phi_last[1] + draw(small)]
    names: list[str] = list(WHEELS)
    if family == "negative sec":
        t = Time(sec=draw(st.integers(INT32_MIN, -1)), nanosec=draw(st.integers(0, UINT32_MAX)))
    elif family == "nanosec >= 1e9":
        t = Time(sec=draw(st.integers(0, INT32_MAX)), nanosec=draw(st.integers(S, UINT32_MAX)))
    elif family == "plausible instant, nanosec >= 1e9":
        dt_ns = draw(st.integers(1, t_next_ns - t_last_ns - 1))
        t = encoded_with_large_nanosec(t_last_ns + dt_ns, draw(st.integers(1, 3)))
        angles = [phi_last[0], phi_last[1]]  # standing still: only the stamp is wrong
    elif family == "exact duplicate":
        t, angles = stamp(t_last_ns), list(phi_last)
    elif family == "repeated stamp":
        t = stamp(t_last_ns)
        angles[draw(st.integers(0, 1))] += draw(st.sampled_from([1e-9, -1e-9, 1e-3, -0.05]))
    elif family == "backwards":
        t = stamp(
            t_last_ns - draw(st.one_of(st.integers(1, 10 * S), st.sampled_from([1, S // 20, t_last_ns])))
        )
    elif family == "jump > 0.5 s":
        lead = draw(
            st.one_of(st.integers(CONTRACT.max_jump_ns + 1_000, 20 * S), st.integers(20 * S, 10**6 * S))
        )
        t = stamp(t_last_ns + lead)
    elif family == "increment too large":
        dt_ns = draw(st.integers(1, t_next_ns - t_last_ns - 1))
        t = stamp(t_last_ns + dt_ns)
        bound = CONTRACT.max_increment_rad(dt_ns)
        excess = draw(st.one_of(st.floats(1.05, 100.0), st.sampled_from([1e6, 1e300 / max(bound, 1.0)])))
        sign = draw(st.sampled_from([1.0, -1.0]))
        wheel = draw(st.sampled_from([(0,), (1,), (0, 1)]))
        angles = [phi_last[0], phi_last[1]]
        for side in wheel:
            angles[side] = phi_last[side] + sign * (bound * excess + 1e-6)
    elif family == "non-finite angle":
        t = stamp(t_last_ns + draw(st.integers(1, t_next_ns - t_last_ns - 1)))
        angles[draw(st.integers(0, 1))] = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
    elif family == "bad names":
        t = stamp(t_last_ns + draw(st.integers(1, t_next_ns - t_last_ns - 1)))
        names = list(draw(st.sampled_from([(_L,), (_R,), (_L, _L), (_R, _R), ("left", "right"), ("", "")])))
        angles = angles[: len(names)]
    else:  # lengths differ
        t = stamp(t_last_ns + draw(st.integers(1, t_next_ns - t_last_ns - 1)))
        angles = draw(st.sampled_from([[], angles[:1], [*angles, 0.0]]))
    msg = JointState(name=names, position=[float(a) for a in angles])
    msg.header.stamp = t
    return Sent(topic, f"joint_states: {family}", msg)


# --- poses, odometry, twists, clocks ------------------------------------------------------------------------


@st.composite
def hostile_pose_stamped(draw, topic: str, frames: Sequence[str], t_ref_ns: int = S):
    """A PoseWithCovarianceStamped (initialpose, teleport) in one of ``frames`` or any other, of any pose."""
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = draw(st.one_of(st.sampled_from(list(frames)), frame_ids()))
    msg.header.stamp = draw(st.one_of(hostile_stamps(t_ref_ns), plausible_stamps(t_ref_ns)))
    msg.pose.pose = draw(poses())
    msg.pose.covariance = draw(covariances())
    return Sent(topic, "pose", msg)


@st.composite
def refused_pose_stamped(
    draw, topic: str, frame: str, t_ref_ns: int = S, families: Sequence[str] = POSE_FAMILIES
):
    """A pose in ``frame`` the contract refuses (bad quaternion, non-finite position), or a plausible pose in
    another frame."""
    msg = PoseWithCovarianceStamped()
    msg.header.stamp = draw(plausible_stamps(t_ref_ns))
    family = draw(st.sampled_from(families))
    plausible_position = st.builds(Point, x=st.floats(-3.0, 3.0), y=st.floats(-3.0, 3.0))
    msg.header.frame_id = frame
    if family == "bad quaternion":
        msg.pose.pose = draw(st.builds(Pose, position=plausible_position, orientation=bad_quaternions()))
    elif family == "non-finite position":
        bad = st.sampled_from([math.nan, math.inf, -math.inf])
        msg.pose.pose.position = draw(
            st.one_of(
                st.builds(Point, x=bad, y=st.floats(-3, 3)), st.builds(Point, x=st.floats(-3, 3), y=bad)
            )
        )
        msg.pose.pose.orientation = quaternion_from_yaw(draw(st.floats(-3.0, 3.0)))
    else:
        msg.header.frame_id = draw(other_frame_ids(frame))
        msg.pose.pose.position = draw(plausible_position)
        msg.pose.pose.orientation = quaternion_from_yaw(draw(st.floats(-3.0, 3.0)))
    return Sent(topic, f"{topic}: {family}", msg)


@st.composite
def hostile_odometry(draw, t_ref_ns: int, topic: str = "odom"):
    """nav_msgs/Odometry (slam's odom input) of any frames, pose, covariance and twist."""
    msg = Odometry()
    msg.header.frame_id = draw(st.one_of(st.just("odom"), frame_ids()))
    msg.child_frame_id = draw(st.one_of(st.just("base_footprint"), frame_ids()))
    msg.header.stamp = draw(st.one_of(hostile_stamps(t_ref_ns), plausible_stamps(t_ref_ns)))
    msg.pose.pose = draw(poses())
    msg.pose.covariance = draw(covariances())
    msg.twist.twist = draw(st.builds(Twist, linear=vectors(), angular=vectors()))
    msg.twist.covariance = draw(covariances())
    return Sent(topic, "odom", msg)


@st.composite
def refused_odometry(draw, t_ref_ns: int, topic: str = "odom", families: Sequence[str] = POSE_FAMILIES):
    """An odom the contract refuses: a bad quaternion or a non-finite position in the right frames, or other
    frames."""
    pose_msg = draw(refused_pose_stamped(topic, "odom", t_ref_ns, families)).msg
    msg = Odometry(child_frame_id="base_footprint")
    msg.header = pose_msg.header
    msg.pose.pose = pose_msg.pose.pose
    if msg.header.frame_id != "odom" and draw(st.booleans()):
        msg.header.frame_id, msg.child_frame_id = (
            "odom",
            draw(other_frame_ids("base_footprint")),
        )
    return Sent(topic, "odom: refused", msg)


def hostile_twists(topic: str = "cmd_vel") -> st.SearchStrategy[Sent]:
    return st.builds(Twist, linear=vectors(), angular=vectors()).map(lambda msg: Sent(topic, "cmd_vel", msg))


def hostile_clocks(t_ref_ns: int) -> st.SearchStrategy[Sent]:
    return st.builds(Clock, clock=hostile_stamps(t_ref_ns)).map(lambda msg: Sent("/clock", "clock", msg))


# --- scans --------------------------------------------------------------------------------------------------

SCAN_SIZES = (0, 1, 2, 3, 10, 359, 360, 361, 720, 1000, 100_000)
SCAN_FILLS = ("elements", "cylinder", "constant", "noise", "alternate")


@st.composite
def hostile_scans(draw, t_ref_ns: int = S, topic: str = "scan"):
    """LaserScans whose layouts disagree with their ranges (or not), of any ranges, sizes up to 100,000."""
    n = draw(st.one_of(st.sampled_from(SCAN_SIZES), st.integers(0, 400)))
    fill = draw(st.sampled_from(SCAN_FILLS))
    if fill == "elements" and n <= 400:
        ranges = np.array(
            draw(st.lists(st.one_of(float32s(), st.floats(0.0, 4.0, width=32)), min_size=n, max_size=n))
        )
    elif fill == "cylinder":
        ranges = np.resize(np.array(cylinder_scan_ranges()), n)
    elif fill == "noise":
        ranges = np.random.default_rng(draw(st.integers(0, 2**32 - 1))).uniform(-1.0, 5.0, n)
    elif fill == "alternate":
        ranges = np.resize(np.array([draw(float32s()), 1.0, draw(float32s())]), n)
    else:
        ranges = np.full(n, draw(float32s()))
    layout = draw(st.sampled_from(["lds01", "consistent", "free"]))
    if layout == "lds01":
        angle_min, increment = LDS01.angle_min, LDS01.angle_increment
        angle_max = angle_min + (LDS01.samples - 1) * increment
    elif layout == "consistent":
        angle_min = draw(st.floats(-3.0, 3.0, width=32))
        increment = draw(st.one_of(st.floats(2**-20, 1.0, width=32), st.floats(-1.0, -(2**-20), width=32)))
        angle_max = angle_min + max(n - 1, 0) * increment
    else:
        angle_min, angle_max, increment = draw(float32s()), draw(float32s()), draw(float32s())
    limits = draw(
        st.one_of(
            st.just((LDS01.range_min, LDS01.range_max)),
            st.tuples(float32s(), float32s()),
            st.floats(0.0, 10.0, width=32).map(lambda r: (r, r)),  # range_min == range_max
            st.just((3.5, 0.12)),
        )
    )
    intensities = draw(st.sampled_from([0, n, n + 1, max(n - 1, 0)]))
    msg = scan_message(
        0,
        ranges,
        frame_id=draw(st.one_of(st.just("base_scan"), frame_ids())),
        angle_min=_float32(angle_min),
        angle_max=_float32(angle_max),
        angle_increment=_float32(increment),
        range_min=_float32(limits[0]),
        range_max=_float32(limits[1]),
        time_increment=draw(float32s()),
        scan_time=draw(float32s()),
    )
    msg.intensities = float32_array(np.full(intensities, draw(float32s())))
    msg.header.stamp = draw(st.one_of(hostile_stamps(t_ref_ns), plausible_stamps(t_ref_ns)))
    return Sent(topic, f"scan: {layout} layout, {fill} x {n}", msg)


SCAN_LAYOUT_FAMILIES = (
    "no ranges",
    "zero increment",
    "non-finite layout",
    "ranges disagree with the angles",
    "angle_max disagrees",
    "range_min >= range_max",
    "NaN range limit",
)


@st.composite
def refused_scans(draw, t_ns: int, topic: str = "scan", families: Sequence[str] = SCAN_LAYOUT_FAMILIES):
    """A LaserScan (of the cylinder scan's plausible ranges) whose layout the contract refuses: no ranges, a
    zero or non-finite angle, a number of ranges or an angle_max far (60 beams and more) from what angle_min
    and angle_increment give (one beam off is the real LDS-01 driver's angle_max = 2 pi), range_min >=
    range_max, a NaN range limit."""
    family = draw(st.sampled_from(families))
    ranges = np.array(cylinder_scan_ranges())
    layout: dict[str, float] = {}
    if family == "no ranges":
        ranges = ranges[:0]
    elif family == "zero increment":
        layout = {"angle_increment": draw(st.sampled_from([0.0, -0.0])), "angle_max": LDS01.angle_min}
    elif family == "non-finite layout":
        name = draw(st.sampled_from(["angle_min", "angle_max", "angle_increment"]))
        layout = {name: draw(st.sampled_from([math.nan, math.inf, -math.inf]))}
    elif family == "ranges disagree with the angles":
        ranges = np.resize(ranges, draw(st.sampled_from([1, 2, 90, 180, 300, 420, 720, 1000])))
    elif family == "angle_max disagrees":
        layout = {"angle_max": _float32(draw(st.sampled_from([-1.0, 0.5, math.pi, 10.0, 1e6])))}
    elif family == "range_min >= range_max":
        range_min, range_max = draw(st.sampled_from([(3.5, 0.12), (1.0, 1.0), (0.12, 0.0)]))
        layout = {"range_min": range_min, "range_max": range_max}
    else:
        name = draw(st.sampled_from(["range_min", "range_max"]))
        layout = {name: math.nan}
    return Sent(topic, f"scan: {family}", scan_message(t_ns, ranges, **layout))


def _float32(value: float) -> float:
    """The float32 nearest ``value`` (a LaserScan field refuses doubles beyond float32's range)."""
    with np.errstate(over="ignore"):
        return float(np.float32(value))


# --- observations -------------------------------------------------------------------------------------------

# a few sizes (many markers: the layouts are cheap to refuse or to handle, see the module docstring)
MARKER_COUNTS = (0, 1, 2, 3, 5, 8, 20, 100, 101, 150)
MANY_MARKER_COUNTS = (101, 1_000, 10_000)
NEAR_SENSOR_M = (0.0, 5e-324, 1e-300, 1e-9, 1e-6, 0.01, 0.05, CONTRACT.min_range_m - 0.001)


def near_sensor(frame_id: str, distance_m: float, bearing_rad: float) -> tuple[float, float]:
    """A point ``distance_m`` from the LiDAR at ``bearing_rad``, in ``frame_id`` (base_scan, else the
    body)."""
    x, y = distance_m * math.cos(bearing_rad), distance_m * math.sin(bearing_rad)
    if frame_id == "base_scan":
        return x, y
    p = T_BODY_SENSOR @ np.array([x, y])
    return float(p[0]), float(p[1])


@st.composite
def marker_positions(draw, frame_id: str):
    kind = draw(st.sampled_from(["plausible", "near the sensor", "any"]))
    if kind == "plausible":
        return draw(st.floats(-3.5, 3.5)), draw(st.floats(-3.5, 3.5))
    if kind == "near the sensor":
        return near_sensor(frame_id, draw(st.sampled_from(NEAR_SENSOR_M)), draw(st.floats(-math.pi, math.pi)))
    return draw(coordinates()), draw(coordinates())


@functools.cache
def many_markers(count: int, layout: str, frame_id: str, stamp_sn: tuple[int, int] = (0, 0)) -> MarkerArray:
    """A large array, built once per (count, layout, frame, stamp): ids distinct, positions out of range, at
    one spot (one object seen ``count`` times), 1 nm from the sensor, or NaN; or all with one id."""
    header_stamp = Time(sec=stamp_sn[0], nanosec=stamp_sn[1])
    markers = []
    for k in range(count):
        if layout == "out of range":
            angle = 2 * math.pi * k / count
            x, y, marker_id = 50.0 * math.cos(angle), 50.0 * math.sin(angle), k
        elif layout == "one spot":
            (x, y), marker_id = (1.0, 0.5), 0
        elif layout == "1 nm from the sensor":
            (x, y), marker_id = near_sensor(frame_id, 1e-9, 0.3), 0
        elif layout == "one id":
            x, y, marker_id = 1.0 + 1e-3 * k, 0.5, 7
        else:  # NaN
            x, y, marker_id = math.nan, 0.5, k
        markers.append(cylinder_marker(frame_id, header_stamp, marker_id, x, y))
    return MarkerArray(markers=markers)


@st.composite
def hostile_marker_arrays(draw, frames: Sequence[str], t_ref_ns: int, topic: str):
    """Observation arrays (landmarks, fake_sensor) in one of ``frames`` or not, of any size up to 10,000,
    ids, actions, stamps and positions (also 1 nm from the sensor)."""
    frame_id = draw(st.one_of(st.sampled_from(list(frames)), frame_ids()))
    header_stamp = draw(
        st.one_of(st.just(stamp(t_ref_ns)), plausible_stamps(t_ref_ns), hostile_stamps(t_ref_ns))
    )
    if draw(st.integers(0, 9)) == 0:
        # few stamps, so that the cache builds each large array once
        header_stamp = draw(st.sampled_from([stamp(t_ref_ns), stamp(t_ref_ns + 2 * S), Time(sec=-1)]))
        count = draw(st.sampled_from(MANY_MARKER_COUNTS))
        layout = draw(st.sampled_from(["out of range", "one spot", "1 nm from the sensor", "one id", "NaN"]))
        if layout == "one spot" and topic == "fake_sensor":
            layout = "one id"  # distinct ids at one spot: known association would map them all
        msg = many_markers(count, layout, frame_id, stamp_key(header_stamp))
        return Sent(topic, f"{topic}: {count} markers, {layout}", msg)
    count = draw(st.sampled_from(MARKER_COUNTS))
    ids = st.one_of(st.integers(0, 20), st.sampled_from([-1, INT32_MIN, INT32_MAX]))
    markers = []
    if count > 8:  # distinct ids at distinct plausible places (bounded: 150 landmarks at most)
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        for k, (x, y) in enumerate(rng.uniform(-3.0, 3.0, (count, 2))):
            markers.append(cylinder_marker(frame_id, header_stamp, k, float(x), float(y)))
    else:
        for _ in range(count):
            x, y = draw(marker_positions(frame_id))
            marker = cylinder_marker(frame_id, header_stamp, draw(ids), x, y)
            marker.action = draw(
                st.sampled_from([Marker.ADD, Marker.ADD, Marker.DELETE, Marker.DELETEALL, 1, 99, -1])
            )
            marker.type = draw(st.sampled_from([Marker.CYLINDER, Marker.SPHERE, Marker.POINTS, -5]))
            marker.pose.orientation = draw(st.one_of(st.just(marker.pose.orientation), quaternions()))
            if draw(st.integers(0, 5)) == 0:
                marker.header.frame_id = draw(frame_ids())
            if draw(st.integers(0, 5)) == 0:
                marker.header.stamp = draw(hostile_stamps(t_ref_ns))
            markers.append(marker)
    if draw(st.booleans()):
        delete_all = Marker(action=Marker.DELETEALL)
        delete_all.header.frame_id, delete_all.header.stamp = frame_id, header_stamp
        markers.insert(0, delete_all)
    return Sent(topic, f"{topic}: {len(markers)} markers", MarkerArray(markers=markers))


@st.composite
def refused_marker_arrays(
    draw,
    t_newest_ns: int,
    T_world_frame: Transform2D,
    frame_id: str,
    landmarks: dict[int, tuple[float, float]],
    mapped: bool,
    known: bool,
    topic: str,
    families: Sequence[str] = OBSERVATION_FAMILIES,
):
    """An observation array the contract refuses, drawn while the newest joint_states is stamped
    ``t_newest_ns`` and the observing frame ``frame_id`` (sensor or body) is at ``T_world_frame`` among the
    ``landmarks`` (``mapped`` by now): every observation nearer than 0.12 m; more than 100 observations;
    stamped more than 1 s after the newest joint_states; stale (before the filter's time, which is at most
    max_observation_delay = 0.25 s behind the newest joint_states); non-finite; in an unknown frame; frames
    or stamps that differ; repeated ids; empty; and for known association (once mapped) every observation
    far outside the innovation gate of its landmark."""
    if not (known and mapped):
        families = [family for family in families if family != "outside the gate"]
    family = draw(st.sampled_from(families))
    seen = relative(T_world_frame, landmarks)  # what the sensor sees now: plausible observations
    t_ns = t_newest_ns
    points = seen
    frame = frame_id
    if family == "too near":
        count = draw(st.integers(1, 3))
        ids = [i for i, _, _ in seen][:count] if known else list(range(count))
        points = [
            (
                i,
                *near_sensor(
                    frame_id, draw(st.sampled_from(NEAR_SENSOR_M[1:])), draw(st.floats(-3.14, 3.14))
                ),
            )
            for i in ids
        ]
    elif family == "too many":
        count = draw(st.sampled_from([CONTRACT.max_observations + 1, 120, 150]))
        jitter = np.random.default_rng(draw(st.integers(0, 2**32 - 1))).normal(0.0, 0.01, (count, 2))
        # the landmarks as seen now (their ids first, then new ones) a centimetre off: harmful if applied
        points = []
        for k in range(count):
            seen_id, x, y = seen[k % len(seen)]
            points.append((seen_id if k < len(seen) else 1000 + k, x + jitter[k, 0], y + jitter[k, 1]))
    elif family == "too far ahead":
        # mostly within the clean stream's 4 s (where a queued one would be applied), sometimes far
        near, far = st.integers(1_000, 3 * S // 2), st.integers(3 * S, 10**6 * S)
        t_ns = t_newest_ns + CONTRACT.max_observation_lead_ns + draw(st.one_of(near, near, far))
    elif family == "stale":
        t_ns = t_newest_ns - S // 4 - draw(st.integers(1_000, 10 * S))
    elif family == "non-finite":
        k = draw(st.integers(0, len(seen) - 1))
        bad = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
        points = [(i, bad if j == k else x, y) for j, (i, x, y) in enumerate(seen)]
    elif family == "unknown frame":
        frame = draw(st.sampled_from(["odom", "map", "base_link", "", "nusim/world", " base_scan"]))
    elif family == "outside the gate":
        offset = draw(st.floats(1.0, 3.0))
        angle = draw(st.floats(-math.pi, math.pi))
        points = [(i, x + offset * math.cos(angle), y + offset * math.sin(angle)) for i, x, y in seen]
    elif family == "repeated ids":
        points = [(seen[0][0], x, y) for _, x, y in seen]
    if family == "empty":
        msg = MarkerArray()
    else:
        msg = cylinder_array(frame, t_ns, points)
    if family == "frames differ":
        msg.markers[draw(st.integers(1, len(msg.markers) - 1))].header.frame_id = "base_link"
    elif family == "stamps differ":
        msg.markers[draw(st.integers(1, len(msg.markers) - 1))].header.stamp = stamp(
            t_ns - draw(st.integers(1, S))
        )
    return Sent(topic, f"{topic}: {family}", msg)
