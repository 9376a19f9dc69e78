"""Plain data (JSON-ready) from the project's frozen dataclasses, and back.

Checkpoints of a session (:mod:`app.service.checkpoint`) carry value types such as
:class:`~app.localization.types.Estimate` or :class:`~app.service.types.SessionSpec`.
Rather than one hand-written converter per type, :func:`to_plain` walks a dataclass's
fields and :func:`from_plain` rebuilds it from its type hints, so a field added to one
of those types later is carried without touching this module. Only what the types use
is supported: dataclasses, tuples, lists, dicts with string keys, ``X | None``, numpy
arrays, and numbers, strings and booleans. Non-finite floats pass through as ``NaN``/``Infinity``
(Python's JSON reads and writes them).
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar, Union

import numpy as np

T = TypeVar("T")


def to_plain(value: Any) -> Any:
    """``value`` as nested dicts, lists, numbers and strings (numpy arrays stay arrays:
    :func:`app.service.checkpoint.pack` stores them as raw bytes)."""
    if isinstance(value, np.ndarray):
        return value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, tuple | list):
        return [to_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): to_plain(v) for k, v in value.items()}
    if hasattr(value, "item") and callable(value.item):  # numpy scalar
        return value.item()
    return value


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def from_plain(kind: Any, data: Any) -> Any:
    """Rebuild a value of type ``kind`` (a dataclass or a typing form) from plain data."""
    if data is None:
        return None
    origin = typing.get_origin(kind)
    if origin in (Union, types.UnionType):
        options = [a for a in typing.get_args(kind) if a is not type(None)]
        for option in options:
            try:
                return from_plain(option, data)
            except (TypeError, ValueError, KeyError):
                continue
        raise ValueError(f"{data!r} fits none of {options}")
    if kind is np.ndarray or origin is np.ndarray:
        return np.array(data)  # a writable copy
    if isinstance(kind, type) and dataclasses.is_dataclass(kind):
        if not isinstance(data, Mapping):
            raise TypeError(f"{kind.__name__}: expected an object, got {type(data).__name__}")
        hints = _hints(kind)
        known = {f.name for f in dataclasses.fields(kind) if f.init}
        return kind(**{k: from_plain(hints[k], v) for k, v in data.items() if k in known})
    if origin is tuple:
        args = typing.get_args(kind)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(from_plain(args[0], v) for v in data)
        return tuple(from_plain(a, v) for a, v in zip(args, data, strict=True))
    if origin is list:
        (arg,) = typing.get_args(kind) or (Any,)
        return [from_plain(arg, v) for v in data]
    if origin in (dict, Mapping) or kind in (dict, Mapping):
        args = typing.get_args(kind)
        value_kind = args[1] if args else Any
        return {k: from_plain(value_kind, v) for k, v in data.items()}
    if kind is float:
        if isinstance(data, bool) or not isinstance(data, int | float):
            raise TypeError(f"expected a number, got {data!r}")
        return float(data)
    if kind is int:
        if isinstance(data, bool) or not isinstance(data, int):
            raise TypeError(f"expected an integer, got {data!r}")
        return data
    if kind is str:
        if not isinstance(data, str):
            raise TypeError(f"expected a string, got {data!r}")
        return data
    if kind is bool:
        if not isinstance(data, bool):
            raise TypeError(f"expected true or false, got {data!r}")
        return data
    if typing.get_origin(kind) is typing.Literal:
        if data not in typing.get_args(kind):
            raise ValueError(f"{data!r} is not one of {typing.get_args(kind)}")
        return data
    return data  # Any, object and aliases: as stored
