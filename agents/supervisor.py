"""Start agent processes on demand and reap them (used by ``swarmcover spawn`` and ``run``).

Children are started with ``subprocess`` (fork+exec with no Python code in between, so it is
safe even in a process that holds an open Zenoh session) as
``python -m swarmcover agent --id N --parent-pid <this pid> <agent args>``. The
``--parent-pid`` makes every agent exit cleanly by itself if the supervisor dies without
stopping it (even by SIGKILL), so no agent outlives its supervisor.
"""
from __future__ import annotations

import logging
import os
import select
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from typing import IO, Sequence

from swarmcover.bus.node import READY_FD_ENV

log = logging.getLogger("swarmcover.supervisor")


@dataclass
class Child:
    rid: int
    proc: subprocess.Popen
    argv: list[str]
    started: float
    ready_fd: int | None = None     # read end of its readiness pipe, until it said READY

    @property
    def pid(self) -> int:
        return self.proc.pid

    def close_ready(self) -> None:
        if self.ready_fd is not None:
            os.close(self.ready_fd)
            self.ready_fd = None


class Supervisor:
    """A set of agent processes keyed by robot id.

    ``agent_args``: flags given to every agent (e.g. ``["--connect", ep, "--swarm", s]``).
    ``new_session``: put each child in its own session/process group (then terminal signals
    reach only the supervisor, which forwards them); default: share the caller's group.
    Use as a context manager, or call :meth:`stop_all` on every exit path.
    """

    def __init__(self, agent_args: Sequence[str] = (), *, python: str = sys.executable,
                 env: dict | None = None, new_session: bool = False, cwd: str | None = None):
        self.agent_args = list(agent_args)
        self.python = python
        self.env = env
        self.new_session = new_session
        self.cwd = cwd
        self.children: dict[int, Child] = {}

    def argv(self, rid: int, extra: Sequence[str] = ()) -> list[str]:
        return [self.python, "-m", "swarmcover", "agent", "--id", str(rid),
                "--parent-pid", str(os.getpid()), *self.agent_args, *extra]

    def start(self, rid: int, extra: Sequence[str] = (), *, stdout: IO | int | None = None,
              stderr: IO | int | None = None, watch_ready: bool = False) -> int:
        """Start the agent of robot ``rid``; returns its pid. Raises ValueError if that
        robot's agent is already running. ``watch_ready``: give it a readiness pipe
        (bus.node.ready writes to it), so :meth:`starting` can tell when it serves."""
        cur = self.children.get(rid)
        if cur is not None and cur.proc.poll() is None:
            raise ValueError(f"robot {rid}: an agent is already running (pid {cur.pid})")
        argv = self.argv(rid, extra)
        env, fds, rfd = self.env, (), None
        if watch_ready:
            rfd, wfd = os.pipe()
            env = dict(os.environ if env is None else env, **{READY_FD_ENV: str(wfd)})
            fds = (wfd,)
        try:
            proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=stdout,
                                    stderr=stderr, env=env, cwd=self.cwd, pass_fds=fds,
                                    start_new_session=self.new_session)
        finally:
            for fd in fds:
                os.close(fd)
        self.children[rid] = Child(rid, proc, argv, time.monotonic(), rfd)
        log.debug("started agent %d (pid %d)", rid, proc.pid)
        return proc.pid

    def starting(self) -> list[int]:
        """Robot ids of children started with ``watch_ready`` that have not said READY yet
        and still run (a child that exited no longer counts)."""
        out = []
        for rid, c in self.children.items():
            if c.ready_fd is None:
                continue
            if c.proc.poll() is not None:
                c.close_ready()
                continue
            r, _, _ = select.select([c.ready_fd], [], [], 0)
            if r:
                c.close_ready()        # READY (or the pipe closed: it exited)
            else:
                out.append(rid)
        return out

    def running(self) -> dict[int, int]:
        """Robot id -> pid of the children still running."""
        return {rid: c.pid for rid, c in self.children.items() if c.proc.poll() is None}

    def poll(self) -> list[tuple[int, int]]:
        """Reap children that exited since the last call: [(robot id, return code)]."""
        out = []
        for rid, c in list(self.children.items()):
            rc = c.proc.poll()
            if rc is not None:
                out.append((rid, rc))
                c.close_ready()
                del self.children[rid]
        return out

    def signal_all(self, sig: int = signal.SIGTERM) -> None:
        for c in self.children.values():
            if c.proc.poll() is None:
                try:
                    c.proc.send_signal(sig)
                except ProcessLookupError:
                    pass

    def stop(self, rid: int, timeout: float = 5.0, sig: int = signal.SIGTERM) -> int | None:
        """Stop one agent (signal, then SIGKILL after ``timeout`` s); returns its code."""
        return self.stop_many([rid], timeout, sig).get(rid)

    def stop_many(self, rids, timeout: float = 5.0,
                  sig: int = signal.SIGTERM) -> dict[int, int]:
        """Stop these agents at once (``sig`` to all, SIGKILL those still up after
        ``timeout`` s in total); robot id -> return code of those that were running."""
        children = [c for c in (self.children.pop(r, None) for r in rids) if c is not None]
        for c in children:
            c.close_ready()
        return _stop(children, timeout, sig)

    def stop_all(self, timeout: float = 5.0, sig: int = signal.SIGTERM) -> dict[int, int]:
        """Stop every agent: ``sig`` to all, wait up to ``timeout`` s in total, SIGKILL the
        rest, reap all. Returns robot id -> return code."""
        children = list(self.children.values())
        self.children.clear()
        for c in children:
            c.close_ready()
        return _stop(children, timeout, sig)

    def __enter__(self) -> "Supervisor":
        return self

    def __exit__(self, *exc) -> None:
        self.stop_all()


def _stop(children: list[Child], timeout: float, sig: int) -> dict[int, int]:
    for c in children:
        if c.proc.poll() is None:
            try:
                c.proc.send_signal(sig)
            except ProcessLookupError:
                pass
    end = time.monotonic() + timeout
    out: dict[int, int] = {}
    for c in children:
        try:
            out[c.rid] = c.proc.wait(max(0.0, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            log.warning("agent %d (pid %d) ignored signal %d: killing it", c.rid, c.pid, sig)
            c.proc.kill()
            out[c.rid] = c.proc.wait()
    return out
