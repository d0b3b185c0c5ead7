//! `tarn.TileSet` and the builds: the cells of logs before the water stage, merging them,
//! and the water stage over them.

use std::path::PathBuf;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use tarn::grid::TileMap;
use tarn::hazard::{HazardMap, TileKey};
use tarn_log::build::{build_tiles as core_build_tiles, finish_tiles};

use crate::map::Map;
use crate::{config_of, err, Reduced};

/// Per-tile cell statistics and water evidence of one or more logs, before the water
/// stage. Merging is exact (integer sums): any split, any order, the same bytes.
#[pyclass(module = "tarn")]
pub(crate) struct TileSet {
    pub(crate) tiles: TileMap,
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

    /// The tile set format of `docs/distributed.md` (magic `TARNTILE`, version 3, CRC).
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

    /// The colour labels' false alarms on the dry ground of the logs this set was built
    /// from: `(samples, labelled water)`. Merging sets sums them; a cut of a set
    /// (`blocks`, `select_near`, `partition` but its first part) holds none.
    #[getter]
    fn colour_false_alarms(&self) -> (u64, u64) {
        let a = self.tiles.false_alarms().colour;
        (a.samples, a.water)
    }

    /// The SWIR labels' false alarms, as `colour_false_alarms`.
    #[getter]
    fn swir_false_alarms(&self) -> (u64, u64) {
        let a = self.tiles.false_alarms().swir;
        (a.samples, a.water)
    }

    /// Adds colour false alarms `(samples, labelled water)` measured on this set's logs: a
    /// region cut from a merged map is finished with the whole build's.
    fn add_colour_false_alarms(&mut self, samples: u64, water: u64) -> PyResult<()> {
        let colour = false_alarms(samples, water)?;
        self.tiles.add_false_alarms(&tarn::grid::LabelFalseAlarms {
            colour,
            ..Default::default()
        });
        Ok(())
    }

    /// Adds SWIR false alarms, as `add_colour_false_alarms`.
    fn add_swir_false_alarms(&mut self, samples: u64, water: u64) -> PyResult<()> {
        let swir = false_alarms(samples, water)?;
        self.tiles.add_false_alarms(&tarn::grid::LabelFalseAlarms {
            swir,
            ..Default::default()
        });
        Ok(())
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
pub(crate) fn build_tiles(
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
pub(crate) fn finish(
    py: Python<'_>,
    tiles: PyRef<'_, TileSet>,
    config: Option<PathBuf>,
) -> PyResult<Map> {
    let cfg = config_of(config)?.mapper;
    let t = &tiles.tiles;
    let map = py.detach(|| finish_tiles(t, &cfg)).map_err(err)?;
    Ok(Map::new(map))
}

/// The map of one log, as `tarn build LOG` makes it (the same cells, bit for bit).
#[pyfunction]
#[pyo3(signature = (path, config = None))]
pub(crate) fn build(py: Python<'_>, path: PathBuf, config: Option<PathBuf>) -> PyResult<Map> {
    build_many(py, vec![path], config)
}

/// The map of many logs in this process: each log built on its own, the tile sets merged,
/// the water stage run once over the whole.
#[pyfunction]
#[pyo3(signature = (paths, config = None))]
pub(crate) fn build_many(
    py: Python<'_>,
    paths: Vec<PathBuf>,
    config: Option<PathBuf>,
) -> PyResult<Map> {
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

/// False alarms `(samples, labelled water)`, refused when there are more alarms than samples.
fn false_alarms(samples: u64, water: u64) -> PyResult<tarn::grid::FalseAlarms> {
    if water > samples {
        return Err(PyValueError::new_err(format!(
            "{water} false alarms of {samples} samples"
        )));
    }
    Ok(tarn::grid::FalseAlarms { samples, water })
}
