"""``swarmcover view [--port P]``: live view of the swarm in the browser.

A local web page (one HTML file with a canvas, no build step, no network access) draws the
robots, the complex and the fence (frontier K, obstacle O) of a live run or of a replay,
under a header with cycle, robots alive, coverage and state.

Data flow: Zenoh callbacks only enqueue (bus.session.Mailbox); the main loop (``pump``)
decodes, updates a :class:`LiveState` and publishes a JSON snapshot at most ``max_hz``
times a second into a :class:`Snapshot` store; the HTTP server (stdlib ThreadingHTTPServer,
its own threads) only reads that store. Endpoints:
  /        the page, with the current map and state inlined (drawn on load)
  /state   latest state JSON (the page polls it 4x a second)
  /map     the map JSON (WorldInfo as polygons), refetched when ``map_version`` changes
  /healthz "ok"
Robots alive are the liveliness tokens ``alive/robot/*``; robots drawn are the bodies in
the latest Truth. The page zooms (wheel, +/-) and pans (drag; double-click resets), shows a
robot's id and state on hover, pauses (space or the button), draws a scale bar, and while
nothing has arrived says which swarm and router it listens to. It exposes
``window.swarmState`` ({robots_drawn, robots_alive, cycle, px_per_m, hover, paused, ...})
and mirrors it into ``<pre id="swarm-state">`` for headless tests.

``--foxglove`` also serves the same scene as recording/scene.py's ``foxglove.SceneUpdate``
on topic ``/swarmcover/scene`` through foxglove-sdk's WebSocket server (``--foxglove-port``,
default 8766): in Foxglove or Lichtblick, "Open connection" -> Foxglove WebSocket ->
``ws://127.0.0.1:8766``, and add a 3D panel. ``--ros2`` publishes the swarm to ROS 2 over
Zenoh as rmw_zenoh does (swarmcover/ros2.py).
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from swarmcover.bus import messages as m
from swarmcover.bus.keys import Keys
from swarmcover.bus.session import undeclare

import swarmcover.viz as _viz
from swarmcover.viz.coverage import coverage_measure, map_bounds, polygon_xy
from swarmcover.viz.geometry import build_scene, redundant_robots

log = logging.getLogger("swarmcover.view")
PAGE = Path(_viz.__file__).with_name("static") / "view.html"  # package data of viz
_ROLES = ("world", "coordinator", "hwbridge")


def _r(v: float) -> float:
    return round(float(v), 4)


def map_json(info: m.WorldInfo | None, version: int) -> dict:
    """The map for the page: polygons as [[x, y], ...] lists (m), bounds, rv, sources."""
    if info is None:
        return {"version": 0}
    return {"version": version, "name": info.name, "rv": info.rv,
            "robot_radius": info.robot_radius,
            "boundary": polygon_xy(info.boundary).round(4).tolist(),
            "obstacles": [polygon_xy(o).round(4).tolist() for o in info.obstacles],
            "sources": [[_r(v) for v in info.sources[k:k + 3]]
                        for k in range(0, len(info.sources) - 2, 3)],
            "bounds": [_r(v) for v in map_bounds(info, margin=0.05 * info.rv)]}


class LiveState:
    """The latest of everything the page shows. Pure: fed decoded messages, no I/O.

    coverage_fn(info, truth) -> fraction or None is re-evaluated at most every
    ``coverage_period_s`` seconds of wall time (it rasterises the map).
    """

    def __init__(self, coverage: str = "auto", coverage_period_s: float = 0.5):
        self.info: m.WorldInfo | None = None
        self.map_version = 0
        self.truth: m.Truth | None = None
        self.cx: m.Complex | None = None
        self.mocap: dict[int, tuple[float, float]] = {}
        self.alive: set[int] = set()
        self.removed: set[int] = set()   # robots marked redundant so far (history)
        self.roles: dict[str, bool] = {r: False for r in _ROLES}
        self.coverage_fn, self.coverage_label = coverage_measure(coverage)
        self.coverage: float | None = None
        self._cov_at = -1e9
        self._cov_dirty = False
        self.coverage_period_s = coverage_period_s
        self.seq = 0

    def set_info(self, info: m.WorldInfo) -> None:
        if self.info is None or info.encode() != self.info.encode():
            self.info = info
            self.map_version += 1
            self._cov_dirty = True
            self.seq += 1

    def on_message(self, key: str, msg: m.Message) -> None:
        if isinstance(msg, m.Truth):
            self.truth = msg
            self._cov_dirty = True
        elif isinstance(msg, m.Complex):
            self.cx = msg
            self.removed |= redundant_robots(msg)
        elif isinstance(msg, m.Pose):
            if msg.source == "mocap":
                self.mocap[msg.robot] = (msg.x, msg.y)
        elif isinstance(msg, m.WorldInfo):
            self.set_info(msg)
            return
        else:
            return
        self.seq += 1

    def on_token(self, keys: Keys, key: str, present: bool) -> None:
        rel = keys.relative(key).split("/")
        if len(rel) < 3 or rel[0] != "alive":
            return
        if rel[1] == "robot" and rel[2].isdigit():
            rid = int(rel[2])
            (self.alive.add if present else self.alive.discard)(rid)
            if not present:
                self.mocap.pop(rid, None)
        elif rel[1] in self.roles:
            self.roles[rel[1]] = present
        self.seq += 1

    def update_coverage(self, now: float) -> None:
        if not self._cov_dirty or now - self._cov_at < self.coverage_period_s:
            return
        self._cov_at = now
        self._cov_dirty = False
        if self.info is not None and self.truth is not None:
            cov = self.coverage_fn(self.info, self.truth)
            if cov != self.coverage:
                self.coverage = cov
                self.seq += 1

    def snapshot(self) -> dict:
        """The page's state JSON: robots as [id, x, y, live, in_complex, redundant, alive,
        removed] (removed: taken out of the complex as redundant, now outside it)."""
        sc = build_scene(self.truth, self.cx, self.mocap, removed=self.removed)
        robots = [[int(i), _r(x), _r(y), int(lv), int(inc), int(red), int(int(i) in self.alive),
                   int(rm and not inc)]
                  for i, (x, y), lv, inc, red, rm in zip(sc.ids, sc.xy, sc.live, sc.in_complex,
                                                         sc.redundant, sc.removed)]
        seg = lambda a: a.reshape(-1, 4).round(4).tolist()  # noqa: E731
        cx = self.cx
        return {"seq": self.seq, "map_version": self.map_version,
                "t": None if self.truth is None else _r(self.truth.t),
                "tick": None if self.truth is None else self.truth.tick,
                "cycle": None if cx is None else cx.cycle,
                "state": None if cx is None else cx.state,
                "certified": bool(cx.certified) if cx else False,
                "coverage": None if self.coverage is None else round(self.coverage, 5),
                "coverage_label": self.coverage_label,
                "alive": sorted(self.alive), "roles": dict(self.roles),
                "robots": robots,
                "mocap": [[int(k), _r(x), _r(y)] for k, (x, y) in sorted(self.mocap.items())],
                "edges": seg(sc.edges), "frontier": seg(sc.frontier),
                "obstacle": seg(sc.obstacle),
                "triangles": sc.triangles.reshape(-1, 6).round(4).tolist()}


class Snapshot:
    """Thread-safe store of the latest state and map JSON bytes (written by the main loop)."""

    def __init__(self):
        self._lock = threading.Lock()
        self.state = b'{"seq":-1,"robots":[],"alive":[],"cycle":null}'
        self.map = b'{"version":0}'
        self.state_obj: dict = {}
        self.map_obj: dict = {"version": 0}

    def put(self, state: dict, map_obj: dict | None = None) -> None:
        sb = json.dumps(state, separators=(",", ":")).encode()
        mb = json.dumps(map_obj, separators=(",", ":")).encode() if map_obj is not None else None
        with self._lock:
            self.state, self.state_obj = sb, state
            if mb is not None:
                self.map, self.map_obj = mb, map_obj

    def get(self) -> tuple[bytes, bytes, dict, dict]:
        with self._lock:
            return self.state, self.map, self.state_obj, self.map_obj


def render_page(store: Snapshot, template: str | None = None) -> bytes:
    """The page with the current map and state inlined, so it draws on load."""
    html = template if template is not None else PAGE.read_text(encoding="utf-8")
    _, _, st, mp = store.get()
    initial = json.dumps({"map": mp if mp.get("version") else None, "state": st or None},
                         separators=(",", ":")).replace("</", "<\\/")
    return html.replace("/*__INITIAL__*/null", initial, 1).encode("utf-8")


def make_handler(store: Snapshot, template: str):
    class Handler(BaseHTTPRequestHandler):
        server_version = "swarmcover-view"

        def _send(self, body: bytes, ctype: str, status=HTTPStatus.OK) -> None:
            self.send_response(status)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            if self.command != "HEAD":
                self.wfile.write(body)

        def do_GET(self):  # noqa: N802 (stdlib naming)
            path = self.path.split("?", 1)[0]
            try:
                if path in ("/", "/index.html"):
                    self._send(render_page(store, template), "text/html; charset=utf-8")
                elif path == "/state":
                    self._send(store.get()[0], "application/json")
                elif path == "/map":
                    self._send(store.get()[1], "application/json")
                elif path == "/healthz":
                    self._send(b"ok\n", "text/plain")
                else:
                    self._send(b"not found\n", "text/plain", HTTPStatus.NOT_FOUND)
            except (BrokenPipeError, ConnectionResetError):
                pass

        do_HEAD = do_GET

        def log_message(self, fmt, *args):  # quiet: access logs only at debug level
            log.debug("%s %s", self.address_string(), fmt % args)

    return Handler


class ViewServer:
    """The live view on an open session (``run`` can embed it; ``main`` wraps it).

    keys: the swarm's Keys; host/port: where to serve (port 0 = any free port; see
    ``url``); max_hz: snapshot rate limit; coverage: viz.coverage kind.
    Call ``start()``, then ``pump()`` from the owning thread's loop, then ``close()``.
    """

    def __init__(self, session, keys: Keys, *, host: str = "127.0.0.1", port: int = 8765,
                 max_hz: float = 10.0, coverage: str = "auto", info_retry_s: float = 2.0,
                 router: str = "", foxglove_port: int | None = None,
                 ros2: dict | None = None):
        from swarmcover.bus.session import Mailbox, Receiver
        self.session = session
        self.keys = keys
        self.router = router
        self.scene = None
        self.fox_server = None
        self.fox_channel = None
        self._scene_seq = -1
        self._scene_at = -1e9
        self.ros2 = None
        self._ros2_seq = -1
        self._ros2_at = -1e9
        if foxglove_port is not None:
            self._start_foxglove(host, foxglove_port)
        if ros2 is not None:
            from swarmcover.ros2 import Ros2Out
            self.ros2 = Ros2Out(session, **ros2)
        self.state = LiveState(coverage=coverage)
        self.store = Snapshot()
        self.mailbox = Mailbox(maxsize=100_000)
        self.tokens = Mailbox(maxsize=100_000)
        self.receiver = Receiver(log)
        self.min_dt = 1.0 / max_hz if max_hz > 0 else 0.0
        self.info_retry_s = info_retry_s
        self._subs: list = []
        self._published_seq = -1
        self._published_map = -1
        self._last_pub = -1e9
        self._info_at = -1e9
        self._want_info = True
        template = PAGE.read_text(encoding="utf-8")
        self.httpd = ThreadingHTTPServer((host, port), make_handler(self.store, template))
        self.httpd.daemon_threads = True
        self._http_thread: threading.Thread | None = None

    def _start_foxglove(self, host: str, port: int) -> None:
        import foxglove
        from foxglove.channels import SceneUpdateChannel

        from swarmcover.recording.scene import SCENE_TOPIC, SceneState
        self.scene = SceneState()
        self.fox_context = foxglove.Context()
        self.fox_channel = SceneUpdateChannel(SCENE_TOPIC, context=self.fox_context)
        self.fox_server = foxglove.start_server(name=f"swarmcover {self.keys.swarm}", host=host,
                                                port=port, context=self.fox_context)

    @property
    def foxglove_url(self) -> str | None:
        if self.fox_server is None:
            return None
        host = self.httpd.server_address[0]
        return f"ws://{host}:{self.fox_server.port}"

    def _log_scene(self, now: float) -> None:
        """Log the scene to the Foxglove server when it changed (and once a second anyway,
        for clients that joined since: the protocol keeps no last message)."""
        sc = self.scene
        if sc is None or not sc.ready:
            return
        if now - self._scene_at < self.min_dt or (sc.seq == self._scene_seq
                                                  and now - self._scene_at < 1.0):
            return
        self._scene_at = now
        self._scene_seq = sc.seq
        t_ns = time.time_ns()
        self.fox_channel.log(sc.update(t_ns), log_time=t_ns)

    def _ros2_publish(self, now: float) -> None:
        st = self.state
        if self.ros2 is None or st.seq == self._ros2_seq or now - self._ros2_at < self.min_dt:
            return
        self._ros2_at = now
        self._ros2_seq = st.seq
        try:
            self.ros2.publish(st.info, st.truth, st.cx, st.mocap, time.time_ns())
        except Exception as e:  # an output, never fatal to the view
            log.warning("ROS 2 publish failed: %s", e)

    @property
    def url(self) -> str:
        host, port = self.httpd.server_address[:2]
        return f"http://{host}:{port}/"

    def start(self) -> "ViewServer":
        k = self.keys
        from swarmcover.bus.trust import CoordinatorGate  # a Complex only from the coordinator
        gate = CoordinatorGate().attach(self.session, k.prefix)
        self._subs.append(gate)
        for key in (k.truth, k.complex, f"{k.prefix}/robot/*/odom"):
            cb = gate.wrap(self.mailbox.callback) if key == k.complex else self.mailbox.callback
            self._subs.append(self.session.declare_subscriber(key, cb))
        self._subs.append(self.session.liveliness().declare_subscriber(
            f"{k.prefix}/alive/**", self.tokens.callback, history=True))
        self._publish(force=True)
        self._http_thread = threading.Thread(target=self.httpd.serve_forever, name="view-http",
                                             kwargs={"poll_interval": 0.2}, daemon=True)
        self._http_thread.start()
        return self

    def _query_info(self) -> None:
        self._want_info = False
        self._info_at = time.monotonic()
        try:
            for reply in self.session.get(self.keys.world_info, timeout=1.0):
                s = reply.ok
                if s is None:
                    continue
                msg = self.receiver.decode(str(s.key_expr), s.payload.to_bytes(), m.WorldInfo)
                if msg is not None:
                    self.state.set_info(msg)
                    if self.scene is not None:
                        self.scene.on_message(msg)
        except Exception as e:  # a failed query only delays the map
            log.warning("world/info query failed: %s", e)

    def pump(self, timeout: float = 0.05) -> int:
        """Handle what arrived (waiting up to ``timeout`` s for the first item); returns count."""
        import zenoh
        n = 0
        first = self.mailbox.get(timeout)
        items = ([first] if first is not None else []) + self.mailbox.drain()
        for key, payload, _kind in items:
            msg = self.receiver.decode(key, payload)
            if msg is not None:
                self.state.on_message(key, msg)
                if self.scene is not None:
                    self.scene.on_message(msg)
            n += 1
        for key, _payload, kind in self.tokens.drain():
            present = kind == zenoh.SampleKind.PUT
            self.state.on_token(self.keys, key, present)
            if present and self.keys.relative(key).startswith("alive/world/"):
                self._want_info = True
            n += 1
        now = time.monotonic()
        if self.state.info is None and now - self._info_at >= self.info_retry_s:
            self._want_info = True
        if self._want_info:
            self._query_info()
        self.state.update_coverage(now)
        self._publish()
        self._log_scene(now)
        self._ros2_publish(now)
        return n

    def _publish(self, force: bool = False) -> None:
        now = time.monotonic()
        st = self.state
        if not force and (st.seq == self._published_seq or now - self._last_pub < self.min_dt):
            return
        self._last_pub = now
        self._published_seq = st.seq
        mp = None
        if st.map_version != self._published_map:
            mp = map_json(st.info, st.map_version)
            self._published_map = st.map_version
        snap = st.snapshot()
        snap["swarm"] = self.keys.swarm
        snap["router"] = self.router
        self.store.put(snap, mp)

    def close(self) -> None:
        if self.ros2 is not None:
            self.ros2.close()
            self.ros2 = None
        if self.fox_server is not None:
            try:
                self.fox_server.stop()
            except Exception:
                pass
            self.fox_server = None
        undeclare(*self._subs)
        self._subs.clear()
        if self._http_thread is not None:
            self.httpd.shutdown()
            self._http_thread.join(5)
            self._http_thread = None
        self.httpd.server_close()


def _args(p: argparse.ArgumentParser) -> None:
    from swarmcover.viz.coverage import KINDS
    p.add_argument("--port", type=int, default=8765, help="HTTP port (default 8765; 0 = any free)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to serve on (default 127.0.0.1: this machine only)")
    p.add_argument("--coverage", choices=KINDS, default="auto",
                   help="coverage shown in the header (default auto)")
    p.add_argument("--max-hz", type=float, default=10.0, help="state updates per second at most")
    p.add_argument("--foxglove", action="store_true",
                   help="also serve the scene to Foxglove/Lichtblick over foxglove-sdk's "
                        "WebSocket server (topic /swarmcover/scene)")
    p.add_argument("--foxglove-port", type=int, default=8766, metavar="PORT",
                   help="WebSocket port of --foxglove (default 8766; 0 = any free)")
    p.add_argument("--ros2", action="store_true",
                   help="also publish to ROS 2 over Zenoh as rmw_zenoh does: <ns>/poses "
                        "(geometry_msgs/PoseArray) and <ns>/complex "
                        "(visualization_msgs/MarkerArray), frame 'map'")
    p.add_argument("--ros-domain", type=int, default=0, metavar="N",
                   help="ROS_DOMAIN_ID of --ros2 (default 0)")
    p.add_argument("--ros-namespace", default="/swarmcover", metavar="NS",
                   help="ROS namespace of the --ros2 topics (default /swarmcover)")


def _serve(args, session, keys, stop) -> int:
    from swarmcover.bus.node import ready
    from swarmcover.bus.session import DEFAULT_ROUTER
    router = ", ".join(args.connect or ([] if args.mode in ("peer", "router")
                                        else [DEFAULT_ROUTER])) or f"{args.mode} mode"
    view = None
    try:
        try:
            view = ViewServer(session, keys, host=args.host, port=args.port,
                              max_hz=args.max_hz, coverage=args.coverage, router=router,
                              foxglove_port=args.foxglove_port if args.foxglove else None,
                              ros2=({"domain": args.ros_domain,
                                     "namespace": args.ros_namespace}
                                    if args.ros2 else None))
        except ValueError as e:  # --ros-domain / --ros-namespace
            log.error("%s", e)
            return 2
        except OSError as e:
            log.error("--host %s --port %d: cannot serve: %s", args.host, args.port, e)
            return 2
        except RuntimeError as e:  # foxglove-sdk: port taken, bad host
            log.error("--foxglove-port %d: cannot serve: %s", args.foxglove_port, e)
            return 2
        view.start()
        if view.foxglove_url:
            ready(f"foxglove {view.foxglove_url}")
        if view.ros2 is not None:
            ready("ros2 " + " ".join(view.ros2.topics.values()))
        ready(f"view {view.url}")
        log.info("live view of %s (router %s) at %s", keys.prefix, router, view.url)
        while not stop.is_set():
            view.pump(0.05)
    finally:
        if view is not None:
            view.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    from swarmcover.bus.node import run_node
    return run_node("swarmcover view", __doc__, _args, _serve, argv=argv,
                    logger="swarmcover.view", formatter_class=argparse.RawDescriptionHelpFormatter)


if __name__ == "__main__":
    sys.exit(main())
