"""Helpers for tests that start real processes: free ports, a process group reaper."""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SWARMCOVER = [sys.executable, "-m", "swarmcover"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Proc:
    """A child process in its own process group, with its output captured line by line."""

    def __init__(self, argv: list[str], env: dict | None = None, cwd: str | None = None):
        self.argv = argv
        e = dict(os.environ)
        e.setdefault("PYTHONUNBUFFERED", "1")
        # the exit watchdog (bus.session.Shutdown) must fire inside the tests' 15 s waits,
        # not at them: a fake-robot once outlived SIGINT by 15 s in CI with the 15 s default
        e.setdefault("SWARMCOVER_EXIT_GRACE_S", "12")
        # a child stops when the test process dies without its teardown (pytest killed by a
        # signal or a CI timeout): a router of test_lab_security outlived a SIGTERMed run
        e.setdefault("SWARMCOVER_WATCH_PARENT", "1")
        e.update(env or {})
        self.p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  stdin=subprocess.DEVNULL, text=True, env=e,
                                  cwd=cwd or str(ROOT), start_new_session=True)
        self.lines: list[str] = []
        self._lock = threading.Lock()
        self._t = threading.Thread(target=self._read, daemon=True)
        self._t.start()

    def _read(self):
        for line in self.p.stdout:
            with self._lock:
                self.lines.append(line.rstrip("\n"))

    @property
    def pid(self) -> int:
        return self.p.pid

    def output(self) -> str:
        with self._lock:
            return "\n".join(self.lines)

    def wait_line(self, needle: str, timeout: float = 15.0) -> str:
        """Wait for an output line containing ``needle``; raise with the output if not."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self._lock:
                for line in self.lines:
                    if needle in line:
                        return line
            if self.p.poll() is not None:
                self._t.join(1)
                with self._lock:
                    for line in self.lines:
                        if needle in line:
                            return line
                break
            time.sleep(0.05)
        raise AssertionError(f"no line with {needle!r} from {self.argv} "
                             f"(rc={self.p.poll()}):\n{self.output()}")

    def signal(self, sig=signal.SIGINT):
        if self.p.poll() is None:
            os.kill(self.p.pid, sig)

    def wait(self, timeout: float = 10.0) -> int:
        rc = self.p.wait(timeout)
        self._t.join(2)
        return rc

    def kill_group(self):
        """SIGTERM then SIGKILL the whole process group; never raises."""
        for sig, grace in ((signal.SIGTERM, 3.0), (signal.SIGKILL, 2.0)):
            try:
                os.killpg(self.p.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.p.wait(grace)
                # the leader is gone; make sure its group is too
                os.killpg(self.p.pid, signal.SIGKILL)
            except ProcessLookupError:
                break
            except subprocess.TimeoutExpired:
                continue
            break


# the robot, sensing and world lines every small lockstep test room shares (a [world]
# section left open: add seed, spawn, ... after it)
LOCKSTEP_ROBOTS_TOML = """
[robots]
radius = 0.06
kind = "holonomic"
v_max = 0.5

[sensing]
noise_deg = 0.5
n_touch = 8

[world]
dt = 0.05
mode = "lockstep"
"""


def wait_until(pred, timeout: float, interval: float = 0.05) -> bool:
    """Poll ``pred`` until it is true or ``timeout`` seconds pass (bus.session.wait_for)."""
    from swarmcover.bus.session import wait_for
    return wait_for(pred, timeout, interval)


def decoded(mail, timeout: float):
    """The messages arriving in ``mail`` (a bus.session.Mailbox), decoded, until ``timeout``
    seconds have passed (undecodable payloads are skipped)."""
    from swarmcover.bus.messages import WireError, decode
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        item = mail.get(0.05)
        if item is None:
            continue
        try:
            yield decode(item[1])
        except WireError:
            continue


def toml_tables(name: str, *rows: dict) -> str:
    """TOML text of an array of tables ``[[name]]``, one per row (values as TOML literals:
    str quoted, lists and numbers as written), for configs written inline in tests."""
    def lit(v):
        return f'"{v}"' if isinstance(v, str) else str(v).replace("True", "true").replace(
            "False", "false")
    return "".join(f"[[{name}]]\n" + "".join(f"{k} = {lit(v)}\n" for k, v in r.items())
                   for r in rows)


def group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:
        return True


def pids_with(needle: str) -> list[int]:
    """Live pids whose command line contains ``needle`` (from /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            stat = (d / "stat").read_text()
        except OSError:
            continue
        if needle in cmd and ") Z " not in stat:
            out.append(int(d.name))
    return out


def client_session(endpoint: str, swarm: str = "default"):
    """An in-test Zenoh client session connected to ``endpoint`` (close it!)."""
    import argparse

    from swarmcover.bus.session import add_zenoh_args, open_session
    p = argparse.ArgumentParser()
    add_zenoh_args(p)
    return open_session(p.parse_args(["--connect", endpoint, "--swarm", swarm]))


def wait_cycle(out: Path, cycle: int, timeout: float) -> dict:
    """The last row of ``out``/cycles.jsonl once its cycle reaches ``cycle``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        f = out / "cycles.jsonl"
        if f.exists():
            rows = [json.loads(x) for x in f.read_text().splitlines() if x.strip()]
            if rows and rows[-1]["cycle"] >= cycle:
                return rows[-1]
        time.sleep(0.2)
    raise AssertionError(f"cycle {cycle} not reached in {timeout} s")


def no_leftovers(out: Path, timeout: float = 10.0) -> None:
    """Asserts that no process whose command line names ``out`` outlives ``timeout``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and pids_with(str(out)):
        time.sleep(0.2)
    assert not pids_with(str(out)), "processes of the run are still alive"


def decoded_into(typ, sink: list, lock):
    """A Zenoh subscriber callback: appends each payload that decodes as ``typ`` to ``sink``
    under ``lock``; undecodable payloads are dropped (it never blocks nor raises)."""
    from swarmcover.bus.messages import decode

    def cb(sample):
        try:
            m = decode(sample.payload.to_bytes(), typ)
        except Exception:
            return
        with lock:
            sink.append(m)
    return cb
