"""A 24 m x 14 m office floor as a ROS map (bench/configs/maps/office_floor.*): a 1.6 m
corridor down the middle, six rooms on each side behind doors 0.4-1.2 m wide, some rooms
joined to their neighbour by a second door, desks inside. Walls 0.1 m thick.
Usage: python make_office.py SEED OUT_STEM  (writes OUT_STEM.pgm/.yaml; seed 0 is the one
stored)."""
import sys

import numpy as np

from swarmcover.world.maps import write_ros_map

seed = int(sys.argv[1]); out = sys.argv[2]
rng = np.random.default_rng(seed)
res, W, H = 0.05, 24.0, 14.0
t = 0.1                                  # wall thickness, m
nx, ny = int(W / res), int(H / res)
yy, xx = (np.mgrid[0:ny, 0:nx] + 0.5) * res
free = np.zeros((ny, nx), bool)


def box(x0, y0, x1, y1, val):
    free[(xx >= x0) & (xx < x1) & (yy >= y0) & (yy < y1)] = val


box(0.2, 0.2, W - 0.2, H - 0.2, True)
cy0, cy1 = 6.2, 7.8                      # the corridor
box(0.2, cy0 - t, W - 0.2, cy0, False)
box(0.2, cy1, W - 0.2, cy1 + t, False)
xs = np.linspace(0.2, W - 0.2, 7)
doors = []
for side in (0, 1):                      # rooms below, then above the corridor
    for i in range(6):
        x0, x1 = xs[i], xs[i + 1]
        if i > 0:                        # the wall to the room before, maybe with a door
            box(x0 - t / 2, 0.2 if side == 0 else cy1, x0 + t / 2, cy0 if side == 0 else H - 0.2, False)
            if rng.random() < 0.3:
                w = rng.uniform(0.4, 1.0); yc = rng.uniform(1.5, 4.5) + (0 if side == 0 else cy1 - 0.2)
                box(x0 - t, yc - w / 2, x0 + t, yc + w / 2, True)
        w = float(rng.choice([0.4, 0.6, 0.8, 1.2]))    # the door to the corridor
        xc = rng.uniform(x0 + 0.4 + w / 2, x1 - 0.4 - w / 2)
        doors.append(round(w, 2))
        if side == 0:
            box(xc - w / 2, cy0 - t - 0.01, xc + w / 2, cy0 + 0.01, True)
        else:
            box(xc - w / 2, cy1 - 0.01, xc + w / 2, cy1 + t + 0.01, True)
        for _ in range(rng.integers(0, 3)):              # desks, off the door's wall
            dw, dh = rng.uniform(0.8, 1.6), rng.uniform(0.5, 0.8)
            if rng.random() < 0.5:
                dw, dh = dh, dw
            ylo, yhi = (0.9, cy0 - 1.2) if side == 0 else (cy1 + 1.2, H - 0.9)
            dx = rng.uniform(x0 + 0.8, x1 - 0.8 - dw); dy = rng.uniform(ylo, yhi - dh)
            box(dx, dy, dx + dw, dy + dh, False)
write_ros_map(out, free, res)
print("free area m2", round(free.sum() * res * res, 1), "doors to the corridor (m)", doors)
