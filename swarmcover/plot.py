"""``swarmcover plot RUN_DIR_OR_MCAP``: thesis-style figures and an animation of a run.

Reads a recording (a run folder's ``run.mcap``, or an ``.mcap`` file) without Zenoh and
writes, next to it or into ``--out``:
  * ``snapshot_cycle_NNNN.png`` at chosen deployment cycles (``--cycles 14,64,106``; by
    default ``--snapshots`` evenly spaced ones, first and last included): map, robots, the
    complex, frontier and obstacle edges, redundant robots, live robots and their twins;
  * ``progress.png``: coverage, robots and frontier edges per cycle (coverage measure:
    ``--coverage``, see viz/coverage.py), and the same numbers in ``cycles.csv``;
  * ``animation.gif``: one frame per cycle (at most ``--gif-frames``, evenly sampled).
A recording without Complex messages (no coordinator) is drawn from Truth over time.
Each written file is printed on stdout, one path per line.
"""
from __future__ import annotations

import argparse
import csv
import logging
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

from swarmcover.bus import messages as m
from swarmcover.viz.geometry import redundant_robots

log = logging.getLogger("swarmcover.plot")


@dataclass
class Frame:
    """One instant to draw: a Complex (or None) and the latest Truth and mocap poses then."""
    cx: m.Complex | None
    truth: m.Truth | None
    mocap: dict = field(default_factory=dict)
    t_log: float = 0.0  # seconds since the first recorded message
    removed: frozenset = frozenset()  # robots marked redundant so far (drawn while outside)

    @property
    def cycle(self) -> int | None:
        return None if self.cx is None else int(self.cx.cycle)


@dataclass
class RunData:
    """What a recording holds for figures. frames: one per cycle (or sampled Truths)."""
    source: Path
    info: m.WorldInfo | None
    frames: list[Frame]
    by_cycle: bool
    invalid: int = 0
    messages: int = 0


def find_recording(path: str | Path) -> Path:
    """A run folder's run.mcap (or its only .mcap), or the file itself."""
    p = Path(path)
    if p.is_dir():
        if (p / "run.mcap").is_file():
            return p / "run.mcap"
        found = sorted(p.glob("*.mcap"))
        if len(found) == 1:
            return found[0]
        raise FileNotFoundError(f"{p}: no run.mcap in this folder"
                                + (f" (and {len(found)} other .mcap files)" if found else ""))
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file or folder")
    return p


def load_run(path: str | Path, *, max_truth_frames: int = 400, progress: bool = False) -> RunData:
    """Read a recording: the WorldInfo, and one Frame per Complex cycle (the last Complex of
    each cycle with the latest Truth before it); without Complexes, up to
    ``max_truth_frames`` Truths evenly spread in time."""
    from swarmcover.ground.progress import Progress
    from swarmcover.recording.replay import read_messages, summary_counts

    src = find_recording(path)
    total, _ = summary_counts(src)
    prog = Progress(total=total or None, label="plot: reading", unit="msg", enabled=progress)
    live_ids: set[int] = set()
    info = None
    truth = None
    mocap: dict[int, tuple[float, float]] = {}
    frames: dict[int, Frame] = {}
    truths: list[tuple[float, m.Truth, dict]] = []
    pending: list[Frame] = []
    redundant: set[int] = set()
    n_truth, stride, last_truth = 0, 1, None
    invalid = 0
    n = 0
    t0 = None
    for r in read_messages(src):
        n += 1
        if n % 5000 == 0:
            prog.set(n)
        if t0 is None:
            t0 = r.log_time_ns
        k = r.key
        want = (k.endswith("/world/info") or k.endswith("/world/truth")
                or k.endswith("/coord/complex"))
        if k.endswith("/odom"):  # only live robots' odometry can be mocap: skip the rest cheaply
            parts = k.split("/")
            want = len(parts) >= 3 and parts[-2].isdigit() and int(parts[-2]) in live_ids
        if r.kind == "liveliness" or not want:
            continue
        try:
            msg = m.decode(r.data)
        except m.WireError as e:
            invalid += 1
            if invalid == 1:
                log.warning("%s: skipping invalid message on %s: %s", src, k, e)
            continue
        t = (r.log_time_ns - t0) / 1e9
        if isinstance(msg, m.WorldInfo):
            info = info or msg
        elif isinstance(msg, m.Truth):
            truth = msg
            live_ids = {i for i, lv in zip(msg.ids, msg.live) if lv}
            if not frames:  # kept only for runs without a coordinator, thinned as they grow
                n_truth += 1
                if n_truth % stride == 0:
                    truths.append((t, msg, dict(mocap)))
                    if len(truths) >= 2 * max_truth_frames:
                        truths = truths[1::2]
                        stride *= 2
                last_truth = (t, msg, dict(mocap))
            for f in pending:  # Complexes that came before any Truth get the first one
                f.truth = msg
            pending.clear()
        elif isinstance(msg, m.Pose):
            if msg.source == "mocap":
                mocap[msg.robot] = (msg.x, msg.y)
        elif isinstance(msg, m.Complex):
            redundant |= redundant_robots(msg)
            frames[msg.cycle] = Frame(msg, truth, dict(mocap), t, frozenset(redundant))
            if truth is None:
                pending.append(frames[msg.cycle])
    prog.close()
    if frames:
        out = [frames[c] for c in sorted(frames)]
        by_cycle = True
    else:
        by_cycle = False
        if last_truth is not None and (not truths or truths[-1][1] is not last_truth[1]):
            truths.append(last_truth)
        step = max(1, math.ceil(len(truths) / max_truth_frames))
        picked = truths[::step]
        if truths and picked[-1] is not truths[-1]:
            picked.append(truths[-1])
        out = [Frame(None, tr, mc, t) for t, tr, mc in picked]
    if info is None:
        info = _info_from_frames(out)
        log.warning("%s: no world/info in the recording (world not up when recording began?); "
                    "drawing without the map", src)
    return RunData(src, info, out, by_cycle, invalid, n)


NO_MAP = "(no map recorded)"


def _info_from_frames(frames: list[Frame]) -> m.WorldInfo:
    """A stand-in map when no world/info was recorded: a frame around every robot seen."""
    xs = [x for f in frames if f.truth for x in f.truth.x] or [0.0, 1.0]
    ys = [y for f in frames if f.truth for y in f.truth.y] or [0.0, 1.0]
    x0, x1, y0, y1 = min(xs) - 0.5, max(xs) + 0.5, min(ys) - 0.5, max(ys) + 0.5
    return m.WorldInfo(name=NO_MAP, rv=1.0, robot_radius=0.06, dt=0.05,
                       boundary=[x0, y0, x1, y0, x1, y1, x0, y1], obstacles=[], sources=[],
                       free_area=0.0, config="")


def parse_cycles(text: str) -> list[int]:
    try:
        out = [int(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError:
        raise ValueError(f"--cycles {text!r}: expected comma-separated integers, e.g. 14,64,106") from None
    if not out:
        raise ValueError(f"--cycles {text!r}: no cycle given")
    return out


def pick_frames(frames: list[Frame], by_cycle: bool, cycles: list[int] | None,
                count: int) -> list[int]:
    """Indices into ``frames``: the frame of each requested cycle (nearest available), or
    ``count`` evenly spaced ones including the first and the last."""
    if not frames:
        return []
    if cycles and by_cycle:
        avail = [f.cycle for f in frames]
        idx = []
        for c in cycles:
            k = min(range(len(avail)), key=lambda i: (abs(avail[i] - c), avail[i]))
            if avail[k] != c:
                log.warning("cycle %d not recorded; using cycle %d", c, avail[k])
            if k not in idx:
                idx.append(k)
        return idx
    count = max(1, min(count, len(frames)))
    if count == 1:
        return [len(frames) - 1]
    return sorted({round(i * (len(frames) - 1) / (count - 1)) for i in range(count)})


def stats_rows(run: RunData, coverage_fn) -> list[dict]:
    """Per frame: cycle (or index), t, robots, frontier and obstacle edges, coverage."""
    rows = []
    for i, f in enumerate(run.frames):
        robots = len(f.truth.ids) if f.truth is not None else (f.cx.robots if f.cx else 0)
        rows.append({"cycle": f.cycle if f.cycle is not None else i, "t": round(f.t_log, 3),
                     "robots": robots,
                     "frontier": len(f.cx.frontier) if f.cx else 0,
                     "obstacle": len(f.cx.obstacle) if f.cx else 0,
                     "redundant": len(f.cx.redundant) if f.cx else 0,
                     "certified": bool(f.cx.certified) if f.cx else False,
                     "coverage": coverage_fn(run.info, f.truth)})
    return rows


def make_plots(path: str | Path, out: str | Path | None = None, *, cycles: list[int] | None = None,
               snapshots: int = 4, show_disks: bool = False, coverage: str = "auto",
               gif: bool = True, gif_frames: int = 80, fps: float = 5.0,
               progress: bool = True) -> list[Path]:
    """Everything ``swarmcover plot`` writes; returns the written paths."""
    from swarmcover.ground.progress import Progress

    from swarmcover.viz.coverage import coverage_measure
    from swarmcover.viz.figures import render_progress, render_snapshot, snapshot_image, write_gif

    run = load_run(path, progress=progress)
    cov_fn, cov_label = coverage_measure("none" if run.info.name == NO_MAP else coverage)
    if not run.frames:
        raise ValueError(f"{run.source}: no Truth or Complex messages to plot "
                         f"({run.messages} messages recorded)")
    outdir = Path(out) if out is not None else run.source.parent
    outdir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    info = run.info
    unit = "cycle" if run.by_cycle else "frame"

    def title(f: Frame, i: int) -> str:
        if f.cx is None:
            return f"{info.name}, t = {f.t_log:.1f} s, {len(f.truth.ids) if f.truth else 0} robots"
        return ""

    for i in pick_frames(run.frames, run.by_cycle, cycles, snapshots):
        f = run.frames[i]
        name = (f"snapshot_cycle_{f.cycle:04d}.png" if f.cycle is not None
                else f"snapshot_t{f.t_log:07.1f}s.png")
        written.append(render_snapshot(info, f.truth, f.cx, outdir / name, title=title(f, i),
                                       show_disks=show_disks, mocap=f.mocap, removed=f.removed))
    with Progress(total=len(run.frames), label="plot: coverage", unit=unit, enabled=progress) as p:
        rows = []
        for r in stats_rows(run, cov_fn):
            rows.append(r)
            p.update(1)
    csv_path = outdir / "cycles.csv"
    with open(csv_path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    written.append(csv_path)
    written.append(render_progress(rows, outdir / "progress.png", coverage_label=cov_label,
                                   title=info.name))
    if gif:
        idx = pick_frames(run.frames, False, None, gif_frames)
        frames = []
        with Progress(total=len(idx), label="plot: animation", unit="frame", enabled=progress) as p:
            for i in idx:
                f = run.frames[i]
                frames.append(snapshot_image(info, f.truth, f.cx, title=title(f, i),
                                             show_disks=show_disks, mocap=f.mocap,
                                             removed=f.removed))
                p.update(1)
        written.append(write_gif(frames, outdir / "animation.gif", fps=fps))
    return written


def main(argv: list[str] | None = None) -> int:
    from swarmcover.bus.session import setup_logging

    from swarmcover.viz.coverage import KINDS

    p = argparse.ArgumentParser(prog="swarmcover plot", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", metavar="RUN_DIR_OR_MCAP", help="run folder (with run.mcap) or .mcap file")
    p.add_argument("--out", "-o", default=None, metavar="DIR",
                   help="output folder (default: next to the recording)")
    p.add_argument("--cycles", default=None, help="snapshot cycles, e.g. 14,64,106")
    p.add_argument("--snapshots", type=int, default=4,
                   help="number of evenly spaced snapshots when --cycles is not given (default 4)")
    p.add_argument("--disks", action="store_true", help="draw the rv visibility disks")
    p.add_argument("--coverage", choices=KINDS, default="auto",
                   help="coverage measure (default auto: ground truth if world/groundtruth.py has "
                        "one, else rv disks without line of sight)")
    p.add_argument("--no-gif", action="store_true", help="skip the animation")
    p.add_argument("--gif-frames", type=int, default=80, help="animation frames at most (default 80)")
    p.add_argument("--fps", type=float, default=5.0, help="animation frames per second (default 5)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    p.add_argument("--log-level", default="INFO")
    args = p.parse_args(argv)
    setup_logging(args.log_level, "swarmcover.plot")
    try:
        cycles = parse_cycles(args.cycles) if args.cycles else None
        paths = make_plots(args.run, args.out, cycles=cycles, snapshots=args.snapshots,
                           show_disks=args.disks, coverage=args.coverage, gif=not args.no_gif,
                           gif_frames=args.gif_frames, fps=args.fps, progress=not args.quiet)
    except (OSError, ValueError) as e:
        log.error("%s", e)
        return 2
    for path in paths:
        print(path, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
