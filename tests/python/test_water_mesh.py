"""trimesh and Open3D read tarn's water.ply; closed bodies are watertight and consistently
wound, and their volume and surface area agree with report.json within 1 %.

The files are written by the Rust integration test `cargo test --test water_export`
(tools/test.sh runs `cargo test` before pytest) into target/water-check/mixed/."""
import json
import pathlib

import numpy as np
import open3d as o3d
import pytest
import trimesh

DIR = pathlib.Path(__file__).resolve().parents[2] / "target" / "water-check" / "mixed"


@pytest.fixture(scope="module")
def files():
    if not (DIR / "water.ply").exists():
        raise AssertionError(f"{DIR}/water.ply missing: run `cargo test --test water_export` first")
    report = json.loads((DIR / "report.json").read_text())
    mesh = trimesh.load(DIR / "water.ply", process=False)
    return report["water_bodies"], mesh


def body_meshes(mesh):
    body = np.asarray(mesh.metadata["_ply_raw"]["vertex"]["data"]["body"])
    face_body = body[mesh.faces[:, 0]]
    out = {}
    for b in np.unique(face_body):
        sub = mesh.submesh([np.nonzero(face_body == b)[0]], append=True, repair=False)
        out[int(b)] = sub
    return out


def test_every_body_is_in_the_mesh(files):
    bodies, mesh = files
    assert len(bodies) >= 2
    assert set(body_meshes(mesh)) == {b["id"] for b in bodies}


def test_closed_bodies_are_watertight_and_agree_with_the_report(files):
    bodies, mesh = files
    parts = body_meshes(mesh)
    closed = [b for b in bodies if b["volume_m3"] is not None]
    assert closed, "the scene has bodies with every depth known"
    for b in closed:
        m = parts[b["id"]]
        # The mesh's own vertices: merge the top/bottom seam only by index, as written.
        assert m.is_watertight, b["id"]
        assert m.is_winding_consistent, b["id"]
        assert m.volume > 0
        assert abs(m.volume - b["volume_m3"]) <= 0.01 * b["volume_m3"], (m.volume, b)
        # The top sheet (normals up) projects onto the body's area.
        up = m.face_normals[:, 2] > 0
        plan = (m.area_faces[up] * m.face_normals[up, 2]).sum()
        assert abs(plan - b["area_m2"]) <= 0.01 * b["area_m2"], (plan, b)


def test_open_bodies_are_their_surface_only(files):
    bodies, mesh = files
    parts = body_meshes(mesh)
    for b in (b for b in bodies if b["volume_m3"] is None):
        m = parts[b["id"]]
        assert not m.is_watertight
        assert (m.face_normals[:, 2] > 0).all()
        assert abs(m.area_faces @ m.face_normals[:, 2] - b["area_m2"]) <= 0.01 * b["area_m2"]
        if b["surface_model"] == "delaunay":
            # A stream: the surface is not level.
            assert np.ptp(m.vertices[:, 2]) > 0.05


def test_open3d_reads_every_export():
    m = o3d.io.read_triangle_mesh(str(DIR / "water.ply"))
    assert len(m.triangles) > 0 and len(m.vertices) > 0
    t = o3d.io.read_triangle_mesh(str(DIR / "terrain.ply"))
    assert len(t.triangles) > 0
    pc = o3d.t.io.read_point_cloud(str(DIR / "map.ply"))
    water = pc.point["class"].numpy().ravel() == 2
    assert water.any()
    depth = pc.point["depth"].numpy().ravel()
    # Depth unknown (NaN) only on water; dry cells 0.
    assert (depth[~water] == 0).all()
    assert np.isnan(depth[water]).any() and np.isfinite(depth[water]).any()
