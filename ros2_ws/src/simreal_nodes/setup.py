"""ament_python package for users with a full ROS 2 Jazzy install (colcon build in ros2_ws/).

The Python package is the repository's simreal_nodes (symlinked here); `ros2 run simreal_nodes
<node>` and `ros2 launch simreal_nodes simreal.launch.py scene:=...` work after sourcing.
Install the pinned Python dependencies first: pip install -r ../../../requirements.txt
"""

import tomllib
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = "simreal_nodes"
# The executables are declared once, in the repository's pyproject.toml: `simreal` and `simreal-NAME` per node.
# ROS executables are named after the node (`ros2 run simreal_nodes ingest`, as simreal.launch.py starts them).
with open(Path(__file__).resolve().parents[3] / "pyproject.toml", "rb") as f:
    SCRIPTS = tomllib.load(f)["project"]["scripts"]
NODE_PREFIX = "simreal-"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["simreal_nodes", "simreal_nodes.*"]),
    package_data={"simreal_nodes": ["ros/*.xml", "specs/*.yaml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="simreal developers",
    maintainer_email="simreal@example.org",
    description="simreal nodes",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [f"{name.removeprefix(NODE_PREFIX)} = {target}" for name, target in SCRIPTS.items()],
    },
)
