"""Benchmark: decoding a typed message with bus/messages.py (msgpack + per-field Python
checks) vs msgspec (a Struct with the same constraints, validated in C), in-process.

The agent decodes one Sense per tick and the coordinator every Status: decode speed is what
counts there (issue 20, "Libraries"). Sense with 6 and 30 neighbours and a Truth of 100
robots; each decoded the same way by both, the results compared field by field.

    python bench/msgspec_decode.py [--n 20000]      (the venv's python, from the repo root)

The last line on stdout is one JSON object: per message, microseconds per decode and the
ratio bus / msgspec.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Annotated

import msgspec

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bus import messages as m  # noqa: E402

PI = math.pi + 1e-9
Angle = Annotated[float, msgspec.Meta(ge=-PI, le=PI)]
Id = Annotated[int, msgspec.Meta(ge=0, le=2**62)]
Coord = Annotated[float, msgspec.Meta(ge=-1e6, le=1e6)]


class Sense(msgspec.Struct, tag_field="_t", tag="Sense", forbid_unknown_fields=True):
    _v: int = 1
    robot: Id = 0
    tick: Id = 0
    t: Annotated[float, msgspec.Meta(ge=-1e9, le=1e9)] = 0.0
    ids: list[Id] = []
    bearings: list[Angle] = []
    back_bearings: list[Angle] = []
    touch: list[Angle] = []
    touch_robot: list[bool] = []
    task_id: Annotated[int, msgspec.Meta(ge=-1, le=2**62)] = -1


class Truth(msgspec.Struct, tag_field="_t", tag="Truth", forbid_unknown_fields=True):
    _v: int = 1
    tick: Id = 0
    t: Annotated[float, msgspec.Meta(ge=-1e9, le=1e9)] = 0.0
    ids: list[Id] = []
    x: list[Coord] = []
    y: list[Coord] = []
    theta: list[Angle] = []
    live: list[bool] = []


def _time(fn, payload, n) -> float:
    t = time.perf_counter()
    for _ in range(n):
        fn(payload)
    return (time.perf_counter() - t) / n * 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=20000)
    args = ap.parse_args()
    cases = {
        "sense6": (m.Sense(robot=3, tick=9, t=0.45, ids=list(range(6)),
                           bearings=[0.1 * i for i in range(6)],
                           back_bearings=[-0.1 * i for i in range(6)], touch=[0.5],
                           touch_robot=[False]), Sense),
        "sense30": (m.Sense(robot=3, tick=9, t=0.45, ids=list(range(30)),
                            bearings=[0.1 * i - 1.5 for i in range(30)],
                            back_bearings=[-0.1 * i + 1.5 for i in range(30)]), Sense),
        "truth100": (m.Truth(tick=9, t=0.45, ids=list(range(100)),
                             x=[0.01 * i for i in range(100)], y=[0.02 * i for i in range(100)],
                             theta=[0.0] * 100, live=[False] * 100), Truth),
    }
    out = {"bench": "msgspec_decode", "n": args.n}
    for name, (msg, struct) in cases.items():
        payload = msg.encode()
        dec = msgspec.msgpack.Decoder(struct)
        a, b = m.decode(payload), dec.decode(payload)
        assert all(getattr(a, f) == getattr(b, f) for f, _ in a._FIELDS), name
        bus_us = _time(m.decode, payload, args.n)
        ms_us = _time(dec.decode, payload, args.n)
        out[name] = {"bus_us": round(bus_us, 2), "msgspec_us": round(ms_us, 2),
                     "bus_vs_msgspec_time_ratio": round(bus_us / ms_us, 1)}
        print(name, json.dumps(out[name]), file=sys.stderr)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
