#!/usr/bin/env python3
"""Where a map's published elevation σ misses: its dry ground cells in a range band from the
vehicle's path, against the simulator's truth, broken down by σ and by the error's sign.

    .venv/bin/python tools/sigma_tails.py SIM_DIR MAP_DIR LO HI [LIDAR_MAP_DIR]

SIM_DIR is what `tarn simulate` wrote (truth.ply, truth.json), MAP_DIR what `tarn build`
wrote (map.ply). A cell counts when the truth calls it ground and the map neither calls it
water nor lacks a σ, as `tarn eval` counts `terrain_within_sigma`. The band is the
distance from the nearest pose of the path.

LIDAR_MAP_DIR, a map of the same log built from its lidar alone (`tarn build LOG --config
lidar.toml --labels none`, lidar.toml holding only `[lidar]`), says of the cells beyond 3σ
how many the lidar observed, and how far its elevation lies from the truth there: what
gating the other points against the lidar could recover.
"""
import json
import sys

import numpy as np

PLY_TYPES = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4", "uint": "<u4"}


def read_ply(path):
    with open(path, "rb") as f:
        n, props = 0, []
        while True:
            line = f.readline().decode().strip()
            if line.startswith("element vertex"):
                n = int(line.split()[2])
            elif line.startswith("property"):
                _, kind, name = line.split()
                props.append((name, PLY_TYPES[kind]))
            elif line == "end_header":
                break
        dt = np.dtype(props)
        return np.frombuffer(f.read(n * dt.itemsize), dtype=dt, count=n)


def main(sim, mapdir, lo, hi, lidar_dir=None):
    truth = read_ply(f"{sim}/truth.ply")
    m = read_ply(f"{mapdir}/map.ply")
    res = json.load(open(f"{sim}/truth.json"))["resolution"]

    def keys(a):
        kx = np.floor(a["x"] / res).astype(np.int64)
        ky = np.floor(a["y"] / res).astype(np.int64)
        return kx * 1_000_003 + ky

    at = dict(zip(keys(truth).tolist(), range(len(truth))))
    idx = np.array([at.get(k, -1) for k in keys(m).tolist()])
    m, t = m[idx >= 0], truth[idx[idx >= 0]]
    s = m["elevation_std"].astype(np.float64)
    keep = (t["class"] == 1) & (m["class"] != 2) & np.isfinite(s) & (s > 0)
    m, t, s = m[keep], t[keep], s[keep]
    path = np.array([[p["x"], p["y"]] for p in json.load(open(f"{sim}/truth.json"))["trajectory"]])
    q = np.c_[m["x"], m["y"]].astype(np.float64)
    d = np.concatenate(
        [np.sqrt(((q[i : i + 10000, None, :] - path[None]) ** 2).sum(-1)).min(1) for i in range(0, len(q), 10000)]
    ) if len(q) else np.zeros(0)
    band = (d >= lo) & (d < hi)
    err = (m["z"] - t["z"]).astype(np.float64)[band]
    s = s[band]
    if len(s) == 0:
        print("no dry cells in the band")
        return
    r = np.abs(err) / s
    out = r > 3
    print(f"{len(s)} dry cells in {lo:g}-{hi:g} m: {100 * np.mean(r <= 1):.1f} % within 1 sigma, "
          f"{100 * np.mean(r <= 3):.1f} % within 3 sigma")
    if out.any():
        print(f"beyond 3 sigma: {out.sum()} cells, map above the truth in {100 * np.mean(err[out] > 0):.0f} %, "
              f"|error| median {np.median(np.abs(err[out])):.3f} m")
    if lidar_dir is not None and out.any():
        lm = read_ply(f"{lidar_dir}/map.ply")
        lat = dict(zip(keys(lm).tolist(), range(len(lm))))
        li = np.array([lat.get(k, -1) for k in keys(m[band][out]).tolist()])
        seen = li >= 0
        print(f"of those, the lidar alone observed {seen.sum()}", end="")
        if seen.any():
            le = (lm["z"][li[seen]] - t["z"][band][out][seen]).astype(np.float64)
            print(f", its |error| there median {np.median(np.abs(le)):.3f} m, "
                  f"within 0.1 m in {100 * np.mean(np.abs(le) < 0.1):.0f} %")
        else:
            print()
    print("| sigma (m) | cells | within 1 sigma | within 3 sigma | RMS error (m) |")
    print("| --- | ---: | ---: | ---: | ---: |")
    edges = [0, 0.002, 0.005, 0.01, 0.03, 0.1, 1.0, np.inf]
    for a, b in zip(edges, edges[1:]):
        k = (s >= a) & (s < b)
        if k.any():
            print(f"| {a:g}–{b:g} | {k.sum()} | {100 * np.mean(r[k] <= 1):.1f} % | "
                  f"{100 * np.mean(r[k] <= 3):.1f} % | {np.sqrt(np.mean(err[k] ** 2)):.3f} |")


if __name__ == "__main__":
    if len(sys.argv) not in (5, 6):
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), *sys.argv[5:])
