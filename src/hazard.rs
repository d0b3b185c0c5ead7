//! The map product: one record per observed cell, with the classes and hazards of the
//! export contract (DESIGN.md, "Map export").

use serde::{Deserialize, Serialize};

use crate::grid::{CellKey, Fusion, TileMap};

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

impl MapCell {
    /// The record of a tile-map cell with the given surface, water and class.
    #[allow(clippy::too_many_arguments)]
    fn of(
        tiles: &TileMap,
        key: CellKey,
        c: &crate::grid::CellStats,
        z: f64,
        water: f32,
        depth: f32,
        class: Class,
        hazard: Hazard,
    ) -> Self {
        let (x, y) = tiles.centre_of(key);
        MapCell {
            key,
            x,
            y,
            z,
            elevation_std: c.elevation_std_m().unwrap_or(f64::NAN),
            water,
            depth,
            class,
            hazard,
            hits: c.hits,
            below: c.below,
        }
    }
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
                Some(MapCell::of(
                    tiles,
                    key,
                    &c,
                    z,
                    0.0,
                    0.0,
                    Class::Ground,
                    Hazard::Free,
                ))
            })
            .collect();
        HazardMap {
            resolution: tiles.resolution(),
            cells,
        }
    }

    /// The map with water from the cues' evidence (see [`crate::grid::Evidence`] for the
    /// fusion rule): `water` is the fused probability of every cell; cells observed only
    /// through water evidence (no returns: a no-return region, reflection crossings) are
    /// included at their measured water level. Provisional until the water stage (issue 8):
    /// a cell with `water ≥ 0.9` is class Water, `z` its water level when one was measured,
    /// `depth` the mean refraction-corrected bottom-return depth (NaN when unknown), and
    /// hazard ShallowWater when that depth is at most `fording_depth_m`, else DeepWater.
    pub fn with_water(tiles: &TileMap, fusion: &Fusion, fording_depth_m: f64) -> Self {
        let cells = tiles
            .observed()
            .filter_map(|(key, c)| {
                let p = c.ev.water_probability(fusion);
                let level = c.ev.level_mm().map(|mm| tiles.z_ref() + mm * 1e-3);
                let elevation = tiles.elevation(&c);
                let water = p >= 0.9;
                let z = if water {
                    level.or(elevation)
                } else {
                    elevation.or(level)
                }?;
                let depth = if water {
                    c.ev.depth_m().unwrap_or(f64::NAN)
                } else {
                    0.0
                };
                let (class, hazard) = if water {
                    let shallow = depth <= fording_depth_m;
                    (
                        Class::Water,
                        if shallow {
                            Hazard::ShallowWater
                        } else {
                            Hazard::DeepWater
                        },
                    )
                } else {
                    (Class::Ground, Hazard::Free)
                };
                Some(MapCell::of(
                    tiles,
                    key,
                    &c,
                    z,
                    p as f32,
                    depth as f32,
                    class,
                    hazard,
                ))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{CellStats, Evidence};

    #[test]
    fn water_evidence_reaches_the_map() {
        let mut t = TileMap::new(0.1, 0.0).unwrap();
        let mut ground = CellStats::default();
        ground.add(100, 65536);
        t.add(CellKey::new(0, 0), &ground);
        // Observed with no return only: no elevation, a level of 0.05 m, water.
        let mut ev = Evidence {
            noret: 20,
            ..Evidence::default()
        };
        ev.add_level(50);
        ev.add_depth(0.2);
        t.add(
            CellKey::new(1, 0),
            &CellStats {
                ev,
                ..CellStats::default()
            },
        );
        let m = HazardMap::with_water(&t, &Fusion::default(), 0.3);
        assert_eq!(m.cells.len(), 2);
        let (g, w) = (&m.cells[0], &m.cells[1]);
        assert_eq!(g.class, Class::Ground);
        assert!((g.water - 0.05).abs() < 1e-6 && g.depth == 0.0);
        assert_eq!(w.class, Class::Water);
        assert_eq!(w.hazard, Hazard::ShallowWater);
        assert!((w.z - 0.05).abs() < 1e-9 && (w.depth - 0.2).abs() < 1e-6);
        // The geometry-only map leaves the evidence-only cell out.
        assert_eq!(HazardMap::from_elevation(&t).cells.len(), 1);
    }
}
