"""Surface error of the simulated stream along its course (issue 8).

Reads MAPDIR/map.ply (binary, the map contract) built from `maps/stream_slope.toml` and
prints, per 2 m of x, the mean and RMS of (water cell z − true surface), where the true
surface is the scene's stream: −0.5 + 0.03 (x + 5) m, within 1.5 m of y = 5; then the
same on either side of x = 18 m, where the simulated rig's map splits the stream in two
bodies, and over all.

    .venv/bin/python tools/stream_profile.py out/eval_water/stream_slope/map
"""

import sys

import numpy as np

TYPES = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4", "uint": "<u4"}


def read_vertices(path):
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    fields, count = [], None
    for line in data[:end].decode("ascii").splitlines():
        t = line.split()
        if t[:2] == ["format", "binary_little_endian"]:
            continue
        if t[:2] == ["element", "vertex"]:
            count = int(t[2])
        elif t[0] == "property" and count is not None:
            fields.append((t[2], TYPES[t[1]]))
        elif t[0] == "element":
            break
    if count is None:
        sys.exit(f"{path}: no vertex element")
    return np.frombuffer(data, dtype=np.dtype(fields), count=count, offset=end)


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: stream_profile.py MAPDIR")
    v = read_vertices(sys.argv[1] + "/map.ply")
    w = v[(v["class"] == 2) & (np.abs(v["y"] - 5.0) <= 1.5)]
    err = w["z"] - (-0.5 + 0.03 * (w["x"] + 5.0))
    print("| x (m) | water cells | mean error (m) | RMS (m) |")
    print("| --- | ---: | ---: | ---: |")
    for x0 in range(-6, 46, 2):
        m = (w["x"] >= x0) & (w["x"] < x0 + 2)
        if m.any():
            e = err[m]
            print(f"| {x0}..{x0 + 2} | {m.sum()} | {e.mean():+.3f} | {np.sqrt((e**2).mean()):.3f} |")
    # The simulated rig sees the stream as two bodies, split near x = 18 m.
    for name, m in (("x < 18", w["x"] < 18.0), ("x ≥ 18", w["x"] >= 18.0)):
        if m.any():
            e = err[m]
            print(f"| {name} | {m.sum()} | {e.mean():+.3f} | {np.sqrt((e**2).mean()):.3f} |")
    print(f"| all | {len(err)} | {err.mean():+.3f} | {np.sqrt((err**2).mean()):.3f} |")


if __name__ == "__main__":
    main()
