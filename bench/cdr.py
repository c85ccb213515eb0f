"""Benchmark: the hardware bridge's ROS 2 CDR codecs, hand-written ``struct`` code vs
rosbags (the maintained CDR library ``swarmcover view --ros2`` uses), in-process, measured
in the same run (issue 20: "where a maintained library does what is hand-written today,
measure it and use it if it is no worse where it counts").

Where it counts:

  * ``decode_pose_stamped`` runs once per mocap pose in the bridge's main loop
    (``hwbridge/mocap.py``, ``format = "pose_stamped"``): the mocap rate (100-200 Hz, the
    bridge warns outside [50, 200] Hz) times the number of live robots;
  * ``encode_twist`` runs once per live robot per command period (``cmd_rate_hz``, 20 Hz
    by default) in the bridge, ``decode_twist`` as often in each ROS 2 fake robot;
  * ``encode_pose_stamped`` only in stand-in mocap publishers and tests.

Each codec is timed three ways:

  * ``struct``: the hand-written codec as it was before (commit 291e903), kept here as the
    baseline;
  * ``hwbridge``: what ``hwbridge.ros2`` exports now, validation and CdrError wrapping
    included (what the bridge and the fake robot call);
  * ``rosbags``: the typestore's ``serialize_cdr`` / ``deserialize_cdr`` alone on a ready
    message, the floor for a rosbags-based codec.

Rounds alternate the three; the median round counts. Every variant must give the same
bytes (encoders) and the same values (decoders) before anything is timed. The budget
figures are the share of one core the ``hwbridge`` variant takes at the given rates.

    python bench/cdr.py [--n 20000] [--rounds 7] [--robots 20] [--mocap-hz 200] [--cmd-hz 20]
    (the venv's python, from the repo root)

Progress goes to stderr; the last line on stdout is one JSON object: per codec,
microseconds per call, the ratio hwbridge / struct, and the core share at the given rates.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import struct
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from swarmcover.hwbridge import ros2 as r  # noqa: E402
from swarmcover.ros2 import typestore  # noqa: E402

TWIST = "geometry_msgs/msg/Twist"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"


# --------------------------------------------------------------------------- the baseline
# hwbridge/ros2.py's hand-written codecs at commit 291e903 (the encoder of Twist had
# already moved to rosbags; its struct form is the one line the wire test checks against)

_endian = r._endian  # the header check, unchanged


def struct_encode_twist(tw: r.Twist) -> bytes:
    vals = (tw.lx, tw.ly, tw.lz, tw.ax, tw.ay, tw.az)
    if not all(math.isfinite(v) for v in vals):
        raise ValueError(f"Twist: non-finite value in {vals}")
    return r.CDR_LE + struct.pack("<6d", *vals)


def struct_decode_twist(data: bytes) -> r.Twist:
    data = bytes(data)
    e = _endian(data, "Twist")
    if len(data) < 52:
        raise r.CdrError(f"Twist: {len(data)} bytes, expected 52")
    vals = struct.unpack_from(e + "6d", data, 4)
    if not all(math.isfinite(v) for v in vals):
        raise r.CdrError(f"Twist: non-finite value in {vals}")
    return r.Twist(*vals)


def struct_encode_pose_stamped(p: r.PoseStamped) -> bytes:
    sec = math.floor(p.stamp)
    nsec = min(int(round((p.stamp - sec) * 1e9)), 999_999_999)
    fid = p.frame_id.encode() + b"\x00"
    body = bytearray(struct.pack("<iI", sec, nsec) + struct.pack("<I", len(fid)) + fid)
    body += b"\x00" * (-len(body) % 8)
    body += struct.pack("<7d", *p.position, *p.orientation)
    return r.CDR_LE + bytes(body)


def struct_decode_pose_stamped(data: bytes) -> r.PoseStamped:
    data = bytes(data)
    e = _endian(data, "PoseStamped")
    body = data[4:]
    if len(body) < 12:
        raise r.CdrError(f"PoseStamped: {len(data)} bytes, too short for a header")
    sec, nsec, n = struct.unpack_from(e + "iII", body, 0)
    if n < 1 or 12 + n > len(body):
        raise r.CdrError(f"PoseStamped: frame_id length {n} does not fit in {len(data)} bytes")
    raw = body[12:12 + n]
    if raw[-1:] != b"\x00":
        raise r.CdrError("PoseStamped: frame_id is not NUL-terminated")
    try:
        frame_id = raw[:-1].decode()
    except UnicodeDecodeError:
        raise r.CdrError("PoseStamped: frame_id is not UTF-8") from None
    off = 12 + n
    off += -off % 8
    if off + 56 > len(body):
        raise r.CdrError(f"PoseStamped: {len(data)} bytes, too short for the pose")
    vals = struct.unpack_from(e + "7d", body, off)
    if not all(math.isfinite(v) for v in vals):
        raise r.CdrError(f"PoseStamped: non-finite value in {vals}")
    return r.PoseStamped(sec + nsec * 1e-9, frame_id, vals[:3], vals[3:])


# --------------------------------------------------------------------------- timing

def _per_call_us(fn, arg, n: int) -> float:
    t = time.perf_counter()
    for _ in range(n):
        fn(arg)
    return (time.perf_counter() - t) / n * 1e6


def cases():
    """(name, struct fn, hwbridge fn, rosbags-alone fn, argument, argument of rosbags)."""
    ts = typestore()
    tw = r.Twist(lx=0.21, ly=0.0, lz=0.0, ax=0.0, ay=0.0, az=-0.7)
    ps = r.PoseStamped(1712.25, "mocap", (1.25, -0.5, 0.05), (0.0, 0.0, 0.6, 0.8))
    tw_b, ps_b = struct_encode_twist(tw), struct_encode_pose_stamped(ps)
    tw_m, ps_m = ts.deserialize_cdr(tw_b, TWIST), ts.deserialize_cdr(ps_b, POSE_STAMPED)
    return [
        ("encode_twist", struct_encode_twist, r.encode_twist,
         lambda m: ts.serialize_cdr(m, TWIST), tw, tw_m),
        ("decode_twist", struct_decode_twist, r.decode_twist,
         lambda b: ts.deserialize_cdr(b, TWIST), tw_b, tw_b),
        ("encode_pose_stamped", struct_encode_pose_stamped, r.encode_pose_stamped,
         lambda m: ts.serialize_cdr(m, POSE_STAMPED), ps, ps_m),
        ("decode_pose_stamped", struct_decode_pose_stamped, r.decode_pose_stamped,
         lambda b: ts.deserialize_cdr(b, POSE_STAMPED), ps_b, ps_b),
    ]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=20000, help="calls per timing")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--robots", type=int, default=20, help="live robots (mocap bodies)")
    ap.add_argument("--mocap-hz", type=float, default=200.0, help="poses per body per second")
    ap.add_argument("--cmd-hz", type=float, default=20.0, help="commands per robot per second")
    args = ap.parse_args()
    rate = {"encode_twist": args.cmd_hz, "decode_twist": args.cmd_hz,
            "encode_pose_stamped": args.mocap_hz, "decode_pose_stamped": args.mocap_hz}
    out = {"bench": "cdr", "n": args.n, "rounds": args.rounds, "robots": args.robots,
           "mocap_hz": args.mocap_hz, "cmd_hz": args.cmd_hz}
    for name, old, new, alone, arg, arg_alone in cases():
        a, b = old(arg), new(arg)
        assert a == b, (name, a, b)
        if name.startswith("encode"):
            assert bytes(alone(arg_alone)) == a, name
        t = {"struct": [], "hwbridge": [], "rosbags": []}
        for _ in range(args.rounds):
            t["struct"].append(_per_call_us(old, arg, args.n))
            t["hwbridge"].append(_per_call_us(new, arg, args.n))
            t["rosbags"].append(_per_call_us(alone, arg_alone, args.n))
        us = {k: statistics.median(v) for k, v in t.items()}
        per_s = rate[name] * args.robots
        out[name] = {"struct_us": round(us["struct"], 2), "hwbridge_us": round(us["hwbridge"], 2),
                     "rosbags_alone_us": round(us["rosbags"], 2),
                     "hwbridge_vs_struct": round(us["hwbridge"] / us["struct"], 2),
                     "calls_per_s": per_s,
                     "core_share_pct": round(us["hwbridge"] * per_s / 1e4, 3),
                     "struct_core_share_pct": round(us["struct"] * per_s / 1e4, 3)}
        print(name, json.dumps(out[name]), file=sys.stderr, flush=True)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
