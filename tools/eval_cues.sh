#!/usr/bin/env bash
# Per-cue evaluation of the geometric water cues against the simulator's ground truth
# (issue 6), regenerating the tables of README.md's "Water cues against the simulator".
#
# For each scene: `tarn simulate` (noise on) -> `tarn build --cues SET` with the rig's
# mapper config (DIR/mapper.toml, written by the simulator) -> `tarn eval --band 5,25`.
# Cue sets: each cue alone, then all fused. Writes out/eval_cues/<scene>/<set>/ and prints
# Markdown tables. Release build.
#
#   tools/eval_cues.sh [scene ...]     # default: fig4_reflections vertical_scanner default dry_decoys
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin tarn >&2
TARN="$PWD/target/release/tarn"
OUT=out/eval_cues
scenes=("$@")
[ ${#scenes[@]} -eq 0 ] && scenes=(fig4_reflections vertical_scanner default dry_decoys)
sets=(none lidar reflectivity stereo stereo,mirror all)

for scene in "${scenes[@]}"; do
  sim="$OUT/$scene/sim"
  "$TARN" simulate "maps/$scene.toml" --out "$sim" >&2
  for set in "${sets[@]}"; do
    dir="$OUT/$scene/${set//,/+}"
    # A cue of a sensor the rig lacks is an error: skip that set.
    if ! "$TARN" build "$sim/log.mcap" --out "$dir" --config "$sim/mapper.toml" --cues "$set" --json \
        > "$dir.build.json" 2> "$dir.build.err"; then
      rm -f "$dir.build.json"
      continue
    fi
    "$TARN" eval "$dir" --truth "$sim" --band 5,25 --json > "$dir.eval.json"
  done
done

.venv/bin/python - "$OUT" "${scenes[@]}" <<'PY'
import json, os, sys
out, scenes = sys.argv[1], sys.argv[2:]
sets = ["none", "lidar", "reflectivity", "stereo", "stereo+mirror", "all"]
def f(v, d=3):
    return "–" if v is None else f"{v:.{d}f}"
for scene in scenes:
    print(f"\n#### {scene}\n")
    print("| cues | recall 5–25 m | water cells 5–25 m | recall all | false-positive rate | dry called water | sunk dry cells | surface RMS (m) | depth RMS (m) | depth cells | terrain RMS (m) | evidence cells | x real time |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for s in sets:
        p = os.path.join(out, scene, s)
        if not os.path.exists(p + ".eval.json"):
            continue
        e = json.load(open(p + ".eval.json")); b = json.load(open(p + ".build.json"))
        a, band = e["all"], e["band"]
        print(f"| {s} | {f(band['water_recall'])} | {band['water_cells']} | {f(a['water_recall'])} | "
              f"{f(a['false_positive_rate'], 4)} | {a['false_water']} of {a['dry_cells']} | {a['sunk_cells']} | "
              f"{f(a['surface_rms_m'])} | {f(a['depth_rms_m'])} | {a['depth_cells']} | {f(a['terrain_rms_m'])} | "
              f"{b['cue_counts']['evidence_cells']} | {b['x_realtime']:.1} |")
    # Where the no-return beams met the ground, against the optics' interval.
    p = os.path.join(out, scene, "lidar.build.json")
    if os.path.exists(p):
        b = json.load(open(p))
        c, iv = b["cue_counts"], b.get("diagnostic_interval_m")
        lk = c.get("lidar_noret_lookahead_mm")
        where = "–" if lk is None else f"{lk[0] / 1000:.2f}–{lk[1] / 1000:.2f} m"
        ivs = "none" if iv is None else f"[{iv[0]:.2f}, {iv[1]:.2f}] m"
        print(f"\nNo-return beams (lidar alone): {c['lidar_noret']}, meeting the ground at a lookahead of "
              f"{where}; the optics' diagnostic interval for this rig is {ivs}.")
PY
