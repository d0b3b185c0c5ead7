#!/usr/bin/env python3
"""Where a build's CPU time goes, by pipeline stage, from a `perf record` call graph.

Each sample goes to the stage of the innermost frame of its stack that names one (so a
sample in the ingest called by a cue counts as ingest); samples in no stage are
"other" (allocator, kernel, thread pool), with their leaf shown.

    perf record -F 999 --call-graph dwarf,16384 -o perf.data \
        target/release/tarn build LOG.mcap --out DIR --rig RIG.toml \
        --per-frame-maps
    perf script -i perf.data > perf.txt
    python3 tools/perf_stages.py perf.txt
    python3 tools/perf_stages.py perf.txt --within 'label'   # that stage, by function

With `--within WORD`, the samples of the stages whose name contains WORD are split
further by the innermost tarn function of their stack (inlined frames count as their
own function).
"""
import sys, re, collections
pats = [
 ('label ray march', r'project::surface::GridSurface::(cast|block_end|last_observed|after_skip)'),
 ('labels besides the march (stereo look-up, quads, tally, votes)', r'project::frame::(quad_cells|triangle_cells|FrameLabels::run|FrameLabels::apply|tighten)'),
 ('label raster', r'project::surface::GridSurface::from_grid'),
 ('classify', r'classify::'),
 ('lidar cue', r'cues::lidar|cues::reflectivity|LidarCueModel'),
 ('stereo cue', r'cues::stereo'),
 ('cue evidence into grid', r'cues::frame|grid::evidence|add_evidence'),
 ('ingest', r'grid::ingest|ingest_chunked|fuse_bucket|bin_chunk'),
 ('water stage (window hazard map)', r'hazard::window|publish_now|water::|hazard::'),
 ('recentre', r'recentre|RollingGrid::recenter|move_to'),
 ('export (end of build)', r'io::export|finish_map'),
 ('log reading and decoding', r'io::frames|io::mcap|io::ros|ZSTD|zstd'),
]
within = sys.argv[sys.argv.index('--within') + 1] if '--within' in sys.argv else None
by_fn = collections.Counter()
cnt = collections.Counter()
total = 0
stack = []
def flush():
    global total
    if not stack: return
    total += 1
    for f in stack:
        for name, p in pats:
            if re.search(p, f):
                cnt[name] += 1
                if within and within in name:
                    fn = next((re.sub(r'::\{\{closure\}\}.*|\s*\(inlined\)', '', m.group(0))
                               for g in stack for m in [re.search(r'tarn::[\w:]+(\{\{closure\}\})?', g)] if m), '?')
                    by_fn[fn] += 1
                return
    cnt['other: ' + (stack[0][:60] if stack else '?')] += 1
for line in open(sys.argv[1], errors='replace'):
    if not line.strip():
        flush(); stack = []; continue
    if line.startswith((' ', '\t')):
        parts = line.strip().split(None, 1)
        if len(parts) == 2: stack.append(parts[1])
flush()
other = sum(v for k, v in cnt.items() if k.startswith('other'))
for k, v in cnt.most_common():
    if not k.startswith('other'): print(f'{100*v/total:5.1f}%  {k}')
print(f'{100*other/total:5.1f}%  other (allocator, kernel, thread pool)')
print(f'{total} samples')
for k, v in cnt.most_common(8):
    if k.startswith('other'): print('   ', f'{100*v/total:4.1f}%', k)
if within:
    n = sum(by_fn.values())
    print(f'\nstages matching {within!r}: {n} samples, by innermost tarn function')
    for k, v in by_fn.most_common(20):
        print(f'{100*v/max(n, 1):5.1f}%  {k}')
