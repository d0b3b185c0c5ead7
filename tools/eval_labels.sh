#!/usr/bin/env bash
# Regenerates the tables of README "Image labels in the map": each scene is simulated,
# built from its log with image labels only (`tarn build --labels ...`) and scored against
# the simulator's truth (`tarn eval`). Release build; outputs under $OUT (default
# out/eval_labels). Usage: tools/eval_labels.sh [SCENE:LABELS ...]
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin tarn >&2
T=target/release/tarn
OUT="${OUT:-out/eval_labels}"
mkdir -p "$OUT/map"
runs=("$@")
if [ ${#runs[@]} -eq 0 ]; then
  runs=(default:colour dry_decoys:colour snow_ice:swir snow_ice:colour
        reservoir_night:mwir reservoir_night:colour)
fi
for r in "${runs[@]}"; do
  scene="${r%%:*}"
  labels="${r#*:}"
  sim="$OUT/sim/$scene"
  if [ ! -f "$sim/log.mcap" ]; then
    "$T" simulate "maps/$scene.toml" --out "$sim" >&2
  fi
  extra=()
  if [[ "$labels" == *mwir* ]]; then
    # MWIR needs the local solar hour: the scene's [sky] time_of_day.
    hour=$(sed -n 's/^time_of_day *= *\([0-9.]*\).*/\1/p' "maps/$scene.toml")
    extra=(--hour "$hour")
  fi
  map="$OUT/map/$scene-${labels//,/+}"
  # An 80 m window (800 cells at 0.1 m) holds every cell within --label-max-range (40 m)
  # of the vehicle: with the default 40 m window, votes beyond 20 m fall outside it.
  # --cues none: the labels alone decide what is water (the geometry still comes from the
  # rig's lidar and stereo, configured by the simulator's mapper.toml).
  "$T" build "$sim/log.mcap" --config "$sim/mapper.toml" --cues none --labels "$labels" \
    "${extra[@]}" --window-cells 800 --out "$map" --json > "$map.report.json"
  echo
  echo "### $scene, \`tarn build --cues none --labels $labels ${extra[*]} --window-cells 800\`"
  echo
  "$T" eval "$map" --truth "$sim"
done
