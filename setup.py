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


def _runtime_pins():
    """The direct runtime dependencies pinned in requirements/python.txt (its `--- direct` section, the
    build backend setuptools aside): what `pip install .` installs. ROS 2 itself (rclpy, the message
    packages) comes from the ROS install or requirements/ros.txt, not from here."""
    pins, direct = [], False
    for line in (HERE / "requirements" / "python.txt").read_text(encoding="utf-8").splitlines():
        text = line.split("#", 1)[0].strip()
        if line.startswith("# ---"):
            direct = "direct" in line
        elif direct and text and not text.lower().startswith("setuptools"):
            pins.append(text)
    return pins


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
    install_requires=_runtime_pins(),
    entry_points={
        "console_scripts": ["hopper = hopper_ros.cli:main"]
        + [f"{name} = {target}" for name, target in sorted(_nodes().items())],
    },
    zip_safe=False,
)
