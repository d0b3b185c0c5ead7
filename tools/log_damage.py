"""Damages a chunked MCAP log one chunk at a time and compares tarn with the official reader.

    python tools/log_damage.py LOG {flip,overwrite,truncate}[-nosummary] [--build]

flip: one bit flipped in each chunk's compressed records; overwrite: 4 KiB of each chunk
overwritten; truncate: the file cut at 5 %, 10 %, ... 95 %. `-nosummary` also zeroes the
footer's magic so that tarn cannot use the chunk index. For each case: whether the
official reader (validate_crcs=True) rejects it, tarn's status and message count
(`tarn info --json`), and whether tarn kept exactly the messages of every undamaged chunk
and named the damaged chunk's byte range. With --build, also `tarn build` each case and
count the maps that changed under exit status 0. TARN_BIN names the binary."""
import io
import json
import os
import random
import subprocess
import sys
import tempfile

from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

TARN = os.environ.get("TARN_BIN", "target/debug/tarn")
MAGIC = b"\x89MCAP0\r\n"


def chunks(data):
    r = make_reader(io.BytesIO(data))
    return sorted(r.get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)


def messages_in(data, c):
    rec = data[c.chunk_start_offset:c.chunk_start_offset + c.chunk_length]
    for r in StreamReader(io.BytesIO(MAGIC + rec), emit_chunks=True).records:
        if isinstance(r, Chunk):
            return sum(isinstance(x, Message) for x in breakup_chunk(r))
    return 0


def official_rejects(data):
    try:
        for _ in make_reader(io.BytesIO(data), validate_crcs=True).iter_messages(log_time_order=False):
            pass
        return False
    except Exception:
        return True


def tarn_info(path):
    o = subprocess.run([TARN, "info", path, "--json"], capture_output=True, text=True)
    try:
        j = json.loads(o.stdout)
        return o.returncode, j["messages"], j["damaged"]
    except (ValueError, KeyError):
        return o.returncode, None, None


def main():
    path, mode = sys.argv[1], sys.argv[2]
    build = "--build" in sys.argv
    nosummary = mode.endswith("-nosummary")
    mode = mode.removesuffix("-nosummary")
    data = open(path, "rb").read()
    cs = chunks(data)
    per = {c.chunk_start_offset: messages_in(data, c) for c in cs}
    total = sum(per.values())
    print(f"{path}: {len(cs)} chunks, {total} messages in chunks")
    tmp = tempfile.mkdtemp()
    base = None
    if build:
        subprocess.run([TARN, "build", path, "--out", f"{tmp}/base"], capture_output=True, check=True)
        base = open(f"{tmp}/base/map.ply", "rb").read()
    rng = random.Random(1)
    stats = dict(cases=0, official_rejects=0, status3=0, kept_exact=0, range_exact=0)
    kept = []
    cases = []
    if mode == "truncate":
        for k in range(1, 20):
            cut = len(data) * k // 20
            through = [c for c in cs if c.chunk_start_offset < cut < c.chunk_start_offset + c.chunk_length]
            start = through[0].chunk_start_offset if through else None
            expect = sum(per[c.chunk_start_offset] for c in cs if c.chunk_start_offset + c.chunk_length <= cut)
            cases.append((bytes(data[:cut]), expect, (start, cut), f"cut at {cut}"))
    else:
        for i, c in enumerate(cs):
            d = bytearray(data)
            start, end = c.chunk_start_offset, c.chunk_start_offset + c.chunk_length
            body = start + 9 + 8 + 8 + 8 + 4 + 4 + len(c.compression) + 8
            if mode == "flip":
                at = rng.randrange(body, end)
                d[at] ^= 1 << rng.randrange(8)
            else:
                at = rng.randrange(start, max(start + 1, end - 64))
                n = min(4096, end - at)
                d[at:at + n] = bytes(rng.randrange(256) for _ in range(n))
            if nosummary:
                d[-8:] = bytes(8)
            cases.append((bytes(d), total - per[start], (start, end), f"chunk {i} byte {at}"))
    for d, expect, rng_want, name in cases:
        p = f"{tmp}/case.mcap"
        open(p, "wb").write(d)
        rej = official_rejects(d)
        rc, n, dmg = tarn_info(p)
        exact = bool(dmg) and (dmg[0]["start_byte"], dmg[0]["end_byte"]) == rng_want
        stats["cases"] += 1
        stats["official_rejects"] += rej
        stats["status3"] += rc == 3
        stats["kept_exact"] += n == expect
        stats["range_exact"] += exact
        kept.append(n or 0)
        if build:
            o = subprocess.run([TARN, "build", p, "--out", f"{tmp}/out"], capture_output=True)
            key = f"build_status_{o.returncode}"
            stats[key] = stats.get(key, 0) + 1
            if o.returncode == 0 and open(f"{tmp}/out/map.ply", "rb").read() != base:
                stats["map_changed_silently"] = stats.get("map_changed_silently", 0) + 1
            subprocess.run(["rm", "-rf", f"{tmp}/out"])
        print(f"{name}: official {'rejects' if rej else 'accepts'}; tarn status {rc}, "
              f"{n} messages (expect {expect}), damaged {[(x['start_byte'], x['end_byte']) for x in dmg or []]}")
    kept.sort()
    stats["median_kept"] = kept[len(kept) // 2]
    print(json.dumps(stats))


if __name__ == "__main__":
    main()
