"""Config validation in one style, for every section of a run config and every flag.

An error is a :class:`ConfigError` (a ``ValueError``) carrying ``file``, ``section``,
``field`` and ``value``; its message is one line::

    configs/x.toml: [coordinator] settle_s = nan: not finite

:class:`Checker` holds the value checks every section uses (numbers are finite and in a
range, integers are not bools, choices, tables, points, simple polygons, unknown keys), and
:func:`check_fields` validates a raw section dict against a frozen dataclass's fields, the
way ``bus/messages.py`` validates a message against its field specs. Pure, no I/O.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Iterable, Mapping

from swarmcover.ground.geometry import signed_area

# numpy is imported inside the polygon check only (self_crossing and its helpers): agents
# import this module for their [agent] section and must not pay for numpy (issue 18).


class ConfigError(ValueError):
    """A bad run config or flag. The message names file, section, field and value."""

    def __init__(self, file: str, section: str = "", fieldname: str = "", value: Any = None,
                 reason: str = ""):
        self.file, self.section, self.field, self.value = file, section, fieldname, value
        self.reason = reason
        where = f"[{section}] " if section else ""
        shown = repr(value)
        if len(shown) > 120:
            shown = shown[:117] + "..."
        what = f"{where}{fieldname} = {shown}" if fieldname else where.strip()
        if not (section or fieldname or reason):
            super().__init__(file)     # a whole message, e.g. ConfigError("x.toml: ...")
        else:
            super().__init__(f"{file}: {what}: {reason}" if what else f"{file}: {reason}")


def _rng(lo, hi, lo_open: bool, hi_open: bool) -> str:
    return f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


class Checker:
    """Value checks for one section of one file; every failure is a ConfigError."""

    def __init__(self, file: str, section: str):
        self.file, self.section = file, section

    def err(self, name: str, value: Any, reason: str) -> ConfigError:
        return ConfigError(self.file, self.section, name, value, reason)

    def num(self, name: str, v: Any, lo: float = -math.inf, hi: float = math.inf,
            lo_open: bool = False, hi_open: bool = False) -> float:
        """A finite number in [lo, hi] (open ends as asked); ints become floats."""
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.err(name, v, "expected a number")
        v = float(v)
        if not math.isfinite(v):
            raise self.err(name, v, "not finite")
        if v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
            raise self.err(name, v, f"outside {_rng(lo, hi, lo_open, hi_open)}")
        return v

    def int_(self, name: str, v: Any, lo: int = -(2**62), hi: int = 2**62) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.err(name, v, "expected an integer")
        if v < lo or v > hi:
            raise self.err(name, v, f"outside [{lo}, {hi}]")
        return v

    def bool_(self, name: str, v: Any) -> bool:
        if not isinstance(v, bool):
            raise self.err(name, v, "expected true or false")
        return v

    def str_(self, name: str, v: Any, maxlen: int = 1000) -> str:
        if not isinstance(v, str):
            raise self.err(name, v, "expected a string")
        if len(v) > maxlen:
            raise self.err(name, v, f"longer than {maxlen} characters")
        return v

    def choice(self, name: str, v: Any, choices: Iterable[str]) -> str:
        choices = tuple(choices)
        if not isinstance(v, str) or v not in choices:
            raise self.err(name, v, f"expected one of {', '.join(choices)}")
        return v

    def table(self, name: str, v: Any) -> dict:
        if not isinstance(v, dict):
            raise self.err(name, v, "expected a table")
        return v

    def point(self, name: str, v: Any, lim: float = 1e6) -> tuple:
        if not isinstance(v, (list, tuple)) or len(v) != 2:
            raise self.err(name, v, "expected a point [x, y]")
        return (self.num(name, v[0], -lim, lim), self.num(name, v[1], -lim, lim))

    def polygon(self, name: str, v: Any, lim: float = 1e6) -> tuple:
        """At least 3 points, non-zero area, and simple (no edge crosses another)."""
        if not isinstance(v, (list, tuple)) or len(v) < 3:
            raise self.err(name, v, "expected a polygon: a list of at least 3 points [x, y]")
        pts = tuple(self.point(f"{name}[{k}]", p, lim) for k, p in enumerate(v))
        bad = self_crossing(pts)
        if bad is not None:
            i, j = bad
            raise self.err(name, v, f"not a simple polygon: edge {i} ({i}-{(i + 1) % len(pts)}) "
                                    f"meets edge {j} ({j}-{(j + 1) % len(pts)})")
        if abs(signed_area(pts)) < 1e-12:
            raise self.err(name, v, "polygon has zero area")
        return pts

    def unknown(self, d: Mapping, allowed: Iterable[str], hint: Mapping[str, str] | None = None):
        """Refuse the first key of d that is not allowed."""
        allowed = set(allowed)
        for k in d:
            if k not in allowed:
                extra = (hint or {}).get(k, "")
                raise self.err(k, d[k], f"unknown field{extra} (known: "
                                        f"{', '.join(sorted(allowed))})")


# --------------------------------------------------------------------------- geometry

def self_crossing(pts, chunk: int = 256) -> tuple[int, int] | None:
    """A pair (i, j), i < j, of non-adjacent edges of the closed ring ``pts`` that meet
    (touching counts), or None if the polygon is simple. Adjacent edges that fold back onto
    each other (collinear overlap) also count. Vectorised: edges sorted by their left end,
    each chunk compared only with the edges whose x-range can overlap it."""
    import numpy as np
    p = np.asarray(pts, float).reshape(-1, 2)
    n = len(p)
    if n < 3:
        return None
    a, b = p, np.roll(p, -1, axis=0)
    xmin, xmax = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
    order = np.argsort(xmin, kind="stable")
    xs = xmin[order]
    for s in range(0, n, chunk):
        rows = order[s:s + chunk]
        stop = int(np.searchsorted(xs, xmax[rows].max(), side="right"))
        cols = order[s:stop]
        i, j = rows[:, None], cols[None, :]
        pa, pb = a[rows][:, None, :], b[rows][:, None, :]
        qa, qb = a[cols][None, :, :], b[cols][None, :, :]
        adjacent = (j == (i + 1) % n) | (i == (j + 1) % n)
        bad = (_meet(pa, pb, qa, qb) & ~adjacent) | (adjacent & _collinear_overlap(pa, pb, qa, qb))
        bad &= i != j
        if bad.any():
            r, c = np.argwhere(bad)[0]
            e1, e2 = int(rows[r]), int(cols[c])
            return min(e1, e2), max(e1, e2)
    return None


def _cross(o, a, b):
    return (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - \
        (a[..., 1] - o[..., 1]) * (b[..., 0] - o[..., 0])


def _on_seg(p, q, r):
    """q on the bounding box of p-r (used once collinear)."""
    import numpy as np
    return ((np.minimum(p[..., 0], r[..., 0]) <= q[..., 0]) &
            (q[..., 0] <= np.maximum(p[..., 0], r[..., 0])) &
            (np.minimum(p[..., 1], r[..., 1]) <= q[..., 1]) &
            (q[..., 1] <= np.maximum(p[..., 1], r[..., 1])))


def _meet(p1, p2, q1, q2):
    d1, d2 = _cross(q1, q2, p1), _cross(q1, q2, p2)
    d3, d4 = _cross(p1, p2, q1), _cross(p1, p2, q2)
    proper = (((d1 > 0) & (d2 < 0)) | ((d1 < 0) & (d2 > 0))) & \
             (((d3 > 0) & (d4 < 0)) | ((d3 < 0) & (d4 > 0)))
    touch = ((d1 == 0) & _on_seg(q1, p1, q2)) | ((d2 == 0) & _on_seg(q1, p2, q2)) | \
            ((d3 == 0) & _on_seg(p1, q1, p2)) | ((d4 == 0) & _on_seg(p1, q2, p2))
    return proper | touch


def _collinear_overlap(p1, p2, q1, q2):
    """Collinear segments sharing more than one point."""
    import numpy as np
    col = (_cross(p1, p2, q1) == 0) & (_cross(p1, p2, q2) == 0)
    d = p2 - p1
    L = np.maximum((d * d).sum(-1), 1e-300)
    t1 = ((q1 - p1) * d).sum(-1) / L
    t2 = ((q2 - p1) * d).sum(-1) / L
    lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
    return col & (np.minimum(hi, 1.0) - np.maximum(lo, 0.0) > 1e-12)


# --------------------------------------------------------------------------- dataclasses

def check_fields(cls, d: Mapping | None, file: str, section: str, *,
                 bounds: Mapping[str, tuple] | None = None,
                 choices: Mapping[str, Iterable[str]] | None = None,
                 skip: Iterable[str] = (), hint: Mapping[str, str] | None = None) -> dict:
    """Validate a raw section against the fields of dataclass ``cls``: unknown keys (and
    ``skip``ped ones) are refused, each value must have its default's type (an int is
    accepted for a float), floats must be finite, and ``bounds[name] = (lo, hi)`` or
    ``(lo, hi, lo_open, hi_open)`` and ``choices[name]`` are enforced. Returns the coerced
    values, ready for ``cls(**values)``."""
    ck = Checker(file, section)
    if d is None:
        d = {}
    if not isinstance(d, Mapping):
        raise ConfigError(file, section, "", d, "expected a table")
    flds = {f.name: f for f in dataclasses.fields(cls)}
    skip = set(skip)
    ck.unknown(d, set(flds) - skip, hint)
    bounds, choices = bounds or {}, choices or {}
    out = {}
    for name, v in d.items():
        f = flds[name]
        default = f.default if f.default is not dataclasses.MISSING else None
        b = tuple(bounds.get(name, ()))
        if isinstance(default, bool):
            out[name] = ck.bool_(name, v)
        elif isinstance(default, int):
            lo, hi = (b[0], b[1]) if b else (-(2**62), 2**62)
            out[name] = ck.int_(name, v, lo, hi)
        elif isinstance(default, float):
            lo, hi, lo_open, hi_open = (b + (False, False))[:4] if b else (
                -math.inf, math.inf, False, False)
            out[name] = ck.num(name, v, lo, hi, lo_open, hi_open)
        elif isinstance(default, str):
            if name in choices:
                out[name] = ck.choice(name, v, choices[name])
            else:
                out[name] = ck.str_(name, v)
        else:
            out[name] = v
    return out
