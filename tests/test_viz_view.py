"""The live view: state from Zenoh (synthetic run on the real keys), served over HTTP, and
drawn by the page in headless Chromium (skipped with a reason if Chromium is absent)."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request

import numpy as np
import pytest
from PIL import Image

from swarmcover.bus.keys import Keys
from procs import client_session, free_port
from swarmcover.viz.synth import Scenario
from swarmcover.view import LiveState, Snapshot, map_json, render_page

SYNTH = [sys.executable, "-m", "swarmcover.viz.synth"]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CYCLES, KILL = 10, (7, 3)


def test_live_state_counts_tokens_and_bodies():
    k = Keys("ls")
    sc = Scenario()
    st = LiveState(coverage="disks", coverage_period_s=0.0)
    st.set_info(sc.info)
    st.on_message(k.truth, sc.truth(5, 0.5, 1, 0.1))
    st.on_message(k.complex, sc.complex(5, 0.1))
    for r in range(6):
        st.on_token(k, k.alive("robot", r), True)
    st.on_token(k, k.alive("robot", 2), False)
    st.on_token(k, k.alive("world", "main"), True)
    st.update_coverage(0.0)
    snap = st.snapshot()
    assert snap["alive"] == [0, 1, 3, 4, 5] and snap["roles"]["world"] is True
    assert len(snap["robots"]) == 6 and snap["cycle"] == 5
    assert [r[6] for r in snap["robots"]] == [1, 1, 0, 1, 1, 1]  # robot 2 has no agent
    assert 0 < snap["coverage"] < 1
    assert len(snap["edges"]) == len(sc.complex(5, 0.1).edges) // 2
    json.dumps(snap)
    store = Snapshot()
    store.put(snap, map_json(st.info, st.map_version))
    page = render_page(store).decode()
    assert "/*__INITIAL__*/" not in page and '"version":1' in page and "</script>" in page
    st.set_info(sc.info)  # the same map again: no new version for the page to fetch
    assert st.map_version == 1


def _get_json(url: str):
    with urllib.request.urlopen(url, timeout=5) as r:
        return json.loads(r.read())


def _start_live(procs, zargs):
    """Synthetic run + view; returns (view url, expected alive robots)."""
    synth = procs.start(SYNTH + ["--cycles", str(CYCLES), "--cycle-s", "0.15", "--hold", "60",
                                 "--kill", f"{KILL[0]}:{KILL[1]}", *zargs])
    synth.wait_line("READY synth", timeout=30)
    port = free_port()
    view = procs.swarmcover("view", "--port", port, *zargs)
    line = view.wait_line("READY view", timeout=30)
    url = line.split()[-1]
    expected = Scenario(kills={KILL[0]: [KILL[1]]}).present(CYCLES - 1)
    deadline = time.monotonic() + 40
    st = {}
    while time.monotonic() < deadline:
        try:
            st = _get_json(url + "state")
        except OSError:
            st = {}
        # liveliness and the world's truth arrive separately: wait until both show the
        # robots of the last cycle (a robot spawned in it can be alive before its body)
        bodies = sorted(r[0] for r in st.get("robots") or [])
        if (st.get("cycle") == CYCLES - 1 and st.get("alive") == expected and bodies == expected
                and st.get("map_version")):
            break
        time.sleep(0.2)
    assert st.get("cycle") == CYCLES - 1, st
    return url, expected, st


def _alive_robots(endpoint: str, swarm: str) -> list[int]:
    s = client_session(endpoint, swarm)
    try:
        replies = list(s.liveliness().get(Keys(swarm).alive_robots(), timeout=3))
        return sorted(int(str(r.ok.key_expr).rsplit("/", 1)[1]) for r in replies if r.ok)
    finally:
        s.close()


def test_view_serves_state_matching_liveliness(router, zargs, procs):
    url, expected, st = _start_live(procs, zargs)
    alive = _alive_robots(router, zargs[zargs.index("--swarm") + 1])
    assert alive == expected
    assert st["alive"] == alive
    assert sorted(r[0] for r in st["robots"]) == alive  # every body has its agent token
    assert st["roles"]["world"] and st["roles"]["coordinator"]
    assert st["coverage"] is not None and 0 < st["coverage"] < 1
    assert len(st["frontier"]) + len(st["obstacle"]) > 0
    mp = _get_json(url + "map")
    assert mp["version"] == st["map_version"] and len(mp["boundary"]) == 4
    with urllib.request.urlopen(url, timeout=5) as r:
        page = r.read().decode()
    assert "<canvas" in page and "window.swarmState" in page
    assert "http://" not in page.replace(url, "") and "https://" not in page  # no CDN
    with pytest.raises(urllib.error.HTTPError):
        urllib.request.urlopen(url + "nope", timeout=5)


def _chromium(args: list[str], timeout: float = 90) -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory() as profile:
        return subprocess.run(
            [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking", "--disable-component-update",
             "--disable-sync", "--disable-dev-shm-usage", f"--user-data-dir={profile}", *args],
            capture_output=True, text=True, timeout=timeout)


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed "
                    "(apt-get install -y chromium); the browser test needs it")
def test_browser_draws_every_alive_robot(router, zargs, procs, tmp_path):
    url, expected, _ = _start_live(procs, zargs)
    alive = _alive_robots(router, zargs[zargs.index("--swarm") + 1])
    assert alive == expected
    shot = tmp_path / "view.png"
    r = _chromium([f"--screenshot={shot}", "--window-size=1000,700", url])
    assert shot.exists(), r.stderr[-2000:]
    img = np.asarray(Image.open(shot).convert("RGB"), dtype=np.int16)
    red = (img[..., 0] > 180) & (img[..., 1] < 80) & (img[..., 2] < 80)
    assert img.shape[:2] == (700, 1000) and red.sum() > 100  # robots were painted
    r = _chromium(["--virtual-time-budget=3000", "--dump-dom", url])
    m = re.search(r'<pre id="swarm-state"[^>]*>([^<]*)</pre>', r.stdout)
    assert m, r.stdout[-2000:] + r.stderr[-2000:]
    state = json.loads(m.group(1))
    assert state["robots_drawn"] == state["robots_alive"] == len(alive), state
    assert state["cycle"] == CYCLES - 1 and state["map"] is True and state["draws"] >= 1


# --------------------------------------------------------------------------- interaction

class _Cdp:
    """A minimal Chrome DevTools Protocol client over the page's WebSocket."""

    def __init__(self, ws_url: str):
        from websockets.sync.client import connect
        self.ws = connect(ws_url, max_size=None, open_timeout=20).__enter__()
        self.n = 0

    def call(self, method: str, **params):
        self.n += 1
        self.ws.send(json.dumps({"id": self.n, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=30))
            if msg.get("id") == self.n:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})

    def eval(self, expr: str):
        r = self.call("Runtime.evaluate", expression=expr, returnByValue=True)
        return r.get("result", {}).get("value")

    def state(self) -> dict:
        return json.loads(self.eval("JSON.stringify(window.swarmState)"))

    def close(self):
        self.ws.__exit__(None, None, None)


def _open_page(procs, url: str, tmp_path) -> _Cdp:
    port = free_port()
    procs.start([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--disable-dev-shm-usage", "--window-size=1000,700",
                 f"--user-data-dir={tmp_path / 'profile'}", f"--remote-debugging-port={port}",
                 "about:blank"])
    deadline = time.monotonic() + 30
    pages = []
    while time.monotonic() < deadline and not pages:
        try:
            pages = [t for t in _get_json(f"http://127.0.0.1:{port}/json/list")
                     if t.get("type") == "page"]
        except OSError:
            time.sleep(0.2)
    assert pages, "chromium's DevTools endpoint did not come up"
    cdp = _Cdp(pages[0]["webSocketDebuggerUrl"])
    cdp.call("Page.navigate", url=url)
    return cdp


def _wait(cdp: _Cdp, pred, what: str, timeout: float = 30) -> dict:
    deadline = time.monotonic() + timeout
    st = {}
    while time.monotonic() < deadline:
        try:
            st = cdp.state()
            if pred(st):
                return st
        except (RuntimeError, TypeError, json.JSONDecodeError):
            pass
        time.sleep(0.2)
    raise AssertionError(f"{what}: {st}")


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed "
                    "(apt-get install -y chromium); the browser test needs it")
def test_browser_waits_naming_swarm_and_router_then_zooms_pauses_and_shows_ids(
        router, zargs, procs, tmp_path):
    swarm = zargs[zargs.index("--swarm") + 1]
    view = procs.swarmcover("view", "--port", free_port(), *zargs)
    url = view.wait_line("READY view", timeout=30).split()[-1]
    cdp = _open_page(procs, url, tmp_path)
    try:
        # no world yet: the page says which swarm and which router it listens to
        deadline = time.monotonic() + 20
        msg = ""
        while time.monotonic() < deadline and swarm not in msg:
            msg = cdp.eval("document.getElementById('msg').textContent") or ""
            time.sleep(0.2)
        assert f'swarm "{swarm}"' in msg and router in msg, msg
        synth = procs.start(SYNTH + ["--cycles", str(CYCLES), "--cycle-s", "0.15", "--hold", "60",
                                     "--kill", f"{KILL[0]}:{KILL[1]}", *zargs])
        synth.wait_line("READY synth", timeout=30)
        expected = Scenario(kills={KILL[0]: [KILL[1]]}).present(CYCLES - 1)
        st = _wait(cdp, lambda s: s["cycle"] == CYCLES - 1 and s["robots_drawn"] == len(expected)
                   and s["map"], "the last cycle drawn")
        assert cdp.eval("document.getElementById('msg').textContent") == ""
        # pause: the drawing stops following the run
        cdp.call("Input.dispatchKeyEvent", type="keyDown", key=" ", code="Space",
                 windowsVirtualKeyCode=32, text=" ")
        cdp.call("Input.dispatchKeyEvent", type="keyUp", key=" ", code="Space",
                 windowsVirtualKeyCode=32)
        st = _wait(cdp, lambda s: s["paused"], "paused after space")
        p0, bar0 = st["px_per_m"], st["scale_bar_m"]
        assert p0 > 0 and bar0 > 0
        # zoom in with the wheel: more pixels per metre, a shorter scale bar
        cdp.call("Input.dispatchMouseEvent", type="mouseWheel", x=500, y=380, deltaX=0,
                 deltaY=-600)
        st = _wait(cdp, lambda s: s["px_per_m"] > 1.5 * p0, "zoomed in")
        assert st["scale_bar_m"] < bar0 and st["paused"]
        # hover a robot: its id shows
        rid = expected[len(expected) // 2]
        xy = cdp.eval(f"JSON.stringify(window.swarmView.robotClientXY({rid}))")
        x, y = json.loads(xy)
        cdp.call("Input.dispatchMouseEvent", type="mouseMoved", x=x, y=y)
        st = _wait(cdp, lambda s: s["hover"] == rid, "hover shows the robot")
        tip = cdp.eval("document.getElementById('tip').textContent")
        assert tip.startswith(f"robot {rid} ") and cdp.eval(
            "getComputedStyle(document.getElementById('tip')).display") == "block"
        cdp.call("Input.dispatchMouseEvent", type="mouseMoved", x=3, y=3)
        _wait(cdp, lambda s: s["hover"] is None, "hover cleared off the robots")
    finally:
        cdp.close()


def test_foxglove_websocket_client_receives_scene_updates(router, zargs, procs):
    """A client speaking Foxglove's WebSocket protocol (what Foxglove and Lichtblick do)
    subscribes to /swarmcover/scene of ``view --foxglove`` during a run and decodes the
    SceneUpdates with the advertised protobuf schema."""
    import base64
    import struct

    from mcap.records import Schema
    from mcap_protobuf.decoder import DecoderFactory
    from websockets.sync.client import connect

    synth = procs.start(SYNTH + ["--cycles", str(CYCLES), "--cycle-s", "0.15", "--hold", "60",
                                 "--kill", f"{KILL[0]}:{KILL[1]}", *zargs])
    synth.wait_line("READY synth", timeout=30)
    view = procs.swarmcover("view", "--port", free_port(), "--foxglove", "--foxglove-port",
                            free_port(), *zargs)
    ws_url = view.wait_line("READY foxglove", timeout=30).split()[-1]
    view.wait_line("READY view", timeout=30)
    expected = Scenario(kills={KILL[0]: [KILL[1]]}).present(CYCLES - 1)
    with connect(ws_url, subprotocols=["foxglove.sdk.v1"], max_size=None,
                 open_timeout=20) as ws:
        assert ws.subprotocol == "foxglove.sdk.v1"
        channel = None
        deadline = time.monotonic() + 20
        while channel is None and time.monotonic() < deadline:
            msg = ws.recv(timeout=20)
            if isinstance(msg, str):
                d = json.loads(msg)
                if d.get("op") == "advertise":
                    channel = next((c for c in d["channels"]
                                    if c["topic"] == "/swarmcover/scene"), None)
        assert channel is not None and channel["encoding"] == "protobuf"
        assert channel["schemaName"] == "foxglove.SceneUpdate"
        decode = DecoderFactory().decoder_for("protobuf", Schema(
            id=1, name=channel["schemaName"], encoding="protobuf",
            data=base64.b64decode(channel["schema"])))
        ws.send(json.dumps({"op": "subscribe",
                            "subscriptions": [{"id": 7, "channelId": channel["id"]}]}))
        updates, ids = 0, []
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline:
            msg = ws.recv(timeout=20)
            if not isinstance(msg, bytes) or msg[0] != 1:
                continue
            sub, _log_time = struct.unpack_from("<IQ", msg, 1)
            assert sub == 7
            scene = decode(msg[13:])
            updates += 1
            ents = {e.id: e for e in scene.entities}
            meta = {kv.key: kv.value for kv in ents["robots"].metadata}
            ids = [int(i) for i in meta["ids"].split(",") if i]
            if ids == expected and meta.get("cycle") == str(CYCLES - 1):
                assert len(ents["robots"].spheres) == len(expected)
                assert ents["walls"].lines and ents["edges"].lines
                break
    assert updates >= 1 and ids == expected, (updates, ids, expected)


def test_robots_removed_as_redundant_keep_their_own_mark_in_page_and_scene():
    from swarmcover.bus import messages as m
    from swarmcover.recording.scene import SceneState
    truth = m.Truth(tick=1, t=0.0, ids=[0, 1, 2, 3], x=[0.0, 1.0, 0.5, 3.0],
                    y=[0.0, 0.0, 0.8, 3.0], theta=[0.0] * 4, live=[False] * 4)
    first = m.Complex(cycle=1, vertices=[10, 11, 12, 13], occupants=[0, 1, 2, 3],
                      edges=[10, 11, 10, 12, 11, 12, 12, 13], triangles=[10, 11, 12],
                      redundant=[13])
    later = m.Complex(cycle=2, vertices=[10, 11, 12], occupants=[0, 1, 2],
                      edges=[10, 11, 10, 12, 11, 12], triangles=[10, 11, 12])
    st, sc = LiveState(coverage="none"), SceneState()
    for msg in (truth, first):
        st.on_message("k", msg)
        sc.on_message(msg)
    assert [r[5] for r in st.snapshot()["robots"]] == [0, 0, 0, 1]  # marked redundant
    assert [r[7] for r in st.snapshot()["robots"]] == [0, 0, 0, 0]  # still in the complex
    st.on_message("k", later)
    sc.on_message(later)
    assert [r[7] for r in st.snapshot()["robots"]] == [0, 0, 0, 1]  # removed: own mark
    from mcap.records import Schema
    from mcap_protobuf.decoder import DecoderFactory

    from swarmcover.recording.scene import scene_schema
    sch = scene_schema()
    decode = DecoderFactory().decoder_for("protobuf", Schema(id=1, name=sch.name,
                                                             encoding=sch.encoding, data=sch.data))
    ents = {e.id: e for e in decode(sc.update(1).encode()).entities}
    assert len(ents["removed"].cubes) == 1 and len(ents["redundant"].cubes) == 0
    assert ents["removed"].cubes[0].pose.position.x == 3.0
