"""The process environment every hopper_ros entry point sets up before rclpy is imported.

Fast DDS's default discovery multicasts to 239.255.0.1 on every interface. The hopper stack
must stay on the machine unless a user explicitly asks for more, so every entry point (the
`hopper` CLI, each node's `main`, the launcher for its children) calls
`apply_ros_environment()` first: it sets `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` unless the
user already chose a range. A range set by the user (OFF, LOCALHOST, SUBNET, SYSTEM_DEFAULT) is
kept; a misspelt one is rejected instead of being handed to rcl. No ROS import here.
"""

from __future__ import annotations

import os
from typing import MutableMapping

DISCOVERY_RANGE_VAR = "ROS_AUTOMATIC_DISCOVERY_RANGE"
DEFAULT_DISCOVERY_RANGE = "LOCALHOST"
# The values rcl accepts (rcl/discovery_options.h); compared exactly, as rcl does.
VALID_DISCOVERY_RANGES = ("OFF", "LOCALHOST", "SUBNET", "SYSTEM_DEFAULT")


class RosEnvironmentError(ValueError):
    """The environment asks for something the stack refuses to run with."""


def discovery_range(environ: MutableMapping[str, str] | None = None) -> str | None:
    """The discovery range the environment asks for, or None when none is set."""
    env = os.environ if environ is None else environ
    value = env.get(DISCOVERY_RANGE_VAR, "")
    return value or None


def apply_ros_environment(environ: MutableMapping[str, str] | None = None, *, strict: bool = True) -> dict[str, str]:
    """Prepare `environ` (default: `os.environ`) for rclpy; returns the variables it set.

    Must run before rclpy is imported (and, in any case, before `rclpy.init`). Idempotent.
    With `strict`, an unknown discovery range raises `RosEnvironmentError`; without it, the
    value is left for a later strict call to report (used at import time, where raising would
    only give a traceback).
    """
    env = os.environ if environ is None else environ
    changed: dict[str, str] = {}
    current = discovery_range(env)
    if current is None:
        env[DISCOVERY_RANGE_VAR] = DEFAULT_DISCOVERY_RANGE
        changed[DISCOVERY_RANGE_VAR] = DEFAULT_DISCOVERY_RANGE
    elif strict and current not in VALID_DISCOVERY_RANGES:
        raise RosEnvironmentError(
            f"{DISCOVERY_RANGE_VAR}={current!r} is not a discovery range; "
            f"use one of {', '.join(VALID_DISCOVERY_RANGES)} (unset means {DEFAULT_DISCOVERY_RANGE})"
        )
    return changed
