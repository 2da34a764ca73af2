"""Plain-data state of a tree of typed values (dataclasses, arrays, numbers, text).

A derived result such as a fitted face is a tree of frozen dataclasses
holding numpy arrays.  To keep it in a case file without pickle, the tree is
turned into nested JSON values with the arrays left in place (the case file
splits them into content-addressed ``.npy`` members), and back.

Only the classes of an explicit *registry* (``{tag: class}``, given by the
caller) are ever built when reading, from their ``__init__`` fields; a tag
that is not in the registry is refused.  Nothing is unpickled and no class
named in the data is looked up.

Encoding
--------
======================  ===================================================
value                   state
======================  ===================================================
None, bool, int, str    itself
float                   itself; non-finite as ``{"@float": "nan"}`` (JSON
                        has no NaN)
numpy scalar            the Python scalar
numpy array             itself; a dtype the case file does not store
                        (:data:`STORED_DTYPES`) as ``{"@cast": dtype, "data":
                        array}`` of a wider stored dtype
list / tuple            ``[...]`` / ``{"@tuple": [...]}``
mapping                 ``{"@map": [[key, value], ...], "proxy": bool}``
                        (keys of any encodable kind, order kept)
Path                    ``{"@path": "..."}``
dataclass               ``{"@type": tag, "fields": {name: state}}``
======================  ===================================================

Units and frames are those of the values themselves; nothing is converted.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Mapping
from pathlib import Path, PurePath
from types import MappingProxyType
from typing import Any

import numpy as np

#: dtypes the case file stores as they are (:data:`workbench.model.state.ARRAY_DTYPES`)
STORED_DTYPES = ("float64", "float32", "int64", "int32", "uint8", "bool")
#: keys that mark an encoded value (a plain mapping never uses them at its top)
MARKS = ("@float", "@cast", "@tuple", "@map", "@path", "@type")


class StateError(ValueError):
    """A value cannot be encoded, or a state cannot be decoded (says where and why)."""


def _wider(dtype: np.dtype) -> str:
    if dtype.kind == "f":
        return "float64"
    if dtype.kind in "iu":
        return "int64"
    if dtype.kind == "b":
        return "bool"
    raise StateError(f"arrays of dtype {dtype} cannot be stored")


def encode(value: Any, registry: Mapping[str, type], where: str = "value") -> Any:
    """The plain state of ``value`` (see the module docstring); arrays stay arrays.

    Raises
    ------
    StateError
        A dataclass not in ``registry``, or a type with no encoding (named with ``where``).
    """
    tags = {cls: tag for tag, cls in registry.items()}

    def walk(v: Any, at: str) -> Any:
        if v is None or isinstance(v, (bool, str)):
            return v
        if isinstance(v, np.ndarray):
            if v.dtype.name in STORED_DTYPES:
                return v
            if v.dtype == object:
                raise StateError(f"{at}: arrays of Python objects cannot be stored")
            return {"@cast": v.dtype.str, "data": v.astype(_wider(v.dtype))}
        if isinstance(v, np.generic):
            return walk(v.item(), at)
        if isinstance(v, int):
            return v
        if isinstance(v, float):
            return v if math.isfinite(v) else {"@float": repr(v)}
        if isinstance(v, PurePath):
            return {"@path": str(v)}
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            tag = tags.get(type(v))
            if tag is None:
                raise StateError(f"{at}: {type(v).__qualname__} is not a registered type")
            fields = {
                f.name: walk(getattr(v, f.name), f"{at}.{f.name}")
                for f in dataclasses.fields(v)
                if f.init
            }
            return {"@type": tag, "fields": fields}
        if isinstance(v, Mapping):
            items = [[walk(k, f"{at} key"), walk(x, f"{at}[{k!r}]")] for k, x in v.items()]
            return {"@map": items, "proxy": isinstance(v, MappingProxyType)}
        if isinstance(v, tuple):
            return {"@tuple": [walk(x, f"{at}[{i}]") for i, x in enumerate(v)]}
        if isinstance(v, list):
            return [walk(x, f"{at}[{i}]") for i, x in enumerate(v)]
        raise StateError(f"{at}: a {type(v).__qualname__} has no stored form")

    return walk(value, where)


def _key(k: Any) -> Any:
    """A decoded mapping key made hashable (lists from JSON become tuples)."""
    return tuple(_key(x) for x in k) if isinstance(k, list) else k


def decode(state: Any, registry: Mapping[str, type], where: str = "state") -> Any:
    """The value ``state`` encodes (inverse of :func:`encode` with the same ``registry``).

    Raises
    ------
    StateError
        An unknown type tag, an unknown or missing field, a malformed mark
        (named with ``where``); errors raised by a class's own checks are
        passed on as a StateError naming the place.
    """

    def walk(s: Any, at: str) -> Any:
        if s is None or isinstance(s, (bool, str, int, float, np.ndarray)):
            return s
        if isinstance(s, list):
            return [walk(x, f"{at}[{i}]") for i, x in enumerate(s)]
        if not isinstance(s, Mapping):
            raise StateError(f"{at}: unexpected {type(s).__name__}")
        if "@float" in s:
            text = s["@float"]
            if text not in ("nan", "inf", "-inf"):
                raise StateError(f"{at}: {text!r} is not a non-finite number")
            return float(text)
        if "@cast" in s:
            data = s.get("data")
            if not isinstance(data, np.ndarray):
                raise StateError(f"{at}: a cast array without its data")
            return data.astype(np.dtype(str(s["@cast"])))
        if "@tuple" in s:
            return tuple(walk(x, f"{at}[{i}]") for i, x in enumerate(s["@tuple"]))
        if "@path" in s:
            return Path(str(s["@path"]))
        if "@map" in s:
            out = {_key(walk(k, f"{at} key")): walk(x, f"{at}[{k!r}]") for k, x in s["@map"]}
            return MappingProxyType(out) if s.get("proxy") else out
        if "@type" in s:
            tag = s["@type"]
            cls = registry.get(tag) if isinstance(tag, str) else None
            if cls is None:
                raise StateError(f"{at}: unknown type {tag!r}")
            names = {f.name for f in dataclasses.fields(cls) if f.init}
            given = s.get("fields")
            if not isinstance(given, Mapping) or not set(given) <= names:
                extra = sorted(set(given or ()) - names) if isinstance(given, Mapping) else []
                raise StateError(f"{at}: fields {extra} are not fields of {tag}")
            kwargs = {name: walk(x, f"{at}.{name}") for name, x in given.items()}
            try:
                return cls(**kwargs)
            except (TypeError, ValueError) as exc:
                raise StateError(f"{at}: {tag} refused its stored fields: {exc}") from exc
        raise StateError(f"{at}: a mapping without a known mark ({', '.join(MARKS)})")

    return walk(state, where)


def digest(state: Any) -> str:
    """SHA-256 (hex) of an encoded state: its JSON text with every array's dtype, shape and bytes."""
    h = hashlib.sha256()

    def walk(s: Any) -> Any:
        if isinstance(s, np.ndarray):
            a = np.ascontiguousarray(s)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
            return "@array"
        if isinstance(s, Mapping):
            return {str(k): walk(x) for k, x in s.items()}
        if isinstance(s, (list, tuple)):
            return [walk(x) for x in s]
        return s

    text = json.dumps(walk(state), sort_keys=True, allow_nan=False)
    h.update(text.encode())
    return h.hexdigest()
