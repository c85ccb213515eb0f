"""Bad input never hangs and never shows a traceback (issue 22, "nothing waits on what
cannot happen"): every row runs ``swarmcover run`` as a real process on a bad config, map or
flag, and must end with exit 2 and one line naming the field and value, with no traceback
and no process left behind. Every row fails before any process starts, so each takes about
as long as Python's imports.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
from pathlib import Path

import pytest

from procs import ROOT, SWARMCOVER, group_alive, pids_with

TINY = (ROOT / "configs" / "tiny.toml").read_text()
MIXED = (ROOT / "configs" / "mixed.toml").read_text()
OFFICE_PGM = ROOT / "configs" / "maps" / "office.pgm"


def _patch(base: str, old: str, new: str) -> str:
    assert old in base, old
    return base.replace(old, new, 1)


def _ros(tmp: Path, yaml_text: str, pgm: bytes | None = None) -> Path:
    (tmp / "m.pgm").write_bytes(pgm if pgm is not None else OFFICE_PGM.read_bytes())
    p = tmp / "m.yaml"
    p.write_text(yaml_text)
    return p


def _yaml_only(tmp: Path, yaml_text: str) -> Path:
    p = tmp / "m.yaml"
    p.write_text(yaml_text)
    return p


YAML = "image: m.pgm\nresolution: {res}\norigin: [0.0, 0.0, 0.0]\n{extra}"

# (row id, how to make the config, extra flags, needles the one line must hold)
# make: a TOML text, or a function tmp_path -> config path.
ROWS = [
    # ---- sections and fields
    ("unknown section", TINY + "\n[coordinater]\nrobots_max = 5\n", [], ["[coordinater]", "unknown section"]),
    ("unknown top-level field", "speed = 3\n" + TINY, [], ["speed = 3", "unknown top-level field"]),
    ("agent typo", TINY + '\n[agent]\nkp = "fast"\n', [], ["[agent] kp = 'fast'", "unknown field"]),
    ("agent wrong type", TINY + '\n[agent]\ng0 = "fast"\n', [], ["[agent] g0 = 'fast'"]),
    ("agent nan", TINY + "\n[agent]\ng0 = nan\n", [], ["[agent] g0 = nan", "not finite"]),
    ("agent int as float", TINY + "\n[agent]\nhold_window = 2.5\n", [], ["[agent] hold_window = 2.5"]),
    ("agent owns not v_max", TINY + "\n[agent]\nv_max = 1.0\n", [], ["[agent] v_max = 1.0", "[robots]"]),
    ("agent out of range", TINY + "\n[agent]\nerror_alpha = 3.0\n", [], ["[agent] error_alpha = 3.0"]),
    ("coordinator nan", TINY + "\n[coordinator]\nsettle_s = nan\n", [], ["[coordinator] settle_s = nan", "not finite"]),
    ("coordinator inf", TINY + "\n[coordinator]\ntask_timeout_s = inf\n", [], ["[coordinator] task_timeout_s = inf"]),
    ("coordinator -inf", TINY + "\n[coordinator]\nw_obstacle = -inf\n", [], ["[coordinator] w_obstacle = -inf"]),
    ("coordinator eps", TINY + "\n[coordinator]\neps_rv = 1.5\n", [], ["[coordinator] eps_rv = 1.5"]),
    ("coordinator robots_max", TINY + "\n[coordinator]\nrobots_max = 0\n", [], ["[coordinator] robots_max = 0"]),
    ("coordinator push_mode", TINY + '\n[coordinator]\npush_mode = "fast"\n', [], ["[coordinator] push_mode = 'fast'"]),
    ("coordinator type", TINY + '\n[coordinator]\nmax_paths = "2"\n', [], ["[coordinator] max_paths = '2'"]),
    ("coordinator unknown", TINY + "\n[coordinator]\nrobot_max = 9\n", [], ["[coordinator] robot_max = 9", "unknown field"]),
    ("coordinator negative", TINY + "\n[coordinator]\nbeta_deg = -1.0\n", [], ["[coordinator] beta_deg = -1.0"]),
    ("rv nan", _patch(TINY, "rv = 1.0", "rv = nan"), [], ["rv = nan"]),
    ("rv inf", _patch(TINY, "rv = 1.0", "rv = inf"), [], ["rv = inf"]),
    ("rv zero", _patch(TINY, "rv = 1.0", "rv = 0.0"), [], ["rv = 0.0"]),
    ("world dt nan", _patch(TINY, "dt = 0.05", "dt = nan"), [], ["[world] dt = nan"]),
    ("world typo", _patch(TINY, "dt = 0.05", "dtt = 0.05"), [], ["[world] dtt = 0.05", "unknown field"]),
    ("world seed", _patch(TINY, "seed = 0", "seed = -1"), [], ["[world] seed = -1"]),
    ("world mode", _patch(TINY, 'mode = "lockstep"', 'mode = "fast"'), [], ["[world] mode = 'fast'"]),
    ("robots v_max inf", _patch(TINY, "v_max = 0.5", "v_max = inf"), [], ["[robots] v_max = inf"]),
    ("robots kind", _patch(TINY, 'kind = "holonomic"', 'kind = "tank"'), [], ["[robots] kind = 'tank'"]),
    ("sensing nan", _patch(TINY, "noise_deg = 0.5", "noise_deg = nan"), [], ["[sensing] noise_deg = nan"]),
    ("hwbridge nan", _patch(MIXED, "kp = 3.0", "kp = nan"), [], ["[hwbridge] kp = nan"]),
    ("hwbridge source", _patch(MIXED, "fake = true", "fake = true\nsource = 3"), [],
     ["[hwbridge.robots[0]] source = 3", "only 1 source"]),
    ("hwbridge unknown", _patch(MIXED, "kp = 3.0", "kpp = 3.0"), [], ["[hwbridge] kpp = 3.0", "unknown field"]),
    ("not TOML", "rv = [1\n", [], ["not valid TOML"]),
    ("no map", "rv = 1.0\n", [], ["[map]", "missing"]),
    # ---- geometry
    ("self-crossing boundary", _patch(TINY, "[[0, 0], [3, 0], [3, 2], [0, 2]]", "[[0, 0], [3, 2], [3, 0], [0, 1.5]]"),
     [], ["[map] boundary", "not a simple polygon"]),
    ("self-crossing obstacle", _patch(TINY, "sources = ", 'obstacles = [{type = "polygon", points = '
                                      "[[1, 0.5], [2, 1.5], [2, 0.5], [1, 1.2]]}]\nsources = "),
     [], ["[map] obstacles[0].points", "not a simple polygon"]),
    ("zero-area boundary", _patch(TINY, "[[0, 0], [3, 0], [3, 2], [0, 2]]", "[[0, 0], [1, 1], [2, 2]]"),
     [], ["[map] boundary = [[0, 0], [1, 1], [2, 2]]"]),
    ("huge map", _patch(TINY, "[[0, 0], [3, 0], [3, 2], [0, 2]]", "[[0, 0], [1e6, 0], [1e6, 1e6], [0, 1e6]]"),
     [], ["[map] boundary", "limit of 2000 rv"]),
    ("wide map", _patch(TINY, "[[0, 0], [3, 0], [3, 2], [0, 2]]", "[[0, 0], [1000, 0], [1000, 100], [0, 100]]"),
     [], ["[map] boundary", "limit of 40000 rv^2"]),
    ("spawn in a wall", TINY + "spawn = [{robot = 0, pose = [5.0, 1.0]}]\n", [],
     ["[world] spawn[0].pose = [5.0, 1.0, 0.0]", "not in free space"]),
    ("robot does not fit", _patch(TINY, "radius = 0.06", "radius = 0.5"), [],
     ["[map] sources[0] = [0.3, 1.0, 0.0]", "radius 0.5 m does not fit"]),
    ("source outside", _patch(TINY, "x = 0.3, y = 1.0", "x = 5.0, y = 1.0"), [], ["[map] sources[0]", "not in free space"]),
    # ---- ROS maps
    ("ros resolution huge", lambda t: _ros(t, YAML.format(res=100000, extra="")), [],
     ["[ros_map] resolution = 100000", "limit"]),
    ("ros resolution nan", lambda t: _ros(t, YAML.format(res=".nan", extra="")), [], ["[ros_map] resolution = nan"]),
    ("ros decompression bomb", lambda t: _ros(t, YAML.format(res=0.05, extra=""),
                                              b"P5\n20000 20000\n255\n" + bytes(1000)), [],
     ["[ros_map] image", "limit"]),
    ("ros image missing", lambda t: _yaml_only(t, YAML.format(res=0.05, extra="")), [],
     ["[ros_map] image = 'm.pgm'", "not found"]),
    ("ros image garbage", lambda t: _ros(t, YAML.format(res=0.05, extra=""), b"not an image"), [],
     ["[ros_map] image = ", "cannot read image"]),
    ("ros mode", lambda t: _ros(t, YAML.format(res=0.05, extra="mode: fancy\n")), [], ["[ros_map] mode = 'fancy'"]),
    ("ros origin", lambda t: _ros(t, "image: m.pgm\nresolution: 0.05\norigin: [a, b]\n"), [], ["[ros_map] origin"]),
    ("missing config", lambda t: t / "nope.toml", [], ["nope.toml", "file not found"]),
    # ---- flags
    ("wall-timeout nan", TINY, ["--wall-timeout", "nan"], ["--wall-timeout = nan", "not finite"]),
    ("wall-timeout inf", TINY, ["--wall-timeout", "inf"], ["--wall-timeout = inf"]),
    ("wall-timeout negative", TINY, ["--wall-timeout", "-1"], ["--wall-timeout = -1.0"]),
    ("wall-timeout word", TINY, ["--wall-timeout", "soon"], ["--wall-timeout", "'soon'"]),
    ("robots-max zero", TINY, ["--robots-max", "0"], ["--robots-max = 0"]),
    ("robots-max negative", TINY, ["--robots-max", "-5"], ["--robots-max = -5"]),
    ("seed negative", TINY, ["--seed", "-1"], ["--seed = -1"]),
    ("swarm slash", TINY, ["--swarm", "a/b"], ["--swarm = 'a/b'"]),
    ("swarm empty", TINY, ["--swarm", ""], ["--swarm = ''"]),
    ("port too big", TINY, ["--port", "99999"], ["--port = 99999"]),
    ("port negative", TINY, ["--port", "-1"], ["--port = -1"]),
    ("port busy", TINY, ["--port", "{busy}"], ["--port = {busy}", "in use", "tcp/127.0.0.1:{busy}"]),
    ("view-port too big", TINY, ["--view", "--view-port", "70000"], ["--view-port = 70000"]),
    ("router nonsense", TINY, ["--router", "localhost"], ["--router = 'localhost'"]),
    ("router bad port", TINY, ["--router", "tcp/127.0.0.1:99999"], ["--router = 'tcp/127.0.0.1:99999'"]),
    ("router not listening", TINY, ["--router", "tcp/127.0.0.1:{closed}"],
     ["--router = 'tcp/127.0.0.1:{closed}'", "no router answers"]),
    ("out is a file", TINY, ["--out", "{tmp}/afile"], ["--out = '{tmp}/afile'", "cannot write"]),
    ("out under a file", TINY, ["--out", "{tmp}/afile/run"], ["--out = '{tmp}/afile/run'", "cannot write"]),
    ("out in /proc", TINY, ["--out", "/proc/swarmcover-run"], ["--out = '/proc/swarmcover-run'", "cannot write"]),
    ("log level", TINY, ["--log-level", "LOUD"], ["--log-level = 'LOUD'"]),
    ("secure empty", TINY, ["--secure", "{tmp}"], ["--secure = '{tmp}'", "incomplete profile"]),
    ("secure missing", TINY, ["--secure", "{tmp}/no-such-dir"], ["--secure = '{tmp}/no-such-dir'"]),
]
ARGPARSE_ROWS = {"wall-timeout word"}
# a bound, not a speed test: each row is done in the time Python takes to import the CLI
TIMEOUT_S = float(os.environ.get("SWARMCOVER_BAD_INPUT_TIMEOUT_S", "60"))


def _config(tmp_path: Path, make) -> Path:
    if callable(make):
        return make(tmp_path)
    p = tmp_path / "bad.toml"
    p.write_text(make)
    return p


def prepare(tmp: Path, make: str, flags) -> tuple[socket.socket, dict, list[str]]:
    """The stage for one row in the folder ``tmp``: a file where a folder is expected, a busy
    port (the returned socket: close it) and a closed one. Returns (busy socket, the
    substitutions for the row's flags and needles, the ``swarmcover run`` argv)."""
    (tmp / "afile").write_text("a file, not a folder")
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    try:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            closed = s.getsockname()[1]          # a port nobody listens on
        subs = dict(tmp=str(tmp), busy=str(busy.getsockname()[1]), closed=str(closed))
        flags = [f.format(**subs) for f in flags]
        if "--out" not in flags:
            flags += ["--out", str(tmp / "run")]
        argv = SWARMCOVER + ["run", str(_config(tmp, make)), "--quiet", "--wall-timeout",
                             "15"] + flags
    except BaseException:
        busy.close()
        raise
    return busy, subs, argv


@pytest.mark.parametrize("row", ROWS, ids=[r[0] for r in ROWS])
def test_bad_input_exits_2_naming_the_field(tmp_path, row):
    name, make, flags, needles = row
    busy, subs, argv = prepare(tmp_path, make, flags)
    try:
        p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             cwd=str(ROOT), start_new_session=True)
        try:
            out, _ = p.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            _reap(p, tmp_path)
            out, _ = p.communicate(timeout=5)
            out += f"\n<still running after {TIMEOUT_S:g} s>"
        finally:
            _reap(p, tmp_path)
    finally:
        busy.close()
    lines = [ln for ln in out.splitlines() if ln.strip()]
    assert p.returncode == 2, f"{name}: exit {p.returncode}\n{out}"
    assert "Traceback" not in out, out
    for n in needles:
        assert n.format(**subs) in out, f"{name}: {n.format(**subs)!r} not in:\n{out}"
    if name not in ARGPARSE_ROWS:      # argparse's own errors come with a usage line
        assert len(lines) == 1, f"{name}: expected one line:\n{out}"
    # nothing started: no run folder with logs, no process of ours left
    assert not (tmp_path / "run" / "logs").exists()
    assert not group_alive(p.pid)
    assert pids_with(str(tmp_path)) == []


def _reap(p: subprocess.Popen, tmp_path: Path) -> None:
    if p.poll() is None:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        p.wait(5)
    for pid in pids_with(str(tmp_path)):      # children of a run that should not have started
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
