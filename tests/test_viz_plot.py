"""``swarmcover plot`` on recordings written with the real MCAP sink (no Zenoh needed)."""
from __future__ import annotations

import csv

import numpy as np
import pytest
from PIL import Image

from swarmcover.bus.keys import Keys
from swarmcover.recording.record import McapSink
from swarmcover import plot
from swarmcover.viz.synth import Scenario


def write_run(path, *, cycles=13, with_info=True, with_complex=True, ticks_per_cycle=4):
    """A synthetic run as ``swarmcover record`` would write it (1 tick = 50 ms)."""
    k = Keys("plotrun")
    sc = Scenario(kills={9: [4]})
    t_ns = 1_700_000_000_000_000_000
    with McapSink(path) as sink:
        if with_info:
            sink.write(k.world_info, sc.info.encode(), t_ns, kind="query_reply")
        tick = 0
        for c in range(cycles):
            if with_complex:
                sink.write(k.complex, sc.complex(c, tick * 0.05).encode(), t_ns + tick * 50_000_000)
            for j in range(ticks_per_cycle):
                t = t_ns + tick * 50_000_000 + 1
                sink.write(k.truth, sc.truth(c, j / ticks_per_cycle, tick, tick * 0.05).encode(), t)
                for rid, (x, y) in sc.mocap(c, j / ticks_per_cycle, 0).items():
                    from swarmcover.bus import messages as m
                    sink.write(k.odom(rid), m.Pose(robot=rid, x=x, y=y, source="mocap").encode(), t)
                tick += 1
    return path


def _px(p):
    return np.asarray(Image.open(p).convert("RGB"), dtype=np.int16)


def test_plot_run_folder_writes_snapshots_progress_csv_and_gif(tmp_path, capsys):
    run = tmp_path / "run1"
    run.mkdir()
    write_run(run / "run.mcap")
    rc = plot.main([str(run), "--cycles", "3,8,12", "--gif-frames", "5", "--disks", "-q"])
    assert rc == 0
    printed = capsys.readouterr().out.split()
    names = sorted(p.split("/")[-1] for p in printed)
    assert names == sorted(["snapshot_cycle_0003.png", "snapshot_cycle_0008.png",
                            "snapshot_cycle_0012.png", "cycles.csv", "progress.png",
                            "animation.gif"])
    shots = [_px(run / f"snapshot_cycle_{c:04d}.png") for c in (3, 8, 12)]
    for a, b in zip(shots, shots[1:]):
        assert a.shape == b.shape
        assert (np.abs(a - b).sum(axis=2) > 30).mean() > 0.005  # pixels differ between cycles
    gif = Image.open(run / "animation.gif")
    assert gif.n_frames == 5
    rows = list(csv.DictReader(open(run / "cycles.csv")))
    assert [int(r["cycle"]) for r in rows] == list(range(13))
    cov = [float(r["coverage"]) for r in rows]
    assert all(0 < c <= 1 for c in cov) and cov[-1] > cov[1]
    # a cycle is paired with the last Truth before its Complex: bodies 0..11 less robot 4
    assert int(rows[12]["robots"]) == 11
    assert int(rows[12]["redundant"]) == 1


def test_plot_mcap_file_into_out_dir_default_cycles(tmp_path):
    f = write_run(tmp_path / "rec.mcap", cycles=9)
    out = tmp_path / "figs"
    paths = plot.make_plots(f, out, snapshots=3, gif=False, progress=False)
    shots = sorted(p.name for p in paths if p.name.startswith("snapshot"))
    assert shots == ["snapshot_cycle_0000.png", "snapshot_cycle_0004.png", "snapshot_cycle_0008.png"]
    assert all(p.parent == out for p in paths)


def test_plot_without_coordinator_or_map_uses_truth_over_time(tmp_path):
    f = write_run(tmp_path / "bare.mcap", cycles=6, with_info=False, with_complex=False)
    paths = plot.make_plots(f, tmp_path, snapshots=2, gif=True, gif_frames=3, progress=False)
    snaps = [p for p in paths if p.name.startswith("snapshot_t")]
    assert len(snaps) == 2
    rows = list(csv.DictReader(open(tmp_path / "cycles.csv")))
    assert len(rows) == 24 and rows[0]["coverage"] == ""  # no map: coverage not measured


def test_pick_frames_nearest_and_even():
    frames = [plot.Frame(cx=type("C", (), {"cycle": c})(), truth=None) for c in (0, 2, 4, 10)]
    assert plot.pick_frames(frames, True, [3, 9, 100], 4) == [1, 3]
    assert plot.pick_frames(frames, True, None, 3) == [0, 2, 3]
    assert plot.pick_frames(frames, True, None, 1) == [3]
    with pytest.raises(ValueError, match="14,64"):
        plot.parse_cycles("a,b")


def test_plot_errors_name_the_path(tmp_path, caplog):
    assert plot.main([str(tmp_path / "missing"), "-q"]) == 2
    assert "missing" in caplog.text
    empty = tmp_path / "empty"
    empty.mkdir()
    assert plot.main([str(empty), "-q"]) == 2
    assert "no run.mcap" in caplog.text
