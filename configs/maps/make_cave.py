"""Cave-like ROS map (configs/maps/cave.*): chambers joined by winding tunnels 0.9-1.3 m
wide, a few rocks. Usage: python make_cave.py SEED OUT_STEM  (writes OUT_STEM.pgm/.yaml)."""
import sys
import numpy as np
from scipy import ndimage
from swarmcover.world.maps import write_ros_map
seed = int(sys.argv[1]); out = sys.argv[2]
rng = np.random.default_rng(seed)
res, W, H = 0.05, 12.0, 9.0
nx, ny = int(W / res), int(H / res)
yy, xx = (np.mgrid[0:ny, 0:nx] + 0.5) * res
free = np.zeros((ny, nx), bool)
centres = [np.array([1.8, 1.8])]
while len(centres) < 5:
    c = rng.uniform([1.8, 1.8], [W - 1.8, H - 1.8])
    if min(np.linalg.norm(c - q) for q in centres) > 3.2:
        centres.append(c)
for c in centres:  # chambers: a few overlapping discs
    for _ in range(3):
        q = c + rng.normal(0, 0.4, 2); r = rng.uniform(0.9, 1.5)
        free |= (xx - q[0]) ** 2 + (yy - q[1]) ** 2 < r * r
order = [0]
left = list(range(1, len(centres)))
while left:  # a tree of tunnels, nearest chamber first
    a, b = min(((a, b) for a in order for b in left), key=lambda ab: np.linalg.norm(centres[ab[0]] - centres[ab[1]]))
    p, q = centres[a], centres[b]
    n = int(np.linalg.norm(q - p) / 0.2)
    side = np.array([-(q - p)[1], (q - p)[0]]) / np.linalg.norm(q - p)
    wig = rng.uniform(-0.8, 0.8)
    for t in np.linspace(0, 1, n):
        m = p + t * (q - p) + side * wig * np.sin(np.pi * t)
        r = rng.uniform(0.45, 0.65)
        free |= (xx - m[0]) ** 2 + (yy - m[1]) ** 2 < r * r
    order.append(b); left.remove(b)
for _ in range(4):  # rocks inside chambers
    c = centres[rng.integers(1, len(centres))] + rng.normal(0, 0.5, 2)
    r = rng.uniform(0.15, 0.3)
    free &= ~((xx - c[0]) ** 2 + (yy - c[1]) ** 2 < r * r)
free[:4, :] = free[-4:, :] = False
free[:, :4] = free[:, -4:] = False
lab, _ = ndimage.label(free)
free = lab == lab[int(1.8 / res), int(1.8 / res)]
write_ros_map(out, free, res)
print("free area m2", round(free.sum() * res * res, 1))
