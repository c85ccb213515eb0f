"""Benchmark: how long an agent takes to start, on run's own machine against through a
``swarmcover host`` (issue 18.4).

Starts a router and a host linked to it (loopback), then starts ``--n`` agents one after
another each way, with the same run config (configs/tiny.toml, as --run-config):

  * local: ``swarmcover agent`` started here (as run's Launcher does), from the start to
    its READY line;
  * host: a HostStart query from this process through the router-to-router link, to the
    host's "ready" event received here (the host's own measure, request to READY, is
    reported too).

    python bench/hosts.py [--n 10]          (the venv's python, from the repo root)

Progress goes to stderr; the last line on stdout is one JSON object (seconds).
"""
from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench.common import eprint, free_port, router_and_starter, stop_all, wait_line  # noqa: E402


def _stats(xs: list[float]) -> dict:
    xs = sorted(xs)
    return dict(median=statistics.median(xs), p90=xs[int(0.9 * (len(xs) - 1))], max=xs[-1],
                n=len(xs))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=10)
    args = ap.parse_args(argv)
    from swarmcover.bus.keys import Keys
    from swarmcover.bus.session import Mailbox
    from swarmcover.hosts import HostEvent, HostReply, HostStart, HostStop, decode, encode
    from tests.procs import client_session
    conf = str(ROOT / "configs" / "tiny.toml")
    text = Path(conf).read_text()
    swarm = "b" + uuid.uuid4().hex[:8]
    keys = Keys(swarm)
    py = [sys.executable, "-m", "swarmcover"]
    out = dict(local=[], host_round_trip=[], host_own=[])
    with router_and_starter(cwd=str(ROOT)) as (start, ep, _router):
        zargs = ["--connect", ep, "--swarm", swarm]
        for k in range(args.n):
            t0 = time.monotonic()
            p = start([*py, "agent", "--id", str(k), "--kind", "holonomic", "--run-config",
                       conf, *zargs])
            wait_line(p, "READY agent", 60)
            out["local"].append(time.monotonic() - t0)
            stop_all([p])
        eprint(f"local: {_stats(out['local'])}")
        logs = tempfile.mkdtemp(prefix="bench-host-")
        host = start([*py, "host", "--capacity", "4", "--name", "bench", *zargs, "--listen",
                      f"tcp/127.0.0.1:{free_port()}", "--log-dir", str(logs)])
        wait_line(host, "READY host", 60)
        s = client_session(ep, swarm)
        mb = Mailbox()
        sub = s.declare_subscriber(keys.host_event("bench"), mb.callback)
        try:
            for k in range(100, 100 + args.n):
                t0 = time.monotonic()
                req = HostStart(run="bench", robot=k, config=text)
                rep = [decode(r.ok.payload.to_bytes(), HostReply)
                       for r in s.get(keys.host("bench"), payload=encode(req), timeout=10)]
                assert rep and rep[0].ok, rep
                while True:
                    item = mb.get(30)
                    assert item is not None, "no ready event"
                    ev = decode(item[1], HostEvent)
                    if ev.robot == k and ev.what == "ready":
                        break
                out["host_round_trip"].append(time.monotonic() - t0)
                out["host_own"].append(ev.start_s)
                list(s.get(keys.host("bench"), payload=encode(HostStop(run="bench", robot=k)),
                           timeout=15))
        finally:
            sub.undeclare()
            s.close()
    shutil.rmtree(logs, ignore_errors=True)
    res = {k: _stats(v) for k, v in out.items()}
    eprint(f"host: {res['host_round_trip']} (the host's own: {res['host_own']})")
    print(json.dumps(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
