"""The wire contract against payloads saved from an earlier codec (tests/wire_corpus.py):
what it accepted still decodes to the same message and re-encodes to the same bytes (so
old recordings replay and old and new processes understand each other), and what it
rejected is still rejected with the same WireError text."""
from __future__ import annotations

import msgpack
import numpy as np
import pytest

import wire_corpus
from swarmcover.bus import messages as m


def _with_added_fields(cls, saved: bytes) -> bytes:
    """The bytes the saved re-encoding becomes once optional fields added to ``cls`` since
    the corpus was written (declared last, each with its default) are appended: a
    newer sender writes them, an older receiver's payloads simply lack them."""
    d = msgpack.unpackb(saved, raw=False)
    added = {name: make() for name, make in cls._OPTIONAL.items() if name not in d}
    return saved if not added else msgpack.packb({**d, **added}, use_bin_type=True)


@pytest.fixture(scope="module")
def corpus() -> list[dict]:
    c = wire_corpus.load()
    assert {e["tag"] for e in c} == set(m.REGISTRY)
    return c


def test_saved_valid_payloads_decode_and_re_encode_to_the_same_bytes(corpus):
    valid = [e for e in corpus if e["ok"]]
    assert len(valid) > 20 * len(m.REGISTRY)
    for e in valid:
        cls = m.REGISTRY[e["tag"]]
        got = m.decode(e["payload"], cls)
        assert type(got) is cls
        assert got.encode() == _with_added_fields(cls, e["reencoded"]), e["tag"]
        assert m.decode(e["payload"]) == got
        assert m.decode(e["reencoded"], cls) == got


def test_saved_invalid_payloads_are_rejected_with_the_same_error(corpus):
    invalid = [e for e in corpus if not e["ok"]]
    assert len(invalid) > 100 * len(m.REGISTRY)
    for e in invalid:
        cls = m.REGISTRY[e["tag"]]
        for key, expected in (("error_expected", cls), ("error_any", None)):
            if e[key] is None:      # valid as some other type: decode(p) accepts it
                assert key == "error_any" and m.decode(e["payload"]).TAG != e["tag"]
                continue
            with pytest.raises(m.WireError) as err:
                m.decode(e["payload"], expected)
            assert str(err.value) == e[key], (e["tag"], key)


def test_numpy_values_encode_as_the_plain_values_they_hold():
    plain = m.Sense(robot=3, tick=9, t=0.5, ids=[1, 2], bearings=[0.25, -1.0],
                    back_bearings=[0.5, 3.0], touch=[0.5], touch_robot=[True])
    arr = m.Sense(robot=np.int64(3), tick=np.int32(9), t=np.float64(0.5),
                  ids=np.array([1, 2]), bearings=np.array([0.25, -1.0]),
                  back_bearings=np.array([0.5, 3.0], dtype=np.float32),
                  touch=np.array([0.5]), touch_robot=np.array([True]))
    assert arr.encode() == plain.encode()
    assert m.decode(arr.encode()) == plain


# --------------------------------------------------------------------------- fast path

def _outcome(fn, p, expected):
    try:
        msg = fn(p, expected)
    except m.WireError as e:
        return ("error", str(e))
    return ("ok", type(msg).__name__, msg.encode())


def _edge_values(meta: dict) -> list:
    """Values at and just past a field's bounds and caps, where two checkers could differ."""
    kind = meta["kind"]
    if kind in ("float", "floats", "polys"):
        lo, hi = meta["lo"], meta["hi"]
        vals = [lo, hi, np.nextafter(lo, -np.inf).item(), np.nextafter(hi, np.inf).item(),
                -0.0, float("nan"), float("inf"), -float("inf"), True, "1.0", None]
        vals += [int(x) for x in (lo, hi) if abs(x) < 2**63] + [2**63 - 1, -2**63, 2**64 - 1]
        if kind == "floats":
            vals = [[v] for v in vals] + vals[:2]
        if kind == "polys":
            vals = [[[v, v]] for v in vals] + [[[0.0]], [0.0, 0.0], [[]], []]
        return vals
    if kind in ("int", "ints"):
        lo, hi = meta["lo"], meta["hi"]
        vals = [lo, hi, lo - 1, hi + 1, float(lo), True, False, 2**63 - 1, -2**63, 2**64 - 1,
                "0", None]
        return [[v] for v in vals] + [lo] if kind == "ints" else vals
    if kind in ("bool", "bools"):
        vals = [True, False, 0, 1, None, "true"]
        return [[v] for v in vals] + [True] if kind == "bools" else vals
    if kind in ("str", "strs"):
        cap = meta["maxlen"]
        vals = [b"bytes", 3, None, ["a"]]
        if meta.get("choices"):
            c = meta["choices"][0]
            vals += list(meta["choices"]) + [c.upper(), c + " ", ""]
        elif cap <= 2000:
            vals += ["é" * cap, "é" * (cap + 1), "✓" * cap, "x" * (cap + 1), ""]
        return [[v] for v in vals] + ["a"] if kind == "strs" else vals
    raise AssertionError(kind)


def test_the_fast_path_decides_as_the_field_checkers_do_at_the_edges():
    """msgspec (decode) and the Python checkers (_decode_checked) agree on every field's
    values at and just past its bounds, on lists over the cap, on missing, extra and
    reordered keys: same message, or same WireError."""
    n = 0
    for cls in m.ALL_MESSAGES:
        base = cls().to_dict()
        cases = [dict(base), {k: v for k, v in base.items() if k not in cls._OPTIONAL},
                 dict(reversed(list(base.items()))), {**base, "_v": 1.0}, {**base, "_v": True},
                 {**base, "_v": None}, {**base, "zz": 1}, {**base, "_t": 7}]
        for name, meta in cls._META.items():
            cases.append({k: v for k, v in base.items() if k != name})
            cases += [{**base, name: v} for v in _edge_values(meta)]
            if meta["kind"] in ("floats", "ints", "bools", "strs", "polys"):
                cases.append({**base, name: [base[name][:1] if meta["kind"] == "polys" else
                                            _edge_values(meta)[-1]] * (m._MAX_LIST + 1)})
        for d in cases:
            try:
                p = m.msgpack.packb(d, use_bin_type=True)
            except (OverflowError, TypeError):
                continue
            for expected in (cls, None, m.Sense):
                assert _outcome(m.decode, p, expected) == _outcome(m._decode_checked, p,
                                                                   expected), (cls.TAG, d)
                n += 1
    assert n > 3000


def test_the_fast_path_decides_as_the_field_checkers_do_on_fuzz():
    import random

    from bench.faults import invalid_payloads
    rng = random.Random(5)
    for cls in m.ALL_MESSAGES:
        for p in invalid_payloads(cls, 300, rng, decode_check=False):
            assert _outcome(m.decode, p, cls) == _outcome(m._decode_checked, p, cls), cls.TAG


def test_msgspec_itself_accepts_the_valid_payloads(corpus):
    """Valid payloads take the fast path (not the Python fallback), but for ``_v`` sent as
    1.0, which the checkers accept (1.0 == 1) and msgspec does not."""
    for e in corpus:
        if e["ok"]:
            cls = m.REGISTRY[e["tag"]]
            v = m.msgpack.unpackb(e["payload"])["_v"]
            if type(v) is int:
                m._decoder(cls).decode(e["payload"])
                m._decoder(None).decode(e["payload"])
