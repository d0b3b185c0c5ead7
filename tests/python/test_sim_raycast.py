"""Cross-checks of the simulator with libraries nobody here wrote.

1. Every scene in maps/ is simulated (noise off) and the official `mcap_ros2` reader reads
   every message of its log.
2. Open3D's `RaycastingScene` on the exported scene mesh (scene.ply) recomputes the range of
   every dry-terrain lidar and stereo point of a frame (rays rebuilt from the TF in the log):
   they agree within 1 mm.
3. `tarn eval` of the truth against itself is perfect.
"""

import json
import pathlib

import numpy as np
import open3d as o3d
import pytest
from mcap_ros2.reader import read_ros2_messages

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = sorted((ROOT / "maps").glob("*.toml"))


def quat_matrix(q):
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def transform(t):
    m = np.eye(4)
    m[:3, :3] = quat_matrix(t.transform.rotation)
    tr = t.transform.translation
    m[:3, 3] = [tr.x, tr.y, tr.z]
    return m


def cloud_xyz(msg):
    names = [f.name for f in msg.fields]
    off = {f.name: f.offset for f in msg.fields}
    assert names[:3] == ["x", "y", "z"] and not msg.is_bigendian
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height * msg.width, msg.point_step)
    cols = [raw[:, off[a] : off[a] + 4].copy().view("<f4")[:, 0] for a in "xyz"]
    return np.stack(cols, axis=1).astype(np.float64)


def read_log(path):
    msgs = {}
    for m in read_ros2_messages(str(path)):
        msgs.setdefault(m.channel.topic, []).append(m.ros_msg)
    return msgs


@pytest.fixture(scope="module")
def simulated(tmp_path_factory, request):
    from conftest import tarn_bin
    import subprocess

    out = {}
    for scene in SCENES:
        d = tmp_path_factory.mktemp(scene.stem)
        r = subprocess.run([tarn_bin(), "simulate", str(scene), "--out", str(d), "--no-noise"], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        out[scene.stem] = d
    return out


def test_official_reader_reads_every_simulated_log(simulated):
    assert SCENES, "no scenes in maps/"
    for name, d in simulated.items():
        msgs = read_log(d / "log.mcap")
        info = json.loads((d / "truth.json").read_text())
        n = len(info["trajectory"])
        assert len(msgs["/tf"]) == n, name
        for topic in info["topics"]:
            assert len(msgs[topic]) == n, (name, topic)
        for img in msgs.get("/camera/image", []):
            assert img.encoding == "rgb8" and len(img.data) == img.height * img.width * 3


def scene_raycaster(d):
    mesh = o3d.t.io.read_triangle_mesh(str(d / "scene.ply"))
    legacy = o3d.io.read_triangle_mesh(str(d / "scene.ply"))
    assert len(legacy.triangles) > 0
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(legacy))
    return rc


def truth_lookup(d):
    pc = o3d.t.io.read_point_cloud(str(d / "truth.ply"))
    info = json.loads((d / "truth.json").read_text())
    res = info["resolution"]
    xyz = pc.point.positions.numpy().astype(np.float64)
    cls = pc.point["class"].numpy().reshape(-1)
    keys = np.floor(xyz[:, :2] / res).astype(np.int64)
    table = {(int(a), int(b)): int(c) for (a, b), c in zip(keys, cls)}
    return res, table


def check_cloud(rc, res, table, msgs, topic, frame_id, frame_index):
    statics = {t.child_frame_id: transform(t) for m in msgs["/tf_static"] for t in m.transforms}
    tf = msgs["/tf"][frame_index].transforms[0]
    assert tf.child_frame_id == "base_link"
    cloud = msgs[topic][frame_index]
    assert cloud.header.frame_id == frame_id
    m = transform(tf) @ statics[frame_id]
    p = cloud_xyz(cloud)
    ok = np.isfinite(p).all(axis=1)
    p = p[ok]
    rng = np.linalg.norm(p, axis=1)
    dirs = (m[:3, :3] @ (p / rng[:, None]).T).T
    origin = m[:3, 3]
    rays = np.hstack([np.repeat(origin[None, :], len(p), axis=0), dirs]).astype(np.float32)
    ans = rc.cast_rays(o3d.core.Tensor(rays))
    t = ans["t_hit"].numpy().astype(np.float64)
    found = np.isfinite(t)
    hit = origin + dirs * np.where(found, t, 0.0)[:, None]
    logged = origin + dirs * rng[:, None]

    def dry_at(points):
        # The cell and its 8 neighbours are ground in the truth (class 1).
        k = np.floor(points[:, :2] / res).astype(np.int64)
        return np.array(
            [all(table.get((int(a) + i, int(b) + j)) == 1 for i in (-1, 0, 1) for j in (-1, 0, 1)) for a, b in k]
        )

    # Dry terrain: Open3D's hit and the logged point both lie on dry ground (points through
    # water, bottom returns and mirror points, are not dry-terrain ranges).
    dry = found & dry_at(hit) & dry_at(logged)
    assert dry.sum() > 100, f"{topic}: only {dry.sum()} dry-terrain points"
    err = np.abs(t[dry] - rng[dry])
    return int(dry.sum()), float(err.max())


@pytest.mark.parametrize("topic,frame_id", [("/lidar/points", "lidar"), ("/stereo/points", "camera_left_optical")])
def test_open3d_recomputes_dry_terrain_ranges(simulated, topic, frame_id):
    checked = 0
    for name, d in simulated.items():
        msgs = read_log(d / "log.mcap")
        if topic not in msgs:
            continue
        rc = scene_raycaster(d)
        res, table = truth_lookup(d)
        for fi in (0, len(msgs[topic]) // 2):
            n, err = check_cloud(rc, res, table, msgs, topic, frame_id, fi)
            assert err < 1e-3, f"{name} frame {fi}: {topic} range differs by {err * 1000:.3f} mm over {n} points"
            checked += n
    assert checked > 0


def test_eval_of_truth_against_itself_is_perfect(simulated, tarn, tmp_path):
    d = simulated["default"]
    (tmp_path / "map.ply").write_bytes((d / "truth.ply").read_bytes())
    r = json.loads(tarn("eval", tmp_path, "--truth", d, "--json").stdout)
    assert r["all"]["water_recall"] == 1.0 and r["all"]["false_positive_rate"] == 0.0
    assert r["all"]["terrain_rms_m"] == 0.0 and r["all"]["surface_rms_m"] == 0.0
    assert [b["range"] for b in r["bins"]] == ["0-5", "5-10", "10-20", "20-30", "30+"]
