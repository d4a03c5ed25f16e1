"""ament_python package definition of semiparam_ros."""

from glob import glob

from setuptools import find_packages, setup

package_name = "semiparam_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "bench"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="semiparam_ros developers",
    maintainer_email="semiparam-ros@example.com",
    description=(
        "Online semiparametric inverse dynamics learning (rigid-body RRLS + random-feature residual) "
        "for ROS 2 Jazzy."
    ),
    license="BSD-3-Clause",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "estimator = semiparam_ros.ros.main:main",
            "simulate = semiparam_ros.cli.simulate:main",
            "evaluate = semiparam_ros.cli.evaluate:main",
            "learn = semiparam_ros.cli.learn:main",
            "learn-fleet = semiparam_ros.cli.learn_fleet:main",
            "export_urdf = semiparam_ros.cli.export_urdf:main",
            "excite = semiparam_ros.cli.excite:main",
            "tune = semiparam_ros.cli.tune:main",
            "real_robots = semiparam_ros.cli.real_robots:main",
        ],
    },
)
