"""Benchmark: the wire codec of bus/messages.py, msgspec (now) vs msgpack + per-field
Python checks (before), in-process, measured in the same run.

The agent decodes one Sense per tick, the coordinator every Status, the world every CmdVel
and a Truth of every robot goes to the recorders and the hwbridge: decode speed is what
counts there (issue 20, "Libraries"). Each case is timed as

  * old: ``bus.messages._decode_checked``, the pre-msgspec decode (msgpack.unpackb, then
    every field's checker in Python); it stays as the path that names the field of a
    payload msgspec rejects;
  * new: ``bus.messages.decode``, what every process calls: msgspec decodes into the Struct
    derived from the field declarations, then the message dataclass is built and the
    cross-field rules checked in Python;
  * msgspec alone: the derived Struct's decode without the dataclass and the Python
    rules, the floor for this design;

and encoding as old (msgpack.packb of the map, numpy values made plain first, as before)
vs new (``Message.encode``, msgspec). Both decoders must give the same message and both
encoders the same bytes. Rounds alternate old and new; the median round counts.

    python bench/msgspec_decode.py [--n 5000] [--rounds 7]   (the venv's python, repo root)

The last line on stdout is one JSON object: per case, microseconds per call and the ratios
old / new.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import msgpack

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from swarmcover.bus import messages as m  # noqa: E402


def _old_encode(msg: m.Message) -> bytes:
    """bus.messages.encode before msgspec."""
    d = {"_t": msg.TAG, "_v": msg.VERSION}
    for name, _ in msg._FIELDS:
        d[name] = m._plain(getattr(msg, name))
    return msgpack.packb(d, use_bin_type=True)


def _per_call_us(fn, arg, n: int, *extra) -> float:
    t = time.perf_counter()
    for _ in range(n):
        fn(arg, *extra)
    return (time.perf_counter() - t) / n * 1e6


def cases() -> dict[str, m.Message]:
    return {
        "sense6": m.Sense(robot=3, tick=9, t=0.45, ids=list(range(6)),
                          bearings=[0.1 * i for i in range(6)],
                          back_bearings=[-0.1 * i for i in range(6)], touch=[0.5],
                          touch_robot=[False], task_id=4),
        "sense30": m.Sense(robot=3, tick=9, t=0.45, ids=list(range(30)),
                           bearings=[0.1 * i - 1.5 for i in range(30)],
                           back_bearings=[-0.1 * i + 1.5 for i in range(30)]),
        "status": m.Status(robot=3, seq=17, t=1.5, kind="diffdrive", state="moving", vertex=4,
                           task_id=9, task_state="running", progress=0.25,
                           nbr_ids=[1, 2, 4, 5, 6, 7],
                           nbr_bearings=[0.1, 0.2, 0.3, -1.0, -2.0, 3.0],
                           pose=[1.0, 2.0, 0.3], tick=9),
        "cmdvel": m.CmdVel(robot=3, tick=9, vx=0.1, vy=0.0, wz=0.2, status_seq=17),
        "task": m.Task(task_id=5, robot=3, epoch=1, kind="goto", vertex=7, landmarks=[1, 2, 4],
                       bearings=[0.1, 1.2, -2.0], ref_offsets=[0.0, 0.1, -0.1]),
        "truth100": m.Truth(tick=9, t=0.45, ids=list(range(100)),
                            x=[0.01 * i for i in range(100)], y=[0.02 * i for i in range(100)],
                            theta=[0.0] * 100, live=[False] * 100),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=5000, help="calls per timing")
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    out = {"bench": "msgspec_decode", "n": args.n, "rounds": args.rounds}
    for name, msg in cases().items():
        cls = type(msg)
        payload = msg.encode()
        assert payload == _old_encode(msg), name
        old, new = m._decode_checked(payload, cls), m.decode(payload, cls)
        assert type(new) is cls and new == old, name
        wire = m._decoder(cls)
        t = {k: [] for k in ("old", "new", "msgspec", "enc_old", "enc_new")}
        for _ in range(args.rounds):
            t["old"].append(_per_call_us(m._decode_checked, payload, args.n, cls))
            t["new"].append(_per_call_us(m.decode, payload, args.n, cls))
            t["msgspec"].append(_per_call_us(wire.decode, payload, args.n))
            t["enc_old"].append(_per_call_us(_old_encode, msg, args.n))
            t["enc_new"].append(_per_call_us(m.encode, msg, args.n))
        us = {k: statistics.median(v) for k, v in t.items()}
        out[name] = {"bytes": len(payload),
                     "decode_old_us": round(us["old"], 2), "decode_new_us": round(us["new"], 2),
                     "decode_old_vs_new": round(us["old"] / us["new"], 1),
                     "msgspec_alone_us": round(us["msgspec"], 2),
                     "encode_old_us": round(us["enc_old"], 2),
                     "encode_new_us": round(us["enc_new"], 2),
                     "encode_old_vs_new": round(us["enc_old"] / us["enc_new"], 1)}
        print(name, json.dumps(out[name]), file=sys.stderr)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
