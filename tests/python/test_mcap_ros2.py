"""Cross-checks tarn's MCAP reading and writing against the official Python `mcap` and
`mcap-ros2-support` packages.

1. Python writes a ROS 2 log (TF, PointCloud2 in odd layouts, images of four encodings with
   padded rows, CameraInfo, a message of a type tarn does not read); `tarn info --json
   --dump-messages` must report the same values.
2. tarn re-encodes that log with its own writer (`tarn recode`); the official reader must read
   every message back with the values Python wrote.

The tarn binary comes from $TARN_BIN, else target/release/tarn, else target/debug/tarn.
"""

import json
import math
import os
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.reader import read_ros2_messages
from mcap_ros2.writer import Writer

ROOT = Path(__file__).resolve().parents[2]


def tarn_bin() -> str:
    env = os.environ.get("TARN_BIN")
    if env:
        return env
    for p in (ROOT / "target/release/tarn", ROOT / "target/debug/tarn"):
        if p.exists():
            return str(p)
    pytest.skip("no tarn binary: build it or set TARN_BIN")


SEP = "=" * 80 + "\n"
TIME = "MSG: builtin_interfaces/Time\n# Time\nint32 sec\nuint32 nanosec\n"
HEADER = "MSG: std_msgs/Header\n# Standard metadata\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
TF_DEF = (
    "geometry_msgs/TransformStamped[] transforms\n" + SEP
    + "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\n"
    "geometry_msgs/Transform transform\n" + SEP + HEADER + SEP + TIME + SEP
    + "MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n"
    + SEP + "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n" + SEP
    + "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
)
PC2_DEF = (
    "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\n"
    "bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n"
    + SEP + HEADER + SEP + TIME + SEP
    + "MSG: sensor_msgs/PointField\nuint8 INT8    = 1\nuint8 UINT8   = 2\nuint8 INT16   = 3\n"
    "uint8 UINT16  = 4\nuint8 INT32   = 5\nuint8 UINT32  = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\n"
    "string name\nuint32 offset\nuint8 datatype\nuint32 count\n"
)
IMAGE_DEF = (
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n"
    "uint32 step\nuint8[] data\n" + SEP + HEADER + SEP + TIME
)
INFO_DEF = (
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n"
    "float64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\n"
    "sensor_msgs/RegionOfInterest roi\n" + SEP + HEADER + SEP + TIME + SEP
    + "MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\n"
    "uint32 width\nbool do_rectify\n"
)
STRING_DEF = "string data\n"
FIX_DEF = (
    "std_msgs/Header header\nsensor_msgs/NavSatStatus status\nfloat64 latitude\nfloat64 longitude\n"
    "float64 altitude\nfloat64[9] position_covariance\nuint8 position_covariance_type\n"
    + SEP + HEADER + SEP + TIME + SEP
    + "MSG: sensor_msgs/NavSatStatus\nint8 STATUS_NO_FIX = -1\nint8 status\nuint16 service\n"
)

T0 = 1_700_000_000 * 10**9


def stamp(ns):
    return {"sec": ns // 10**9, "nanosec": ns % 10**9}


def header(ns, frame):
    return {"stamp": stamp(ns), "frame_id": frame}


def quat_yaw(yaw):
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def transform(parent, child, ns, xyz, yaw):
    return {
        "header": header(ns, parent),
        "child_frame_id": child,
        "transform": {"translation": dict(zip("xyz", xyz)), "rotation": quat_yaw(yaw)},
    }


# PointField datatypes
F32, F64, U8, U16 = 7, 8, 2, 4


def lidar_cloud(k, rng):
    """A 3 × 5 organized cloud with fields out of order, uint16 intensity first, uint8
    reflectivity last, and 4 bytes of padding at the end of each row."""
    h, w, ps = 3, 5, 20
    rs = ps * w + 4
    data = bytearray(rs * h)
    xyz = rng.uniform(-20, 20, size=(h * w, 3)).astype(np.float32)
    xyz[(k + 1) % (h * w)] = np.nan  # missing return as NaN
    xyz[(k + 7) % (h * w)] = 0.0  # missing return as all-zero
    inten = rng.integers(0, 65535, size=h * w)
    refl = rng.integers(0, 255, size=h * w)
    for i in range(h * w):
        r, c = divmod(i, w)
        o = r * rs + c * ps
        struct.pack_into("<H", data, o, int(inten[i]))
        struct.pack_into("<fff", data, o + 4, *xyz[i])
        struct.pack_into("<B", data, o + 16, int(refl[i]))
    fields = [
        {"name": "intensity", "offset": 0, "datatype": U16, "count": 1},
        {"name": "x", "offset": 4, "datatype": F32, "count": 1},
        {"name": "y", "offset": 8, "datatype": F32, "count": 1},
        {"name": "z", "offset": 12, "datatype": F32, "count": 1},
        {"name": "reflectivity", "offset": 16, "datatype": U8, "count": 1},
    ]
    msg = dict(height=h, width=w, fields=fields, is_bigendian=False, point_step=ps,
               row_step=rs, data=bytes(data), is_dense=False)
    return msg, xyz, inten, refl


def stereo_cloud(rng):
    """Unorganized, float64 coordinates, big-endian data flag."""
    n = 4
    xyz = rng.uniform(1, 10, size=(n, 3))
    data = b"".join(struct.pack(">ddd", *p) for p in xyz)
    fields = [{"name": a, "offset": 8 * i, "datatype": F64, "count": 1} for i, a in enumerate("xyz")]
    msg = dict(height=1, width=n, fields=fields, is_bigendian=True, point_step=24,
               row_step=24 * n, data=data, is_dense=True)
    return msg, xyz.astype(np.float32)


def image(enc, w, h, pad, rng):
    bpp = {"rgb8": 3, "bgr8": 3, "mono8": 1, "mono16": 2}[enc]
    step = w * bpp + pad
    data = rng.integers(0, 256, size=step * h, dtype=np.uint8).tobytes()
    return dict(height=h, width=w, encoding=enc, is_bigendian=0, step=step, data=data)


def expected_pixels(m):
    a = np.frombuffer(m["data"], dtype=np.uint8).reshape(m["height"], m["step"])
    w = m["width"]
    if m["encoding"] in ("rgb8", "bgr8"):
        p = a[:, : 3 * w].reshape(-1, 3)
        if m["encoding"] == "bgr8":
            p = p[:, ::-1]
        return p.tolist()
    if m["encoding"] == "mono8":
        return a[:, :w].reshape(-1).tolist()
    return a[:, : 2 * w].copy().view("<u2").reshape(-1).tolist()


def write_python_log(path):
    """Writes the log; returns what tarn must find in it."""
    rng = np.random.default_rng(7)
    expect = {"clouds": [], "stereo": [], "images": [], "tf": [], "infos": [], "fixes": []}
    with open(path, "wb") as f:
        w = Writer(f)
        s_tf = w.register_msgdef("tf2_msgs/msg/TFMessage", TF_DEF)
        s_pc = w.register_msgdef("sensor_msgs/msg/PointCloud2", PC2_DEF)
        s_im = w.register_msgdef("sensor_msgs/msg/Image", IMAGE_DEF)
        s_ci = w.register_msgdef("sensor_msgs/msg/CameraInfo", INFO_DEF)
        s_str = w.register_msgdef("std_msgs/msg/String", STRING_DEF)
        s_fix = w.register_msgdef("sensor_msgs/msg/NavSatFix", FIX_DEF)
        statics = [transform("base_link", "lidar", T0, (0.5, 0.0, 1.8), 0.0),
                   transform("base_link", "camera_optical", T0, (0.3, 0.0, 1.5), 0.2)]
        w.write_message("/tf_static", s_tf, {"transforms": statics}, log_time=T0)
        expect["tf"].append(statics)
        infos = [
            ("/camera/camera_info", "plumb_bob", [0.1, -0.05, 0.001, 0.002, 0.01]),
            ("/swir/camera_info", "equidistant", [0.02, 0.003, -0.001, 0.0005]),
        ]
        for topic, model, d in infos:
            k = [400.0, 0.0, 320.5, 0.0, 401.0, 240.5, 0.0, 0.0, 1.0]
            p = [400.0, 0.0, 320.5, 0.0, 0.0, 401.0, 240.5, 0.0, 0.0, 0.0, 1.0, 0.0]
            msg = dict(header=header(T0, "camera_optical"), height=480, width=640, distortion_model=model,
                       d=d, k=k, r=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], p=p, binning_x=0, binning_y=0,
                       roi=dict(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
            w.write_message(topic, s_ci, msg, log_time=T0)
            expect["infos"].append((topic, msg))
        # 1 s of driving: TF at 50 Hz, lidar at 10 Hz from 0.05 s, images after each scan.
        events = []
        for i in range(51):
            events.append((T0 + i * 20_000_000, "tf", i))
        for k in range(10):
            events.append((T0 + 50_000_000 + k * 100_000_000 + 15_000_000, "scan", k))
        for k in range(2):
            events.append((T0 + 300_000_000 + k * 500_000_000, "fix", k))
        events.append((T0 + 500_000_000, "diag", 0))
        events.append((T0 + 600_000_000, "diag", 1))
        for log_ns, kind, k in sorted(events):
            if kind == "tf":
                ns = T0 + k * 20_000_000
                t = ns / 1e9 - T0 / 1e9
                tf = [transform("map", "base_link", ns, (2.0 * t, 0.1 * t, 0.0), 0.3 * t)]
                w.write_message("/tf", s_tf, {"transforms": tf}, log_time=log_ns)
                expect["tf"].append(tf)
            elif kind == "fix":
                # The second has no fix: its position is not used, and it is no error.
                fix = dict(header=header(log_ns, "gps"), status=dict(status=-k, service=1),
                           latitude=34.2 + 1e-6 * k, longitude=-118.17, altitude=350.5,
                           position_covariance=[0.5, 0, 0, 0, 0.5, 0, 0, 0, 2.0],
                           position_covariance_type=2)
                w.write_message("/gps/fix", s_fix, fix, log_time=log_ns)
                expect["fixes"].append(fix)
            elif kind == "diag":
                w.write_message("/diagnostics", s_str, {"data": "ok"}, log_time=log_ns)
            else:
                ns = T0 + 50_000_000 + k * 100_000_000
                msg, xyz, inten, refl = lidar_cloud(k, rng)
                msg["header"] = header(ns, "lidar")
                w.write_message("/lidar/points", s_pc, msg, log_time=log_ns)
                expect["clouds"].append((msg, xyz, inten, refl))
                smsg, sxyz = stereo_cloud(rng)
                smsg["header"] = header(ns + 5_000_000, "camera_optical")
                w.write_message("/stereo/points", s_pc, smsg, log_time=log_ns + 1)
                expect["stereo"].append((smsg, sxyz))
                for topic, enc, pad in [("/camera/image", "rgb8", 5), ("/camera2/image", "bgr8", 0),
                                        ("/swir/image", "mono16", 2), ("/mwir/image", "mono8", 3)]:
                    im = image(enc, 7, 4, pad, rng)
                    im["header"] = header(ns + 10_000_000, "camera_optical")
                    w.write_message(topic, s_im, im, log_time=log_ns + 2)
                    expect["images"].append((topic, im))
        w.finish()
    return expect


def run_tarn(*args):
    r = subprocess.run([tarn_bin(), *map(str, args)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r.stdout


def same_float(a, b, tol=0.0):
    if a is None or b is None or (isinstance(b, float) and math.isnan(b)):
        return (a is None or math.isnan(a)) and (b is None or math.isnan(b))
    return abs(a - b) <= tol


def test_tarn_reads_what_python_wrote(tmp_path):
    log = tmp_path / "py.mcap"
    expect = write_python_log(log)
    out = json.loads(run_tarn("info", log, "--json", "--dump-messages"))

    counts = {t["topic"]: (t["type"], t["count"]) for t in out["topics"]}
    assert counts["/lidar/points"] == ("sensor_msgs/msg/PointCloud2", 10)
    assert counts["/tf"] == ("tf2_msgs/msg/TFMessage", 51)
    assert counts["/camera/image"] == ("sensor_msgs/msg/Image", 10)
    assert counts["/diagnostics"] == ("std_msgs/msg/String", 2)
    # Log times run from T0 to the last TF message at 1.0 s.
    assert out["duration_s"] == pytest.approx(1.0, abs=1e-9)

    # Frames: TF covers 0..1 s, scans at 0.05..0.95 s: all ten built.
    assert out["frames"]["frames_built"] == 10
    assert out["frames"]["frames_skipped_no_tf"] == 0
    assert out["frames"]["unknown_type"] == {"/diagnostics (std_msgs/msg/String)": 2}
    assert out["errors"] == []

    msgs = out["messages_decoded"]
    clouds = [m for m in msgs if m["topic"] == "/lidar/points"]
    assert len(clouds) == 10
    for m, (src, xyz, inten, refl) in zip(clouds, expect["clouds"]):
        assert m["stamp"] == [src["header"]["stamp"]["sec"], src["header"]["stamp"]["nanosec"]]
        assert (m["rows"], m["cols"]) == (3, 5)
        for got, want in zip(m["xyz"], xyz.tolist()):
            if any(math.isnan(v) for v in want) or want == [0.0, 0.0, 0.0]:
                assert got == [None, None, None]
            else:
                assert got == want  # float32 values survive exactly
        assert m["intensity"] == [float(v) for v in inten]
        assert m["reflectivity"] == [float(v) for v in refl]
    stereo = [m for m in msgs if m["topic"] == "/stereo/points"]
    for m, (src, xyz) in zip(stereo, expect["stereo"]):
        assert m["xyz"] == xyz.tolist()
        assert m["intensity"] is None

    images = [m for m in msgs if m["type"] == "sensor_msgs/msg/Image"]
    assert len(images) == len(expect["images"]) == 40
    for m, (topic, src) in zip(images, expect["images"]):
        assert m["topic"] == topic
        assert (m["width"], m["height"], m["encoding"]) == (src["width"], src["height"], src["encoding"])
        assert m["pixels"] == expected_pixels(src)

    tfs = [m for m in msgs if m["type"] == "tf2_msgs/msg/TFMessage"]
    assert len(tfs) == len(expect["tf"])
    for m, src in zip(tfs, expect["tf"]):
        for g, s in zip(m["transforms"], src):
            assert (g["parent"], g["child"]) == (s["header"]["frame_id"], s["child_frame_id"])
            tr = s["transform"]
            assert g["translation"] == [tr["translation"][a] for a in "xyz"]
            assert g["rotation"] == [tr["rotation"][a] for a in "xyzw"]

    infos = [m for m in msgs if m["type"] == "sensor_msgs/msg/CameraInfo"]
    for m, (topic, src) in zip(infos, expect["infos"]):
        assert m["topic"] == topic
        assert (m["distortion_model"], m["d"], m["k"], m["p"]) == (
            src["distortion_model"], src["d"], src["k"], src["p"])

    fixes = [m for m in msgs if m["type"] == "sensor_msgs/msg/NavSatFix"]
    assert len(fixes) == len(expect["fixes"]) == 2
    for m, src in zip(fixes, expect["fixes"]):
        assert (m["status"], m["latitude"], m["longitude"], m["altitude"]) == (
            src["status"]["status"], src["latitude"], src["longitude"], src["altitude"])


def to_plain(v):
    """A decoded ROS message as plain Python values (bytes as lists)."""
    if isinstance(v, (bytes, bytearray)):
        return list(v)
    if isinstance(v, (list, tuple)):
        return [to_plain(x) for x in v]
    if hasattr(v, "__slots__"):
        return {k: to_plain(getattr(v, k)) for k in v.__slots__}
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    return v


@pytest.mark.parametrize("flags", [[], ["--compression", "lz4"], ["--compression", "none", "--unchunked"]])
def test_python_reads_what_tarn_wrote(tmp_path, flags):
    src = tmp_path / "py.mcap"
    write_python_log(src)
    dst = tmp_path / "tarn.mcap"
    out = run_tarn("recode", src, "--out", dst, *flags)
    assert "skipped 2 messages of unknown type on /diagnostics" in out

    original = [(m.channel.topic, m.log_time_ns, to_plain(m.ros_msg))
                for m in read_ros2_messages(str(src)) if m.channel.topic != "/diagnostics"]
    rewritten = [(m.channel.topic, m.log_time_ns, to_plain(m.ros_msg)) for m in read_ros2_messages(str(dst))]
    assert len(rewritten) == len(original) == 1 + 2 + 51 + 10 * 6 + 2
    for a, b in zip(original, rewritten):
        assert a == b

    report = json.loads(run_tarn("recode", src, "--out", tmp_path / "again.mcap", *flags, "--json"))
    assert report == {"written": len(original), "skipped_unknown": {"/diagnostics": 2}, "damaged": []}

    with open(dst, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        assert header.profile == "ros2"
        summary = reader.get_summary()
        if "--unchunked" not in flags:
            assert summary is not None and len(summary.chunk_indexes) >= 1
        schemas = {s.name: s for s in summary.schemas.values()}
        assert set(schemas) == {"tf2_msgs/msg/TFMessage", "sensor_msgs/msg/PointCloud2",
                                "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo",
                                "sensor_msgs/msg/NavSatFix"}
        for s in schemas.values():
            assert s.encoding == "ros2msg"
        pc2 = schemas["sensor_msgs/msg/PointCloud2"].data.decode()
        assert ("\n" + "=" * 80 + "\nMSG: sensor_msgs/PointField\n") in pc2
        for c in summary.channels.values():
            assert c.message_encoding == "cdr"
