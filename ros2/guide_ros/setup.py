"""ament_python package of the GUIDE ROS 2 node; the planner itself is the `guide` Python package
(pip install the repository with its robot extra in the same environment)."""

from glob import glob

from setuptools import setup

PACKAGE = "guide_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=[PACKAGE],
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml", "README.md"]),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="guide maintainers",
    description="GUIDE exploration on a ROS 2 robot (SLAM map in, plans and Nav2 goals out)",
    license="MIT",
    entry_points={"console_scripts": [f"explorer = {PACKAGE}.explorer:main"]},
)
