#!/usr/bin/env bash
# Each cue alone and all fused, on every scene × every rig of the accuracy matrix: the logs
# tools/eval_matrix.sh simulated (run it first) are built again with one cue family at a
# time — the lidar cues, the stereo cues, the image labels — and scored like the matrix.
# Writes docs/cues.md.
#
#   tools/eval_cue_tables.sh                  # after tools/eval_matrix.sh
#   OUT=out/matrix DOC=docs/cues.md TARN_BIN=target/release/tarn tools/eval_cue_tables.sh
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${TARN_BIN:-}" ]; then
  cargo build --release --bin tarn >&2
  TARN_BIN=target/release/tarn
fi
OUT="${OUT:-out/matrix}"
DOC="${DOC:-docs/cues.md}"
SCENES="${SCENES:-default pond_bush fig4_reflections puddles stream_slope reservoir_night snow_ice dry_decoys dry_paved vertical_scanner}"
RIGS="${RIGS:-small wide lidar_camera stereo_camera}"
start=$(date +%s)
for rig in $RIGS; do
  for scene in $SCENES; do
    dir="$OUT/$rig/$scene"
    [ -f "$dir/sim/log.mcap" ] || { echo "no $dir/sim/log.mcap: run tools/eval_matrix.sh first" >&2; exit 1; }
    for set in "lidar:lidar:none" "stereo:stereo,mirror:none" "labels:none:colour,swir"; do
      name=${set%%:*}; rest=${set#*:}; cues=${rest%%:*}; labels=${rest#*:}
      # A cue family the rig has no sensor for is left out.
      if ! "$TARN_BIN" build "$dir/sim/log.mcap" --rig "$dir/sim/rig.toml" --cues "$cues" \
          --labels "$labels" --out "$dir/$name" --json > "$dir.$name.build.json" 2> "$dir.$name.err"; then
        rm -f "$dir.$name.build.json" "$dir.$name.eval.json"
        continue
      fi
      "$TARN_BIN" eval "$dir/$name" --truth "$dir/sim" --json > "$dir.$name.eval.json"
    done
  done
done
secs=$(( $(date +%s) - start ))
commit=$(git rev-parse --short HEAD)
git diff --quiet HEAD -- src maps/rigs $(ls maps/*.toml) || commit="$commit (with uncommitted changes)"
python3 tools/cue_table.py "$OUT" "$commit" "$secs" "$SCENES" "$RIGS" > "$DOC"
echo "cue tables: wrote $DOC in $secs s" >&2
