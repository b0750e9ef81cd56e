"""turtlelib: pure numpy SE(2) geometry, diff-drive kinematics, LiDAR landmark detection, EKF SLAM and
occupancy grid mapping.

No ROS import, ever: the ROS nodes in nusim, nuturtle_control and nuslam are thin wrappers over this.
"""

from .estimation.consistency import chi2_bounds, nees, nis
from .estimation.ekf_slam import MODES, Association, EkfSlam, ObservationStatus, SlamConfig
from .estimation.lidar_odometry import LidarOdometry, LidarOdometryConfig
from .estimation.scan_steps import FilterUpdate, Outcome, PoseListener, ScanStep, StepResult
from .estimation.slam_timeline import ScanResult, SlamTimeline, TimelineConfig
from .geometry.se2 import Transform2D, Twist2D, integrate_twist, normalize_angle, normalize_angles
from .mapping.grid_map_file import load_grid_map, save_grid_map
from .mapping.landmark_map import LandmarkMap, load_map, save_map
from .mapping.occupancy_grid import (
    GridConfig,
    GridMap,
    KeyframeConfig,
    OccupancyGrid,
    ScanKeyframes,
)
from .motion.kinematics import DiffDrive
from .motion.motion_models import (
    AckermannMotion,
    DiffDriveMotion,
    MeasuredMotion,
    MotionModel,
    OdometryMotion,
    TwistNoise,
    UnicycleMotion,
)
from .motion.motion_signals import HeldInputs, MeasuredPoses, MotionSignal, OdometryPoses, WheelAngles
from .motion.sample_gate import GateResult, SampleGate, SampleGateConfig, Verdict
from .sensing.circle_fit import Circle, CircleFits, fit_circle, fit_circles, refine_for_range_sensor
from .sensing.detection import (
    Clusters,
    Detections,
    DetectorConfig,
    LandmarkDetector,
    beams_in_one_turn,
    cluster_scan,
)
from .sensing.range_scan import RangeScan, check_scan_layout
from .sensing.scan_model import LidarConfig, arena_walls, cast_beams, polygon_walls, simulate_scan
from .sensing.scan_registration import RegistrationConfig

__all__ = [
    "Circle",
    "CircleFits",
    "Clusters",
    "DetectorConfig",
    "Detections",
    "LandmarkDetector",
    "LidarConfig",
    "arena_walls",
    "cast_beams",
    "polygon_walls",
    "beams_in_one_turn",
    "check_scan_layout",
    "cluster_scan",
    "fit_circle",
    "fit_circles",
    "refine_for_range_sensor",
    "simulate_scan",
    "DiffDrive",
    "AckermannMotion",
    "DiffDriveMotion",
    "MeasuredMotion",
    "MotionModel",
    "OdometryMotion",
    "TwistNoise",
    "UnicycleMotion",
    "HeldInputs",
    "MeasuredPoses",
    "MotionSignal",
    "OdometryPoses",
    "WheelAngles",
    "Transform2D",
    "Twist2D",
    "integrate_twist",
    "normalize_angle",
    "normalize_angles",
    "MODES",
    "Association",
    "EkfSlam",
    "LidarOdometry",
    "LidarOdometryConfig",
    "RegistrationConfig",
    "ObservationStatus",
    "SlamConfig",
    "GridConfig",
    "GridMap",
    "KeyframeConfig",
    "OccupancyGrid",
    "RangeScan",
    "ScanKeyframes",
    "load_grid_map",
    "save_grid_map",
    "LandmarkMap",
    "load_map",
    "save_map",
    "SlamTimeline",
    "TimelineConfig",
    "ScanResult",
    "ScanStep",
    "StepResult",
    "Outcome",
    "FilterUpdate",
    "PoseListener",
    "GateResult",
    "SampleGate",
    "SampleGateConfig",
    "Verdict",
    "chi2_bounds",
    "nees",
    "nis",
]
