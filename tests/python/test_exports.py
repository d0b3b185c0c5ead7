"""Open3D and trimesh read tarn's map.ply and terrain.ply; the values agree with the terrain
tarn was given and with what tarn reports."""
import json

import numpy as np
import open3d as o3d
import pytest
import trimesh

RES = 0.1
GROUND_RGB = (176, 148, 104)


def surface(x, y):
    return 0.5 + 0.1 * x - 0.05 * y + 0.2 * np.sin(x / 3.0)


def write_cloud(path, seed=1):
    """An irregular patch of terrain: 25 noisy points per 0.1 m cell over cells of a
    10 m × 8 m rectangle with a hole cut out, written as binary PLY by numpy (not tarn)."""
    rng = np.random.default_rng(seed)
    cells = [(i, j) for i in range(100) for j in range(80)
             if not (40 <= i < 55 and 30 <= j < 45)]
    cells = np.array(cells)
    k = 25
    ij = np.repeat(cells, k, axis=0).astype(np.float64)
    x = (ij[:, 0] + rng.uniform(0.02, 0.98, len(ij))) * RES
    y = (ij[:, 1] + rng.uniform(0.02, 0.98, len(ij))) * RES
    z = surface(x, y) + rng.normal(0, 0.02, len(ij))
    pts = np.stack([x, y, z], axis=1).astype("<f4")
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(pts)}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    )
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(pts.tobytes())
    return {tuple(c) for c in cells}


def expected_triangles(cells):
    n = 0
    for (i, j) in cells:
        a, b, c, d = (i, j) in cells, (i + 1, j) in cells, (i + 1, j + 1) in cells, (i, j + 1) in cells
        n += 2 if (a and b and c and d) else int(a + b + c + d == 3 and a)
        # the block whose lower-left corner is missing
        if (i - 1, j) not in cells and (i, j + 1) in cells and (i - 1, j + 1) in cells:
            n += 1
    return n


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    import conftest
    import subprocess

    d = tmp_path_factory.mktemp("build")
    cells = write_cloud(d / "in.ply")
    r = subprocess.run([conftest.tarn_bin(), "build", d / "in.ply", "--out", d / "out", "--json"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return d / "out", cells, json.loads(r.stdout)


def test_open3d_reads_every_contract_attribute(built):
    out, cells, report = built
    pc = o3d.t.io.read_point_cloud(str(out / "map.ply"))
    names = set(pc.point)
    for attr in ["positions", "elevation_std", "water", "depth", "class", "hazard", "colors"]:
        assert attr in names, f"{attr} missing from {sorted(names)}"
    pos = pc.point.positions.numpy()
    assert len(pos) == len(cells) == report["cells_observed"]
    # Cell centres on the grid, one per observed cell.
    ij = np.floor(pos[:, :2] / RES + 1e-3).astype(int)
    assert {tuple(c) for c in ij} == cells
    np.testing.assert_allclose(pos[:, :2], (ij + 0.5) * RES, atol=1e-5)
    # Elevation against the analytic terrain: 25 points of 2 cm noise per cell.
    err = pos[:, 2] - surface(pos[:, 0], pos[:, 1])
    rms = float(np.sqrt(np.mean(err ** 2)))
    assert rms < 0.01, rms
    std = pc.point.elevation_std.numpy().ravel()
    assert np.all(std > 0) and np.all(std < 0.05)
    assert np.all(pc.point.water.numpy() == 0)
    assert np.all(pc.point.depth.numpy() == 0)
    assert np.all(pc.point["class"].numpy() == 1)
    assert np.all(pc.point.hazard.numpy() == 0)
    assert str(pc.point["class"].dtype) == "UInt8"
    cols = pc.point.colors.numpy()
    assert np.all(cols == np.array(GROUND_RGB, dtype=cols.dtype))


def test_trimesh_reads_map_and_terrain_and_agrees_with_open3d(built):
    out, cells, report = built
    pts = trimesh.load(out / "map.ply")
    assert isinstance(pts, trimesh.PointCloud)
    pc = o3d.t.io.read_point_cloud(str(out / "map.ply"))
    np.testing.assert_array_equal(np.asarray(pts.vertices, dtype=np.float32), pc.point.positions.numpy())
    mesh = trimesh.load(out / "terrain.ply", process=False)
    assert isinstance(mesh, trimesh.Trimesh)
    assert len(mesh.vertices) == len(cells)
    np.testing.assert_allclose(mesh.vertices, pc.point.positions.numpy(), atol=1e-6)
    assert len(mesh.faces) == expected_triangles(cells)
    # Counter-clockwise from above: every face normal points up.
    assert np.all(mesh.face_normals[:, 2] > 0)
    # No triangle spans more than one cell step in x or y.
    v = mesh.vertices[mesh.faces]
    span = np.abs(v[:, :, None, :2] - v[:, None, :, :2]).max(axis=(1, 2))
    assert np.all(span <= RES + 1e-4)
    assert np.all(mesh.visual.vertex_colors[:, :3] == GROUND_RGB)
    # Open3D's mesh reader agrees.
    m3 = o3d.io.read_triangle_mesh(str(out / "terrain.ply"))
    assert len(m3.triangles) == len(mesh.faces)
    # The surface area is close to the analytic patch's (planar area × slope factor).
    assert 0.9 * len(cells) * RES**2 < mesh.area < 1.2 * len(cells) * RES**2


def test_report_and_png(built):
    out, cells, report = built
    assert report["points"]["points"] == len(cells) * 25
    assert report["points"]["fused"] + report["points"]["below"] == report["points"]["points"]
    on_disk = json.loads((out / "report.json").read_text())
    assert on_disk["cells_observed"] == report["cells_observed"]
    png = (out / "map.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_input_fails_cleanly_and_writes_nothing(tarn, tmp_path):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\n"
                    b"property float y\nproperty float z\nend_header\n" + b"\0" * 100)
    r = tarn("build", bad, "--out", tmp_path / "out", check=False)
    assert r.returncode != 0
    assert "bad.ply" in r.stderr
    assert not (tmp_path / "out" / "map.ply").exists()
