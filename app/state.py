"""Plain data (JSON-ready) from the project's frozen dataclasses, and back.

Checkpoints of a session (:mod:`app.service.checkpoint`) carry value types such as
:class:`~app.localization.types.Estimate` or :class:`~app.service.types.SessionSpec`.
Rather than one hand-written converter per type, :func:`to_plain` walks a dataclass's
fields and :func:`from_plain` rebuilds it from its type hints, so a field added to one
of those types later is carried without touching this module. Only what the types use
is supported: dataclasses, tuples, lists, dicts with string keys, ``X | None``, numpy
arrays, and numbers, strings and booleans. Non-finite floats pass through as ``NaN``/``Infinity``
(Python's JSON reads and writes them).

:func:`plain_step` converts one level only, for an encoder that walks the rest itself
(:func:`app.service.checkpoint.pack` hands it to MessagePack's encoder, and the journal
to orjson's, whose walks are compiled). :func:`to_columns` stores many values of one
type as a few long arrays, and :func:`from_columns` reads them back: checkpoints of
format 3 kept the evidence window's observations so (format 4 keeps fewer arrays,
:func:`app.localization.sensor.observation_columns`), and are still read.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from collections.abc import Mapping, Sequence
from typing import Any, TypeVar, Union

import numpy as np

T = TypeVar("T")


#: What :func:`_one_level` returns for a value it leaves as it is.
_AS_IS = object()


def _one_level(value: Any) -> Any:
    """A dataclass as a dict of its fields, any other mapping as a dict (string keys), a
    numpy scalar as a number; anything else :data:`_AS_IS`."""
    kind: type = type(value)
    names = _dataclass_names(kind)
    if names is not None:
        return {name: getattr(value, name) for name in names}
    if isinstance(value, Mapping):
        return {str(k): v for k, v in value.items()}
    if isinstance(value, np.generic):
        return value.item()
    return _AS_IS


def to_plain(value: Any) -> Any:
    """``value`` as nested dicts, lists, numbers and strings (numpy arrays stay arrays:
    :func:`app.service.checkpoint.pack` stores them as raw bytes)."""
    if isinstance(value, np.ndarray):
        return value
    if isinstance(value, tuple | list):
        return [to_plain(v) for v in value]
    step = _one_level(value)
    if step is _AS_IS:
        return value
    return {k: to_plain(v) for k, v in step.items()} if isinstance(step, dict) else step


def plain_step(value: Any) -> Any:
    """``value`` one level nearer plain data (:func:`_one_level`; TypeError for anything
    it leaves as it is, as an encoder's ``default`` must)."""
    step = _one_level(value)
    if step is _AS_IS:
        raise TypeError(f"{type(value).__name__} is not plain data")
    return step


def to_columns(values: Sequence[Any]) -> dict[str, Any]:
    """Values of one dataclass type as columns: each field holding 1-d arrays as those
    arrays joined end to end (the arrays of a field share a dtype), with every value's
    lengths in ``lengths``, shape (values, array fields); any other field as a list."""
    if not values:
        return {"arrays": {}, "lengths": np.zeros((0, 0), np.int64), "fields": {}}
    cls: type = type(values[0])
    names = _names(cls)
    arrays = [n for n in names if isinstance(getattr(values[0], n), np.ndarray)]
    return {
        "arrays": {n: np.concatenate([getattr(v, n) for v in values]) for n in arrays},
        "lengths": np.array([[getattr(v, n).size for n in arrays] for v in values], np.int64),
        "fields": {n: [getattr(v, n) for v in values] for n in names if n not in arrays},
    }


def from_columns(kind: type[T], columns: Mapping[str, Any]) -> list[T]:
    """The values :func:`to_columns` was given (their arrays slices of one writable copy
    of each column)."""
    arrays = {n: np.array(a) for n, a in columns["arrays"].items()}
    ends = np.cumsum(columns["lengths"], axis=0).tolist()
    cls: type = kind
    hints = _hints(cls)
    init = _init_names(cls)
    fields = {
        n: [from_plain(hints[n], v) for v in vs] for n, vs in columns["fields"].items() if n in init
    }
    starts = [[0] * len(arrays), *ends]
    values = []
    for i, end in enumerate(ends):
        args = {n: a[s:e] for (n, a), s, e in zip(arrays.items(), starts[i], end, strict=True)}
        values.append(kind(**args, **{n: vs[i] for n, vs in fields.items()}))
    return values


@functools.cache
def _names(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls))


@functools.cache
def _dataclass_names(cls: type) -> tuple[str, ...] | None:
    """The field names of a dataclass type, None for any other type (a dataclass type
    itself is a value of type ``type``): one lookup for each value a checkpoint meets,
    where ``dataclasses.is_dataclass`` took several."""
    return _names(cls) if dataclasses.is_dataclass(cls) else None


@functools.cache
def _init_names(cls: type) -> frozenset[str]:
    return frozenset(f.name for f in dataclasses.fields(cls) if f.init)


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def from_plain(kind: Any, data: Any) -> Any:
    """Rebuild a value of type ``kind`` (a dataclass or a typing form) from plain data."""
    if data is None:
        return None
    # Numbers, strings and dataclasses first: they are most of the calls.
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
    if isinstance(kind, type) and dataclasses.is_dataclass(kind):
        if isinstance(data, kind):  # not packed yet: taken as it is
            return data
        if not isinstance(data, Mapping):
            raise TypeError(f"{kind.__name__}: expected an object, got {type(data).__name__}")
        hints = _hints(kind)
        known = _init_names(kind)
        return kind(**{k: from_plain(hints[k], v) for k, v in data.items() if k in known})
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
    if origin is typing.Literal:
        if data not in typing.get_args(kind):
            raise ValueError(f"{data!r} is not one of {typing.get_args(kind)}")
        return data
    return data  # Any, object and aliases: as stored
