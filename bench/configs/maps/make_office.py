"""Office floors as ROS maps: a corridor down the middle, rooms on each side behind doors,
some rooms joined to their neighbour by a second door, desks inside. Walls 0.1 m thick.

    python make_office.py SEED OUT_STEM            # the 24 m x 14 m floor: 1.6 m corridor,
                                                   # 6 rooms a side, doors 0.4-1.2 m
                                                   # (seed 0 is office_floor.pgm/.yaml)
    python make_office.py --small SEED OUT_DIR     # a small floor with narrow doors, and its
                                                   # run config: OUT_DIR/office_sSEED.toml

The small floors (``--small``): 2-4 rooms a side, 3.0-4.2 m wide and 2.4-3.6 m deep, a
1.2-1.8 m corridor, doors to the corridor 0.3-0.6 m (0.3-0.6 rv at rv = 1 m), side doors
0.3-0.8 m, 0-2 desks a room; one source at the corridor's west end; 0.5 deg bearing noise;
47-82 m^2 of free area, 88-149 robots by the Euler bound (seeds 0-5).
"""
import sys
from pathlib import Path

import numpy as np

from swarmcover.world.maps import write_ros_map

RES = 0.05     # m per cell
T = 0.1        # wall thickness, m


def floor(rng, W: float, H: float, cy0: float, cy1: float, n: int, *, door_widths,
          side_door=(0.4, 1.0), side_door_y=None, desk=((0.8, 1.6), (0.5, 0.8)),
          desk_margin=(0.8, 0.9, 1.2)):
    """Free mask (rows = y) of a W x H floor, corridor between y = cy0 and cy1, ``n``
    rooms a side; returns (free, widths of the doors to the corridor). ``side_door_y(side,
    w)`` draws a side door's centre (default: the 24 m floor's); ``desk_margin``: a desk's
    least distance (m) to the room's side walls, outer wall, corridor wall."""
    nx, ny = int(W / RES), int(H / RES)
    yy, xx = (np.mgrid[0:ny, 0:nx] + 0.5) * RES
    free = np.zeros((ny, nx), bool)

    def box(x0, y0, x1, y1, val):
        free[(xx >= x0) & (xx < x1) & (yy >= y0) & (yy < y1)] = val

    if side_door_y is None:
        def side_door_y(side, w):
            return rng.uniform(1.5, 4.5) + (0 if side == 0 else cy1 - 0.2)
    box(0.2, 0.2, W - 0.2, H - 0.2, True)
    box(0.2, cy0 - T, W - 0.2, cy0, False)
    box(0.2, cy1, W - 0.2, cy1 + T, False)
    xs = np.linspace(0.2, W - 0.2, n + 1)
    mx, mo, mc = desk_margin
    doors = []
    for side in (0, 1):                      # rooms below, then above the corridor
        for i in range(n):
            x0, x1 = xs[i], xs[i + 1]
            if i > 0:                        # the wall to the room before, maybe with a door
                box(x0 - T / 2, 0.2 if side == 0 else cy1, x0 + T / 2,
                    cy0 if side == 0 else H - 0.2, False)
                if rng.random() < 0.3:
                    w = rng.uniform(*side_door)
                    yc = side_door_y(side, w)
                    box(x0 - T, yc - w / 2, x0 + T, yc + w / 2, True)
            w = float(rng.choice(door_widths))    # the door to the corridor
            xc = rng.uniform(x0 + 0.4 + w / 2, x1 - 0.4 - w / 2)
            doors.append(round(w, 2))
            if side == 0:
                box(xc - w / 2, cy0 - T - 0.01, xc + w / 2, cy0 + 0.01, True)
            else:
                box(xc - w / 2, cy1 - 0.01, xc + w / 2, cy1 + T + 0.01, True)
            for _ in range(rng.integers(0, 3)):              # desks, off the door's wall
                dw, dh = rng.uniform(*desk[0]), rng.uniform(*desk[1])
                if rng.random() < 0.5:
                    dw, dh = dh, dw
                ylo, yhi = (mo, cy0 - mc) if side == 0 else (cy1 + mc, H - mo)
                if yhi - dh <= ylo or x1 - mx - dw <= x0 + mx:
                    continue                 # no room for it (small floors only)
                dx = rng.uniform(x0 + mx, x1 - mx - dw); dy = rng.uniform(ylo, yhi - dh)
                box(dx, dy, dx + dw, dy + dh, False)
    return free, doors


def large(seed: int, out: str) -> None:
    free, doors = floor(np.random.default_rng(seed), 24.0, 14.0, 6.2, 7.8, 6,
                        door_widths=[0.4, 0.6, 0.8, 1.2])
    write_ros_map(out, free, RES)
    print("free area m2", round(free.sum() * RES * RES, 1), "doors to the corridor (m)", doors)


def small(seed: int, outdir: Path) -> None:
    rng = np.random.default_rng(1000 + seed)
    n = int(rng.integers(2, 5))                 # rooms a side
    W = round(float(n * rng.uniform(3.0, 4.2)) + 0.4, 2)
    rh = float(rng.uniform(2.4, 3.6))           # room depth
    cw = float(rng.uniform(1.2, 1.8))           # corridor width
    H = round(2 * rh + cw + 0.4, 2)
    cy0 = 0.2 + rh
    cy1 = cy0 + cw

    def side_door_y(side, w):
        return rng.uniform(0.6 + w / 2, rh - 0.4 - w / 2) + (0.2 if side == 0 else cy1 + 0.1)

    free, doors = floor(rng, W, H, cy0, cy1, n, door_widths=[0.3, 0.35, 0.4, 0.5, 0.6],
                        side_door=(0.3, 0.8), side_door_y=side_door_y,
                        desk=((0.6, 1.2), (0.4, 0.7)), desk_margin=(0.7, 0.9, 1.0))
    outdir.mkdir(parents=True, exist_ok=True)
    name = f"office_s{seed}"
    write_ros_map(outdir / name, free, RES)
    (outdir / f"{name}.toml").write_text(f"""# bench/configs/maps/make_office.py --small {seed}
name = "{name}"
rv = 1.0

[map]
ros_map = "{name}.yaml"
sources = [{{x = 0.6, y = {(cy0 + cy1) / 2:.2f}, theta = 0.0}}]

[robots]
radius = 0.06
kind = "holonomic"

[sensing]
noise_deg = 0.5

[world]
dt = 0.05
mode = "lockstep"
seed = {seed}
""")
    print(name, "W", W, "H", H, "rooms a side", n,
          "free area m2", round(free.sum() * RES * RES, 1), "doors to the corridor (m)", doors)


if __name__ == "__main__":
    if sys.argv[1] == "--small":
        small(int(sys.argv[2]), Path(sys.argv[3]))
    else:
        large(int(sys.argv[1]), sys.argv[2])
