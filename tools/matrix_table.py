"""Writes the accuracy matrix (docs/accuracy.md) and each cue family alone (docs/cues.md)
from the runs of tools/eval_matrix.sh.

Usage: matrix_table.py OUT COMMIT SECONDS CUE_SECONDS "SCENES" "RIGS" ACCURACY_MD CUES_MD
"""
import contextlib
import json
import os
import sys

out, commit, secs, cue_secs = sys.argv[1:5]
scenes, rigs = sys.argv[5].split(), sys.argv[6].split()
accuracy_md, cues_md = sys.argv[7], sys.argv[8]
FAMILIES = [("lidar", "lidar cues"), ("stereo", "stereo cues"), ("labels", "image labels"), ("all", "all fused")]


def load(rig, scene, kind):
    with open(f"{out}/{rig}/{scene}.{kind}.json") as f:
        return json.load(f)


def pct(v, d=1):
    return "–" if v is None else f"{100 * v:.{d}f} %"


def num(v, d=3):
    return "–" if v is None else f"{v:.{d}f}"


def band(e, name):
    for b in e["matrix_bands"]:
        if b["range"] == name:
            return b
    raise KeyError(name)


def family_band(rig, scene, name):
    """The 5-30 m band of a cue family's build (`all`: the fused one); None without it."""
    kind = "eval" if name == "all" else f"{name}.eval"
    if not os.path.exists(f"{out}/{rig}/{scene}.{kind}.json"):
        return None
    return band(load(rig, scene, kind), "5-30")


def cell(b, key, scale=100.0, digits=1):
    if b is None:
        return "n/a"
    v = b[key]
    return "–" if v is None else f"{scale * v:.{digits}f}"


def header(title, took):
    print(f"# {title}")
    print()
    print(f"Measured at commit {commit}; {took} on the 2-core build machine.")
    print("Regenerate with:")
    print()
    print("```bash")
    print("tools/eval_matrix.sh")
    print("```")
    print()


rig_desc = {}
for rig in rigs:
    for line in open(f"maps/rigs/{rig}.toml"):
        if line.startswith("description"):
            rig_desc[rig] = line.split("=", 1)[1].strip().strip('"')


def accuracy():
    took = f"{secs} s" if secs.isdigit() else secs
    header("Accuracy: every scene × every rig", f"the whole matrix took {took}")
    print("Each scene in `maps/` is rendered with each rig in `maps/rigs/`")
    print("(`tarn simulate SCENE --rig RIG`) and built as a user would build it:")
    print("`tarn build LOG --rig RIG` — the log and the rig's datasheet values, every sensor the")
    print("log carries (colour and SWIR labels where there is a camera), default settings. Nothing")
    print("of the scene reaches the mapper (`tarn simulate` writes no mapper config). Then")
    print("`tarn eval` scores the map against the simulator's truth by range band from the")
    print("vehicle's path (5–10, 10–20, 20–30 m):")
    print()
    print("- **recall**: water cells the sensors could see (some lidar beam or camera pixel met")
    print("  the water there first) that the map calls water, counted from the truth, so water the")
    print("  map left out counts as missed;")
    print("- **sky-reflection recall**: the same over the seen water cells the colour camera saw")
    print("  reflecting the sky in some frame (what a colour classifier can call water). The rest")
    print("  of the seen water it saw only reflecting terrain (the far half of a pond at grazing")
    print("  incidence, mirroring its far bank: the paper's open problem), or only a lidar beam or")
    print("  a stereo pixel met it; there only the lidar's no-returns, whose scan lines lie metres")
    print("  apart at 20–30 m, and stereo reflections can find it;")
    print("- **false water**: dry cells off the shore (more than 0.5 m from any water) called")
    print("  water, over those the map observed;")
    print("- **precision**: map cells called water that are water;")
    print("- **surface, depth, terrain**: RMS error (m) of the water surface where water is found,")
    print("  of depth where the map gives one, and of dry ground not called water.")
    print()
    print("Rigs:")
    print()
    for rig in rigs:
        print(f"- `{rig}`: {rig_desc.get(rig, '')}")
    print()
    print("## 5–30 m")
    print()
    print("| scene | rig | water seen | recall | sky-reflection seen | sky-reflection recall | dry off shore | false water | precision | surface RMS | depth RMS | terrain RMS |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for scene in scenes:
        for rig in rigs:
            b = band(load(rig, scene, "eval"), "5-30")
            print(
                f"| {scene} | {rig} | {b['seen_water_cells']} | {pct(b['seen_recall'])} | "
                f"{b.get('seen_sky_cells', 0)} | {pct(b.get('seen_sky_recall'))} | "
                f"{b['dry_offshore_cells']} | {pct(b['false_rate_offshore'], 2)} | {pct(b['precision'])} | "
                f"{num(b['surface_rms_m'])} | {num(b['depth_rms_m'])} | {num(b['terrain_rms_m'])} |"
            )
    print()
    for rig in rigs:
        print(f"## By range band: `{rig}`")
        print()
        print("| scene | recall 5–10 | 10–20 | 20–30 | false water 5–10 | 10–20 | 20–30 | terrain RMS 5–10 | 10–20 | 20–30 |")
        print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        for scene in scenes:
            e = load(rig, scene, "eval")
            bs = [band(e, n) for n in ("5-10", "10-20", "20-30")]
            rec = " | ".join(pct(b["seen_recall"]) for b in bs)
            fw = " | ".join(pct(b["false_rate_offshore"], 2) for b in bs)
            ter = " | ".join(num(b["terrain_rms_m"]) for b in bs)
            print(f"| {scene} | {rec} | {fw} | {ter} |")
        print()
    print("## What each build used")
    print()
    print("| scene | rig | frames | cues | labels | lidar height (m) | no-return interval (m) | build s |")
    print("| --- | --- | ---: | --- | --- | ---: | --- | ---: |")
    for scene in scenes:
        for rig in rigs:
            r = load(rig, scene, "build")
            labels = r.get("labels") or {}
            used = ",".join(k for k in ("colour", "swir", "mwir") if labels.get(k) and labels[k].get("frames", 0) > 0) or "–"
            di = r.get("diagnostic_interval_m")
            di = "–" if not di else f"{di[0]:.1f}–{di[1]:.1f}"
            h = r.get("lidar_height_m")
            print(
                f"| {scene} | {rig} | {r['frames_fused']} | {','.join(r.get('cues') or []) or '–'} | {used} | "
                f"{num(h, 2)} | {di} | {r['timings_s']['total']:.2f} |"
            )


def cues():
    header("Each cue alone, and all fused", f"the cue runs (after the matrix's) took {cue_secs} s")
    print("The logs of the accuracy matrix ([accuracy.md](accuracy.md)) built again with one cue")
    print("family at a time: `--cues lidar --labels none` (no-return, bottom and specular returns,")
    print("reflectivity), `--cues stereo,mirror --labels none` (stereo reflections and their mirror")
    print("check), `--cues none --labels colour,swir` (image labels), against all of them fused (the")
    print("matrix's build). Band 5–30 m from the vehicle's path; `n/a`: the rig has no sensor for")
    print("that family. Each cell is recall of the water the sensors could see / false water off the")
    print("shore, in per cent.")
    print()
    head = " | ".join(f"{t} recall / false" for _, t in FAMILIES)
    print(f"| scene | rig | {head} |")
    print("| --- | --- |" + " ---: |" * len(FAMILIES))
    for scene in scenes:
        for rig in rigs:
            cells = []
            for name, _ in FAMILIES:
                b = family_band(rig, scene, name)
                cells.append("n/a" if b is None else f"{cell(b, 'seen_recall')} / {cell(b, 'false_rate_offshore', digits=2)}")
            print(f"| {scene} | {rig} | " + " | ".join(cells) + " |")


for path, write in [(accuracy_md, accuracy), (cues_md, cues)]:
    with open(path, "w") as f, contextlib.redirect_stdout(f):
        write()
