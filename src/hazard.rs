//! The map product: one record per observed cell, with the classes and hazards of the
//! export contract (DESIGN.md, "Map export").

use serde::{Deserialize, Serialize};

use crate::grid::{CellKey, TileMap};

/// Cell class codes of the export contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[repr(u8)]
pub enum Class {
    Unknown = 0,
    Ground = 1,
    Water = 2,
    Vegetation = 3,
    Obstacle = 4,
    SnowIce = 5,
}

impl Class {
    pub const ALL: [Class; 6] = [
        Class::Unknown,
        Class::Ground,
        Class::Water,
        Class::Vegetation,
        Class::Obstacle,
        Class::SnowIce,
    ];

    /// The colour viewers show for the class.
    pub fn colour(self) -> [u8; 3] {
        match self {
            Class::Unknown => [128, 128, 128],
            Class::Ground => [176, 148, 104],
            Class::Water => [30, 100, 220],
            Class::Vegetation => [56, 150, 60],
            Class::Obstacle => [200, 50, 40],
            Class::SnowIce => [225, 240, 255],
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Class::Unknown => "unknown",
            Class::Ground => "ground",
            Class::Water => "water",
            Class::Vegetation => "vegetation",
            Class::Obstacle => "obstacle",
            Class::SnowIce => "snow/ice",
        }
    }
}

/// Hazard codes of the export contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[repr(u8)]
pub enum Hazard {
    Free = 0,
    /// Water within the vehicle's fording depth.
    ShallowWater = 1,
    /// Water deeper than the fording depth, or of unknown depth.
    DeepWater = 2,
    /// A geometric obstacle (step or slope beyond the vehicle's limits).
    Obstacle = 3,
}

/// One observed cell of the map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MapCell {
    pub key: CellKey,
    /// Cell centre (map frame).
    pub x: f64,
    pub y: f64,
    /// Terrain elevation, or the water surface elevation for water cells.
    pub z: f64,
    pub elevation_std: f64,
    /// Probability of water, 0..1.
    pub water: f32,
    /// Water depth in metres: 0 for dry cells, NaN where unknown.
    pub depth: f32,
    pub class: Class,
    pub hazard: Hazard,
    /// Fused points and below-surface points of the cell.
    pub hits: u32,
    pub below: u32,
}

/// A map ready for export: observed cells in a deterministic order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HazardMap {
    pub resolution: f64,
    pub cells: Vec<MapCell>,
}

impl HazardMap {
    /// The geometry-only map of a tile map: every cell with fused points is ground, free.
    /// (Water, vegetation and obstacles come from the later stages of the pipeline.)
    /// Cells holding only below-surface points have no elevation and are left out.
    pub fn from_elevation(tiles: &TileMap) -> Self {
        let cells = tiles
            .observed()
            .filter_map(|(key, c)| {
                let z = tiles.elevation(&c)?;
                let (x, y) = tiles.centre_of(key);
                Some(MapCell {
                    key,
                    x,
                    y,
                    z,
                    elevation_std: c.elevation_std_m().unwrap_or(f64::NAN),
                    water: 0.0,
                    depth: 0.0,
                    class: Class::Ground,
                    hazard: Hazard::Free,
                    hits: c.hits,
                    below: c.below,
                })
            })
            .collect();
        HazardMap {
            resolution: tiles.resolution(),
            cells,
        }
    }

    /// Inclusive key bounds of the cells.
    pub fn key_bounds(&self) -> Option<(CellKey, CellKey)> {
        let first = self.cells.first()?.key;
        Some(self.cells.iter().fold((first, first), |(lo, hi), c| {
            (
                CellKey::new(lo.x.min(c.key.x), lo.y.min(c.key.y)),
                CellKey::new(hi.x.max(c.key.x), hi.y.max(c.key.y)),
            )
        }))
    }

    /// Number of cells of each class, indexed by class code.
    pub fn class_counts(&self) -> [usize; 6] {
        let mut n = [0; 6];
        for c in &self.cells {
            n[c.class as usize] += 1;
        }
        n
    }
}
