"""Angle helpers. Bearings are radians, body frame, CCW positive, in [-pi, pi)."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["wrap", "wrap_array", "angle_between", "circular_mean", "side"]

_TWO_PI = 2.0 * math.pi


def wrap(a: float) -> float:
    """Wrap an angle (rad) to [-pi, pi): ((a + pi) mod 2pi) - pi."""
    r = math.fmod(a + math.pi, _TWO_PI)
    if r < 0.0:
        r += _TWO_PI
    r -= math.pi
    # fmod may return exactly 2pi - tiny rounding; keep the interval half-open
    return r if r < math.pi else -math.pi


def wrap_array(a: np.ndarray) -> np.ndarray:
    """Vectorised :func:`wrap`."""
    return np.mod(np.asarray(a, dtype=np.float64) + math.pi, _TWO_PI) - math.pi


def angle_between(theta_j: float, theta_k: float) -> float:
    """theta_{jk} = wrap(theta_k - theta_j): angle at the observer from j to k (rad)."""
    return wrap(theta_k - theta_j)


def side(theta_j: float, theta_k: float) -> int:
    """Sign (+1 CCW, -1 CW, 0 degenerate) of the angle from bearing j to bearing k."""
    a = wrap(theta_k - theta_j)
    return 1 if a > 0.0 else (-1 if a < 0.0 else 0)


def circular_mean(angles) -> tuple[float, float]:
    """Circular mean (rad, wrapped) and mean resultant length in [0, 1] of ``angles``.

    Returns (0.0, 0.0) for an empty input.
    """
    angles = list(angles)
    if not angles:
        return 0.0, 0.0
    s = sum(math.sin(a) for a in angles)
    c = sum(math.cos(a) for a in angles)
    return wrap(math.atan2(s, c)), math.hypot(s, c) / len(angles)
