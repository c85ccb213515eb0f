"""Benchmark: how fast the MCAP recorder keeps up, as ratios against baselines in-process.

1. sink: ``McapSink.write`` of realistic payloads (Sense of 6 neighbours, Truth of 100
   robots) vs the floor of writing the same bytes to a plain file.
2. recorder: a real router, this process publishing N messages (BLOCK, nothing dropped)
   to (a) a bare Mailbox subscriber that only enqueues (the floor of Zenoh delivery into
   Python) and (b) a ``Recorder`` on the same key space; throughput of each until the
   last message is delivered / written.
3. plot load: ``swarmcover.plot.load_run`` over a recording vs ``replay.read_messages`` alone.
4. writers: the same JSON messages plus foxglove.SceneUpdates written with the ``mcap``
   package's Writer (what McapSink uses) vs foxglove-sdk's own MCAP writer (Rust), and the
   share of a recording's time the scene costs; also the JSON format vs the old msgpack
   channels (sink time and file size).

    python bench/record.py [--n 20000]        (the venv's python, from the repo root)

Progress goes to stderr; the last line on stdout is one JSON object.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench.common import eprint, free_port  # noqa: E402
from swarmcover.bus import messages as m  # noqa: E402
from swarmcover.bus.keys import Keys  # noqa: E402


def payloads(keys: Keys, n: int) -> list[tuple[str, bytes]]:
    """n (key, payload): 20 Sense per Truth, as a 20-robot swarm at one Truth per tick."""
    sense = [m.Sense(robot=r, tick=1, t=0.05, ids=list(range(6)), bearings=[0.1 * i for i in range(6)],
                     back_bearings=[-0.1 * i for i in range(6)], touch=[0.5], touch_robot=[False]
                     ).encode() for r in range(20)]
    truth = m.Truth(tick=1, t=0.05, ids=list(range(100)), x=[0.01 * i for i in range(100)],
                    y=[0.02 * i for i in range(100)], theta=[0.0] * 100,
                    live=[False] * 100).encode()
    out = []
    for i in range(n):
        if i % 21 == 20:
            out.append((keys.truth, truth))
        else:
            r = i % 21
            out.append((keys.sense(r), sense[r]))
    return out


def bench_sink(items, tmp: Path) -> dict:
    from swarmcover.recording.record import McapSink
    t = time.perf_counter()
    with open(tmp / "plain.bin", "wb") as f:
        for i, (k, d) in enumerate(items):
            f.write(d)
    base = time.perf_counter() - t
    t = time.perf_counter()
    with McapSink(tmp / "sink.mcap") as sink:
        for i, (k, d) in enumerate(items):
            sink.write(k, d, 1_000_000 + i * 1000)
    mcap = time.perf_counter() - t
    return {"n": len(items), "plain_msg_s": len(items) / base, "sink_msg_s": len(items) / mcap,
            "sink_vs_plain_time_ratio": mcap / base,
            "mcap_bytes": (tmp / "sink.mcap").stat().st_size,
            "payload_bytes": sum(len(d) for _, d in items)}


def _session(endpoint: str):
    import argparse as ap

    from swarmcover.bus.session import add_zenoh_args, open_session
    p = ap.ArgumentParser()
    add_zenoh_args(p)
    return open_session(p.parse_args(["--connect", endpoint]))


def _deliver(pub_s, items, done, timeout=120.0) -> float:
    import zenoh
    pubs = {}
    t = time.perf_counter()
    for k, d in items:
        p = pubs.get(k)
        if p is None:
            p = pubs[k] = pub_s.declare_publisher(k, congestion_control=zenoh.CongestionControl.BLOCK)
        p.put(d)
    end = time.monotonic() + timeout
    while done() < len(items) and time.monotonic() < end:
        time.sleep(0.002)
    el = time.perf_counter() - t
    for p in pubs.values():
        p.undeclare()
    if done() < len(items):
        raise RuntimeError(f"only {done()} of {len(items)} delivered in {timeout} s")
    return el


def bench_recorder(items, keys: Keys, tmp: Path) -> dict:
    from swarmcover.bus.session import Mailbox
    from swarmcover.recording.record import Recorder
    port = free_port()
    router = subprocess.Popen([sys.executable, "-m", "swarmcover", "router", "--listen",
                               f"tcp/127.0.0.1:{port}"], cwd=ROOT, stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True, start_new_session=True)
    try:
        for line in router.stdout:
            if line.startswith("READY router"):
                break
        ep = f"tcp/127.0.0.1:{port}"
        sub_s, pub_s = _session(ep), _session(ep)
        try:
            mb = Mailbox()
            count = [0]

            def cb(sample):
                mb.callback(sample)
                count[0] += 1
            sub = sub_s.declare_subscriber(keys.all, cb)
            time.sleep(0.5)
            eprint("recorder bench: bare subscriber ...")
            base = _deliver(pub_s, items, lambda: count[0])
            sub.undeclare()
            rec = Recorder(sub_s, keys.all, tmp / "rec.mcap", world_info_key=None)
            rec.start()
            time.sleep(0.5)
            eprint("recorder bench: Recorder ...")
            recd = _deliver(pub_s, items, lambda: rec.messages)
            stats = rec.stop()
        finally:
            sub_s.close()
            pub_s.close()
    finally:
        os.killpg(router.pid, signal.SIGTERM)
        router.wait(10)
    return {"n": len(items), "bare_sub_msg_s": len(items) / base,
            "recorder_msg_s": len(items) / recd, "recorder_vs_bare_time_ratio": recd / base,
            "recorded": stats["messages"]}


def bench_plot_load(tmp: Path, cycles: int = 200) -> dict:
    from swarmcover.recording.record import McapSink
    from swarmcover.recording.replay import read_messages
    from swarmcover.plot import load_run
    from swarmcover.viz.synth import Scenario
    k = Keys("bench")
    sc = Scenario(n_max=60)
    path = tmp / "run.mcap"
    t_ns = 0
    with McapSink(path) as sink:
        sink.write(k.world_info, sc.info.encode(), 0, kind="query_reply")
        for c in range(cycles):
            cx = sc.complex(min(c, 59), 0.0)
            cx.cycle = c
            sink.write(k.complex, cx.encode(), t_ns)
            for j in range(20):
                t_ns += 50_000_000
                tr = sc.truth(min(c, 59), j / 20, c * 20 + j, t_ns / 1e9).encode()
                sink.write(k.truth, tr, t_ns)
                for r in range(min(c, 59)):  # odometry: the loader decodes live robots' only
                    sink.write(k.odom(r), m.Pose(robot=r, source="sim").encode(), t_ns)
    t = time.perf_counter()
    n = sum(1 for _ in read_messages(path))
    base = time.perf_counter() - t
    t = time.perf_counter()
    run = load_run(path)
    load = time.perf_counter() - t
    return {"messages": n, "frames": len(run.frames), "read_only_s": base, "load_run_s": load,
            "load_vs_read_time_ratio": load / base}


def bench_writers(items, tmp: Path, scenes: int = 200) -> dict:
    """mcap package Writer vs foxglove-sdk's MCAP writer for what a recording holds."""
    import foxglove
    from mcap.writer import CompressionType, Writer

    from swarmcover.recording.record import McapSink, payload_to_json, schema_bytes
    from swarmcover.recording.scene import SCENE_TOPIC, SceneState, scene_schema
    from swarmcover.viz.synth import Scenario
    sc = Scenario(n_max=60)
    st = SceneState()
    st.on_message(sc.info)
    st.on_message(sc.truth(40, 0.5, 1, 0.1))
    st.on_message(sc.complex(40, 0.1))
    t = time.perf_counter()
    updates = [st.update(1_000 + i) for i in range(scenes)]
    build = time.perf_counter() - t
    conv = [(k, payload_to_json(d)[0], m.decode(d).TAG) for k, d in items]
    out = {"scene_build_ms": 1e3 * build / scenes}

    t = time.perf_counter()
    with open(tmp / "w_mcap.mcap", "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="swarmcover", library="bench")
        chans, sids = {}, {}
        for i, (k, js, tag) in enumerate(conv):
            c = chans.get(k)
            if c is None:
                if tag not in sids:
                    sids[tag] = w.register_schema(tag, "jsonschema", schema_bytes(m.REGISTRY[tag]))
                c = chans[k] = w.register_channel(k, "json", sids[tag])
            w.add_message(c, log_time=i, data=js, publish_time=i)
        sch = scene_schema()
        sc_c = w.register_channel(SCENE_TOPIC, "protobuf",
                                  w.register_schema(sch.name, sch.encoding, sch.data))
        for i, u in enumerate(updates):
            w.add_message(sc_c, log_time=i, data=u.encode(), publish_time=i)
        w.finish()
    out["mcap_pkg_s"] = time.perf_counter() - t

    ctx = foxglove.Context()
    t = time.perf_counter()
    with foxglove.open_mcap(tmp / "w_fox.mcap", context=ctx, allow_overwrite=True):
        chans = {}
        for i, (k, js, tag) in enumerate(conv):
            c = chans.get(k)
            if c is None:
                c = chans[k] = foxglove.Channel(k, message_encoding="json", context=ctx,
                                                schema=foxglove.Schema(
                                                    name=tag, encoding="jsonschema",
                                                    data=schema_bytes(m.REGISTRY[tag])))
            c.log(js, log_time=i)
        sc_c = foxglove.channels.SceneUpdateChannel(SCENE_TOPIC, context=ctx)
        for i, u in enumerate(updates):
            sc_c.log(u, log_time=i)
    out["foxglove_sdk_s"] = time.perf_counter() - t
    out["foxglove_vs_mcap_pkg_time_ratio"] = out["foxglove_sdk_s"] / out["mcap_pkg_s"]
    out["mcap_pkg_bytes"] = (tmp / "w_mcap.mcap").stat().st_size
    out["foxglove_sdk_bytes"] = (tmp / "w_fox.mcap").stat().st_size
    # the JSON format against the msgpack channels recordings had before
    t = time.perf_counter()
    with open(tmp / "old.mcap", "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="swarmcover", library="bench")
        chans = {}
        for i, (k, d) in enumerate(items):
            c = chans.get(k) or chans.setdefault(k, w.register_channel(k, "msgpack", 0))
            w.add_message(c, log_time=i, data=d, publish_time=i)
        w.finish()
    old = time.perf_counter() - t
    t = time.perf_counter()
    with McapSink(tmp / "new.mcap") as sink:
        for i, (k, d) in enumerate(items):
            sink.write(k, d, i)
    new = time.perf_counter() - t
    out["json_vs_msgpack_sink_time_ratio"] = new / old
    out["json_vs_msgpack_size_ratio"] = ((tmp / "new.mcap").stat().st_size
                                         / (tmp / "old.mcap").stat().st_size)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=20000, help="messages per measurement")
    args = ap.parse_args()
    keys = Keys("benchrec")
    items = payloads(keys, args.n)
    out = {"bench": "record"}
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        eprint("sink bench ...")
        out["sink"] = bench_sink(items, tmp)
        eprint(json.dumps(out["sink"]))
        out["recorder"] = bench_recorder(items, keys, tmp)
        eprint(json.dumps(out["recorder"]))
        eprint("plot load bench ...")
        out["plot_load"] = bench_plot_load(tmp)
        eprint(json.dumps(out["plot_load"]))
        eprint("writer bench ...")
        out["writers"] = bench_writers(items, tmp)
        eprint(json.dumps(out["writers"]))
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
