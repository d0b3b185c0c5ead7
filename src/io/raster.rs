//! The hazard map as a dense raster: the layers the ROS and GIS exports write
//! (`tarn_log::ros_export`, [`crate::io::write_geotiff`]), over the bounding box of the
//! observed cells.
//!
//! Cell `(ix, iy)` of the raster is the map cell with key `(lo.x + ix, lo.y + iy)`: `ix`
//! grows with x, `iy` with y. Each exporter reorders the cells into its own convention.

use crate::error::{Error, Result};
use crate::grid::CellKey;
use crate::hazard::{HazardMap, MapCell};

/// Largest raster written, cells: 2^28 cells (a 1.6 km square at 0.10 m) is 1 GiB per
/// float layer. A sparse map over a larger box is refused rather than allocated.
pub(crate) const MAX_RASTER_CELLS: usize = 1 << 28;

/// A layer of the exports, in the order they are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layer {
    /// Terrain elevation, or the water surface for water cells, metres (map frame).
    Elevation,
    /// One σ of the elevation, metres.
    ElevationStd,
    /// Probability of water, 0..1.
    WaterProbability,
    /// Class code of `map.ply` (0 unknown, 1 ground, 2 water, 3 vegetation, 4 obstacle,
    /// 5 snow/ice).
    Class,
    /// Hazard code of `map.ply` (0 free, 1 shallow water, 2 deep or unknown-depth water,
    /// 3 obstacle).
    Hazard,
    /// Water depth, metres: 0 for dry cells, NaN where unknown.
    Depth,
}

impl Layer {
    /// Every layer, in the order of the GridMap's layers and the GeoTIFF's bands.
    pub const ALL: [Layer; 6] = [
        Layer::Elevation,
        Layer::ElevationStd,
        Layer::WaterProbability,
        Layer::Class,
        Layer::Hazard,
        Layer::Depth,
    ];

    /// The layer's name in the GridMap and the GeoTIFF band description.
    pub fn name(self) -> &'static str {
        match self {
            Layer::Elevation => "elevation",
            Layer::ElevationStd => "elevation_std",
            Layer::WaterProbability => "water_probability",
            Layer::Class => "class",
            Layer::Hazard => "hazard",
            Layer::Depth => "depth",
        }
    }

    /// The value of an observed cell.
    pub fn value(self, c: &MapCell) -> f32 {
        match self {
            Layer::Elevation => c.z as f32,
            Layer::ElevationStd => c.elevation_std as f32,
            Layer::WaterProbability => c.water,
            Layer::Class => c.class as u8 as f32,
            Layer::Hazard => c.hazard as u8 as f32,
            Layer::Depth => c.depth,
        }
    }
}

/// The observed cells of a map placed on their bounding box.
#[derive(Debug, Clone)]
pub struct MapRaster<'a> {
    map: &'a HazardMap,
    /// Key of raster cell (0, 0).
    pub lo: CellKey,
    /// Cells along x.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
    /// Index into `map.cells` of raster cell `ix + nx * iy`, `u32::MAX` where unobserved.
    index: Vec<u32>,
}

impl<'a> MapRaster<'a> {
    /// The raster of `map` (an empty map gives a 0 × 0 raster). A box of more than 2^28
    /// cells is refused.
    pub fn new(map: &'a HazardMap) -> Result<Self> {
        let Some(first) = map.cells.first() else {
            return Ok(MapRaster {
                map,
                lo: CellKey::new(0, 0),
                nx: 0,
                ny: 0,
                index: Vec::new(),
            });
        };
        let (lo, hi) = map
            .cells
            .iter()
            .fold((first.key, first.key), |(lo, hi), c| {
                (
                    CellKey::new(lo.x.min(c.key.x), lo.y.min(c.key.y)),
                    CellKey::new(hi.x.max(c.key.x), hi.y.max(c.key.y)),
                )
            });
        let nx = (hi.x - lo.x + 1) as usize;
        let ny = (hi.y - lo.y + 1) as usize;
        if nx.saturating_mul(ny) > MAX_RASTER_CELLS || map.cells.len() >= u32::MAX as usize {
            return Err(Error::invalid(
                "map raster",
                format!(
                    "the observed cells span {nx} × {ny} cells, more than the {MAX_RASTER_CELLS} a raster export holds"
                ),
            ));
        }
        let mut index = vec![u32::MAX; nx * ny];
        for (i, c) in map.cells.iter().enumerate() {
            let (ix, iy) = ((c.key.x - lo.x) as usize, (c.key.y - lo.y) as usize);
            index[ix + nx * iy] = i as u32;
        }
        Ok(MapRaster {
            map,
            lo,
            nx,
            ny,
            index,
        })
    }

    /// Cell edge length, metres.
    pub fn resolution(&self) -> f64 {
        self.map.resolution
    }

    /// The observed cell at raster `(ix, iy)`, if any.
    pub fn cell(&self, ix: usize, iy: usize) -> Option<&'a MapCell> {
        match self.index[ix + self.nx * iy] {
            u32::MAX => None,
            i => Some(&self.map.cells[i as usize]),
        }
    }

    /// Map-frame coordinates of the raster's lower-left corner (min x, min y), metres.
    pub fn corner_min(&self) -> [f64; 2] {
        let r = self.resolution();
        [self.lo.x as f64 * r, self.lo.y as f64 * r]
    }

    /// The layer's value at raster `(ix, iy)`: NaN where the cell is unobserved.
    pub fn value(&self, layer: Layer, ix: usize, iy: usize) -> f32 {
        self.cell(ix, iy).map_or(f32::NAN, |c| layer.value(c))
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::hazard::{Class, Hazard};

    pub(crate) fn cell(kx: i64, ky: i64, z: f64, hazard: Hazard) -> MapCell {
        let (x, y) = crate::grid::centre_of(0.5, CellKey::new(kx, ky));
        MapCell {
            key: CellKey::new(kx, ky),
            x,
            y,
            z,
            elevation_std: 0.01,
            water: if hazard == Hazard::Free { 0.1 } else { 0.9 },
            depth: if hazard == Hazard::DeepWater {
                f32::NAN
            } else {
                0.0
            },
            class: if hazard == Hazard::Free {
                Class::Ground
            } else {
                Class::Water
            },
            hazard,
            hits: 1,
            below: 0,
        }
    }

    #[test]
    fn raster_spans_the_observed_cells() {
        let map = HazardMap {
            resolution: 0.5,
            cells: vec![
                cell(-2, 3, 1.0, Hazard::Free),
                cell(1, 4, 2.0, Hazard::DeepWater),
            ],
            bodies: Vec::new(),
        };
        let r = MapRaster::new(&map).unwrap();
        assert_eq!((r.lo, r.nx, r.ny), (CellKey::new(-2, 3), 4, 2));
        assert_eq!(r.corner_min(), [-1.0, 1.5]);
        assert_eq!(r.value(Layer::Elevation, 0, 0), 1.0);
        assert_eq!(r.value(Layer::Hazard, 3, 1), 2.0);
        assert!(r.value(Layer::Depth, 3, 1).is_nan());
        assert!(r.value(Layer::Elevation, 1, 0).is_nan());
        let empty = HazardMap {
            resolution: 0.5,
            cells: Vec::new(),
            bodies: Vec::new(),
        };
        assert_eq!(MapRaster::new(&empty).unwrap().nx, 0);
    }
}
