"""Validation of untrusted structure: JSON documents (model files, checkpoint
headers) and arrays read from checkpoints.

Everything a file declares is checked here before it is used: JSON nesting
depth, integer range, finiteness and string length; array dtype, byte order,
shape and finiteness. Failures raise the caller's :mod:`subid.errors` class
with a message naming the file and the field.
"""

from __future__ import annotations

import json
import math

import numpy as np

MAX_DEPTH = 64                   # nesting of JSON objects and lists
MAX_INT_DIGITS = 19              # |int| < 10**19: beyond int64 is never a subid value
MAX_STRING = 1 << 20             # characters of one JSON string


class _Invalid(Exception):
    pass


def _parse_int(text: str) -> int:
    if len(text.lstrip("-")) > MAX_INT_DIGITS:
        raise _Invalid(f"an integer of {len(text.lstrip('-'))} digits")
    value = int(text)
    if not -2**63 <= value < 2**63:
        raise _Invalid(f"the integer {value} is outside the 64-bit range")
    return value


def _parse_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise _Invalid(f"the number {text[:40]} overflows a float")
    return value


def _parse_constant(name: str):
    raise _Invalid(f"{name} is not valid JSON (non-finite numbers are stored tagged)")


def check_tree(obj, where: str, error, *, max_depth: int = MAX_DEPTH) -> None:
    """Walk a decoded JSON value iteratively: depth, key types, string lengths."""
    stack = [(obj, 1)]
    while stack:
        value, depth = stack.pop()
        if depth > max_depth:
            raise error(f"{where} is nested more than {max_depth} levels deep")
        if isinstance(value, dict):
            for key, item in value.items():
                if not isinstance(key, str) or len(key) > MAX_STRING:
                    raise error(f"{where} has an invalid key")
                stack.append((item, depth + 1))
        elif isinstance(value, list):
            stack.extend((item, depth + 1) for item in value)
        elif isinstance(value, str):
            if len(value) > MAX_STRING:
                raise error(f"{where} holds a string of {len(value)} characters")
        elif isinstance(value, float):
            if not math.isfinite(value):
                raise error(f"{where} holds a non-finite number")
        elif value is not None and not isinstance(value, (bool, int)):
            raise error(f"{where} holds a {type(value).__name__}")


def parse_json(text, where: str, error, *, max_depth: int = MAX_DEPTH):
    """Decode JSON ``text`` (str or UTF-8 bytes) and check its structure.

    Raises ``error(message)`` on invalid UTF-8, invalid JSON, nesting deeper
    than ``max_depth``, integers beyond 64 bits, numbers that overflow and
    NaN/Infinity literals. ``json.JSONDecodeError`` details (line, column)
    are kept in the message.
    """
    if isinstance(text, (bytes, bytearray, memoryview)):
        try:
            text = bytes(text).decode("utf-8")
        except UnicodeDecodeError:
            raise error(f"{where} is not UTF-8 text: it is not a subid file, or it is "
                        "corrupted") from None
    try:
        obj = json.loads(text, parse_int=_parse_int, parse_float=_parse_float,
                         parse_constant=_parse_constant)
    except _Invalid as exc:
        raise error(f"{where} is not valid: {exc}") from None
    except RecursionError:
        raise error(f"{where} is nested too deeply to be a subid file") from None
    except json.JSONDecodeError as exc:
        raise error(f"{where} is not valid JSON ({exc.msg} at line {exc.lineno}, column "
                    f"{exc.colno}); the file may be truncated or corrupted") from None
    except ValueError as exc:           # e.g. int() digit limits
        raise error(f"{where} is not valid JSON ({exc})") from None
    check_tree(obj, where, error, max_depth=max_depth)
    return obj


def check_array(value, where: str, error, *, dtype=np.float64, shape=None,
                finite: bool = True) -> np.ndarray:
    """``value`` as a native-byte-order array of exactly ``dtype`` and ``shape``.

    A non-native byte order of the right type is converted (same values);
    any other dtype (integers where floats are expected, complex, strings,
    float32...) is an error, as are non-finite values and a wrong shape.
    """
    want = np.dtype(dtype)
    if not isinstance(value, np.ndarray):
        raise error(f"{where} is not an array")
    got = value.dtype
    if got.kind != want.kind or got.itemsize != want.itemsize or got.fields is not None:
        raise error(f"{where} has dtype {got.str} ({got}), expected {want}")
    if not got.isnative:
        value = value.astype(got.newbyteorder("="))
    if shape is not None and value.shape != tuple(shape):
        raise error(f"{where} has shape {value.shape}, expected {tuple(shape)}")
    if finite and value.dtype.kind in "fc" and not np.isfinite(value).all():
        raise error(f"{where} holds non-finite values")
    return np.ascontiguousarray(value)
