"""ament_python build of the nuturtle_eval package (colcon); pip installs use the root pyproject.toml."""

from glob import glob

from setuptools import find_packages, setup

package_name = "nuturtle_eval"


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
    + [share(folder) for folder in ("config", "launch", "urdf") if glob(f"{folder}/*")],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="nuturtle team",
    maintainer_email="team@nuturtle.dev",
    description=(
        "The evaluation of a SLAM run (no ROS): metrics, figures, and the real-data pipeline "
        "(datasets, calibration)."
    ),
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "datasets = nuturtle_eval.datasets.__main__:main",
        ],
    },
)
