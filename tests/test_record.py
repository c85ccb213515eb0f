"""Recording to MCAP and replaying: schemas, the sink, the Recorder class, and a recorded
synthetic run replayed into ``swarmcover topics echo --raw`` with identical payloads."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections import defaultdict

import pytest
from mcap.reader import make_reader

from swarmcover.bus import messages as m
from swarmcover.bus.keys import Keys
from swarmcover.bus.session import Mailbox
from procs import client_session
from swarmcover.recording.record import (McapSink, Recorder, json_to_payload, payload_to_json,
                               resolve_keyexpr, schema_for)
from swarmcover.recording.replay import (JsonDecoderFactory, read_messages, recorded_swarm, remap_key,
                               summary_counts)
from swarmcover.viz.synth import Scenario

SYNTH = [sys.executable, "-m", "swarmcover.viz.synth"]


# --------------------------------------------------------------------------- pure parts

def test_schema_describes_every_field_of_every_message():
    for tag, cls in m.REGISTRY.items():
        s = schema_for(cls)
        json.dumps(s)  # serialisable
        wire = cls().to_dict()
        assert set(s["properties"]) == set(wire), tag
        assert s["properties"]["_t"] == {"const": tag}
        # every field is required but those a sender that predates them may leave out
        optional = {k for k, meta in cls._META.items() if meta.get("optional")}
        assert s["required"] == [k for k in s["properties"] if k not in optional], tag
    assert "ttl" not in schema_for(m.LiveCmd)["required"]          # added with a default
    assert "robot" in schema_for(m.LiveCmd)["required"]
    sense = schema_for(m.Sense)["properties"]
    assert sense["bearings"]["type"] == "array"
    assert sense["bearings"]["items"]["type"] == "number"
    assert sense["bearings"]["items"]["maximum"] == pytest.approx(3.141592654589793)
    assert sense["ids"]["items"] == {"type": "integer", "minimum": 0, "maximum": 2**62}
    status = schema_for(m.Status)["properties"]
    assert sorted(status["state"]["enum"]) == sorted(m.AGENT_STATES)
    assert schema_for(m.WorldInfo)["properties"]["obstacles"]["items"]["type"] == "array"
    assert schema_for(m.Truth)["x-same-length"] == [["ids", "x", "y", "theta", "live"]]


def test_keyexpr_resolution_and_swarm_remap():
    assert resolve_keyexpr(None, "lab") == "sc/lab/**"
    assert resolve_keyexpr("world/**", "lab") == "sc/lab/world/**"
    assert resolve_keyexpr("sc/other/**", "lab") == "sc/other/**"
    assert remap_key("sc/a/world/truth", "b") == "sc/b/world/truth"
    assert remap_key("sc/a/world/truth", None) == "sc/a/world/truth"
    assert remap_key("other/key", "b") == "other/key"


def test_sink_writes_schemas_channels_and_exact_bytes(tmp_path):
    k = Keys("s1")
    sc = Scenario()
    path = tmp_path / "x.mcap"
    truth = sc.truth(3, 0.5, 7, 0.35)
    sent = [(k.truth, truth.encode(), 2_000, "put"),
            (k.world_info, sc.info.encode(), 1_000, "query_reply"),
            (k.alive("robot", 3), b"put", 1_500, "liveliness"),
            (k.complex, sc.complex(3, 0.3).encode(), 3_000, "put"),
            ("sc/s1/unknown/thing", b"\x93\x01\x02\x03", 4_000, "put"),
            (k.alive("robot", 3), b"delete", 5_000, "liveliness")]
    with McapSink(path, metadata={"swarm": "s1"}) as sink:
        for key, data, t, kind in sent:
            sink.write(key, data, t, kind=kind)
        with pytest.raises(ValueError, match="kind='bogus'"):
            sink.write(k.truth, b"", 1, kind="bogus")
    got = list(read_messages(path))
    assert [(r.key, r.data, r.log_time_ns, r.kind) for r in got] == sorted(
        [(a, b, c, d) for a, b, c, d in sent], key=lambda x: x[2])
    schemas = {r.key: r.schema for r in got}
    assert schemas[k.truth] == "Truth" and schemas[k.complex] == "Complex"
    assert schemas[k.world_info] == "WorldInfo" and schemas["sc/s1/unknown/thing"] == "swarmcover.Raw"
    n, chans = summary_counts(path)
    assert n == len(sent)
    assert chans[k.alive("robot", 3)] == "liveliness"
    with open(path, "rb") as f:
        r = make_reader(f)
        summ = r.get_summary()
        for sch in summ.schemas.values():
            assert sch.encoding == "jsonschema"
            assert json.loads(sch.data)["title"] == sch.name
        assert {c.message_encoding for c in summ.channels.values()} == {"json"}
        meta = list(r.iter_metadata())
        assert meta and meta[0].metadata["swarm"] == "s1"
    # mcap's own reader decodes every channel with a JSON decoder, to the messages' fields
    with open(path, "rb") as f:
        dec = {ch.topic: d for _, ch, _, d in
               make_reader(f, decoder_factories=[JsonDecoderFactory()]).iter_decoded_messages()}
    assert dec[k.truth] == json.loads(json.dumps(truth.to_dict()))
    assert dec[k.alive("robot", 3)] == {"token": "delete"}
    assert set(dec["sc/s1/unknown/thing"]) == {"_msgpack_b64"}  # not a map: kept as bytes


def test_json_conversion_is_byte_exact_and_lossless_for_odd_payloads():
    import msgpack
    sc = Scenario()
    for msg in (sc.info, sc.truth(9, 0.3, 4, 0.2), sc.complex(9, 0.2),
                m.Status(robot=3, pose=[1e-300, -0.0, 3.141592653589793], reason="é✓")):
        data, tag = payload_to_json(msg.encode())
        assert tag == msg.TAG and json_to_payload(data) == msg.encode()
        assert m.decode(json_to_payload(data)) == msg
    odd = [b"", b"\xc1", msgpack.packb({"x": float("nan")}), msgpack.packb({1: 2}),
           msgpack.packb({"b": b"\x00\x01"}, use_bin_type=True),
           b"\x81\xa1x\xca\x3f\x80\x00\x00",  # float32 1.0: JSON would repack as float64
           msgpack.packb({"_msgpack_b64": "aGk="})]  # a map that looks like the raw form
    for p in odd:
        data, tag = payload_to_json(p)
        json.loads(data)  # strict JSON
        assert json_to_payload(data) == p


def test_old_msgpack_recordings_still_read_and_convert(tmp_path):
    from mcap.writer import Writer
    k = Keys("old")
    sc = Scenario()
    old = tmp_path / "old.mcap"
    truth, cx = sc.truth(4, 0.5, 3, 0.2).encode(), sc.complex(4, 0.2).encode()
    with open(old, "wb") as f:  # the format recordings had before JSON channels
        w = Writer(f)
        w.start(profile="swarmcover", library="old")
        w.add_metadata("swarmcover", {"swarm": "old"})
        sid = w.register_schema("Truth", "jsonschema", b"{}")
        ct = w.register_channel(k.truth, "msgpack", sid, {"zenoh": "put"})
        cc = w.register_channel(k.complex, "msgpack", 0, {"zenoh": "put"})
        cl = w.register_channel(k.alive("robot", 1), "liveliness", 0, {"zenoh": "liveliness"})
        cw = w.register_channel(k.world_info, "msgpack", 0, {"zenoh": "query_reply"})
        w.add_message(cw, log_time=1, data=sc.info.encode(), publish_time=1)
        w.add_message(cl, log_time=2, data=b"put", publish_time=2)
        w.add_message(ct, log_time=3, data=truth, publish_time=3)
        w.add_message(cc, log_time=4, data=cx, publish_time=4)
        w.finish()
    got = [(r.key, r.data, r.kind) for r in read_messages(old)]
    assert got == [(k.world_info, sc.info.encode(), "query_reply"),
                   (k.alive("robot", 1), b"put", "liveliness"), (k.truth, truth, "put"),
                   (k.complex, cx, "put")]
    assert recorded_swarm(old) == "old"
    new = tmp_path / "new.mcap"
    out = subprocess.run([sys.executable, "-m", "swarmcover", "record", "--from", str(old),
                          "-o", str(new), "-q"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert [(r.key, r.data, r.kind) for r in read_messages(new) if r.kind != "scene"] == got
    with open(new, "rb") as f:
        chans = make_reader(f).get_summary().channels.values()
    assert {c.message_encoding for c in chans} == {"json", "protobuf"}


def test_missing_directory_and_bad_file_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere"):
        McapSink(tmp_path / "nowhere" / "x.mcap")
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(ValueError, match="bad.mcap"):
        list(read_messages(bad))


# --------------------------------------------------------------------------- Recorder

def test_recorder_excludes_counts_and_fetches_world_info_when_world_appears(router, tmp_path):
    swarm = "rec" + uuid.uuid4().hex[:8]
    k = Keys(swarm)
    rec_s = client_session(router, swarm)
    pub_s = client_session(router, swarm)
    path = tmp_path / "r.mcap"
    info = Scenario().info.encode()
    stop = threading.Event()
    rec = Recorder(rec_s, k.all, path, exclude=[f"{k.prefix}/robot/*/sense"])
    try:
        rec.start()
        time.sleep(0.5)
        for i in range(20):
            pub_s.put(k.demo, m.Demo(seq=i, t=0.0, text="x").encode())
            pub_s.put(k.sense(1), m.Sense(robot=1, tick=i).encode())
        # the world comes up late: the recorder must query world/info when its token appears
        q = pub_s.declare_queryable(k.world_info)

        def serve():
            while not stop.is_set():
                query = q.try_recv()
                if query is None:
                    time.sleep(0.01)
                    continue
                query.reply(k.world_info, info)
                query.drop()

        th = threading.Thread(target=serve, daemon=True)
        th.start()
        tok = pub_s.liveliness().declare_token(k.alive("world", "main"))
        deadline = time.monotonic() + 20
        while (rec.messages < 22 or not rec.have_world_info) and time.monotonic() < deadline:
            time.sleep(0.05)
        stats = rec.stop()
        tok.undeclare()
        stop.set()
        th.join(2)
        q.undeclare()
    finally:
        rec.stop()
        rec_s.close()
        pub_s.close()
    assert stats["world_info"] is True
    assert stats["counts"][k.demo] == 20
    assert k.sense(1) not in stats["counts"]
    got = list(read_messages(path))
    assert [r.data for r in got if r.key == k.demo] == [
        m.Demo(seq=i, t=0.0, text="x").encode() for i in range(20)]
    assert any(r.key == k.world_info and r.kind == "query_reply" and r.data == info for r in got)
    assert any(r.key == k.alive("world", "main") and r.data == b"put" for r in got)


# --------------------------------------------------------------------------- end to end

def check_tools_decode_every_channel(path, last_truth: m.Truth) -> None:
    """What Foxglove/Lichtblick do: the ``mcap`` reader decodes every message of every
    channel (JSON, and the protobuf scene), and the last scene shows the robots of the
    last Truth, each with its id."""
    from jsonschema import Draft202012Validator
    from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[JsonDecoderFactory(),
                                                   ProtobufDecoderFactory()])
        summary = reader.get_summary()
        encodings = {c.message_encoding for c in summary.channels.values()}
        validators = {sid: Draft202012Validator(json.loads(sc.data))
                      for sid, sc in summary.schemas.items() if sc.encoding == "jsonschema"}
        n, scenes, topics, checked = 0, [], set(), 0
        for _, channel, _, decoded in reader.iter_decoded_messages():
            n += 1
            topics.add(channel.topic)
            if channel.topic == "/swarmcover/scene":
                scenes.append(decoded)
            else:
                assert isinstance(decoded, dict), channel.topic
                # every JSON message is valid against the schema its channel embeds
                errors = [f"{list(e.absolute_path)}: {e.message}" for e in validators[channel.schema_id].iter_errors(decoded)]
                assert not errors, (channel.topic, errors[:3])
                checked += 1
    assert encodings == {"json", "protobuf"} and n > 100 and checked == n - len(scenes)
    assert len(scenes) >= 3
    last = {e.id: e for e in scenes[-1].entities}
    assert set(last) >= {"walls", "sources", "robots", "robot_ids", "edges", "frontier",
                         "obstacle", "redundant", "coverage"}
    meta = {kv.key: kv.value for kv in last["robots"].metadata}
    ids = [int(i) for i in meta["ids"].split(",") if i]
    assert ids == list(last_truth.ids) and len(last["robots"].spheres) == len(ids)
    assert sorted(int(t.text) for t in last["robot_ids"].texts) == sorted(ids)
    for sp, x, y in zip(last["robots"].spheres, last_truth.x, last_truth.y):
        assert (sp.pose.position.x, sp.pose.position.y) == pytest.approx((x, y))
    assert len(last["walls"].lines[0].points) >= 8  # a closed boundary as a line list


def test_replay_honours_swarm_and_prints_the_recorded_one(router, procs, tmp_path):
    src, dst = Keys("recorded" + uuid.uuid4().hex[:6]), Keys("other" + uuid.uuid4().hex[:6])
    path = tmp_path / "s.mcap"
    with McapSink(path, metadata={"swarm": src.swarm}) as sink:
        for i in range(5):
            sink.write(src.demo, m.Demo(seq=i, text="r").encode(), 1000 + i)
    s = client_session(router, dst.swarm)
    mb = Mailbox()
    sub = s.declare_subscriber("sc/*/demo", mb.callback)
    try:
        time.sleep(0.5)
        rep = procs.swarmcover("replay", path, "--rate", "0", "--start-delay", "0.5", "-q",
                               "--connect", router, "--swarm", dst.swarm)
        assert rep.wait(30) == 0, rep.output()
        assert f"recorded swarm: {src.swarm}; republished as swarm {dst.swarm}" in rep.output()
        deadline = time.monotonic() + 10
        got = []
        while len(got) < 5 and time.monotonic() < deadline:
            item = mb.get(0.1)
            if item is not None:
                got.append(item)
    finally:
        sub.undeclare()
        s.close()
    assert [k for k, _, _ in got] == [dst.demo] * 5
    assert [m.decode(d).seq for _, d, _ in got] == list(range(5))
    bad = procs.swarmcover("replay", path, "--connect", router, "--swarm", "a", "--to-swarm", "b")
    assert bad.wait(20) == 2 and "disagree" in bad.output()

def test_recorded_run_replays_into_topics_echo_with_identical_payloads(router, zargs, procs,
                                                                       tmp_path):
    out = tmp_path / "run.mcap"
    swarm = zargs[zargs.index("--swarm") + 1]
    k = Keys(swarm)
    rec = procs.swarmcover("record", "-o", out, "-q", *zargs)
    rec.wait_line("READY record", timeout=30)
    synth = procs.start(SYNTH + ["--cycles", "8", "--cycle-s", "0.2", "--kill", "6:2", *zargs])
    synth.wait_line("DONE synth", timeout=60)
    assert synth.wait(20) == 0
    time.sleep(0.5)
    rec.signal(signal.SIGINT)
    assert rec.wait(20) == 0, rec.output()

    recorded = list(read_messages(out))
    puts = defaultdict(list)
    for r in recorded:
        if r.kind == "put":
            puts[r.key].append(r.data)
    assert len(puts[k.truth]) >= 20 and len(puts[k.complex]) == 8, {a: len(b) for a, b in puts.items()}
    for key, datas in puts.items():
        for d in datas:
            m.decode(d)  # everything recorded is a valid message
    info = [r for r in recorded if r.kind == "query_reply"]
    assert len(info) == 1 and info[0].key == k.world_info
    tokens = {(r.key, r.data) for r in recorded if r.kind == "liveliness"}
    assert (k.alive("robot", 2), b"put") in tokens and (k.alive("robot", 2), b"delete") in tokens
    check_tools_decode_every_channel(out, m.decode(puts[k.truth][-1]))

    # replay into `topics echo --raw`, a liveliness monitor and a world/info query
    echo = procs.swarmcover("topics", "echo", "**", "--raw", *zargs)
    echo.wait_line("# echo", timeout=30)
    mon = client_session(zargs[1], swarm)
    seen_tokens = Mailbox()
    lsub = mon.liveliness().declare_subscriber(k.alive("robot", "*"), seen_tokens.callback,
                                               history=True)
    try:
        span = (recorded[-1].log_time_ns - recorded[0].log_time_ns) / 1e9
        t0 = time.monotonic()
        rep = procs.swarmcover("replay", out, "--rate", "2", "--start-delay", "1.0",
                               "--hold", "30", "-q", *zargs)
        rep.wait_line("READY replay", timeout=30)
        # the replayer's queryable reaches this session through the router a moment after
        # READY: a get sent before that finds nobody (the full suite failed on it once)
        got, end = [], time.monotonic() + 10
        while not got and time.monotonic() < end:
            got = [r.ok.payload.to_bytes() for r in mon.get(k.world_info, timeout=5) if r.ok]
            if not got:
                time.sleep(0.2)
        assert got == [info[0].data]
        n_puts = sum(len(v) for v in puts.values())
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if sum(1 for line in echo.lines if line.startswith("{")) >= n_puts:
                break
            time.sleep(0.1)
        elapsed = time.monotonic() - t0
        rep.signal(signal.SIGINT)
        assert rep.wait(20) == 0, rep.output()
        assert f"recorded swarm: {swarm} (swarmcover topics list --swarm {swarm})" in rep.output()
    finally:
        lsub.undeclare()
        mon.close()
    echo.signal(signal.SIGINT)
    echo.wait(20)
    got = defaultdict(list)
    for line in echo.lines:
        if line.startswith("{"):
            d = json.loads(line)
            got[d["key"]].append(bytes.fromhex(d["bytes"]))
    assert dict(got) == dict(puts)  # same keys, same payload bytes, same order per key
    assert elapsed >= 0.8 * span / 2  # original timing (at rate 2) was kept, not rushed
    robots_seen = {int(key.rsplit("/", 1)[1]) for key, _, kind in seen_tokens.drain()
                   if str(kind).endswith("PUT")}
    assert robots_seen == {int(key.rsplit("/", 1)[1]) for key, d in tokens if "robot" in key}


def test_recorder_forgotten_stop_still_leaves_a_readable_file(router, tmp_path):
    """A process that exits without Recorder.stop() (an error path) still finishes the file."""
    import subprocess
    out = tmp_path / "forgot.mcap"
    script = f"""
import sys, time
sys.path.insert(0, 'tests')
from procs import client_session
from swarmcover.recording.record import Recorder
from swarmcover.bus import messages as m
s = client_session({router!r}, 'forgot')
rec = Recorder(s, 'sc/forgot/**', {str(out)!r}).start()
time.sleep(0.3)
for i in range(5):
    s.put('sc/forgot/demo', m.Demo(seq=i).encode())
t = time.monotonic() + 10
while rec.messages < 5 and time.monotonic() < t:
    time.sleep(0.02)
s.close()
print('EXIT', rec.messages, flush=True)
"""
    from procs import ROOT
    r = subprocess.run([sys.executable, "-c", script], cwd=str(ROOT), capture_output=True,
                       text=True, timeout=60)
    assert "EXIT 5" in r.stdout, r.stdout + r.stderr
    assert [r.data for r in read_messages(out)] == [m.Demo(seq=i).encode() for i in range(5)]


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_recorded_tiny_run_opens_in_the_tools_with_the_final_robots_in_the_scene(procs,
                                                                                  tmp_path):
    """`run --record` on the tiny map: the mcap package decodes every channel of run.mcap,
    and the scene's last update shows the robots of the last Truth (the ones alive at the
    end), ids included."""
    from procs import free_port
    out = tmp_path / "run"
    p = procs.swarmcover("run", "configs/tiny.toml", "--out", str(out), "--quiet", "--record",
                         "--port", str(free_port()))
    assert p.wait(280) == 0, p.output()[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    truths = [r for r in read_messages(out / "run.mcap", topics=None)
              if r.kind == "put" and r.key.endswith("/world/truth")]
    last = m.decode(truths[-1].data)
    assert summary["certified"] and len(last.ids) >= summary["ideal_count"] == 7
    check_tools_decode_every_channel(out / "run.mcap", last)
