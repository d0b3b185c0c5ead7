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
    args = os.environ.get("BUILD_ARGS", "").strip()
    print(f'BUILD_ARGS="{args}" tools/eval_matrix.sh' if args else "tools/eval_matrix.sh")
    print("```")
    print()


rig_desc = {}
for rig in rigs:
    with open(f"maps/rigs/{rig}.toml") as f:
        for line in f:
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
    print("  of depth where the map gives one, and of dry ground not called water; **terrain")
    print("  (lidar)** over the dry ground a lidar return of the log fell on (`tarn eval` reads")
    print("  the log beside the truth), where a rig has a lidar.")
    print()
    print("Rigs:")
    print()
    for rig in rigs:
        print(f"- `{rig}`: {rig_desc.get(rig, '')}")
    print()
    print("## 5–30 m")
    print()
    print("| scene | rig | water seen | recall | sky-reflection seen | sky-reflection recall | dry off shore | false water | precision | surface RMS | depth RMS | terrain RMS | terrain RMS (lidar) |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for scene in scenes:
        for rig in rigs:
            b = band(load(rig, scene, "eval"), "5-30")
            print(
                f"| {scene} | {rig} | {b['seen_water_cells']} | {pct(b['seen_recall'])} | "
                f"{b.get('seen_sky_cells', 0)} | {pct(b.get('seen_sky_recall'))} | "
                f"{b['dry_offshore_cells']} | {pct(b['false_rate_offshore'], 2)} | {pct(b['precision'])} | "
                f"{num(b['surface_rms_m'])} | {num(b['depth_rms_m'])} | {num(b['terrain_rms_m'])} | "
                f"{num(b.get('terrain_lidar_rms_m'))} |"
            )
    print()
    for rig in rigs:
        print(f"## By range band: `{rig}`")
        print()
        print("| scene | recall 5–10 | 10–20 | 20–30 | false water 5–10 | 10–20 | 20–30 | terrain RMS 5–10 | 10–20 | 20–30 | terrain RMS (lidar) 5–10 | 10–20 | 20–30 |")
        print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        for scene in scenes:
            e = load(rig, scene, "eval")
            bs = [band(e, n) for n in ("5-10", "10-20", "20-30")]
            rec = " | ".join(pct(b["seen_recall"]) for b in bs)
            fw = " | ".join(pct(b["false_rate_offshore"], 2) for b in bs)
            ter = " | ".join(num(b["terrain_rms_m"]) for b in bs)
            tl = " | ".join(num(b.get("terrain_lidar_rms_m")) for b in bs)
            print(f"| {scene} | {rec} | {fw} | {ter} | {tl} |")
        print()
    print("## The map's own uncertainty, by range band")
    print()
    print("Of the dry cells `tarn eval` scores for terrain, the share whose error is within 1σ and")
    print("3σ of the map's `elevation_std` (a Gaussian puts 68.3 and 99.7 % there), and the terrain")
    print("RMS over the cells whose σ is at most 5 cm; then the water probability's reliability over")
    print("5–30 m: the largest gap between a decile's mean probability and the share of its cells")
    print("that are water, over the deciles with at least 200 cells.")
    print()
    print("| scene | rig | within 1σ 5–10 | 10–20 | 20–30 | within 3σ 5–10 | 10–20 | 20–30 | RMS σ ≤ 5 cm 5–10 | 10–20 | 20–30 | reliability gap |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for scene in scenes:
        for rig in rigs:
            e = load(rig, scene, "eval")
            bs = [band(e, n) for n in ("5-10", "10-20", "20-30")]
            frac = lambda b, k: (b.get("terrain_within_sigma_frac") or [None] * 3)[k]
            one = " | ".join(pct(frac(b, 0)) for b in bs)
            three = " | ".join(pct(frac(b, 2)) for b in bs)
            conf = " | ".join(num(b.get("terrain_confident_rms_m")) for b in bs)
            rel = [r for r in band(e, "5-30").get("water_reliability") or [] if r["cells"] >= 200]
            gap = max((abs(r["water_fraction"] - r["mean_p"]) for r in rel), default=None)
            print(f"| {scene} | {rig} | {one} | {three} | {conf} | {num(gap, 2)} |")
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


# Each cue's events in the tile sets of the matrix's builds (`cue_rates` of `tarn eval`):
# (name, key, what an event is, what the other count is, the rule's likelihoods).
RATE_CUES = [
    ("colour labels", "colour", "frame votes water / not", "p_colour_detect", "p_colour_false"),
    ("SWIR labels", "swir", "frame votes dark / lit", "p_swir_detect", "p_swir_false"),
    ("lidar no-return", "noret", "diagnostic beams empty / returned", None, "p_dropout"),
    ("reflectivity", "reflectivity", "cells dark / lit", "p_dark_wet", "p_dark_dry"),
]
COUNT_CUES = [
    ("reflection rays", "reflect", "p_reflect_detect", "p_reflect_false"),
    ("bottom returns", "bottom", "p_bottom_detect", "p_bottom_false"),
]


def rates_of(rig, scene):
    """The 5-30 m cue counts and the default rule of one build; None without a tile set."""
    e = load(rig, scene, "eval")
    if "cue_rates" not in e:
        return None
    r = next(b for b in e["cue_rates"] if b["range"] == "5-30")
    return r, e["fusion_default"]


def ratio(a, b):
    return None if b == 0 else a / b


def rates():
    runs = {(rig, scene): rates_of(rig, scene) for rig in rigs for scene in scenes}
    runs = {k: v for k, v in runs.items() if v is not None}
    if not runs:
        return
    rule = next(iter(runs.values()))[1]
    print()
    print("## Each cue's events on water and on dry ground")
    print()
    print("The fusion rule ([`grid::Fusion`](../src/grid/evidence.rs)) gives each event of a cue")
    print("the log-likelihood ratio ln P(event | water) / P(event | dry). Here those probabilities")
    print("are counted on the matrix's builds (`tarn build --tiles` writes each cell's evidence;")
    print("`tarn eval` scores it, `cue_rates` in its JSON): cells of the tile set 5–30 m from the")
    print("path, on true water or on dry ground farther than 0.5 m from water, every scene and")
    print("rig summed (one row per rig below). P(for | ·) is the share of a cue's events that")
    print("speak for water. LR is the likelihood ratio of an event for water, then of one")
    print("against; the rule's are beside it. The colour labels' P(for | dry) is measured from")
    print("each log where its lidar sampled dry ground (`Fusion::measured`; the stated 0.05")
    print("where it did not): the range the row's builds used is shown.")
    print()
    print("| cue (event for / against) | rig | on water: for / against | P(for \\| water) | on dry: for / against | P(for \\| dry) | P(for \\| dry), the worst scene | LR for / against | rule: P(for \\| water), P(for \\| dry) | rule: LR for / against |")
    print("| --- | --- | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: |")

    def in_row(rig, k):
        """Whether the run `k` = (rig, scene) counts in the row of `rig` ("all": every run)."""
        return rig == "all" or k[0] == rig

    def tot(rig, key):
        w, d = [0, 0], [0, 0]
        for k, (r, _) in runs.items():
            if in_row(rig, k):
                for i in range(2):
                    w[i] += r[key]["water"][i]
                    d[i] += r[key]["dry"][i]
        return w, d

    def top(rig, share):
        """The largest `share(counts)` of one scene (× rig in the "all" row) in the row,
        over the runs for which it is not None, with where; "–" without one above 0."""
        best = max(((v, k) for k, (r, _) in runs.items() if in_row(rig, k)
                    for v in [share(r)] if v is not None), default=None)
        if best is None or best[0] == 0:
            return "–"
        (v, (r, scene)) = best
        return f"{pct(v, 2)} ({scene}" + (f" × {r})" if rig == "all" else ")")

    def lr(pw, pd):
        if pw is None or pd is None:
            return "–"
        f = "–" if pd == 0 else f"{pw / pd:.1f}"
        a = "–" if pd == 1 else f"{(1 - pw) / (1 - pd):.2f}"
        return f"{f} / {a}"

    def used(rig, pd_name):
        """The P(for | dry) each build of the row used (a rate measured from its log, or the
        stated one): "a" or "a–b" over the builds, from their reports."""
        ps = sorted({(load(r, scene, "build").get("fusion") or rule)[pd_name]
                     for (r, scene) in runs if in_row(rig, (r, scene))})
        f = lambda p: f"{p:.2f}" if p >= 0.01 else f"{p:.0e}"
        return f(ps[0]) if len(ps) == 1 else f"{f(ps[0])}–{f(ps[-1])}"

    for name, key, what, pw_name, pd_name in RATE_CUES:
        rpw = 1 - rule["p_water_return"] if pw_name is None else rule[pw_name]
        rpd = rule[pd_name]
        for rig in rigs + ["all"]:
            w, d = tot(rig, key)
            if sum(w) + sum(d) == 0:
                continue
            if key in ("colour", "swir"):
                # Measured per log where a lidar samples dry ground: the rule's ratio is the
                # stated one's, the rates the builds used beside.
                print(f"| {name} ({what}) | {rig} | {w[0]:,} / {w[1]:,} | {pct(ratio(w[0], sum(w)))} | {d[0]:,} / {d[1]:,} | {pct(ratio(d[0], sum(d)), 2)} | {top(rig, lambda r: r[key]['dry'][0] / sum(r[key]['dry']) if sum(r[key]['dry']) >= 1000 else None)} | {lr(ratio(w[0], sum(w)), ratio(d[0], sum(d)))} | {rpw:.2f}, {used(rig, pd_name)} | measured per log |")
                continue
            pw, pd = ratio(w[0], sum(w)), ratio(d[0], sum(d))
            # The scene whose dry ground fooled the cue most, among those with at least
            # 1,000 events on dry ground.
            ws = top(rig, lambda r: r[key]["dry"][0] / sum(r[key]["dry"]) if sum(r[key]["dry"]) >= 1000 else None)
            print(f"| {name} ({what}) | {rig} | {w[0]:,} / {w[1]:,} | {pct(pw)} | {d[0]:,} / {d[1]:,} | {pct(pd, 2)} | {ws} | {lr(pw, pd)} | {rpw:.2f}, {rpd:.2f} | {lr(rpw, rpd)} |")
    print()
    print("Reflection rays and bottom returns have no event against (a ray that found no")
    print("reflection is not recorded), so their rates per ray cannot be counted. What can be:")
    print("the share of cells with at least one, and the events in them.")
    print()
    print("| cue | rig | water cells with one | the best scene | events a water cell | dry cells with one | the worst scene | events a dry cell | cells-with-one ratio | rule: LR an event |")
    print("| --- | --- | ---: | --- | ---: | ---: | --- | ---: | ---: | ---: |")

    def cells(rig, side):
        return sum(r["cells"][side] for k, (r, _) in runs.items() if in_row(rig, k))

    for name, key, pw_name, pd_name in COUNT_CUES:
        for rig in rigs + ["all"]:
            w, d = tot(rig, key)
            if w[0] + d[0] == 0:
                continue
            fw, fd = ratio(w[1], cells(rig, 0)), ratio(d[1], cells(rig, 1))
            rr = "–" if not fd else f"{fw / fd:.1f}"
            # The scene with the largest share of its water (side 0) or dry (side 1) cells
            # with an event, among those with 500 such cells.
            best = [top(rig, lambda r, side=side, on=on: r[key][on][1] / r["cells"][side]
                        if r["cells"][side] >= 500 else None)
                    for side, on in enumerate(("water", "dry"))]
            print(f"| {name} | {rig} | {pct(fw, 2)} | {best[0]} | {num(ratio(w[0], w[1]), 1)} | {pct(fd, 3)} | {best[1]} | {num(ratio(d[0], d[1]), 1)} | {rr} | {rule[pw_name] / rule[pd_name]:.1f} |")
    print()
    nw, nd = cells("all", 0), cells("all", 1)
    print(f"The cells scored: {nw:,} on water and {nd:,} on dry ground off the shore; water is")
    print(f"{pct(nw / (nw + nd))} of them, against the rule's prior of {pct(rule['prior'])}.")


def cues_and_rates():
    cues()
    rates()


for path, write in [(accuracy_md, accuracy), (cues_md, cues_and_rates)]:
    with open(path, "w") as f, contextlib.redirect_stdout(f):
        write()
