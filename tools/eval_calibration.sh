#!/usr/bin/env bash
# The calibration axis of the accuracy matrix: every scene × rig rendered as real logs come,
# with their calibration whole, without the right camera's CameraInfo, with a zero baseline
# in it, and with the lidar's raw intensity named `reflectivity`; each built as a user builds
# it (plain `tarn build LOG`), beside the same log built with the rig's true datasheet
# (`--rig`) and with a rig file whose disparity noise is wrong by 2× either way. Scored
# against the simulator's truth by range band. Writes docs/calibration.md.
#
#   tools/eval_calibration.sh                                   # the default scenes and rigs
#   SCENES="default dry_paved" RIGS="small" tools/eval_calibration.sh
#   TARN_BIN=target/release/tarn OUT=out/calibration DOC=docs/calibration.md
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${TARN_BIN:-}" ]; then
  cargo build --release --bin tarn >&2
  TARN_BIN=target/release/tarn
fi
OUT="${OUT:-out/calibration}"
DOC="${DOC:-docs/calibration.md}"
SCENES="${SCENES:-default dry_paved pond_far_shore}"
RIGS="${RIGS:-small wide lidar_camera stereo_camera full_frame vertical_scanner}"
start=$(date +%s)
for rig in $RIGS; do
  has_stereo=$(grep -q '^\[stereo\]' "maps/rigs/$rig.toml" && echo 1 || true)
  has_lidar=$(grep -q '^\[lidar\]' "maps/rigs/$rig.toml" && echo 1 || true)
  for scene in $SCENES; do
    dir="$OUT/$rig/$scene"
    mkdir -p "$dir"
    build() { # NAME LOG [ARGS...]: build, then score
      local name=$1 log=$2; shift 2
      echo "calibration: $scene with $rig, $name" >&2
      "$TARN_BIN" build "$log" --out "$dir/$name" --json "$@" > "$dir/$name.build.json"
      "$TARN_BIN" eval "$dir/$name" --truth "$dir/full" --json > "$dir/$name.eval.json"
    }
    variants="full"
    [ -n "$has_stereo" ] && variants="$variants no-right-info zero-baseline"
    [ -n "$has_lidar" ] && variants="$variants raw-as-reflectivity"
    for v in $variants; do
      [ -f "$dir/$v/log.mcap" ] && [ -n "${REUSE_SIMS:-}" ] || \
        "$TARN_BIN" simulate "maps/$scene.toml" --rig "maps/rigs/$rig.toml" --calibration "$v" \
          --out "$dir/$v" --json > "$dir/$v.sim.json"
    done
    build datasheet "$dir/full/log.mcap" --rig "$dir/full/rig.toml"
    for v in $variants; do
      build "plain-$v" "$dir/$v/log.mcap"
      # What `tarn info` measures over the log's first 20 frames.
      "$TARN_BIN" info "$dir/$v/log.mcap" --json > "$dir/$v.info.json"
    done
    if [ -n "$has_stereo" ]; then
      for f in 2 0.5; do
        python3 - "$dir/full/rig.toml" "$f" > "$dir/rig-sigma-x$f.toml" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
f = float(sys.argv[2])
print(re.sub(r"(?m)^disparity_noise_px = ([0-9.eE+-]+)",
             lambda m: f"disparity_noise_px = {float(m.group(1)) * f}", text), end="")
PY
        build "rig-sigma-x$f" "$dir/full/log.mcap" --rig "$dir/rig-sigma-x$f.toml"
      done
    fi
  done
done
secs=$(( $(date +%s) - start ))
commit=$(git rev-parse --short HEAD)
git diff --quiet HEAD -- src crates maps || commit="$commit (with uncommitted changes)"
python3 tools/calibration_table.py "$OUT" "$commit" "$secs" "$SCENES" "$RIGS" > "$DOC"
echo "calibration: wrote $DOC in $secs s" >&2
