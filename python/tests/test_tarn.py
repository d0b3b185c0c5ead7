"""The Python package: builds of simulated logs through `tarn`, tile sets, and the Dask
map-reduce against the one-process build."""

import json
import os
import pathlib
import pickle
import subprocess
import sys

import numpy as np
import pytest

import tarn

ROOT = pathlib.Path(__file__).resolve().parents[2]

# Two drives past the default scene's pond, one along each shore: each log sees part of
# the pond; the pond (x 15..29 m) crosses tile borders (tiles are 6.4 m) and the border
# between the logs' areas, so the water body of the merged map needs both logs.
DRIVES = {
    "south": "[[4.0, -1.0], [34.0, -1.0]]",
    "north": "[[36.0, 13.0], [6.0, 13.0]]",
}


def tarn_bin() -> str:
    env = os.environ.get("TARN_BIN")
    if env:
        return env
    for profile in ("release", "debug"):
        p = ROOT / "target" / profile / "tarn"
        if p.exists():
            return str(p)
    raise RuntimeError("no tarn binary: build it or set TARN_BIN")


def scene(path: pathlib.Path, waypoints: str, frames: int = 8) -> pathlib.Path:
    text = (ROOT / "maps" / "default.toml").read_text()
    head, _ = text.split("[trajectory]")
    head = head.replace('rig = "rigs/small.toml"', f'rig = "{ROOT / "maps" / "rigs" / "small.toml"}"')
    path.write_text(
        head
        + f"[trajectory]\nwaypoints = {waypoints}\nspeed = 3.0\nrate_hz = 2.0\nframes = {frames}\n"
    )
    return path


@pytest.fixture(scope="session")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("logs")
    out = []
    for name, wp in DRIVES.items():
        s = scene(d / f"{name}.toml", wp)
        sim = d / name
        subprocess.run(
            [tarn_bin(), "simulate", str(s), "--out", str(sim)],
            check=True,
            capture_output=True,
        )
        out.append(str(sim / "log.mcap"))
    return out


@pytest.fixture(scope="session")
def one_process(logs):
    return tarn.build_many(logs)


def test_build_is_what_tarn_build_writes(logs, tmp_path):
    subprocess.run(
        [tarn_bin(), "build", logs[0], "--out", str(tmp_path / "cli")],
        check=True,
        capture_output=True,
    )
    m = tarn.build(logs[0])
    assert m.ply_bytes() == (tmp_path / "cli" / "map.ply").read_bytes()
    back = tarn.read_map(tmp_path / "cli")
    assert len(back) == len(m)
    np.testing.assert_allclose(back.layer("elevation"), m.layer("elevation"), equal_nan=True, atol=1e-6)
    # map.ply keeps no point counts.
    assert (back.layer("hits") == 0).all() and (m.layer("hits") > 0).any()


def test_layers(one_process):
    m = one_process
    assert m.layer_names() == [
        "elevation", "sigma", "water", "class", "hazard", "depth", "hits", "below",
    ]
    rows, cols = m.shape
    for name in m.layer_names():
        a = m.layer(name)
        assert a.shape == (rows, cols), name
    z = m.layer("elevation")
    assert z.dtype == np.float64 and m.layer("class").dtype == np.uint8
    assert np.isfinite(z).sum() == len(m)
    # Points fused into every ground cell; none where nothing was observed.
    hits = m.layer("hits")
    assert hits.dtype == np.uint32 and (hits[m.layer("class") == 1] > 0).all()
    assert (hits[~np.isfinite(z)] == 0).all() and m.layer("below").dtype == np.uint32
    # Every observed cell at its key.
    keys = m.keys()
    kx, ky = m.key_origin
    assert np.isfinite(z[keys[:, 1] - ky, keys[:, 0] - kx]).all()
    x0, y0 = m.origin
    assert x0 == pytest.approx(kx * m.resolution) and y0 == pytest.approx(ky * m.resolution)
    # Water: class 2 cells, a body with its cells.
    assert (m.layer("class") == 2).sum() > 100
    assert m.bodies and m.bodies[0]["cells"].shape[1] == 2
    with pytest.raises(ValueError, match="no layer"):
        m.layer("nope")


def test_a_planner_asks_a_position(one_process):
    m = one_process
    keys, cls, z = m.keys(), m.layer("class"), m.layer("elevation")
    kx, ky = m.key_origin
    water = keys[cls[keys[:, 1] - ky, keys[:, 0] - kx] == 2][0]
    dry = keys[cls[keys[:, 1] - ky, keys[:, 0] - kx] == 1][0]
    for k, name in [(water, "water"), (dry, "ground")]:
        x, y = (k + 0.5) * m.resolution
        c = m.at(x, y)
        assert c["class"] == name
        assert c["elevation"] == z[k[1] - ky, k[0] - kx]
    assert m.at(*((water + 0.5) * m.resolution))["body"] in [b["id"] for b in m.bodies]
    assert m.at(*((dry + 0.5) * m.resolution))["body"] is None
    assert m.at(1e12, 0.0) is None and m.at(float("nan"), 0.0) is None


def calibrated_mapper(log):
    """A mapper that measured the sensors' noise on the log's first frames and holds it,
    as an offline build does before it maps."""
    mp = tarn.Mapper()
    for f in tarn.read_frames(log):
        mp.calibrate(f)
        if mp.calibration_settled:
            break
    mp.hold_calibration()
    return mp


def test_mapper_online_is_the_offline_build(logs):
    mp = calibrated_mapper(logs[1])
    cal = json.loads(mp.calibration())
    assert cal["lidar"]["used_sigma0_m"]["source"] == "measured"
    n = 0
    for f in tarn.read_frames(logs[1]):
        assert f.lidar_points().shape[1] == 3
        r = mp.update(f)
        n += 1
        assert r["frame_index"] == n
    assert mp.frames == n > 0
    assert mp.finish().ply_bytes() == tarn.build(logs[1]).ply_bytes()
    with pytest.raises(tarn.TarnError, match="finished"):
        mp.finish()


def test_cells_taken_while_driving_merge_to_the_log(logs):
    mp = calibrated_mapper(logs[1])
    taken = []
    for f in tarn.read_frames(logs[1]):
        mp.update(f)
        taken.append(mp.take_left_tiles())
    assert sum(len(t) for t in taken) > 0
    held, whole = mp.finish_tiles(), tarn.build_tiles(logs[1])
    assert len(held) < len(whole)
    assert tarn.merge(taken + [held]).to_bytes() == whole.to_bytes()
    with pytest.raises(tarn.TarnError, match="finished"):
        mp.take_left_tiles()


def test_tile_sets_merge_exactly(logs, one_process):
    a, b = (tarn.build_tiles(p) for p in logs)
    ab, ba = tarn.merge([a, b]), tarn.merge([b, a])
    assert ab.to_bytes() == ba.to_bytes()
    assert pickle.loads(pickle.dumps(ab)).to_bytes() == ab.to_bytes()
    parts = ab.partition(3)
    assert tarn.merge(parts[::-1]).to_bytes() == ab.to_bytes()
    assert tarn.finish(tarn.TileSet.from_bytes(ab.to_bytes())).ply_bytes() == one_process.ply_bytes()
    assert len(ab) <= len(a) + len(b) and ab.points == a.points + b.points


def test_errors_carry_tarns_message(tmp_path):
    with pytest.raises(tarn.TarnError, match="magic"):
        tarn.TileSet.from_bytes(b"x" * 64)
    good = tarn.TileSet().to_bytes()
    with pytest.raises(tarn.TarnError, match="CRC"):
        tarn.TileSet.from_bytes(good[:-1] + bytes([good[-1] ^ 1]))
    with pytest.raises(tarn.TarnError, match="resolution/z_ref"):
        tarn.TileSet(0.1).merge(tarn.TileSet(0.2))
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not a log at all")
    with pytest.raises((tarn.TarnError, OSError)):
        tarn.build(bad)
    with pytest.raises(OSError):
        tarn.build(tmp_path / "missing.mcap")


def test_time_chunks_are_not_the_one_pass(logs):
    """Documented: a log cut by time merges to a different map than its one pass."""
    whole = tarn.build_tiles(logs[0])
    chunks = tarn.merge([tarn.build_tiles(logs[0], start=None, end=102.0), tarn.build_tiles(logs[0], start=102.0)])
    assert chunks.to_bytes() != whole.to_bytes()


@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    )
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def test_dask_build_is_the_one_process_build(logs, one_process, client):
    import tarn.dask

    stats = {}
    m = tarn.dask.build_many(logs, client, stats=stats)
    assert m.ply_bytes() == one_process.ply_bytes()
    for name in m.layer_names():
        np.testing.assert_array_equal(m.layer(name), one_process.layer(name))
    assert stats["points"] > 0 and stats["log_bytes"] > 0
    # Another reduction split and order: the same bytes.
    m3 = tarn.dask.build_many(logs[::-1], client, parts=3)
    assert m3.ply_bytes() == one_process.ply_bytes()


def test_a_pond_cut_by_logs_and_tiles_comes_out_whole(logs, one_process, client):
    import tarn.dask

    m = tarn.dask.build_many(logs, client, parts=4)
    big = max(m.bodies, key=lambda b: b["area_m2"])
    ref = max(one_process.bodies, key=lambda b: b["area_m2"])
    np.testing.assert_array_equal(big["cells"], ref["cells"])
    assert big["area_m2"] == ref["area_m2"]
    cells = big["cells"]
    tiles = {(int(x) // 64, int(y) // 64) for x, y in cells}
    assert len(tiles) > 1, "the body should cross tile borders"
    # Each log alone sees only part of it: the merged body is more than either, and holds
    # cells only one of the logs observed, of each log.
    only = []
    for p in logs:
        alone = tarn.build(p)
        largest = max((b["area_m2"] for b in alone.bodies), default=0.0)
        assert largest < big["area_m2"], (p, largest, big["area_m2"])
        only.append({(int(x), int(y)) for x, y in alone.keys()})
    body = {(int(x), int(y)) for x, y in cells}
    assert body & (only[0] - only[1]) and body & (only[1] - only[0])
    # One body, not pieces: no other body touches it.
    near = {(x + dx, y + dy) for x, y in body for dx in (-1, 0, 1) for dy in (-1, 0, 1)}
    for b in m.bodies:
        if b["id"] != big["id"]:
            assert not near & {(int(x), int(y)) for x, y in b["cells"]}, "the pond came out in pieces"


def same_bodies(a, b):
    """Two maps' body lists alike: every report field (repr, so NaN matches NaN) and cells."""
    assert len(a) == len(b)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.pop("cells"), y.pop("cells"))
        assert repr(x) == repr(y)


def test_regions_with_a_halo_join_to_the_whole_finish(logs, one_process):
    whole = tarn.merge([tarn.build_tiles(p) for p in logs])
    keys = whole.tile_keys()
    bounds = (
        (min(k[0] for k in keys), min(k[1] for k in keys)),
        (max(k[0] for k in keys), max(k[1] for k in keys)),
    )
    # One region per tile, one tile of halo, each given only the tiles it reads (and the
    # build's colour and SWIR false alarms, which a cut does not hold) and sent through pickle;
    # undecided tiles finished again with twice the halo.
    assert whole.colour_false_alarms[0] > 0
    regions, pending, again = [], [([k], 1) for k in keys], 0
    while pending:
        region, h = pending.pop()
        crop = whole.select_near(region, h)
        assert crop.colour_false_alarms == (0, 0) and crop.swir_false_alarms == (0, 0)
        crop.add_colour_false_alarms(*whole.colour_false_alarms)
        crop.add_swir_false_alarms(*whole.swir_false_alarms)
        assert crop.swir_false_alarms == whole.swir_false_alarms
        r = tarn.finish_region(crop, region, h, bounds)
        r = pickle.loads(pickle.dumps(r))
        assert r.tiles_read <= (2 * h + 1) ** 2
        if r.undecided:
            again += len(r.undecided)
            pending.append((r.undecided, 2 * h))
        regions.append(r)
    assert again > 0, "the pond is larger than one tile of halo"
    m = tarn.join_regions(regions)
    assert m.ply_bytes() == one_process.ply_bytes()
    same_bodies(m.bodies, one_process.bodies)
    # Without the re-finishes the undecided tiles are missing: refused.
    first = [r for r in regions if r.undecided]
    with pytest.raises(tarn.TarnError, match="undecided"):
        tarn.join_regions(first)
    with pytest.raises(tarn.TarnError):
        tarn.finish_region(whole, keys[:1], 0, bounds)
    with pytest.raises(tarn.TarnError):
        tarn.Region.from_bytes(regions[0].to_bytes()[:-1])


def test_dask_regions_cut_through_the_pond(logs, one_process, client):
    import tarn.dask

    # Regions of one tile (6.4 m) read with one tile of halo: the pond (about 14 m
    # across) crosses region borders and reaches past the halos; the tiles it leaves
    # undecided are finished again with larger halos. The same map, bodies and all.
    stats = {}
    m = tarn.dask.build_many(logs, client, region_tiles=1, halo=1, stats=stats)
    assert stats["parts"] > 4 and stats["refinished_tiles"] > 0 and stats["largest_halo"] > 1
    assert m.ply_bytes() == one_process.ply_bytes()
    same_bodies(m.bodies, one_process.bodies)
    m2 = tarn.dask.build_many(logs[::-1], client, region_tiles=2, halo=3)
    assert m2.ply_bytes() == one_process.ply_bytes()
    same_bodies(m2.bodies, one_process.bodies)


def test_command_line(logs, one_process, tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "tarn.dask", *logs, "--out", str(tmp_path / "m"), "--threads"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "m" / "map.ply").read_bytes() == one_process.ply_bytes()
    assert "logs:" in r.stdout
