"""Which robots a lockstep world senses this tick, so that idle robots cost (almost) nothing.

Pure: ids, positions and headings in, a mask out; no I/O, no clock but the tick.

A robot's view (the bearings and identities it sees, its touch) is a function of its own
pose and the poses of the robots near it: the walls never move. So a robot that holds still
with nothing to do (its agent said ``idle`` in its last command) learns nothing new from a
Sense unless it, or some robot near it, moved. :class:`WakeRule` senses such a robot only

* while it or any body within ``reach`` (rv plus the farthest a body moves in one sensing
  period, so that a robot leaving its view is still near it on the tick it leaves) moved
  within the last ``wake_ticks`` sensing ticks: every change of its view reaches it on the
  tick it happens, and its bearing windows fill with still samples after the motion ends;
* on the tick a body near it appeared or was removed (and ``wake_ticks`` after);
* when the caller says so (a task announced to it, a Status asked for, a joining agent);
* and once every ``keepalive_ticks`` sensing ticks, staggered by robot id, so an agent
  that hangs is still noticed by the lockstep gate and its statuses never grow old.

Every other robot (not idle, or not in the lockstep roster: live twins, bodies whose agent
has not answered yet) is sensed on every sensing tick, as before. The world still computes
every robot's sensing each tick (the noise draws stay in the same order, so a run is the
same whichever robots were sensed); what idle robots save is the message, the agent's wake-up
and its answer, and the lockstep wait for it.

Motion is measured between consecutive calls: a body moved if its position changed by more
than ``eps_pos`` (m) or its heading by more than ``eps_th`` (rad). A body at rest in
pymunk (zero commanded velocity) stays exactly where it is, so any motion at all is a push
or a command.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from swarmcover.ground.angles import wrap_array

__all__ = ["WakeRule", "wake_params"]


def wake_params(rv: float, v_max: float, dt: float, sense_every: int, keepalive_s: float,
                wake_s: float) -> dict:
    """WakeRule's arguments from a run's values (m, m/s, s): reach = rv plus twice the
    farthest a body can move in one sensing period (a margin for pushes)."""
    period = dt * max(1, sense_every)
    return dict(reach=rv + max(2.0 * v_max * period, 0.02 * rv),
                wake_ticks=max(1, math.ceil(wake_s / period - 1e-9)),
                keepalive_ticks=max(1, round(keepalive_s / period)))


def _members(ida: np.ndarray, ids) -> np.ndarray:
    """Which of the sorted ids ``ida`` are in the set ``ids`` (a bool mask)."""
    out = np.zeros(len(ida), bool)
    if ids and len(ida):
        q = np.fromiter(ids, np.int64, len(ids))
        j = np.minimum(np.searchsorted(ida, q), len(ida) - 1)
        out[j[ida[j] == q]] = True
    return out


class WakeRule:
    """Decides, per sensing tick, which robots get a Sense (see the module docstring).

    reach: m; wake_ticks, keepalive_ticks: sensing ticks; eps_pos: m; eps_th: rad."""

    def __init__(self, reach: float, wake_ticks: int, keepalive_ticks: int,
                 eps_pos: float = 1e-6, eps_th: float = 1e-6):
        self.reach = float(reach)
        self.wake_ticks = int(wake_ticks)
        self.keepalive = max(1, int(keepalive_ticks))
        self.eps_pos = float(eps_pos)
        self.eps_th = float(eps_th)
        self._ids = np.zeros(0, np.int64)           # the previous call's ids, sorted
        self._pos = np.zeros((0, 2))
        self._th = np.zeros(0)
        self._moved = np.zeros(0, np.int64)         # per id: last sensing tick it moved
        self._events: list[tuple[int, float, float]] = []   # (tick, x, y) of removals

    def due(self, k: int, ids, pos: np.ndarray, th: np.ndarray, idle, wake) -> np.ndarray:
        """The robots to sense at sensing tick ``k`` (tick // sense_every), as a bool mask
        over ``ids`` (sorted robot ids; ``pos`` (n, 2) m and ``th`` (n,) rad in that order).
        ``idle``: ids whose agent said idle and that the rule may skip (the caller leaves
        out robots outside the lockstep roster); ``wake``: ids that must be sensed now
        whatever they do. Call once per sensing tick, in order."""
        ida = np.asarray(ids, np.int64)
        pos = np.asarray(pos, float).reshape(-1, 2)
        th = np.asarray(th, float).reshape(-1)
        moved = self._track(k, ida, pos, th)
        recent = moved >= k - self.wake_ticks
        centres = [pos[recent]]
        self._events = [e for e in self._events if e[0] >= k - self.wake_ticks]
        if self._events:
            centres.append(np.array([(x, y) for _, x, y in self._events]))
        c = np.concatenate(centres) if centres else np.zeros((0, 2))
        n = len(ida)
        awake = np.zeros(n, bool)
        if len(c) and n:
            hits = cKDTree(pos).query_ball_point(c, self.reach)
            near = [i for h in hits for i in h]
            if near:
                awake[np.asarray(near, np.int64)] = True
        awake |= ~_members(ida, idle)
        if wake:
            awake |= _members(ida, wake)
        awake |= (ida + k) % self.keepalive == 0
        return awake

    def _track(self, k: int, ida: np.ndarray, pos: np.ndarray, th: np.ndarray) -> np.ndarray:
        """Per id of ``ida``, the last sensing tick it moved (a new body: now); removed
        bodies become events at their last position."""
        old = self._ids
        if len(old) == len(ida) and np.array_equal(old, ida):
            moved = self._moved.copy()
            d = (np.abs(pos - self._pos) > self.eps_pos).any(axis=1)
            d |= np.abs(wrap_array(th - self._th)) > self.eps_th
            moved[d] = k
        else:
            moved = np.full(len(ida), k, np.int64)           # new bodies count as moved
            j = np.searchsorted(old, ida)
            jc = np.minimum(j, max(len(old) - 1, 0))
            same = (j < len(old)) & (old[jc] == ida) if len(old) else np.zeros(len(ida), bool)
            if same.any():
                jj = jc[same]
                d = (np.abs(pos[same] - self._pos[jj]) > self.eps_pos).any(axis=1)
                d |= np.abs(wrap_array(th[same] - self._th[jj])) > self.eps_th
                moved[same] = np.where(d, k, self._moved[jj])
            gone = ~np.isin(old, ida)
            for x, y in self._pos[gone]:
                self._events.append((k, float(x), float(y)))
        self._ids, self._pos, self._th, self._moved = ida, pos.copy(), th.copy(), moved
        return moved
