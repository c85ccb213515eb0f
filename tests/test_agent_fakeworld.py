"""A test-local lockstep "fake world" process speaking the world's Sense/CmdVel/odom keys,
for agent process tests (run as a script; pytest finds only the small test below).

    python tests/test_agent_fakeworld.py --connect EP --swarm S --goto 0,0 --ticks 300

Copies: ``--copies 2`` simulates independent identical worlds whose robot ids are offset by
``--stride`` (robot 0 with landmarks 1,2,3; robot 10 with 11,12,13, ...), so two agents get
identical Sense streams. ``--odom`` chooses what each copy's robot gets on robot/<id>/odom:
``true`` (its pose), ``none``, or ``garbage`` (random poses and undecodable bytes); give
one value per copy, comma separated. At the end it prints ``POSE <id> <x> <y> <theta>`` for
every controlled robot and ``DONE``.
"""
from __future__ import annotations

import argparse
import math
import random
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

LMS = {1: (0.8, 0.0, 0.0), 2: (-0.4, 0.69, 0.0), 3: (-0.4, -0.69, 0.0)}


def main(argv=None) -> int:
    from bus.messages import CmdVel, Pose, Task, decode
    from bus.session import (Mailbox, Shutdown, add_zenoh_args, keys_from_args, open_session,
                             publisher)
    from test_agent_kinematics import KinSim, bearings_from

    ap = argparse.ArgumentParser()
    ap.add_argument("--start", default="0.3,-0.2,0.0", help="x,y,theta of the controlled robot")
    ap.add_argument("--goto", default=None, help="x,y: send a goto to bearings recorded there")
    ap.add_argument("--ticks", type=int, default=300)
    ap.add_argument("--copies", type=int, default=1)
    ap.add_argument("--stride", type=int, default=10)
    ap.add_argument("--odom", default="true")
    ap.add_argument("--noise-deg", type=float, default=0.0)
    ap.add_argument("--cmd-timeout", type=float, default=5.0)
    add_zenoh_args(ap)
    args = ap.parse_args(argv)
    keys = keys_from_args(args)
    start = tuple(float(v) for v in args.start.split(","))
    odom_modes = args.odom.split(",")
    odom_modes += [odom_modes[-1]] * (args.copies - len(odom_modes))
    sims, me = [], []
    for c in range(args.copies):
        off = c * args.stride
        robots = {off: start}
        robots.update({off + k: v for k, v in LMS.items()})
        sims.append(KinSim(robots, rv=1.5, noise_deg=args.noise_deg, seed=1))
        me.append(off)
    session = open_session(args)
    mb = Mailbox()
    rng = random.Random(7)
    with Shutdown() as stop:
        subs = []
        try:
            for rid in me:
                subs.append(session.declare_subscriber(keys.cmd_vel(rid), mb.callback))
            pub_sense = {rid: publisher(session, keys.sense(rid), block=True, express=True)
                         for rid in me}
            # wait for the agents' liveliness tokens
            end = time.monotonic() + 20
            alive: set[int] = set()
            while alive != set(me) and time.monotonic() < end and not stop.is_set():
                for r in session.liveliness().get(keys.alive_robots(), timeout=1.0):
                    if r.ok is not None:
                        rid = keys.robot_id(str(r.ok.key_expr))
                        if rid is not None:
                            alive.add(rid)
                time.sleep(0.1)
            print(f"READY fakeworld alive={sorted(alive)}", flush=True)
            time.sleep(0.3)
            if args.goto:
                gx, gy = (float(v) for v in args.goto.split(","))
                for sim, rid in zip(sims, me):
                    lms = [rid + k for k in LMS]
                    task = Task(task_id=1, robot=rid, kind="goto", vertex=5, landmarks=lms,
                                bearings=bearings_from(sim, (gx, gy), lms), timeout_s=60.0)
                    session.put(keys.task(rid), task.encode())
                time.sleep(0.3)
            for tick in range(args.ticks):
                if stop.is_set():
                    break
                for sim, rid in zip(sims, me):
                    pub_sense[rid].put(sim.sense(rid).encode())
                got: dict[int, object] = {}
                end = time.monotonic() + args.cmd_timeout
                while len(got) < len(me) and time.monotonic() < end and not stop.is_set():
                    item = mb.get(timeout=0.05)
                    if item is None:
                        continue
                    cmd = decode(item[1], CmdVel)
                    if cmd.tick == tick:
                        got[cmd.robot] = cmd
                for sim, rid, mode in zip(sims, me, odom_modes):
                    if rid in got:
                        sim.apply(rid, got[rid])
                    sim.advance()
                    if tick % 4 == 0:
                        x, y, th = sim.pose[rid]
                        if mode == "true":
                            session.put(keys.odom(rid), Pose(robot=rid, t=sim.t, x=x, y=y,
                                                             theta=th).encode())
                        elif mode == "garbage":
                            session.put(keys.odom(rid), Pose(
                                robot=rid, t=sim.t, x=rng.uniform(-50, 50),
                                y=rng.uniform(-50, 50), theta=rng.uniform(-3, 3)).encode())
                            session.put(keys.odom(rid), b"\x93garbage" + bytes([tick % 256]))
            for sim, rid in zip(sims, me):
                x, y, th = sim.pose[rid]
                print(f"POSE {rid} {x:.6f} {y:.6f} {th:.6f}", flush=True)
            print("DONE", flush=True)
        finally:
            for s in subs:
                s.undeclare()
            session.close()
    return 0


def test_fake_world_parses_its_arguments():
    import subprocess
    out = subprocess.run([sys.executable, __file__, "--help"], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0 and "--goto" in out.stdout


if __name__ == "__main__":
    sys.exit(main())
