#!/usr/bin/env bash
# The accuracy matrix: every scene in maps/ rendered with every rig in maps/rigs/, built as a
# user would build it (`tarn build LOG --rig RIG`: the log and the rig's datasheet, every
# sensor the log carries, default settings, nothing from the scene), and scored against the
# simulator's truth by range band from the vehicle's path. Writes docs/accuracy.md. Then
# each log is built again with one cue family at a time (the lidar cues, the stereo cues,
# the image labels) and scored the same way: docs/cues.md.
#
#   tools/eval_matrix.sh                      # every scene × every rig
#   SCENES="default dry_paved" RIGS="small" tools/eval_matrix.sh   # a part of it
#   TARN_BIN=target/debug/tarn tools/eval_matrix.sh                # skip the release build
#   OUT=out/matrix DOC=docs/accuracy.md       # where runs and the table go (defaults)
#   REUSE_SIMS=1 tools/eval_matrix.sh         # keep logs already simulated in OUT (the
#                                             # simulator unchanged): builds and scores only
#   BUILD_ARGS="--water-prior 1" ...          # options added to every `tarn build`
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${TARN_BIN:-}" ]; then
  cargo build --release --bin tarn >&2
  TARN_BIN=target/release/tarn
fi
OUT="${OUT:-out/matrix}"
DOC="${DOC:-docs/accuracy.md}"
CUES_DOC="${CUES_DOC:-docs/cues.md}"
SCENES="${SCENES:-default pond_bush fig4_reflections puddles stream_slope reservoir_night snow_ice dry_decoys dry_paved vertical_scanner pond_far_shore pond_deep_banks pond_trees track_puddles}"
RIGS="${RIGS:-small wide lidar_camera stereo_camera}"
start=$(date +%s)
for rig in $RIGS; do
  for scene in $SCENES; do
    dir="$OUT/$rig/$scene"
    mkdir -p "$OUT/$rig"
    echo "matrix: $scene with $rig" >&2
    if [ -z "${REUSE_SIMS:-}" ] || [ ! -f "$dir/sim/log.mcap" ]; then
      "$TARN_BIN" simulate "maps/$scene.toml" --rig "maps/rigs/$rig.toml" --out "$dir/sim" --json \
        > "$dir.sim.json"
    fi
    "$TARN_BIN" build "$dir/sim/log.mcap" --rig "$dir/sim/rig.toml" --out "$dir/map" --tiles --json ${BUILD_ARGS:-} \
      > "$dir.build.json"
    "$TARN_BIN" eval "$dir/map" --truth "$dir/sim" --json > "$dir.eval.json"
  done
done
secs=$(( $(date +%s) - start ))
# Each cue family alone (a family the rig has no sensor for is left out).
for rig in $RIGS; do
  for scene in $SCENES; do
    dir="$OUT/$rig/$scene"
    for set in "lidar:lidar:none" "stereo:stereo,mirror:none" "labels:none:colour,swir"; do
      name=${set%%:*}; rest=${set#*:}; cues=${rest%%:*}; labels=${rest#*:}
      if ! "$TARN_BIN" build "$dir/sim/log.mcap" --rig "$dir/sim/rig.toml" --cues "$cues" \
          --labels "$labels" --out "$dir/$name" --json ${BUILD_ARGS:-} > "$dir.$name.build.json" 2> "$dir.$name.err"; then
        rm -f "$dir.$name.build.json" "$dir.$name.eval.json"
        continue
      fi
      "$TARN_BIN" eval "$dir/$name" --truth "$dir/sim" --json > "$dir.$name.eval.json"
    done
  done
done
cue_secs=$(( $(date +%s) - start - secs ))
commit=$(git rev-parse --short HEAD)
git diff --quiet HEAD -- src maps/rigs $(ls maps/*.toml) || commit="$commit (with uncommitted changes)"
[ -n "${REUSE_SIMS:-}" ] && secs="$secs s of builds and scoring (reusing the logs already simulated)"
python3 tools/matrix_table.py "$OUT" "$commit" "$secs" "$cue_secs" "$SCENES" "$RIGS" "$DOC" "$CUES_DOC"
echo "matrix: wrote $DOC in $secs s and $CUES_DOC in $cue_secs s more" >&2
