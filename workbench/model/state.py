"""Plain-data state helpers shared by every part of the Case.

A part's *state* is nested plain data: ``dict`` with ``str`` keys, ``list``,
``str``, ``int``, ``float``, ``bool``, ``None`` and read-only ``numpy``
arrays.  Small values stay in ``case.json``; arrays are split out by
:func:`split_arrays` into content-addressed ``.npy`` members and joined back by
:func:`join_arrays`.

User-supplied JSON values (the generic ``parameters`` mapping) are kept
*frozen* (tuples and read-only mappings) so that a part can never be edited in
place; :func:`thaw_json` turns them back into plain JSON.
"""

from __future__ import annotations

import hashlib
import io
import math
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

#: Key that marks an array reference inside ``case.json``.
ARRAY_KEY = "@array"

#: dtypes an array reference may name (nothing that could need pickle).
ARRAY_DTYPES = ("float64", "float32", "int64", "int32", "uint8", "bool")


def freeze_json(value: Any, where: str = "value") -> Any:
    """Deep-copy a JSON-able value into an immutable form.

    Lists become tuples and mappings become read-only mappings; numpy scalars
    become Python scalars.  Non-finite floats and non-JSON types raise.

    Raises
    ------
    TypeError, ValueError
        Naming ``where`` and the offending item.
    """
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(value):
            raise ValueError(f"{where}: non-finite number {value!r} cannot be stored")
        return float(value)
    if isinstance(value, Mapping):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise TypeError(f"{where}: keys must be strings, got {key!r}")
            out[key] = freeze_json(item, f"{where}.{key}")
        return MappingProxyType(out)
    if isinstance(value, (list, tuple)):
        return tuple(freeze_json(item, f"{where}[{i}]") for i, item in enumerate(value))
    raise TypeError(f"{where}: {type(value).__name__} is not a JSON value")


def thaw_json(value: Any) -> Any:
    """Inverse of :func:`freeze_json`: plain ``dict`` / ``list`` copies."""
    if isinstance(value, Mapping):
        return {key: thaw_json(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [thaw_json(item) for item in value]
    return value


def states_equal(a: Any, b: Any) -> bool:
    """Exact structural equality of two states (arrays by dtype, shape and value).

    NaN equals NaN, so undefined landmark positions compare equal.
    """
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return _arrays_equal(a, b)
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        return a.keys() == b.keys() and all(states_equal(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(states_equal(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return type(a) is type(b) and a == b


def _arrays_equal(a: Any, b: Any) -> bool:
    if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)):
        return False
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    equal_nan = a.dtype.kind in "fc"
    return bool(np.array_equal(a, b, equal_nan=equal_nan))


def readonly_array(value: Any, dtype: Any, shape: tuple[int | None, ...]) -> np.ndarray:
    """Copy ``value`` into a read-only array of ``dtype``, checking ``shape``.

    ``None`` in ``shape`` matches any length.
    """
    array = np.array(value, dtype=dtype, copy=True)
    ok = array.ndim == len(shape) and all(
        want is None or have == want for have, want in zip(array.shape, shape, strict=True)
    )
    if not ok:
        raise ValueError(f"expected an array of shape {shape}, got {array.shape}")
    array.setflags(write=False)
    return array


# ------------------------------------------------------------------ arrays
def npy_bytes(array: np.ndarray) -> bytes:
    """Serialise one array as ``.npy`` bytes (never pickled)."""
    buffer = io.BytesIO()
    np.save(buffer, np.ascontiguousarray(array), allow_pickle=False)
    return buffer.getvalue()


def array_ref(array: np.ndarray) -> tuple[dict[str, Any], bytes]:
    """Content-addressed reference to ``array`` and its ``.npy`` bytes.

    The address is the sha256 of the ``.npy`` bytes, so a loader can re-hash
    the stored member and detect any change.
    """
    if array.dtype.name not in ARRAY_DTYPES:
        raise TypeError(f"arrays of dtype {array.dtype} cannot be stored")
    data = npy_bytes(array)
    ref = {
        ARRAY_KEY: hashlib.sha256(data).hexdigest(),
        "dtype": array.dtype.name,
        "shape": [int(n) for n in array.shape],
    }
    return ref, data


def array_from_npy(data: bytes, ref: Mapping[str, Any]) -> np.ndarray:
    """Load ``.npy`` bytes (never unpickling) and check them against ``ref``.

    Raises
    ------
    ValueError
        If the bytes are not an array, or its dtype or shape differ from ``ref``.
    """
    try:
        array = np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as error:
        raise ValueError(f"not a readable array ({error})") from None
    if array.dtype.name != ref["dtype"] or list(array.shape) != list(ref["shape"]):
        raise ValueError(
            f"holds {array.dtype}{list(array.shape)}, "
            f"case.json expects {ref['dtype']}{list(ref['shape'])}"
        )
    return array


def split_arrays(state: Any) -> tuple[Any, dict[str, bytes]]:
    """Replace every array in ``state`` by a reference.

    Returns
    -------
    doc : JSON-able copy of ``state``
    blobs : dict
        ``{sha256: npy bytes}`` for every referenced array.
    """
    blobs: dict[str, bytes] = {}

    def walk(value: Any) -> Any:
        if isinstance(value, np.ndarray):
            ref, data = array_ref(value)
            blobs[ref[ARRAY_KEY]] = data
            return ref
        if isinstance(value, Mapping):
            return {key: walk(item) for key, item in value.items()}
        if isinstance(value, (list, tuple)):
            return [walk(item) for item in value]
        return value

    return walk(state), blobs


def join_arrays(doc: Any, load: Callable[[Mapping[str, Any]], np.ndarray]) -> Any:
    """Inverse of :func:`split_arrays`; ``load(ref)`` returns the array for a reference."""
    if isinstance(doc, Mapping):
        if ARRAY_KEY in doc:
            return load(doc)
        return {key: join_arrays(item, load) for key, item in doc.items()}
    if isinstance(doc, list):
        return [join_arrays(item, load) for item in doc]
    return doc


def array_refs(doc: Any) -> list[Mapping[str, Any]]:
    """Every array reference inside ``doc``, in document order."""
    found: list[Mapping[str, Any]] = []

    def walk(value: Any) -> None:
        if isinstance(value, Mapping):
            if ARRAY_KEY in value:
                found.append(value)
                return
            for item in value.values():
                walk(item)
        elif isinstance(value, list):
            for item in value:
                walk(item)

    walk(doc)
    return found
