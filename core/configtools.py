"""Typed configuration from TOML: nested frozen dataclasses, validated on construction.

A config class is a frozen dataclass whose fields are scalars, tuples or other config
classes; ``__post_init__`` raises ``ValueError`` for a bad value. ``build`` fills it from a
mapping, refusing unknown keys, wrong types, non-finite numbers (NaN, inf) and numbers outside
the accepted range with an ``InputError`` that names the key, the range and the fix. The
ranges live in a ranges file beside the defaults file (``slicer/ranges.toml``,
``planner/cell_ranges.toml``): ``"section.key" = [min, max]``, applied to every number of a
list too; a number without a range must still be finite and, if whole, below ``MAX_INT``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from core.errors import InputError

T = TypeVar("T")
Ranges = Mapping[str, tuple[float, float]]
MAX_INT = 2**31 - 1  # a whole number without a range: at most this (a count, never a size)


def read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file; a missing or malformed file is an ``InputError``."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"config file {path} does not exist", "check the path")
    try:
        return tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path} is not valid TOML ({exc})", "fix the syntax") from exc


def merge(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """Deep-merge two nested mappings; ``override`` wins."""
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merge(out[key], value)
        else:
            out[key] = value
    return out


def read_ranges(text: str, source: str) -> dict[str, tuple[float, float]]:
    """The ranges of a ranges file's text: ``{"section.key": (min, max)}``."""
    out: dict[str, tuple[float, float]] = {}

    def walk(table: Mapping[str, Any], prefix: str) -> None:
        for key, value in table.items():
            if isinstance(value, Mapping):
                walk(value, f"{prefix}{key}.")
            else:
                lo, hi = value
                out[f"{prefix}{key}"] = (float(lo), float(hi))

    walk(tomllib.loads(text), "")
    for key, (lo, hi) in out.items():
        if not lo <= hi:
            raise ValueError(f"{source}: range of {key} is empty")
    return out


def build(cls: type[T], data: Mapping[str, Any], where: str = "config",
          ranges: Ranges | None = None, source: str = "the defaults file") -> T:
    """Construct config class ``cls`` from ``data``; every problem is an ``InputError``.

    Args:
        ranges: ``{"section.key": (min, max)}`` relative to ``where`` (see the module
            docstring); ``source`` names the file they come from, for the fix.
    """
    return _build(cls, data, where, "", ranges or {}, source)


def _build(cls: type[T], data: Mapping[str, Any], where: str, path: str, ranges: Ranges,
           source: str) -> T:
    if not isinstance(data, Mapping):
        raise InputError(f"{where} must be a table", "see the defaults file for the format")
    hints = typing.get_type_hints(cls)
    known = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise InputError(
            f"unknown key '{where}.{unknown[0]}'",
            f"allowed keys in [{where}]: {', '.join(sorted(known))}",
        )
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        key = f"{path}{name}"
        value = _coerce(hints[name], value, f"{where}.{name}", key, ranges, source)
        _check_range(value, f"{where}.{name}", key, ranges, source)
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except InputError:
        raise
    except ValueError as exc:
        raise InputError(f"bad value in [{where}]: {exc}", "see the defaults file") from exc


def _check_range(value: Any, where: str, key: str, ranges: Ranges, source: str) -> None:
    """Every number of ``value`` (a number or a tuple of them) within the range of ``key``."""
    if key not in ranges:
        return
    lo, hi = ranges[key]
    items = value if isinstance(value, tuple) else (value,)
    for item in items:
        if isinstance(item, int | float) and not isinstance(item, bool) and not lo <= item <= hi:
            raise InputError(f"'{where}' = {item!r} is outside {lo:g} to {hi:g}",
                             f"set {key.split('.')[-1]} between {lo:g} and {hi:g} "
                             f"(the ranges are in {source})")


def _coerce(hint: Any, value: Any, where: str, key: str = "", ranges: Ranges | None = None,
            source: str = "the defaults file") -> Any:
    origin = typing.get_origin(hint)
    ranges = ranges or {}
    if dataclasses.is_dataclass(hint):
        return _build(hint, value, where, f"{key}.", ranges, source)  # type: ignore[arg-type]
    if origin in (types.UnionType, typing.Union):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(arg, value, where, key, ranges, source)
            except InputError as exc:
                errors.append(exc)
        raise errors[0]
    if origin is typing.Literal:
        allowed = typing.get_args(hint)
        if value not in allowed:
            raise InputError(
                f"'{where}' is {value!r}", f"use one of {', '.join(map(repr, allowed))}"
            )
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise InputError(f"'{where}' must be a list", f"write {where.split('.')[-1]} = [...]")
        args = typing.get_args(hint)
        item = args[0]
        return tuple(_coerce(item, v, f"{where}[{i}]", key, ranges, source)
                     for i, v in enumerate(value))
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(f"'{where}' must be a number, got {value!r}", "write a number")
        if not math.isfinite(value):
            raise InputError(f"'{where}' is {value!r}", "write a finite number")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"'{where}' must be a whole number, got {value!r}", "write an integer")
        if key not in ranges and abs(value) > MAX_INT:
            raise InputError(f"'{where}' = {value} is out of bounds",
                             f"write a whole number of at most {MAX_INT}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise InputError(f"'{where}' must be true or false, got {value!r}", "write true/false")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise InputError(f"'{where}' must be a string, got {value!r}", "quote the value")
        return value
    if hint is Path:
        if not isinstance(value, str):
            raise InputError(f"'{where}' must be a path string, got {value!r}", "quote it")
        return Path(value)
    raise TypeError(f"unsupported config type {hint!r} at {where}")


def to_dict(config: Any) -> dict[str, Any]:
    """A config value as plain TOML-able data."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            out[f.name] = to_dict(value)
        elif isinstance(value, tuple):
            out[f.name] = list(value)
        elif isinstance(value, Path):
            out[f.name] = str(value)
        elif value is not None:
            out[f.name] = value
    return out
