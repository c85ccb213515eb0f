"""End to end: `swarmcover run configs/mixed.toml` covers the small room with two stand-in
live robots (fake-robot processes behind the hardware bridge) among virtual ones, and the
live robots' twins track them within a stated bound.

Bound (see bench/hwbridge.py for the measured numbers): with feed-forward on, as in
configs/mixed.toml, twin position error mean < 5 cm and p95 < 15 cm per live robot.

The run is real time: 784 s measured (cycle 32; 100% coverage at cycle 9, the rest is
probing the walls), so it is in the slow tier (pytest -m slow).
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from procs import free_port

ROOT = Path(__file__).resolve().parent.parent


pytestmark = [pytest.mark.timeout(1000), pytest.mark.slow]


def test_mixed_run_covers_with_live_stand_ins(procs, tmp_path):
    out = tmp_path / "run"
    run = procs.swarmcover("run", ROOT / "configs" / "mixed.toml", "--out", out,
                           "--port", free_port(), "--quiet", "--wall-timeout", "900")
    rc = run.wait(960)
    logs = out / "logs"
    summary = json.loads((out / "summary.json").read_text())
    assert rc == 0 and summary["certified"], run.output()[-3000:]

    # both live robots were spawned as twins and took part
    world_log = (logs / "world.log").read_text()
    for rid in (1, 2):
        assert re.search(rf"spawned robot {rid} \(diffdrive, live twin\)", world_log), world_log[-2000:]
    for rid in (1, 2):
        fin = (logs / f"fake-robot-{rid}.log").read_text()
        m = re.search(r"FINAL fake-robot \d+ x=(\S+) y=(\S+) .* commands=(\d+)", fin)
        assert m and int(m.group(3)) > 0
        print(next(ln for ln in fin.splitlines() if ln.startswith("FINAL")))   # expiry_stops
        # the stand-in stops at the walls like a real robot: still in the 2.5 m x 2 m room
        x, y = float(m.group(1)), float(m.group(2))
        assert 0.0 < x < 2.5 and 0.0 < y < 2.0, fin[-500:]

    # the bridge's own report: twins tracked the stand-ins
    line = next(ln for ln in (logs / "hwbridge.log").read_text().splitlines()
                if ln.startswith("SUMMARY "))
    rep = json.loads(line.split("SUMMARY ", 1)[1])
    for rid in ("1", "2"):
        err = rep["robots"][rid]["position_error_m"]
        assert err["n"] > 100
        assert err["mean"] < 0.05 and err["p95"] < 0.15, rep["robots"][rid]
        # robots touch walls (agents find them by touch) but never leave the map: the
        # geofence must not have held a live robot
        assert rep["gate_decisions"][rid]["geofence"] == 0, rep["gate_decisions"]
    assert rep["refused_commands"] == 0
    # ... and the run's own summary carries them (issue 20: not only in hwbridge.json)
    for rid in ("1", "2"):
        tt = summary["twin_tracking"][rid]
        assert tt["position_error_mean_m"] == rep["robots"][rid]["position_error_m"]["mean"]
        assert tt["position_error_p95_m"] < 0.15 and tt["stops"] >= 0
