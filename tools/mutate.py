#!/usr/bin/env python3
"""Mutation campaign: runs the release `tarn` binary on mutated and hand-made inputs of every
kind it reads, each under an address-space limit and a wall-clock limit, and counts what
happened.

    tools/mutate.py --tarn target/release/tarn --work /tmp/tarn-mutate --cases 500

Input kinds (each gets `--cases` cases: the hand-made semantic cases first, then byte
mutations of the seeds):

    ply_bin, ply_ascii, kitti   tarn build CLOUD --out DIR
    mcap_build                  tarn build LOG --out DIR
    mcap_info                   tarn info LOG --json
    db3_build, db3_info         the same on a rosbag2 sqlite3 file (.db3)
    bag_build, bag_info         the same on a ROS 1 bag (.bag)
    config                      tarn build SEED_LOG --config CFG.toml --out DIR
    colour_model                tarn classify IMG.png --model MODEL.json --out MASK.png
    scene                       tarn simulate SCENE.toml --out DIR --no-noise

Seeds are made here: small clouds written by this script, a short simulated log
(`tarn simulate` of a 3-frame copy of maps/default.toml), its config and scene, and the
committed `fuzz/corpus` files of each kind (the ROS 1 bags: `fuzz/corpus/ros1_bag`; the
.db3 seed is the simulated log's messages copied into rosbag2's tables). Byte mutations are bit flips, bytes set to
0/0xff/random, truncations, overwritten runs, duplicated and deleted ranges, and (text
kinds) numbers replaced by 1e30, -1e30, inf, nan, 0, -1 or a 20-digit integer. Semantic
log cases rewrite messages of the seed log through mcap_ros2 (needs the `mcap` and
`mcap-ros2-support` packages, as in tools/requirements.txt): a pose jump, NaN, zero and
non-unit quaternions, points at ±1e30, 1e20 and inf, 0×0 images, zero and NaN focal
lengths, a cloud whose width × height disagrees with its data, point_step smaller than its
fields, bad steps and stamps.

A run is clean when it exits 0, 1 or 3 without "panicked" on stderr. Anything else is a
failure: a panic (exit 101 or "panicked"), an abort (killed by a signal, e.g. SIGABRT when an
allocation fails under the limit), a timeout, another exit code, or a run that exited 1 and
left files in its (fresh) output directory (a damaged log's partial map is counted apart). Peak
RSS is tarn's own, from GNU time; the limits are set with prlimit. Failing
inputs are copied to WORK/failures/. The table (Markdown) goes to stdout and to
WORK/table.md; every case to WORK/cases.jsonl.
"""

import argparse
import concurrent.futures as cf
import json
import os
import random
import re
import shutil
import signal
import struct
import subprocess
import sqlite3
import sys
import time
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CLEAN = (0, 1, 3)


# ---------------------------------------------------------------------------------------
# running one case


def run_case(args, timeout_s, mem_bytes, out_dir=None):
    """Runs `args` under GNU time and prlimit; returns what happened.

    The peak RSS is the one `time` reads with wait4 for the child it forks: a small
    process, so the figure is tarn's own (a child forked from this script would carry the
    script's resident pages in its peak)."""
    if out_dir is not None:
        shutil.rmtree(out_dir, ignore_errors=True)
    t0 = time.monotonic()
    tag = str(out_dir or "/tmp/tarn-mutate-case")
    err_path, rss_path = Path(tag + ".stderr"), Path(tag + ".time")
    wrapped = [
        "/usr/bin/time", "-o", str(rss_path), "-f", "maxrss_kb %M",
        "prlimit", "--as=%d" % mem_bytes, "--core=0", "--",
    ] + args
    with open(err_path, "wb") as err:
        p = subprocess.Popen(
            wrapped,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=err,
            start_new_session=True,
            env={**os.environ, "RAYON_NUM_THREADS": "1", "RUST_BACKTRACE": "0"},
        )
        timed_out = False
        try:
            p.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            timed_out = True
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    secs = time.monotonic() - t0
    stderr = err_path.read_bytes()[-4000:].decode("utf-8", "replace")
    err_path.unlink(missing_ok=True)
    report = rss_path.read_text() if rss_path.exists() else ""
    rss_path.unlink(missing_ok=True)
    m = re.search(r"maxrss_kb (\d+)", report)
    rss_kb = int(m.group(1)) if m else 0
    m = re.search(r"terminated by signal (\d+)", report)
    sig = int(m.group(1)) if m else None
    code = -sig if sig is not None else p.returncode
    if timed_out:
        kind = "timeout"
    elif sig is not None:
        kind = "abort"
    elif code == 101 or "panicked" in stderr:
        kind = "panic"
    elif code not in CLEAN:
        kind = "other"
    else:
        kind = "clean"
    left = []
    if out_dir is not None and code == 1 and out_dir.exists():
        left = sorted(str(q.relative_to(out_dir)) for q in out_dir.rglob("*"))
        if left and kind == "clean":
            # A damaged log's partial map exits 1 until damaged inputs exit 3.
            damaged = "the map holds what came before the damage" in stderr
            kind = "damaged_partial" if damaged else "left_outputs"
    if out_dir is not None:
        shutil.rmtree(out_dir, ignore_errors=True)
    return {
        "result": kind,
        "exit": code,
        "signal": sig,
        "rss_kb": rss_kb,
        "seconds": round(secs, 3),
        "left": left,
        "stderr": stderr[-600:],
    }


# ---------------------------------------------------------------------------------------
# byte mutations

SPECIAL_NUMBERS = [b"1e30", b"-1e30", b"inf", b"-inf", b"nan", b"0", b"-1", b"99999999999999999999", b"1e-30"]
NUMBER = re.compile(rb"-?\d+(\.\d+)?([eE][-+]?\d+)?")


def mutate_bytes(rng, data, text=False):
    d = bytearray(data)
    ops = rng.randint(1, 4)
    for _ in range(ops):
        if not d:
            d = bytearray(rng.randbytes(rng.randint(1, 64)))
            continue
        op = rng.choice(
            ["flip", "byte", "truncate", "run", "dup", "delete"] + (["number"] * 4 if text else [])
        )
        i = rng.randrange(len(d))
        if op == "flip":
            d[i] ^= 1 << rng.randrange(8)
        elif op == "byte":
            d[i] = rng.choice([0, 0xFF, 0x7F, 0x80, rng.randrange(256)])
        elif op == "truncate":
            d = d[:i]
        elif op == "run":
            n = rng.randint(2, 64)
            fill = rng.choice(["zero", "ff", "random"])
            b = {
                "zero": bytes(n),
                "ff": b"\xff" * n,
                "random": rng.randbytes(n),
            }[fill]
            d[i : i + n] = b
        elif op == "dup":
            n = rng.randint(1, 256)
            d[i:i] = d[i : i + n]
        elif op == "delete":
            n = rng.randint(1, 64)
            del d[i : i + n]
        elif op == "number":
            nums = list(NUMBER.finditer(bytes(d)))
            if nums:
                m = rng.choice(nums)
                d[m.start() : m.end()] = rng.choice(SPECIAL_NUMBERS)
    return bytes(d)


# ---------------------------------------------------------------------------------------
# seeds


def ramp_points(n_side, step=0.1):
    pts = []
    for j in range(n_side):
        for i in range(n_side):
            x, y = i * step, j * step
            pts.append((x, y, 0.05 * x + 0.02 * y))
    return pts


def ply_binary(pts, intensity=True):
    head = (
        "ply\nformat binary_little_endian 1.0\nelement vertex %d\n"
        "property float x\nproperty float y\nproperty float z\n" % len(pts)
    )
    if intensity:
        head += "property uchar intensity\n"
    head += "end_header\n"
    body = bytearray()
    for k, p in enumerate(pts):
        body += struct.pack("<3f", *p)
        if intensity:
            body += bytes([k % 256])
    return head.encode() + bytes(body)


def ply_ascii(pts):
    head = (
        "ply\nformat ascii 1.0\nelement vertex %d\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n" % len(pts)
    )
    return (head + "".join("%g %g %g\n" % p for p in pts)).encode()


def kitti(pts):
    return b"".join(struct.pack("<4f", *p, 0.5) for p in pts)


def png_rgb(w, h, pixel):
    raw = b"".join(b"\x00" + b"".join(bytes(pixel(x, y)) for x in range(w)) for y in range(h))

    def chunk(t, d):
        c = struct.pack(">I", len(d)) + t + d
        return c + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)

    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


CONFIG_SEED = """[grid]
resolution = 0.1
size_cells = 400

[fusion]

[vehicle]

[lidar]
cues = true
reflectivity = true
dry_limit_m = 40.0
max_range_m = 300.0

[stereo]
reflections = true
mirror_check = true
max_range_m = 200.0

[log]
tolerance_s = 0.05
lookahead_s = 0.5
max_speed_mps = 30.0

[build]
max_window_cells = 2048
"""


def db3_of(mcap_path, db3_path):
    """The messages of an MCAP log (CDR as they are) in rosbag2's sqlite3 tables; the
    file's bytes."""
    from mcap.reader import make_reader

    if db3_path.exists():
        db3_path.unlink()
    db = sqlite3.connect(db3_path)
    db.executescript(
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,"
        " serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);"
        "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,"
        " timestamp INTEGER NOT NULL, data BLOB NOT NULL);")
    ids = {}
    with open(mcap_path, "rb") as f:
        for schema, channel, m in make_reader(f).iter_messages(log_time_order=False):
            if channel.topic not in ids:
                ids[channel.topic] = len(ids) + 1
                db.execute("INSERT INTO topics VALUES (?, ?, ?, 'cdr', '')",
                           (ids[channel.topic], channel.topic, schema.name))
            db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (?, ?, ?)",
                       (ids[channel.topic], m.log_time, m.data))
    db.commit()
    db.close()
    return db3_path.read_bytes()


def corpus(name):
    d = ROOT / "fuzz" / "corpus" / name
    return sorted(p for p in d.iterdir() if p.name.startswith("seed-")) if d.exists() else []


def make_seeds(tarn, work):
    s = work / "seeds"
    s.mkdir(parents=True, exist_ok=True)
    seeds = {}
    pts = ramp_points(50)
    far = ramp_points(20) + [(1e6, 0.0, 0.0)]
    seeds["ply_bin"] = [("ramp.ply", ply_binary(pts)), ("far.ply", ply_binary(far, False))] + [
        (p.name, p.read_bytes()) for p in corpus("ply") if b"binary" in p.read_bytes()[:64]
    ]
    seeds["ply_ascii"] = [("ramp.ply", ply_ascii(ramp_points(25)))] + [
        (p.name, p.read_bytes()) for p in corpus("ply") if b"ascii" in p.read_bytes()[:64]
    ]
    seeds["kitti"] = [("ramp.bin", kitti(pts))] + [(p.name, p.read_bytes()) for p in corpus("kitti")]
    # A short simulated drive: its scene, log and config.
    scene = (ROOT / "maps" / "default.toml").read_text()
    scene = re.sub(r"(?m)^frames = \d+", "frames = 3", scene)
    scene = scene.replace('rig = "rigs/small.toml"', 'rig = "%s"' % (ROOT / "maps" / "rigs" / "small.toml"))
    (s / "scene.toml").write_text(scene)
    sim = s / "sim"
    if not (sim / "log.mcap").exists():
        r = subprocess.run([tarn, "simulate", s / "scene.toml", "--out", sim], capture_output=True)
        if r.returncode != 0:
            sys.exit("tarn simulate failed: " + r.stderr.decode())
    log = (sim / "log.mcap").read_bytes()
    seeds["mcap"] = [("log.mcap", log)] + [(p.name, p.read_bytes()) for p in corpus("mcap")]
    seeds["db3"] = [("log.db3", db3_of(sim / "log.mcap", s / "log.db3"))]
    seeds["bag"] = [(p.name, p.read_bytes()) for p in corpus("ros1_bag")]
    seeds["scene"] = [("scene.toml", scene.encode())] + [(p.name, p.read_bytes()) for p in corpus("scene_toml")]
    seeds["config"] = [("tarn.toml", CONFIG_SEED.encode())]
    seeds["colour_model"] = [(p.name, p.read_bytes()) for p in corpus("color_model_json")]
    img = s / "img.png"
    img.write_bytes(png_rgb(32, 24, lambda x, y: (40 + 5 * x, 120, 200 - 6 * y) if y > 8 else (150, 180, 230)))
    return seeds, sim / "log.mcap", img


# ---------------------------------------------------------------------------------------
# semantic cases


def cloud_semantics(kind):
    """Hand-made clouds: (name, bytes)."""
    base = ramp_points(20)
    cases = []
    values = [1e30, -1e30, 3.4e38, float("inf"), float("-inf"), float("nan"), 1e12, 1e20, -1e7, 9.9e7]
    for v in values:
        for where in ["x", "y", "z", "xyz"]:
            p = list(base)
            pt = [0.5, 0.5, 0.0]
            for c in where:
                pt["xyz".index(c)] = v
            p.append(tuple(pt))
            cases.append(("one-%s-%g" % (where, v), p))
        cases.append(("all-%g" % v, [(v, v, v)] * 50))
        cases.append(("half-%g" % v, base + [(v, y, 0.0) for (_, y, _) in base]))
    rng = random.Random(7)
    for scale in [1e3, 1e6, 1e7, 1e9]:
        cases.append(("scatter-%g" % scale, [(rng.uniform(-scale, scale), rng.uniform(-scale, scale), rng.uniform(-5, 5)) for _ in range(3000)]))
    cases.append(("one-point", [(1.0, 2.0, 3.0)]))
    cases.append(("same-point", [(1.0, 2.0, 3.0)] * 5000))
    cases.append(("line-1e6", [(x * 1000.0, 0.0, 0.0) for x in range(1000)]))
    out = []
    enc = {"ply_bin": lambda p: ply_binary(p, False), "ply_ascii": ply_ascii, "kitti": kitti}[kind]
    for name, p in cases:
        out.append((name, enc(p)))
    if kind == "ply_bin":
        good = ply_binary(base, False)
        h = good.index(b"end_header\n") + 11
        out.append(("count-larger", good.replace(b"vertex 400", b"vertex 401")))
        out.append(("count-huge", good.replace(b"vertex 400", b"vertex 4000000000000")))
        out.append(("count-smaller", good.replace(b"vertex 400", b"vertex 10")))
        out.append(("no-body", good[:h]))
        out.append(("big-endian-lie", good.replace(b"binary_little_endian", b"binary_big_endian")))
        out.append(("list-x", good.replace(b"property float x", b"property list uchar float x")))
        out.append(("double-lie", good.replace(b"property float x", b"property double x")))
    if kind == "ply_ascii":
        good = ply_ascii(base)
        out.append(("count-larger", good.replace(b"vertex 400", b"vertex 401")))
        out.append(("count-huge", good.replace(b"vertex 400", b"vertex 99999999999")))
        out.append(("extra-columns", good.replace(b"\n0 0 0\n", b"\n0 0 0 1 2 3\n")))
        out.append(("missing-columns", good.replace(b"\n0 0 0\n", b"\n0 0\n")))
    if kind == "kitti":
        good = kitti(base)
        out += [("odd-length", good[:-3]), ("empty", b""), ("one-float", good[:4])]
    return out


def mcap_semantics(seed_log, work):
    """Rewrites messages of the seed log: (name, bytes). Empty without mcap_ros2."""
    try:
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory
        from mcap_ros2.writer import Writer
    except ImportError:
        print("mcap / mcap_ros2 not installed: no semantic log cases", file=sys.stderr)
        return []
    import io
    import math

    with open(seed_log, "rb") as f:
        reader = make_reader(f)
        msgs = [(s, c, m) for s, c, m in reader.iter_messages()]
    factory = DecoderFactory()

    def rewrite(fn):
        buf = io.BytesIO()
        w = Writer(buf)
        schemas = {}
        k = {}
        for s, c, m in msgs:
            # Decoded afresh for every case: a change never leaks into the next case.
            d = factory.decoder_for(c.message_encoding, s)(m.data)
            if s.name not in schemas:
                schemas[s.name] = w.register_msgdef(s.name, s.data.decode())
            i = k.get(c.topic, 0)
            k[c.topic] = i + 1
            d2 = fn(c.topic, i, d)
            if d2 is not None:
                w.write_message(c.topic, schemas[s.name], d2, log_time=m.log_time, publish_time=m.publish_time)
        w.finish()
        return buf.getvalue()

    def on(topic, index, change):
        def fn(t, i, d):
            if t == topic and (index is None or i == index):
                r = change(d)
                return d if r is None else r
            return d

        return fn

    def tf_set(attr):
        def change(d):
            for t in d.transforms:
                attr(t.transform)

        return change

    def point_field(d, name):
        for f in d.fields:
            if f.name == name:
                return f.offset
        return None

    def cloud_value(v, count=1, name="x"):
        def change(d):
            off = point_field(d, name)
            data = bytearray(d.data)
            n = len(data) // max(d.point_step, 1)
            for j in range(min(count, n)):
                at = (j * 7919 % n) * d.point_step + off
                data[at : at + 4] = struct.pack("<f" if not d.is_bigendian else ">f", v)
            d.data = bytes(data)

        return change

    def set_attrs(**kv):
        def change(d):
            for k_, v in kv.items():
                setattr(d, k_, v)

        return change

    topics = sorted({c.topic for _, c, _ in msgs})
    n_tf = sum(c.topic == "/tf" for _, c, _ in msgs)
    # The first, second, middle and last transform, and all of them.
    tf_at = sorted({0, min(1, n_tf - 1), n_tf // 2, n_tf - 1}) + [None]
    cases = []
    tf_changes = {
        "jump-1e5": lambda tr: setattr(tr.translation, "x", tr.translation.x + 1e5),
        "jump-1e6": lambda tr: setattr(tr.translation, "x", tr.translation.x + 1e6),
        "jump-1e12": lambda tr: setattr(tr.translation, "y", 1e12),
        "jump-1e30": lambda tr: setattr(tr.translation, "x", -1e30),
        "nan-translation": lambda tr: setattr(tr.translation, "z", math.nan),
        "nan-quaternion": lambda tr: setattr(tr.rotation, "w", math.nan),
        "zero-quaternion": lambda tr: [setattr(tr.rotation, a, 0.0) for a in "xyzw"],
        "nonunit-quaternion": lambda tr: setattr(tr.rotation, "w", 2.0),
        "inf-quaternion": lambda tr: setattr(tr.rotation, "x", math.inf),
    }
    for name, ch in tf_changes.items():
        for idx in tf_at:
            cases.append(("tf-%s-at-%s" % (name, idx), on("/tf", idx, tf_set(ch))))
        cases.append(("tf_static-%s" % name, on("/tf_static", None, tf_set(ch))))
    clouds = [t for t in topics if t.endswith("points")]
    for t in clouds:
        for v in [1e30, -1e30, 1e20, 1e12, math.inf, math.nan, 3.4e38]:
            for count in [1, 50]:
                cases.append(("%s-x-%g-%d" % (t, v, count), on(t, 1, cloud_value(v, count))))
        cases.append(("%s-z-1e20-all" % t, on(t, None, cloud_value(1e20, 10**9, "z"))))
        cases.append(("%s-width-plus-1" % t, on(t, 1, lambda d: setattr(d, "width", d.width + 1))))
        cases.append(("%s-height-x1000" % t, on(t, 1, lambda d: setattr(d, "height", d.height * 1000))))
        cases.append(("%s-width-huge" % t, on(t, 1, set_attrs(width=2**31 - 1, height=2**31 - 1))))
        cases.append(("%s-zero-size" % t, on(t, 1, set_attrs(width=0, height=0))))
        cases.append(("%s-point_step-4" % t, on(t, 1, set_attrs(point_step=4))))
        cases.append(("%s-point_step-0" % t, on(t, 1, set_attrs(point_step=0))))
        cases.append(("%s-row_step-0" % t, on(t, 1, set_attrs(row_step=0))))
        cases.append(("%s-row_step-huge" % t, on(t, 1, set_attrs(row_step=2**32 - 1))))
        cases.append(("%s-no-data" % t, on(t, 1, set_attrs(data=b""))))
        cases.append(("%s-field-offset-huge" % t, on(t, 1, lambda d: setattr(d.fields[0], "offset", 2**31))))
        cases.append(("%s-field-count-huge" % t, on(t, 1, lambda d: setattr(d.fields[0], "count", 2**31))))
        cases.append(("%s-field-type-bad" % t, on(t, 1, lambda d: setattr(d.fields[0], "datatype", 99))))
        cases.append(("%s-stamp-huge" % t, on(t, 1, lambda d: setattr(d.header.stamp, "sec", 2**31 - 1))))
        cases.append(("%s-stamp-negative" % t, on(t, 1, lambda d: setattr(d.header.stamp, "sec", -(2**31)))))
    images = [t for t in topics if t.endswith("image")]
    for t in images:
        cases.append(("%s-0x0" % t, on(t, 1, set_attrs(width=0, height=0, step=0, data=b""))))
        cases.append(("%s-0x0-with-data" % t, on(t, 1, set_attrs(width=0, height=0))))
        cases.append(("%s-step-1" % t, on(t, 1, set_attrs(step=1))))
        cases.append(("%s-huge" % t, on(t, 1, set_attrs(width=2**31, height=2**31))))
        cases.append(("%s-encoding-bad" % t, on(t, 1, set_attrs(encoding="yuv422"))))
        cases.append(("%s-no-data" % t, on(t, 1, set_attrs(data=b""))))
    infos = [t for t in topics if t.endswith("camera_info")]

    def k_set(i, v):
        def change(d):
            k = list(d.k)
            k[i] = v
            d.k = k
            p = list(d.p)
            if i in (0, 4):
                p[{0: 0, 4: 5}[i]] = v
            d.p = p

        return change

    for t in infos:
        for v in [0.0, -1.0, math.nan, math.inf, 1e-300, 1e300]:
            cases.append(("%s-fx-%g" % (t, v), on(t, None, k_set(0, v))))
            cases.append(("%s-fy-%g" % (t, v), on(t, None, k_set(4, v))))
        cases.append(("%s-0x0" % t, on(t, None, set_attrs(width=0, height=0))))
        cases.append(("%s-huge" % t, on(t, None, set_attrs(width=2**31 - 1, height=2**31 - 1))))
        cases.append(("%s-binning-huge" % t, on(t, None, set_attrs(binning_x=2**31 - 1))))
        cases.append(("%s-distortion-nan" % t, on(t, None, lambda d: setattr(d, "d", [math.nan] * 5))))
        cases.append(("%s-distortion-long" % t, on(t, None, lambda d: setattr(d, "d", [0.0] * 1000))))
        cases.append(("%s-baseline-zero" % t, on(t, None, lambda d: setattr(d, "p", list(d.p[:3]) + [0.0] + list(d.p[4:])))))
    for t in topics:
        cases.append(("drop-all-%s" % t, lambda tt, i, d, t=t: None if tt == t else d))
    out = []
    for name, fn in cases:
        try:
            out.append(("sem-" + re.sub(r"[^A-Za-z0-9._+-]", "_", name) + ".mcap", rewrite(fn)))
        except Exception as e:  # a change the ROS 2 encoder itself refuses
            print("semantic case %s not written: %s" % (name, e), file=sys.stderr)
    return out


def config_semantics():
    cases = []
    for key, section in [
        ("resolution", "grid"),
        ("size_cells", "grid"),
        ("max_range_m", "lidar"),
        ("dry_limit_m", "lidar"),
        ("max_range_m", "stereo"),
        ("max_speed_mps", "log"),
        ("tolerance_s", "log"),
        ("lookahead_s", "log"),
        ("max_window_cells", "build"),
    ]:
        for v in ["0", "-1", "1e30", "inf", "nan", "1e-30", "99999999999999999999", "\"x\""]:
            text = re.sub(r"(?m)^%s = .*$" % key, "%s = %s" % (key, v), CONFIG_SEED, count=1)
            if "%s = %s" % (key, v) not in text:
                text = CONFIG_SEED.replace("[%s]\n" % section, "[%s]\n%s = %s\n" % (section, key, v))
            cases.append(("%s.%s=%s.toml" % (section, key, v.strip('"')), text.encode()))
    cases.append(("empty.toml", b""))
    cases.append(("unknown-key.toml", CONFIG_SEED.encode() + b"\n[grid2]\nx = 1\n"))
    return cases


def colour_semantics(seeds):
    cases = []
    if not seeds:
        return cases
    text = seeds[0][1].decode("utf-8", "replace")
    for v in ["0", "-1", "1e30", "-1e30", "1e-300", "NaN", "Infinity", "[]", "{}", "null"]:
        for k in range(6):
            nums = list(NUMBER.finditer(text.encode()))
            if not nums:
                break
            m = nums[(k * 37) % len(nums)]
            t = text[: m.start()] + v + text[m.end() :]
            cases.append(("num%d-%s.json" % (k, v), t.encode()))
    return cases


def scene_semantics(scene):
    cases = []
    for key in ["frames", "rate_hz", "speed", "resolution", "radius", "depth", "seed", "time_of_day", "attenuation", "level"]:
        for v in ["0", "-1", "1e30", "inf", "nan", "1e9", "1e-9"]:
            t = re.sub(r"(?m)^%s = .*$" % key, "%s = %s" % (key, v), scene, count=1)
            if t != scene:
                cases.append(("%s=%s.toml" % (key, v), t.encode()))
    for key, v in [("size", "[1e7, 1e7]"), ("size", "[0.0, 0.0]"), ("origin", "[1e30, -1e30]"), ("waypoints", "[[0.0, 0.0]]"), ("waypoints", "[[0.0, 0.0], [1e9, 0.0]]"), ("waypoints", "[]")]:
        t = re.sub(r"(?m)^%s = .*$" % key, "%s = %s" % (key, v), scene, count=1)
        cases.append(("%s=%s.toml" % (key, v), t.encode()))
    return cases


# ---------------------------------------------------------------------------------------


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tarn", default=str(ROOT / "target" / "release" / "tarn"))
    ap.add_argument("--work", default="/tmp/tarn-mutate")
    ap.add_argument("--cases", type=int, default=500, help="cases per input kind")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=60.0)
    ap.add_argument("--mem-gb", type=float, default=2.0)
    ap.add_argument("--seed", type=int, default=20261125)
    ap.add_argument("--kinds", default="all")
    a = ap.parse_args()
    tarn = str(Path(a.tarn).resolve())
    work = Path(a.work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    (work / "cases").mkdir(exist_ok=True)
    (work / "runs").mkdir(exist_ok=True)
    (work / "failures").mkdir(exist_ok=True)
    mem = int(a.mem_gb * (1 << 30))
    seeds, seed_log, img = make_seeds(tarn, work)

    # (kind, file suffix, seed list, semantic cases, text?, command builder)
    def cmd_build(f, out):
        return [tarn, "build", f, "--out", out]

    kinds = {
        "ply_bin": (".ply", seeds["ply_bin"], cloud_semantics("ply_bin"), False, cmd_build),
        "ply_ascii": (".ply", seeds["ply_ascii"], cloud_semantics("ply_ascii"), True, cmd_build),
        "kitti": (".bin", seeds["kitti"], cloud_semantics("kitti"), False, cmd_build),
        "mcap_build": (".mcap", seeds["mcap"], None, False, cmd_build),
        "mcap_info": (".mcap", seeds["mcap"], None, False, lambda f, out: [tarn, "info", f, "--json"]),
        "db3_build": (".db3", seeds["db3"], [], False, cmd_build),
        "db3_info": (".db3", seeds["db3"], [], False, lambda f, out: [tarn, "info", f, "--json"]),
        "bag_build": (".bag", seeds["bag"], [], False, cmd_build),
        "bag_info": (".bag", seeds["bag"], [], False, lambda f, out: [tarn, "info", f, "--json"]),
        "config": (".toml", seeds["config"], config_semantics(), True, lambda f, out: [tarn, "build", seed_log, "--config", f, "--out", out]),
        "colour_model": (".json", seeds["colour_model"], colour_semantics(seeds["colour_model"]), True, lambda f, out: [tarn, "classify", img, "--model", f, "--out", out / "mask.png"]),
        "scene": (".toml", seeds["scene"], scene_semantics(seeds["scene"][0][1].decode()), True, lambda f, out: [tarn, "simulate", f, "--out", out, "--no-noise"]),
    }
    mcap_sem = None
    chosen = list(kinds) if a.kinds == "all" else a.kinds.split(",")
    rows = []
    log = open(work / "cases.jsonl", "a")
    for kind in chosen:
        suffix, seed_list, semantic, text, cmd = kinds[kind]
        if semantic is None:
            if mcap_sem is None:
                mcap_sem = mcap_semantics(seed_log, work)
            semantic = mcap_sem
        rng = random.Random("%d-%s" % (a.seed, kind))
        cases = list(semantic[: a.cases])
        while len(cases) < a.cases:
            name, data = rng.choice(seed_list)
            cases.append(("mut%04d-%s" % (len(cases), name), mutate_bytes(rng, data, text)))
        case_dir = work / "cases" / kind
        case_dir.mkdir(parents=True, exist_ok=True)

        def one(i_case):
            i, (name, data) = i_case
            f = case_dir / ("%04d%s" % (i, suffix))
            f.write_bytes(data)
            out = work / "runs" / ("%s-%04d" % (kind, i))
            out_dir = out if not kind.endswith("_info") else None
            if kind == "colour_model":
                out.mkdir(parents=True, exist_ok=True)
                # classify writes one file: the output directory exists, the file must not.
                r = run_case([str(x) for x in cmd(f, out)], a.timeout, mem, None)
                if r["exit"] == 1 and (out / "mask.png").exists():
                    r["left"] = ["mask.png"]
                    if r["result"] == "clean":
                        r["result"] = "left_outputs"
                shutil.rmtree(out, ignore_errors=True)
            else:
                r = run_case([str(x) for x in cmd(f, out)], a.timeout, mem, out_dir)
            r.update(kind=kind, case=i, name=name, file=str(f))
            if r["result"] != "clean":
                shutil.copy(f, work / "failures" / ("%s-%04d-%s%s" % (kind, i, r["result"], suffix)))
            else:
                f.unlink()
            return r

        t0 = time.monotonic()
        with cf.ThreadPoolExecutor(a.jobs) as ex:
            results = list(ex.map(one, enumerate(cases)))
        for r in results:
            log.write(json.dumps(r) + "\n")
        log.flush()
        count = lambda k: sum(r["result"] == k for r in results)
        codes = lambda c: sum(r["exit"] == c for r in results)
        rss = sorted(r["rss_kb"] for r in results)
        row = {
            "kind": kind,
            "cases": len(results),
            "semantic": min(len(semantic), a.cases),
            "exit0": codes(0),
            "exit1": codes(1),
            "exit3": codes(3),
            "panics": count("panic"),
            "aborts": count("abort"),
            "timeouts": count("timeout"),
            "other": count("other"),
            "left": count("left_outputs"),
            "damaged": count("damaged_partial"),
            "rss_max_mb": rss[-1] / 1024,
            "rss_median_mb": rss[len(rss) // 2] / 1024,
            "max_s": max(r["seconds"] for r in results),
            "total_s": time.monotonic() - t0,
        }
        rows.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
        for r in results:
            if r["result"] != "clean":
                print("  %s case %d (%s): %s exit %s: %s" % (kind, r["case"], r["name"], r["result"], r["exit"], r["stderr"][-300:].replace("\n", " | ")), file=sys.stderr)
    head = "| input kind | cases (semantic) | exit 0 | exit 1 | exit 3 | panics | aborts | timeouts | other exit | outputs left by exit 1: other / damaged log's partial map | peak RSS max / median (MB) | slowest run (s) |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n"
    body = "".join(
        "| %(kind)s | %(cases)d (%(semantic)d) | %(exit0)d | %(exit1)d | %(exit3)d | %(panics)d | %(aborts)d | %(timeouts)d | %(other)d | %(left)d / %(damaged)d | %(rss_max_mb).0f / %(rss_median_mb).0f | %(max_s).1f |\n" % r
        for r in rows
    )
    table = head + body
    (work / "table.md").write_text(table)
    print(table)
    bad = sum(r["panics"] + r["aborts"] + r["timeouts"] + r["other"] + r["left"] + r["damaged"] for r in rows)
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
