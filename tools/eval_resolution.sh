#!/usr/bin/env bash
# Colour-only water recall against the colour camera's resolution (issue 7): the default
# and dry-decoy scenes with their stereo camera at 320 × 240 (as shipped), 640 × 480 and
# 1280 × 960, everything else unchanged, each built with colour labels alone at label
# strides 1 and 2 and scored with `tarn eval --band 5,30`. Prints a Markdown table.
#
#   tools/eval_resolution.sh            # release build; outputs under $OUT (out/eval_resolution)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin tarn >&2
T=target/release/tarn
OUT="${OUT:-out/eval_resolution}"
mkdir -p "$OUT"
echo "| scene | camera | label stride | sky-reflection recall | water recall 5–30 m | dry cells called water 5–30 m | labels per frame (median ms) |"
echo "| --- | --- | ---: | ---: | ---: | ---: | ---: |"
for scene in default dry_decoys; do
  for w in 320 640 1280; do
    h=$((w * 3 / 4))
    sim="$OUT/$scene-$w"
    # Only the [rig.stereo] table's size changes (the colour image is its left camera).
    sed -e "/^\[rig.stereo\]/,/^\[/ s/^width = .*/width = $w/" \
      -e "/^\[rig.stereo\]/,/^\[/ s/^height = .*/height = $h/" "maps/$scene.toml" > "$OUT/$scene-$w.toml"
    "$T" simulate "$OUT/$scene-$w.toml" --out "$sim" >&2
    for s in 1 2; do
      map="$sim/map-stride$s"
      "$T" build "$sim/log.mcap" --config "$sim/mapper.toml" --cues none --labels colour \
        --label-stride "$s" --window-cells 800 --out "$map" --json > "$map.build.json"
      "$T" eval "$map" --truth "$sim" --band 5,30 --json > "$map.eval.json"
      python3 - "$scene" "$w" "$h" "$s" "$map" <<'PY'
import json, sys
scene, w, h, s, m = sys.argv[1:]
e = json.load(open(f"{m}.eval.json"))
b = json.load(open(f"{m}.build.json"))
band = e["band"]
sky = (e.get("colour_view") or {}).get("sky") or {}
def frac(n, d):
    return f"{n / d:.3f} ({n} of {d})" if d else "–"
labels = next(x["median_ms"] for x in b["stage_latency_ms"] if x["stage"] == "labels")
print(f"| {scene} | {w} × {h} | {s} | {frac(sky.get('water_detected', 0), sky.get('water_cells', 0))} | "
      f"{frac(band['water_detected'], band['water_cells'])} | "
      f"{band['false_water'] / band['dry_cells']:.4f} ({band['false_water']} of {band['dry_cells']}) | {labels:.1f} |")
PY
    done
  done
done
