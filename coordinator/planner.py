"""One deployment cycle's decisions, as a pure function of what the robots reported.

``plan_cycle(snapshot, params, ...)`` builds the complex over the occupied vertices, the
fence (frontier K, obstacle O), the coverage certificate, the redundant vertices (every
T_H cycles) and the push jobs: vertex-disjoint paths from the sources and redundant
vertices to frontier vertices, each with its deployment direction and the desired
bearings of the new position (spec 4.4). No I/O, no positions.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from .topology.params import TopologyParams


@dataclass
class Snapshot:
    """The swarm at the start of a cycle, keyed by vertex.

    occupant: vertex -> robot id. nbrs: vertex -> {neighbour vertex: bearing (rad, in the
    occupant's body frame)}. contact: vertex -> sticky obstacle-contact bearing (rad, body
    frame). kinds: vertex -> robot kind. sources: source vertices present (vertex k is the
    vertex at base station k). source_dirs: heading (rad) of each base station, used as the
    deployment direction of a lone first robot. known: (vertex a, vertex b, length, same unit
    as rv) for pairs whose distance the coordinator commanded (a clear test drive).
    """
    occupant: dict[int, int]
    nbrs: dict[int, dict[int, float]]
    contact: dict[int, float] = field(default_factory=dict)
    kinds: dict[int, str] = field(default_factory=dict)
    sources: list[int] = field(default_factory=list)
    source_dirs: list[float] = field(default_factory=list)
    known: list[tuple[int, int, float]] = field(default_factory=list)


class Placed(StrEnum):
    """How :func:`_place_on_lattice` chose a job's new position (``JobSpec.placed``)."""
    LATTICE = "lattice"        # a free lattice point within reach of both ends of the edge
    LATTICE_F = "lattice_f"    # a free lattice point within reach of f alone
    SPEC = "spec"              # no free lattice point: the spec's direction at the spacing


@dataclass
class JobSpec:
    """One push: path p0..pm (vertex ids), pm = f the frontier vertex.

    direction: deployment bearing at f (rad, f's occupant's body frame).
    deploy_landmarks/deploy_bearings: the new position's desired bearings to vertices
    (spec 4.4 assumed geometry), in f's occupant's frame.
    new_vertex: id for the new position. enter_source: base-station index whose new robot
    refills p0, or None when p0 is a redundant vertex (left empty). frontier_edge: the fence
    edge deployed from (None for single file / a lone robot). distance: how far the test
    drive goes (rv units) when the planner chose the new position's distance, else None
    (the configured d_td).
    A probe (kind "probe", coordinator.topology.evidence) first homes to the point at ``via_frac``
    of the frontier edge from f (``via_landmarks`` / ``via_bearings``, f's occupant's frame;
    empty for an end probe), then drives ``direction`` (perpendicular to the edge) for
    ``distance``; it is never moved onto a lattice point. A wall sweep (``sweep_far`` > 0,
    the Deployment's) drives ``direction`` from f and on a touch sweeps the wall:
    ``sweep_side`` is the side swept seen from f (+1 CCW of f -> q), ``sweep_edge`` the
    bearing of q from f, ``sweep_points`` vertex -> (x, y) where f's neighbours stand in
    f's frame with |fq| = 1 (:func:`coordinator.topology.targets.star_shape`).
    """
    path: list[int]
    direction: float
    deploy_landmarks: list[int]
    deploy_bearings: list[float]
    new_vertex: int
    enter_source: int | None
    test_drive: bool = True
    scale_correct: bool = False
    frontier_edge: tuple[int, int] | None = None
    distance: float | None = None  # test-drive length (same unit as rv); None: d_td
    kind: str = "edge"             # the Deployment's kind ("probe": evidence, see below)
    via_frac: float = 0.0          # probe: approach to this fraction of the frontier edge
    via_landmarks: list[int] = field(default_factory=list)    # probe approach: vertex ids
    via_bearings: list[float] = field(default_factory=list)   # and their desired bearings
    deployment: object = None      # the coordinator.topology.fence.Deployment driven (for Evidence)
    free: bool = False             # a probe off every path (path [f], nobody refills f):
                                   # it ends back at f whatever it found
    sweep_far: float = 0.0         # wall sweep (see above): 0 = none
    sweep_stop: float = 0.0
    sweep_side: int = 0
    sweep_edge: float = 0.0
    placed: str = ""               # a Placed: how _place_on_lattice chose the new position;
                                   # "" when it did not place the job
    sweep_points: dict = field(default_factory=dict)


@dataclass
class CyclePlan:
    """edges/triangles: vertex-id tuples. frontier/obstacle: indices into edges.
    certified: the certificate holds (a 2-chain whose boundary is the one-sided fence).
    hole_edges: edges around an uncovered hole when not certified."""
    edges: list[tuple[int, int]]
    triangles: list[tuple[int, int, int]]
    frontier: list[int]
    obstacle: list[int]
    certified: bool
    hole_edges: list[tuple[int, int]] = field(default_factory=list)
    inferred: list[tuple[int, str]] = field(default_factory=list)  # (index into edges, why)
    exceptions: list[int] = field(default_factory=list)  # one-sided edges excused (spec 3.2)
    # obstacle edges closed on the evidence of their gaps' probe lines ('gap_probes')
    gap_probed: list[int] = field(default_factory=list)
    redundant: set[int] = field(default_factory=set)
    jobs: list[JobSpec] = field(default_factory=list)
    open_vertices: set[int] = field(default_factory=set)  # vertices with a deployment left
    # sides (u, v, sigma) this plan asked to be swept before they are deployed
    # (TopologyParams.sweep_fallbacks); the caller keeps them for later cycles' evidence
    sweep_first: frozenset = frozenset()

    @property
    def complete(self) -> bool:
        """K is empty (no frontier edge, no single-file/lone robot to extend) and certified."""
        return self.certified and not self.frontier and not self.open_vertices


def _reports(snap: Snapshot) -> dict[int, dict]:
    out = {}
    for v, nb in snap.nbrs.items():
        tb = snap.contact.get(v)
        out[v] = {"neighbours": nb, "touch": tb is not None, "touch_bearing": tb}
    return out


def _complex_and_fence(snap: Snapshot, params: TopologyParams, failures: dict,
                       evidence: dict | None = None):
    """The Rips complex of the snapshot and its fence (spec 2-3). evidence: further
    detect_fence keywords (probe_failures, probe_fracs, probe_unreachable)."""
    from .topology.complex import build_complex
    from .topology.fence import detect_fence

    cx = build_complex(_reports(snap))
    lone_dir = snap.source_dirs[0] if snap.source_dirs else 0.0
    return cx, detect_fence(cx, params, test_drive_failures=failures, default_bearing=lone_dir,
                            **(evidence or {}))


def plan_cycle(snap: Snapshot, params: TopologyParams, *, cycle: int, redundancy: bool,
               test_drive_failures: dict[int, list[float]], previous_redundant: set,
               protected: set, max_paths: int, scale_correct: bool, test_drive: bool,
               next_vertex: int, lattice_spacing: float | None = None,
               evidence: dict | None = None, free_probes: bool = False,
               returned_probes: frozenset = frozenset(), sweeps_last: bool = False,
               out: frozenset = frozenset(), sweeps_free: bool = False,
               free_max: int | None = None) -> CyclePlan:
    """Decide one cycle. ``next_vertex``: the first unused vertex id (for new positions).

    lattice_spacing: when set (rv units) and every robot is holonomic, each new position
    is a point of one triangular lattice of that spacing through the source vertex (from
    the swarm's shape estimated from bearings, coordinator.topology.shape), so fronts growing from
    different places mesh instead of colliding; else the spec's 60-deg rule at d_td.

    test_drive_failures: vertex -> directions of test drives that touched a wall (sticky).
    evidence: further detect_fence keywords from coordinator.topology.evidence (probe_failures,
    probe_fracs, probe_unreachable).
    free_probes: also let frontier robots away from every push probe their side without a
    path (a JobSpec with ``free``; the deployer sends a clear one back home, so no vertex is
    left empty). returned_probes: probe keys (coordinator.topology.evidence.probe_key) a free probe
    already drove clear and came back from: never offered as a free probe again (their side
    stays open; a push along a path may still take them, and its robot stays there).
    sweeps_last: no push goes to a wall sweep while the fence offers anything else
    (:func:`_placing_first`); free probes still sweep. sweeps_free (with free_probes): once
    the push fence offers nothing but sweeps, free probes are chosen first (off the sources
    and ``out`` only) and pushes avoid them and their neighbours. free_max: free probes
    per cycle at most (None: max_paths).
    certified is False whenever the fence has no one-sided edge (an empty target cycle
    proves nothing).
    previous_redundant: redundant vertices found earlier (used as path starts until the
    next redundancy pass). protected: vertices that must not be counted redundant.
    out: vertices whose robots are still out on free probes of the last cycle
    (``[coordinator] free_probes_carry``; the snapshot has them where they left): no path
    uses them or their neighbours (the landmarks they home back on), and no free probe
    goes to them or next to them.
    With ``TopologyParams.sweep_fallbacks`` a push placed by the fallback from a robot
    resting on a wall (:func:`_fallback_sides`) is not driven: its side joins ``evidence``'s
    ``sweep_first`` and the cycle is planned again (``CyclePlan.sweep_first``: the sides
    asked); each side is asked once, so this ends.
    """
    args = dict(locals())          # this call's arguments, to plan again with more asked
    from .topology.certificate import certify
    from .topology.paths import plan_pushes
    from .topology.redundancy import find_redundant

    cx, fence = _complex_and_fence(snap, params, test_drive_failures, evidence)
    cert = certify(cx, fence)
    ids = cx.ids
    edges = list(map(tuple, ids[cx.edges].tolist()))
    tris = list(map(tuple, ids[cx.triangles].tolist()))
    plan = CyclePlan(edges=edges, triangles=tris, frontier=[int(e) for e in fence.frontier],
                     obstacle=[int(e) for e in fence.obstacle],
                     certified=bool(cert.certified) and fence.z.size > 0,
                     hole_edges=[tuple(int(x) for x in e) for e in cert.hole_edge_nodes],
                     inferred=[(int(e), str(w)) for e, w in fence.inferred],
                     exceptions=[int(e) for e in fence.exceptions],
                     gap_probed=[int(e) for e in fence.gap_probed])
    if redundancy and plan.certified:
        prot = set(protected) | set(snap.sources)
        red = find_redundant(cx, fence, cert, protected=prot)
        plan.redundant = {int(v) for v in red.redundant}
    else:
        plan.redundant = {v for v in previous_redundant if v in snap.occupant
                          and v not in fence.fence_vertices}
    plan.open_vertices = {int(v) for v, d in fence.deployments.items() if d}
    if not plan.open_vertices:
        return plan

    # pushes: vertex-disjoint paths from redundant vertices and sources; a source may feed
    # several paths in one cycle (its new robots enter one after another)
    push_fence = _placing_first(fence) if sweeps_last else fence
    hold = {int(v) for v in out if v in cx}
    hold.update(int(x) for v in list(hold) for x in cx.neighbours(v))
    first: list[JobSpec] = []
    n_free = max_paths if free_max is None else int(free_max)
    if free_probes and sweeps_free and _only_sweeps(push_fence):
        # nothing but wall sweeps left: free probes take every one they can, many at once;
        # pushes (whose paths would keep the probes off their neighbourhoods) only the rest
        first = _free_probe_specs(snap, params, cx, fence,
                                  set(int(s) for s in snap.sources) | {int(v) for v in out},
                                  next_vertex, n_free, returned_probes)
        for spec in first:
            f = int(spec.path[-1])
            hold.add(f)
            hold.update(int(x) for x in cx.neighbours(f))
    paths = plan_pushes(cx, push_fence, snap.sources, sorted(plan.redundant), params=params,
                        max_paths=max_paths, exclude=hold)
    chosen = list(paths)
    while len(chosen) < max_paths and snap.sources:
        used = _claimed(cx, [pth.vertices for pth in chosen]) | hold
        extra = None
        for s in snap.sources:
            cand = plan_pushes(cx, push_fence, [s], (), params=params, max_paths=1,
                               exclude=used - {s})
            if cand and cand[0].frontier not in used:
                extra = cand[0]
                break
        if extra is None:
            break
        chosen.append(extra)

    vid = next_vertex + len(first)
    for pth in chosen:
        plan.jobs.append(_job_spec(snap, params, pth, vid, test_drive, scale_correct))
        vid += 1
    plan.jobs.extend(first)
    # free probes: a frontier robot away from every push probes its side in the same cycle,
    # without a path; clear or not, it ends back at its vertex (the deployer homes it). A
    # probe homes on its vertex's neighbours (its landmarks), which must hold still, and
    # nobody may home on a mover: f must be off every mover (push paths, sources, other free
    # probers) and off every other job's landmarks (the neighbours of its movers), and f's
    # neighbours off every mover. With symmetric neighbourhoods both say: f is neither a
    # mover nor next to one. Landmarks may be shared.
    if free_probes:
        _add_free_probes(snap, params, cx, fence, plan, vid, n_free - len(first),
                         returned_probes, out=out)
    if lattice_spacing and plan.jobs:
        _place_on_lattice(snap, plan.jobs, float(lattice_spacing), params, test_drive_failures)
        prior = frozenset((evidence or {}).get("sweep_first", ()))
        asked = (_fallback_sides(snap, plan.jobs) - prior
                 if params.sweep_fallbacks else frozenset())
        if asked:
            args["evidence"] = dict(evidence or {}, sweep_first=prior | asked)
            again = plan_cycle(**args)
            again.sweep_first = asked | again.sweep_first
            return again
    return plan


def _fallback_sides(snap: Snapshot, jobs: list[JobSpec]) -> frozenset:
    """The sides (u, v, sigma) of the pushes in ``jobs`` that :func:`_place_on_lattice`
    placed by its fallback (``Placed.SPEC``: no free lattice point) from a frontier robot
    resting on a wall (its contact in ``snap``). Along a wall that fallback is the spec's
    60-deg direction, which there runs along the wall: it laid a second row under the
    lattice's last (pillar_hall seed 0: 9 of the 10 robots of its bottom row; docs/measured.md,
    "Where the robots go"), where a sweep of the side may find no room. (Counting a failed
    drive as a wall too asked more and cost more: pillar_hall seed 0, 121 robots against
    116 and 110 without asking.)"""
    out = set()
    for job in jobs:
        dep = job.deployment
        f = job.path[-1]
        if (job.placed == Placed.SPEC and job.kind == "edge" and not job.free
                and dep is not None and dep.edge is not None and f in snap.contact):
            out.add((int(dep.edge[0]), int(dep.edge[1]), int(dep.sigma)))
    return frozenset(out)


def _keeping(fence, keep) -> dict:
    """``fence``'s deployments for which ``keep`` holds, by frontier vertex (none left: the
    vertex is dropped)."""
    deps = {f: tuple(d for d in lst if keep(d)) for f, lst in fence.deployments.items()}
    return {f: lst for f, lst in deps.items() if lst}


def _placing_first(fence):
    """``fence`` without its wall sweeps while it offers any other deployment: pushes then
    go where a robot may stay, and the sweeps (which mostly come home, "swept") run as free
    probes beside them; with nothing but sweeps left, ``fence`` itself."""
    from dataclasses import replace
    deps = _keeping(fence, lambda d: not d.sweep_far > 0)
    return replace(fence, deployments=deps) if deps else fence


def _only_sweeps(fence) -> bool:
    """Whether every deployment ``fence`` offers is a wall sweep (and it offers one)."""
    deps = [d for lst in fence.deployments.values() for d in lst]
    return bool(deps) and all(d.sweep_far > 0 for d in deps)


def _without_probes(fence, skip):
    """``fence`` with the probe deployments whose key (coordinator.topology.evidence.probe_key) is in
    ``skip`` left out (probes already driven free); ``fence`` itself when skip is empty."""
    if not skip:
        return fence
    from dataclasses import replace

    from .topology.evidence import probe_key
    return replace(fence, deployments=_keeping(
        fence, lambda d: d.kind != "probe" or d.edge is None
        or probe_key(d.vertex, d.edge, d.sigma, d.via_frac) not in skip))


def _add_free_probes(snap: Snapshot, params: TopologyParams, cx, fence, plan: CyclePlan,
                     vid: int, max_paths: int, returned, out=frozenset()) -> None:
    """Append free probes to ``plan.jobs`` (see plan_cycle's free_probes): at most
    ``max_paths``, lowest frontier vertex first, each at a vertex that is neither a mover
    (push path, source, earlier free prober, a prober still ``out``) nor a neighbour of
    one."""
    movers: set[int] = set(int(s) for s in snap.sources) | {int(v) for v in out}
    for job in plan.jobs:
        movers.update(int(v) for v in job.path)
    plan.jobs.extend(_free_probe_specs(snap, params, cx, fence, movers, vid, max_paths,
                                       returned))


def _free_probe_specs(snap: Snapshot, params: TopologyParams, cx, fence, movers: set[int],
                      vid: int, max_n: int, returned, skip=frozenset()) -> list[JobSpec]:
    """Free probes (JobSpecs with ``free``, new vertex ids from ``vid``): at most ``max_n``,
    lowest frontier vertex first, each at a vertex of ``cx`` that is neither in ``movers``
    nor next to one, nor next to an earlier one, nor in ``skip``."""
    from .topology.paths import PushPath

    movers = set(movers)
    near: set[int] = set(movers)
    for v in movers:
        if v in cx:
            near.update(int(x) for x in cx.neighbours(v))
    fence = _without_probes(fence, frozenset(returned))
    out: list[JobSpec] = []
    for f in sorted(fence.deployments):
        if len(out) >= max_n:
            break
        f = int(f)
        if f in near or f in skip or f not in cx or f not in snap.occupant:
            continue
        probes = [d for d in fence.deployments[f] if d.kind == "probe" and d.edge is not None]
        if not probes:
            continue
        spec = _job_spec(snap, params, PushPath((f,), probes[0], 0.0), vid, True, False)
        spec.free = True
        out.append(spec)
        vid += 1
        movers.add(f)
        near.add(f)
        near.update(int(x) for x in cx.neighbours(f))
    return out


def reachable(starts, neighbours, blocked=frozenset()) -> set[int]:
    """The vertices a walk from ``starts`` reaches through ``neighbours(v)`` (an iterable of
    vertices), never entering ``blocked`` (a start in it is not reached)."""
    seen = {v for v in starts if v not in blocked}
    stack = list(seen)
    while stack:
        for x in neighbours(stack.pop()):
            if x not in seen and x not in blocked:
                seen.add(x)
                stack.append(x)
    return seen


def source_component(snap: Snapshot, n_sources: int | None = None) -> set[int]:
    """The vertices of ``snap`` linked to a source vertex by mutual sightings (sources: the
    vertices 0 .. n_sources - 1 present; None: ``snap.sources``)."""
    starts = (snap.sources if n_sources is None
              else [k for k in range(n_sources) if k in snap.occupant])
    nbrs = snap.nbrs
    return reachable([k for k in starts if k in snap.occupant],
                     lambda v: (u for u in nbrs.get(v, {}) if v in nbrs.get(u, {})))


def carryable(edges, sources, targets, probers) -> set[int]:
    """Which probers (vertices whose robots are out on free probes) may stay out into the
    next cycle (``[coordinator] free_probes_carry``), in order, greedily: while one is
    out no path uses its vertex or a neighbour, so none may stay out where that, with the
    ones before it, would cut every source off from a vertex of ``targets`` (vertices with
    a deployment) that a path reaches now, its own neighbourhood aside. The others are
    waited for, as before. edges: the cycle's edges (vertex pairs); sources: vertices.

    In a corridor two robots wide a prober and its neighbours cross it: carried, it held
    every push of the next cycle out of the corridor beyond (structured seed 0: 24 of the
    56 plans made with probes out had fewer pushes than the same plan without them)."""
    nb: dict[int, set[int]] = {}
    for a, b in edges:
        nb.setdefault(int(a), set()).add(int(b))
        nb.setdefault(int(b), set()).add(int(a))
    starts = [int(s) for s in sources if int(s) in nb]

    def reached(blocked: set[int]) -> set[int]:
        return reachable(starts, lambda v: nb[v], blocked)

    targets = {int(t) for t in targets}
    held: set[int] = set()
    reach = reached(held) & targets
    ok: set[int] = set()
    for f in probers:
        hold = {int(f)} | nb.get(int(f), set())
        if reach - hold - reached(held | hold):
            continue
        ok.add(int(f))
        held |= hold
        reach -= hold
    return ok


def more_free_probes(snap: Snapshot, params: TopologyParams, *, movers: set[int],
                     skip: set[int], test_drive_failures: dict[int, list[float]],
                     new_vertex: int, max_n: int, evidence: dict | None = None,
                     returned=frozenset()) -> list[JobSpec]:
    """Free probes to start within a running cycle, once some of its jobs are over
    (``[coordinator] free_probes_rolling``).

    At the start of a cycle a free probe goes only where neither f nor a neighbour of f is
    a mover, so two neighbours never probe at once; a wall's robots probed one in two per
    cycle, and the rest waited for the push that was still running (tiny seed 0: nine wall
    sweeps in a row, 124 s, in one cycle). Here the fence is recomputed on the cycle's
    snapshot with the evidence gathered since, and probes go where it still offers one.

    movers: the vertices whose robots are not to be relied on: the sources, every push
    path of the cycle (done or not: its robots stand where they homed, not where the
    snapshot has them), the free probes still out, and every vertex whose robot is gone or
    elsewhere. skip: vertices that already probed free this cycle. No probe goes to a
    mover or a neighbour of one, so its landmarks are where the snapshot has them.
    """
    cx, fence = _complex_and_fence(snap, params, test_drive_failures, evidence)
    return _free_probe_specs(snap, params, cx, fence, movers, new_vertex, max_n, returned,
                             skip=frozenset(skip))


def replan_push(snap: Snapshot, params: TopologyParams, *, start: int, busy: list[JobSpec],
                exclude: set[int], test_drive_failures: dict[int, list[float]],
                new_vertex: int, scale_correct: bool, test_drive: bool,
                lattice_spacing: float | None = None,
                evidence: dict | None = None, skip_probes=frozenset(),
                sweeps_last: bool = False) -> JobSpec | None:
    """The next-best push from ``start`` within this cycle, after a test drive touched
    (spec 3.4(iv): "choose the next-best frontier"), or None.

    The fence is recomputed on the same snapshot with ``test_drive_failures``, which now
    hold the failed direction: deployments within 30 deg of it are gone, and its side
    closes once both ends have no room (coordinator.topology.fence).
    busy: the other pushes of this cycle; their paths, and every neighbour of their
    frontier vertices, are not used (their occupants are moving or about to), and a lattice
    position keeps clear of their targets. exclude: further vertices no path may use.
    skip_probes: probe keys not to offer (a free probe's retry: those it drove clear).
    sweeps_last: as plan_cycle's.
    """
    from .topology.paths import plan_pushes

    cx, fence = _complex_and_fence(snap, params, test_drive_failures, evidence)
    if start not in cx:
        return None
    fence = _without_probes(fence, skip_probes)
    if sweeps_last:
        fence = _placing_first(fence)
    used = set(exclude) | _claimed(cx, [job.path for job in busy])
    used.discard(start)
    found = plan_pushes(cx, fence, [start], (), params=params, max_paths=1, exclude=used)
    if not found or found[0].frontier in used:
        return None
    spec = _job_spec(snap, params, found[0], new_vertex, test_drive, scale_correct)
    if lattice_spacing:
        _place_on_lattice(snap, [spec], float(lattice_spacing), params, test_drive_failures,
                          fixed=busy)
    return spec


def _claimed(cx, paths) -> set[int]:
    """Vertices a cycle's pushes take: their paths, and every neighbour of their frontier
    vertices (the landmarks and surroundings of the new position)."""
    used: set[int] = set()
    for path in paths:
        used.update(int(v) for v in path)
        if path[-1] in cx:
            used.update(int(x) for x in cx.neighbours(path[-1]))
    return used


def _job_spec(snap: Snapshot, params: TopologyParams, pth, vid: int, test_drive: bool,
              scale_correct: bool) -> JobSpec:
    """The push along ``pth`` (a paths.PushPath) deploying to new vertex ``vid``."""
    from .topology.targets import frontier_desired_bearings, probe_via_bearings, star_shape

    dep = pth.deployment
    f = pth.frontier
    want = frontier_desired_bearings(snap.nbrs.get(f, {}), dep.bearing, d0=params.d0,
                                     rv=params.rv, old_vertex=f)
    start = pth.vertices[0]
    enter = snap.sources.index(start) if start in snap.sources else None
    spec = JobSpec(path=list(pth.vertices), direction=float(dep.bearing),
                   deploy_landmarks=list(want), deploy_bearings=[want[v] for v in want],
                   new_vertex=vid, enter_source=enter, test_drive=test_drive,
                   scale_correct=scale_correct, frontier_edge=dep.edge, kind=dep.kind,
                   deployment=dep)
    if dep.kind == "probe":
        # a probe is a test drive, whatever the config says; it ends depth_rv out
        spec.test_drive = True
        spec.distance = dep.depth_rv * params.rv if dep.depth_rv > 0 else None
        spec.via_frac = float(dep.via_frac)
        q = None if dep.edge is None else (dep.edge[1] if dep.edge[0] == f else dep.edge[0])
        nf = snap.nbrs.get(f, {})
        if dep.sweep_far > 0 and q is not None:
            spec.sweep_far, spec.sweep_stop = float(dep.sweep_far), float(dep.sweep_stop)
            spec.sweep_side = int(dep.sigma) if dep.edge[0] == f else -int(dep.sigma)
            spec.sweep_edge = float(nf.get(q, 0.0))
            spec.sweep_points = star_shape(snap.nbrs, f, q)
        if dep.via_frac > 0 and q is not None and q in nf:
            via = probe_via_bearings(nf, snap.nbrs.get(q, {}), f, q, float(dep.via_frac))
            spec.via_landmarks = list(via)
            spec.via_bearings = [via[v] for v in via]
    return spec


def _place_on_lattice(snap: Snapshot, jobs: list[JobSpec], spacing: float,
                      params: TopologyParams, failures: dict,
                      fixed: list[JobSpec] = ()) -> None:
    """Point each job's deployment at a free lattice point (sets direction and distance).

    A candidate is within reach (1.02 x spacing, below rv) of the frontier robot f and of
    the fence edge's other end, on the open side, at least half a spacing from f and 0.35
    spacing from every robot and from this cycle's other targets, and outside the 90-deg
    cone of f's wall contact and of each direction f's test drives failed in. Failing
    that, a free lattice point within reach of f alone on the open side; failing that, the
    spec's direction at the lattice spacing.
    Robots that rotate (their frames drift apart between cycles) keep the spec's rule.
    fixed: pushes already under way this cycle; their targets count as taken.
    Each placed job's deploy bearings are re-derived for the distance chosen.
    """
    from swarmcover.ground.angles import wrap
    from .topology.shape import Lattice, align_headings, estimate_shape, lattice_target
    from .topology.targets import frontier_desired_bearings

    if not snap.sources or any(k != "holonomic" for k in snap.kinds.values()):
        return
    if all(job.kind == "probe" for job in jobs):
        return          # probes are never moved onto the lattice: no shape estimate needed
    root = snap.sources[0]
    head = align_headings(snap.nbrs, snap.kinds, root=root)
    X = estimate_shape(snap.nbrs, head, snap.known, root=root, default_edge=spacing)
    if root not in X:
        return
    axis = snap.source_dirs[0] if snap.source_dirs else 0.0
    lat = Lattice(X[root], axis, spacing)
    reach = min(1.02 * spacing, params.rv * (1.0 - 1e-3))
    XP = np.array(list(X.values())).reshape(-1, 2)   # estimated positions, in X's order
    taken = [XP]                  # blocks of points: the robots, then targets placed
    for job in fixed:
        f = job.path[-1]
        if f in X:
            a = job.direction + head.get(f, 0.0)
            d = params.d_td if job.distance is None else job.distance
            taken.append((X[f] + d * np.array([math.cos(a), math.sin(a)])).reshape(1, 2))
    for job in jobs:
        f = job.path[-1]
        if f not in X or job.kind == "probe":
            continue
        pf = X[f]
        u = np.array([math.cos(job.direction + head.get(f, 0.0)),
                      math.sin(job.direction + head.get(f, 0.0))])
        walls = list(failures.get(f, ()))
        if f in snap.contact:
            walls.append(snap.contact[f])
        walls = [w + head.get(f, 0.0) for w in walls]
        o = None
        if job.frontier_edge:
            a, b = job.frontier_edge
            o = b if a == f else a
        po = X.get(o) if o is not None else None
        near = XP[np.hypot(XP[:, 0] - pf[0], XP[:, 1] - pf[1]) <= 2.5 * spacing]
        local = lat.fitted(near) if len(near) >= 3 else lat
        if len(taken) > 1:
            taken = [np.concatenate(taken)]
        p = None
        job.placed = Placed.SPEC
        for need_o in ((True, False) if po is not None else (False,)):
            p = lattice_target(local, pf, po if need_o else None, u, taken[0], reach=reach,
                               min_sep=0.35 * spacing, min_dist=0.5 * spacing,
                               blocked=walls, side_from=po)
            if p is not None:
                job.placed = Placed.LATTICE if need_o else Placed.LATTICE_F
                break
        job.distance = spacing
        if p is not None:
            job.direction = wrap(math.atan2(p[1] - pf[1], p[0] - pf[0]) - head.get(f, 0.0))
            job.distance = float(np.hypot(*(p - pf)))
            taken.append(np.reshape(p, (1, 2)))
        else:
            taken.append((pf + spacing * u).reshape(1, 2))
        want = frontier_desired_bearings(snap.nbrs.get(f, {}), job.direction,
                                         d0=job.distance, rv=params.rv, old_vertex=f)
        job.deploy_landmarks = list(want)
        job.deploy_bearings = [want[v] for v in want]
