"""Scale benchmark (issue 18): N real agent processes in one large open map, lockstep, most
of them idle and about ten active, against the same swarm with every robot sensed every
tick (``[sensing] idle_keepalive_s = 0``, the baseline) in the same invocation.

    python bench/scale.py                          # N = 100, 250, 500; baseline at N = 100
    python bench/scale.py --n 50 --baseline-n 50 --sim-s 10

Per N it starts a router, ``swarmcover spawn N`` (N agent processes) and a world whose
``[[world.spawn]]`` puts the N bodies on a triangular lattice 0.8 rv apart; the benchmark
itself plays the coordinator over the real interface: it holds the liveliness token, acks
every tick (so the world has it in the lockstep barrier), sends every robot a ``hold`` task
(they then keep their snapshot: idle) and keeps ``--active`` robots driving open loop back
and forth (``deploy`` tasks of 0.4 m along 0 and pi, each sent when the last one is done).
After a warm-up it measures ``--sim-s`` simulated seconds: ticks per wall second, simulated
seconds per wall second (the real-time factor), CPU seconds of the world, the router and the
agents per simulated second, and memory: RSS and PSS sums over the agent processes
(``/proc/<pid>/smaps_rollup``; PSS shares the interpreter's and libraries' pages fairly),
with the world's and router's.

Prints a table and, last, one JSON object. Times are this machine's, loaded as it is: the
ratio against the baseline (same N, same invocation) is the figure to compare.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.agent_memory import memory_mb  # noqa: E402
from bench.common import cpu_seconds, eprint, router_and_starter, wait_line  # noqa: E402

SPACING = 0.8   # lattice spacing (m), rv = 1 m
DIST = 0.4      # an active robot's open-loop leg (m)


def lattice(n: int, spacing: float) -> tuple[list[tuple[float, float]], float]:
    """n points of a triangular lattice filling a square, and the square's side (m)."""
    cols = max(1, math.ceil(math.sqrt(n * 2 / math.sqrt(3))))
    pts = []
    k = 0
    while len(pts) < n:
        row, col = divmod(k, cols)
        pts.append((1.0 + col * spacing + (spacing / 2 if row % 2 else 0.0),
                    1.0 + row * spacing * math.sqrt(3) / 2))
        k += 1
    side = max(max(x for x, _ in pts), max(y for _, y in pts)) + 1.0
    return pts, side


def write_config(path: Path, n: int, keepalive_s: float) -> None:
    pts, side = lattice(n, SPACING)
    lines = ['name = "scale"', "rv = 1.0", "[map]",
             f"boundary = [[0, 0], [{side:.2f}, 0], [{side:.2f}, {side:.2f}], [0, {side:.2f}]]",
             "sources = [{x = 0.5, y = 0.5, theta = 0.0}]",
             "[robots]", "radius = 0.06", 'kind = "holonomic"', "v_max = 0.5",
             "[sensing]", "noise_deg = 0.5", f"idle_keepalive_s = {keepalive_s}",
             "[world]", "dt = 0.05", 'mode = "lockstep"', "seed = 0", "tick_timeout_s = 10.0"]
    for rid, (x, y) in enumerate(pts):
        lines += ["[[world.spawn]]", f"robot = {rid}", f"pose = [{x:.3f}, {y:.3f}, 0.0]"]
    path.write_text("\n".join(lines) + "\n")


class Coordinator:
    """The benchmark's side of the barrier: acks, hold tasks, the active robots' legs."""

    def __init__(self, session, keys, n: int, active: list[int]):
        from swarmcover.bus.session import Mailbox, publisher
        self.s, self.keys, self.n = session, keys, n
        self.mail = Mailbox()
        self.subs = [session.declare_subscriber(keys.clock, self.mail.callback)]
        self.subs += [session.declare_subscriber(keys.status(r), self.mail.callback)
                      for r in active]
        self.ack_pub = publisher(session, keys.coord_ack, block=True)
        self.task_pubs: dict[int, object] = {}
        self.publisher = publisher
        self.active = active
        self.next_id = 1
        self.current: dict[int, int] = {}     # active robot -> task id running
        self.leg: dict[int, int] = {r: 0 for r in active}
        self.token = session.liveliness().declare_token(keys.alive("coordinator", "main"))
        self.held = False
        self.driving = False
        self.legs_done = 0

    def _task(self, rid: int, **kw):
        from swarmcover.bus.messages import Task
        tid = self.next_id
        self.next_id += 1
        pub = self.task_pubs.get(rid)
        if pub is None:
            pub = self.task_pubs[rid] = self.publisher(self.s, self.keys.task(rid), block=True)
        pub.put(Task(task_id=tid, robot=rid, epoch=1, **kw).encode())
        return tid

    def step(self, timeout: float = 0.5):
        """Handle what arrived; ack a new Clock. Returns the Clock acked, or None."""
        from swarmcover.bus.messages import Clock, CoordAck, Status, decode
        item = self.mail.get(timeout)
        if item is None:
            return None
        try:
            m = decode(item[1])
        except Exception:
            return None
        if isinstance(m, Status):
            if self.current.get(m.robot) == m.task_id and m.task_state in ("done", "failed"):
                self.current.pop(m.robot)
                self.legs_done += 1
            return None
        if not isinstance(m, Clock):
            return None
        ack = CoordAck(tick=m.tick)
        if not self.held and len(m.agents) >= self.n:
            self.held = True
            for r in range(self.n):
                ack.task_robots.append(r)
                ack.task_ids.append(self._task(r, kind="hold", vertex=r))
        elif self.driving:
            for r in self.active:
                if r not in self.current:
                    d = math.pi if self.leg[r] % 2 else 0.0
                    self.leg[r] += 1
                    tid = self._task(r, kind="deploy", vertex=r, direction=d, distance=DIST,
                                     timeout_s=30.0)
                    self.current[r] = tid
                    ack.task_robots.append(r)
                    ack.task_ids.append(tid)
        self.ack_pub.put(ack.encode())
        return m

    def close(self):
        for x in self.subs + [self.token, self.ack_pub, *self.task_pubs.values()]:
            try:
                x.undeclare()
            except Exception:
                pass


def measure(n: int, keepalive_s: float, active_n: int, sim_s: float, py: str,
            tmp: Path) -> dict:
    from swarmcover.bus.keys import Keys
    from swarmcover.bus.session import add_zenoh_args, open_session
    conf = tmp / f"scale{n}_{keepalive_s:g}.toml"
    write_config(conf, n, keepalive_s)
    swarm = f"scale{os.getpid()}n{n}k{int(keepalive_s * 10)}"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    with router_and_starter(py, env, str(ROOT)) as (start, ep, router):
        z = ["--connect", ep, "--swarm", swarm]
        t0 = time.monotonic()
        spawn = start([py, "-m", "swarmcover", "spawn", str(n), "--run-config", str(conf),
                       "--log-level", "WARNING", *z])
        pids = []
        while len(pids) < n:
            line = spawn.stdout.readline()
            if not line:
                raise RuntimeError("swarmcover spawn ended early")
            if line.startswith("agent "):
                pids.append(int(line.split()[3]))
        world = start([py, "-m", "swarmcover", "world", str(conf), "--await-coordinator",
                       "900", "--log-level", "WARNING", *z])
        wait_line(world, "READY world", timeout=120)
        ap = argparse.ArgumentParser()
        add_zenoh_args(ap)
        session = open_session(ap.parse_args(z))
        keys = Keys(swarm)
        step = max(1, n // max(1, active_n))
        active = list(range(0, n, step))[:active_n]
        co = Coordinator(session, keys, n, active)
        try:
            clk, held_tick = None, None
            deadline = time.monotonic() + 600 + 2 * n
            while time.monotonic() < deadline:      # every agent in the roster, holding
                c = co.step()
                if c is None:
                    continue
                clk = c
                if co.held and held_tick is None:
                    held_tick = c.tick
                if held_tick is not None and c.tick >= held_tick + 40:   # holds recorded
                    break
            else:
                raise RuntimeError(f"the roster never reached {n} agents")
            startup_s = time.monotonic() - t0
            co.driving = True
            agents_cpu0 = sum(cpu_seconds(p) for p in pids)
            world_cpu0, router_cpu0 = cpu_seconds(world.pid), cpu_seconds(router.pid)
            w0, tick0, t_sim0 = time.monotonic(), clk.tick, clk.t
            sensed_roster = []
            while clk.t - t_sim0 < sim_s:
                c = co.step()
                if c is not None:
                    clk = c
                    sensed_roster.append(len(c.agents))
            wall = time.monotonic() - w0
            ticks = clk.tick - tick0
            agents_cpu = sum(cpu_seconds(p) for p in pids) - agents_cpu0
            world_cpu = cpu_seconds(world.pid) - world_cpu0
            router_cpu = cpu_seconds(router.pid) - router_cpu0
            mem = [memory_mb(p) for p in pids]
            wm, rm = memory_mb(world.pid), memory_mb(router.pid)
        finally:
            co.close()
            session.close()
    sim = ticks * 0.05
    return {"n": n, "idle_keepalive_s": keepalive_s, "active": len(active),
            "startup_wall_s": round(startup_s, 1), "ticks": ticks, "wall_s": round(wall, 2),
            "ticks_per_s": round(ticks / wall, 1), "rtf": round(sim / wall, 2),
            "legs_done": co.legs_done,
            "cpu_s_per_sim_s": {"agents": round(agents_cpu / sim, 3),
                                "world": round(world_cpu / sim, 3),
                                "router": round(router_cpu / sim, 3)},
            "agents_rss_mb_sum": round(sum(m["rss"] for m in mem), 1),
            "agents_pss_mb_sum": round(sum(m["pss"] for m in mem), 1),
            "pss_mb_per_agent": round(sum(m["pss"] for m in mem) / n, 2),
            "world_pss_mb": round(wm["pss"], 1), "router_pss_mb": round(rm["pss"], 1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[100, 250, 500])
    ap.add_argument("--baseline-n", type=int, default=100,
                    help="N of the baseline run with every robot sensed every tick (0: none)")
    ap.add_argument("--active", type=int, default=10, help="robots kept driving")
    ap.add_argument("--sim-s", type=float, default=20.0, help="simulated seconds measured")
    ap.add_argument("--keepalive", type=float, default=2.0,
                    help="[sensing] idle_keepalive_s of the measured runs (default 2)")
    args = ap.parse_args(argv)
    py = sys.executable
    rows = []
    with tempfile.TemporaryDirectory() as d:
        runs = [(n, args.keepalive) for n in args.n]
        if args.baseline_n:
            runs.insert(0, (args.baseline_n, 0.0))
        for n, ka in runs:
            eprint(f"scale: N = {n}, idle_keepalive_s = {ka:g} ...")
            r = measure(n, ka, args.active, args.sim_s, py, Path(d))
            eprint(f"  {r['ticks_per_s']} ticks/s, rtf {r['rtf']}, agents PSS "
                   f"{r['agents_pss_mb_sum']} MB")
            rows.append(r)
    base = next((r for r in rows if r["idle_keepalive_s"] == 0), None)
    print(f"{'N':>5} {'keepalive':>9} {'ticks/s':>8} {'rtf':>6} {'agents cpu/sim s':>16} "
          f"{'world':>6} {'router':>6} {'RSS sum MB':>10} {'PSS sum MB':>10} {'vs base':>8}")
    for r in rows:
        c = r["cpu_s_per_sim_s"]
        vs = ""
        if base is not None and r is not base and r["n"] == base["n"]:
            vs = f"{r['ticks_per_s'] / base['ticks_per_s']:.1f}x"
        print(f"{r['n']:>5} {r['idle_keepalive_s']:>9g} {r['ticks_per_s']:>8} {r['rtf']:>6} "
              f"{c['agents']:>16} {c['world']:>6} {c['router']:>6} "
              f"{r['agents_rss_mb_sum']:>10} {r['agents_pss_mb_sum']:>10} {vs:>8}")
    print(json.dumps({"bench": "scale", "runs": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
