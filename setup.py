"""Python packaging of hopper_ros for the venv path (`make setup` runs `pip install -e .`).

The messages are not built here: `make setup` generates them with rosidl through CMake
(CMakeLists.txt, HOPPER_VENV_BUILD=ON). On a ROS 2 machine colcon builds the package with
ament_cmake and does not use this file.
"""
import re
from pathlib import Path

from setuptools import find_packages, setup

HERE = Path(__file__).resolve().parent


def _version():
    text = (HERE / "package.xml").read_text(encoding="utf-8")
    return re.search(r"<version>\s*([^<\s]+)\s*</version>", text).group(1)


def _nodes():
    """NODES of hopper_ros/nodes/registry.py, read without importing the package."""
    path = HERE / "hopper_ros" / "nodes" / "registry.py"
    namespace = {}
    exec(compile(path.read_text(encoding="utf-8"), str(path), "exec"), namespace)
    return dict(namespace["NODES"])


setup(
    name="hopper_ros",
    version=_version(),
    description="ROS 2 stack for a one-legged hopping robot",
    license="MIT",
    python_requires=">=3.10",
    packages=find_packages(include=["hopper_ros", "hopper_ros.*"]),
    # Python dependencies are pinned in requirements/*.txt and installed by make setup.
    install_requires=[],
    entry_points={
        "console_scripts": ["hopper = hopper_ros.cli:main"]
        + [f"{name} = {target}" for name, target in sorted(_nodes().items())],
    },
    zip_safe=False,
)
