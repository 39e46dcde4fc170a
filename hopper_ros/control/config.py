"""config/control.yaml as typed settings: `load_control(name)` reads and checks the file once
(schema hopper_ros.config.schemas.CONTROL; a bad file is one ConfigError line naming the file,
the key and what is wrong) and returns `ControlConfig`. No ROS import."""

from __future__ import annotations

import os
from dataclasses import dataclass

from .deadbeat import DeadbeatSettings
from .stride_policy import StrideSettings


@dataclass(frozen=True)
class ControlConfig:
    """control.yaml: the deadbeat decision's settings and the stride policy's timing."""

    deadbeat: DeadbeatSettings
    stride: StrideSettings


def load_control(name: str | os.PathLike = "control.yaml") -> ControlConfig:
    """control.yaml (a config/ name or a path), checked and typed."""
    from hopper_ros.config import config_path
    from hopper_ros.config.schemas import CONTROL
    from hopper_ros.config.schema import load_config

    values = load_config(name, CONTROL)
    return ControlConfig(DeadbeatSettings.from_mapping(values["deadbeat"], str(config_path(name))),
                         StrideSettings.from_mapping(values["stride"]))
