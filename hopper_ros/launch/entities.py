"""The keys of each launch file entity `hopper launch` supports, as pydantic models (extra keys
forbidden), and `check_keys`, which words an unknown key as the launch file's one line. The values
are read by hopper_ros/launch/frontend.py (substitutions, conditions). No ROS import.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError


class LaunchFileError(ValueError):
    """A launch file that cannot be used, with the file and entry named."""


class _Keys(BaseModel):
    """These keys only; any value (the frontend reads it)."""

    model_config = ConfigDict(extra="forbid")


class _Conditional(_Keys):
    if_: Any = Field(None, alias="if")
    unless: Any = None


class Arg(_Conditional):
    name: Any = None
    default: Any = None
    description: Any = None


class Let(_Conditional):
    name: Any = None
    value: Any = None


class _Named(_Conditional):
    """What a process and a composable node share."""

    pkg: Any = None
    name: Any = None
    namespace: Any = None
    param: Any = None
    remap: Any = None


class _Process(_Named):
    """What `node` and `node_container` share."""

    exec: Any = None
    env: Any = None
    ros_args: Any = None
    output: Any = None
    on_exit: Any = None
    sigterm_timeout: Any = None
    sigkill_timeout: Any = None
    respawn: Any = None
    respawn_delay: Any = None


class Node(_Process):
    args: Any = None


class NodeContainer(_Process):
    composable_node: Any = None


class ComposableNode(_Named):
    plugin: Any = None
    extra_arg: Any = None


class Param(_Keys):
    name: Any = None
    value: Any = None
    param: Any = None


class NestedParamFile(_Keys):
    from_: Any = Field(None, alias="from")


class ParamFile(NestedParamFile):
    allow_substs: Any = None


class Remap(_Keys):
    from_: Any = Field(None, alias="from")
    to: Any = None


class NameValue(_Keys):
    """An `env` or `extra_arg` entry."""

    name: Any = None
    value: Any = None


#: the entities of a launch file's list, by their key
ENTITIES = {"arg": Arg, "let": Let, "node": Node, "node_container": NodeContainer}


def check_keys(entity: dict, model: type[BaseModel], kind: str, where: str) -> None:
    """LaunchFileError naming every key of `entity` that `model` does not know, and the keys it does."""
    try:
        model.model_validate(entity)
    except ValidationError as exc:
        unknown = sorted(str(error["loc"][-1]) for error in exc.errors() if error["type"] == "extra_forbidden")
        known = sorted(field.alias or name for name, field in model.model_fields.items())
        raise LaunchFileError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))} of '{kind}' "
                              f"(hopper launch supports: {', '.join(known)})") from None
