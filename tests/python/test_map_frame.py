"""A map at UTM-like coordinates (x ≈ 500 km, y ≈ 4,500 km): map.ply and terrain.ply hold
`double` x y z in the map frame, and Open3D and trimesh read them in place, within 1 mm of
the cell centres tarn built, without any offset to add."""
import json
import subprocess

import numpy as np
import open3d as o3d
import pytest
import trimesh

RES = 0.1
E, N = 500_000.0, 4_500_000.0


def surface(x, y):
    return 312.0 + 0.05 * (x - E) - 0.03 * (y - N)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    import conftest

    d = tmp_path_factory.mktemp("utm")
    rng = np.random.default_rng(7)
    cells = [(i, j) for i in range(60) for j in range(40)]
    ij = np.repeat(np.array(cells), 9, axis=0).astype(np.float64)
    # Cells of the 0.1 m lattice of the map frame, 9 points each, in double.
    i0, j0 = round(E / RES), round(N / RES)
    x = (i0 + ij[:, 0] + rng.uniform(0.05, 0.95, len(ij))) * RES
    y = (j0 + ij[:, 1] + rng.uniform(0.05, 0.95, len(ij))) * RES
    z = surface(x, y)
    pts = np.stack([x, y, z], axis=1).astype("<f8")
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(pts)}\nproperty double x\nproperty double y\nproperty double z\n"
        "end_header\n"
    )
    (d / "utm.ply").write_bytes(header.encode() + pts.tobytes())
    r = subprocess.run([conftest.tarn_bin(), "build", d / "utm.ply", "--out", d / "out", "--json"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    want = {(i0 + i, j0 + j) for (i, j) in cells}
    return d / "out", want, json.loads(r.stdout)


def header(path):
    data = path.read_bytes()
    return data[: data.index(b"end_header\n")].decode()


def check_centres(xyz, want):
    """Every vertex on the centre of one of the cells tarn was given, within 1 mm."""
    assert xyz.dtype == np.float64
    ij = np.floor(xyz[:, :2] / RES).astype(np.int64)
    assert {tuple(c) for c in ij} == want
    np.testing.assert_allclose(xyz[:, :2], (ij + 0.5) * RES, rtol=0, atol=1e-3)
    np.testing.assert_allclose(xyz[:, 2], surface(xyz[:, 0], xyz[:, 1]), rtol=0, atol=0.02)


@pytest.mark.parametrize("name", ["map.ply", "terrain.ply"])
def test_header_says_double_and_has_no_origin_line(built, name):
    out, _, _ = built
    h = header(out / name)
    assert "property double x\nproperty double y\nproperty double z\n" in h
    assert "comment origin" not in h


def test_open3d_reads_map_ply_in_the_map_frame(built):
    out, want, report = built
    pc = o3d.t.io.read_point_cloud(str(out / "map.ply"))
    xyz = pc.point.positions.numpy()
    assert len(xyz) == report["cells_observed"] == len(want)
    check_centres(xyz, want)
    # The legacy API too (it keeps positions as double).
    legacy = np.asarray(o3d.io.read_point_cloud(str(out / "map.ply")).points)
    check_centres(legacy, want)


def test_open3d_reads_terrain_ply_in_the_map_frame(built):
    out, want, _ = built
    mesh = o3d.io.read_triangle_mesh(str(out / "terrain.ply"))
    check_centres(np.asarray(mesh.vertices), want)
    assert len(mesh.triangles) > 0


def test_trimesh_reads_both_in_the_map_frame(built):
    out, want, _ = built
    pc = trimesh.load(out / "map.ply", process=False)
    check_centres(np.asarray(pc.vertices, dtype=np.float64), want)
    mesh = trimesh.load(out / "terrain.ply", process=False)
    check_centres(np.asarray(mesh.vertices, dtype=np.float64), want)
    # 60 × 40 cells: 59 × 39 blocks of two triangles.
    assert len(mesh.faces) == 2 * 59 * 39
