"""The msgpack codec: the message envelope, bounded parsing, and strict checks of each field.

Messages are msgpack maps with string keys. Every map carries ``"schema"`` (`SCHEMA_VERSION`)
and ``"type"`` (``"poses"``, ``"cmd"``, ``"config"``, ``"control"``, ``"debug"``), so a message
published on the wrong key is rejected too. Keys are checked strictly: a missing or an
extra key is an error. Numeric arrays travel as msgpack ``bin`` holding little-endian
``float64`` (`F8`) or ``int32`` (`I4`) values.

Decoding validates types, sizes, finiteness, ranges and the schema version; every helper
here raises `ProtocolError` naming the field. The configuration dataclasses travel through
one generic, strict serialiser (`dump_dataclass`, `load_dataclass`) that follows their type
hints.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from collections.abc import Collection, Mapping
from typing import TYPE_CHECKING, Any, TypeVar

import msgpack
import numpy as np

from eifp_wire.limits import (
    MAX_MESSAGE_BYTES,
    MAX_OBSTACLES,
    MAX_REASON_CHARS,
    MAX_ROBOTS,
    MAX_SEQ,
    ProtocolError,
)

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

_Config = TypeVar("_Config", bound="DataclassInstance")
"""A configuration dataclass (`load_dataclass`)."""

SCHEMA_VERSION = 4
"""Bumped on any incompatible change of a message schema."""

F8 = np.dtype("<f8")
I4 = np.dtype("<i4")


def _no_duplicate_keys(pairs: list[tuple[Any, Any]]) -> dict[Any, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):
        raise ProtocolError("duplicate map key")
    return out


_BUFFER_TYPES = (memoryview, bytearray)
UNPACK_FLAT: dict[str, Any] = {
    "raw": False, "strict_map_key": True, "max_str_len": MAX_MESSAGE_BYTES,
    "max_bin_len": MAX_MESSAGE_BYTES, "max_array_len": 2 * (MAX_ROBOTS + MAX_OBSTACLES),
    "max_map_len": 256, "max_ext_len": 0}
"""`msgpack.unpackb` options: strings are UTF-8, bounded sizes, no extension types."""
_UNPACK_CHECKED: dict[str, Any] = {**UNPACK_FLAT, "object_pairs_hook": _no_duplicate_keys}
"""The same, every map checked for duplicate keys on the way."""


def _unpack(data: object, *, flat: bool = False) -> object:
    """Parse a payload; every map is checked for duplicate keys.

    `flat`: the message is one map whose values hold no map (a `PosesMsg`): its duplicate
    keys are found by comparing its size with the count in its header, without calling a
    hook on every map (a nested map would go unchecked, and then fails the message's own
    type checks anyway)."""
    if isinstance(data, _BUFFER_TYPES):
        data = bytes(data)
    if not isinstance(data, bytes):
        raise ProtocolError(f"payload must be bytes, got {type(data).__name__}")
    if len(data) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"payload of {len(data)} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        obj = msgpack.unpackb(data, **(UNPACK_FLAT if flat else _UNPACK_CHECKED))
    except ProtocolError:
        raise
    except Exception as exc:  # msgpack raises many kinds (FormatError, StackError, ...)
        raise ProtocolError(f"not valid msgpack: {type(exc).__name__}: {exc}") from exc
    if flat and type(obj) is dict and len(obj) != _map_count(data):
        raise ProtocolError("duplicate map key")
    return obj


def _map_count(data: bytes) -> int:
    """The entry count in the header of the msgpack map `data` starts with."""
    head = data[0]
    if head == 0xDE:  # map 16
        return int.from_bytes(data[1:3], "big")
    if head == 0xDF:  # map 32
        return int.from_bytes(data[1:5], "big")
    return head & 0x0F  # fixmap


def _as_map(obj: object, where: str, keys: Collection[str]) -> dict[str, Any]:
    if not isinstance(obj, dict):
        raise ProtocolError(f"{where}: expected a map, got {type(obj).__name__}")
    want = keys if isinstance(keys, frozenset) else frozenset(keys)
    if obj.keys() != want:  # compared as sets
        got = set(obj)
        missing = sorted(map(str, want - got))
        extra = sorted(map(str, got - want))
        raise ProtocolError(f"{where}: missing keys {missing}, unknown keys {extra}")
    return obj


def open_envelope(data: object, msg_type: str, keys: tuple[str, ...], *,
                  flat: bool = False) -> dict[str, Any]:
    """The map of a payload of type `msg_type` whose body has exactly `keys`.

    Checks the size, the msgpack, the schema version, the type and the set of keys (`flat`:
    see `_unpack`); the values are the caller's to check."""
    obj = _unpack(data, flat=flat)
    if not isinstance(obj, dict):
        raise ProtocolError(f"expected a map, got {type(obj).__name__}")
    version = obj.get("schema")
    if isinstance(version, bool) or not isinstance(version, int):
        raise ProtocolError(f"missing or non-integer schema version: {version!r}")
    if version != SCHEMA_VERSION:
        raise ProtocolError(f"schema version {version}, expected {SCHEMA_VERSION}")
    if obj.get("type") != msg_type:
        raise ProtocolError(f"message type {obj.get('type')!r}, expected {msg_type!r}")
    return _as_map(obj, msg_type, _envelope_keys(keys))


@functools.lru_cache(maxsize=64)
def _envelope_keys(keys: tuple[str, ...]) -> frozenset[str]:
    """Every key of a message's map: the envelope's and its body's `keys`."""
    return frozenset(("schema", "type", *keys))


def pack_message(msg_type: str, body: Mapping[str, Any]) -> bytes:
    """The payload of a message: the envelope (schema, type) and `body`, at most
    `MAX_MESSAGE_BYTES`."""
    data = msgpack.packb({"schema": SCHEMA_VERSION, "type": msg_type, **body}, use_bin_type=True)
    if len(data) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"{msg_type}: encoded size {len(data)} exceeds {MAX_MESSAGE_BYTES}")
    return data


_NUMBER_TYPES = (int, float, np.integer, np.floating)
_INT_TYPES = (int, np.integer)


def check_float(value: object, where: str, lo: float = -math.inf, hi: float = math.inf,
                *, lo_open: bool = False) -> float:
    """`value` as a finite float in [lo, hi] (`lo_open`: (lo, hi]); ints and numpy numbers
    pass, bools do not."""
    if type(value) is float:  # the usual case, as msgpack decodes it
        out = value
    else:
        if isinstance(value, bool) or not isinstance(value, _NUMBER_TYPES):
            raise ProtocolError(f"{where}: expected a number, got {type(value).__name__}")
        try:
            out = float(value)
        except OverflowError as exc:
            raise ProtocolError(f"{where}: number too large") from exc
    if not math.isfinite(out):
        raise ProtocolError(f"{where}: non-finite value {out!r}")
    if out < lo or out > hi or (lo_open and out == lo):
        bracket = "(" if lo_open else "["
        raise ProtocolError(f"{where}: {out!r} outside {bracket}{lo}, {hi}]")
    return out


def check_int(value: object, where: str, lo: int, hi: int) -> int:
    """`value` as an int in [lo, hi]; numpy integers pass, bools do not."""
    if type(value) is int:  # the usual case (not bool, a subclass)
        out = value
    else:
        if isinstance(value, bool) or not isinstance(value, _INT_TYPES):
            raise ProtocolError(f"{where}: expected an int, got {type(value).__name__}")
        out = int(value)
    if not lo <= out <= hi:
        raise ProtocolError(f"{where}: {out} outside [{lo}, {hi}]")
    return out


def check_str(value: object, where: str, max_chars: int = MAX_REASON_CHARS) -> str:
    """`value` if it is a string of at most `max_chars` characters."""
    if not isinstance(value, str):
        raise ProtocolError(f"{where}: expected a string, got {type(value).__name__}")
    if len(value) > max_chars:
        raise ProtocolError(f"{where}: longer than {max_chars} characters")
    return value


def read_column(value: object, where: str, dtype: np.dtype, n: int | None,
                max_n: int) -> np.ndarray:
    """One packed column: ``bin`` of n little-endian `dtype` items, returned read-only (n,)."""
    if not isinstance(value, bytes):
        raise ProtocolError(f"{where}: expected bin, got {type(value).__name__}")
    if len(value) % dtype.itemsize:
        raise ProtocolError(f"{where}: {len(value)} bytes is not a multiple of {dtype.itemsize}")
    count = len(value) // dtype.itemsize
    if count > max_n:
        raise ProtocolError(f"{where}: {count} items exceeds {max_n}")
    if n is not None and count != n:
        raise ProtocolError(f"{where}: {count} items, expected {n}")
    return np.frombuffer(value, dtype=dtype)


def frozen_array(arr: object, dtype: type, shape: tuple[int, ...], where: str) -> np.ndarray:
    """A read-only copy of `arr` as `dtype`, which must have `shape`."""
    out: np.ndarray = np.array(arr, dtype=dtype)
    if out.shape != shape:
        raise ProtocolError(f"{where}: shape {out.shape}, expected {shape}")
    out.flags.writeable = False
    return out


def known_set(known_ids: Collection[int] | None) -> frozenset[int] | set[int] | None:
    """`known_ids` as a set of Python ints (kept as is if it already is a set)."""
    if known_ids is None or isinstance(known_ids, set | frozenset):
        return known_ids
    return frozenset(np.asarray(known_ids, dtype=np.int64).reshape(-1).tolist())


def check_ids(ids: np.ndarray, where: str, lo: int, hi: int,
              known_ids: frozenset[int] | set[int] | None) -> None:
    """Raise unless `ids` (n,) are unique, in [lo, hi] and (if given) all in `known_ids`."""
    if ids.size == 0:
        return
    values = ids.tolist()
    if min(values) < lo or max(values) > hi:
        raise ProtocolError(f"{where}: id outside [{lo}, {hi}]")
    unique = set(values)
    if len(unique) != len(values):
        raise ProtocolError(f"{where}: duplicate ids")
    if known_ids is not None and not unique <= known_ids:
        raise ProtocolError(f"{where}: unknown ids {sorted(unique - known_ids)[:8]}")


def check_values(arr: np.ndarray, where: str, lo: float, hi: float,
                 *, lo_open: bool = False) -> None:
    """Raise unless every value of `arr` is finite and in [lo, hi] (`lo_open`: (lo, hi])."""
    if arr.size == 0:
        return
    # min/max propagate NaN, so one pass each checks finiteness and range.
    low, high = float(arr.min()), float(arr.max())
    if not (math.isfinite(low) and math.isfinite(high)):
        raise ProtocolError(f"{where}: non-finite value")
    if low < lo or high > hi or (lo_open and low <= lo):
        raise ProtocolError(f"{where}: value outside {'(' if lo_open else '['}{lo}, {hi}]")


# --- Generic, strict (de)serialisation of the shared configuration dataclasses --------------


def _dump_value(value: Any, hint: object, where: str) -> object:
    """A configuration value as plain msgpack-able data, following its type hint.

    `value` is typed `Any`: its type is the one `hint` names, known only at run time."""
    if value is None:
        return None
    if dataclasses.is_dataclass(hint):
        return dump_dataclass(value, where)
    origin = typing.get_origin(hint)
    if origin in (types.UnionType, typing.Union):
        (inner,) = [a for a in typing.get_args(hint) if a is not type(None)]
        return _dump_value(value, inner, where)
    if origin is tuple:
        args = typing.get_args(hint)
        return [_dump_value(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args))]
    if hint is float:
        return float(value)
    if hint is int:
        return int(value)
    if hint in (str, bool):
        return value
    raise TypeError(f"{where}: unsupported configuration type {hint!r}")


def dump_dataclass(obj: DataclassInstance, where: str) -> dict[str, object]:
    """A configuration dataclass as a map of its fields, nested dataclasses as maps."""
    hints = typing.get_type_hints(type(obj))
    return {
        f.name: _dump_value(getattr(obj, f.name), hints[f.name], f"{where}.{f.name}")
        for f in dataclasses.fields(obj)
    }


def _load_value(value: object, hint: object, where: str) -> object:
    """Rebuild a configuration value from msgpack data, checking it against its type hint."""
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return load_dataclass(value, hint, where)
    origin = typing.get_origin(hint)
    if origin in (types.UnionType, typing.Union):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _load_value(value, inner, where)
    if origin is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, list) or len(value) != len(args):
            raise ProtocolError(f"{where}: expected a list of {len(args)} items")
        return tuple(
            _load_value(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args))
        )
    if hint is float:
        return check_float(value, where)
    if hint is int:
        return check_int(value, where, -MAX_SEQ - 1, MAX_SEQ)
    if hint is bool:
        if not isinstance(value, bool):
            raise ProtocolError(f"{where}: expected a bool")
        return value
    if hint is str:
        return check_str(value, where)
    raise ProtocolError(f"{where}: unsupported configuration type {hint!r}")


def load_dataclass(data: object, cls: type[_Config], where: str) -> _Config:
    """Rebuild dataclass `cls` from `dump_dataclass`'s map: exactly its fields, each checked
    against its type hint, then the class's own checks (raised as `ProtocolError`)."""
    fields = dataclasses.fields(cls)
    body = _as_map(data, where, [f.name for f in fields])
    hints = typing.get_type_hints(cls)
    kwargs = {f.name: _load_value(body[f.name], hints[f.name], f"{where}.{f.name}")
              for f in fields}
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ProtocolError(f"{where}: {exc}") from exc
