//! `tarn.Region`: the water stage of one region of a merged map, and joining regions
//! back into one map.

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyBytes;

use tarn::hazard::{join_regions as core_join_regions, RegionMap, TileKey};
use tarn_log::build::finish_tile_region;

use crate::map::Map;
use crate::tiles::TileSet;
use crate::{config_of, err, Reduced};

/// The water stage of one region of a merged map (`finish_region`): the records and
/// bodies of the tiles it decided, and the tiles it could not decide (a water body, or
/// the ring of cells its surface fit reads, reaching beyond the halo).
#[pyclass(module = "tarn", frozen)]
pub(crate) struct Region {
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
pub(crate) fn finish_region(
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
pub(crate) fn join_regions(py: Python<'_>, regions: Vec<PyRef<'_, Region>>) -> PyResult<Map> {
    let parts: Vec<RegionMap> = regions.iter().map(|r| r.region.clone()).collect();
    let map = py.detach(|| core_join_regions(parts)).map_err(err)?;
    Ok(Map::new(map))
}
