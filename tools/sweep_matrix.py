"""Speed against error on the accuracy matrix: every `tarn build` knob that trades one for
the other, each value built on every log of the matrix (`tools/eval_matrix.sh` simulates
them into OUT first) and scored against the simulator's truth with `tarn eval`, as that
script scores the defaults. Writes a markdown table (and the raw rows as JSON beside it).

Usage: sweep_matrix.py [--out out/matrix] [--doc docs/sweep.md] [--bin target/release/tarn]
                       [--scenes "a b"] [--rigs "x y"] [--knobs "label-stride=1,3,4 ..."]

Each knob value is built with the defaults otherwise; the logs are visited one at a time,
and on each log every setting (the defaults among them) is built in turn, so that a burst
of load on the shared machine falls on all settings alike. Time is per frame, as the
vehicle sees it: builds publish the map after every frame (`--per-frame-maps`, which does
not change the map), and each setting's median frame time on a log is divided by the
defaults' on the same log; the table gives the median of those ratios over the logs, and
the median frame time in ms. Accuracy is that of the 5-30 m band, each measure averaged
over the logs where it is defined. The rows per log go to OUT/sweep.json (`--from-json`
tabulates them again).
"""
import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile

SCENES = "default pond_bush fig4_reflections puddles stream_slope reservoir_night snow_ice dry_decoys dry_paved vertical_scanner"
RIGS = "small wide lidar_camera stereo_camera"
KNOBS = "label-stride=1,3,4 label-wide-rows label-surface-max-std=0.05,inf label-sampler=march resolution=0.2 window-cells=300,600"

ap = argparse.ArgumentParser()
ap.add_argument("--out", default="out/matrix")
ap.add_argument("--doc", default="docs/sweep.md")
ap.add_argument("--bin", default="target/release/tarn")
ap.add_argument("--scenes", default=SCENES)
ap.add_argument("--rigs", default=RIGS)
ap.add_argument("--knobs", default=KNOBS)
ap.add_argument("--from-json", action="store_true",
                help="tabulate the rows of an earlier run (OUT/sweep.json) without building")
ap.add_argument("--logs", help='rig/scene pairs ("small/default wide/puddles"), in place of scenes × rigs')
args = ap.parse_args()

# (label, extra build arguments); the defaults first.
settings = [("defaults", [])]
for spec in args.knobs.split():
    name, _, values = spec.partition("=")
    if not values:
        settings.append((f"--{name}", [f"--{name}"]))
        continue
    for v in values.split(","):
        settings.append((f"--{name} {v}", [f"--{name}", v]))

pairs = (args.logs.split() if args.logs else
         [f"{rig}/{scene}" for rig in args.rigs.split() for scene in args.scenes.split()])
logs = []
for pair in pairs:
    rig, scene = pair.split("/")
    sim = f"{args.out}/{rig}/{scene}/sim"
    if not os.path.exists(f"{sim}/log.mcap"):
        sys.exit(f"{sim}/log.mcap is missing: run tools/eval_matrix.sh first")
    logs.append((rig, scene, sim))

if args.from_json:
    with open(f"{args.out}/sweep.json") as f:
        earlier = json.load(f)
    rows = earlier["rows"]
    settings = [(label, None) for label in rows]
    logs = [(r["rig"], r["scene"], None) for r in rows["defaults"]]
else:
    rows = {label: [] for label, _ in settings}
    tmp = tempfile.mkdtemp(prefix="tarn-sweep-")
    try:
        for rig, scene, sim in logs:
            print(f"sweep: {scene} with {rig}", file=sys.stderr)
            for label, extra in settings:
                d = f"{tmp}/map"
                shutil.rmtree(d, ignore_errors=True)
                cmd = [args.bin, "build", f"{sim}/log.mcap", "--rig", f"{sim}/rig.toml", "--out", d,
                       "--per-frame-maps", "--json", *extra]
                rep = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
                ev = json.loads(subprocess.run([args.bin, "eval", d, "--truth", sim, "--json"],
                                               check=True, capture_output=True, text=True).stdout)
                band = next(b for b in ev["matrix_bands"] if b["range"] == "5-30")
                lat = {s["stage"]: s["median_ms"] for s in rep["stage_latency_ms"]}
                rows[label].append({"rig": rig, "scene": scene, "frame_ms": lat["total"],
                                    "labels_ms": lat["labels"], "water_ms": lat["water"], "band": band})
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def mean_over_logs(rs):
    """Each measure's mean over the logs where it is defined (a log without water has no
    recall): every scene and rig weighs the same, where cells summed would let the one
    scene with the most water decide."""
    def mean(k):
        v = [r["band"][k] for r in rs if r["band"][k] is not None]
        return statistics.mean(v) if v else None

    return {
        "recall": mean("seen_recall"),
        "sky_recall": mean("seen_sky_recall"),
        "false_water": mean("false_rate_offshore"),
        "precision": mean("precision"),
        "surface_rms": mean("surface_rms_m"),
        "terrain_rms": mean("terrain_rms_m"),
    }


base = rows["defaults"]
table = []
for label, _ in settings:
    rs = rows[label]
    ratio = statistics.median(r["frame_ms"] / b["frame_ms"] for r, b in zip(rs, base))
    lab = statistics.median(r["labels_ms"] / b["labels_ms"] for r, b in zip(rs, base) if b["labels_ms"] > 0)
    table.append({"setting": label, "frame_ms": statistics.median(r["frame_ms"] for r in rs),
                  "frame_vs_defaults": ratio, "labels_vs_defaults": lab, **mean_over_logs(rs)})

if args.from_json:
    commit = earlier["commit"]
else:
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    if subprocess.run(["git", "diff", "--quiet", "HEAD", "--", "src"]).returncode:
        commit += " (with uncommitted changes)"
pct = lambda v, d=1: "–" if v is None else f"{100 * v:.{d}f} %"
num = lambda v, d=3: "–" if v is None else f"{v:.{d}f}"
with open(args.doc, "w") as f:
    w = lambda s="": print(s, file=f)
    w("# Speed against error on the accuracy matrix")
    w()
    rigs = list(dict.fromkeys(r for r, _, _ in logs))
    scenes = list(dict.fromkeys(s for _, s, _ in logs))
    if len(logs) == len(rigs) * len(scenes):
        which = f"every scene ({', '.join(scenes)}) with every rig ({', '.join(rigs)})"
    else:
        which = ", ".join(f"{s} ({r})" for r, s, _ in logs)
    w(f"Measured at commit {commit} on the 2-core build machine, {len(logs)} logs: {which}. "
      "Regenerate with:")
    w()
    w("```bash")
    w("tools/eval_matrix.sh            # simulates the logs into out/matrix (once)")
    extra = "" if args.knobs == KNOBS else f' --knobs "{args.knobs}"'
    if args.logs:
        extra += f' --logs "{args.logs}"'
    elif (args.scenes, args.rigs) != (SCENES, RIGS):
        extra += f' --scenes "{args.scenes}" --rigs "{args.rigs}"'
    w(f"python3 tools/sweep_matrix.py{extra}")
    w("```")
    w()
    w("Each row is `tarn build LOG --rig RIG --per-frame-maps` with one option changed from the "
      "defaults, on every log of the matrix, scored by `tarn eval` against the simulator's "
      "truth in the 5–30 m band; each measure is its mean over the logs where it is defined "
      "(recall over the logs with water, precision over those where the map calls some), so "
      "that every scene and rig weighs the same (the columns are those of "
      "[accuracy.md](accuracy.md)). Time: the median frame "
      "(`Mapper::update` with the map published) and the label stage's, each divided by the "
      "defaults' on the same log, built in turn with it; the median of those ratios over the "
      "logs, and the median frame in ms.")
    w()
    w("| setting | frame (ms) | frame / defaults | labels / defaults | recall | sky-reflection recall "
      "| false water | precision | surface RMS (m) | terrain RMS (m) |")
    w("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for t in table:
        w(f"| `{t['setting']}` | {t['frame_ms']:.1f} | {t['frame_vs_defaults']:.2f} | "
          f"{t['labels_vs_defaults']:.2f} | {pct(t['recall'])} | {pct(t['sky_recall'])} | "
          f"{pct(t['false_water'], 2)} | {pct(t['precision'])} | {num(t['surface_rms'])} | "
          f"{num(t['terrain_rms'])} |")
if not args.from_json:
    with open(f"{args.out}/sweep.json", "w") as f:
        json.dump({"commit": commit, "table": table, "rows": rows}, f, indent=1)
print(f"sweep: wrote {args.doc}", file=sys.stderr)
