"""What the benchmarks share: progress on stderr, the in-process benches' config x seed
loop, a free port, a process's CPU time, waiting for a line of a child's stdout, starting
and stopping children, a router to start them against."""
from __future__ import annotations

import os
import socket
from contextlib import contextmanager
import subprocess
import sys
import time

CLK = os.sysconf("SC_CLK_TCK")


def eprint(*a):
    print(*a, file=sys.stderr, flush=True)


def run_configs(description: str, run, argv=None, add_args=None) -> list[dict]:
    """Parse ``configs... [--seeds ...] [--timeout S]`` (every config in configs/ but
    mixed.toml when none is named) and return ``run(config, seed, timeout)`` for each pair,
    with progress on stderr. ``add_args(parser)``: the bench's own flags; ``run`` is then
    called with the parsed arguments as a fourth argument."""
    import argparse
    from pathlib import Path
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("configs", nargs="*")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--timeout", type=float, default=3000.0, help="wall seconds per run")
    if add_args is not None:
        add_args(ap)
    a = ap.parse_args(argv)
    root = Path(__file__).resolve().parents[1]
    configs = a.configs or sorted(str(p) for p in (root / "configs").glob("*.toml")
                                  if p.name != "mixed.toml")
    pairs = [(c, s) for c in configs for s in a.seeds]
    runs = []
    for k, (c, s) in enumerate(pairs):
        eprint(f"[{k + 1}/{len(pairs)}] {Path(c).stem} seed {s} ...")
        runs.append(run(c, s, a.timeout) if add_args is None else run(c, s, a.timeout, a))
    return runs


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid: int) -> float:
    """utime + stime of a process (s), threads included."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK


def wait_line(proc, needle, timeout=30.0) -> str:
    """The first line of ``proc``'s stdout (a text pipe) that holds ``needle``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        line = proc.stdout.readline()
        if not line:
            break
        if needle in line:
            return line
    raise RuntimeError(f"no {needle!r} from {proc.args}")


def stop_all(procs, grace_s: float = 10.0) -> None:
    """SIGINT every child still running (the last started first), then wait for each up to
    ``grace_s`` and kill what is left."""
    for p in reversed(procs):
        if p.poll() is None:
            p.send_signal(2)
    for p in reversed(procs):
        try:
            p.wait(grace_s)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def starter(procs: list, env=None, cwd=None):
    """A function that starts argv as a child (stdout a text pipe, stderr and stdin
    closed) and appends it to ``procs``, for :func:`stop_all`. The children stop if this
    process dies first (SWARMCOVER_WATCH_PARENT)."""
    env = dict(os.environ if env is None else env, SWARMCOVER_WATCH_PARENT="1")

    def start(argv):
        p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                             stdin=subprocess.DEVNULL, text=True, env=env, cwd=cwd)
        procs.append(p)
        return p
    return start


@contextmanager
def router_and_starter(py: str | None = None, env=None, cwd=None):
    """A ``swarmcover router`` on a free loopback port, and a :func:`starter` for more
    children: yields ``(start, endpoint, router)``; every child (the router last) is stopped
    on the way out, whatever happened."""
    procs: list = []
    start = starter(procs, env, cwd)
    ep = f"tcp/127.0.0.1:{free_port()}"
    try:
        router = start([py or sys.executable, "-m", "swarmcover", "router", "--listen", ep])
        wait_line(router, "READY router")
        yield start, ep, router
    finally:
        stop_all(procs)
