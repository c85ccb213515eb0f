"""`run`'s report and supervision rules as plain code: strict JSON, ratios only when
certified, the ground-truth false-certificate check, cycles across coordinator restarts,
the stall rules (robots_max, no progress), the certificate re-check, and robots_max from
the map."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from swarmcover.bus.messages import Complex, Truth
from swarmcover.recheck import recheck
from swarmcover.run import (RunState, StallWatch, compute_summary, default_robots_max,
                            resolve_config, build_parser, strict_json, twin_tracking)
from swarmcover.world.config import load_config
from swarmcover.world.groundtruth import coverage_fraction, euler_bound, reachable_uncovered
from swarmcover.world.maps import WorldMap, build_map


def _strict(text: str):
    def bad(c):
        raise ValueError(f"non-strict JSON constant {c}")
    return json.loads(text, parse_constant=bad)


def _room(w=4.0, h=3.0) -> WorldMap:
    return WorldMap(name="room", boundary=np.array([[0, 0], [w, 0], [w, h], [0, h]], float), obstacles=[],
                    sources=np.array([[0.5, 0.5, 0.0]]))


def _lattice(w, h, s):
    xs, ys = np.meshgrid(np.arange(0.25, w, s), np.arange(0.25, h, s * math.sqrt(3) / 2))
    xs = xs + (np.arange(xs.shape[0])[:, None] % 2) * s / 2
    P = np.c_[xs.ravel(), ys.ravel()]
    return P[(P[:, 0] < w) & (P[:, 1] < h)]


def test_strict_json_has_no_nan_and_keeps_numbers():
    text = strict_json({"a": float("nan"), "b": [np.float64(1.5), float("inf")],
                        "c": np.int64(3), "d": {"e": np.bool_(True)}})
    assert _strict(text) == {"a": None, "b": [1.5, None], "c": 3, "d": {"e": True}}


def test_uncertified_summary_has_null_ratios_and_a_stop_reason():
    cfg = load_config("configs/tiny.toml")
    wm = build_map(cfg)
    t = Truth(ids=[0, 1], x=[0.5, 1.0], y=[0.5, 0.5], theta=[0.0, 0.0], live=[False, False], t=10.0)
    s = compute_summary(cfg, wm, t, None, dict(certified=False, stop_reason="wall_timeout",
                                               sim_time_s=10.0))
    _strict(strict_json(s))
    assert s["stop_reason"] == "wall_timeout" and s["certified"] is False
    assert s["ratio"] is None and s["ratio_same_spacing"] is None and s["robots_per_bound"] is None
    assert s["euler_bound"] == euler_bound(wm, cfg.rv)["robots"] and s["sim_s_per_robot"] == 5.0
    # the bound at the deployment spacing d0 = rv - eps is higher (smaller triangles)
    assert s["d0_m"] == pytest.approx(0.9 * cfg.rv)
    assert s["euler_bound_d0"] == euler_bound(wm, 0.9 * cfg.rv)["robots"] > s["euler_bound"]
    assert s["robots_per_bound_d0"] is None
    assert s["mean_spacing"] is None and s["false_certificate"] is False
    assert s["inferred_obstacle_edges"] is None  # the coordinator did not send them
    # nothing at all (the world died before a truth arrived) still gives a summary
    s = compute_summary(cfg, wm, None, None, dict(certified=False, stop_reason="world_died"))
    assert _strict(strict_json(s))["coverage"] == 0.0
    # and says which software made it: the same code and seed can differ across versions
    import numpy, pymunk, scipy
    sw = _strict(strict_json(s))["software"]
    assert (sw["numpy"], sw["scipy"], sw["pymunk"]) == (numpy.__version__, scipy.__version__,
                                                          pymunk.version)
    assert sw["python"].count(".") == 2 and sw["eclipse-zenoh"]
    import platform
    assert sw["machine"] == platform.machine()
    assert sw["numpy_simd"] in ("X86_V2", "X86_V3", "X86_V4", "ASIMD", "SVE", "baseline")


def test_reachable_uncovered_finds_the_hole_a_false_certificate_hides():
    wm = _room()
    full = _lattice(4.0, 3.0, 0.8)
    frac, cov, r = coverage_fraction(wm, full, 1.0, return_mask=True)
    assert frac > 0.99
    assert reachable_uncovered(wm, cov, r, (0.5, 0.5), 0.06, 1.0)["uncovered_reachable_m2"] == 0.0
    half = full[full[:, 0] < 1.5]
    frac, cov, r = coverage_fraction(wm, half, 1.0, return_mask=True)
    rep = reachable_uncovered(wm, cov, r, (0.5, 0.5), 0.06, 1.0)
    # the far part of the room beyond everyone's reach (x > ~2.2) and 0.5 rv from the walls
    assert 1.5 < rep["uncovered_reachable_m2"] < 3.0
    assert rep["where"][0] >= 2.0 and rep["where"][2] <= 3.55 and rep["where"][1] >= 0.45
    # the summary flags it LOUDLY when the run claims certified
    cfg = load_config("configs/tiny.toml")
    ids = list(range(len(half)))
    t = Truth(ids=ids, x=half[:, 0].tolist(), y=half[:, 1].tolist(), theta=[0.0] * len(ids),
              live=[False] * len(ids), t=1.0)
    s = compute_summary(cfg, wm, t, None, dict(certified=True, stop_reason="certified"))
    assert s["false_certificate"] is True and s["uncovered_reachable_m2"] > 1.5


def test_a_certificate_is_judged_by_its_own_complex_not_by_robots_left_outside_it():
    """Robots cut off and sent away (or freed as redundant) stand where they stopped and
    see, but the certificate is about the complex's robots: a complex covering half the
    room, with the other half's robots alive outside it, is a false certificate (covered
    by all robots alive, it passed: bench/unseen.py seed 0 map 8, 100% against 54.5%)."""
    wm = _room()
    full = _lattice(4.0, 3.0, 0.8)
    ids = list(range(len(full)))
    t = Truth(ids=ids, x=full[:, 0].tolist(), y=full[:, 1].tolist(), theta=[0.0] * len(ids),
              live=[False] * len(ids), t=1.0)
    inside = [i for i in ids if full[i, 0] < 1.5]
    cfg = load_config("configs/tiny.toml")
    s = compute_summary(cfg, wm, t, Complex(occupants=inside),
                        dict(certified=True, stop_reason="certified"))
    assert s["coverage"] > 0.99 and s["coverage_complex"] < 0.7
    assert s["false_certificate"] is True and s["uncovered_reachable_m2"] > 1.5
    assert s["robots_used"] == len(inside)
    # the whole lattice in the complex: no false certificate
    s = compute_summary(cfg, wm, t, Complex(occupants=ids), dict(certified=True))
    assert s["coverage_complex"] > 0.99 and s["false_certificate"] is False


def test_cycles_and_failures_healed_add_up_across_coordinator_restarts():
    st = RunState()
    for c in range(6):   # the first coordinator planned cycles 0..5, then was killed
        st.on_cycle(Complex(cycle=c, epoch=11, failures_healed=1 if c >= 3 else 0))
    for c in range(9):   # the restarted one counts from 0 again and certifies at 8
        st.on_cycle(Complex(cycle=c, epoch=42, failures_healed=0))
    assert st.cycles == 6 + 8 and st.failures_healed == 1
    assert st.end("robots_max", "x") and not st.end("certified")
    assert st.rc == 1 and st.stop_reason == "robots_max" and not st.certified


def test_the_decided_truth_outlives_a_world_that_ticks_on_while_the_run_stops():
    """The summary's world is the one at the last complex's tick, even when the world ran
    on for more than the 400 ticks the run keeps (its roster empty once agents stopped)."""
    st = RunState()
    tr = lambda k: Truth(tick=k, t=k * 0.05, ids=[1], x=[0.0], y=[0.0], theta=[0.0],  # noqa: E731
                         live=[False])
    for k in range(10):
        st.saw_truth(tr(k))
    st.saw_complex(Complex(cycle=3, epoch=1, t=0.45, state="certified"))
    for k in range(10, 2000):
        st.saw_truth(tr(k))
    assert st.decided_truth().tick == 9 and st.last_truth.tick == 1999
    st.saw_complex(Complex(cycle=4, epoch=1, t=200.0))   # its truth arrives after it
    st.saw_truth(tr(4000))
    assert st.decided_truth().tick == 4000
    assert RunState().decided_truth() is None


def _cx(cycle, vertices, frontier=1, obstacle=0, robots=None, epoch=1, state="running"):
    return Complex(cycle=cycle, epoch=epoch, vertices=list(vertices),
                   occupants=list(vertices), edges=[0, 1] * max(frontier, obstacle, 1),
                   frontier=list(range(frontier)), obstacle=list(range(obstacle)),
                   robots=len(vertices) if robots is None else robots, state=state)


def test_stall_watch_ends_at_robots_max_and_when_nothing_progresses():
    w = StallWatch(robots_max=5, at_cap=5, stall=20)
    assert w.on_complex(_cx(0, range(3))) is None
    assert w.on_complex(_cx(1, range(5))) is None          # a new vertex: progress
    out = [w.on_complex(_cx(c, range(5))) for c in range(2, 7)]
    assert out[:-1] == [None] * 4 and out[-1][0] == "robots_max"
    # below the cap: no_progress only after `stall` idle cycles; progress resets it
    w = StallWatch(robots_max=100, at_cap=5, stall=20)
    w.on_complex(_cx(0, range(3), frontier=4))
    assert all(w.on_complex(_cx(c, range(3), frontier=4)) is None for c in range(1, 15))
    assert w.on_complex(_cx(15, range(3), frontier=3)) is None    # the fence closes a bit
    res = [w.on_complex(_cx(c, range(3), frontier=3)) for c in range(16, 36)]
    assert res[-1][0] == "no_progress" and all(r is None for r in res[:-1])
    # a restarted coordinator (new epoch) starts afresh
    assert w.on_complex(_cx(0, range(3), frontier=3, epoch=2)) is None


def _certified_square() -> Complex:
    # two triangles 0-1-2 and 1-3-2 filling a unit square; the four sides are obstacle edges
    edges = [0, 1, 0, 2, 1, 2, 1, 3, 2, 3]
    return Complex(cycle=3, epoch=1, vertices=[0, 1, 2, 3], occupants=[10, 11, 12, 13],
                   edges=edges, triangles=[0, 1, 2, 1, 2, 3], frontier=[], obstacle=[0, 1, 3, 4],
                   certified=True, state="certified", robots=4)


def test_recheck_accepts_a_true_certificate_and_refuses_forged_ones():
    good = _certified_square()
    pos = {10: (0, 0), 11: (0.8, 0), 12: (0, 0.8), 13: (0.8, 0.8)}
    assert recheck(good, pos, 1.0).ok
    d = good.to_dict()
    d.pop("_t"), d.pop("_v")

    def forged(**kw):
        return Complex(**dict(d, **kw))

    assert not recheck(forged(triangles=[]), pos, 1.0).ok                 # nothing certified
    assert not recheck(forged(frontier=[2]), pos, 1.0).ok                 # K not empty
    assert not recheck(forged(obstacle=[0, 1]), pos, 1.0).ok              # sides 1-3, 2-3 open
    assert "neither obstacle nor exception" in recheck(forged(obstacle=[0, 1]), pos, 1.0).why
    assert recheck(forged(obstacle=[0, 1], exceptions=[3, 4]), pos, 1.0).ok   # excused
    assert not recheck(forged(obstacle=[0]), pos, 1.0).ok
    assert not recheck(forged(obstacle=[]), pos, 1.0).ok
    assert not recheck(forged(triangles=[0, 1, 3]), pos, 1.0).ok          # 0-3 is no edge
    assert not recheck(forged(occupants=[10, 11, 12, 99]), pos, 1.0).ok   # no such robot
    far = {**pos, 13: (3.0, 3.0)}
    assert not recheck(good, far, 1.0).ok                                 # edges longer than rv
    assert not recheck(forged(state="running"), pos, 1.0).ok


def test_robots_max_scales_with_the_map_unless_given():
    args = build_parser().parse_args(["configs/tiny.toml"])
    cfg, resolved = resolve_config("configs/tiny.toml", args)
    wm = build_map(cfg)
    cfg2, resolved2, how = default_robots_max(cfg, wm, resolved)
    bound = euler_bound(wm, cfg.rv)["robots"]
    assert how["robots_max"] == math.ceil(3 * bound) and "Euler" in how["robots_max_from"]
    assert cfg2.section("coordinator")["robots_max"] == how["robots_max"]
    assert f"robots_max = {how['robots_max']}" in resolved2
    # a bigger map gets a bigger cap
    big = WorldMap(name="hall", boundary=np.array([[0, 0], [20, 0], [20, 12], [0, 12]], float), obstacles=[],
                   sources=np.array([[1, 1, 0.0]]))
    assert default_robots_max(cfg, big, resolved)[2]["robots_max"] > 400
    # an explicit cap stays
    args = build_parser().parse_args(["configs/tiny.toml", "--robots-max", "7"])
    cfg, resolved = resolve_config("configs/tiny.toml", args)
    assert default_robots_max(cfg, wm, resolved)[2] == dict(robots_max=7, robots_max_from="config")


def test_twin_tracking_is_lifted_from_the_bridge_report():
    rep = {"robots": {"1": {"position_error_m": {"n": 9, "mean": 0.01, "p95": 0.03, "max": 0.05},
                            "lag_s": 0.12}},
           "gate_decisions": {"1": {"ok": 50, "command_stale": 2, "geofence": 1}}}
    t = twin_tracking(rep)["1"]
    assert t["position_error_mean_m"] == 0.01 and t["position_error_p95_m"] == 0.03
    assert t["lag_s"] == 0.12 and t["stops"] == 3


def test_inferred_obstacle_edges_are_listed_when_the_complex_has_them():
    from swarmcover.run import _inferred_edges
    cx = _certified_square()
    assert _inferred_edges(None, {}) is None   # no Complex received
    assert _inferred_edges(cx, {}) == []       # a Complex with none inferred
    cx.inferred = [3]
    cx.inferred_why = ["both ends' test drives touched"]
    out = _inferred_edges(cx, {11: (0.8, 0.0), 13: (0.8, 0.8)})
    assert out == [dict(a=1, b=3, length_m=pytest.approx(0.8), why="both ends' test drives touched")]


def test_recheck_accepts_the_pillar_hall_end_state_whose_fence_crosses_itself():
    """tests/data/pillar_hall_end.json: the one-sided edges z_raw have odd vertices where
    edges cross pillars; the certificate closes them inside their one-hop zone, and run's
    re-check, on the same criterion, must accept the end state whose O is z_raw (every
    side closed) and refuse it when a stretch of the fence is missing."""
    from pathlib import Path

    from swarmcover.coordinator import build_complex, certify, detect_fence
    from swarmcover.coordinator.topology.params import TopologyParams
    d = json.loads((Path(__file__).parent / "data" / "pillar_hall_end.json").read_text())
    reps = {int(k): {"neighbours": {int(a): b for a, b in v["neighbours"].items()},
                     "touch": v["touch"],
                     "touch_bearing": math.nan if v["touch_bearing"] is None else v["touch_bearing"]}
            for k, v in d["reports"].items()}
    cx = build_complex(reps)
    fence = detect_fence(cx, TopologyParams(rv=1.0, eps=0.1),
                         test_drive_failures={int(k): v for k, v in d["test_drive_failures"].items()})
    assert certify(cx, fence).certified
    ids = cx.ids.tolist()
    msg = Complex(vertices=ids, occupants=ids, edges=[ids[x] for e in cx.edges for x in e],
                  triangles=[ids[x] for t in cx.triangles for x in t], frontier=[],
                  obstacle=[int(x) for x in fence.z_raw], exceptions=[int(x) for x in fence.exceptions],
                  certified=True, state="certified")
    pos = {int(k): tuple(v[:2]) for k, v in d["positions"].items()}
    assert recheck(msg, pos, 1.0).ok
    # the fence edges within 2.5 m of one fence edge's midpoint dropped (18 of 90): the
    # zone (one hop around the gap's ends) cannot close it
    E = np.asarray(msg.edges).reshape(-1, 2)

    def mid(k):
        return (np.array(pos[E[k, 0]]) + np.array(pos[E[k, 1]])) / 2

    c = mid(msg.obstacle[0])
    keep = [k for k in msg.obstacle if np.linalg.norm(mid(k) - c) > 2.5]
    assert len(msg.obstacle) - len(keep) >= 15
    gap = Complex(**{**{k: v for k, v in msg.to_dict().items() if k[0] != "_"}, "obstacle": keep})
    assert not recheck(gap).ok                                    # GF(2) alone refuses it
    assert "neither obstacle nor exception" in recheck(gap, pos, 1.0).why   # and the world
    none = Complex(**{**{k: v for k, v in msg.to_dict().items() if k[0] != "_"}, "obstacle": []})
    assert "no obstacle edge" in recheck(none).why


def test_only_the_coordinators_session_with_the_run_key_is_believed():
    from swarmcover.bus.trust import mac, new_key
    from swarmcover.run import _Coordinator
    key = bytes.fromhex(new_key())
    c = _Coordinator(key)
    c.started("READY coordinator epoch 123 zid 0a1b2c")
    assert (c.zid, c.epoch) == ("0a1b2c", 123)
    k, payload = "sc/tiny/coord/complex", _certified_square().encode()
    assert c.check(k, payload, "0a1b2c", mac(key, k, payload)) == ""
    assert c.check(k, payload, "ffff", mac(key, k, payload)) == "not from the coordinator's session"
    assert c.check(k, payload, None, None) == "not from the coordinator's session"
    # the right zid (spoofed source_info) without the key, or with a payload changed
    assert c.check(k, payload, "0a1b2c", None) == "bad or missing run-key signature"
    assert c.check(k, payload, "0a1b2c", mac(bytes(32), k, payload)) != ""
    assert c.check(k, payload + b"x", "0a1b2c", mac(key, k, payload)) != ""
    # a genuine sample moved to another key does not verify either
    assert c.check("sc/tiny/world/spawn", payload, "0a1b2c", mac(key, k, payload)) != ""


def test_final_png_marks_the_robots_the_run_saw_removed_as_redundant():
    """final.png's figure gets the robots that accepted Complexes marked redundant: robot 7,
    redundant at cycle 1 and outside the complex at cycle 2, is drawn as a grey diamond
    (the `plot` command's, the GIF's and the live views' mark), not as a hollow robot."""
    from types import SimpleNamespace

    from swarmcover.bus.messages import WorldInfo
    from swarmcover.run import final_figure
    from swarmcover.viz.figures import COLORS
    tri = dict(edges=[0, 1, 0, 2, 1, 2], triangles=[0, 1, 2], obstacle=[0, 1])
    state = RunState(info=WorldInfo(name="room", rv=1.0, robot_radius=0.06, dt=0.05,
                                    boundary=[-1, -1, 5, -1, 5, 4, -1, 4], obstacles=[],
                                    sources=[0.3, 0.3, 0.0], free_area=30.0, config=""))
    state.saw_complex(Complex(cycle=1, epoch=1, vertices=[0, 1, 2, 3], occupants=[0, 1, 2, 7],
                              redundant=[3], **tri))
    state.saw_complex(Complex(cycle=2, epoch=1, vertices=[0, 1, 2], occupants=[0, 1, 2], **tri))
    assert state.removed == {7} and state.last_cx.cycle == 2 and state.cycles == 2
    truth = Truth(tick=1, t=0.0, ids=[0, 1, 2, 7], x=[0.0, 2.0, 1.0, 3.5],
                  y=[0.0, 0.0, 1.6, 3.0], theta=[0.0] * 4, live=[False] * 4)
    fig = final_figure(state, truth, state.last_cx, SimpleNamespace(name="room"))
    fig.canvas.draw()
    assert "removed (redundant)" in [t.get_text() for t in fig.legends[0].get_texts()]
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(int)
    X, Y = fig.axes[0].transData.transform((3.5, 3.0))
    grey = np.array([int(COLORS["removed"][k:k + 2], 16) for k in (1, 3, 5)])
    assert np.abs(img[int(round(img.shape[0] - Y)), int(round(X))] - grey).max() <= 3


def test_push_floor_is_the_complex_mean_move_plus_entry_and_null_without_them():
    cfg = load_config("configs/tiny.toml")
    wm = build_map(cfg)
    t = Truth(ids=[0, 1], x=[0.5, 1.0], y=[0.5, 0.5], theta=[0.0, 0.0], live=[False, False],
              t=40.0)
    cx = Complex(cycle=3, t=40.0, vertices=[0, 1], occupants=[0, 1], edges=[0, 1],
                 sources=[0], move_s=3.0, enter_s=1.0)
    s = compute_summary(cfg, wm, t, cx, dict(certified=False, sim_time_s=40.0))
    assert s["move_s"] == 3.0 and s["enter_s"] == 1.0 and s["push_floor_s"] == 4.0
    assert s["sim_s_per_robot"] == 20.0 and s["s_per_robot_over_floor"] == 5.0
    # a coordinator that predates the fields, or a run with no entry yet: no floor
    for fields in ({}, dict(move_s=3.0)):
        cx = Complex(cycle=3, t=40.0, vertices=[0, 1], occupants=[0, 1], edges=[0, 1],
                     sources=[0], **fields)
        s = compute_summary(cfg, wm, t, cx, dict(certified=False, sim_time_s=40.0))
        assert s["push_floor_s"] is None and s["s_per_robot_over_floor"] is None
        _strict(strict_json(s))


def test_fence_audit_says_how_deep_the_free_space_runs_behind_each_closed_side():
    """The four sides of a square of robots in a 4 m x 3 m room: the bottom one 0.2 m
    from the wall (no room), the left one 1 m from it, the right and top ones facing the
    open room (room behind, depth capped at 2 rv). Per reason: the inferred left side is
    counted apart from the three closed on evidence, and whether the room behind a side
    is covered comes from the coverage raster it is given."""
    from swarmcover.recheck import fence_audit
    wm = _room()
    cx = _certified_square()
    cx.inferred, cx.inferred_why = [1], ["probe_clear"]
    pos = {10: (1.0, 0.2), 11: (1.8, 0.2), 12: (1.0, 1.0), 13: (1.8, 1.0)}
    _, covered, raster = coverage_fraction(wm, np.array(list(pos.values())), 1.0,
                                           return_mask=True)
    a = fence_audit(cx, pos, wm.walls, 1.0, 0.75, covered, raster)
    by = a["by_why"]
    assert set(by) == {"probes", "probe_clear"}
    assert by["probes"]["sides"] == 3 and by["probes"]["room_behind"] == 2
    assert by["probe_clear"] == dict(sides=1, room_behind=1, room_covered=1, room_uncovered=0,
                                     max_depth_rv=pytest.approx(1.0))
    assert by["probes"]["max_depth_rv"] == pytest.approx(2.0)
    depth = {(r["a"], r["b"]): r["depth_m"] for r in a["examples"]}
    assert depth[(0, 2)] == pytest.approx(1.0) and (0, 1) not in depth   # 0.2 m: a wall
    none = fence_audit(cx, pos, wm.walls, 1.0, 0.75, np.zeros_like(covered), raster)
    assert none["by_why"]["probe_clear"]["room_uncovered"] == 1
    assert none["by_why"]["probes"]["room_uncovered"] == 2
    # a side closed on its gaps' probe lines is evidence too, counted under its own name
    cx.gap_probed = [0]
    gp = fence_audit(cx, pos, wm.walls, 1.0, 0.75, covered, raster)["by_why"]
    assert set(gp) == {"probes", "gap_probes", "probe_clear"}
    assert gp["gap_probes"]["sides"] == 1 and gp["probes"]["sides"] == 2
    # both triangles' apexes on one side is what makes a side open: a lone edge has none
    lone = Complex(vertices=[0, 1], occupants=[10, 11], edges=[0, 1], triangles=[],
                   obstacle=[0], certified=True, state="certified")
    assert fence_audit(lone, pos, wm.walls, 1.0, 0.75)["by_why"] == {}
