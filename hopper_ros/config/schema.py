"""Typed, validated configuration: the one mechanism of the package (issue 17). No ROS import.

A schema is built from a few dataclasses (`Number`, `Text`, `Flag`, `Items`, `Section`,
`Anything`) and checked by one validator, `validate(schema, data, source)`: types, required
keys, ranges with their units, choices, unknown keys refused, and checks across keys. It returns
the data with every value converted to its type (int, float, str, bool, list, dict) and defaults
filled in, or raises `ConfigError`, whose message is one line naming the file, the key and what
is wrong, e.g.

    config/control.yaml: deadbeat.max_torque: must be > 0 N m, got -12

The schemas of the package's files are in `hopper_ros/config/schemas.py`; `load_config(name,
schema)` reads a file (config/ name or path, `base:` variants merged) and validates it.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

_REQUIRED = object()


class ConfigError(ValueError):
    """A configuration file that cannot be used; one line: file, key, what is wrong."""


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _unit(unit: str) -> str:
    return f" {unit}" if unit else ""


@dataclass(frozen=True, kw_only=True)
class _Spec:
    """What every kind of value has: its default (required when none) and a description."""

    default: Any = _REQUIRED
    doc: str = ""


@dataclass(frozen=True)
class Number(_Spec):
    """A finite number (an int where `integer`), in `unit`, within the bounds given."""

    unit: str = ""
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    integer: bool = False
    choices: tuple = ()

    def check(self, value: Any, where: str) -> Any:
        kind = "an integer" if self.integer else "a number"
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: must be {kind}{self._range()}, got {_show(value)}")
        if not math.isfinite(value):
            raise ConfigError(f"{where}: must be finite, got {value}")
        if self.integer:
            if int(value) != value:
                raise ConfigError(f"{where}: must be an integer{self._range()}, got {value}")
            value = int(value)
        else:
            value = float(value)
        if self.choices and value not in self.choices:
            raise ConfigError(f"{where}: must be one of {list(self.choices)}, got {_show(value)}")
        for bound, ok, sign in ((self.gt, lambda v, b: v > b, ">"), (self.ge, lambda v, b: v >= b, ">="),
                                (self.lt, lambda v, b: v < b, "<"), (self.le, lambda v, b: v <= b, "<=")):
            if bound is not None and not ok(value, bound):
                raise ConfigError(f"{where}: must be {sign} {bound:g}{_unit(self.unit)}, got {value:g}")
        return value

    def _range(self) -> str:
        parts = []
        for bound, sign in ((self.gt, ">"), (self.ge, ">="), (self.lt, "<"), (self.le, "<=")):
            if bound is not None:
                parts.append(f"{sign} {bound:g}")
        text = " and ".join(parts)
        return f" ({text}{_unit(self.unit)})" if text else (f" [{self.unit}]" if self.unit else "")


@dataclass(frozen=True)
class Text(_Spec):
    """A non-empty string, one of `choices` when given."""

    choices: tuple = ()

    def check(self, value: Any, where: str) -> str:
        if not isinstance(value, str) or not value:
            expected = f"one of {list(self.choices)}" if self.choices else "a non-empty string"
            raise ConfigError(f"{where}: must be {expected}, got {_show(value)}")
        if self.choices and value not in self.choices:
            raise ConfigError(f"{where}: must be one of {list(self.choices)}, got {_show(value)}")
        return value


@dataclass(frozen=True)
class Flag(_Spec):
    """true or false."""

    def check(self, value: Any, where: str) -> bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: must be true or false, got {_show(value)}")
        return value


@dataclass(frozen=True)
class Items(_Spec):
    """A list of `item`, with `min_items` .. `max_items` entries, optionally all different."""

    item: Any
    min_items: int = 0
    max_items: int | None = None
    unique: bool = False

    def check(self, value: Any, where: str) -> list:
        if not isinstance(value, list):
            raise ConfigError(f"{where}: must be a list, got {_show(value)}")
        if len(value) < self.min_items or (self.max_items is not None and len(value) > self.max_items):
            count = (f"{self.min_items}" if self.max_items == self.min_items else
                     f"{self.min_items} to {self.max_items}" if self.max_items is not None else f"at least {self.min_items}")
            raise ConfigError(f"{where}: must hold {count} entries, got {len(value)}")
        out = [_check(self.item, entry, f"{where}[{index}]") for index, entry in enumerate(value)]
        if self.unique and len(set(map(repr, out))) != len(out):
            raise ConfigError(f"{where}: names an entry twice: {_show(value)}")
        return out


@dataclass(frozen=True)
class Anything(_Spec):
    """Passed through unchecked (a part another module validates, e.g. sim.effects)."""

    def check(self, value: Any, where: str) -> Any:
        return value


#: a check across keys: (section values) -> None, or (key, problem) naming what is wrong
Check = Callable[[dict], "tuple[str, str] | None"]


@dataclass(frozen=True)
class Section(_Spec):
    """A mapping with exactly these keys (`fields`); missing required keys and unknown keys are
    errors. `values`: instead of fixed keys, any key (its name checked by `keys`) with values of
    this schema. `checks` run on the converted values."""

    fields: Mapping[str, Any] = field(default_factory=dict)
    values: Any = None
    keys: tuple = ()
    checks: tuple = ()

    def check(self, value: Any, where: str) -> dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where or 'the file'}: must be a mapping of keys, got {_show(value)}")
        prefix = f"{where}." if where else ""
        out: dict = {}
        if self.values is not None:
            for key, entry in value.items():
                if self.keys and key not in self.keys:
                    raise ConfigError(f"{prefix}{key}: unknown key; known: {', '.join(self.keys)}")
                out[key] = _check(self.values, entry, f"{prefix}{key}")
        else:
            unknown = [key for key in value if key not in self.fields]
            if unknown:
                raise ConfigError(f"{prefix}{unknown[0]}: unknown key; known here: {', '.join(self.fields)}")
            for key, spec in self.fields.items():
                if key in value:
                    out[key] = _check(spec, value[key], f"{prefix}{key}")
                elif spec.default is _REQUIRED:
                    raise ConfigError(f"{prefix}{key}: missing (required{_describe(spec)})")
                elif spec.default is not None:
                    out[key] = spec.default
        for check in self.checks:
            problem = check(out)
            if problem is not None:
                key, text = problem
                raise ConfigError(f"{prefix}{key}: {text}")
        return out


def _describe(spec: Any) -> str:
    if isinstance(spec, Number):
        return f": {'an integer' if spec.integer else 'a number'}{spec._range()}"
    if isinstance(spec, Section):
        return ": a mapping"
    if isinstance(spec, Items):
        return ": a list"
    if isinstance(spec, Flag):
        return ": true or false"
    if isinstance(spec, Text) and spec.choices:
        return f": one of {list(spec.choices)}"
    return ""


def _check(spec: Any, value: Any, where: str) -> Any:
    return spec.check(value, where)


def validate(schema: Section, data: Any, source: str) -> dict:
    """`data` checked and converted by `schema`; ConfigError "SOURCE: key.path: problem" otherwise."""
    try:
        return schema.check(data, "")
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def load_config(name: str | os.PathLike, schema: Section) -> dict:
    """Read a config file (config/ name or path; `base:` variants merged) and validate it."""
    from hopper_ros.config.files import config_path, load_yaml

    path = config_path(name)                  # FileNotFoundError naming the file
    try:
        data = load_yaml(path)
    except (ValueError, OSError) as exc:
        message = " ".join(str(exc).split())
        raise ConfigError(message if str(path) in message else f"{path}: {message}") from None
    if data is None:
        raise ConfigError(f"{path}: the file is empty")
    return validate(schema, data, str(path))


# ------------------------------------------------------------------ checks used by several schemas

def ordered(low: str, high: str, strict: bool = True) -> Check:
    """`low` below `high` (both present)."""
    def check(values: dict):
        if low in values and high in values:
            a, b = values[low], values[high]
            if (a >= b) if strict else (a > b):
                return high, f"must be {'above' if strict else 'at least'} {low} ({a:g}), got {b:g}"
        return None
    return check


def within(key: str, low: str, high: str) -> Check:
    """`key` inside [low, high] (all present)."""
    def check(values: dict):
        if all(k in values for k in (key, low, high)) and not values[low] <= values[key] <= values[high]:
            return key, f"must lie in [{low}, {high}] = [{values[low]:g}, {values[high]:g}], got {values[key]:g}"
        return None
    return check
