"""Fault injection for lab-network runs: lossy/delayed links, router restarts, fuzzed payloads.

Library (used by tests/test_lab_faults.py) and benchmark (``python bench/faults.py ...``):

  loss     sweep per-segment loss on every link of a small run (through :class:`FaultProxy`)
           and report at what loss the run stops certifying within the wall bound
  netns-loss  the same with real packet loss: router and clients in two network namespaces,
           iptables ``statistic`` drops in the router's (needs root, iproute2, iptables)
  delay    the same for one-way delay
  restart  kill -9 the router mid-run and restart it on the same port; does the run finish?
  fuzz     N invalid payloads on every topic against world, coordinator, agent, hwbridge and
           stand-in live robots; report crashes and each process's drop counters

Link model (no tc netem in this kernel): every process reaches the router through a TCP
proxy. The byte stream is cut into MSS-sized segments (1448 B); each one is delayed by
``delay_s`` (+- uniform ``jitter_s``, in order) and is "lost" with probability ``loss``. TCP
never loses bytes, so a loss shows up as what TCP does about it: the segment and all after
it wait for a retransmission timeout ``rto_s`` (200 ms, Linux's minimum RTO), doubling on
each repeated loss of the same segment. This is pessimistic for busy links (fast retransmit
recovers in about one RTT) and faithful for the sparse request/answer traffic of lockstep.
Benchmarks print progress to stderr and end with one JSON line.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgpack

ROOT = Path(__file__).resolve().parent.parent
PY = [sys.executable, "-m", "swarmcover"]
MSS = 1448


# --------------------------------------------------------------------------- link faults

def loss_stall(rng: random.Random, loss: float, rto_s: float, max_tries: int = 8) -> float:
    """Extra wait of one segment under per-segment loss ``loss``: sum of doubling RTOs over
    its consecutive losses (at most ``max_tries``)."""
    stall, k = 0.0, 0
    while k < max_tries and rng.random() < loss:
        stall += rto_s * (2 ** k)
        k += 1
    return stall


class FaultProxy:
    """A TCP proxy with delay, jitter and loss-as-retransmission-stall, in a thread.

    ``FaultProxy(("127.0.0.1", router_port), loss=0.05, delay_s=0.01).start()`` returns
    the local port to connect to. Every accepted connection gets its own faulty pipe in
    each direction. ``set(loss=..., delay_s=...)`` changes the faults live; ``cut()``
    resets every open connection (a link outage); ``stop()`` ends the thread.
    """

    def __init__(self, upstream: tuple[str, int], listen: tuple[str, int] = ("127.0.0.1", 0),
                 loss: float = 0.0, delay_s: float = 0.0, jitter_s: float = 0.0,
                 rto_s: float = 0.2, seed: int = 0):
        self.upstream, self.listen = upstream, listen
        self.loss, self.delay_s, self.jitter_s, self.rto_s = loss, delay_s, jitter_s, rto_s
        self.rng = random.Random(seed)
        self.stats = dict(connections=0, segments=0, lost=0, stall_s=0.0, bytes=0)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._server = None
        self._writers: set = set()
        self._ready = threading.Event()
        self.port = 0

    def set(self, **kw) -> None:
        for k, v in kw.items():
            if k not in ("loss", "delay_s", "jitter_s", "rto_s"):
                raise ValueError(f"FaultProxy.set: unknown fault {k!r}")
            setattr(self, k, float(v))

    def start(self) -> int:
        self._thread = threading.Thread(target=self._run, daemon=True, name="fault-proxy")
        self._thread.start()
        if not self._ready.wait(10):
            raise RuntimeError("FaultProxy did not start")
        return self.port

    def _run(self) -> None:
        self._loop = asyncio.new_event_loop()
        self._loop.run_until_complete(self._serve())
        self._loop.run_forever()
        self._loop.close()

    async def _serve(self) -> None:
        self._server = await asyncio.start_server(self._client, *self.listen)
        self.port = self._server.sockets[0].getsockname()[1]
        self._ready.set()

    async def _client(self, cr, cw) -> None:
        try:
            ur, uw = await asyncio.open_connection(*self.upstream)
        except (OSError, asyncio.CancelledError):
            cw.close()
            return
        self.stats["connections"] += 1
        self._writers |= {cw, uw}
        try:
            await asyncio.gather(self._pipe(cr, uw), self._pipe(ur, cw), return_exceptions=True)
        except asyncio.CancelledError:
            pass            # stop(): the proxy is going away
        self._writers -= {cw, uw}

    async def _pipe(self, reader, writer) -> None:
        q: asyncio.Queue = asyncio.Queue()

        async def send():
            while True:
                due, data = await q.get()
                if data is None:
                    break
                wait = due - time.monotonic()
                if wait > 0:
                    await asyncio.sleep(wait)
                writer.write(data)
                await writer.drain()

        sender = asyncio.ensure_future(send())
        last_due = 0.0
        try:
            while True:
                data = await reader.read(65536)
                if not data:
                    break
                now = time.monotonic()
                for i in range(0, len(data), MSS):
                    seg = data[i:i + MSS]
                    d = self.delay_s + (self.rng.uniform(-self.jitter_s, self.jitter_s)
                                        if self.jitter_s else 0.0)
                    stall = loss_stall(self.rng, self.loss, self.rto_s) if self.loss else 0.0
                    self.stats["segments"] += 1
                    self.stats["bytes"] += len(seg)
                    if stall:
                        self.stats["lost"] += 1
                        self.stats["stall_s"] += stall
                    last_due = max(last_due, now + max(0.0, d)) + stall   # in order
                    q.put_nowait((last_due, seg))
        except (ConnectionError, OSError):
            pass
        finally:
            q.put_nowait((0.0, None))
            try:
                await sender
            except (ConnectionError, OSError, asyncio.CancelledError):
                sender.cancel()
            try:
                writer.close()
            except Exception:
                pass

    def cut(self) -> None:
        """Reset every open connection (the processes see their link drop)."""
        def _cut():
            for w in list(self._writers):
                tr = w.transport
                if tr is not None:
                    tr.abort()
        if self._loop is not None:
            self._loop.call_soon_threadsafe(_cut)

    def stop(self) -> None:
        if self._loop is None or self._loop.is_closed():
            return

        async def _shutdown():
            if self._server is not None:
                self._server.close()
            for w in list(self._writers):
                if w.transport is not None:
                    w.transport.abort()
            tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self._loop.stop()
        asyncio.run_coroutine_threadsafe(_shutdown(), self._loop)
        if self._thread is not None:
            self._thread.join(5)

    def __enter__(self) -> "FaultProxy":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


# --------------------------------------------------------------------------- fuzzing

def _junk(rng: random.Random, depth: int = 0):
    r = rng.random()
    if depth > 3 or r < 0.35:
        return rng.choice([None, True, -1, 2**63 - 1, -2**63, 3.5, float("nan"), float("inf"),
                           "", "x" * rng.randint(1, 40), "robot", 0, 7])
    if r < 0.65:
        return [_junk(rng, depth + 1) for _ in range(rng.randint(0, 4))]
    return {rng.choice(["_t", "_v", "robot", "x", "t", "tick", "ids"]): _junk(rng, depth + 1)
            for _ in range(rng.randint(0, 4))}


def _bad_value(rng: random.Random, kind: str):
    return rng.choice({
        "float": [float("nan"), float("inf"), -float("inf"), "1.0", None, [1.0], 1e300, True],
        "int": [1.5, "3", None, 2**63 - 1, -2**63, True, [1]],
        "bool": [0, 1, "true", None],
        "str": [3, None, b"x".decode() * 5000, ["a"]],
        "floats": [[float("nan")], "x", [None], [1e300], {"a": 1}, 5],
        "ints": [[1.5], "x", [None], 7],
        "bools": [[1], "x", 3],
        "polys": [[[1.0]], [[float("nan"), 0.0]], "x", [5]],
    }.get(kind, [None, "x"]))


def invalid_payloads(cls, n: int, rng: random.Random, decode_check=True) -> list[bytes]:
    """``n`` payloads that ``bus.messages.decode(p, cls)`` rejects (WireError): random bytes,
    truncated and bit-flipped valid messages, msgpack junk, wrong tag/version, wrong-typed,
    non-finite or out-of-range fields, missing fields, mismatched list lengths.
    ``cls=None`` (a non-msgpack topic): random bytes only."""
    from swarmcover.bus.messages import REGISTRY, WireError, decode
    out: list[bytes] = []
    base = None
    if cls is not None:
        base = cls().to_dict()
    tries = 0
    while len(out) < n:
        tries += 1
        if tries > 50 * n + 1000:
            raise RuntimeError(f"could not make {n} invalid {getattr(cls, 'TAG', cls)} payloads")
        r = rng.random()
        if base is None or r < 0.15:
            p = rng.randbytes(rng.randint(0, 96))
        elif r < 0.25:
            good = msgpack.packb(base, use_bin_type=True)
            p = good[:rng.randint(0, max(0, len(good) - 1))]
        elif r < 0.35:
            good = bytearray(msgpack.packb(base, use_bin_type=True))
            for _ in range(rng.randint(1, 3)):
                good[rng.randrange(len(good))] ^= 1 << rng.randrange(8)
            p = bytes(good)
        elif r < 0.45:
            p = msgpack.packb(_junk(rng), use_bin_type=True)
        else:
            d = dict(base)
            m = rng.random()
            if m < 0.15:
                d["_t"] = rng.choice([None, 7, "Nope", rng.choice(list(REGISTRY))])
            elif m < 0.25:
                d["_v"] = rng.choice([None, 99, "1", -1])
            elif m < 0.35 and len(cls._FIELDS):
                del d[rng.choice([f for f, _ in cls._FIELDS])]
            else:
                for _ in range(rng.randint(1, 3)):
                    f = rng.choice([f for f, _ in cls._FIELDS] or ["x"])
                    d[f] = _bad_value(rng, cls._META.get(f, {}).get("kind", "?"))
            try:
                p = msgpack.packb(d, use_bin_type=True)
            except (OverflowError, ValueError, TypeError):
                continue
        if decode_check and cls is not None:
            try:
                decode(p, cls)
                continue            # accidentally valid: not a fuzz case
            except WireError:
                pass
        out.append(p)
    return out


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process and its reaped children (s), from /proc."""
    try:
        f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return 0.0
    return sum(int(x) for x in f[11:15]) / os.sysconf("SC_CLK_TCK")


def wait_quiet(pids: list[int], busy: float = 0.3, window_s: float = 0.5,
               timeout: float = 30.0) -> bool:
    """Wait until every process uses less than ``busy`` of a core over ``window_s`` (they
    have worked through their queues); False after ``timeout``."""
    end = time.monotonic() + timeout
    last = {p: cpu_seconds(p) for p in pids}
    while time.monotonic() < end:
        time.sleep(window_s)
        now = {p: cpu_seconds(p) for p in pids}
        if all(now[p] - last[p] < busy * window_s for p in pids):
            return True
        last = now
    return False


# --------------------------------------------------------------------------- runs

def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Router:
    """A ``swarmcover router`` child on a fixed port; restartable."""

    def __init__(self, port: int, extra: list[str] | None = None, log: Path | None = None,
                 host: str = "127.0.0.1", prefix: list[str] | None = None):
        self.port, self.extra, self.log = port, extra or [], log
        self.host, self.prefix = host, prefix or []
        self.p: subprocess.Popen | None = None

    @property
    def endpoint(self) -> str:
        return f"tcp/{self.host}:{self.port}"

    def start(self, timeout: float = 20.0) -> "Router":
        out = open(self.log, "ab") if self.log else subprocess.DEVNULL
        self.p = subprocess.Popen(self.prefix + PY + ["router", "--listen", self.endpoint]
                                  + self.extra,
                                  stdout=subprocess.PIPE, stderr=out, stdin=subprocess.DEVNULL,
                                  cwd=str(ROOT), start_new_session=True, text=True)
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            line = self.p.stdout.readline()
            if "READY router" in line:
                return self
            if not line and self.p.poll() is not None:
                break
        self.kill()
        raise RuntimeError(f"router on {self.endpoint} did not start")

    def kill(self, sig: int = signal.SIGKILL) -> None:
        if self.p is not None and self.p.poll() is None:
            try:
                os.killpg(self.p.pid, sig)
            except ProcessLookupError:
                pass
            try:
                self.p.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(self.p.pid, signal.SIGKILL)
                self.p.wait(5)


def small_run(out: Path, router_endpoint: str, config: str = "configs/small.toml",
              wall_timeout: float = 120.0, extra: list[str] | None = None,
              on_start=None, prefix: list[str] | None = None) -> dict:
    """``swarmcover run CONFIG --router ENDPOINT``; returns its summary plus rc and wall time.
    ``on_start(proc, out)`` runs in this thread while the run goes (fault scripts);
    ``prefix`` wraps the command (e.g. ``ip netns exec NS``)."""
    t0 = time.monotonic()
    argv = (prefix or []) + PY + ["run", config, "--router", router_endpoint, "--out", str(out), "--quiet",
                 "--wall-timeout", str(wall_timeout)] + (extra or [])
    with open(out.parent / f"{out.name}.out", "w") as f:
        p = subprocess.Popen(argv, stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                             cwd=str(ROOT), start_new_session=True)
        try:
            if on_start is not None:
                on_start(p, out)
            rc = p.wait(wall_timeout + 60)
        except subprocess.TimeoutExpired:
            rc = None
        finally:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
                try:
                    p.wait(15)
                except subprocess.TimeoutExpired:
                    os.killpg(p.pid, signal.SIGKILL)
                    p.wait(5)
    summary = {}
    try:
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError):
        pass
    return dict(summary, rc=rc, wall_s=time.monotonic() - t0,
                certified=bool(summary.get("certified")) and rc == 0)


def clocked_config(config: str, work: Path, realtime: bool, rtf: float = 1.0) -> str:
    """``config`` itself for lockstep; for ``realtime`` a copy in ``work`` with
    ``[world] mode = "realtime"`` and ``rtf`` (a ROS map path made absolute, so the copy
    reads the same map)."""
    if not realtime:
        return config
    import tomllib

    from swarmcover.ground.toml import dumps_toml
    src = (ROOT / config) if not Path(config).is_absolute() else Path(config)
    raw = tomllib.loads(src.read_text())
    raw.setdefault("world", {}).update(mode="realtime", rtf=float(rtf))
    ros = raw.get("map", {}).get("ros_map")
    if ros and not Path(ros).is_absolute():
        raw["map"]["ros_map"] = str((src.parent / ros).resolve())
    work.mkdir(parents=True, exist_ok=True)
    out = work / f"{src.stem}-realtime-{rtf:g}.toml"
    out.write_text(dumps_toml(raw))
    return str(out)


def first_cycle(out: Path, timeout: float = 60.0) -> dict | None:
    """Wait for the first row of the run's cycles.jsonl."""
    end = time.monotonic() + timeout
    f = out / "cycles.jsonl"
    while time.monotonic() < end:
        try:
            line = f.read_text().splitlines()
            if line:
                return json.loads(line[0])
        except (OSError, ValueError):
            pass
        time.sleep(0.05)
    return None


def restart_run(work: Path, down_s: float = 1.0, wall_timeout: float = 120.0,
                config: str = "configs/small.toml") -> dict:
    """A small run whose router is killed (SIGKILL) at the first cycle and restarted on the
    same port ``down_s`` later."""
    work.mkdir(parents=True, exist_ok=True)
    router = Router(free_port(), log=work / "router.log").start()
    info: dict = {}

    def fault(proc, out):
        row = first_cycle(out)
        info["cycle_at_kill"] = row
        t = time.monotonic()
        router.kill()
        time.sleep(down_s)
        router.start()
        info["outage_s"] = time.monotonic() - t

    try:
        res = small_run(work / "run", router.endpoint, config=config, wall_timeout=wall_timeout,
                        on_start=fault)
    finally:
        router.kill(signal.SIGTERM)
    return dict(res, **info)


def lossy_run(work: Path, loss: float, delay_s: float, jitter_s: float = 0.0,
              wall_timeout: float = 120.0, seed: int = 0, rto_s: float = 0.2,
              config: str = "configs/small.toml") -> dict:
    """A small run with every process's link to the router through one FaultProxy."""
    work.mkdir(parents=True, exist_ok=True)
    router = Router(free_port(), log=work / "router.log").start()
    try:
        with FaultProxy(("127.0.0.1", router.port), loss=loss, delay_s=delay_s,
                        jitter_s=jitter_s, rto_s=rto_s, seed=seed) as fp:
            res = small_run(work / "run", f"tcp/127.0.0.1:{fp.port}", config=config,
                            wall_timeout=wall_timeout)
            res["link"] = dict(fp.stats, loss=loss, delay_s=delay_s, jitter_s=jitter_s,
                               rto_s=rto_s)
    finally:
        router.kill(signal.SIGTERM)
    return res


class NetnsPair:
    """Two network namespaces joined by one veth pair: the router's (10.200.b.1) and the
    clients' (10.200.b.2). ``loss(p)`` makes the router's namespace drop each packet in and
    out with probability p (iptables ``statistic`` match: real kernel packet loss, real TCP
    recovery). Needs root, iproute2 and iptables; ``up()`` raises OSError otherwise."""

    def __init__(self):
        tag = f"{os.getpid() % 10000:04d}"
        b = 100 + (os.getpid() % 48) * 3 + 2
        self.r, self.c = f"scf{tag}r", f"scf{tag}c"
        self.rv, self.cv = f"scf{tag}r0", f"scf{tag}c0"
        self.router_ip, self.client_ip = f"10.200.{b}.1", f"10.200.{b}.2"
        self.made: list[str] = []

    @staticmethod
    def _run(*cmd: str) -> None:
        r = subprocess.run(list(cmd), capture_output=True, text=True, timeout=15)
        if r.returncode:
            raise OSError(f"{' '.join(cmd)}: {r.stderr.strip()}")

    def exec(self, ns: str) -> list[str]:
        return ["ip", "netns", "exec", ns]

    def up(self) -> "NetnsPair":
        if os.geteuid() != 0:
            raise OSError("network namespaces need root")
        for tool in ("ip", "iptables"):
            if shutil.which(tool) is None:
                raise OSError(f"no `{tool}` (Debian packages iproute2, iptables)")
        for ns in (self.r, self.c):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=15)
            self._run("ip", "netns", "add", ns)
            self.made.append(ns)
            self._run("ip", "-n", ns, "link", "set", "lo", "up")
        self._run("ip", "link", "add", self.rv, "type", "veth", "peer", "name", self.cv)
        self._run("ip", "link", "set", self.rv, "netns", self.r)
        self._run("ip", "link", "set", self.cv, "netns", self.c)
        self._run("ip", "-n", self.r, "addr", "add", self.router_ip + "/24", "dev", self.rv)
        self._run("ip", "-n", self.c, "addr", "add", self.client_ip + "/24", "dev", self.cv)
        self._run("ip", "-n", self.r, "link", "set", self.rv, "up")
        self._run("ip", "-n", self.c, "link", "set", self.cv, "up")
        return self

    def loss(self, p: float) -> None:
        for chain in ("INPUT", "OUTPUT"):
            self._run(*self.exec(self.r), "iptables", "-F", chain)
            if p > 0:
                self._run(*self.exec(self.r), "iptables", "-A", chain, "-i" if chain == "INPUT"
                          else "-o", self.rv, "-m", "statistic", "--mode", "random",
                          "--probability", f"{p:.6f}", "-j", "DROP")

    def down(self) -> None:
        for ns in self.made:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=15)
        self.made = []


def netns_loss_run(work: Path, loss: float, wall_timeout: float = 120.0,
                   config: str = "configs/small.toml") -> dict:
    """A small run whose processes reach the router over a veth with real packet loss."""
    work.mkdir(parents=True, exist_ok=True)
    net = NetnsPair().up()
    try:
        net.loss(loss)
        router = Router(7447, log=work / "router.log", host=net.router_ip,
                        prefix=net.exec(net.r)).start()
        try:
            res = small_run(work / "run", router.endpoint, config=config, wall_timeout=wall_timeout,
                            prefix=net.exec(net.c))
        finally:
            router.kill(signal.SIGTERM)
    finally:
        net.down()
    res["link"] = dict(loss=loss, kind="netns+iptables")
    return res


# --------------------------------------------------------------------------- fuzz campaign

FUZZ_CONFIG = "configs/mixed.toml"


def fuzz_targets(keys, live_ids=(1, 2)) -> list[tuple[str, object]]:
    """(key, message class or None) for every topic a process subscribes to; None: raw
    (ROS 2 CDR) keys."""
    from swarmcover.bus import messages as m
    rid = 0
    out = [(keys.sense(rid), m.Sense), (keys.cmd_vel(rid), m.CmdVel), (keys.odom(rid), m.Pose),
           (keys.pose(rid), m.Pose), (keys.status(rid), m.Status), (keys.task(rid), m.Task),
           (keys.twin_cmd(rid), m.TwinCmd), (keys.complex, m.Complex), (keys.clock, m.Clock),
           (keys.truth, m.Truth), (keys.spawn, m.Spawn), (keys.remove, m.Remove),
           (keys.mocap("scarab1"), m.MocapPose), (keys.live_cmd(live_ids[0]), m.LiveCmd),
           (keys.demo, m.Demo), (keys.world_info, m.WorldInfo),
           (keys.cmd_vel(live_ids[0]), m.CmdVel), (keys.status(12345), m.Status),
           ("scarab2/cmd_vel", None)]
    return out


def fuzz_processes(procs_start, zargs: list[str], report: Path) -> dict:
    """Start the fuzz targets with ``procs_start(name, argv) -> handle``; returns handles."""
    cfg = FUZZ_CONFIG
    return {
        "world": procs_start("world", ["world", cfg] + zargs),
        "coordinator": procs_start("coordinator", ["coordinator", cfg] + zargs),
        "agent-0": procs_start("agent-0", ["agent", "--id", "0", "--run-config", cfg] + zargs),
        "hwbridge": procs_start("hwbridge", ["hwbridge", cfg, "--report", str(report)] + zargs),
        "fake-robot-1": procs_start("fake-robot-1", ["fake-robot", cfg, "--id", "1"] + zargs),
        "fake-robot-2": procs_start("fake-robot-2", ["fake-robot", cfg, "--id", "2"] + zargs),
    }


def send_fuzz(session, targets, per_topic: int, seed: int = 0, progress=None,
              rate_hz: float | None = None) -> dict:
    """Put ``per_topic`` invalid payloads on every target key (BLOCK: none is dropped on the
    way). Returns {key: count}.

    rate_hz: at most this many puts per second (None: as fast as possible). BLOCK does not
    wait forever: a router whose queue to a subscriber stays full for 5 s (Zenoh's default
    ``congestion_control.block.wait_before_close``) closes that link, and what was queued
    on it is lost; a process starved of CPU while it decodes a flood can fall that far
    behind on a loaded 2-core machine."""
    import zenoh
    rng = random.Random(seed)
    sent = {}
    for key, cls in targets:
        pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        payloads = invalid_payloads(cls, min(per_topic, 2000), rng)
        if cls is None:   # ROS 2 CDR: keep payloads a Twist decoder must refuse
            from swarmcover.hwbridge.ros2 import CdrError, decode_twist
            ok = []
            for p in payloads:
                try:
                    decode_twist(p)
                except (CdrError, ValueError, Exception):
                    ok.append(p)
            payloads = ok or [b""]
        t0 = time.monotonic()
        for i in range(per_topic):
            pub.put(payloads[i % len(payloads)])
            if rate_hz and i % 100 == 99:
                ahead = (i + 1) / rate_hz - (time.monotonic() - t0)
                if ahead > 0:
                    time.sleep(ahead)
        pub.undeclare()
        sent[key] = per_topic
        if progress:
            progress(key)
    return sent


# --------------------------------------------------------------------------- main

def _log(*a) -> None:
    print(*a, file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="bench/faults.py", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=("loss", "netns-loss", "delay", "restart", "fuzz", "all"))
    ap.add_argument("--losses", default="0,0.01,0.02,0.05,0.1,0.15,0.2,0.3",
                    help="per-segment loss levels for the loss sweep")
    ap.add_argument("--delays-ms", default="0,10,50,100,200,400",
                    help="one-way delays (ms) for the delay sweep")
    ap.add_argument("--base-delay-ms", type=float, default=1.0,
                    help="one-way delay during the loss sweep (ms)")
    ap.add_argument("--rto-ms", type=float, default=200.0)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--per-topic", type=int, default=10_000)
    ap.add_argument("--wall-timeout", type=float, default=120.0)
    ap.add_argument("--work", default="/tmp/swarmcover-faults")
    ap.add_argument("--config", default="configs/small.toml",
                    help="run config of the loss, delay and restart runs")
    ap.add_argument("--realtime", action="store_true",
                    help="run them on the real-time clock ([world] mode = realtime) at --rtf")
    ap.add_argument("--rtf", type=float, default=1.0,
                    help="real-time factor with --realtime (1 = a real lab's speed)")
    args = ap.parse_args(argv)
    # SIGTERM unwinds like Ctrl-C, so every finally below stops the processes it started
    signal.signal(signal.SIGTERM, lambda *a: (_ for _ in ()).throw(KeyboardInterrupt()))
    os.chdir(ROOT)
    sys.path.insert(0, str(ROOT))
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    result: dict = {"bench": "faults"}
    if args.what != "fuzz":  # the fuzz campaign has its own config (FUZZ_CONFIG)
        result.update(config=args.config,
                      clock=f"realtime x{args.rtf:g}" if args.realtime else "lockstep")
    config = clocked_config(args.config, work, args.realtime, args.rtf)

    def baseline():
        r = lossy_run(work / "base", 0.0, 0.0, wall_timeout=args.wall_timeout, config=config)
        _log(f"baseline: certified={r['certified']} wall={r['wall_s']:.1f}s")
        return r

    if args.what in ("loss", "all"):
        rows = []
        for loss in [float(x) for x in args.losses.split(",")]:
            for rep in range(args.repeats):
                r = lossy_run(work / f"loss-{loss}-{rep}", loss, args.base_delay_ms / 1000,
                              wall_timeout=args.wall_timeout, seed=rep, rto_s=args.rto_ms / 1000,
                              config=config)
                rows.append(dict(loss=loss, rep=rep, certified=r["certified"],
                                 wall_s=round(r["wall_s"], 2), sim_s=r.get("sim_time_s"),
                                 sim_per_wall=round((r.get("sim_time_s") or 0) / r["wall_s"], 3),
                                 robots=r.get("robots_used"), lost=r["link"]["lost"],
                                 segments=r["link"]["segments"]))
                _log(f"loss {loss:.3f} rep {rep}: {rows[-1]}")
        ok = [r["loss"] for r in rows if r["certified"]]
        bad = sorted({r["loss"] for r in rows if not r["certified"]})
        result["loss"] = dict(rows=rows, rto_ms=args.rto_ms, base_delay_ms=args.base_delay_ms,
                              max_certified_loss=max(ok) if ok else None,
                              first_failed_loss=bad[0] if bad else None)
    if args.what in ("netns-loss", "all"):
        rows = []
        for loss in [float(x) for x in args.losses.split(",")]:
            for rep in range(args.repeats):
                try:
                    r = netns_loss_run(work / f"nloss-{loss}-{rep}", loss, args.wall_timeout,
                                       config=config)
                except OSError as e:
                    _log(f"netns-loss: skipped ({e})")
                    rows = None
                    break
                rows.append(dict(loss=loss, rep=rep, certified=r["certified"],
                                 wall_s=round(r["wall_s"], 2), sim_s=r.get("sim_time_s"),
                                 sim_per_wall=round((r.get("sim_time_s") or 0) / r["wall_s"], 3),
                                 robots=r.get("robots_used")))
                _log(f"netns loss {loss:.3f} rep {rep}: {rows[-1]}")
            if rows is None:
                break
        if rows is not None:
            ok = [r["loss"] for r in rows if r["certified"]]
            bad = sorted({r["loss"] for r in rows if not r["certified"]})
            result["netns_loss"] = dict(rows=rows, max_certified_loss=max(ok) if ok else None,
                                        first_failed_loss=bad[0] if bad else None)
    if args.what in ("delay", "all"):
        rows = []
        for dms in [float(x) for x in args.delays_ms.split(",")]:
            r = lossy_run(work / f"delay-{dms}", 0.0, dms / 1000, jitter_s=dms / 10000,
                          wall_timeout=args.wall_timeout, config=config)
            rows.append(dict(delay_ms=dms, certified=r["certified"], wall_s=round(r["wall_s"], 2),
                             sim_s=r.get("sim_time_s"), robots=r.get("robots_used"),
                             cycles=r.get("cycles"), coverage=r.get("coverage"),
                             sim_per_wall=round((r.get("sim_time_s") or 0) / r["wall_s"], 3)))
            _log(f"delay {dms} ms: {rows[-1]}")
        ok = [r["delay_ms"] for r in rows if r["certified"]]
        result["delay"] = dict(rows=rows, max_certified_delay_ms=max(ok) if ok else None)
    if args.what in ("restart", "all"):
        r = restart_run(work / "restart", wall_timeout=args.wall_timeout, config=config)
        result["restart"] = {k: r.get(k) for k in ("certified", "rc", "wall_s", "sim_time_s",
                                                   "outage_s", "cycles", "robots_used",
                                                   "failures_healed")}
        _log(f"restart: {result['restart']}")
    if args.what in ("fuzz", "all"):
        result["fuzz"] = fuzz_campaign(work / "fuzz", args.per_topic)
    if "loss" in result or "delay" in result:
        result["baseline"] = {k: v for k, v in baseline().items()
                              if k in ("certified", "wall_s", "sim_time_s")}
    print(json.dumps(result), flush=True)
    return 0


def fuzz_campaign(work: Path, per_topic: int) -> dict:
    """Fuzz every topic of a mixed live/virtual set-up; report crashes and drop counters."""
    import uuid

    from swarmcover.bus.keys import Keys
    work.mkdir(parents=True, exist_ok=True)
    router = Router(free_port(), log=work / "router.log").start()
    swarm = "fz" + uuid.uuid4().hex[:6]
    zargs = ["--connect", router.endpoint, "--swarm", swarm]
    children: dict[str, subprocess.Popen] = {}
    logs: dict[str, Path] = {}

    def start(name, argv):
        logs[name] = work / f"{name}.log"
        children[name] = subprocess.Popen(PY + argv, stdout=open(logs[name], "w"),
                                          stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                          cwd=str(ROOT), start_new_session=True)
        return children[name]

    try:
        fuzz_processes(start, zargs, work / "hwbridge.json")
        time.sleep(6.0)
        import argparse as _a

        from swarmcover.bus.session import add_zenoh_args, open_session
        p = _a.ArgumentParser()
        add_zenoh_args(p)
        s = open_session(p.parse_args(zargs))
        t0 = time.monotonic()
        try:
            sent = send_fuzz(s, fuzz_targets(Keys(swarm)), per_topic,
                             progress=lambda k: _log(f"fuzzed {k}"))
        finally:
            s.close()
        send_s = time.monotonic() - t0
        wait_quiet([c.pid for c in children.values()])
        alive = {n: c.poll() is None for n, c in children.items()}
    finally:
        for c in children.values():
            if c.poll() is None:
                os.killpg(c.pid, signal.SIGINT)
        for c in children.values():
            try:
                c.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(c.pid, signal.SIGKILL)
        router.kill(signal.SIGTERM)
    return dict(per_topic=per_topic, topics=len(sent), messages=sum(sent.values()),
                send_s=round(send_s, 2), alive_after=alive,
                counters=read_counters(logs, work / "hwbridge.json"))


def read_counters(logs: dict[str, Path], hw_report: Path) -> dict:
    """Each process's own count of dropped invalid messages, from its logs / report."""
    import re
    out: dict = {}
    for name, f in logs.items():
        text = f.read_text(errors="replace") if f.exists() else ""
        if name == "world":
            m = re.search(r"world stopped: (\{.*\})", text)
            if m:
                out[name] = sum(json.loads(m.group(1)).get("invalid", {}).values())
        elif name == "coordinator":
            m = re.search(r"dropped (\d+) invalid messages", text)
            out[name] = int(m.group(1)) if m else 0
        elif name.startswith("agent-"):
            m = re.search(r"(\d+) invalid messages", text)
            out[name] = int(m.group(1)) if m else None
        elif name.startswith("fake-robot"):
            m = re.search(r"commands=(\d+)", text)
            out[name + ".commands"] = int(m.group(1)) if m else None
    try:
        out["hwbridge"] = json.loads(hw_report.read_text()).get("invalid_messages")
    except (OSError, ValueError):
        out["hwbridge"] = None
    return out


if __name__ == "__main__":
    sys.exit(main())
