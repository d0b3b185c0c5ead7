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
    """map.ply's vertices, laid out as its header says (x y z are `double` in the map frame
    when a `float` would lose millimetres), and their x and y in the map frame."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    types = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4", "uint": "<u4"}
    fields = [(name, types[t]) for kind, t, name in
              (line.split() for line in data[:end].decode().splitlines()
               if line.startswith("property "))]
    v = np.frombuffer(data[end:], dtype=np.dtype(fields))
    return v, v["x"].astype(np.float64), v["y"].astype(np.float64)


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



def test_config_file_asks_for_the_geotiff_and_names_the_crs(tmp_path):
    write_cloud(tmp_path / "in.ply")
    (tmp_path / "tarn.toml").write_text("[build]\ngeotiff = true\nepsg = 25832\n")
    r = subprocess.run([conftest.tarn_bin(), "build", tmp_path / "in.ply", "--out",
                        tmp_path / "out", "--config", tmp_path / "tarn.toml"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    with rasterio.open(tmp_path / "out" / "map.tif") as ds:
        assert ds.crs.to_epsg() == 25832

RIG = """name = "lidar_small_camera"
description = "a 32-ring lidar and a small colour camera"

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

[camera]
position = [0.25, 0.0, 1.6]
rpy_deg = [0.0, 10.0, 0.0]
width = 160
height = 120
hfov_deg = 75.0
"""

SCENE = """name = "puddle_and_pond"
description = "a puddle near a lidar and a pond farther on"
seed = 7
rig = "rig.toml"

[terrain]
origin = [-5.0, -10.0]
size = [45.0, 20.0]
resolution = 0.1
roughness = 0.02
roughness_scale = 3.0
material = "mud"

[[terrain.features]]
kind = "depression"
centre = [24.0, 0.0]
radius = [4.0, 3.0]
depth = 0.4
flat = 0.4

[[terrain.features]]
kind = "depression"
centre = [8.0, 2.0]
radius = [1.5, 1.0]
depth = 0.15
flat = 0.3

[[water]]
kind = "level"
level = -0.1
centre = [24.0, 0.0]
radius = 4.5
attenuation = 11.1
colour = [0.12, 0.10, 0.07]

[[water]]
kind = "level"
level = -0.06
centre = [8.0, 2.0]
radius = 2.0
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


@pytest.fixture(scope="module")
def from_log(tmp_path_factory):
    """A four-frame simulated log (about a second to simulate and build) whose map holds
    water of unknown depth; built with --ros-map and --geotiff, default frame."""
    d = tmp_path_factory.mktemp("maps_out_log")
    (d / "rig.toml").write_text(RIG)
    (d / "scene.toml").write_text(SCENE)
    for args in (["simulate", d / "scene.toml", "--out", d / "sim"],
                 ["build", d / "sim" / "log.mcap", "--out", d / "out", "--ros-map", "--geotiff"]):
        r = subprocess.run([conftest.tarn_bin(), *args], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
    return d, read_map_ply(d / "out" / "map.ply")


def test_log_map_is_stamped_and_its_water_reaches_both_messages(from_log):
    from mcap.reader import make_reader

    d, (v, x, y) = from_log
    with open(d / "sim" / "log.mcap", "rb") as f:
        last = max(m.log_time for _, _, m in make_reader(f).iter_messages())
    msgs = messages(d / "out" / "map.mcap")
    g, o = msgs["/tarn/grid_map"].ros_msg, msgs["/tarn/occupancy"].ros_msg
    for m in msgs.values():
        assert m.log_time_ns == last
        h = m.ros_msg.header
        assert h.frame_id == "map"
        assert h.stamp.sec * 1_000_000_000 + h.stamp.nanosec == last
    assert (v["hazard"] == 2).sum() > 50, "the scene should hold water of unknown depth"
    rows = round(g.info.length_x / g.info.resolution)
    i = np.rint((g.info.pose.position.x + g.info.length_x / 2 - x) / g.info.resolution - 0.5)
    j = np.rint((g.info.pose.position.y + g.info.length_y / 2 - y) / g.info.resolution - 0.5)
    flat = (j * rows + i).astype(int)
    for layer, field in zip(LAYERS, PLY_FIELDS):
        a = np.asarray(g.data[LAYERS.index(layer)].data, dtype=np.float32)[flat]
        np.testing.assert_array_equal(a, v[field].astype(np.float32), err_msg=layer)
    grid = np.asarray(o.data, dtype=np.int8).reshape(o.info.height, o.info.width)
    col = np.floor((x - o.info.origin.position.x) / o.info.resolution).astype(int)
    row = np.floor((y - o.info.origin.position.y) / o.info.resolution).astype(int)
    occ = grid[row, col]
    assert (occ[v["hazard"] == 2] == 100).all() and (occ[v["hazard"] == 0] == 0).all()
    with rasterio.open(d / "out" / "map.tif") as ds:
        assert ds.crs is None
        water = ds.read(3)[rasterio.transform.rowcol(ds.transform, x, y)]
    np.testing.assert_array_equal(water, v["water"])
