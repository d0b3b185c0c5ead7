"""tarn reads the same drive from a rosbag2 sqlite3 bag and from ROS 1 bags written by the
`rosbags` library as from the MCAP log `tarn simulate` wrote, and refuses damaged bags
clearly.

1. A short simulated drive (lidar, stereo, colour camera) is written by `tarn simulate` to
   an MCAP log. Its messages are copied as they are (CDR) into rosbag2 directories with
   sqlite3 and with MCAP storage by `rosbags`' rosbag2 writer, and the sqlite3 bag is
   converted by `rosbags` into ROS 1 bags (uncompressed, bz2 and lz4 chunks).
2. `tarn info --json` counts the same messages and frames in each; `tarn build` makes the
   same map.ply (its header comments, which name the input, aside) from the MCAP log, the
   rosbag2 directories, the .db3 file and each ROS 1 bag.
3. Truncated and overwritten .db3 and .bag files, and files that are not bags at all, end
   with exit status 1 (nothing built) or 3 (built from what could be read), a message that
   names the file, and never a panic.
"""

import json
import shutil
import subprocess
from pathlib import Path

import pytest

import conftest

rosbags = pytest.importorskip("rosbags")
from mcap.reader import make_reader  # noqa: E402
from rosbags.convert import convert  # noqa: E402
from rosbags.rosbag2 import StoragePlugin  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

RIG = """name = "lidar_stereo_camera"
description = "a 32-ring lidar, a small stereo pair and its colour camera"

[lidar]
position = [0.0, 0.0, 1.8]
rings = 32
elevation_deg = [-25.0, 15.0]
columns = 512
wavelength_nm = 905.0
aperture_m = 0.0254
dry_limit_m = 40.0
range_noise_m = 0.02
intensity = "raw"

[stereo]
position = [0.2, 0.06, 1.6]
rpy_deg = [0.0, 10.0, 0.0]
width = 160
height = 120
hfov_deg = 70.0
baseline_m = 0.12
disparity_noise_px = 0.5
min_disparity_px = 1.0
bin = 2
"""

SCENE = """name = "puddle"
description = "a puddle ahead of the vehicle"
seed = 7
rig = "rig.toml"

[terrain]
origin = [-5.0, -10.0]
size = [30.0, 20.0]
resolution = 0.1
roughness = 0.02
roughness_scale = 3.0
material = "mud"

[[terrain.features]]
kind = "depression"
centre = [8.0, 1.0]
radius = [2.0, 1.5]
depth = 0.3
flat = 0.3

[[water]]
kind = "level"
level = -0.08
centre = [8.0, 1.0]
radius = 2.5
attenuation = 11.1
colour = [0.12, 0.10, 0.07]

[sky]
kind = "overcast"
time_of_day = 13.0

[trajectory]
waypoints = [[0.0, 0.0], [2.0, 0.0]]
speed = 1.0
rate_hz = 2.0
frames = 4
"""

ROS2_TYPES = {
    "tf2_msgs/msg/TFMessage",
    "sensor_msgs/msg/PointCloud2",
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CameraInfo",
}


def tarn(*args):
    return subprocess.run([conftest.tarn_bin(), *map(str, args)], capture_output=True, text=True)


def mcap_to_rosbag2(mcap_path, bag_dir, storage=StoragePlugin.SQLITE3):
    """Copies every message of the MCAP log (CDR bytes as they are, log times) into a
    rosbag2 directory with `storage`."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    conns = {}
    with open(mcap_path, "rb") as f, Writer2(bag_dir, version=8, storage_plugin=storage) as w:
        for schema, channel, m in make_reader(f).iter_messages(log_time_order=False):
            assert schema.name in ROS2_TYPES, schema.name
            if channel.topic not in conns:
                conns[channel.topic] = w.add_connection(channel.topic, schema.name,
                                                        typestore=store)
            w.write(conns[channel.topic], m.log_time, m.data)


def db3_to_bag(bag_dir, bag, compress):
    convert([bag_dir], bag, "sqlite3", 8, compress, "file",
            get_typestore(Stores.ROS2_HUMBLE), None, [], [], [], [])


def map_body(out_dir):
    """map.ply without its comment lines (which name the input)."""
    data = (out_dir / "map.ply").read_bytes()
    end = data.index(b"end_header\n")
    head = [ln for ln in data[:end].split(b"\n") if not ln.startswith(b"comment")]
    return b"\n".join(head), data[end:]


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("robot_logs")
    (d / "rig.toml").write_text(RIG)
    (d / "scene.toml").write_text(SCENE)
    r = tarn("simulate", d / "scene.toml", "--out", d / "sim")
    assert r.returncode == 0, r.stderr
    mcap = d / "sim" / "log.mcap"
    mcap_to_rosbag2(mcap, d / "rosbag2")
    mcap_to_rosbag2(mcap, d / "rosbag2-mcap", StoragePlugin.MCAP)
    db3 = next((d / "rosbag2").glob("*.db3"))
    out = {"mcap": mcap, "rosbag2": d / "rosbag2", "db3": db3, "rosbag2-mcap": d / "rosbag2-mcap"}
    for c in (None, "bz2", "lz4"):
        bag = d / f"drive-{c or 'none'}.bag"
        db3_to_bag(d / "rosbag2", bag, c)
        out[f"bag-{c or 'none'}"] = bag
    return d, out


def test_info_counts_the_same_messages_and_frames(logs):
    _, paths = logs
    ref = None
    for name, p in paths.items():
        r = tarn("info", p, "--json")
        assert r.returncode == 0, f"{name}: {r.stderr}"
        j = json.loads(r.stdout)
        counts = {t["topic"]: t["count"] for t in j["topics"]}
        got = (j["messages"], counts, j["frames"]["frames_built"], j["start_ns"], j["end_ns"],
               j["frames"]["decode_errors"], j["errors"])
        assert j["frames"]["unknown_type"] == {}, name
        if ref is None:
            ref = got
            assert got[2] == 4 and set(counts) >= {"/lidar/points", "/stereo/points", "/tf"}
        assert got == ref, name


def test_build_gives_the_same_map(logs):
    d, paths = logs
    ref = None
    for name, p in paths.items():
        out = d / f"out-{name}"
        r = tarn("build", p, "--out", out, "--json")
        assert r.returncode == 0, f"{name}: {r.stderr}"
        rep = json.loads(r.stdout)
        assert rep["frames_fused"] == 4, name
        body = map_body(out)
        if ref is None:
            ref = (body, rep["cue_counts"])
            assert rep["cells_observed"] > 1000
        assert body == ref[0], f"{name}: map.ply differs from the MCAP log's"
        assert rep["cue_counts"] == ref[1], name


def test_recode_turns_a_ros1_bag_into_the_same_mcap_messages(logs):
    d, paths = logs
    r = tarn("recode", paths["bag-lz4"], "--out", d / "recoded.mcap")
    assert r.returncode == 0, r.stderr
    with open(paths["mcap"], "rb") as a, open(d / "recoded.mcap", "rb") as b:
        n_a = sum(1 for _ in make_reader(a).iter_messages())
        n_b = sum(1 for _ in make_reader(b).iter_messages())
    assert n_a == n_b


def damaged_variants(src, d):
    data = src.read_bytes()
    n = len(data)
    cases = {
        "truncated-half": data[: n // 2],
        "truncated-tenth": data[: n // 10],
        "truncated-header": data[:40],
        "empty": b"",
        "zeroed-middle": data[: n // 3] + bytes(4096) + data[n // 3 + 4096:],
        "garbage-middle": data[: n // 2] + bytes((i * 37) & 0xFF for i in range(8192))
        + data[n // 2 + 8192:],
        "not-a-bag": b"this is not a bag\n" * 100,
    }
    for k, v in cases.items():
        p = d / f"{k}{src.suffix}"
        p.write_bytes(v)
        yield k, p


@pytest.mark.parametrize("which", ["db3", "bag-none", "bag-lz4", "bag-bz2"])
def test_damaged_bags_are_refused_or_reported_never_a_panic(logs, which, tmp_path):
    _, paths = logs
    for case, p in damaged_variants(paths[which], tmp_path):
        for args in (["info", p, "--json"], ["build", p, "--out", tmp_path / f"out-{case}"]):
            r = tarn(*args)
            err = r.stderr
            assert r.returncode in (0, 1, 3), f"{which} {case} {args[0]}: {r.returncode}\n{err}"
            assert "panicked" not in err, f"{which} {case} {args[0]}: {err}"
            if r.returncode != 0:
                assert p.name in err, f"{which} {case} {args[0]}: {err}"
        if case.startswith("truncated") and p.suffix == ".db3":
            r = tarn("info", p)
            assert r.returncode == 1 and "truncated" in r.stderr, f"{which} {case}: {r.stderr}"
        if case == "truncated-header" and p.suffix == ".bag":
            # The magic holds: what follows is reported as the cut end of the file.
            r = tarn("info", p)
            assert r.returncode == 3 and "runs past the end of the file" in r.stderr, r.stderr
            continue
        if case in ("not-a-bag", "empty", "truncated-header"):
            r = tarn("info", p)
            assert r.returncode == 1, f"{which} {case}"
            want = "not a ROS 1 bag"
            if p.suffix == ".db3":
                want = "truncated" if case == "truncated-header" else "not an SQLite database"
            assert want in r.stderr, f"{which} {case}: {r.stderr}"


def test_a_truncated_ros1_bag_builds_what_precedes_the_cut(logs, tmp_path):
    _, paths = logs
    data = paths["bag-none"].read_bytes()
    p = tmp_path / "cut.bag"
    p.write_bytes(data[: int(len(data) * 0.8)])
    r = tarn("build", p, "--out", tmp_path / "out", "--json")
    assert r.returncode == 3, r.stderr
    rep = json.loads(r.stdout)
    assert rep["frames_fused"] >= 1
    assert rep["damaged"] and rep["damaged"][-1]["resumed_by"] == "end"
    assert "cut.bag" in r.stderr and "damaged" in r.stderr


def test_rosbag2_directory_without_its_files_names_what_is_missing(logs, tmp_path):
    _, paths = logs
    d = tmp_path / "bag"
    shutil.copytree(paths["rosbag2"], d)
    for f in d.glob("*.db3"):
        f.unlink()
    r = tarn("info", d)
    assert r.returncode == 1
    assert "missing" in r.stderr and ".db3" in r.stderr, r.stderr
