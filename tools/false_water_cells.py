#!/usr/bin/env python3
"""Where a simulated map calls dry ground water: the false-water cells of MAP_DIR/map.ply
against the simulator's truth (TRUTH_DIR/truth.ply, truth.json), by range band from the
vehicle's path, with the scorer's rules (`tarn eval`): a dry cell is one more than 0.5 m
from any true water cell, and it is called water when its class is water.

Usage: tools/false_water_cells.py MAP_DIR TRUTH_DIR [--cells]
Prints per band (5-10, 10-20, 20-30 m) the dry cells, the false ones and their share, the
bounding box of the false cells, their water probabilities (quartiles) and, with --cells,
each false cell: position, map and true elevation, and its distance to the nearest water.
Needs numpy."""
import json
import sys

import numpy as np

RES_DT = np.dtype([('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('s', '<f4'), ('w', '<f4'),
                   ('d', '<f4'), ('c', 'u1'), ('h', 'u1'), ('r', 'u1'), ('g', 'u1'), ('b', 'u1')])
WATER = 2


def read_ply(path):
    data = open(path, 'rb').read()
    start = data.index(b'end_header\n') + len(b'end_header\n')
    return np.frombuffer(data[start:], dtype=RES_DT)


def main():
    args = [a for a in sys.argv[1:] if not a.startswith('--')]
    if len(args) != 2:
        sys.exit(__doc__)
    map_dir, truth_dir = args
    m, t = read_ply(f'{map_dir}/map.ply'), read_ply(f'{truth_dir}/truth.ply')
    truth = json.load(open(f'{truth_dir}/truth.json'))
    res = truth['resolution']
    path = np.array([[p['x'], p['y']] for p in truth['trajectory']])
    ix = lambda a: np.floor(a['x'] / res).astype(int)
    iy = lambda a: np.floor(a['y'] / res).astype(int)
    tx, ty = ix(t), iy(t)
    ox, oy = tx.min() - 10, ty.min() - 10
    shape = (tx.max() - ox + 11, ty.max() - oy + 11)
    water = np.zeros(shape, bool)
    water[tx[t['c'] == WATER] - ox, ty[t['c'] == WATER] - oy] = True
    true_z = np.full(shape, np.nan)
    true_z[tx - ox, ty - oy] = t['z']
    known = np.zeros(shape, bool)
    known[tx - ox, ty - oy] = True
    # Within 0.5 m of water: a disc of 0.5 m around every water cell.
    r = int(round(0.5 / res))
    near = water.copy()
    for dx in range(-r, r + 1):
        for dy in range(-r, r + 1):
            if dx * dx + dy * dy <= r * r:
                near |= np.roll(np.roll(water, dx, 0), dy, 1)
    mx, my = ix(m) - ox, iy(m) - oy
    inside = (mx >= 0) & (my >= 0) & (mx < shape[0]) & (my < shape[1])
    near_water = np.ones(len(m), bool)
    near_water[inside] = near[mx[inside], my[inside]]
    # Cells the truth does not cover are not scored.
    inside[inside] = known[mx[inside], my[inside]]
    d_path = np.full(len(m), np.inf)
    for px, py in path:
        d_path = np.minimum(d_path, np.hypot(m['x'] - px, m['y'] - py))
    wet = np.argwhere(water) * res
    for lo, hi in [(5, 10), (10, 20), (20, 30)]:
        dry = (d_path >= lo) & (d_path < hi) & ~near_water & inside
        false = np.where(dry & (m['c'] == WATER))[0]
        print(f'{lo}-{hi} m: {dry.sum()} dry cells, {len(false)} called water '
              f'({100 * len(false) / max(1, dry.sum()):.2f} %)')
        if not len(false):
            continue
        print(f'  x {m["x"][false].min():.1f}..{m["x"][false].max():.1f} m, '
              f'y {m["y"][false].min():.1f}..{m["y"][false].max():.1f} m; water p quartiles '
              f'{np.round(np.percentile(m["w"][false], [0, 25, 50, 75, 100]), 2).tolist()}')
        if '--cells' in sys.argv:
            for i in false:
                d = np.hypot(wet[:, 0] + ox * res - m['x'][i], wet[:, 1] + oy * res - m['y'][i])
                print(f'  x {m["x"][i]:.2f} y {m["y"][i]:.2f}  water {m["w"][i]:.2f}  z map '
                      f'{m["z"][i]:.3f} true {true_z[mx[i], my[i]]:.3f}  to water '
                      f'{d.min() if len(d) else float("nan"):.2f} m')


if __name__ == '__main__':
    main()
