"""Typed, validated configuration on pydantic v2 (issues 17, 30): the one mechanism of the package. No ROS import.

A file's schema is a pydantic model built on `Section`: unknown keys refused, strict types (a bool
or a string is not a number, NaN and inf are refused, an integer key wants an int, a text a
non-empty string), ranges as `Field(gt=..., le=...)`, the unit as field metadata (`unit("m",
gt=0)`), choices as `Literal` (`choice(...)` for numbers), checks across keys as
`model_validator(mode="after")` raising `Problem(key, text)`. `validate(schema, data, source)`
returns the data as plain dicts and lists, converted to their types, defaults filled in (a key
whose default is None is left out), or raises `ConfigError`: `config_error` words pydantic's
ValidationError as one line naming the file, the key and what is wrong, e.g.

    config/control.yaml: deadbeat.max_torque: must be > 0 N m, got -12

The schemas of the package's files are in `hopper_ros/config/schemas.py`; `load_config(name,
schema)` reads a file (config/ name or path, `base:` variants merged) and validates it.
"""

from __future__ import annotations

import os
from typing import Annotated, Any, Literal, get_args, get_origin

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, ValidationError
from pydantic.fields import FieldInfo


class ConfigError(ValueError):
    """A configuration file that cannot be used; one line: file, key, what is wrong."""


class Section(BaseModel):
    """A mapping of exactly these keys, each of its type, strictly (no bool for a number, no
    NaN or inf, no text for a number, no empty text)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, str_min_length=1,
                              defer_build=True)     # a model is built when first used: a node builds its own files only


def unit(unit: str, default: Any = ..., **constraints: Any) -> Any:
    """`Field` of a quantity in `unit` (shown with its bounds in the errors and the JSON schema)."""
    return Field(default, json_schema_extra={"unit": unit}, **constraints)


class Problem(ValueError):
    """What a check raises in a validator: the key of the section it names (None: the value checked)
    and what is wrong, in the words of the one-line error."""

    def __init__(self, key: str | None, text: str):
        super().__init__(text)
        self.key = key


def choice(*values: Any) -> Any:
    """One of these numbers (True is not 1 here)."""
    def not_a_bool(value: Any) -> Any:
        if isinstance(value, bool):
            raise Problem(None, f"must be one of {list(values)}, got {value!r}")
        return value

    return Annotated[Literal[values], BeforeValidator(not_a_bool)]


def _all_different(values: list) -> list:
    if len(set(map(repr, values))) != len(values):
        raise Problem(None, f"names an entry twice: {_show(values)}")
    return values


#: a list whose entries all differ: `Annotated[list[X], DISTINCT]`
DISTINCT = AfterValidator(_all_different)


def ordered(section: BaseModel, low: str, high: str) -> None:
    """`low` below `high` (both given)."""
    a, b = getattr(section, low), getattr(section, high)
    if a is not None and b is not None and a >= b:
        raise Problem(high, f"must be above {low} ({a:g}), got {b:g}")


def at_most(section: BaseModel, key: str, limit: str, unit: str) -> None:
    """`key` not above `limit` (both given)."""
    a, b = getattr(section, key), getattr(section, limit)
    if a is not None and b is not None and a > b:
        raise Problem(key, f"must not exceed {limit} ({b:g} {unit}), got {a:g}")


def within(section: BaseModel, key: str, low: str, high: str) -> None:
    """`key` inside [low, high]."""
    value, a, b = getattr(section, key), getattr(section, low), getattr(section, high)
    if not a <= value <= b:
        raise Problem(key, f"must lie in [{low}, {high}] = [{a:g}, {b:g}], got {value:g}")


# ------------------------------------------------------------------ validation and its one line


def validate(schema: type[BaseModel], data: Any, source: str, at: str = "") -> dict:
    """`data` checked and converted by `schema` (`at`: the key path it sits under, for the errors);
    ConfigError "SOURCE: key.path: problem" otherwise."""
    try:
        return _plain(schema.model_validate(data))
    except ValidationError as exc:
        raise config_error(exc, schema, source, at) from None


def load_config(name: str | os.PathLike, schema: type[BaseModel]) -> dict:
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


def _plain(value: Any) -> Any:
    """A validated model as plain dicts and lists; a key whose default None was left as it is: left out."""
    if isinstance(value, BaseModel):
        return {name: _plain(getattr(value, name)) for name in type(value).model_fields
                if name in value.model_fields_set or getattr(value, name) is not None}
    if isinstance(value, list):
        return [_plain(entry) for entry in value]
    if isinstance(value, dict):
        return {key: _plain(entry) for key, entry in value.items()}
    return value


def config_error(error: ValidationError, schema: type, source: str, at: str = "") -> ConfigError:
    """pydantic's ValidationError as one line, `SOURCE: key.path: what is wrong`: its first error,
    an unknown key before the others (a misspelt key is why its right spelling is missing)."""
    first = min(error.errors(), key=lambda e: e["type"] != "extra_forbidden")
    kind, loc, value, ctx = first["type"], tuple(first["loc"]), first.get("input"), first.get("ctx") or {}
    if isinstance(ctx.get("error"), Problem):
        text, loc = str(ctx["error"]), loc + ((ctx["error"].key,) if ctx["error"].key else ())
    elif loc[-1:] == ("[key]",):                       # a key outside a mapping's known keys
        text = f"unknown key; known: {', '.join(get_args(_field(schema, loc[:-2] + loc[-1:]).annotation))}"
        loc = loc[:-1]
    elif kind == "extra_forbidden":
        text = f"unknown key; known here: {', '.join(getattr(_field(schema, loc[:-1]).annotation, 'model_fields', ()))}"
    else:
        text = _phrase(kind, value, ctx, _field(schema, loc), first["msg"])
    path = ".".join(filter(None, [at, "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in loc)[1:]]))
    return ConfigError(f"{source}: {path or 'the file'}: {text}")


_BOUNDS = {"greater_than": (">", "gt"), "greater_than_equal": (">=", "ge"), "less_than": ("<", "lt"),
           "less_than_equal": ("<=", "le")}


def _phrase(kind: str, value: Any, ctx: dict, info: FieldInfo, msg: str) -> str:
    """What is wrong with the value of a field (pydantic's error `kind`), in the project's words."""
    if kind == "missing":
        expected = _expected(info, missing=True)
        return f"missing (required{': ' + expected if expected else ''})"
    if kind == "finite_number":
        return f"must be finite, got {value}"
    if kind in _BOUNDS:
        sign, bound = _BOUNDS[kind]
        return f"must be {sign} {ctx[bound]:g}{_unit(info)}, got {value:g}"
    if kind in ("too_short", "too_long"):
        low, high = _constraints(info).get("min_length", 0), _constraints(info).get("max_length")
        count = f"{low}" if high == low else f"{low} to {high}" if high is not None else f"at least {low}"
        return f"must hold {count} entries, got {ctx['actual_length']}"
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        return f"must be a mapping of keys, got {_show(value)}"
    expected = _expected(info)
    return f"must be {expected}, got {_show(value)}" if expected else f"{msg}, got {_show(value)}"


def _expected(info: FieldInfo, missing: bool = False) -> str:
    """What a field holds, in words: "a number (> 0 m)", "one of ['p', 'q']", ... ("" for any value;
    for a text when it is missing too, as ever)."""
    annotation = info.annotation
    if get_origin(annotation) is Literal:
        return f"one of {list(get_args(annotation))}"
    if annotation in (float, int):
        return f"{'an integer' if annotation is int else 'a number'}{_range(info)}"
    if annotation is bool:
        return "true or false"
    if annotation is str:
        return "" if missing else "a non-empty string"
    if get_origin(annotation) is list:
        return "a list"
    if get_origin(annotation) is dict or isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return "a mapping"
    return ""


def _constraints(info: FieldInfo) -> dict:
    return {name: getattr(item, name) for item in info.metadata
            for name in ("gt", "ge", "lt", "le", "min_length", "max_length") if getattr(item, name, None) is not None}


def _unit(info: FieldInfo) -> str:
    unit = (info.json_schema_extra or {}).get("unit")
    return f" {unit}" if unit else ""


def _range(info: FieldInfo) -> str:
    bounds = _constraints(info)
    text = " and ".join(f"{sign} {bounds[name]:g}" for sign, name in _BOUNDS.values() if name in bounds)
    return f" ({text}{_unit(info)})" if text else (f" [{_unit(info).strip()}]" if _unit(info) else "")


def _field(schema: type, loc: tuple) -> FieldInfo:
    """The field at `loc` (keys, list indexes, "[key]" for a mapping's key) of the model `schema`."""
    info = FieldInfo.from_annotation(schema)
    for step in loc:
        annotation, args = info.annotation, get_args(info.annotation)
        if isinstance(annotation, type) and issubclass(annotation, BaseModel) and step in annotation.model_fields:
            info = annotation.model_fields[step]
        elif get_origin(annotation) in (list, dict):
            info = FieldInfo.from_annotation(args[0] if step == "[key]" or get_origin(annotation) is list else args[1])
        else:
            return FieldInfo.from_annotation(Any)        # (nothing known of it: pydantic's own words)
    return info


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
