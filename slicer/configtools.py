"""Typed configuration from TOML: nested frozen dataclasses, validated on construction.

A config class is a frozen dataclass whose fields are scalars, tuples or other config
classes; ``__post_init__`` raises ``ValueError`` for a bad value. ``build`` fills it from a
mapping, refusing unknown keys and wrong types with an ``InputError`` that names the key.
"""

from __future__ import annotations

import dataclasses
import tomllib
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from slicer.errors import InputError

T = TypeVar("T")


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


def build(cls: type[T], data: Mapping[str, Any], where: str = "config") -> T:
    """Construct config class ``cls`` from ``data``; every problem is an ``InputError``."""
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
        kwargs[name] = _coerce(hints[name], value, f"{where}.{name}")
    try:
        return cls(**kwargs)
    except InputError:
        raise
    except ValueError as exc:
        raise InputError(f"bad value in [{where}]: {exc}", "see the defaults file") from exc


def _coerce(hint: Any, value: Any, where: str) -> Any:
    origin = typing.get_origin(hint)
    if dataclasses.is_dataclass(hint):
        return build(hint, value, where)  # type: ignore[arg-type]
    if origin in (types.UnionType, typing.Union):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(arg, value, where)
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
        return tuple(_coerce(item, v, f"{where}[{i}]") for i, v in enumerate(value))
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(f"'{where}' must be a number, got {value!r}", "write a number")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"'{where}' must be a whole number, got {value!r}", "write an integer")
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
