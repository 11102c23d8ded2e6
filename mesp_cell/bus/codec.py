"""Compact binary encoding of the typed bus messages (no pickle).

A message is a frozen dataclass whose fields are ``float``, ``int``, ``bool``, ``str``,
``tuple[float, ...]`` or ``tuple[int, ...]``. Its encoding is little-endian: a ``u16`` type id,
then the fields in declaration order: ``float`` as f64, ``int`` as i64, ``bool`` as u8, ``str``
as u32 byte length + UTF-8, a tuple as u32 count + f64/i64 items. Runs of fixed-size fields
are packed with one precompiled ``struct.Struct``, so a state message costs one or two calls.
"""

from __future__ import annotations

import dataclasses
import struct
import typing
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")

_HEADER = struct.Struct("<H")
_LEN = struct.Struct("<I")
_SCALAR = {float: "d", int: "q", bool: "?"}


class CodecError(ValueError):
    """A payload that is not a well-formed encoding of a registered message."""


@dataclasses.dataclass(frozen=True)
class _Plan:
    cls: type
    type_id: int
    # Each step: ("fixed", Struct, field names) | ("str", name) | ("floats", name) | ("ints", name)
    steps: tuple[tuple[Any, ...], ...]


_BY_ID: dict[int, _Plan] = {}
_BY_CLS: dict[type, _Plan] = {}


def _compile(cls: type, type_id: int) -> _Plan:
    hints = typing.get_type_hints(cls)
    steps: list[tuple[Any, ...]] = []
    fmt = ""
    names: list[str] = []

    def flush() -> None:
        nonlocal fmt, names
        if names:
            steps.append(("fixed", struct.Struct("<" + fmt), tuple(names)))
        fmt, names = "", []

    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if hint in _SCALAR:
            fmt += _SCALAR[hint]
            names.append(f.name)
            continue
        flush()
        if hint is str:
            steps.append(("str", f.name))
        elif hint == tuple[float, ...]:
            steps.append(("floats", f.name))
        elif hint == tuple[int, ...]:
            steps.append(("ints", f.name))
        else:
            raise TypeError(f"{cls.__name__}.{f.name}: type {hint} cannot go on the bus")
    flush()
    return _Plan(cls, type_id, tuple(steps))


def register(type_id: int) -> Callable[[type[T]], type[T]]:
    """Class decorator: make a frozen dataclass a bus message with a unique ``type_id``."""

    def wrap(cls: type[T]) -> type[T]:
        if not dataclasses.is_dataclass(cls):
            raise TypeError(f"{cls.__name__} is not a dataclass")
        if type_id in _BY_ID and _BY_ID[type_id].cls is not cls:
            raise ValueError(f"type id {type_id} already used by {_BY_ID[type_id].cls.__name__}")
        plan = _compile(cls, type_id)
        _BY_ID[type_id] = plan
        _BY_CLS[cls] = plan
        return cls

    return wrap


def encode(message: Any) -> bytes:
    """The binary encoding of a registered message."""
    plan = _BY_CLS.get(type(message))
    if plan is None:
        raise TypeError(f"{type(message).__name__} is not a registered bus message")
    out = [_HEADER.pack(plan.type_id)]
    for step in plan.steps:
        kind = step[0]
        if kind == "fixed":
            out.append(step[1].pack(*(getattr(message, n) for n in step[2])))
        elif kind == "str":
            data = getattr(message, step[1]).encode()
            out.append(_LEN.pack(len(data)))
            out.append(data)
        else:
            items = getattr(message, step[1])
            code = "d" if kind == "floats" else "q"
            out.append(struct.pack(f"<I{len(items)}{code}", len(items), *items))
    return b"".join(out)


def decode(data: bytes | bytearray | memoryview, expect: type[T] | None = None) -> T:
    """Decode a payload; with ``expect``, a message of another type is a ``CodecError``."""
    buf = memoryview(data)
    try:
        (type_id,) = _HEADER.unpack_from(buf, 0)
        plan = _BY_ID.get(type_id)
        if plan is None:
            raise CodecError(f"unknown message type id {type_id}")
        if expect is not None and plan.cls is not expect:
            raise CodecError(f"expected {expect.__name__}, got {plan.cls.__name__}")
        pos = _HEADER.size
        values: dict[str, Any] = {}
        for step in plan.steps:
            kind = step[0]
            if kind == "fixed":
                values.update(zip(step[2], step[1].unpack_from(buf, pos), strict=True))
                pos += step[1].size
            else:
                (n,) = _LEN.unpack_from(buf, pos)
                pos += _LEN.size
                if kind == "str":
                    if pos + n > len(buf):
                        raise CodecError("string runs past the end of the payload")
                    values[step[1]] = bytes(buf[pos : pos + n]).decode()
                    pos += n
                else:
                    code = "d" if kind == "floats" else "q"
                    values[step[1]] = struct.unpack_from(f"<{n}{code}", buf, pos)
                    pos += 8 * n
        if pos != len(buf):
            raise CodecError(f"{len(buf) - pos} trailing bytes after {plan.cls.__name__}")
        return plan.cls(**values)
    except (struct.error, UnicodeDecodeError) as exc:
        raise CodecError(f"truncated or corrupt payload ({exc})") from exc
