"""The wire contract: every message round-trips; bad payloads are rejected naming the field."""
from __future__ import annotations

import math

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmcover.bus import ALL_MESSAGES, Complex, Keys, Sense, Status, Task, WireError, decode
from swarmcover.bus.keys import TOPICS, message_for_key, topic_table_markdown
from swarmcover.bus.messages import REGISTRY


def _scalar(meta):
    kind = meta["kind"]
    if kind == "float":
        return st.floats(max(meta["lo"], -1e6), min(meta["hi"], 1e6), allow_nan=False)
    if kind == "int":
        return st.integers(max(meta["lo"], -(2**40)), min(meta["hi"], 2**40))
    if kind == "bool":
        return st.booleans()
    if kind == "str":
        if meta["choices"]:
            return st.sampled_from(meta["choices"])
        return st.text(max_size=min(meta["maxlen"], 40))
    raise AssertionError(kind)


def _elem(meta):
    kind = meta["kind"]
    if kind == "floats":
        return st.floats(max(meta["lo"], -1e6), min(meta["hi"], 1e6), allow_nan=False)
    if kind == "ints":
        return st.integers(max(meta["lo"], 0), min(meta["hi"], 10_000))
    if kind == "bools":
        return st.booleans()
    if kind == "polys":
        return st.lists(st.floats(-1e3, 1e3), min_size=6, max_size=12).map(
            lambda v: v[: len(v) // 2 * 2])
    if kind == "strs":
        return st.text(max_size=min(meta["maxlen"], 20))
    raise AssertionError(kind)


@st.composite
def messages(draw, cls):
    vals = {}
    lists = [n for n, m in cls._META.items()
             if m["kind"] in ("floats", "ints", "bools", "polys", "strs")]
    lengths = {}
    for group in cls._SAME_LEN:
        n = draw(st.integers(0, 6))
        for name in group:
            lengths[name] = n
    for name, meta in cls._META.items():
        if name in lists:
            n = lengths.get(name, draw(st.integers(0, 6)))
            vals[name] = draw(st.lists(_elem(meta), min_size=n, max_size=n))
        else:
            vals[name] = draw(_scalar(meta))
    # cross-field rules of a few types
    if cls is Status:
        vals["pose"] = vals["pose"][:3] if len(vals["pose"]) >= 3 else []
    if cls is Task and vals["ref_offsets"]:
        vals["ref_offsets"] = [0.5] * len(vals["landmarks"])
    if cls is Task:
        vals["sweep_points"] = (vals["sweep_points"] * 2)[: 2 * len(vals["sweep_landmarks"])]
        vals["sweep_landmarks"] = vals["sweep_landmarks"][: len(vals["sweep_points"]) // 2]
    if cls is Complex:
        vals["occupants"] = vals["occupants"][: len(vals["vertices"])]
        vals["vertices"] = vals["vertices"][: len(vals["occupants"])]
        vals["edges"] = vals["edges"][: len(vals["edges"]) // 2 * 2]
        vals["triangles"] = vals["triangles"][: len(vals["triangles"]) // 3 * 3]
        m = len(vals["edges"]) // 2
        vals["frontier"] = [e % m for e in vals["frontier"]] if m else []
        vals["obstacle"] = [e % m for e in vals["obstacle"]] if m else []
        vals["inferred"] = [e % m for e in vals["inferred"]] if m else []
        vals["exceptions"] = [e % m for e in vals["exceptions"]] if m else []
        vals["gap_probed"] = [e % m for e in vals["gap_probed"]] if m else []
        vals["inferred_why"] = vals["inferred_why"][: len(vals["inferred"])]
    return cls(**vals)


@pytest.mark.parametrize("cls", ALL_MESSAGES, ids=lambda c: c.TAG)
def test_round_trip(cls):
    @settings(max_examples=60, deadline=None)
    @given(messages(cls))
    def check(msg):
        msg.validate()
        back = decode(msg.encode(), cls)
        assert back == msg
        assert back.to_dict()["_t"] == cls.TAG
    check()


def good_sense() -> Sense:
    return Sense(robot=1, tick=3, t=0.15, ids=[2, 5], bearings=[0.1, -2.0],
                 back_bearings=[3.0, 1.1], touch=[0.5], touch_robot=[False])


def _tamper(msg, **changes) -> bytes:
    d = msg.to_dict()
    d.update(changes)
    return msgpack.packb(d)


@pytest.mark.parametrize("changes, field", [
    (dict(bearings=[0.1, float("nan")]), "bearings"),
    (dict(bearings=[0.1, 7.0]), "bearings"),
    (dict(tick=-1), "tick"),
    (dict(tick=1.5), "tick"),
    (dict(robot=True), "robot"),
    (dict(ids=[2, "x"]), "ids"),
    (dict(back_bearings=[1.0]), "back_bearings"),       # length mismatch with ids
    (dict(touch_robot=[1]), "touch_robot"),
    (dict(t=float("inf")), "t"),
    (dict(_v=99), "_v"),
    (dict(_t="Nope"), "_t"),
    (dict(extra=1), "extra"),
])
def test_bad_sense_names_the_field(changes, field):
    with pytest.raises(WireError) as e:
        decode(_tamper(good_sense(), **changes), Sense)
    assert e.value.field == field
    assert e.value.msg_type in ("Sense", "Message")
    assert field in str(e.value)


def test_missing_field_is_named():
    d = good_sense().to_dict()
    del d["bearings"]
    with pytest.raises(WireError, match=r"Sense\.bearings: missing"):
        decode(msgpack.packb(d))


def test_wrong_type_for_key():
    with pytest.raises(WireError) as e:
        decode(good_sense().encode(), Task)
    assert e.value.field == "_t"


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64))
def test_garbage_never_escapes_as_another_exception(data):
    try:
        decode(data)
    except WireError:
        pass


@pytest.mark.parametrize("cls", ALL_MESSAGES, ids=lambda c: c.TAG)
def test_truncated_payloads_rejected(cls):
    data = cls().encode()
    for cut in range(0, len(data) - 1, max(1, len(data) // 17)):
        with pytest.raises(WireError):
            decode(data[:cut])


def test_task_ref_offsets_rule_and_status_pose_rule():
    t = Task(task_id=1, robot=2, kind="goto", landmarks=[1, 2], bearings=[0.0, 1.0],
             ref_offsets=[0.1])
    with pytest.raises(WireError, match="ref_offsets"):
        decode(t.encode())
    s = Status(robot=1, pose=[1.0, 2.0])
    with pytest.raises(WireError, match="pose"):
        decode(s.encode())
    c = Complex(vertices=[0, 1], occupants=[3, 4], edges=[0, 1], frontier=[1])
    with pytest.raises(WireError, match="frontier"):
        decode(c.encode())


def test_keys_scope_by_swarm_and_parse():
    a, b = Keys("lab1"), Keys("lab2")
    assert a.sense(7) == "sc/lab1/robot/7/sense" != b.sense(7)
    assert a.robot_id(a.status(12)) == 12
    assert a.robot_id(a.alive("robot", 5)) == 5
    assert a.robot_id(a.complex) is None
    for bad in ("", "a/b", "x*", "a b", "é"):
        with pytest.raises(ValueError, match="swarm name"):
            Keys(bad)


def test_every_topic_maps_to_its_message():
    k = Keys("x")
    assert message_for_key(k.sense(3)) is Sense
    assert message_for_key(k.task(3)) is Task
    assert message_for_key(k.complex) is Complex
    assert message_for_key(k.mocap("body_1")).TAG == "MocapPose"
    for t in TOPICS:
        if t.message in ("liveliness",):
            continue
        assert t.message in REGISTRY, t


def test_readme_topic_table_matches_code():
    from pathlib import Path
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    assert topic_table_markdown() in readme, (
        "README topic table is out of date: paste the output of "
        "`python -c 'from swarmcover.bus.keys import topic_table_markdown as t; print(t())'`")


def test_angles_accept_pi_boundary():
    s = Sense(robot=0, ids=[1], bearings=[-math.pi], back_bearings=[math.pi])
    assert decode(s.encode()).bearings == [-math.pi]


def test_zenoh_cli_decoder_entry_point():
    """`zenoh subscribe ... --decoder swarmcover` finds our decoder through the entry point."""
    import json
    from importlib.metadata import entry_points
    eps = [e for e in entry_points(group="zenoh_cli.codecs.decoders") if e.name == "swarmcover"]
    assert eps, "entry point zenoh_cli.codecs.decoders:swarmcover is not installed"
    decode_fn = eps[0].load()
    line = json.loads(decode_fn("sc/x/robot/1/sense", good_sense().encode()))
    assert line["_t"] == "Sense" and line["key"] == "sc/x/robot/1/sense" and line["ids"] == [2, 5]
    bad = json.loads(decode_fn("sc/x/robot/1/sense", b"\x00"))
    assert "_error" in bad and "Sense" not in bad.get("_t", "")


@given(hi=st.floats(-1.0, 2.0), end=st.booleans(), lo=st.floats(-1.0, 1.0),
       by=st.lists(st.integers(0, 10**6), max_size=20),
       tail=st.sampled_from(["", " (return: lost landmarks)"]))
def test_a_sweep_reason_carries_its_stoppers_and_fits_a_status(hi, end, lo, by, tail):
    """"swept HI LO by IDS": the fractions parse back (3 decimals), the robots that stopped
    the sweep too (sorted, at most SWEEP_BY_MAX), after a failed return's words as well; the
    reason always fits Status.reason."""
    from swarmcover.bus.messages import (SWEEP_BY_MAX, Status, parse_sweep_reason,
                                         sweep_reason, sweep_stoppers)
    r = sweep_reason(hi, -math.inf if end else lo, by) + tail
    h, l = parse_sweep_reason(r)
    assert h == pytest.approx(hi, abs=6e-4)
    assert (l == -math.inf) if end else l == pytest.approx(lo, abs=6e-4)
    assert sweep_stoppers(r) == tuple(sorted(set(by))[:SWEEP_BY_MAX])
    Status(robot=1, reason=r)
