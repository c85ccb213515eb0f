"""Hosts on one machine for the multi-host tests: network namespaces joined by veth pairs
(`ip netns`, Debian's iproute2; needs root). Every address is on veths the test creates
(10.200.x.y); nothing leaves the machine.

  ns R   the router's namespace, one veth address per side: 10.200.(base+k).1
  side k a namespace per letter of ``sides`` (10.200.(base+k).2), and with ``root`` one
         more pair to the test's own namespace, last
"""
from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys

import pytest

PY = sys.executable


def _ip(*args, ns: str | None = None) -> None:
    cmd = (["ip", "netns", "exec", ns, "ip"] if ns else ["ip"]) + list(args)
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=15)
    if r.returncode:
        raise OSError(f"{' '.join(cmd)}: {r.stderr.strip()}")


class Lab:
    """A router namespace and one namespace per letter of ``sides``; ``up()`` raises
    OSError if they cannot be made here."""

    def __init__(self, sides: str, root: bool = True):
        tag = f"{os.getpid() % 10000:04d}"
        self.base = 100 + (os.getpid() % 36) * 4
        self.tag, self.sides, self.root = tag, sides, root
        self.r = f"sc{tag}r"
        self.made: list[str] = []
        self.host_veth = f"sc{tag}h1"

    def ns(self, side: str) -> str:
        return f"sc{self.tag}{side}"

    def addr(self, k: int, host: int) -> str:
        return f"10.200.{self.base + k}.{host}"

    def up(self) -> None:
        for ns in (self.r, *map(self.ns, self.sides)):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=15)
            _ip("netns", "add", ns)
            self.made.append(ns)
            _ip("link", "set", "lo", "up", ns=ns)
        ends = [(s, self.ns(s)) for s in self.sides] + ([("h", None)] if self.root else [])
        for k, (side, peer) in enumerate(ends):
            ra, pb = f"sc{self.tag}{side}0", f"sc{self.tag}{side}1"
            _ip("link", "add", ra, "type", "veth", "peer", "name", pb)
            _ip("link", "set", ra, "netns", self.r)
            if peer:
                _ip("link", "set", pb, "netns", peer)
            _ip("addr", "add", self.addr(k, 1) + "/24", "dev", ra, ns=self.r)
            _ip("link", "set", ra, "up", ns=self.r)
            _ip("addr", "add", self.addr(k, 2) + "/24", "dev", pb, ns=peer)
            _ip("link", "set", pb, "up", ns=peer)

    def down(self) -> None:
        for ns in self.made:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=15)
        if self.root:
            subprocess.run(["ip", "link", "del", self.host_veth], capture_output=True, timeout=15)


@contextlib.contextmanager
def lab_or_skip(sides: str, root: bool = True):
    """The namespaces of a test, torn down after it; skips saying why where they cannot
    be made (not root, no iproute2, no CAP_NET_ADMIN)."""
    if os.geteuid() != 0:
        pytest.skip("network namespaces need root (CAP_NET_ADMIN); not root here")
    if shutil.which("ip") is None:
        pytest.skip("no `ip` command (Debian package iproute2)")
    lab = Lab(sides, root)
    try:
        lab.up()
    except (OSError, subprocess.TimeoutExpired) as e:
        lab.down()
        pytest.skip(f"cannot create network namespaces here: {e}")
    try:
        yield lab
    finally:
        lab.down()


def in_ns(ns: str, *argv: str) -> list[str]:
    """``python -m swarmcover ARGV`` inside namespace ``ns``."""
    return ["ip", "netns", "exec", ns, PY, "-m", "swarmcover", *argv]
