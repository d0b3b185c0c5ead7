//! `tarn.Map`: a hazard map, its layers as arrays, lookups by position, and its files.

use std::path::PathBuf;

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

use tarn::grid::CellKey;
use tarn::hazard::{HazardMap, MapLookup};

use crate::{err, TarnError};

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
pub(crate) struct Map {
    map: HazardMap,
    /// The map looked up by position, built on the first `at`.
    lookup: std::sync::OnceLock<MapLookup>,
}

impl Map {
    pub(crate) fn new(map: HazardMap) -> Self {
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
            tarn::io::write_map_files(&dir, &self.map)
        })
        .map_err(err)
    }

    /// The bytes of the map's `map.ply`: equal bytes, equal maps.
    fn ply_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let bytes = py
            .detach(|| {
                let dir = tempfile_dir()?;
                let p = dir.join("map.ply");
                tarn::io::write_map_ply(&p, &self.map)?;
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

/// A map read back from a build's folder (its `map.ply`; no water bodies).
#[pyfunction]
pub(crate) fn read_map(py: Python<'_>, dir: PathBuf) -> PyResult<Map> {
    let p = if dir.is_dir() {
        dir.join("map.ply")
    } else {
        dir
    };
    let map = py.detach(|| tarn::io::read_map_ply(&p)).map_err(err)?;
    Ok(Map::new(map))
}
