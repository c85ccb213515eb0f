"""A small TOML writer (the standard library reads TOML but does not write it): one copy
for ``resolved.toml`` (world/config.py), ``swarmcover config defaults`` and docs/config.md
(swarmcover/configref.py). Pure, no I/O."""
from __future__ import annotations

import math
from typing import Any


_BARE = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-")


def toml_key(k: str) -> str:
    if k and all(c in _BARE for c in k):  # str.isalnum would pass non-ASCII digits
        return k
    return toml_value(str(k))


def toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        out = ['"']
        for c in v:
            if c == '"':
                out.append('\\"')
            elif c == "\\":
                out.append("\\\\")
            elif c == "\n":
                out.append("\\n")
            elif c == "\t":
                out.append("\\t")
            elif ord(c) < 0x20 or ord(c) == 0x7F:
                out.append(f"\\u{ord(c):04x}")
            else:
                out.append(c)
        out.append('"')
        return "".join(out)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + "}"
    if v is None:
        raise ValueError("TOML has no null")
    if hasattr(v, "isoformat"):
        return v.isoformat()
    raise ValueError(f"cannot write {type(v).__name__} as TOML")


def dumps_toml(d: dict, _prefix: str = "") -> str:
    """A small TOML writer: scalars and arrays inline, nested tables as [a.b] headers."""
    lines, tables = [], []
    for k, v in d.items():
        if v is None:
            continue
        if isinstance(v, dict):
            tables.append((k, v))
        else:
            lines.append(f"{toml_key(k)} = {toml_value(v)}")
    out = "\n".join(lines)
    for k, v in tables:
        name = f"{_prefix}.{toml_key(k)}" if _prefix else toml_key(k)
        body = dumps_toml(v, name)
        out += ("\n\n" if out else "") + f"[{name}]" + ("\n" + body if body else "")
    return out + ("\n" if not _prefix else "")
