"""Shared fixtures: a real `swarmcover router` on an ephemeral loopback port, and a process
manager that kills every process a test started, whatever happens."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from procs import SWARMCOVER, Proc, free_port  # noqa: E402


@pytest.fixture
def procs():
    """Start processes with ``procs.start(argv)``; all are killed (by group) at teardown."""

    class Manager:
        def __init__(self):
            self.all: list[Proc] = []

        def start(self, argv, env=None) -> Proc:
            p = Proc(list(argv), env=env)
            self.all.append(p)
            return p

        def swarmcover(self, *args, env=None) -> Proc:
            return self.start(SWARMCOVER + [str(a) for a in args], env=env)

    m = Manager()
    yield m
    for p in reversed(m.all):
        p.kill_group()


@pytest.fixture
def router(procs):
    """A router on a free loopback port. Yields its endpoint, e.g. 'tcp/127.0.0.1:40123'."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    p = procs.swarmcover("router", "--listen", endpoint)
    p.wait_line("READY router", timeout=20)
    return endpoint


@pytest.fixture
def zargs(router):
    """Client flags for the test router, with a swarm name unique to the test."""
    import uuid
    return ["--connect", router, "--swarm", "t" + uuid.uuid4().hex[:8]]
