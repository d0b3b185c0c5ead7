//! `tarn._tarn`: the Python bindings of tarn. The Python package `tarn` re-exports them
//! (see `tarn/__init__.py` and the stubs `tarn/_tarn.pyi`).
//!
//! Every long call (a build, a merge, the water stage, encoding and decoding tile sets)
//! releases the interpreter while it runs, so Python threads (a Dask worker's, say) build
//! in parallel. Errors are `tarn.TarnError` carrying tarn's own message; a file that cannot
//! be opened is an `OSError`.

use std::path::PathBuf;

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyOSError, PyStopIteration, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

use tarn_log::build::{
    build_tiles as core_build_tiles, finish_tile_region, finish_tiles, LogBuildConfig,
};
use tarn::grid::{CellKey, TileMap};
use tarn::hazard::{join_regions as core_join_regions, HazardMap, MapLookup, RegionMap, TileKey};
use tarn_log::frames::FrameStream;
use tarn::sensor::Frame as CoreFrame;
use tarn::mapper::{Mapper as CoreMapper, MapperConfig};

create_exception!(
    _tarn,
    TarnError,
    PyException,
    "An error from tarn: bad input, a bad setting, a damaged file. The message is tarn's."
);

fn err(e: tarn::Error) -> PyErr {
    match e {
        tarn::Error::Io { .. } => PyOSError::new_err(e.to_string()),
        e => TarnError::new_err(e.to_string()),
    }
}

/// The config of a build: `None` for what `tarn build` uses on a log without options
/// (every sensor, colour and SWIR labels), else the path of a `tarn.toml` (or JSON) file.
fn config_of(config: Option<PathBuf>) -> PyResult<LogBuildConfig> {
    match config {
        None => Ok(LogBuildConfig::of_mapper(MapperConfig::every_sensor())),
        Some(p) => LogBuildConfig::load(&p).map_err(err),
    }
}

/// Largest layer [`Map::layer`] makes, in cells (4 GB of `f64`).
const MAX_LAYER_CELLS: usize = 500_000_000;

/// The names of [`Map::layer`], in order.
const LAYERS: [&str; 8] = [
    "elevation",
    "sigma",
    "water",
    "class",
    "hazard",
    "depth",
    "hits",
    "below",
];

/// A hazard map: one record per observed cell, and the water bodies.
#[pyclass(module = "tarn", frozen)]
struct Map {
    map: HazardMap,
    /// The map looked up by position, built on the first `at`.
    lookup: std::sync::OnceLock<MapLookup>,
}

impl Map {
    fn new(map: HazardMap) -> Self {
        Map {
            map,
            lookup: std::sync::OnceLock::new(),
        }
    }

    /// Inclusive cell-key bounds, `(lo, hi)`; an empty map has a 0 × 0 grid at key 0.
    fn bounds(&self) -> (CellKey, CellKey) {
        self.map
            .key_bounds()
            .unwrap_or((CellKey::new(0, 0), CellKey::new(-1, -1)))
    }

    fn grid<T: Copy + numpy::Element>(
        &self,
        empty: T,
        value: impl Fn(&tarn::hazard::MapCell) -> T,
    ) -> PyResult<Array2<T>> {
        let (lo, hi) = self.bounds();
        let (w, h) = ((hi.x - lo.x + 1) as usize, (hi.y - lo.y + 1) as usize);
        // Maps of logs far apart span a bounding box far larger than their cells.
        if w.saturating_mul(h) > MAX_LAYER_CELLS {
            return Err(TarnError::new_err(format!(
                "a layer of {h} × {w} cells is more than {MAX_LAYER_CELLS}: the map's cells \
                 are too far apart for one array; read them by keys()"
            )));
        }
        let mut a = Array2::from_elem((h, w), empty);
        for c in &self.map.cells {
            let (r, col) = ((c.key.y - lo.y) as usize, (c.key.x - lo.x) as usize);
            a[[r, col]] = value(c);
        }
        Ok(a)
    }
}

#[pymethods]
impl Map {
    /// Cell size, metres.
    #[getter]
    fn resolution(&self) -> f64 {
        self.map.resolution
    }

    /// Map-frame `(x, y)` of the lower-left corner of the layers' cell `[0, 0]`: row `r`,
    /// column `c` covers `x` in `origin.x + c·res ..+res`, `y` in `origin.y + r·res ..+res`.
    #[getter]
    fn origin(&self) -> (f64, f64) {
        let (lo, _) = self.bounds();
        (
            lo.x as f64 * self.map.resolution,
            lo.y as f64 * self.map.resolution,
        )
    }

    /// `(rows, columns)` of every layer.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        let (lo, hi) = self.bounds();
        ((hi.y - lo.y + 1) as usize, (hi.x - lo.x + 1) as usize)
    }

    /// Cell key `(kx, ky)` of the layers' cell `[0, 0]`.
    #[getter]
    fn key_origin(&self) -> (i64, i64) {
        let (lo, _) = self.bounds();
        (lo.x, lo.y)
    }

    /// Observed cells.
    fn __len__(&self) -> usize {
        self.map.cells.len()
    }

    #[staticmethod]
    fn layer_names() -> Vec<&'static str> {
        LAYERS.to_vec()
    }

    /// One layer as a 2-D array, rows along +y, columns along +x (see `origin`).
    /// Unobserved cells: NaN in `elevation`, `sigma`, `water`, `depth`; 0 (unknown) in
    /// `class`; 255 in `hazard`; 0 in `hits` (points fused into the elevation) and `below`
    /// (points far below the cell's surface, not averaged in). A map read from `map.ply`
    /// has no point counts: `hits` and `below` are 0 there.
    fn layer<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        Ok(match name {
            "elevation" => self.grid(f64::NAN, |c| c.z)?.into_pyarray(py).into_any(),
            "sigma" => self
                .grid(f64::NAN, |c| c.elevation_std)?
                .into_pyarray(py)
                .into_any(),
            "water" => self
                .grid(f32::NAN, |c| c.water)?
                .into_pyarray(py)
                .into_any(),
            "depth" => self
                .grid(f32::NAN, |c| c.depth)?
                .into_pyarray(py)
                .into_any(),
            "class" => self
                .grid(0u8, |c| c.class as u8)?
                .into_pyarray(py)
                .into_any(),
            "hazard" => self
                .grid(255u8, |c| c.hazard as u8)?
                .into_pyarray(py)
                .into_any(),
            "hits" => self.grid(0u32, |c| c.hits)?.into_pyarray(py).into_any(),
            "below" => self.grid(0u32, |c| c.below)?.into_pyarray(py).into_any(),
            _ => {
                return Err(PyValueError::new_err(format!(
                    "no layer {name:?}; the layers are {}",
                    LAYERS.join(", ")
                )))
            }
        })
    }

    /// What the map says of map position `(x, y)`: a dict of its cell (`class` and
    /// `hazard` by name, `water` probability, `elevation`, `sigma`, `depth`, and `body`,
    /// the id of the water body holding it, or None), or None where no cell was observed.
    /// The first call indexes the cells; every later one is a lookup.
    fn at<'py>(&self, py: Python<'py>, x: f64, y: f64) -> PyResult<Option<Bound<'py, PyDict>>> {
        let lookup = self.lookup.get_or_init(|| MapLookup::of(&self.map));
        let Some(c) = lookup.at(&self.map, x, y) else {
            return Ok(None);
        };
        let body = lookup.body_at(&self.map, x, y).map(|b| b.id);
        let d = PyDict::new(py);
        d.set_item("class", c.class.name())?;
        d.set_item("hazard", c.hazard.name())?;
        d.set_item("water", c.water)?;
        d.set_item("elevation", c.z)?;
        d.set_item("sigma", c.elevation_std)?;
        d.set_item("depth", c.depth)?;
        d.set_item("body", body)?;
        Ok(Some(d))
    }

    /// The observed cells' keys, an `(N, 2)` int64 array of `(kx, ky)` in the map's order.
    fn keys<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        let n = self.map.cells.len();
        let mut a = Array2::zeros((n, 2));
        for (i, c) in self.map.cells.iter().enumerate() {
            a[[i, 0]] = c.key.x;
            a[[i, 1]] = c.key.y;
        }
        a.into_pyarray(py)
    }

    /// The water bodies: a list of dicts (the `report.json` record of each body, plus
    /// `cells`, an `(N, 2)` int64 array of its cell keys). Empty for a map read from disk
    /// (`read_map`), whose `map.ply` does not carry them.
    #[getter]
    fn bodies<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let json = py.import("json")?;
        let out = PyList::empty(py);
        for b in &self.map.bodies {
            let d = json.call_method1("loads", (b.report().to_string(),))?;
            let mut a = Array2::zeros((b.cells.len(), 2));
            for (i, k) in b.cells.iter().enumerate() {
                a[[i, 0]] = k.x;
                a[[i, 1]] = k.y;
            }
            d.set_item("cells", a.into_pyarray(py))?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// Writes `map.ply`, `terrain.ply`, `water.ply` and `map.png` into `dir` (created if
    /// needed), as `tarn build` does.
    fn write(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        py.detach(|| {
            std::fs::create_dir_all(&dir).map_err(|e| tarn::Error::io(&dir, e))?;
            tarn::io::export::write_map_files(&dir, &self.map)
        })
        .map_err(err)
    }

    /// The bytes of the map's `map.ply`: equal bytes, equal maps.
    fn ply_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let bytes = py
            .detach(|| {
                let dir = tempfile_dir()?;
                let p = dir.join("map.ply");
                tarn::io::export::write_map_ply(&p, &self.map)?;
                let b = std::fs::read(&p).map_err(|e| tarn::Error::io(&p, e));
                let _ = std::fs::remove_dir_all(&dir);
                b
            })
            .map_err(err)?;
        Ok(PyBytes::new(py, &bytes))
    }

    fn __repr__(&self) -> String {
        let (r, c) = self.shape();
        format!(
            "<tarn.Map {} cells, {} × {} at {} m, {} water bodies>",
            self.map.cells.len(),
            r,
            c,
            self.map.resolution,
            self.map.bodies.len()
        )
    }
}

/// A private scratch folder for one file.
fn tempfile_dir() -> tarn::Result<PathBuf> {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    let dir = std::env::temp_dir().join(format!(
        "tarn-py-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).map_err(|e| tarn::Error::io(&dir, e))?;
    Ok(dir)
}

/// What `__reduce__` gives pickle: a constructor and its arguments.
type Reduced<'py> = (Bound<'py, PyAny>, (Bound<'py, PyBytes>,));

/// Per-tile cell statistics and water evidence of one or more logs, before the water
/// stage. Merging is exact (integer sums): any split, any order, the same bytes.
#[pyclass(module = "tarn")]
struct TileSet {
    tiles: TileMap,
}

#[pymethods]
impl TileSet {
    /// An empty tile set at a resolution and reference height (metres).
    #[new]
    #[pyo3(signature = (resolution = 0.1, z_ref = 0.0))]
    fn new(resolution: f64, z_ref: f64) -> PyResult<Self> {
        Ok(TileSet {
            tiles: TileMap::new(resolution, z_ref).map_err(err)?,
        })
    }

    /// Adds every cell of `other` into this set (same resolution and reference height).
    fn merge(&mut self, py: Python<'_>, other: PyRef<'_, TileSet>) -> PyResult<()> {
        let o = &other.tiles;
        let t = &mut self.tiles;
        py.detach(|| t.merge(o)).map_err(err)
    }

    /// The tile set format of `docs/distributed.md` (magic `TARNTILE`, version 2, CRC).
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        let b = py.detach(|| self.tiles.to_bytes());
        PyBytes::new(py, &b)
    }

    #[staticmethod]
    fn from_bytes(py: Python<'_>, data: &[u8]) -> PyResult<TileSet> {
        let tiles = py.detach(|| TileMap::from_bytes(data)).map_err(err)?;
        Ok(TileSet { tiles })
    }

    /// Pickles as its bytes (Dask moves tile sets between processes this way).
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<Reduced<'py>> {
        let cls = py.get_type::<TileSet>().getattr("from_bytes")?;
        Ok((cls, (self.to_bytes(py),)))
    }

    #[getter]
    fn resolution(&self) -> f64 {
        self.tiles.resolution()
    }

    #[getter]
    fn z_ref(&self) -> f64 {
        self.tiles.z_ref()
    }

    /// Observed cells.
    fn __len__(&self) -> usize {
        self.tiles.observed_count()
    }

    /// Tiles holding observed cells.
    #[getter]
    fn tile_count(&self) -> usize {
        self.tiles.tile_count()
    }

    /// Points fused into the cells plus points counted below their surface.
    #[getter]
    fn points(&self) -> u64 {
        self.tiles
            .observed()
            .map(|(_, c)| c.hits as u64 + c.below as u64)
            .sum()
    }

    /// The tile keys `(tx, ty)`, in increasing order (tiles are 64 × 64 cells).
    fn tile_keys(&self) -> Vec<(i64, i64)> {
        self.tiles.tile_keys()
    }

    /// Splits by tile key into `parts` sets; part `i` of every log covers the same tiles,
    /// so each part is reduced on its own and the parts merged back are the whole.
    fn partition(&self, py: Python<'_>, parts: usize) -> Vec<TileSet> {
        py.detach(|| self.tiles.partition(parts))
            .into_iter()
            .map(|tiles| TileSet { tiles })
            .collect()
    }

    /// Splits by blocks of `side × side` tiles counted from the tile `origin`:
    /// `[((bx, by), TileSet)]` in block order, block `(bx, by)` holding the tiles with
    /// `ox + bx·side <= tx < ox + (bx + 1)·side`, likewise `ty`.
    #[pyo3(signature = (side, origin = (0, 0)))]
    fn blocks(
        &self,
        py: Python<'_>,
        side: i64,
        origin: TileKey,
    ) -> PyResult<Vec<((i64, i64), TileSet)>> {
        if side < 1 {
            return Err(PyValueError::new_err(format!(
                "blocks of {side} tiles: the side is at least 1"
            )));
        }
        let t = &self.tiles;
        let block = move |(tx, ty): TileKey| {
            (
                tx.saturating_sub(origin.0).div_euclid(side),
                ty.saturating_sub(origin.1).div_euclid(side),
            )
        };
        let out = py.detach(|| {
            let blocks: std::collections::BTreeSet<(i64, i64)> =
                t.tile_keys().into_iter().map(block).collect();
            blocks
                .into_iter()
                .map(|b| {
                    (
                        b,
                        TileSet {
                            tiles: t.select(|k| block(k) == b),
                        },
                    )
                })
                .collect()
        });
        Ok(out)
    }

    /// The tiles within `halo` tiles (Chebyshev) of any tile of `region`: what a region's
    /// water stage reads of this set.
    fn select_near(&self, py: Python<'_>, region: Vec<TileKey>, halo: i64) -> TileSet {
        let t = &self.tiles;
        let tiles = py.detach(|| {
            let region: std::collections::BTreeSet<TileKey> = region.into_iter().collect();
            let h = halo.max(0);
            t.select(|k| {
                region
                    .range((k.0.saturating_sub(h), i64::MIN)..=(k.0.saturating_add(h), i64::MAX))
                    .any(|r| r.1.abs_diff(k.1) <= h as u64)
            })
        });
        TileSet { tiles }
    }

    /// A copy.
    fn copy(&self) -> TileSet {
        TileSet {
            tiles: self.tiles.clone(),
        }
    }

    fn __eq__(&self, other: PyRef<'_, TileSet>) -> bool {
        self.tiles == other.tiles
    }

    fn __repr__(&self) -> String {
        format!(
            "<tarn.TileSet {} cells in {} tiles at {} m>",
            self.tiles.observed_count(),
            self.tiles.tile_count(),
            self.tiles.resolution()
        )
    }
}

/// The cells of one log (or of the frames stamped `start <= t < end`, log seconds) as a
/// `TileSet`. Time chunks of a log do not merge to exactly its one-pass build (a frame's
/// cues read the window the earlier frames left); whole logs merge exactly.
#[pyfunction]
#[pyo3(signature = (path, config = None, start = None, end = None))]
fn build_tiles(
    py: Python<'_>,
    path: PathBuf,
    config: Option<PathBuf>,
    start: Option<f64>,
    end: Option<f64>,
) -> PyResult<TileSet> {
    let cfg = config_of(config)?;
    let range = match (start, end) {
        (None, None) => None,
        (s, e) => Some((s.unwrap_or(f64::NEG_INFINITY), e.unwrap_or(f64::INFINITY))),
    };
    let b = py
        .detach(|| core_build_tiles(&path, &cfg, range))
        .map_err(err)?;
    Ok(TileSet { tiles: b.tiles })
}

/// The water stage over a tile set: water bodies (found whole, across tile borders),
/// classes, hazards and depth.
#[pyfunction]
#[pyo3(signature = (tiles, config = None))]
fn finish(py: Python<'_>, tiles: PyRef<'_, TileSet>, config: Option<PathBuf>) -> PyResult<Map> {
    let cfg = config_of(config)?.mapper;
    let t = &tiles.tiles;
    let map = py.detach(|| finish_tiles(t, &cfg)).map_err(err)?;
    Ok(Map::new(map))
}

/// The map of one log, as `tarn build LOG` makes it (the same cells, bit for bit).
#[pyfunction]
#[pyo3(signature = (path, config = None))]
fn build(py: Python<'_>, path: PathBuf, config: Option<PathBuf>) -> PyResult<Map> {
    build_many(py, vec![path], config)
}

/// The map of many logs in this process: each log built on its own, the tile sets merged,
/// the water stage run once over the whole.
#[pyfunction]
#[pyo3(signature = (paths, config = None))]
fn build_many(py: Python<'_>, paths: Vec<PathBuf>, config: Option<PathBuf>) -> PyResult<Map> {
    let cfg = config_of(config)?;
    let mapper = &cfg.mapper;
    let map = py
        .detach(|| -> tarn::Result<HazardMap> {
            let mut all = TileMap::new(mapper.grid.resolution, mapper.grid.z_ref)?;
            for p in &paths {
                all.merge(&core_build_tiles(p, &cfg, None)?.tiles)?;
            }
            finish_tiles(&all, mapper)
        })
        .map_err(err)?;
    Ok(Map::new(map))
}

/// The water stage of one region of a merged map (`finish_region`): the records and
/// bodies of the tiles it decided, and the tiles it could not decide (a water body, or
/// the ring of cells its surface fit reads, reaching beyond the halo).
#[pyclass(module = "tarn", frozen)]
struct Region {
    region: RegionMap,
}

#[pymethods]
impl Region {
    /// The decided tiles holding observed cells, in increasing key order.
    #[getter]
    fn tiles(&self) -> Vec<TileKey> {
        self.region.tiles.clone()
    }

    /// The region's tiles it could not decide: finish them again with a larger halo.
    #[getter]
    fn undecided(&self) -> Vec<TileKey> {
        self.region.undecided.clone()
    }

    /// Tiles of the map the finish read (the region's and its halo's).
    #[getter]
    fn tiles_read(&self) -> usize {
        self.region.tiles_read
    }

    /// Records (observed cells) of the decided tiles.
    fn __len__(&self) -> usize {
        self.region.cells.len()
    }

    /// The region in tarn's region format (magic `TARNREGN`, CRC).
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        let b = py.detach(|| self.region.to_bytes());
        PyBytes::new(py, &b)
    }

    #[staticmethod]
    fn from_bytes(py: Python<'_>, data: &[u8]) -> PyResult<Region> {
        let region = py.detach(|| RegionMap::from_bytes(data)).map_err(err)?;
        Ok(Region { region })
    }

    /// Pickles as its bytes (Dask moves finished regions to the client this way).
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<Reduced<'py>> {
        let cls = py.get_type::<Region>().getattr("from_bytes")?;
        Ok((cls, (self.to_bytes(py),)))
    }

    fn __repr__(&self) -> String {
        format!(
            "<tarn.Region {} cells in {} tiles, {} undecided, {} tiles read>",
            self.region.cells.len(),
            self.region.tiles.len(),
            self.region.undecided.len(),
            self.region.tiles_read
        )
    }
}

/// The water stage of the region `region` (tile keys) of a merged map whose tile keys lie
/// within `bounds` = `((tx0, ty0), (tx1, ty1))`, inclusive. `tiles` holds every tile of
/// the merged map within `halo` tiles of the region (more is ignored). The records and
/// bodies are those `finish` of the whole merged map gives, for the tiles the region
/// decides; `Region.undecided` lists the others.
#[pyfunction]
#[pyo3(signature = (tiles, region, halo, bounds, config = None))]
fn finish_region(
    py: Python<'_>,
    tiles: PyRef<'_, TileSet>,
    region: Vec<TileKey>,
    halo: i64,
    bounds: (TileKey, TileKey),
    config: Option<PathBuf>,
) -> PyResult<Region> {
    let cfg = config_of(config)?.mapper;
    let t = &tiles.tiles;
    let region = py
        .detach(|| finish_tile_region(t, &region, halo, bounds, &cfg))
        .map_err(err)?;
    Ok(Region { region })
}

/// The map of regions that decided every tile between them, each tile once: the map
/// `finish` of the whole merged map gives, byte for byte, bodies numbered as it numbers
/// them.
#[pyfunction]
fn join_regions(py: Python<'_>, regions: Vec<PyRef<'_, Region>>) -> PyResult<Map> {
    let parts: Vec<RegionMap> = regions.iter().map(|r| r.region.clone()).collect();
    let map = py.detach(|| core_join_regions(parts)).map_err(err)?;
    Ok(Map::new(map))
}

/// A map read back from a build's folder (its `map.ply`; no water bodies).
#[pyfunction]
fn read_map(py: Python<'_>, dir: PathBuf) -> PyResult<Map> {
    let p = if dir.is_dir() {
        dir.join("map.ply")
    } else {
        dir
    };
    let map = py
        .detach(|| tarn::io::mapfile::read_map_ply(&p))
        .map_err(err)?;
    Ok(Map::new(map))
}

/// One frame of a log: the scan, the matched stereo cloud and images, with poses.
#[pyclass(module = "tarn", frozen)]
struct Frame {
    frame: CoreFrame,
}

#[pymethods]
impl Frame {
    /// The scan's stamp, log seconds.
    #[getter]
    fn stamp(&self) -> f64 {
        self.frame.stamp
    }

    /// The vehicle's position `(x, y, z)` in the map frame.
    #[getter]
    fn position(&self) -> (f64, f64, f64) {
        let t = &self.frame.base_to_map.translation.vector;
        (t.x, t.y, t.z)
    }

    /// The lidar points in the map frame, `(N, 3)` float64 (missing returns left out);
    /// `None` without a lidar scan.
    fn lidar_points<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        let c = self.frame.lidar.as_ref()?;
        let pts: Vec<[f64; 3]> = (0..c.len())
            .filter(|&i| c.xyz[i].iter().all(|v| v.is_finite()))
            .map(|i| {
                let p = c.point_in_map(i);
                [p.x, p.y, p.z]
            })
            .collect();
        let mut a = Array2::zeros((pts.len(), 3));
        for (i, p) in pts.iter().enumerate() {
            for (k, v) in p.iter().enumerate() {
                a[[i, k]] = *v;
            }
        }
        Some(a.into_pyarray(py))
    }

    fn __repr__(&self) -> String {
        let f = &self.frame;
        format!(
            "<tarn.Frame at {:.3} s: lidar {}, stereo {}, images {}>",
            f.stamp,
            f.lidar.as_ref().map_or(0, |c| c.len()),
            f.stereo.as_ref().map_or(0, |c| c.len()),
            [&f.image, &f.swir, &f.mwir]
                .iter()
                .filter(|i| i.is_some())
                .count()
        )
    }
}

/// The frames of a log, in order; frames that cannot be built are skipped (their errors
/// in `errors`).
#[pyclass(module = "tarn", unsendable)]
struct FrameIter {
    stream: FrameStream,
    errors: Vec<String>,
}

#[pymethods]
impl FrameIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self) -> PyResult<Frame> {
        loop {
            match self.stream.next() {
                Some(Ok(frame)) => return Ok(Frame { frame }),
                Some(Err(e)) => self.errors.push(e.to_string()),
                None => {
                    if let Some(e) = self.stream.fatal_error() {
                        return Err(TarnError::new_err(e.to_string()));
                    }
                    return Err(PyStopIteration::new_err(()));
                }
            }
        }
    }

    /// Messages or frames that could not be used so far, with why.
    #[getter]
    fn errors(&self) -> Vec<String> {
        self.errors.clone()
    }
}

/// The frames of a log as `tarn build` reads them (the config's `[log]` settings; the
/// frame topic chosen from the log unless the config names one).
#[pyfunction]
#[pyo3(signature = (path, config = None))]
fn read_frames(path: PathBuf, config: Option<PathBuf>) -> PyResult<FrameIter> {
    let cfg = config_of(config)?;
    let summary = tarn_log::log::summarize_quick(&path).map_err(err)?;
    let log_cfg = tarn_log::build::frame_log_config(&cfg, &summary, &path).map_err(err)?;
    let stream = FrameStream::open(&path, &log_cfg).map_err(err)?;
    Ok(FrameIter {
        stream,
        errors: Vec::new(),
    })
}

/// The online mapper: one `update(frame)` per frame; `finish()` is the map of everything.
#[pyclass(module = "tarn", unsendable)]
struct Mapper {
    mapper: Option<CoreMapper>,
}

impl Mapper {
    fn take(&mut self) -> PyResult<CoreMapper> {
        self.mapper
            .take()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))
    }
}

#[pymethods]
impl Mapper {
    /// `publish=True` runs the water stage after every frame (`hazard_map()` is then the
    /// window's latest map); off, as an offline build runs, only `finish()` runs it.
    #[new]
    #[pyo3(signature = (config = None, publish = false))]
    fn new(config: Option<PathBuf>, publish: bool) -> PyResult<Self> {
        let mut m = CoreMapper::new(config_of(config)?.mapper).map_err(err)?;
        m.set_publish(publish);
        Ok(Mapper { mapper: Some(m) })
    }

    /// Fuses one frame; returns its report (frame index, stamp, points, stage times).
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        frame: PyRef<'_, Frame>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let m = self
            .mapper
            .as_mut()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        let r = m.update(&frame.frame).map_err(err)?;
        let d = PyDict::new(py);
        d.set_item("frame_index", r.frame_index)?;
        d.set_item("stamp", r.stamp)?;
        d.set_item("lidar_fused", r.lidar_points().map_or(0, |s| s.fused))?;
        d.set_item("stereo_fused", r.stereo_points().map_or(0, |s| s.fused))?;
        d.set_item("warnings", r.warnings.clone())?;
        let t = PyDict::new(py);
        for (name, v) in tarn::mapper::StageTimes::NAMES
            .iter()
            .zip(r.times_s.values())
        {
            t.set_item(*name, v)?;
        }
        d.set_item("times_s", t)?;
        Ok(d)
    }

    /// Measures the sensors' noise on a frame without mapping it, as an offline build does
    /// on the log's first frames before it maps any (`calibration_settled` says when that
    /// is enough; `hold_calibration()` then keeps the values for every frame after).
    fn calibrate(&mut self, frame: PyRef<'_, Frame>) -> PyResult<()> {
        let m = self
            .mapper
            .as_mut()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        m.calibrate(&frame.frame).map_err(err)
    }

    /// Whether the sensors' noise is measured well enough to be held.
    #[getter]
    fn calibration_settled(&self) -> bool {
        self.mapper
            .as_ref()
            .is_some_and(|m| m.calibration_settled())
    }

    /// Holds the sensors' noise as measured so far, for every frame that follows.
    fn hold_calibration(&mut self) -> PyResult<()> {
        let m = self
            .mapper
            .as_mut()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        m.hold_calibration();
        Ok(())
    }

    /// Every sensor value used so far, its source and what the log measured, as JSON text.
    fn calibration(&self) -> PyResult<String> {
        let m = self
            .mapper
            .as_ref()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        serde_json::to_string(m.calibration()).map_err(|e| TarnError::new_err(e.to_string()))
    }

    /// Frames fused so far.
    #[getter]
    fn frames(&self) -> u64 {
        self.mapper.as_ref().map_or(0, |m| m.frames())
    }

    /// The latest published map of the window (empty until one was published).
    fn hazard_map(&self) -> PyResult<Map> {
        let m = self
            .mapper
            .as_ref()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        Ok(Map::new((*m.hazard_map()).clone()))
    }

    /// The cells that have left the window so far, as a `TileSet`, which the mapper then
    /// forgets: they are final, and the merge of every take and `finish_tiles()` is what
    /// `finish_tiles()` alone would have given, byte for byte.
    fn take_left_tiles(&mut self, py: Python<'_>) -> PyResult<TileSet> {
        let m = self
            .mapper
            .as_mut()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        let tiles = py.detach(|| m.take_left_tiles());
        Ok(TileSet { tiles })
    }

    /// Ends the run: the map of everything the mapper saw. The mapper cannot be used after.
    fn finish(&mut self, py: Python<'_>) -> PyResult<Map> {
        let m = self.take()?;
        let (_, map) = py.detach(|| m.finish_map()).map_err(err)?;
        Ok(Map::new(map))
    }

    /// Ends the run: everything the mapper saw as a `TileSet`, for merging with others.
    fn finish_tiles(&mut self, py: Python<'_>) -> PyResult<TileSet> {
        let m = self.take()?;
        let tiles = py.detach(|| m.finish());
        Ok(TileSet { tiles })
    }
}

#[pymodule]
fn _tarn(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("TarnError", m.py().get_type::<TarnError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<Map>()?;
    m.add_class::<TileSet>()?;
    m.add_class::<Region>()?;
    m.add_class::<Frame>()?;
    m.add_class::<FrameIter>()?;
    m.add_class::<Mapper>()?;
    m.add_function(wrap_pyfunction!(build, m)?)?;
    m.add_function(wrap_pyfunction!(build_many, m)?)?;
    m.add_function(wrap_pyfunction!(build_tiles, m)?)?;
    m.add_function(wrap_pyfunction!(finish, m)?)?;
    m.add_function(wrap_pyfunction!(finish_region, m)?)?;
    m.add_function(wrap_pyfunction!(join_regions, m)?)?;
    m.add_function(wrap_pyfunction!(read_map, m)?)?;
    m.add_function(wrap_pyfunction!(read_frames, m)?)?;
    Ok(())
}
