"""Where the configuration lives and how it is read. No ROS import.

Parameters live in `config/*.yaml` and launch files in `launch/` (repository checkout) or, after
`colcon build`, in `share/hopper_ros/config` and `share/hopper_ros/launch` of the install prefix.
`HOPPER_CONFIG_DIR` overrides the config directory.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

_PACKAGE = "hopper_ros"


def package_share_dir() -> Path:
    """The folder holding config/ and launch/: the repository checkout, or after `colcon build`
    the install prefix's share/hopper_ros (what `$(find-pkg-share hopper_ros)` gives)."""
    source_tree = Path(__file__).resolve().parents[2]
    if (source_tree / "config").is_dir():
        return source_tree
    try:  # installed with colcon: share/hopper_ros
        from ament_index_python.packages import get_package_share_directory
    except ImportError as exc:  # pragma: no cover - only without a checkout and without ament
        raise FileNotFoundError("cannot find the hopper_ros share directory; set HOPPER_CONFIG_DIR") from exc
    return Path(get_package_share_directory(_PACKAGE))


def config_dir() -> Path:
    """The directory holding the project's YAML configuration."""
    override = os.environ.get("HOPPER_CONFIG_DIR")
    if override:
        return Path(override)
    return package_share_dir() / "config"


def launch_dir() -> Path:
    """The directory of the launch files (launch/*.launch.yaml; CMake installs them to
    share/hopper_ros/launch)."""
    return package_share_dir() / "launch"


def config_path(name: str | os.PathLike) -> Path:
    """Resolve a config file: an existing path as given, else relative to `config_dir()`."""
    path = Path(name)
    if path.exists():
        return path
    candidate = config_dir() / path
    if candidate.exists():
        return candidate
    raise FileNotFoundError(f"config file {str(name)!r} not found (looked in {config_dir()})")


def load_yaml(name: str | os.PathLike) -> Any:
    """Read one YAML config file, with the file named in any error.

    A mapping with a top-level `base: OTHER.yaml` is that file with this one's keys merged over
    it (mappings merged key by key), so a variant names only what it changes.
    """
    path = config_path(name)
    try:
        with open(path, encoding="utf-8") as handle:
            data = yaml.safe_load(handle)
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: not valid YAML: {exc}") from exc
    if isinstance(data, dict) and "base" in data:
        base = data.pop("base")
        data = _merge(load_yaml(base), data)
    return data


def _merge(base: Any, changes: Any) -> Any:
    if isinstance(base, dict) and isinstance(changes, dict):
        return {**base, **{key: _merge(base.get(key), value) for key, value in changes.items()}}
    return changes
