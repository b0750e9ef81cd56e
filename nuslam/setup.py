"""ament_python build of the nuslam package (colcon); pip installs use the root pyproject.toml."""

from glob import glob

from setuptools import find_packages, setup

package_name = "nuslam"


def share(folder: str) -> tuple[str, list[str]]:
    return (f"share/{package_name}/{folder}", glob(f"{folder}/*"))


setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["py.typed"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{package_name}"]),
        (f"share/{package_name}", ["package.xml"]),
    ]
    + [share(folder) for folder in ("config", "launch", "rviz", "urdf") if glob(f"{folder}/*")],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="nuturtle team",
    maintainer_email="team@nuturtle.dev",
    description="LiDAR landmark detection and EKF SLAM (known and unknown data association) nodes.",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "landmarks = nuslam.landmarks_node:main",
            "slam = nuslam.slam_node:main",
            "robot_side = nuslam.robot_side:main",
            "slam_side = nuslam.slam_side:main",
            "slam_managed = nuslam.managed_nodes:slam_main",
            "landmarks_managed = nuslam.managed_nodes:landmarks_main",
        ],
    },
)
