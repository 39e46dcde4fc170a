"""Configuration: where the YAML files live and how they are read and checked. No ROS import.

- `files`    where config/ and launch/ are (a checkout or share/hopper_ros), `load_yaml` (with `base:`)
- `schema`   typed configuration on pydantic v2: `Section` (the models' base), `unit`, `choice`, `Problem`,
             `validate`, `load_config`, `ConfigError` (pydantic's errors as one line: file, key, problem)
- `schemas`  one pydantic model per config file (CONTROL, HARDWARE, SIM, ...) and `load_model`

What `hopper_ros.config` (a module until issue 30) exported is re-exported here.
"""

from .files import config_dir, config_path, launch_dir, load_yaml, package_share_dir

__all__ = ["config_dir", "config_path", "launch_dir", "load_yaml", "package_share_dir"]
