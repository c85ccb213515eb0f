"""Where a run's simulated time goes (issue 19: time per robot against the 5 s target).

Runs each config in-process (swarmcover.simloop, the same nodes as ``swarmcover run``) and
reads the bus only: the coordinator's Task messages (what each robot was asked to do: a
plain test drive, a probe (``via_distance`` > 0), a wall sweep (``sweep_side`` != 0), a
goto, a deploy) and the agents' Status messages (``state``: moving, deploying,
test_driving; how each task ended). Every tick of simulated time is booked to one class:

* ``moves``: some robot moves, deploys or leaves (a push under way; test drives may run
  beside it);
* ``sweeps``: no push moves, and a wall sweep runs (agents/sweep.py);
* ``drives``: no push moves, and only plain test drives and probes run (with their
  return home): the pushes wait for them (spec 3.4(iv));
* ``still``: nobody moves (the cycle barrier, planning, a new robot joining).

Per drive class it counts the drives, how they ended (``touch``: failed on a touch and
came back; ``clear``: done, the robot stayed or went home; ``other`` failures) and their
mean duration, task sent to task over.

    python bench/simtime.py                                  # every config, seed 0
    python bench/simtime.py configs/small.toml --seeds 0 1   # prints a table, then JSON
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.common import run_configs  # noqa: E402

CLASSES = ("moves", "sweeps", "drives", "still")
DRIVES = ("drive", "probe", "sweep")
_MOVING = {"moving", "deploying", "leaving"}


def _drive_kind(task) -> str:
    if task.sweep_side:
        return "sweep"
    return "probe" if task.via_distance > 0 else "drive"


def run(config: str, seed: int, timeout: float) -> dict:
    from swarmcover.bus.messages import Task
    from swarmcover.coordinator.actions import SendTask
    from swarmcover.run import default_robots_max
    from swarmcover.simloop import SimLoop
    from swarmcover.world.config import load_config
    from swarmcover.world.maps import build_map

    cfg = load_config(config)
    cfg, _, _ = default_robots_max(cfg, build_map(cfg), "")
    sim = SimLoop(cfg, seed=seed)
    state: dict[int, str] = {}                  # robot -> last Status.state
    drive_of: dict[int, tuple[str, float, int]] = {}  # robot -> its test drive (kind, sent at, id)
    drives = {k: {"n": 0, "touch": 0, "clear": 0, "other": 0, "s": 0.0} for k in DRIVES}
    booked = dict.fromkeys(CLASSES, 0.0)

    apply = sim._apply

    def on_actions(actions):
        for a in actions:
            if isinstance(a, SendTask) and isinstance(a.task, Task):
                if a.task.kind == "test_drive":
                    drive_of[a.robot] = (_drive_kind(a.task), sim.t, a.task.task_id)
                else:
                    drive_of.pop(a.robot, None)
        return apply(actions)

    sim._apply = on_actions
    sync = sim.coord.sync
    add_status = sync.add_status

    def on_status(st):
        state[st.robot] = st.state
        if (st.robot in drive_of and st.task_state in ("done", "failed")
                and st.task_id == drive_of[st.robot][2]):     # not a repeat of the last task's
            kind, t0, _ = drive_of.pop(st.robot)
            d = drives[kind]
            d["n"] += 1
            d["s"] += sim.t - t0
            d["clear" if st.task_state == "done" else
              "touch" if st.reason.startswith(("touch", "swept")) else "other"] += 1
        return add_status(st)

    sync.add_status = on_status
    t_wall = time.monotonic()
    while True:
        done = sim.step()
        live = set(sim.agents)
        busy = [r for r in live if state.get(r) in _MOVING]
        driving = [drive_of[r][0] for r in live if state.get(r) == "test_driving" and r in drive_of]
        cls = ("moves" if busy else "sweeps" if "sweep" in driving
               else "drives" if driving else "still")
        booked[cls] += sim.dt
        if done or time.monotonic() - t_wall > timeout or sim.t > 20000.0:
            break
    robots = len([r for r in sim.complexes[-1].occupants if r >= 0]) if sim.complexes else 0
    total = sum(booked.values())
    return {
        "name": cfg.name, "seed": seed, "certified": bool(sim.dep.certified),
        "robots": robots, "cycles": int(sim.dep.cycle), "sim_s": round(total, 1),
        "sim_s_per_robot": round(total / max(robots, 1), 2),
        "share": {k: round(v / max(total, 1e-9), 3) for k, v in booked.items()},
        "sim_s_by_class": {k: round(v, 1) for k, v in booked.items()},
        "drives": {k: {**d, "mean_s": round(d["s"] / d["n"], 2) if d["n"] else None,
                       "s": round(d["s"], 1)} for k, d in drives.items()},
        "wall_s": round(time.monotonic() - t_wall, 1),
    }


def main(argv=None) -> int:
    runs = run_configs(__doc__.split("\n\n")[0], run, argv)
    print("| config | seed | robots | cycles | sim s (per robot) | moves / sweeps / drives / still "
          "| drives: n, touch, mean s | probes: n, touch, mean s | sweeps: n, touch, mean s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in runs:
        sh = r["share"]
        cells = [f"{d['n']}, {d['touch']}, {d['mean_s']}" for d in (r["drives"][k] for k in DRIVES)]
        print(f"| {r['name']} | {r['seed']} | {r['robots']} | {r['cycles']} | {r['sim_s']} "
              f"({r['sim_s_per_robot']}) | " + " / ".join(f"{100 * sh[k]:.0f}%" for k in CLASSES)
              + " | " + " | ".join(cells) + " |")
    print(json.dumps({"bench": "simtime", "runs": runs}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
