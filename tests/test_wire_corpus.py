"""The wire contract against payloads saved from an earlier codec (tests/wire_corpus.py):
what it accepted still decodes to the same message and re-encodes to the same bytes (so
old recordings replay and old and new processes understand each other), and what it
rejected is still rejected with the same WireError text."""
from __future__ import annotations

import numpy as np
import pytest

import wire_corpus
from bus import messages as m


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
        assert got.encode() == e["reencoded"], e["tag"]
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
