"""Benchmark: CPU cost of one real ``swarmcover agent`` process per Sense message.

Starts a router, one agent (robot 0) and a bare Zenoh echo process (robot 1: receives each
Sense and answers with a pre-encoded CmdVel, no decoding: the floor any Python Zenoh client
pays), then drives both in lockstep from this process with realistic Sense messages (six
neighbours on a hexagon, one touch sector, bearings recomputed from a little kinematic model
that applies the agent's commands). Phases: ``hold`` (station keeping) and ``goto``
(homing), each first as a burst (CPU seconds per message, from /proc/<pid>/stat) and then
at 20 Hz for a few seconds (share of one core, idle Zenoh threads included). Then, in this
process, where an agent's own Python time per Sense goes (``split``): decoding the Sense
(bus/messages.py: msgpack plus per-field checks), the behaviour's step, encoding the CmdVel,
with the same messages and phases (CPU microseconds per message; the rest of the process's
time per message is Zenoh's, as the echo shows). Memory per agent is bench/agent_memory.py.

    python bench/agent.py [--burst 1500] [--rate-s 6] [--split-n 3000]
                                                           (the venv's python, from the repo root)

Progress goes to stderr; the last line on stdout is one JSON object.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench.common import CLK, cpu_seconds, eprint, router_and_starter, wait_line  # noqa: E402


# --------------------------------------------------------------------------- echo process

def echo_main(argv) -> int:
    """The baseline: a bare Zenoh client answering each Sense with a fixed CmdVel."""
    from swarmcover.bus.messages import CmdVel
    from swarmcover.bus.session import (Mailbox, Shutdown, add_zenoh_args, keys_from_args, open_session,
                             publisher)
    ap = argparse.ArgumentParser()
    ap.add_argument("--echo", action="store_true")
    ap.add_argument("--id", type=int, default=1)
    add_zenoh_args(ap)
    args = ap.parse_args(argv)
    keys = keys_from_args(args)
    with Shutdown() as stop:
        s = open_session(args)
        try:
            mb = Mailbox()
            sub = s.declare_subscriber(keys.sense(args.id), mb.callback)
            pub = publisher(s, keys.cmd_vel(args.id), block=True, express=True)
            token = s.liveliness().declare_token(keys.alive("robot", args.id))
            reply = CmdVel(robot=args.id, tick=0).encode()
            print("READY echo", flush=True)
            while not stop.is_set():
                item = mb.get(timeout=0.2)
                if item is not None:
                    pub.put(reply)
            sub.undeclare()
            token.undeclare()
        finally:
            s.close()
    return 0


# --------------------------------------------------------------------------- driver

class Model:
    """Robot 0 among six static neighbours on a hexagon of radius 0.8 m (holonomic)."""

    def __init__(self):
        self.lms = {10 + k: (0.8 * math.cos(k * math.pi / 3), 0.8 * math.sin(k * math.pi / 3))
                    for k in range(6)}
        self.x, self.y = 0.15, -0.1

    def bearings_at(self, x, y):
        return {l: math.atan2(py - y, px - x) for l, (px, py) in self.lms.items()}

    def sense(self, rid, tick, t):
        from swarmcover.bus.messages import Sense
        b = self.bearings_at(self.x, self.y)
        ids = list(b)
        return Sense(robot=rid, tick=tick, t=t, ids=ids, bearings=[b[i] for i in ids],
                     back_bearings=[math.atan2(math.sin(b[i] + math.pi),
                                               math.cos(b[i] + math.pi)) for i in ids],
                     touch=[1.5707963267948966], touch_robot=[True])

    def apply(self, cmd, dt):
        self.x += cmd.vx * dt
        self.y += cmd.vy * dt


def drive(session, keys, mailbox, model, n, rate_hz, t0, tick0, goto_every=0):
    """Send n Sense ticks to robots 0 and 1 in lockstep; returns the next tick and time."""
    from swarmcover.bus.messages import CmdVel, Task, decode
    dt = 0.05
    period = 1.0 / rate_hz if rate_hz else 0.0
    nxt = time.monotonic()
    tick, t = tick0, t0
    for k in range(n):
        if goto_every and k % goto_every == 0:
            # restart a goto from a displaced position so that homing keeps running
            model.x, model.y = 0.15 * math.cos(k), 0.15 * math.sin(k)
            b = model.bearings_at(0.0, 0.0)
            session.put(keys.task(0), Task(task_id=1000 + tick, robot=0, kind="goto",
                                           landmarks=list(b), bearings=list(b.values())
                                           ).encode())
        for rid in (0, 1):
            session.put(keys.sense(rid), model.sense(rid, tick, t).encode())
        got = {}
        end = time.monotonic() + 5
        while len(got) < 2 and time.monotonic() < end:
            item = mailbox.get(timeout=0.5)
            if item is None:
                continue
            rid = keys.robot_id(item[0])
            if rid == 0:
                cmd = decode(item[1], CmdVel)
                if cmd.tick == tick:
                    got[0] = cmd
            else:
                got[1] = True
        if 0 in got:
            model.apply(got[0], dt)
        tick += 1
        t = round(t + dt, 9)
        if period:
            nxt += period
            time.sleep(max(0.0, nxt - time.monotonic()))
    return tick, t


def split(n: int) -> dict:
    """CPU microseconds per message an agent spends decoding, stepping and encoding."""
    from swarmcover.agents.behaviours import Behaviour
    from swarmcover.agents.params import AgentParams
    from swarmcover.bus.messages import CmdVel, Sense, Task, decode
    clock = time.process_time
    out = {}
    for name, goto_every in (("hold", 0), ("goto", 60)):
        model, beh = Model(), Behaviour(AgentParams(), 0)
        beh.on_task(Task(task_id=1, robot=0, kind="hold"))
        td = ts = te = 0.0
        for k in range(n):
            if goto_every and k % goto_every == 0:
                model.x, model.y = 0.15 * math.cos(k), 0.15 * math.sin(k)
                b = model.bearings_at(0.0, 0.0)
                beh.on_task(Task(task_id=1000 + k, robot=0, kind="goto", landmarks=list(b),
                                 bearings=list(b.values())))
            raw = model.sense(0, k, 0.05 * k).encode()
            t0 = clock()
            sense = decode(raw, Sense)
            t1 = clock()
            cmd = beh.step(sense)
            t2 = clock()
            out_msg = CmdVel(robot=0, tick=k)
            if cmd is not None:
                out_msg.vx, out_msg.vy, out_msg.wz = cmd.vx, cmd.vy, cmd.wz
            out_msg.encode()
            t3 = clock()
            td, ts, te = td + t1 - t0, ts + t2 - t1, te + t3 - t2
            if cmd is not None:
                model.apply(cmd, 0.05)
        total = td + ts + te
        out[name] = {"decode_us": round(1e6 * td / n, 1), "step_us": round(1e6 * ts / n, 1),
                     "encode_us": round(1e6 * te / n, 1),
                     "decode_share_of_python": round(td / total, 3)}
    return out


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if "--echo" in argv:
        return echo_main(argv)
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--burst", type=int, default=1500, help="messages per burst phase")
    ap.add_argument("--rate-s", type=float, default=6.0, help="seconds per 20 Hz phase")
    ap.add_argument("--split-n", type=int, default=3000,
                    help="messages per phase of the in-process split (0: skip)")
    args = ap.parse_args(argv)
    from swarmcover.bus.keys import Keys
    from swarmcover.bus.messages import Task
    from swarmcover.bus.session import Mailbox, add_zenoh_args, open_session

    swarm = f"bench{os.getpid()}"
    py = sys.executable
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    result: dict = {"bench": "agent"}
    session = None
    with router_and_starter(py, env, str(ROOT)) as (start, ep, _):
        try:
            z = ["--connect", ep, "--swarm", swarm]
            agent = start([py, "-m", "swarmcover", "agent", "--id", "0", "--info-timeout", "0",
                           "--log-level", "WARNING", *z])
            echo = start([py, str(Path(__file__).resolve()), "--echo", "--id", "1", *z])
            wait_line(agent, "READY agent")
            wait_line(echo, "READY echo")
            eprint("router, agent and echo are up")
            ap2 = argparse.ArgumentParser()
            add_zenoh_args(ap2)
            session = open_session(ap2.parse_args(z))
            keys = Keys(swarm)
            mb = Mailbox()
            subs = [session.declare_subscriber(keys.cmd_vel(r), mb.callback) for r in (0, 1)]
            model = Model()
            time.sleep(0.5)
            session.put(keys.task(0), Task(task_id=1, robot=0, kind="hold").encode())
            tick, t = drive(session, keys, mb, model, 50, 0, 0.0, 0)  # warm up
            phases = {}
            for name, goto_every in (("hold", 0), ("goto", 60)):
                if name == "hold":
                    session.put(keys.task(0), Task(task_id=2, robot=0, kind="hold").encode())
                    tick, t = drive(session, keys, mb, model, 20, 0, t, tick)
                a0, e0, w0 = cpu_seconds(agent.pid), cpu_seconds(echo.pid), time.monotonic()
                tick, t = drive(session, keys, mb, model, args.burst, 0, t, tick, goto_every)
                a1, e1, w1 = cpu_seconds(agent.pid), cpu_seconds(echo.pid), time.monotonic()
                burst = {"messages": args.burst, "wall_s": round(w1 - w0, 3),
                         "agent_ms_per_msg": round(1e3 * (a1 - a0) / args.burst, 4),
                         "echo_ms_per_msg": round(1e3 * (e1 - e0) / args.burst, 4)}
                burst["ratio_agent_over_echo"] = round((a1 - a0) / max(e1 - e0, 1e-9), 3)
                eprint(f"{name} burst: {burst}")
                n20 = int(args.rate_s * 20)
                a0, e0, w0 = cpu_seconds(agent.pid), cpu_seconds(echo.pid), time.monotonic()
                tick, t = drive(session, keys, mb, model, n20, 20, t, tick, goto_every)
                a1, e1, w1 = cpu_seconds(agent.pid), cpu_seconds(echo.pid), time.monotonic()
                at20 = {"seconds": round(w1 - w0, 2),
                        "agent_core_pct": round(100 * (a1 - a0) / (w1 - w0), 2),
                        "echo_core_pct": round(100 * (e1 - e0) / (w1 - w0), 2)}
                at20["ratio_agent_over_echo"] = round((a1 - a0) / max(e1 - e0, 1e-9), 3)
                eprint(f"{name} at 20 Hz: {at20}")
                phases[name] = {"burst": burst, "rate_20hz": at20}
            for s_ in subs:
                s_.undeclare()
            result.update(phases=phases, budget_core_pct_at_20hz=2.0,
                          within_budget=all(p["rate_20hz"]["agent_core_pct"] <= 2.0
                                            for p in phases.values()),
                          cpu_clock_tick_s=1.0 / CLK)
        finally:
            if session is not None:
                session.close()
    if args.split_n > 0:
        result["split"] = sp = split(args.split_n)
        for name, ph in sp.items():
            # against the agent process's whole CPU per message (Zenoh's threads included)
            msg = result.get("phases", {}).get(name, {}).get("burst", {}).get("agent_ms_per_msg")
            if msg:
                ph["decode_share_of_process"] = round(1e-3 * ph["decode_us"] / msg, 3)
        eprint(f"split: {sp}")
    print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
