"""Twin-sync quality metrics (pure): tracking error, mocap-to-twin lag, formation discrepancy.

  * tracking error: distance (m) and heading difference (rad) between a live robot's mocap
    pose and its twin's pose, both taken at the bridge's receipt time (the mocap pose is
    interpolated to the twin sample's receipt time);
  * mocap-to-twin lag (s): the delay tau that best aligns the twin trajectory with the
    mocap trajectory, p_twin(t) ~ p_mocap(t - tau) (least squares over a grid); it lumps
    transport, world tick and P-control lag together;
  * formation discrepancy (spec 8, the thesis's dashed lines): for every ordered pair
    (i, j) with i live and j within rv of i in the simulation, |wrap(b_real - b_sim)|,
    where b is the bearing from i to j in i's body frame, computed from the real poses
    (mocap for live robots, simulation for virtual ones) and from the simulated poses.
"""
from __future__ import annotations

import bisect
import math
from collections import deque
from typing import Iterable, Sequence

from swarmcover.ground.angles import wrap


def percentile(xs: Sequence[float], p: float) -> float:
    """Linear-interpolated percentile (p in [0, 100]); nan for an empty list."""
    if not xs:
        return math.nan
    s = sorted(xs)
    k = (len(s) - 1) * p / 100.0
    lo = math.floor(k)
    hi = min(lo + 1, len(s) - 1)
    return s[lo] + (s[hi] - s[lo]) * (k - lo)


def summary(xs: Sequence[float]) -> dict:
    """{n, mean, p95, max} of a sample (nan when empty)."""
    xs = list(xs)
    if not xs:
        return {"n": 0, "mean": math.nan, "p95": math.nan, "max": math.nan}
    return {"n": len(xs), "mean": sum(xs) / len(xs), "p95": percentile(xs, 95), "max": max(xs)}


def interp_pose(ts: Sequence[float], poses: Sequence[tuple], t: float) -> tuple | None:
    """Pose at time ``t`` by linear interpolation (heading on the circle); None outside."""
    if not ts or t < ts[0] or t > ts[-1]:
        return None
    k = bisect.bisect_left(ts, t)
    if ts[k] == t or k == 0:
        return poses[k]
    t0, t1 = ts[k - 1], ts[k]
    a, b = poses[k - 1], poses[k]
    f = (t - t0) / (t1 - t0) if t1 > t0 else 0.0
    return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), wrap(a[2] + f * wrap(b[2] - a[2])))


def estimate_lag(tm: Sequence[float], pm: Sequence[tuple], tt: Sequence[float],
                 pt: Sequence[tuple], max_lag: float = 1.0, step: float = 0.005) -> float:
    """Delay (s) in [0, max_lag] minimising the mean squared position difference between
    the twin samples (tt, pt) and the mocap trajectory (tm, pm) shifted by the delay.
    nan if the trajectories do not overlap."""
    best, best_tau = math.inf, math.nan
    n = int(round(max_lag / step))
    for k in range(n + 1):
        tau = k * step
        err, cnt = 0.0, 0
        for t, p in zip(tt, pt):
            q = interp_pose(tm, pm, t - tau)
            if q is not None:
                err += (p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2
                cnt += 1
        if cnt >= max(3, len(tt) // 4) and err / cnt < best:
            best, best_tau = err / cnt, tau
    return best_tau


def bearing(frm: tuple, to: tuple) -> float:
    """Bearing (rad) of ``to`` in the body frame of ``frm`` (both x, y, theta)."""
    return wrap(math.atan2(to[1] - frm[1], to[0] - frm[0]) - frm[2])


def formation_discrepancy(real: dict[int, tuple], sim: dict[int, tuple],
                          live: Iterable[int], rv: float) -> list[float]:
    """|wrap(b_real - b_sim)| (rad) for each ordered pair (live i, any j within rv in sim)."""
    out = []
    for i in live:
        if i not in real or i not in sim:
            continue
        for j, pj in sim.items():
            if j == i or j not in real:
                continue
            if math.hypot(pj[0] - sim[i][0], pj[1] - sim[i][1]) > rv:
                continue
            out.append(abs(wrap(bearing(real[i], real[j]) - bearing(sim[i], pj))))
    return out


class TrackLog:
    """Per live robot, the recent mocap and twin trajectories (receipt times) and the errors.

    ``settle_s``: errors are only counted once a robot has been synced this long (after its
    first twin sample), and not within ``settle_s`` after a teleport.
    """

    def __init__(self, horizon_s: float = 30.0, settle_s: float = 1.0):
        self.horizon = horizon_s
        self.settle = settle_s
        self.mocap: dict[int, deque] = {}
        self.twin: dict[int, deque] = {}
        self.pos_err: dict[int, list] = {}
        self.head_err: dict[int, list] = {}
        self.since: dict[int, float] = {}
        self.teleports: dict[int, int] = {}
        self.lags: dict[int, list] = {}

    def on_mocap(self, rid: int, now: float, pose: tuple) -> None:
        d = self.mocap.setdefault(rid, deque())
        d.append((now, pose))
        while d and d[0][0] < now - self.horizon:
            d.popleft()

    def on_teleport(self, rid: int, now: float) -> None:
        self.teleports[rid] = self.teleports.get(rid, 0) + 1
        self.since[rid] = now

    def on_twin(self, rid: int, now: float, pose: tuple) -> None:
        d = self.twin.setdefault(rid, deque())
        d.append((now, pose))
        while d and d[0][0] < now - self.horizon:
            d.popleft()
        self.since.setdefault(rid, now)
        if now - self.since[rid] < self.settle:
            return
        m = self.mocap.get(rid)
        if not m:
            return
        ts = [t for t, _ in m]
        q = interp_pose(ts, [p for _, p in m], now)
        if q is None:
            q = m[-1][1] if now - m[-1][0] < 0.2 else None
        if q is None:
            return
        self.pos_err.setdefault(rid, []).append(math.hypot(pose[0] - q[0], pose[1] - q[1]))
        self.head_err.setdefault(rid, []).append(abs(wrap(pose[2] - q[2])))

    def lag(self, rid: int, max_lag: float = 1.0) -> float:
        m, w = self.mocap.get(rid), self.twin.get(rid)
        if not m or not w:
            return math.nan
        kept = [(t, p) for t, p in w if t - w[0][0] >= self.settle]
        kept = kept[::max(1, len(kept) // 300)]          # bound the cost
        return estimate_lag([t for t, _ in m], [p for _, p in m], [t for t, _ in kept],
                            [p for _, p in kept], max_lag)

    def report(self) -> dict:
        out = {}
        for rid in sorted(set(self.mocap) | set(self.twin)):
            out[str(rid)] = {
                "position_error_m": summary(self.pos_err.get(rid, [])),
                "heading_error_rad": summary(self.head_err.get(rid, [])),
                "teleports": self.teleports.get(rid, 0),
                "lag_s": self.lag(rid),
            }
        return out
