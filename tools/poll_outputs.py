"""Rebuilds OUT from two inputs in turn while another thread polls it, and counts the polls
that see `report.json` and `map.ply` of different builds (mixed sets) or a missing file:
by path, and through one handle on the folder.

    python tools/poll_outputs.py TARN INPUT_A INPUT_B OUT [REBUILDS]
"""
import json, os, subprocess, sys, threading, time
tarn, a, b, out = sys.argv[1:5]
builds = int(sys.argv[5]) if len(sys.argv) > 5 else 12
subprocess.run([tarn, "build", a, "--out", out], capture_output=True, check=True)
stop = False
stats = {"naive": [0, 0, 0], "dirfd": [0, 0, 0]}  # polls, mixed, missing

def vertices(data):
    h = data[: data.index(b"end_header\n")].decode()
    return int(h.split("element vertex ")[1].split()[0])

def poll():
    while not stop:
        for mode in ("naive", "dirfd"):
            s = stats[mode]
            try:
                if mode == "naive":
                    r = json.load(open(os.path.join(out, "report.json")))
                    m = open(os.path.join(out, "map.ply"), "rb").read()
                else:
                    fd = os.open(out, os.O_RDONLY | os.O_DIRECTORY)
                    try:
                        r = json.load(open(os.open("report.json", os.O_RDONLY, dir_fd=fd)))
                        m = open(os.open("map.ply", os.O_RDONLY, dir_fd=fd), "rb").read()
                    finally:
                        os.close(fd)
                s[0] += 1
                if r["cells_observed"] != vertices(m):
                    s[1] += 1
            except (FileNotFoundError, ValueError, json.JSONDecodeError, IndexError):
                s[0] += 1
                s[2] += 1

t = threading.Thread(target=poll); t.start()
for k in range(builds):
    subprocess.run([tarn, "build", b if k % 2 == 0 else a, "--out", out], capture_output=True, check=True)
stop = True; t.join()
for mode, (n, mixed, missing) in stats.items():
    print(f"{mode}: {n} polls, {mixed} mixed sets, {missing} missing/partial")
