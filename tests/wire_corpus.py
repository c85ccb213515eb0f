"""A saved corpus of wire payloads and what the codec made of them, to hold the wire contract
across codec rewrites (tests/test_wire_corpus.py).

tests/data/wire_corpus.msgpack.gz was written by this script with the hand-written decoder
(before bus/messages.py decoded with msgspec, commit e30dd53). Per message type it holds:
  * valid payloads: seeded random messages (bounds, ints in float fields, non-ASCII text at
    the length cap), the same with the optional fields left out (an older sender) and with
    the keys in another order, and with ``_v`` sent as 1.0 (accepted: 1.0 == 1); each with
    the bytes the codec re-encoded the decoded message to;
  * invalid payloads (bench/faults.py's fuzz and a few targeted ones), each with the exact
    WireError text decode(p, cls) and decode(p) raised.

    python tests/wire_corpus.py      (from the repo root) rewrites the file from the code as
                                     it is now: only do that on purpose.
"""
from __future__ import annotations

import gzip
import math
import random
import sys
from pathlib import Path

import msgpack

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from swarmcover.bus import messages as m  # noqa: E402

PATH = ROOT / "tests" / "data" / "wire_corpus.msgpack.gz"
VALID_PER_TYPE = 12
INVALID_PER_TYPE = 120


def _text(rng: random.Random, n: int) -> str:
    return "".join(rng.choice("aZ0 _-é✓ß") for _ in range(n))


def _scalar(rng: random.Random, meta: dict):
    kind = meta["kind"]
    if kind in ("float", "floats", "polys"):
        lo, hi = max(meta["lo"], -1e6), min(meta["hi"], 1e6)
        r = rng.random()
        if r < 0.15:
            return lo if lo == meta["lo"] else math.ceil(lo)
        if r < 0.3:
            return hi if hi == meta["hi"] else math.floor(hi)
        if r < 0.45:
            return rng.randint(math.ceil(lo), math.floor(hi))     # an int in a float field
        return rng.uniform(lo, hi)
    if kind in ("int", "ints"):
        lo, hi = meta["lo"], meta["hi"]
        return rng.choice([lo, hi, rng.randint(lo, min(hi, lo + 50)),
                           rng.randint(max(lo, -1000), min(hi, 10**6))])
    if kind in ("bool", "bools"):
        return rng.random() < 0.5
    if kind in ("str", "strs"):
        if meta.get("choices"):
            return rng.choice(meta["choices"])
        cap = min(meta["maxlen"], 200)
        return _text(rng, cap if rng.random() < 0.2 else rng.randint(0, min(cap, 30)))
    raise AssertionError(kind)


def random_message(rng: random.Random, cls):
    vals, lengths = {}, {}
    for group in cls._SAME_LEN:
        n = rng.randint(0, 5)
        for name in group:
            lengths[name] = n
    for name, meta in cls._META.items():
        kind = meta["kind"]
        if kind == "polys":
            vals[name] = [[_scalar(rng, meta) for _ in range(2 * rng.randint(0, 4))]
                          for _ in range(rng.randint(0, 3))]
        elif kind in ("floats", "ints", "bools", "strs"):
            n = lengths.get(name, rng.randint(0, 5))
            vals[name] = [_scalar(rng, meta) for _ in range(n)]
        else:
            vals[name] = _scalar(rng, meta)
    if cls is m.Status:
        vals["pose"] = vals["pose"][:3] if len(vals["pose"]) >= 3 else []
    if cls is m.Task:
        vals["ref_offsets"] = [0.5] * len(vals["landmarks"]) if rng.random() < 0.5 else []
    if cls is m.Complex:
        n = min(len(vals["vertices"]), len(vals["occupants"]))
        vals["vertices"], vals["occupants"] = vals["vertices"][:n], vals["occupants"][:n]
        vals["edges"] = vals["edges"][: len(vals["edges"]) // 2 * 2]
        vals["triangles"] = vals["triangles"][: len(vals["triangles"]) // 3 * 3]
        k = len(vals["edges"]) // 2
        for name in ("frontier", "obstacle", "inferred", "exceptions", "gap_probed"):
            vals[name] = [e % k for e in vals[name]] if k else []
        vals["inferred_why"] = (vals["inferred_why"] + ["forced"] * 9)[: len(vals["inferred"])]
    return cls(**vals)


def _errors(p: bytes, cls) -> dict:
    out = {}
    for key, exp in (("error_expected", cls), ("error_any", None)):
        try:
            m.decode(p, exp)
            out[key] = None
        except m.WireError as e:
            out[key] = str(e)
    return out


def _targeted_invalid(cls) -> list[bytes]:
    """A few hand-made rejects: non-finite, bool-for-int, over-long lists and strings."""
    base = cls().to_dict()
    out = []
    for name, meta in cls._META.items():
        kind = meta["kind"]
        bad = {"float": [float("nan"), float("inf"), True], "int": [True, 1.0],
               "bool": [1], "str": ["x" * (meta.get("maxlen", 0) + 1)],
               "floats": [[float("-inf")]], "ints": [[False]], "bools": [[0]],
               "strs": [["x" * (meta.get("maxlen", 0) + 1)]], "polys": [[[1.0, 2.0, 3.0]]]}
        for v in bad[kind]:
            if kind == "str" and len(v) > 2000:
                continue
            out.append(msgpack.packb({**base, name: v}, use_bin_type=True))
    if cls is m.Sense:
        out.append(msgpack.packb({**base, "ids": [0] * 100_001}, use_bin_type=True))
    return out


def make_corpus(seed: int = 20) -> list[dict]:
    from bench.faults import invalid_payloads
    rng = random.Random(seed)
    out: list[dict] = []
    for cls in m.ALL_MESSAGES:
        made = 0
        while made < VALID_PER_TYPE:
            msg = random_message(rng, cls)
            d = {k: m._plain(v) for k, v in msg.to_dict().items()}
            variants = [d]
            opt = [k for k, meta in cls._META.items() if meta.get("optional")]
            if opt:
                variants.append({k: v for k, v in d.items() if k not in opt})
            keys = list(d)
            rng.shuffle(keys)
            variants.append({k: d[k] for k in keys})
            if made == 0:
                variants.append({**d, "_v": float(cls.VERSION)})
            try:
                payloads = [msgpack.packb(v, use_bin_type=True) for v in variants]
                got = [m.decode(p, cls) for p in payloads]
            except m.WireError:
                continue
            made += 1
            for p, g in zip(payloads, got):
                assert m.decode(g.encode(), cls) == g      # what it re-encodes to is valid
                out.append({"tag": cls.TAG, "payload": p, "ok": True, "reencoded": g.encode()})
        bad = invalid_payloads(cls, INVALID_PER_TYPE, rng) + _targeted_invalid(cls)
        for p in bad:
            e = _errors(p, cls)
            assert e["error_expected"] is not None, (cls.TAG, p)
            out.append({"tag": cls.TAG, "payload": p, "ok": False, **e})
    return out


def load() -> list[dict]:
    return msgpack.unpackb(gzip.decompress(PATH.read_bytes()), raw=False)


if __name__ == "__main__":
    corpus = make_corpus()
    PATH.write_bytes(gzip.compress(msgpack.packb(corpus, use_bin_type=True), mtime=0))
    print(f"{PATH}: {len(corpus)} payloads, {PATH.stat().st_size} bytes")
