"""Thesis-style figures of a run (cf. thesis Figs. 3.10-3.12): pure drawing, no Zenoh.

matplotlib with the Agg canvas (no pyplot state, safe in any thread). Colours:
walls black, obstacles grey, sources blue triangles; virtual robots red, twins of live
robots green, measured (mocap) poses of live robots green hollow squares joined to their
twins by dashed lines; robots not (yet) in the complex hollow; redundant robots crossed;
robots removed as redundant grey diamonds; complex edges grey over the area the triangles
cover, in one flat colour (overlaps do not shade darker); frontier edges (K) orange,
obstacle edges (O) purple, those the coordinator inferred (Complex.inferred, when sent)
dotted; optional rv disks, flat light blue. World frame, metres, x right, y up.

Layout in inches (fixed margins for tick labels, axis labels, title and legend rows), so no
label is clipped whatever the map's aspect, and animation frames share one size.
"""
from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.collections import LineCollection, PolyCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Circle, Polygon  # noqa: E402

from .coverage import map_bounds, polygon_xy  # noqa: E402
from .geometry import Scene, build_scene  # noqa: E402

COLORS = {
    "wall": "#111111", "obstacle": "#9a9a9a", "source": "#1f4fbf",
    "virtual": "#d62728", "twin": "#2ca02c", "mocap": "#2ca02c",
    "edge": "#8c8c8c", "triangle": "#1f77b4", "frontier": "#ff7f0e", "obstacle_edge": "#9467bd",
    "redundant": "#000000", "disk": "#1f77b4", "removed": "#7f7f7f",
}
# flat fills: the colour a 10 % (triangles) or 6 % (disks) tint of blue gives on white, drawn
# opaque, so overlapping triangles or disks read as one area, not as "more covered"
TRI_FILL = "#e8f1f7"
DISK_FILL = "#f1f6fa"
LEGEND_COLS = 4
LEGEND_ROWS = 3   # room for every legend item (12 at most), so all frames share one size


def _figure(info, width_in: float = 7.0, legend_rows: int = 2,
            legend_fontsize: float = 7.5) -> tuple[Figure, object]:
    """Figure and map axes. Margins are in inches: left for the y tick labels and label,
    bottom for the x label and the legend rows, top for the title."""
    x0, x1, y0, y1 = map_bounds(info, margin=0.05 * max(info.rv, 0.1))
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    left, right, top = 0.85, 0.2, 0.45
    bottom = 0.55 + legend_rows * legend_fontsize * 1.75 / 72 + 0.1
    aw = width_in - left - right
    ah = float(np.clip(aw * aspect, 1.2, 2.0 * width_in))
    h = ah + top + bottom
    fig = Figure(figsize=(width_in, h), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((left / width_in, bottom / h, aw / width_in, ah / h))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.tick_params(labelsize=8)
    return fig, ax


def draw_map(ax, info) -> None:
    """Walls (boundary), obstacles and sources of a WorldInfo."""
    b = polygon_xy(info.boundary)
    if len(b) >= 2:
        ax.add_patch(Polygon(b, closed=True, fill=False, edgecolor=COLORS["wall"], lw=1.6, zorder=3))
    obs = [polygon_xy(o) for o in info.obstacles]
    obs = [o for o in obs if len(o) >= 3]
    if obs:
        ax.add_collection(PolyCollection(obs, facecolors=COLORS["obstacle"],
                                         edgecolors=COLORS["wall"], linewidths=0.8, zorder=3))
    src = np.asarray(info.sources, float).reshape(-1, 3) if len(info.sources) else np.zeros((0, 3))
    if len(src):
        ax.scatter(src[:, 0], src[:, 1], marker="^", s=70, c=COLORS["source"], zorder=4,
                   edgecolors="white", linewidths=0.6)


def draw_scene(ax, info, scene: Scene, *, show_disks: bool = False) -> None:
    """Complex, fence and robots of a Scene (on top of :func:`draw_map`)."""
    if show_disks and scene.n_robots:
        for x, y in scene.xy:
            ax.add_patch(Circle((x, y), info.rv, facecolor=DISK_FILL, edgecolor="none",
                                zorder=1))
    if len(scene.triangles):  # opaque, no edge: the union reads as one flat area
        ax.add_collection(PolyCollection(scene.triangles, facecolors=TRI_FILL,
                                         edgecolors=TRI_FILL, linewidths=0.3, zorder=1.5))
    if len(scene.edges):
        ax.add_collection(LineCollection(scene.edges, colors=COLORS["edge"], linewidths=0.6,
                                         zorder=2))
    if len(scene.obstacle):
        ax.add_collection(LineCollection(scene.obstacle, colors=COLORS["obstacle_edge"],
                                         linewidths=2.0, zorder=2.5))
    if len(scene.inferred):  # obstacle edges the coordinator inferred: white dots on O
        ax.add_collection(LineCollection(scene.inferred, colors="white", linewidths=1.0,
                                         linestyles=(0, (1.0, 1.6)), zorder=2.55))
    if len(scene.frontier):
        ax.add_collection(LineCollection(scene.frontier, colors=COLORS["frontier"],
                                         linewidths=2.0, zorder=2.6))
    if scene.n_robots:
        col = np.where(scene.live, COLORS["twin"], COLORS["virtual"])
        inc = scene.in_complex if len(scene.in_complex) == scene.n_robots else np.ones(scene.n_robots, bool)
        if inc.any():
            ax.scatter(scene.xy[inc, 0], scene.xy[inc, 1], s=22, c=col[inc], zorder=5,
                       edgecolors="black", linewidths=0.3)
        removed = scene.removed if len(scene.removed) == scene.n_robots else np.zeros(
            scene.n_robots, bool)
        removed = removed & ~inc
        if removed.any():
            ax.scatter(scene.xy[removed, 0], scene.xy[removed, 1], s=30, marker="D",
                       c=COLORS["removed"], edgecolors="black", linewidths=0.3, zorder=5)
        out = ~inc & ~removed
        if out.any():
            ax.scatter(scene.xy[out, 0], scene.xy[out, 1], s=22, facecolors="none",
                       edgecolors=col[out], linewidths=1.1, zorder=5)
        if scene.redundant.any():
            r = scene.redundant
            ax.scatter(scene.xy[r, 0], scene.xy[r, 1], s=55, marker="x", c=COLORS["redundant"],
                       linewidths=1.2, zorder=6)
    if scene.mocap:
        pos = {int(i): p for i, p in zip(scene.ids, scene.xy)}
        for rid, (mx, my) in scene.mocap.items():
            if rid in pos:
                tx, ty = pos[rid]
                ax.plot([mx, tx], [my, ty], ls="--", lw=0.9, color=COLORS["mocap"], zorder=4)
            ax.scatter([mx], [my], marker="s", s=30, facecolors="none",
                       edgecolors=COLORS["mocap"], linewidths=1.2, zorder=5)


def _legend_items(scene: Scene) -> list:
    items = [Line2D([], [], color=COLORS["wall"], lw=1.6, label="walls"),
             Line2D([], [], marker="^", ls="", color=COLORS["source"], label="source"),
             Line2D([], [], marker="o", ls="", color=COLORS["virtual"], mec="black", mew=0.3,
                    label="virtual robot"),
             Line2D([], [], color=COLORS["edge"], lw=0.8, label="complex edge"),
             Line2D([], [], color=COLORS["frontier"], lw=2, label="frontier K"),
             Line2D([], [], color=COLORS["obstacle_edge"], lw=2, label="obstacle O")]
    if scene.live.any():
        items.append(Line2D([], [], marker="o", ls="", color=COLORS["twin"], label="live robot twin"))
    if scene.mocap:
        items.append(Line2D([], [], marker="s", ls="--", color=COLORS["mocap"], mfc="none",
                            label="live robot (mocap)"))
    if len(scene.in_complex) and (~scene.in_complex).any():
        items.append(Line2D([], [], marker="o", ls="", mfc="none", color=COLORS["virtual"],
                            label="not in complex"))
    if scene.redundant.any():
        items.append(Line2D([], [], marker="x", ls="", color=COLORS["redundant"], label="redundant"))
    if len(scene.removed) and (scene.removed & ~scene.in_complex).any():
        items.append(Line2D([], [], marker="D", ls="", color=COLORS["removed"], mec="black",
                            mew=0.3, label="removed (redundant)"))
    if len(scene.inferred):
        items.append(Line2D([], [], color=COLORS["obstacle_edge"], lw=2, ls=(0, (1, 1)),
                            label="inferred obstacle O"))
    return items


def _legend(fig, items: list, fontsize: float = 7.5) -> None:
    fig.legend(handles=items, loc="lower center", ncol=min(LEGEND_COLS, len(items)),
               fontsize=fontsize, frameon=False, bbox_to_anchor=(0.5, 0.02))


def default_title(info, scene: Scene, cx=None) -> str:
    parts = [info.name or "run"]
    if scene.cycle is not None:
        parts.append(f"cycle {scene.cycle}")
    parts.append(f"{scene.n_robots} robots")
    if cx is not None:
        parts.append(f"{len(cx.frontier)} frontier edges")
        if cx.certified:
            parts.append("certified")
    if scene.t is not None:
        parts.append(f"t = {scene.t:.1f} s")
    return ", ".join(parts)


def snapshot_figure(info, truth=None, cx=None, *, title: str = "", show_disks: bool = False,
                    mocap: dict | None = None, width_in: float = 7.0, removed=(),
                    legend_fontsize: float = 7.5) -> Figure:
    """The snapshot as a matplotlib Figure (Agg canvas attached). removed: robot ids taken
    out of the complex as redundant (drawn with their own mark while not in the complex)."""
    scene = build_scene(truth, cx, mocap, removed=removed)
    items = _legend_items(scene)
    fig, ax = _figure(info, width_in, LEGEND_ROWS, legend_fontsize)
    draw_map(ax, info)
    draw_scene(ax, info, scene, show_disks=show_disks)
    ax.set_title(title or default_title(info, scene, cx), fontsize=10)
    _legend(fig, items, legend_fontsize)
    return fig


SNAPSHOT_DPI = 110   # the PNG snapshots (plot's frames, run's final.png)


def render_snapshot(info, truth=None, cx=None, path: str | os.PathLike = "snapshot.png", *,
                    title: str = "", show_disks: bool = False, mocap: dict | None = None,
                    dpi: int = SNAPSHOT_DPI, removed=()) -> Path:
    """Draw one instant to a PNG file and return its path.

    info: WorldInfo (map); truth: Truth or None (no robots); cx: Complex or None (no
    complex); positions come from ``truth``, matched to vertices through
    ``cx.occupants``; robots not in the complex are drawn hollow. mocap: optional
    {robot id: (x, y)} measured poses of live robots; removed: ids of robots removed as
    redundant.
    """
    fig = snapshot_figure(info, truth, cx, title=title, show_disks=show_disks, mocap=mocap,
                          removed=removed)
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    return path


GIF_WIDTH_IN, GIF_DPI, GIF_LEGEND_PT = 5.0, 100, 9.0   # 500 px wide, legend text ~12 px


def snapshot_image(info, truth=None, cx=None, *, title: str = "", show_disks: bool = False,
                   mocap: dict | None = None, dpi: int = GIF_DPI, width_in: float = GIF_WIDTH_IN,
                   legend_fontsize: float = GIF_LEGEND_PT, removed=()):
    """The snapshot as a PIL RGB image (animation frames): a smaller figure at a higher dpi
    than the PNGs, so the text (legend, ticks) stays readable at the GIF's pixel size."""
    from PIL import Image
    fig = snapshot_figure(info, truth, cx, title=title, show_disks=show_disks, mocap=mocap,
                          width_in=width_in, removed=removed, legend_fontsize=legend_fontsize)
    fig.set_dpi(dpi)
    canvas = fig.canvas
    canvas.draw()
    return Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3].copy())


def write_gif(frames: Sequence, path: str | os.PathLike, *, fps: float = 5.0,
              last_hold_s: float = 1.5) -> Path:
    """Write PIL frames as an animated GIF (looping); the last frame is held a little."""
    if not frames:
        raise ValueError(f"write_gif {path}: no frames")
    path = Path(path)
    ms = max(20, int(round(1000.0 / fps)))
    durations = [ms] * (len(frames) - 1) + [max(ms, int(last_hold_s * 1000))]
    pal = [f.convert("P", palette=1, colors=256) for f in frames]  # 1 = ADAPTIVE
    pal[0].save(path, save_all=True, append_images=pal[1:], duration=durations, loop=0,
                optimize=False, disposal=1)
    return path


def render_progress(rows: Iterable[dict], path: str | os.PathLike, *,
                    coverage_label: str = "coverage", title: str = "") -> Path:
    """Coverage, robots and frontier edges per cycle, three stacked axes sharing x.

    rows: dicts with "cycle", "robots", "frontier" and optional "coverage" (fraction or None).
    """
    rows = list(rows)
    fig = Figure(figsize=(7, 6.2), dpi=100)
    FigureCanvasAgg(fig)
    axs = fig.subplots(3, 1, sharex=True)
    cyc = np.array([r["cycle"] for r in rows], float)
    cov = np.array([np.nan if r.get("coverage") is None else 100.0 * r["coverage"] for r in rows], float)
    rob = np.array([r["robots"] for r in rows], float)
    fro = np.array([r["frontier"] for r in rows], float)
    if np.isfinite(cov).any():
        axs[0].plot(cyc, cov, color="#1f77b4", lw=1.5)
        axs[0].set_ylim(0, 102)
    else:
        axs[0].text(0.5, 0.5, "coverage not measured", ha="center", va="center",
                    transform=axs[0].transAxes, color="grey")
    axs[0].set_ylabel("%", fontsize=9)
    axs[0].set_title(coverage_label, fontsize=9, loc="left")
    axs[1].step(cyc, rob, where="post", color=COLORS["virtual"], lw=1.5)
    axs[1].set_ylabel("robots", fontsize=9)
    axs[2].step(cyc, fro, where="post", color=COLORS["frontier"], lw=1.5)
    axs[2].set_ylabel("frontier edges", fontsize=9)
    axs[2].set_xlabel("deployment cycle")
    for ax in axs:
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path


def png_bytes(fig: Figure, dpi: int = 100) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()
