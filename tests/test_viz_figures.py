"""Pure drawing and geometry: snapshots, scene building, coverage raster, progress line."""
from __future__ import annotations

import io
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from swarmcover.bus import messages as m
from swarmcover.ground.progress import Progress
from swarmcover.viz.coverage import coverage_measure, disk_coverage
from swarmcover.viz.figures import render_progress, render_snapshot, snapshot_image, write_gif
from swarmcover.viz.geometry import build_scene
from swarmcover.viz.synth import Scenario


def _pixels(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.int16)


def test_snapshots_exist_and_differ_between_cycles(tmp_path):
    sc = Scenario(kills={9: [4]})
    paths = []
    for c in (3, 12):
        truth, cx = sc.truth(c, 0.5, 10 * c, 0.3 * c), sc.complex(c, 0.3 * c)
        paths.append(render_snapshot(sc.info, truth, cx, tmp_path / f"c{c}.png",
                                     show_disks=True, mocap=sc.mocap(c, 0.5, 0.0)))
    a, b = (_pixels(p) for p in paths)
    assert a.shape == b.shape and a.shape[0] > 300 and a.shape[1] > 500
    diff = np.abs(a - b).sum(axis=2) > 30
    assert diff.mean() > 0.01  # more robots, edges and disks: a visible change
    # the robot colours are there: red virtual robots and the green live twin
    for img in (a, b):
        red = (img[..., 0] > 180) & (img[..., 1] < 80) & (img[..., 2] < 80)
        green = (img[..., 1] > 130) & (img[..., 0] < 90) & (img[..., 2] < 90)
        assert red.sum() > 20 and green.sum() > 5


def test_snapshot_without_truth_or_complex_draws_the_map(tmp_path):
    sc = Scenario()
    p = render_snapshot(sc.info, None, None, tmp_path / "map.png", title="map only")
    img = _pixels(p)
    dark = (img.sum(axis=2) < 150).mean()
    assert 0.001 < dark < 0.2  # walls and text, not blank, not black
    # a complex without truth: no positions, nothing crashes
    render_snapshot(sc.info, None, sc.complex(5, 1.0), tmp_path / "cx.png")


def test_gif_and_progress_plot(tmp_path):
    sc = Scenario()
    frames = [snapshot_image(sc.info, sc.truth(c, 0.5, c, c), sc.complex(c, c), dpi=40)
              for c in (2, 6, 10)]
    g = write_gif(frames, tmp_path / "a.gif", fps=4)
    im = Image.open(g)
    assert im.n_frames == 3
    with pytest.raises(ValueError, match="no frames"):
        write_gif([], tmp_path / "b.gif")
    rows = [{"cycle": c, "robots": c + 1, "frontier": c % 4, "coverage": c / 20} for c in range(10)]
    p = render_progress(rows, tmp_path / "p.png", coverage_label="cov")
    assert _pixels(p).shape[0] > 400
    rows2 = [dict(r, coverage=None) for r in rows]  # coverage unmeasured: still a figure
    render_progress(rows2, tmp_path / "p2.png")


# --------------------------------------------------------------------------- geometry

@st.composite
def truth_and_complex(draw):
    n = draw(st.integers(0, 12))
    ids = draw(st.lists(st.integers(0, 50), min_size=n, max_size=n, unique=True))
    xs = [draw(st.floats(-5, 5)) for _ in ids]
    ys = [draw(st.floats(-5, 5)) for _ in ids]
    truth = m.Truth(tick=1, t=0.0, ids=ids, x=xs, y=ys, theta=[0.0] * n,
                    live=[draw(st.booleans()) for _ in ids])
    nv = draw(st.integers(0, 10))
    verts = list(range(100, 100 + nv))
    pool = ids + [-1, 60, 61]  # occupants: present robots, empty, robots without a body
    occ = [draw(st.sampled_from(pool)) for _ in verts]
    edges = []
    if nv >= 2:
        for _ in range(draw(st.integers(0, 15))):
            a, b = draw(st.lists(st.sampled_from(verts), min_size=2, max_size=2, unique=True))
            edges += [a, b]
    ne = len(edges) // 2
    fr = draw(st.lists(st.integers(0, max(0, ne - 1)), max_size=ne)) if ne else []
    red = draw(st.lists(st.sampled_from(verts), max_size=3)) if verts else []
    cx = m.Complex(cycle=1, vertices=verts, occupants=occ, edges=edges, frontier=fr,
                   redundant=red)
    cx.validate()
    return truth, cx


@settings(max_examples=60, deadline=None)
@given(truth_and_complex())
def test_scene_places_simplices_only_at_present_robots(tc):
    truth, cx = tc
    s = build_scene(truth, cx)
    pos = {(x, y) for x, y in zip(truth.x, truth.y)}
    for seg in np.concatenate([s.edges, s.frontier]).reshape(-1, 2):
        assert (seg[0], seg[1]) in pos
    occ = dict(zip(cx.vertices, cx.occupants))
    present = set(truth.ids)
    drawable = [(cx.edges[2 * k], cx.edges[2 * k + 1]) for k in range(len(cx.edges) // 2)]
    expected = sum(1 for a, b in drawable if occ[a] in present and occ[b] in present)
    assert len(s.edges) == expected
    assert s.n_robots == len(truth.ids)
    assert not (s.redundant & ~s.in_complex).any()  # redundant implies in the complex


# --------------------------------------------------------------------------- coverage

def test_disk_coverage_of_one_robot_is_its_disk_area():
    info = Scenario().info
    cov = disk_coverage(info, [5.0], [3.0], res=0.02)  # disk fully inside free space
    assert cov == pytest.approx(math.pi * info.rv ** 2 / info.free_area, rel=0.02)
    assert disk_coverage(info, [], []) == 0.0


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 6), st.floats(0, 4)), max_size=8),
       st.tuples(st.floats(0, 6), st.floats(0, 4)))
def test_disk_coverage_is_a_fraction_and_grows_with_robots(pts, extra):
    info = Scenario().info
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    a = disk_coverage(info, xs, ys)
    b = disk_coverage(info, xs + [extra[0]], ys + [extra[1]])
    assert 0.0 <= a <= b <= 1.0


def test_coverage_measure_kinds():
    fn, label = coverage_measure("disks")
    sc = Scenario()
    assert 0 < fn(sc.info, sc.truth(5, 0.5, 1, 1.0)) < 1 and "disks" in label
    assert coverage_measure("none")[0](sc.info, sc.truth(5, 0.5, 1, 1.0)) is None
    with pytest.raises(ValueError, match="bogus"):
        coverage_measure("bogus")


# --------------------------------------------------------------------------- progress

def test_progress_log_style_and_tty_style():
    buf = io.StringIO()
    p = Progress(total=10, label="work", unit="msg", stream=buf, tty=False, every_s=3600)
    for _ in range(10):
        p.update(1, note="n")
    p.close()
    p.close()
    lines = buf.getvalue().splitlines()
    assert len(lines) == 2  # the first update and the final line, nothing in between
    assert lines[-1].startswith("work: 10/10 msg (100%)")
    tty = io.StringIO()
    q = Progress(total=None, label="rec", stream=tty, tty=True, hz=1e9)
    q.update(5)
    q.close(note="done")
    out = tty.getvalue()
    assert out.startswith("\rrec: 5") and out.endswith("done\n") and out.count("\n") == 1
    off = io.StringIO()
    with Progress(total=3, stream=off, enabled=False) as r:
        r.update(3)
    assert off.getvalue() == ""


def test_groundtruth_coverage_is_used_when_world_provides_it():
    pytest.importorskip("swarmcover.world.groundtruth")
    fn, label = coverage_measure("auto")
    assert "ground truth" in label
    sc = Scenario()
    truth = sc.truth(12, 0.5, 1, 1.0)
    gt = fn(sc.info, truth)
    disks = disk_coverage(sc.info, truth.x, truth.y)
    assert gt is not None and 0 < gt <= disks + 0.02  # line of sight only removes coverage


# --------------------------------------------------------------------------- readability

def _info(boundary, name="t"):
    return m.WorldInfo(name=name, rv=1.0, robot_radius=0.06, dt=0.05, boundary=boundary,
                       obstacles=[], sources=[0.3, 0.3, 0.0], free_area=1.0, config="")


def _drawn(fig):
    fig.canvas.draw()
    return fig, fig.canvas.get_renderer()


@pytest.mark.parametrize("x0,y0,w,h", [(0, 0, 30.0, 2.0), (0, 0, 2.0, 14.0), (0, 0, 6.0, 4.0),
                                       (-20, -12.5, 40.0, 5.0), (100, 100, 30.0, 3.0)])
def test_no_label_title_or_legend_is_clipped_whatever_the_map_aspect(x0, y0, w, h):
    """Wide maps with wide tick labels (-12.5, 102.5: ROS maps have such origins) clipped
    the y label at 0.07 of the figure width; margins are now in inches."""
    from swarmcover.viz.figures import snapshot_figure
    truth = m.Truth(tick=1, t=0.0, ids=[0, 1], x=[0.5, 1.2], y=[0.5, 0.6], theta=[0.0, 0.0],
                    live=[False, True])
    truth.x[:], truth.y[:] = [x0 + 0.5, x0 + 1.2], [y0 + 0.5, y0 + 0.6]
    fig, r = _drawn(snapshot_figure(_info([x0, y0, x0 + w, y0, x0 + w, y0 + h, x0, y0 + h]),
                                    truth, None,
                                    title="a long title naming the map, cycle and robots"))
    W, H = fig.canvas.get_width_height()
    ax = fig.axes[0]
    boxes = [ax.yaxis.label.get_window_extent(r), ax.xaxis.label.get_window_extent(r),
             ax.title.get_window_extent(r), fig.legends[0].get_window_extent(r)]
    y0, y1 = ax.get_ylim()
    boxes += [t.get_window_extent(r) for t in ax.get_yticklabels()
              if t.get_text() and y0 <= t.get_position()[1] <= y1]  # ticks drawn
    for b in boxes:
        assert b.x0 >= 0 and b.y0 >= 0 and b.x1 <= W and b.y1 <= H, (w, h, b, W, H)
    # the legend does not run into the x axis label
    assert fig.legends[0].get_window_extent(r).y1 <= ax.xaxis.label.get_window_extent(r).y0 + 1


def test_overlapping_triangles_shade_like_one_triangle():
    from swarmcover.viz.figures import TRI_FILL, snapshot_figure
    # triangles ABC and ABE overlap inside ABE (E is inside ABC)
    truth = m.Truth(tick=1, t=0.0, ids=[0, 1, 2, 3], x=[0.0, 4.0, 2.0, 2.0],
                    y=[0.0, 0.0, 3.2, 1.6], theta=[0.0] * 4, live=[False] * 4)
    cx = m.Complex(cycle=1, vertices=[0, 1, 2, 3], occupants=[0, 1, 2, 3],
                   edges=[0, 1, 0, 2, 1, 2, 0, 3, 1, 3, 2, 3], triangles=[0, 1, 2, 0, 1, 3])
    fig, _ = _drawn(snapshot_figure(_info([-1, -1, 5, -1, 5, 4, -1, 4]), truth, cx))
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(int)
    H = img.shape[0]
    ax = fig.axes[0]

    def px(x, y):
        X, Y = ax.transData.transform((x, y))
        return img[int(round(H - Y)), int(round(X))]
    twice, once = px(1.4, 0.5), px(1.2, 1.5)
    want = np.array([int(TRI_FILL[k:k + 2], 16) for k in (1, 3, 5)])
    assert np.abs(twice - once).max() <= 2 and np.abs(once - want).max() <= 2, (twice, once)


def test_removed_redundant_robots_and_inferred_edges_have_their_own_marks():
    from types import SimpleNamespace

    from swarmcover.viz.figures import COLORS, snapshot_figure
    truth = m.Truth(tick=1, t=0.0, ids=[0, 1, 2, 7], x=[0.0, 2.0, 1.0, 3.5],
                    y=[0.0, 0.0, 1.6, 3.0], theta=[0.0] * 4, live=[False] * 4)
    base = m.Complex(cycle=4, vertices=[0, 1, 2], occupants=[0, 1, 2],
                     edges=[0, 1, 0, 2, 1, 2], triangles=[0, 1, 2], obstacle=[0, 1])
    # Complex.inferred is optional on the wire: a Complex without it draws as before
    assert len(build_scene(truth, base).inferred) == 0
    cx = SimpleNamespace(**{**{f: getattr(base, f) for f, _ in base._FIELDS}, "inferred": [1]})
    scene = build_scene(truth, cx, removed={7})
    assert scene.removed.tolist() == [False, False, False, True]
    assert scene.inferred.shape == (1, 2, 2)
    fig, _ = _drawn(snapshot_figure(_info([-1, -1, 5, -1, 5, 4, -1, 4]), truth, cx,
                                    removed={7}))
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "removed (redundant)" in labels and "inferred obstacle O" in labels
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(int)
    X, Y = fig.axes[0].transData.transform((3.5, 3.0))
    grey = np.array([int(COLORS["removed"][k:k + 2], 16) for k in (1, 3, 5)])
    assert np.abs(img[int(round(img.shape[0] - Y)), int(round(X))] - grey).max() <= 3


def test_gif_frame_legend_text_is_readable_at_its_pixel_size():
    from swarmcover.viz.figures import GIF_DPI, GIF_LEGEND_PT, GIF_WIDTH_IN, snapshot_figure
    sc = Scenario()
    fig = snapshot_figure(sc.info, sc.truth(6, 0.5, 6, 6.0), sc.complex(6, 6.0),
                          width_in=GIF_WIDTH_IN, legend_fontsize=GIF_LEGEND_PT)
    fig.set_dpi(GIF_DPI)
    fig, r = _drawn(fig)
    heights = [t.get_window_extent(r).height for t in fig.legends[0].get_texts()]
    assert min(heights) >= 12, heights  # was ~8.5 px (7.5 pt at 70 dpi)
    img = snapshot_image(sc.info, sc.truth(6, 0.5, 6, 6.0), sc.complex(6, 6.0))
    assert 450 <= img.size[0] <= 550  # the GIF stays about as wide as before (490 px)
