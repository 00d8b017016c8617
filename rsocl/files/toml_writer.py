"""A minimal TOML writer: what rig files need (tomllib, which reads them, cannot write).

Tables, arrays of tables, strings, integers, floats (``inf``, ``nan``), booleans, lists and
inline tables, NumPy scalars and arrays. TOML has no null: keys whose value is None are left out.
"""

from __future__ import annotations

import math
import numbers
import os
import re

import numpy as np

__all__ = ["dumps_toml"]

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")
_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _toml_string(text: str) -> str:
    out = []
    for ch in text:
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _toml_key(key) -> str:
    if not isinstance(key, str):
        raise ValueError(f"TOML keys must be strings, got {key!r}")
    return key if _BARE.match(key) else _toml_string(key)


def _toml_value(value, where) -> str:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        value = float(value)
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, (str, os.PathLike)):
        return _toml_string(os.fspath(value))
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v, f"{where}[{j}]") for j, v in enumerate(value)) + "]"
    if isinstance(value, dict):
        items = [f"{_toml_key(k)} = {_toml_value(v, f'{where}.{k}')}" for k, v in value.items() if v is not None]
        return "{" + ", ".join(items) + "}" if items else "{}"
    if value is None:
        raise ValueError(f"{where}: TOML has no null; leave the key out instead of None")
    raise ValueError(f"{where}: cannot write a {type(value).__name__} to TOML ({value!r})")


def _is_table(value):
    return isinstance(value, dict)


def _is_table_array(value):
    return isinstance(value, (list, tuple)) and bool(value) and all(isinstance(v, dict) for v in value)


def _write_table(lines, header, table, array=False):
    scalars = [(k, v) for k, v in table.items() if v is not None and not _is_table(v) and not _is_table_array(v)]
    if header is not None:
        if lines:
            lines.append("")
        lines.append(f"[[{header}]]" if array else f"[{header}]")
    for key, value in scalars:
        lines.append(f"{_toml_key(key)} = {_toml_value(value, (header + '.' if header else '') + str(key))}")
    for key, value in table.items():
        name = _toml_key(key) if header is None else f"{header}.{_toml_key(key)}"
        if _is_table(value):
            _write_table(lines, name, value)
        elif _is_table_array(value):
            for item in value:
                _write_table(lines, name, item, array=True)


def dumps_toml(data: dict) -> str:
    """TOML text of ``data`` (nested dicts become tables, lists of dicts arrays of tables).

    Supports str, int, float (including inf and nan), bool, lists, dicts and
    NumPy scalars/arrays; keys whose value is None are left out. The output
    reads back with :mod:`tomllib` to equal data (tuples become lists).
    """
    if not isinstance(data, dict):
        raise ValueError(f"data must be a dict, got {type(data).__name__}")
    lines: list[str] = []
    _write_table(lines, None, data)
    return "\n".join(lines) + "\n"
