"""Angles: the one ``wrap`` and the one circular mean of the project.

Bearings are radians, CCW positive, wrapped to the half-open interval [-pi, pi). Every
module that wraps an angle imports it from here (a test fails on a second definition).

The interval is half-open, so an angle of exactly pi (a collinear point behind) wraps to
-pi. Code that asks "which side" must not read that as CW: use :func:`side` and
:func:`side_array`, which return 0 for exactly 0 and exactly +-pi.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Iterable

if TYPE_CHECKING:  # numpy is imported by the array functions only: an agent needs none
    import numpy as np

__all__ = ["PI", "TWO_PI", "wrap", "wrap_array", "angle_between", "side", "side_array",
           "circular_mean", "circmean", "resultant"]

PI = math.pi
TWO_PI = 2.0 * math.pi


def wrap(a: float) -> float:
    """Angle (rad) wrapped to [-pi, pi). Exactly pi (and -pi) give -pi; an angle already in
    range comes back unchanged (bit for bit)."""
    if -PI <= a < PI:
        return a
    r = math.fmod(a + PI, TWO_PI)
    if r < 0.0:
        r += TWO_PI
    r -= PI
    # fmod (or the += above, for tiny negative r) may round to exactly pi: keep it half-open
    return r if r < PI else -PI


def wrap_array(a) -> np.ndarray:
    """Vectorised :func:`wrap` (same values, element by element), float64 array out."""
    import numpy as np
    a = np.asarray(a, dtype=np.float64)
    r = np.where((a >= -PI) & (a < PI), a, np.mod(a + PI, TWO_PI) - PI)
    # np.mod of a tiny negative number rounds to 2pi: keep the interval half-open
    return np.where(r >= PI, -PI, r)


def angle_between(theta_j: float, theta_k: float) -> float:
    """theta_{jk} = wrap(theta_k - theta_j): the angle at the observer from j to k (rad)."""
    return wrap(theta_k - theta_j)


def side(a: float) -> int:
    """Side of a (wrapped or not) angle: +1 CCW, -1 CW, 0 for exactly 0 or +-pi (collinear)."""
    w = wrap(a)
    return 0 if (w == 0.0 or w == -PI) else (1 if w > 0.0 else -1)


def side_array(a) -> np.ndarray:
    """Vectorised :func:`side` (int64): 0 where the wrapped angle is exactly 0 or -pi."""
    import numpy as np
    w = wrap_array(a)
    s = np.sign(w).astype(np.int64)
    s[w == -PI] = 0
    return s


def circular_mean(angles: Iterable[float]) -> tuple[float, float]:
    """Circular mean (rad, wrapped) and mean resultant length in [0, 1] of ``angles``.

    (0.0, 0.0) for an empty input; the mean is 0.0 when the angles cancel exactly.
    """
    a = angles if isinstance(angles, (list, tuple)) else list(angles)
    n = len(a)
    if n == 0:
        return 0.0, 0.0
    s = sum(map(math.sin, a))   # left to right from 0, as a loop would add them
    c = sum(map(math.cos, a))
    return wrap(math.atan2(s, c)), math.hypot(s, c) / n


def circmean(angles: Iterable[float]) -> float | None:
    """Circular mean (rad, wrapped), or None if ``angles`` is empty or they cancel out."""
    a = angles if isinstance(angles, (list, tuple)) else list(angles)
    mean, r = circular_mean(a)
    return None if r * len(a) < 1e-9 else mean


def resultant(angles: Iterable[float]) -> float:
    """Mean resultant length in [0, 1] (1: all equal, ~0: spread evenly); 0 if empty."""
    return circular_mean(angles)[1]


def bearing_spread(angles: Iterable[float]) -> float:
    """How well landmarks seen at these bearings (rad) fix the observer's position: the
    determinant of the sum of the bearings' unit normals' outer products, which is the sum
    over pairs of sin^2 of their difference. 0 when all lie on one line (one bearing, or
    opposite ones: a step along that line changes none of them); 0.25 for two bearings
    30 deg apart; 0.75 for two 60 deg apart; 2.25 for three 120 deg apart."""
    sxx = syy = sxy = 0.0
    for a in angles:             # O(n): robots evaluate it every tick while homing
        s, c = math.sin(a), math.cos(a)
        sxx += s * s
        syy += c * c
        sxy += s * c
    return max(0.0, sxx * syy - sxy * sxy)
