#!/usr/bin/env bash
# The SWIR labels on the rigs with a SWIR camera of their own × the water and dry scenes, each
# range band on its own. Each log is built three ways and scored against the simulator's
# truth (`tarn eval`):
#
#   swir        --cues none --labels swir               the SWIR labels alone
#   colour+swir --cues none --labels colour,swir        no lidar or stereo cue, and no
#               with [labels] colour_check = false      lidar/stereo check of the colour
#   all         --labels colour,swir (every cue)        the full build
#
# and docs/swir.md is written from the scores, citing this command and the commit.
#
#   tools/eval_swir.sh                                  # both SWIR rigs × every scene
#   RIGS="swir_small" SCENES="default dry_paved" tools/eval_swir.sh
#   TARN_BIN=target/release/tarn tools/eval_swir.sh     # skip the release build
#   REUSE_SIMS=1 tools/eval_swir.sh                     # keep logs already simulated in OUT
#   OUT=out/swir DOC=docs/swir.md                       # where runs and the table go
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${TARN_BIN:-}" ]; then
  cargo build --release --bin tarn >&2
  TARN_BIN="${CARGO_TARGET_DIR:-target}/release/tarn"
fi
OUT="${OUT:-out/swir}"
DOC="${DOC:-docs/swir.md}"
# The rigs with a SWIR camera of their own (wide_gps is wide with a GNSS receiver: the same
# SWIR camera).
RIGS="${RIGS:-wide swir_small}"
SCENES="${SCENES:-default pond_far_shore pond_trees track_puddles reservoir_night dry_paved dry_decoys snow_ice}"
mkdir -p "$OUT"
nocheck="$OUT/no_range_checks.toml"
# Every sensor's section present (absent is off), the colour check against lidar and stereo off.
cat > "$nocheck" <<'EOF'
[lidar]
[stereo]
[labels]
sensors = ["colour", "swir"]
colour_check = false
EOF
start=$(date +%s)
for rig in $RIGS; do
  for scene in $SCENES; do
    dir="$OUT/$rig/$scene"
    mkdir -p "$dir"
    echo "swir: $scene with $rig" >&2
    if [ -z "${REUSE_SIMS:-}" ] || [ ! -f "$dir/sim/log.mcap" ]; then
      "$TARN_BIN" simulate "maps/$scene.toml" --rig "maps/rigs/$rig.toml" --out "$dir/sim" --json \
        > "$dir/sim.json"
    fi
    for set in "swir|--cues none --labels swir" \
               "colour_swir|--config $nocheck --cues none --labels colour,swir" \
               "all|--labels colour,swir"; do
      name=${set%%|*}; args=${set#*|}
      # shellcheck disable=SC2086
      "$TARN_BIN" build "$dir/sim/log.mcap" --rig "$dir/sim/rig.toml" $args --out "$dir/$name" \
        --json > "$dir/$name.build.json"
      "$TARN_BIN" eval "$dir/$name" --truth "$dir/sim" --json > "$dir/$name.eval.json"
    done
  done
done
secs=$(( $(date +%s) - start ))
commit=$(git rev-parse HEAD)
git diff --quiet HEAD -- src crates maps tools || commit="$commit (with uncommitted changes)"
python3 - "$OUT" "$commit" "$secs" "$RIGS" "$SCENES" > "$DOC" <<'PY'
import json, os, sys
out, commit, secs, rigs, scenes = sys.argv[1:6]
rigs, scenes = rigs.split(), scenes.split()
BANDS = ["5-10", "10-20", "20-30"]
SETS = [("swir", "SWIR alone"), ("colour_swir", "colour + SWIR, no lidar/stereo"), ("all", "colour + SWIR, every cue")]
def pct(x, d=1):
    return "–" if x is None else f"{100 * x:.{d}f}"
def bands(rig, scene, name):
    p = os.path.join(out, rig, scene, f"{name}.eval.json")
    if not os.path.exists(p):
        return None
    e = json.load(open(p))
    return {b["range"]: b for b in e["matrix_bands"]}
print("# SWIR labels by range band")
print()
print("Written by `tools/eval_swir.sh` (do not edit by hand) at commit")
print(f"`{commit}`, {secs} s. The rigs {', '.join(f'`{r}`' for r in rigs)}, each with a SWIR camera of its own, × the scenes below,")
print("simulated (`tarn simulate maps/SCENE.toml --rig maps/rigs/RIG.toml`) and built three ways:")
print()
print("- **SWIR alone**: `tarn build LOG --rig RIG --cues none --labels swir`;")
print("- **colour + SWIR, no lidar/stereo**: `--cues none --labels colour,swir` with the colour")
print("  check against the lidar and stereo off (`[labels] colour_check = false`): what the two")
print("  cameras say on their own, as on a rig without range sensors;")
print("- **colour + SWIR, every cue**: `--labels colour,swir`, every water cue the log allows.")
print()
print("Scored by `tarn eval MAP --truth SIM` per range band from the vehicle's path. Each cell")
print("is **sky-reflection recall / water recall / false water** in per cent: the share of the")
print("sky-reflecting water cells the cameras saw that are called water, of all water cells")
print("seen, and of the dry cells off the shore (more than 0.5 m from any water) called water.")
print("`–`: no such cells in the band.")
for rig in rigs:
    print()
    print(f"## {rig}")
    print()
    head = " | ".join(f"{t} {b} m" for _, t in SETS for b in BANDS)
    print(f"| scene | {head} |")
    print("|" + " --- |" * (1 + len(SETS) * len(BANDS)))
    for scene in scenes:
        cells = []
        for name, _ in SETS:
            bs = bands(rig, scene, name)
            for b in BANDS:
                x = None if bs is None else bs.get(b)
                if x is None:
                    cells.append("n/a")
                else:
                    cells.append(f"{pct(x.get('seen_sky_recall'))} / {pct(x.get('seen_recall'))} / {pct(x.get('false_rate_offshore'), 2)}")
        print(f"| {scene} | " + " | ".join(cells) + " |")
PY
echo "swir: wrote $DOC in $secs s" >&2
