"""``swarmcover run CONFIG``: one command for a whole coverage run.

Starts an embedded Zenoh router, the world, the coordinator and (as the coordinator asks
for robots) one agent process per robot; plus the hardware bridge and stand-in live robots
when the config has a ``[hwbridge]`` section. It shows live progress, and at the end writes
a run folder (``summary.json``, ``final.png``, ``cycles.jsonl``, ``resolved.toml``,
``logs/``, and ``run.mcap`` with ``--record``). Exit status 0 if and only if coverage was
certified. Ctrl-C stops everything cleanly; a killed ``run`` takes its children with it
(they watch their parent).

CONFIG may be a TOML run config or a bare ROS map_server YAML (defaults are built around it).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import zenoh

from bus.keys import Keys
from bus.messages import Complex, Spawn, Truth, WorldInfo
from bus.session import Mailbox, Receiver, Shutdown, add_zenoh_args, open_session, setup_logging

log = logging.getLogger("swarmcover.run")
MAX_COORDINATOR_RESTARTS = 3
PY = [sys.executable, "-m", "swarmcover"]


# --------------------------------------------------------------------------- processes

class Child:
    """A child process writing to a log file, in its own session (we stop it ourselves)."""

    def __init__(self, name: str, argv: list[str], logdir: Path, env: dict):
        self.name = name
        self.log_path = logdir / f"{name}.log"
        self._f = open(self.log_path, "ab", buffering=0)
        self._offset = self._f.tell()  # a restarted child appends: READY is looked for after
        self.p = subprocess.Popen(argv, stdout=self._f, stderr=subprocess.STDOUT,
                                  stdin=subprocess.DEVNULL, env=env, start_new_session=True)

    def alive(self) -> bool:
        return self.p.poll() is None

    def wait_ready(self, needle: str, timeout: float) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                with open(self.log_path, "rb") as f:
                    f.seek(self._offset)
                    text = f.read().decode(errors="replace")
            except OSError:
                text = ""
            if needle in text:
                return
            if self.p.poll() is not None:
                break
            time.sleep(0.05)
        tail = self.log_path.read_text(errors="replace")[-3000:]
        raise RuntimeError(f"{self.name} did not become ready (exit {self.p.poll()}); "
                           f"last lines of {self.log_path}:\n{tail}")

    def signal(self, sig: int) -> None:
        if self.p.poll() is None:
            try:
                os.killpg(self.p.pid, sig)
            except ProcessLookupError:
                pass

    def close(self) -> None:
        self._f.close()


class Launcher:
    def __init__(self, logdir: Path, zargs: list[str]):
        self.logdir = logdir
        self.zargs = zargs
        self.children: dict[str, Child] = {}
        self.env = dict(os.environ, SWARMCOVER_WATCH_PARENT="1", PYTHONUNBUFFERED="1")

    def start(self, name: str, args: list[str], zenoh_args: bool = True) -> Child:
        argv = PY + args + (self.zargs if zenoh_args else [])
        c = self.children[name] = Child(name, argv, self.logdir, self.env)
        return c

    def stop_all(self, order: list[str] | None = None, grace: float = 8.0) -> None:
        """SIGINT everyone (agents first, router last), wait, then SIGKILL stragglers."""
        names = list(self.children)
        first = [n for n in names if n.startswith("agent-") or n.startswith("fake-")]
        rest = [n for n in (order or []) if n in self.children]
        others = [n for n in names if n not in first and n not in rest]
        for group in (first, others, rest):
            for n in group:
                self.children[n].signal(signal.SIGINT)
            end = time.monotonic() + grace
            for n in group:
                c = self.children[n]
                try:
                    c.p.wait(max(0.1, end - time.monotonic()))
                except subprocess.TimeoutExpired:
                    log.warning("%s did not stop on SIGINT: killing it", n)
                    c.signal(signal.SIGKILL)
                    try:
                        c.p.wait(3)
                    except subprocess.TimeoutExpired:
                        pass
        for c in self.children.values():
            c.signal(signal.SIGKILL)  # the process groups: anything a child left behind
            c.close()


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
            return True
        except OSError:
            return False


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# --------------------------------------------------------------------------- config

def resolve_config(path: str, args) -> tuple[object, str]:
    """Load CONFIG, apply the command-line overrides; returns (RunConfig, resolved TOML)."""
    from world.config import load_config, to_toml
    cfg = load_config(path)
    world = cfg.world
    if args.seed is not None:
        world = dataclasses.replace(world, seed=args.seed)
    if args.mode is not None:
        world = dataclasses.replace(world, mode=args.mode)
    sections = dict(cfg.sections)
    coord = dict(sections.get("coordinator", {}))
    if args.robots_max is not None:
        coord["robots_max"] = args.robots_max
    if coord:
        sections["coordinator"] = coord
    cfg = dataclasses.replace(cfg, world=world, sections=sections)
    return cfg, to_toml(cfg)


# --------------------------------------------------------------------------- metrics

def compute_summary(cfg, wmap, truth: Truth | None, cx: Complex | None, extra: dict) -> dict:
    """Ground-truth numbers for summary.json (world positions, never seen by the swarm)."""
    from world.groundtruth import coverage_fraction, ideal_count
    rv = cfg.rv
    pos = {}
    if truth is not None:
        pos = {i: (x, y) for i, x, y in zip(truth.ids, truth.x, truth.y)}
    members = []
    if cx is not None:
        members = [o for o in cx.occupants if o >= 0 and o in pos]
    all_alive = [i for i in pos]
    P = np.array([pos[i] for i in all_alive], float).reshape(-1, 2)
    coverage = float(coverage_fraction(wmap, P, rv)) if len(P) else 0.0
    lengths = []
    if cx is not None:
        occ = dict(zip(cx.vertices, cx.occupants))
        for a, b in zip(cx.edges[0::2], cx.edges[1::2]):
            ra, rb = occ.get(a, -1), occ.get(b, -1)
            if ra in pos and rb in pos:
                lengths.append(math.dist(pos[ra], pos[rb]))
    mean_spacing = float(np.mean(lengths) / rv) if lengths else float("nan")
    ideal = ideal_count(wmap, rv)
    ideal_n = _ideal_number(ideal)
    robots_used = len(members) if members else len(all_alive)
    out = dict(
        certified=bool(extra.get("certified", False)),
        robots_used=robots_used,
        robots_spawned=extra.get("robots_spawned", len(all_alive)),
        ideal_count=ideal_n,
        ratio=robots_used / ideal_n if ideal_n else float("nan"),
        mean_spacing=mean_spacing,
    )
    if lengths:
        same = ideal_count(wmap, mean_spacing * rv)
        out["ideal_count_same_spacing"] = _ideal_number(same)
        out["ratio_same_spacing"] = robots_used / out["ideal_count_same_spacing"]
    else:
        out["ideal_count_same_spacing"] = None
        out["ratio_same_spacing"] = None
    out["coverage"] = coverage
    out.update({k: v for k, v in extra.items() if k not in out})
    return out


def _ideal_number(ideal) -> int:
    if isinstance(ideal, dict):
        for k in ("area_formula", "lattice_points", "count"):
            if k in ideal:
                return int(round(ideal[k]))
    return int(round(float(ideal)))


# --------------------------------------------------------------------------- main

def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="swarmcover run", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("config", help="run config (TOML) or a ROS map_server YAML")
    p.add_argument("--robots-max", type=int, default=None, help="stop if more robots would be needed")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="deterministic lockstep clock (default from the config)")
    mode.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                      help="real-time clock")
    p.set_defaults(mode=None)
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--out", default=None, help="run folder (default runs/<name>-<time>)")
    p.add_argument("--record", action="store_true", help="record every message to run.mcap")
    p.add_argument("--view", action="store_true", help="serve the live view in the browser")
    p.add_argument("--view-port", type=int, default=8765)
    p.add_argument("--wall-timeout", type=float, default=3600.0,
                   help="give up after this many wall seconds (default 3600)")
    p.add_argument("--router", default=None, metavar="ENDPOINT",
                   help="use this existing router instead of starting one")
    p.add_argument("--port", type=int, default=None,
                   help="port of the embedded router (default 7447, or a free one if taken)")
    p.add_argument("--swarm", default=os.environ.get("SWARMCOVER_SWARM"),
                   help="experiment name (default: the config's name)")
    p.add_argument("--secure", metavar="DIR", default=None, help="lab-network security profile "
                   "(swarmcover secure init) for every process; sets env SWARMCOVER_SECURE")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.add_argument("--log-level", default="INFO")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    setup_logging(args.log_level, "swarmcover.run")
    if args.secure:  # children and our own session read it (bus.session --secure default)
        os.environ["SWARMCOVER_SECURE"] = os.path.abspath(args.secure)
    try:
        cfg, resolved = resolve_config(args.config, args)
        from world.maps import build_map
        wmap = build_map(cfg)
        live_limits = _live_limits(cfg, resolved, str(args.config))
    except (ValueError, OSError) as e:
        print(f"swarmcover run: {e}", file=sys.stderr)
        return 2
    swarm = args.swarm or "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in cfg.name)[:64] or "run"
    out = Path(args.out or f"runs/{cfg.name}-{time.strftime('%Y%m%d-%H%M%S')}")
    logdir = out / "logs"
    logdir.mkdir(parents=True, exist_ok=True)
    (out / "resolved.toml").write_text(resolved)
    conf_path = str((out / "resolved.toml").resolve())

    if args.router:
        endpoint = args.router
    else:
        port = args.port or (7447 if _port_free(7447) else _free_port())
        endpoint = f"tcp/127.0.0.1:{port}"
    zargs = ["--connect", endpoint, "--swarm", swarm]
    launcher = Launcher(logdir, zargs)
    t_wall0 = time.monotonic()
    state = dict(certified=False, reason="")
    rc = 1
    with Shutdown(grace_s=0) as stop:  # a supervisor: stop_all bounds its own exit
        session = None
        try:
            if not args.router:
                launcher.start("router", ["router", "--listen", endpoint], zenoh_args=False) \
                    .wait_ready("READY router", 30)
            print(f"swarmcover run: {cfg.name} -> {out}/  (router {endpoint}, swarm {swarm})",
                  file=sys.stderr, flush=True)
            launcher.start("world", ["world", conf_path, "--await-coordinator", "120"]) \
                .wait_ready("READY world", 60)
            session = _open(endpoint, swarm)
            rc = _supervise(args, cfg, wmap, conf_path, launcher, session, Keys(swarm), out,
                            stop, state, t_wall0, live_limits)
        except RuntimeError as e:
            log.error("%s", e)
            state["reason"] = str(e).splitlines()[0]
            rc = 1
        except KeyboardInterrupt:
            rc = 130
        finally:
            if stop.is_set() and stop.signum in (signal.SIGINT, signal.SIGTERM):
                print("\nswarmcover run: interrupted, stopping every process ...",
                      file=sys.stderr, flush=True)
                rc = 130
            if session is not None:
                session.close()
            launcher.stop_all(order=["hwbridge", "coordinator", "world", "router"])
    print(f"swarmcover run: {'CERTIFIED' if state['certified'] else 'NOT certified'}"
          f"{' (' + state['reason'] + ')' if state['reason'] else ''}; report in {out}/",
          file=sys.stderr, flush=True)
    return rc


def _open(endpoint: str, swarm: str) -> zenoh.Session:
    p = argparse.ArgumentParser()
    add_zenoh_args(p)
    return open_session(p.parse_args(["--connect", endpoint, "--swarm", swarm]))


def _agent_args(spawn: Spawn, conf_path: str, live_limits: dict) -> list[str]:
    """A live robot's agent plans with the robot's own limits ([[hwbridge.robots]]), so the
    bridge's clamp does not rescale its turns behind its back."""
    a = ["agent", "--id", str(spawn.robot), "--kind", spawn.kind, "--run-config", conf_path]
    if spawn.live:
        a.append("--live")
        if spawn.robot in live_limits:
            v_max, w_max = live_limits[spawn.robot]
            a += ["--v-max", str(v_max), "--param", f"w_max={float(w_max)}"]
    return a


def _live_limits(cfg, resolved: str, where: str) -> dict:
    """Live robot id -> (v_max, w_max) as the bridge clamps them (its own config parser,
    defaults from [robots] included); {} without a [hwbridge] section. A bad [hwbridge]
    section raises its ConfigError (a ValueError naming the field) before anything starts."""
    if not cfg.section("hwbridge"):
        return {}
    from hwbridge.config import loads
    return {r.id: (r.v_max, r.w_max) for r in loads(resolved, where).robots}


def _supervise(args, cfg, wmap, conf_path, launcher: Launcher, session, keys: Keys, out: Path,
               stop: Shutdown, state: dict, t_wall0: float, live_limits: dict) -> int:
    from swarmcover.progress import Progress
    rx = Receiver(log)
    mb = Mailbox()
    subs = [session.declare_subscriber(keys.spawn, mb.callback),
            session.declare_subscriber(keys.complex, mb.callback),
            session.declare_subscriber(keys.truth, mb.callback)]
    recorder = None
    last_cx: Complex | None = None
    last_truth: Truth | None = None
    truths: dict[int, Truth] = {}   # recent ground truth by tick: the final complex's tick
    cycles_f = open(out / "cycles.jsonl", "w")
    spawned = 0
    progress = Progress(label=cfg.name, enabled=not args.quiet, every_s=10.0)
    restarts = 0
    coverage = 0.0
    final_state = None
    from world.groundtruth import coverage_fraction
    try:
        if args.record:
            from swarmcover.record import Recorder
            recorder = Recorder(session, keys.all, str(out / "run.mcap"))
            recorder.start()
        hw = cfg.section("hwbridge")
        if hw:
            _start_hwbridge(launcher, hw, conf_path, out)
        if args.view:
            launcher.start("view", ["view", "--port", str(args.view_port)])
            print(f"live view: http://127.0.0.1:{args.view_port}/", file=sys.stderr, flush=True)
        launcher.start("coordinator", ["coordinator", conf_path]).wait_ready("READY coordinator", 60)
        while not stop.is_set():
            item = mb.get(0.1)
            items = ([item] if item else []) + mb.drain()
            for key, payload, kind in items:
                rel = keys.relative(key)
                if rel == "world/spawn":
                    sp = rx.decode(key, payload, Spawn)
                    if sp is not None and f"agent-{sp.robot}" not in launcher.children:
                        launcher.start(f"agent-{sp.robot}", _agent_args(sp, conf_path, live_limits))
                        spawned += 1
                elif rel == "world/truth":
                    last_truth = rx.decode(key, payload, Truth) or last_truth
                    if last_truth is not None:
                        truths[last_truth.tick] = last_truth
                        truths.pop(last_truth.tick - 400, None)
                elif rel == "coord/complex":
                    cx = rx.decode(key, payload, Complex)
                    if cx is None:
                        continue
                    last_cx = cx
                    if last_truth is not None and last_truth.ids:
                        pos = np.c_[last_truth.x, last_truth.y]
                        coverage = float(coverage_fraction(wmap, pos, cfg.rv))
                    row = dict(cycle=cx.cycle, t=cx.t, wall=time.monotonic() - t_wall0,
                               robots=cx.robots, vertices=len(cx.vertices),
                               frontier=len(cx.frontier), obstacle=len(cx.obstacle),
                               redundant=len(cx.redundant), certified=cx.certified,
                               coverage=coverage, state=cx.state)
                    cycles_f.write(json.dumps(row) + "\n")
                    cycles_f.flush()
                    progress.set(cx.cycle, note=(
                        f"cycle {cx.cycle} | robots {cx.robots} | frontier {len(cx.frontier)} | "
                        f"obstacle {len(cx.obstacle)} | covered {100 * coverage:.1f}% | "
                        f"sim {cx.t:.0f}s"))
                    if cx.state in ("certified", "stopped"):
                        final_state = cx.state
            if final_state is not None:
                break
            c = launcher.children["world"]
            if not c.alive():
                raise RuntimeError(f"the world process exited ({c.p.returncode}); see {c.log_path}")
            c = launcher.children["coordinator"]
            if not c.alive():
                # a coordinator rebuilds its state from the agents' statuses: restart it
                restarts += 1
                if restarts > MAX_COORDINATOR_RESTARTS:
                    raise RuntimeError(f"the coordinator exited ({c.p.returncode}) "
                                       f"{restarts} times; see {c.log_path}")
                log.warning("the coordinator exited (%s): restarting it (%d/%d)",
                            c.p.returncode, restarts, MAX_COORDINATOR_RESTARTS)
                c.close()
                launcher.start("coordinator", ["coordinator", conf_path]) \
                    .wait_ready("READY coordinator", 60)
            if time.monotonic() - t_wall0 > args.wall_timeout:
                state["reason"] = f"wall timeout {args.wall_timeout:.0f} s"
                break
    finally:
        progress.close()
        for s in subs:
            s.undeclare()
        cycles_f.close()
        if recorder is not None:
            recorder.stop()
    time.sleep(0.3)
    for item in mb.drain():
        if keys.relative(item[0]) == "world/truth":
            last_truth = rx.decode(item[0], item[1], Truth) or last_truth
            if last_truth is not None:
                truths[last_truth.tick] = last_truth
    if final_state is not None and last_cx is not None:
        # the world at the tick the coordinator decided (lockstep: the same every run), not
        # wherever it had got to by the time this loop stopped
        at = [tr for tr in truths.values() if abs(tr.t - last_cx.t) < 1e-6]
        last_truth = at[0] if at else last_truth
    state["certified"] = final_state == "certified"
    if final_state == "stopped":
        state["reason"] = "the coordinator stopped before certifying (see logs/coordinator.log)"
    extra = dict(certified=state["certified"], cycles=last_cx.cycle if last_cx else 0,
                 sim_time_s=(last_truth.t if last_truth else 0.0),
                 wall_time_s=time.monotonic() - t_wall0, robots_spawned=spawned,
                 failures_healed=_failures_healed(out / "logs" / "coordinator.log"),
                 coordinator_restarts=restarts,
                 config=args.config, seed=cfg.world.seed, mode=cfg.world.mode)
    if state["reason"]:
        extra["stop_reason"] = state["reason"]
    summary = compute_summary(cfg, wmap, last_truth, last_cx, extra)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    _final_png(session, keys, out, last_truth, last_cx, cfg)
    print(json.dumps(summary), flush=True)
    return 0 if state["certified"] else 1


def _failures_healed(coord_log: Path) -> int:
    try:
        for line in reversed(coord_log.read_text(errors="replace").splitlines()):
            if "done: {" in line:
                d = line.split("done: ", 1)[1]
                import ast
                return int(ast.literal_eval(d).get("failures_healed", 0))
    except (OSError, ValueError, SyntaxError):
        pass
    return 0


def _final_png(session, keys: Keys, out: Path, truth, cx, cfg) -> None:
    try:
        from coordinator.node import query_world_info
        from viz.figures import render_snapshot
        info = query_world_info(session, keys, 5.0)
        if info is None:
            return
        render_snapshot(info, truth, cx, str(out / "final.png"),
                        title=f"{cfg.name}: {'certified' if cx and cx.certified else 'not certified'}")
    except Exception as e:  # a missing figure must not lose the summary
        log.warning("could not draw final.png: %s", e)


def _start_hwbridge(launcher: Launcher, hw: dict, conf_path: str, out: Path) -> None:
    """Stand-in live robots (``fake = true``) and the bridge, when the config has them."""
    for r in hw.get("robots", []) or []:
        if isinstance(r, dict) and r.get("fake"):
            launcher.start(f"fake-robot-{r['id']}", ["fake-robot", conf_path, "--id", str(r["id"])])
    launcher.start("hwbridge", ["hwbridge", conf_path, "--report", str(out / "hwbridge.json")]) \
        .wait_ready("READY hwbridge", 60)
