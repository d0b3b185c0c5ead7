"""The ROS and GIS outputs of `tarn build` read back by libraries tarn did not write:

1. map.mcap through the official `mcap-ros2-support` reader: a grid_map_msgs/GridMap with
   every layer, decoded from the schema the file carries, each cell where grid_map's index
   convention puts it and equal to map.ply; a nav_msgs/OccupancyGrid of the hazards; both
   headers naming the frame.
2. map.tif through rasterio (GDAL): six float32 bands named by layer, NaN nodata, the
   geotransform of the map frame and the CRS of `--epsg`.

The scene: a terrain patch with a hole, far from the origin in UTM-like coordinates
(`double` PLY vertices), so that the georeference is checked where float32 would fail.
"""
import subprocess

import numpy as np
import pytest
from mcap_ros2.reader import read_ros2_messages

import conftest

rasterio = pytest.importorskip("rasterio")

RES = 0.1
E0, N0 = 500_000.0, 5_000_000.0  # the patch's south-west corner (UTM 33N metres)
LAYERS = ["elevation", "elevation_std", "water_probability", "class", "hazard", "depth"]
PLY_FIELDS = ["z", "elevation_std", "water", "class", "hazard", "depth"]


def write_cloud(path, seed=3):
    """A 6 m × 4 m sloping patch of 0.1 m cells with a 1 m square hole and a 0.5 m step."""
    rng = np.random.default_rng(seed)
    cells = np.array([(i, j) for i in range(60) for j in range(40)
                      if not (20 <= i < 30 and 10 <= j < 20)])
    ij = np.repeat(cells, 9, axis=0).astype(np.float64)
    x = (ij[:, 0] + rng.uniform(0.05, 0.95, len(ij))) * RES
    y = (ij[:, 1] + rng.uniform(0.05, 0.95, len(ij))) * RES
    z = 100.0 + 0.05 * x + np.where(x > 4.5, 0.5, 0.0) + rng.normal(0, 0.01, len(ij))
    pts = np.stack([x + E0, y + N0, z], axis=1).astype("<f8")
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {len(pts)}\nproperty double x\nproperty double y\n"
              "property double z\nend_header\n")
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(pts.tobytes())


def read_map_ply(path):
    """map.ply's vertices (the contract's layout) with the origin comment added back."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    origin = np.zeros(2)
    for line in data[:end].decode().splitlines():
        if line.startswith("comment origin"):
            origin = np.array([float(v) for v in line.split()[2:4]])
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("elevation_std", "<f4"),
                   ("water", "<f4"), ("depth", "<f4"), ("class", "u1"), ("hazard", "u1"),
                   ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    v = np.frombuffer(data[end:], dtype=dt)
    return v, v["x"].astype(np.float64) + origin[0], v["y"].astype(np.float64) + origin[1]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    d = tmp_path_factory.mktemp("maps_out")
    write_cloud(d / "in.ply")
    out = d / "out"
    r = subprocess.run([conftest.tarn_bin(), "build", d / "in.ply", "--out", out, "--ros-map",
                        "--geotiff", "--epsg", "32633", "--frame-id", "utm_33n"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "also wrote map.mcap map.tif" in r.stdout
    return out, read_map_ply(out / "map.ply")


def messages(path):
    return {m.channel.topic: m for m in read_ros2_messages(str(path))}


def test_grid_map_layers_and_values_match_map_ply(built):
    out, (v, x, y) = built
    msgs = messages(out / "map.mcap")
    m = msgs["/tarn/grid_map"]
    assert m.schema.name == "grid_map_msgs/msg/GridMap"
    g = m.ros_msg
    assert g.header.frame_id == "utm_33n"
    assert list(g.layers) == LAYERS
    assert list(g.basic_layers) == ["elevation"]
    assert g.outer_start_index == 0 and g.inner_start_index == 0
    info = g.info
    assert info.resolution == pytest.approx(RES)
    rows, cols = round(info.length_x / RES), round(info.length_y / RES)
    assert (rows, cols) == (60, 40)
    for arr in g.data:
        dims = arr.layout.dim
        assert [d.label for d in dims] == ["column_index", "row_index"]
        assert [(d.size, d.stride) for d in dims] == [(cols, rows * cols), (rows, rows)]
        assert len(arr.data) == rows * cols
    # grid_map: index (i, j) lies at pose + length/2 - (index + 1/2) * resolution.
    px, py = info.pose.position.x, info.pose.position.y
    i = np.rint((px + info.length_x / 2 - x) / RES - 0.5).astype(int)
    j = np.rint((py + info.length_y / 2 - y) / RES - 0.5).astype(int)
    assert i.min() == 0 and i.max() == rows - 1 and j.min() == 0 and j.max() == cols - 1
    flat = j * rows + i
    for layer, field in zip(LAYERS, PLY_FIELDS):
        a = np.asarray(g.data[LAYERS.index(layer)].data, dtype=np.float32)[flat]
        np.testing.assert_array_equal(a, v[field].astype(np.float32), err_msg=layer)
    # The hole is unobserved: NaN in every layer, nowhere else in the elevation.
    elev = np.asarray(g.data[0].data)
    assert np.isnan(elev).sum() == rows * cols - len(v) == 100
    assert m.log_time_ns == 0  # a cloud has no log time


def test_occupancy_grid_holds_the_hazards(built):
    out, (v, x, y) = built
    m = messages(out / "map.mcap")["/tarn/occupancy"]
    assert m.schema.name == "nav_msgs/msg/OccupancyGrid"
    o = m.ros_msg
    assert o.header.frame_id == "utm_33n"
    w, h = o.info.width, o.info.height
    assert (w, h) == (60, 40)
    assert o.info.origin.position.x == pytest.approx(E0)
    assert o.info.origin.position.y == pytest.approx(N0)
    grid = np.asarray(o.data, dtype=np.int8).reshape(h, w)  # decoded as int8
    col = np.floor((x - o.info.origin.position.x) / o.info.resolution).astype(int)
    row = np.floor((y - o.info.origin.position.y) / o.info.resolution).astype(int)
    expected = np.array([0, 50, 100, 100], dtype=np.int8)[v["hazard"]]
    np.testing.assert_array_equal(grid[row, col], expected)
    assert (grid == -1).sum() == 100
    assert set(np.unique(grid)) <= {-1, 0, 50, 100}


def test_geotiff_bands_georeference_and_crs(built):
    out, (v, x, y) = built
    with rasterio.open(out / "map.tif") as ds:
        assert ds.count == 6 and set(ds.dtypes) == {"float32"}
        assert list(ds.descriptions) == LAYERS
        assert np.isnan(ds.nodata)
        assert ds.crs.to_epsg() == 32633
        assert (ds.width, ds.height) == (60, 40)
        t = ds.transform
        assert (t.a, t.b, t.d, t.e) == pytest.approx((RES, 0, 0, -RES))
        assert (t.c, t.f) == pytest.approx((E0, N0 + 40 * RES), abs=1e-6)
        bands = ds.read()
        rows, cols = rasterio.transform.rowcol(t, x, y)
    for k, field in enumerate(PLY_FIELDS):
        np.testing.assert_array_equal(bands[k][rows, cols], v[field].astype(np.float32),
                                      err_msg=LAYERS[k])
    assert np.isnan(bands[0]).sum() == 100


def test_geotiff_without_epsg_has_no_crs(tmp_path):
    write_cloud(tmp_path / "in.ply")
    r = subprocess.run([conftest.tarn_bin(), "build", tmp_path / "in.ply", "--out",
                        tmp_path / "out", "--geotiff"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert not (tmp_path / "out" / "map.mcap").exists()
    with rasterio.open(tmp_path / "out" / "map.tif") as ds:
        assert ds.crs is None
        assert ds.transform.c == pytest.approx(E0)
