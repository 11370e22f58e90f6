"""Typed YAML loading into dataclasses with one-line errors naming file and key.

Drake's ``yaml_load_typed`` reports unknown keys without saying where they are and
cannot tell a missing required key from a default, so configs load through this small
checker instead: every dataclass field without a default is required, unknown keys are
rejected, and values are type-checked against the annotations (str, bool, int, float,
list[...], dict[str, ...], Optional[...], Literal[...], nested dataclasses).
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, Union

import yaml

from romoco_drake.errors import ConfigError

T = TypeVar("T")


def load_yaml_file(path: Path) -> Any:
    """Reads a YAML file, turning I/O and syntax errors into ConfigError."""
    try:
        text = Path(path).read_text()
    except OSError as e:
        raise ConfigError(path, "", f"cannot read file ({e.strerror})") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        line = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(path, "", f"invalid YAML{line}") from None


def load_typed(path: Path, schema: type[T], data: Any = None) -> T:
    """Loads ``path`` (or already-parsed ``data``) into the dataclass ``schema``."""
    if data is None:
        data = load_yaml_file(path)
    return _convert(data, schema, path, "")


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")


def _join(prefix: str, key: Any) -> str:
    if isinstance(key, int):
        return f"{prefix}[{key}]"
    return f"{prefix}.{key}" if prefix else str(key)


def _convert(value: Any, tp: Any, path: Path, key: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if dataclasses.is_dataclass(tp):
        return _convert_dataclass(value, tp, path, key)
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _convert(value, inner[0], path, key)
    if origin is Literal:
        if value not in args:
            choices = ", ".join(str(a) for a in args)
            raise ConfigError(path, key, f"'{value}' is not one of: {choices}")
        return value
    if origin is list:
        if not isinstance(value, list):
            raise ConfigError(path, key, f"expected a list, got {type(value).__name__}")
        return [_convert(v, args[0], path, _join(key, i)) for i, v in enumerate(value)]
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(path, key, f"expected a mapping, got {type(value).__name__}")
        return {str(k): _convert(v, args[1], path, _join(key, k)) for k, v in value.items()}
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(path, key, f"expected a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(path, key, f"expected a finite number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(path, key, f"expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(path, key, f"expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(path, key, f"expected a string, got {value!r}")
        return value
    raise TypeError(f"unsupported schema type {_type_name(tp)} at {key}")


def _convert_dataclass(value: Any, tp: type, path: Path, key: str) -> Any:
    if not isinstance(value, dict):
        got = "nothing" if value is None else type(value).__name__
        raise ConfigError(path, key or "<top>", f"expected a mapping, got {got}")
    hints = typing.get_type_hints(tp)
    fields = {f.name: f for f in dataclasses.fields(tp)}
    unknown = [k for k in value if k not in fields]
    if unknown:
        expected = ", ".join(fields)
        raise ConfigError(path, _join(key, unknown[0]), f"unknown key (expected one of: {expected})")
    kwargs = {}
    for name, field in fields.items():
        if name in value:
            kwargs[name] = _convert(value[name], hints[name], path, _join(key, name))
        elif field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING:
            raise ConfigError(path, _join(key, name), "missing required key")
    try:
        return tp(**kwargs)
    except ValueError as e:
        raise ConfigError(path, key or "<top>", str(e)) from None
