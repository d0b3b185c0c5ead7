#!/usr/bin/env bash
# Water bodies and surfaces against the simulator's truth (issue 8), regenerating README's
# "Water surfaces on the simulated scenes" table.
#
# Each scene runs the main job's pipeline: `tarn simulate` -> `tarn build` with the rig's
# mapper config, every cue, colour labels and an 80 m window -> `tarn eval`. One row per
# body: the surface model the shore chose and its residuals, and the scene's surface RMS
# against the true water level (all water cells the map found).
#
#   tools/eval_water.sh [scene ...]   # default: default pond_bush puddles stream_slope
#   TARN_BIN=target/debug/tarn tools/eval_water.sh   # skip the release build
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${TARN_BIN:-}" ]; then
  cargo build --release --bin tarn >&2
  TARN_BIN=target/release/tarn
fi
OUT="${OUT:-out/eval_water}"
scenes=("$@")
[ ${#scenes[@]} -eq 0 ] && scenes=(default pond_bush puddles stream_slope)
for scene in "${scenes[@]}"; do
  sim="$OUT/$scene/sim"
  map="$OUT/$scene/map"
  "$TARN_BIN" simulate "maps/$scene.toml" --out "$sim" >&2
  "$TARN_BIN" build "$sim/log.mcap" --out "$map" --config "$sim/mapper.toml" --cues all \
    --labels colour --window-cells 800 --json > "$map.build.json"
  "$TARN_BIN" eval "$map" --truth "$sim" --json > "$map.eval.json"
done

python3 - "$OUT" "${scenes[@]}" <<'PY'
import json, sys
out, scenes = sys.argv[1], sys.argv[2:]
def f(v, d=3):
    return "–" if v is None else f"{v:.{d}f}"
print("| scene | body | area (m²) | model | shore kept / all | level residual (m) | Delaunay hold-out (m) | surface z (m) | depth | scene surface RMS (m) | scene depth RMS (m) | water recall | false-positive rate |")
print("| --- | ---: | ---: | --- | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: |")
for s in scenes:
    r = json.load(open(f"{out}/{s}/map/report.json"))
    e = json.load(open(f"{out}/{s}/map.eval.json"))["all"]
    tail = (f"{f(e['surface_rms_m'])} | {f(e['depth_rms_m'])} | {f(e['water_recall'])} | "
            f"{f(e['false_positive_rate'], 4)}")
    bodies = r["water"]["bodies"]
    if not bodies:
        print(f"| {s} | none | | | | | | | | {tail} |")
    for b in bodies:
        d = b["depth"]
        depth = "unknown" if d["known_cells"] == 0 else f"mean {f(d['mean_m'])} m over {d['known_cells']} cells, {d['unknown_cells']} unknown"
        z = "–" if b["surface_model"] != "level" else f(b["surface_z"])
        print(f"| {s} | {b['id']} | {b['area_m2']:.1f} | {b['surface_model']} ({b['surface_source']}) | "
              f"{b['shore_samples_kept']} / {b['shore_samples']} | {f(b['level_residual_m'])} | "
              f"{f(b['delaunay_residual_m'])} | {z} | {depth} | {tail} |")
PY
