"""Writes docs/cues.md from the runs of tools/eval_matrix.sh: each cue family alone, and
all fused.

Usage: cue_table.py OUT COMMIT SECONDS "SCENES" "RIGS" > docs/cues.md
"""
import json
import os
import sys

out, commit, secs, scenes, rigs = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4].split(), sys.argv[5].split()
FAMILIES = [("lidar", "lidar cues"), ("stereo", "stereo cues"), ("labels", "image labels"), ("all", "all fused")]


def band(rig, scene, name):
    p = f"{out}/{rig}/{scene}.eval.json" if name == "all" else f"{out}/{rig}/{scene}.{name}.eval.json"
    if not os.path.exists(p):
        return None
    with open(p) as f:
        for b in json.load(f)["matrix_bands"]:
            if b["range"] == "5-30":
                return b
    return None


def cell(b, key, scale=100.0, digits=1):
    if b is None:
        return "n/a"
    v = b[key]
    return "–" if v is None else f"{scale * v:.{digits}f}"


print("# Each cue alone, and all fused")
print()
print(f"Measured at commit {commit}; the cue runs (after the matrix's) took {secs} s on the 2-core build machine.")
print("Regenerate with:")
print()
print("```bash")
print("tools/eval_matrix.sh")
print("```")
print()
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
            b = band(rig, scene, name)
            cells.append("n/a" if b is None else f"{cell(b, 'seen_recall')} / {cell(b, 'false_rate_offshore', digits=2)}")
        print(f"| {scene} | {rig} | " + " | ".join(cells) + " |")
