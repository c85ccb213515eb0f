"""A scripted stand-in run: publishes what world/ and coordinator/ publish, on the real keys.

For tests and demos of record/replay/plot/view while (or without) the real processes:
a 6 m x 4 m room with one obstacle, robots added one per deployment cycle on a hexagonal
lattice grown from the source (robot ``c`` drives out during cycle ``c`` and joins the
complex at cycle ``c+1``), a Rips complex over the placed robots with frontier (K) and
obstacle (O) edges, one redundant vertex from cycle 8 on, and robot 1 the twin of a live
robot whose "mocap" pose is published on ``robot/1/odom`` (source "mocap").

    python -m viz.synth --connect tcp/127.0.0.1:7447 --swarm demo --cycles 20 --hold 60

Publishes: world/info (queryable), world/truth every tick, world/clock, coord/complex
each cycle, robot/<live>/odom; liveliness alive/world/main, alive/coordinator/main and
alive/robot/<id> for each robot present. ``--kill C:R`` removes robot R at cycle C (its
body and token go together).
"""
from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from swarmcover.bus import messages as m

ROOM = (6.0, 4.0)
OBSTACLE = [2.6, 1.4, 3.3, 1.4, 3.3, 2.5, 2.6, 2.5]
SOURCE = (0.4, 2.0, 0.0)


def synth_info(name: str = "synthetic", rv: float = 1.0) -> m.WorldInfo:
    """The WorldInfo of the scripted room."""
    w, h = ROOM
    config = (f'name = "{name}"\nrv = {rv}\n\n[map]\nboundary = [[0,0],[{w},0],[{w},{h}],[0,{h}]]\n'
              'obstacles = [ {type="rect", min=[2.6,1.4], max=[3.3,2.5]} ]\n'
              f'sources = [ {{x={SOURCE[0]}, y={SOURCE[1]}, theta=0.0}} ]\n')
    return m.WorldInfo(name=name, rv=rv, robot_radius=0.06, dt=0.05, mode="realtime", seed=0,
                       boundary=[0.0, 0.0, w, 0.0, w, h, 0.0, h], obstacles=[list(OBSTACLE)],
                       sources=list(SOURCE), free_area=w * h - 0.7 * 1.1, config=config)


def _inside_obstacle(p, pad: float) -> bool:
    return 2.6 - pad <= p[0] <= 3.3 + pad and 1.4 - pad <= p[1] <= 2.5 + pad


def _wall_dist(p) -> float:
    w, h = ROOM
    d = min(p[0], p[1], w - p[0], h - p[1])
    dx = max(2.6 - p[0], 0.0, p[0] - 3.3)
    dy = max(1.4 - p[1], 0.0, p[1] - 2.5)
    return min(d, math.hypot(dx, dy))


def lattice(spacing: float, n: int) -> np.ndarray:
    """The first ``n`` free hexagonal-lattice points, nearest the source first (m)."""
    w, h = ROOM
    pts = []
    for j in range(-12, 13):
        for i in range(-2, 20):
            x = SOURCE[0] + spacing * (i + 0.5 * (j % 2))
            y = SOURCE[1] + spacing * math.sqrt(3) / 2 * j
            if 0.15 <= x <= w - 0.15 and 0.15 <= y <= h - 0.15 and not _inside_obstacle((x, y), 0.15):
                pts.append((x, y))
    pts.sort(key=lambda p: (round(math.hypot(p[0] - SOURCE[0], p[1] - SOURCE[1]), 6), p[1], p[0]))
    return np.asarray(pts[:n], float)


class Scenario:
    """Deterministic positions and complexes per cycle (no I/O).

    n_max: robots at most; kills: {cycle: [robot ids]} removed from that cycle on;
    live: ids of robots that are twins of live robots.
    """

    def __init__(self, n_max: int = 24, rv: float = 1.0, kills: dict | None = None,
                 live: tuple[int, ...] = (1,)):
        self.info = synth_info(rv=rv)
        self.rv = rv
        self.targets = lattice(0.8 * rv, n_max)
        self.n_max = len(self.targets)
        self.kills = {int(c): set(rs) for c, rs in (kills or {}).items()}
        self.live = set(live)

    def dead(self, cycle: int) -> set:
        return set().union(*[rs for c, rs in self.kills.items() if c <= cycle])

    def present(self, cycle: int) -> list[int]:
        """Robot ids with a body during ``cycle`` (placed ones and the one driving out)."""
        return [k for k in range(min(cycle + 1, self.n_max)) if k not in self.dead(cycle)]

    def placed(self, cycle: int) -> list[int]:
        return [k for k in self.present(cycle) if k < cycle]

    def position(self, k: int, cycle: int, frac: float, t: float) -> tuple[float, float]:
        tx, ty = self.targets[k]
        if k == cycle:  # driving out from the source
            f = min(1.0, max(0.0, frac))
            tx, ty = SOURCE[0] + f * (tx - SOURCE[0]), SOURCE[1] + f * (ty - SOURCE[1])
        wig = 0.01 * math.sin(3.0 * t + k)
        return float(tx + wig), float(ty - wig)

    def truth(self, cycle: int, frac: float, tick: int, t: float) -> m.Truth:
        ids = self.present(cycle)
        xy = [self.position(k, cycle, frac, t) for k in ids]
        return m.Truth(tick=tick, t=t, ids=ids, x=[p[0] for p in xy], y=[p[1] for p in xy],
                       theta=[0.0] * len(ids), live=[k in self.live for k in ids])

    def mocap(self, cycle: int, frac: float, t: float) -> dict[int, tuple[float, float]]:
        out = {}
        for k in self.present(cycle):
            if k in self.live:
                x, y = self.position(k, cycle, frac, t)
                out[k] = (x + 0.05, y - 0.04)
        return out

    def complex(self, cycle: int, t: float) -> m.Complex:
        ids = self.placed(cycle)
        pos = {k: self.targets[k] for k in ids}
        verts = [100 + k for k in ids]
        edges, tris = [], []
        near = lambda a, b: float(np.hypot(*(pos[a] - pos[b]))) <= self.rv  # noqa: E731
        for i, a in enumerate(ids):
            for b in ids[i + 1:]:
                if near(a, b):
                    edges.append((a, b))
        eset = set(edges)
        for (a, b) in edges:
            for c in ids:
                if c > b and (a, c) in eset and (b, c) in eset:
                    tris.append((a, b, c))
        ntri = {e: 0 for e in edges}
        for a, b, c in tris:
            for e in ((a, b), (a, c), (b, c)):
                ntri[e] += 1
        frontier, obstacle = [], []
        for k, e in enumerate(edges):
            if ntri[e] <= 1:
                mid = (pos[e[0]] + pos[e[1]]) / 2
                (obstacle if _wall_dist(mid) < 0.5 * self.rv else frontier).append(k)
        redundant = [100 + 2] if cycle >= 8 and 2 in ids else []
        flat = [100 + v for e in edges for v in e]
        return m.Complex(cycle=cycle, t=t, epoch=0, vertices=verts, occupants=list(ids),
                         edges=flat, triangles=[100 + v for tr in tris for v in tr],
                         frontier=frontier, obstacle=obstacle, redundant=redundant,
                         sources=[100] if 0 in ids else [], certified=False,
                         robots=len(self.present(cycle)), state="running")


def _parse_kills(items: list[str]) -> dict:
    kills: dict[int, list[int]] = {}
    for it in items:
        try:
            c, r = (int(v) for v in it.split(":"))
        except ValueError:
            raise SystemExit(f"--kill {it!r}: expected CYCLE:ROBOT, e.g. 5:3") from None
        kills.setdefault(c, []).append(r)
    return kills


def main(argv: list[str] | None = None) -> int:
    from swarmcover.bus.keys import Keys
    from swarmcover.bus.session import (Shutdown, add_zenoh_args, keys_from_args, open_session, publisher,
                             setup_logging)

    p = argparse.ArgumentParser(prog="python -m viz.synth", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cycles", type=int, default=12, help="deployment cycles (default 12)")
    p.add_argument("--robots", type=int, default=24, help="robots at most (default 24)")
    p.add_argument("--cycle-s", type=float, default=0.3, help="wall seconds per cycle (default 0.3)")
    p.add_argument("--tick-hz", type=float, default=20.0, help="Truth rate (default 20)")
    p.add_argument("--hold", type=float, default=0.0, metavar="S",
                   help="after the last cycle keep publishing the final state S seconds")
    p.add_argument("--kill", action="append", default=[], metavar="C:R",
                   help="remove robot R at cycle C (repeatable)")
    p.add_argument("--log-level", default="WARNING")
    add_zenoh_args(p)
    args = p.parse_args(argv)
    setup_logging(args.log_level, "swarmcover.viz.synth")
    keys: Keys = keys_from_args(args)
    sc = Scenario(n_max=args.robots, kills=_parse_kills(args.kill))
    info_bytes = sc.info.encode()
    session = open_session(args)
    decl: list = []
    tokens: dict[int, object] = {}
    try:
        with Shutdown() as stop:
            qable = session.declare_queryable(keys.world_info)
            decl.append(qable)
            pub_truth = publisher(session, keys.truth, block=False)
            pub_clock = publisher(session, keys.clock, block=False)
            from swarmcover.bus.trust import SignedPublisher  # with source_info, as the coordinator's
            pub_cx = SignedPublisher(publisher(session, keys.complex, block=True), None)
            decl += [pub_truth, pub_clock, pub_cx]
            lv = session.liveliness()
            decl += [lv.declare_token(keys.alive("world", "main")),
                     lv.declare_token(keys.alive("coordinator", "main"))]
            print(f"READY synth {keys.prefix}", flush=True)
            dt = 1.0 / args.tick_hz
            t0 = time.monotonic()
            tick = 0
            total_s = args.cycles * args.cycle_s
            last_cycle = -1
            last_cx = -1e9
            while not stop.is_set():
                el = time.monotonic() - t0
                if el > total_s + args.hold:
                    break
                cycle = min(int(el / args.cycle_s), args.cycles - 1)
                frac = (el - cycle * args.cycle_s) / args.cycle_s
                present = set(sc.present(cycle))
                for r in sorted(present - set(tokens)):
                    tokens[r] = lv.declare_token(keys.alive("robot", r))
                for r in sorted(set(tokens) - present):
                    tokens.pop(r).undeclare()
                t_sim = tick * dt
                # during --hold the final complex is repeated each second, so a viewer that
                # joins after the last cycle still gets it (the final state, as the help says)
                if cycle != last_cycle or (el > total_s and el - last_cx >= 1.0):
                    pub_cx.put(sc.complex(cycle, t_sim).encode())
                    last_cycle = cycle
                    last_cx = el
                pub_truth.put(sc.truth(cycle, frac, tick, t_sim).encode())
                pub_clock.put(m.Clock(tick=tick, t=t_sim, mode="realtime", rtf=1.0).encode())
                if tick % max(1, int(args.tick_hz / 5)) == 0:
                    for rid, (x, y) in sc.mocap(cycle, frac, t_sim).items():
                        session.put(keys.odom(rid), m.Pose(robot=rid, t=t_sim, x=x, y=y,
                                                           theta=0.0, source="mocap").encode())
                while (query := qable.try_recv()) is not None:
                    query.reply(keys.world_info, info_bytes)
                    query.drop()
                tick += 1
                stop.wait(max(0.0, t0 + tick * dt - time.monotonic()))
            print("DONE synth", flush=True)
    finally:
        for tok in tokens.values():
            tok.undeclare()
        for d in reversed(decl):
            try:
                d.undeclare()
            except Exception:
                pass
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
