#!/usr/bin/env python3
"""Water cells a map misses, by their distance to the nearest dry truth cell.

Scores each map cell (`MAPDIR/map.ply`) against the truth cell holding its centre
(`SIMDIR/truth.ply`, `truth.json`), as `tarn eval` does, keeps the true water cells within
`--band LO,HI` metres of the vehicle's path, and prints their recall by distance to the
nearest dry truth cell: at the map's 0.1 m resolution, 0.10–0.14 m means a dry cell among
the 8 neighbours (the water's edge).

    .venv/bin/python tools/edge_misses.py SIMDIR MAPDIR [--band 5,30]
"""
import argparse
import json

import numpy as np
from plyfile import PlyData

ap = argparse.ArgumentParser()
ap.add_argument("sim")
ap.add_argument("map")
ap.add_argument("--band", default="5,30")
a = ap.parse_args()
lo, hi = map(float, a.band.split(","))
info = json.load(open(f"{a.sim}/truth.json"))
res = info["resolution"]
path = np.array([[p["x"], p["y"]] for p in info["trajectory"]])
t = PlyData.read(f"{a.sim}/truth.ply")["vertex"].data
m = PlyData.read(f"{a.map}/map.ply")["vertex"].data
WATER = 2
key = {(int(np.floor(x / res)), int(np.floor(y / res))): i for i, (x, y) in enumerate(zip(t["x"], t["y"]))}
wet = t["class"] == WATER
dry = np.stack([t["x"][~wet], t["y"][~wet]], 1)


def to_path(x, y):
    a0, ab = path[:-1], path[1:] - path[:-1]
    s = np.clip(((np.array([x, y]) - a0) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
    return np.sqrt(((a0 + ab * s[:, None] - [x, y]) ** 2).sum(1)).min()


rows = []
for c in m:
    i = key.get((int(np.floor(c["x"] / res)), int(np.floor(c["y"] / res))))
    if i is None or not wet[i] or not lo <= to_path(c["x"], c["y"]) < hi:
        continue
    d = np.sqrt(((dry - [c["x"], c["y"]]) ** 2).sum(1)).min()
    rows.append((d, c["class"] == WATER))
r = np.array(rows)
print(f"true water cells {lo:g}-{hi:g} m from the path: {len(r)}, recall {r[:, 1].mean():.3f}")
print("| distance to a dry truth cell (m) | water cells | missed | recall |")
print("| --- | ---: | ---: | ---: |")
for a0, b0 in [(0, 0.15), (0.15, 0.25), (0.25, 0.35), (0.35, 0.5), (0.5, 1), (1, 1e9)]:
    s = (r[:, 0] >= a0) & (r[:, 0] < b0)
    n = int(s.sum())
    if n:
        print(f"| {a0:g}–{b0:g} | {n} | {int(n - r[s, 1].sum())} | {r[s, 1].mean():.3f} |")
