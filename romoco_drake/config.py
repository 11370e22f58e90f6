"""Typed YAML loading into dataclasses with one-line errors naming file and key.

Drake's ``yaml_load_typed`` reports unknown keys without saying where they are and
cannot tell a missing required key from a default, so configs load through this small
checker instead: every dataclass field without a default is required, unknown keys are
rejected, and values are type-checked against the annotations (str, bool, int, float,
list[...], dict[str, ...], Optional[...], Literal[...], nested dataclasses).

Numeric fields also have physical ranges: each config dataclass declares a table of
:class:`Range` (``declare_ranges``) next to its definition, and :func:`check_ranges` checks a
loaded (or Python-built) config against the tables of every dataclass in it, so an absurd value
(a 1e300 s time step, a negative gain, a 2-vector where a point goes) fails at load in one line
with the allowed range instead of hanging, crashing or running a meaningless simulation.
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, Union

import yaml

from romoco_drake.errors import ConfigError

T = TypeVar("T")


@dataclasses.dataclass(frozen=True)
class Range:
    """The values a numeric field may take: ``lo``..``hi`` in ``unit``, each end included unless
    ``lo_open``/``hi_open``. For a list (or dict) field it bounds every entry, and ``size``, if
    given, is the length of the field's vectors (of the list, or of each inner list)."""

    lo: float = -math.inf
    hi: float = math.inf
    unit: str = ""
    lo_open: bool = False
    hi_open: bool = False
    size: int | None = None

    def contains(self, x: float) -> bool:
        """Whether ``x`` is in the range (never a NaN)."""
        above = x > self.lo if self.lo_open else x >= self.lo
        below = x < self.hi if self.hi_open else x <= self.hi
        return bool(above and below)

    def describe(self) -> str:
        """The range as a user reads it, e.g. ``in [1e-05, 0.05] s`` or ``positive, at most 3``."""
        unit = f" {self.unit}" if self.unit else ""
        if self.lo == 0.0 and self.lo_open and not self.hi_open:
            return f"positive{'' if math.isinf(self.hi) else f', at most {self.hi:g}'}{unit}"
        left = "(" if self.lo_open else "["
        right = ")" if self.hi_open else "]"
        return f"in {left}{self.lo:g}, {self.hi:g}{right}{unit}"


def positive(hi: float = math.inf, unit: str = "") -> Range:
    """(0, hi]: a quantity that must be strictly positive."""
    return Range(0.0, hi, unit, lo_open=True)


# Component clocks (controllers, estimators, sensors): 1 Hz is the slowest loop that still closes
# anything; 10 kHz the fastest motor loop hardware runs. A clock need not divide the plant step:
# G1 walking on a 2 ms step tracks alike at 300, 500 and 2000 Hz (measured), a faster controller
# just sees the same state again.
RATE_HZ = Range(1.0, 10000.0, "Hz")

# Every system of the control loop ticks this long after the plant's step (on LCM links, after
# the robot's message), as a controller woken by the robot's state message does: it acts on the
# measurement of that step. Ticking on the step itself reads the state before it, one plant step
# (2 ms on G1) of extra delay. The direct simulation ticks the same way, so sim and LCM runs are
# the same closed loop: `romoco run g1_walk` and `--via-lcm` agree to round-off (final base height
# to 1e-13 m); with the direct loop a step behind they differed by up to 0.013 m/s in the averaged
# velocity.
LINK_TICK_OFFSET = 1e-4  # s, less than any plant step


RANGES: dict[type, dict[str, Range]] = {}


def declare_ranges(schema: type, **ranges: Range) -> None:
    """Declares the ranges of ``schema``'s numeric fields (checked by :func:`check_ranges`); a
    subclass inherits its bases' ranges and may add or override fields."""
    names = {f.name for f in dataclasses.fields(schema)}
    unknown = set(ranges) - names
    if unknown:
        raise TypeError(f"{schema.__name__} has no field {', '.join(sorted(unknown))}")
    RANGES[schema] = ranges


def check_ranges(config: Any, where: str | Path, key: str = "") -> None:
    """Checks ``config`` (a dataclass instance) and every dataclass in it against their declared
    ranges; the first value out of range raises ConfigError naming ``where`` and its key."""
    if dataclasses.is_dataclass(config):
        table = ranges_of(type(config))
        hints = typing.get_type_hints(type(config)) if table else {}
        for field in dataclasses.fields(config):
            value = getattr(config, field.name)
            name = _join(key, field.name)
            if field.name in table and value is not None:
                _check_value(value, table[field.name], _list_depth(hints[field.name]), where, name)
            check_ranges(value, where, name)
    elif isinstance(config, list):
        for i, item in enumerate(config):
            check_ranges(item, where, _join(key, i))
    elif isinstance(config, dict):
        for k, item in config.items():
            check_ranges(item, where, _join(key, k))


def ranges_of(schema: type) -> dict[str, Range]:
    """The ranges of ``schema``'s fields: its own table over those of its bases."""
    table: dict[str, Range] = {}
    for cls in reversed(schema.__mro__):
        table.update(RANGES.get(cls, {}))
    return table


def _list_depth(tp: Any) -> int:
    """How many list levels the annotation ``tp`` has (list[list[float]] | None: 2)."""
    if typing.get_origin(tp) in (Union, types.UnionType):
        return max(_list_depth(a) for a in typing.get_args(tp))
    if typing.get_origin(tp) is list:
        return 1 + _list_depth(typing.get_args(tp)[0])
    return 0


def _check_value(value: Any, allowed: Range, depth: int, where: str | Path, key: str) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _check_value(v, allowed, depth, where, _join(key, k))
        return
    if isinstance(value, list):
        if depth == 1 and allowed.size is not None and len(value) != allowed.size:
            raise ConfigError(where, key, f"needs {allowed.size} values, got {len(value)}")
        for i, v in enumerate(value):
            _check_value(v, allowed, depth - 1, where, _join(key, i))
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(where, key, f"expected a number, got {_brief(value)}")
    if not allowed.contains(value):
        raise ConfigError(where, key, f"must be {allowed.describe()}, got {_show(value)}")


def _brief(value: Any) -> str:
    """``repr(value)`` cut to fit an error line (a mistyped value may be a whole mapping)."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _show(value: float) -> str:
    """A number for an error line: short, whatever its size (an int may exceed float range)."""
    if isinstance(value, int) and abs(value) >= 10**15:
        return f"a {len(str(abs(value)))}-digit integer"
    return f"{value:g}"


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader, reading 1e-3 and 2E+5 as numbers, as YAML 1.2 does: its YAML 1.1
    floats need a dot (1.0e-3), so "time_step: 1e-3" was the text '1e-3' and a type error."""


_Loader.add_implicit_resolver("tag:yaml.org,2002:float",
                              re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
                              list("-+0123456789"))


def load_yaml_file(path: Path) -> Any:
    """Reads a YAML file, turning I/O, encoding and syntax errors into ConfigError."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as e:
        raise ConfigError(path, "", f"cannot read file ({e.strerror or e})") from None
    except UnicodeDecodeError as e:
        byte = f"byte 0x{e.object[e.start]:02x} at offset {e.start}"
        raise ConfigError(path, "", f"not UTF-8 text ({byte}); save the file as UTF-8") from None
    try:
        return yaml.load(text, Loader=_Loader)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        line = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(path, "", f"invalid YAML{line}") from None


def load_typed(path: Path, schema: type[T], data: Any = None) -> T:
    """Loads ``path`` (or already-parsed ``data``) into the dataclass ``schema``, ranges checked."""
    if data is None:
        data = load_yaml_file(path)
    config = _convert(data, schema, path, "")
    check_ranges(config, path)
    return config


def load_section(path: str | Path, schema: type[T], data: Any, key: str) -> T:
    """Converts ``data``, the section ``key`` of ``path``, into the dataclass ``schema`` (errors
    name ``key``); ranges are the caller's to check, once the whole config is assembled."""
    return _convert(data, schema, path, key)


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
            raise ConfigError(path, key, f"expected a number, got {_brief(value)}")
        try:
            number = float(value)
        except OverflowError:  # an integer literal past float range
            number = math.inf
        if not math.isfinite(number):
            raise ConfigError(path, key, f"expected a finite number, got {_show(value)}")
        return number
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(path, key, f"expected an integer, got {_brief(value)}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(path, key, f"expected true or false, got {_brief(value)}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(path, key, f"expected a string, got {_brief(value)}")
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
