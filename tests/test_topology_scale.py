"""The coordinator's cycle made near-linear (issue 18, part 5) computes what it computed.

bench/cycle.py times one deployment cycle against N; the optimisations it led to are
checked here on seeded 300-robot states from the same builder (bench.cycle.make_state):
  * shape.estimate_shape (a sparse bordered solve instead of normal equations made dense
    by the scale-gauge row, above _DENSE_MAX vertices) against the straightforward dense
    normal equations (shape._estimate_shape_dense, the code as first written);
  * build_complex's fast path for plain dict reports against the as_report path;
  * plan_cycle as a whole (complex, fence, certificate, redundancy, paths, lattice
    placement) against the same with the straightforward paths switched back in, and,
    on a state without walls' evidence, against its output frozen before the
    optimisations (commit 6df0bd2);
  * find_redundant's quick rejection against the full link test.
No timing here: speed belongs in bench/cycle.py.
"""
from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.cycle import closing_evidence, make_state  # noqa: E402
from swarmcover.coordinator.topology.complex import RobotReport, build_complex  # noqa: E402
from swarmcover.coordinator.config import CoordinatorConfig  # noqa: E402
from swarmcover.coordinator.planner import Snapshot, plan_cycle  # noqa: E402
from swarmcover.coordinator.topology.shape import _DENSE_MAX, _estimate_shape_dense, estimate_shape  # noqa: E402

CFG = CoordinatorConfig()
P = CFG.topology()


@pytest.fixture(scope="module")
def states():
    out = {}
    for kind in ("front", "closed"):
        sw, h = make_state(300, kind, centre=(kind == "front"))
        tdf, ev = closing_evidence(sw, P, h) if kind == "closed" else ({}, {})
        # the reports once (each call draws new contact-bearing noise)
        out[kind] = (sw, h, tdf, ev, sw.reports())
    return out


def snapshot(rep, h) -> Snapshot:
    first = next(iter(rep[0]["neighbours"]))
    return Snapshot(occupant={i: i for i in rep},
                    nbrs={i: dict(r["neighbours"]) for i, r in rep.items()},
                    contact={i: float(r["touch_bearing"]) for i, r in rep.items() if r["touch"]},
                    kinds={i: "holonomic" for i in rep}, sources=[0], source_dirs=[h],
                    known=[(0, first, 0.85)])


def test_estimate_shape_matches_the_dense_normal_equations(states):
    sw, h, _, _, rep = states["front"]
    snap = snapshot(rep, h)
    assert len(snap.nbrs) > _DENSE_MAX       # the sparse path
    rng = np.random.default_rng(3)
    for heads in ({v: 0.0 for v in snap.nbrs},
                  {v: float(rng.uniform(-0.2, 0.2)) for v in snap.nbrs}):
        got = estimate_shape(snap.nbrs, heads, snap.known, root=0)
        want = _estimate_shape_dense(snap.nbrs, heads, snap.known, root=0)
        assert list(got) == list(want)
        err = max(float(np.abs(got[v] - want[v]).max()) for v in want)
        assert err < 1e-7, err
    # and it is the swarm's shape: with one true length known, the true distances
    pos = sw.points()
    d_true = np.hypot(*(pos[1:] - pos[0]).T)
    got = estimate_shape(snap.nbrs, {v: 0.0 for v in snap.nbrs},
                         [(0, 1, float(d_true[0]))], root=0)
    d_est = np.array([np.hypot(*got[v]) for v in range(1, sw.n)])
    assert np.median(np.abs(d_est / d_true - 1.0)) < 0.03


def test_build_complex_fast_path_equals_as_report_path(states):
    sw, _, _, _, rep = states["closed"]
    plain = {i: {"neighbours": {j: float(b) for j, b in r["neighbours"].items()},
                 "touch": bool(r["touch"]),
                 "touch_bearing": None if r["touch_bearing"] is None else float(r["touch_bearing"])}
             for i, r in rep.items()}
    slow = {i: RobotReport(dict(r["neighbours"]), r["touch"], r["touch_bearing"])
            for i, r in plain.items()}
    a, b = build_complex(plain), build_complex(slow)
    assert a.n == sw.n > 250 and a.n_triangles > 400
    for f in ("ids", "edges", "triangles", "bearings", "touch", "touch_bearing"):
        assert np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True), f
    # a bad report still gets as_report's error
    bad = dict(plain)
    bad[5] = {"neighbours": {-1: 0.0}}
    with pytest.raises(ValueError, match="negative"):
        build_complex(bad)


def _plan(snap, tdf, ev):
    return plan_cycle(snap, P, cycle=0, redundancy=True, test_drive_failures=tdf,
                      previous_redundant=set(), protected=set(), max_paths=8,
                      scale_correct=False, test_drive=True, next_vertex=300,
                      lattice_spacing=CFG.d0, evidence=ev, free_probes=True)


def _summary(plan) -> dict:
    return dict(edges=len(plan.edges), triangles=len(plan.triangles),
                frontier=len(plan.frontier), obstacle=len(plan.obstacle),
                certified=plan.certified, redundant=sorted(plan.redundant),
                digest=hashlib.sha1(repr((plan.edges, plan.triangles, plan.frontier,
                                          plan.obstacle)).encode()).hexdigest()[:16],
                jobs=[(j.path, j.direction, j.distance, j.kind, j.free, j.deploy_landmarks)
                      for j in plan.jobs])


def _same_jobs(got, want):
    assert len(got) == len(want)
    for (path, d, dist, kind, free, lms), (path2, d2, dist2, kind2, free2, lms2) in zip(got, want):
        assert (path, kind, free, lms) == (path2, kind2, free2, lms2)
        assert d == pytest.approx(d2, abs=2e-6)
        assert (dist is None) == (dist2 is None)
        if dist is not None:
            assert dist == pytest.approx(dist2, abs=2e-6)


# plan_cycle's output on the front state without wall contacts (no probe, no evidence:
# every job an edge deployment placed on the lattice), computed by the code before the
# optimisations (commit 6df0bd2), and frozen again when shape.estimate_shape took its edge
# length prior (shape.EDGE_PRIOR, 2026-11-27): on this rigid swarm the prior moved the
# jobs' directions by at most 4.5e-4 rad and their distances by at most 1.2e-3 rv, and
# changed nothing else
FROZEN_BARE_FRONT = dict(
    edges=796, triangles=495, frontier=107, obstacle=0, certified=True, redundant=[],
    digest="a6e1bb4efe3c6f2f",
    jobs=[([0, 2, 14, 23, 37], -1.429580, 0.753870, "edge", False, [54, 37]),
          ([0, 4, 16, 31, 57], 3.138042, 0.520985, "edge", False, [44, 49, 72, 80, 57]),
          ([0, 1, 15, 34, 53, 65], 2.618359, 0.558289, "edge", False, [42, 68, 65]),
          ([0, 6, 18, 32, 55, 73], -0.032072, 0.621956, "edge", False, [50, 73]),
          ([0, 5, 9, 19, 46, 59], -1.612914, 0.879024, "edge", False, [85, 59]),
          ([0, 3, 17, 28, 39, 67], -3.084927, 0.9, "edge", False, [72, 88, 67])])


def test_plan_cycle_output_unchanged(states):
    _, h, _, _, rep = states["front"]
    snap = snapshot(rep, h)
    snap.contact.clear()
    got = _summary(_plan(snap, {}, {}))
    assert {k: v for k, v in got.items() if k != "jobs"} == \
        {k: v for k, v in FROZEN_BARE_FRONT.items() if k != "jobs"}
    _same_jobs(got["jobs"], FROZEN_BARE_FRONT["jobs"])


@pytest.mark.parametrize("kind", ["front", "closed"])
def test_plan_cycle_equals_the_straightforward_computation(states, kind, monkeypatch):
    """The whole cycle on the current fence rules (probes, evidence), optimised against
    the straightforward paths: dense shape estimate, every report through as_report, no
    quick rejection in the redundancy pass."""
    from swarmcover.coordinator.topology import complex as cmod
    from swarmcover.coordinator.topology import redundancy, shape

    _, h, tdf, ev, rep = states[kind]
    fast = _summary(_plan(snapshot(rep, h), tdf, ev))
    with monkeypatch.context() as m:
        m.setattr(shape, "estimate_shape", _estimate_shape_dense)
        m.setattr(cmod, "_plain_report", lambda r: None)
        m.setattr(redundancy, "_in_four_clique", lambda c: np.ones(c.n, dtype=bool))
        slow = _summary(_plan(snapshot(rep, h), tdf, ev))
    assert {k: v for k, v in fast.items() if k != "jobs"} == \
        {k: v for k, v in slow.items() if k != "jobs"}
    assert fast["jobs"], "no push planned: the test shows nothing"
    _same_jobs(fast["jobs"], slow["jobs"])


def _redundancy_cases(states):
    """(complex, fence, certificate): the closed 0.85-rv lattice (no 4-clique), and
    bench/topology.py's lattice with holes at 0.61 rv spacing (some 4-cliques) and its
    dense random swarm (all in 4-cliques, many redundant robots)."""
    from bench.topology import dense_swarm, lattice_swarm, reports_from_points
    from swarmcover.coordinator import certify, detect_fence

    sw, h, tdf, ev, rep = states["closed"]
    cx = build_complex(rep)
    fence = detect_fence(cx, P, test_drive_failures=tdf, default_bearing=h, **ev)
    yield cx, fence, certify(cx, fence)
    rng = np.random.default_rng(5)
    for pts, discs in (lattice_swarm(400, rng, spacing=0.61), (dense_swarm(300, rng), ())):
        cx = build_complex(reports_from_points(pts, discs=discs))
        fence = detect_fence(cx)
        yield cx, fence, certify(cx, fence)


def test_find_redundant_quick_rejection_changes_nothing(states, monkeypatch):
    """find_redundant rejects robots whose link has a cycle and no triangle without the
    link test; with that shortcut off (every robot taken for one in a 4-clique) it must
    remove the same robots, run as many tests and reroute to the same chain."""
    from swarmcover.coordinator.topology import redundancy

    removed_any = 0
    for cx, fence, cert in _redundancy_cases(states):
        assert cert.certified
        fast = redundancy.find_redundant(cx, fence, cert, protected=[0])
        with monkeypatch.context() as m:
            m.setattr(redundancy, "_in_four_clique", lambda c: np.ones(c.n, dtype=bool))
            slow = redundancy.find_redundant(cx, fence, cert, protected=[0])
        assert fast.removed == slow.removed
        assert fast.tried == slow.tried
        assert np.array_equal(fast.certificate.chain, slow.certificate.chain)
        removed_any += len(fast.removed)
    assert removed_any > 100


def test_four_cliques_found():
    from bench.topology import dense_swarm, reports_from_points
    from swarmcover.coordinator.topology.redundancy import _in_four_clique

    cx = build_complex(reports_from_points(dense_swarm(200, np.random.default_rng(2), degree=5)))
    adj = cx.adjacency_sets()
    want = np.zeros(cx.n, dtype=bool)
    for a, b, c in cx.triangles.tolist():
        for d in adj[a] & adj[b] & adj[c]:
            want[[a, b, c, d]] = True
    assert want.any() and not want.all()
    assert np.array_equal(_in_four_clique(cx), want)
