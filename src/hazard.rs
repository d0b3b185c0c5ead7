//! The map product: one record per observed cell, with the classes and hazards of the
//! export contract (DESIGN.md, "Map export").
//!
//! Exports: [`HazardMap`] of [`MapCell`]s, each with a [`Class`] and a [`Hazard`]; its
//! settings ([`HazardConfig`], [`Vehicle`]); look-ups by position ([`MapIndex`],
//! [`MapLookup`]); the slope and step test ([`terrain_hazard`] over a [`Neighbourhood`]);
//! and the map finished region by region ([`finish_by_regions`], [`finish_region`],
//! [`join_regions`], [`RegionMap`], [`TileKey`], [`SplitStats`]).

use std::collections::HashMap;

use serde::{Deserialize, Serialize};

use crate::cues::{PriorLevel, WaterPrior};
use crate::error::Result;
use crate::grid::{BuildKeyHasher, CellKey, CellStats, TileMap};
use crate::water::{find_bodies_and_void, WaterBody};

mod config;
mod dry;
mod lookup;
mod record;
mod region;
mod terrain;
mod window;

pub use config::{HazardConfig, Vehicle};
use dry::{dry_terrain, Dry, DryCells, NOT_DRY};
pub use lookup::{MapIndex, MapLookup};
use record::{cell_records, voided_water, water_surface, CellRule, Seen};
pub use region::{finish_by_regions, finish_region, join_regions, RegionMap, SplitStats, TileKey};
pub use terrain::{terrain_hazard, Neighbourhood};
pub(crate) use window::WindowScratch;

/// Cell-keyed maps of the hazard pass: every observed cell goes through them each frame.
type CellMap<V> = HashMap<CellKey, V, BuildKeyHasher>;

/// Cell class codes of the export contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[repr(u8)]
pub enum Class {
    /// Observed, but not classified ground, water or obstacle.
    Unknown = 0,
    /// Ground (its hazard says whether the vehicle can drive its slope).
    Ground = 1,
    /// Part of a water body.
    Water = 2,
    /// Vegetation (a contract code the map builder does not assign).
    Vegetation = 3,
    /// A step beyond the vehicle's limit.
    Obstacle = 4,
    /// Snow or ice (a contract code the map builder does not assign).
    SnowIce = 5,
}

impl Class {
    /// Every class, in code order.
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

    /// The class's name in reports and legends.
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
    /// Nothing the vehicle cannot drive.
    Free = 0,
    /// Water within the vehicle's fording depth.
    ShallowWater = 1,
    /// Water deeper than the fording depth, or of unknown depth.
    DeepWater = 2,
    /// A geometric obstacle (step or slope beyond the vehicle's limits).
    Obstacle = 3,
}

impl Hazard {
    /// The hazard's name, as `report.json`'s `hazard_cells` names it.
    pub fn name(self) -> &'static str {
        match self {
            Hazard::Free => "free",
            Hazard::ShallowWater => "shallow_water",
            Hazard::DeepWater => "deep_water",
            Hazard::Obstacle => "obstacle",
        }
    }
}

/// One observed cell of the map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MapCell {
    /// Global address of the cell.
    pub key: CellKey,
    /// Cell centre x (map frame), metres.
    pub x: f64,
    /// Cell centre y (map frame), metres.
    pub y: f64,
    /// Terrain elevation, or the water surface elevation for water cells.
    pub z: f64,
    /// Standard deviation of the fused elevation, metres; NaN without an elevation.
    pub elevation_std: f64,
    /// Probability of water, 0..1.
    pub water: f32,
    /// Water depth in metres: 0 for dry cells, NaN where unknown.
    pub depth: f32,
    /// What the cell is.
    pub class: Class,
    /// What the cell means to the vehicle.
    pub hazard: Hazard,
    /// Points fused into the elevation.
    pub hits: u32,
    /// Points far below the cell's surface (not averaged in).
    pub below: u32,
}

/// A map ready for export: observed cells in a deterministic order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HazardMap {
    /// Cell edge length, metres.
    pub resolution: f64,
    /// Observed cells, in a deterministic order.
    pub cells: Vec<MapCell>,
    /// Water bodies (empty for a geometry-only map).
    #[serde(default)]
    pub bodies: Vec<WaterBody>,
}

impl HazardMap {
    /// The prior this map's water bodies give the next frames' cues: their surface levels,
    /// carried `reach_m` beyond their cells (in steps of whole cells, 4-connected). Cells of
    /// no body, and bodies with a non-finite surface, give nothing.
    pub fn water_prior(&self, reach_m: f64) -> WaterPrior {
        let sigma: CellMap<f64> = self
            .bodies
            .iter()
            .flat_map(|b| b.cells.iter().map(|&k| (k, b.level_residual_m)))
            .collect();
        let levels = self.cells.iter().filter_map(|c| {
            let &sigma = sigma.get(&c.key)?;
            Some((c.key, PriorLevel { z: c.z, sigma }))
        });
        WaterPrior::from_levels(self.resolution, levels, reach_m)
    }

    /// The geometry-only map of a tile map: every cell with fused points is ground, free.
    /// (Water, vegetation and obstacles come from the later stages of the pipeline.)
    /// Cells holding only below-surface points have no elevation and are left out.
    pub fn from_elevation(tiles: &TileMap) -> Self {
        let cells = tiles
            .observed()
            .filter_map(|(key, c)| {
                let z = tiles.elevation(&c)?;
                Some(Seen::of(key, &c, 0.0).record(
                    tiles.resolution(),
                    z,
                    0.0,
                    Class::Ground,
                    Hazard::Free,
                ))
            })
            .collect();
        HazardMap {
            resolution: tiles.resolution(),
            cells,
            bodies: Vec::new(),
        }
    }

    /// A map of cells without water bodies.
    pub fn new(resolution: f64, cells: Vec<MapCell>) -> Self {
        HazardMap {
            resolution,
            cells,
            bodies: Vec::new(),
        }
    }

    /// The `report.json` record of the water bodies (see [`WaterBody::report`]).
    pub fn water_report(&self) -> serde_json::Value {
        crate::water::bodies_report(&self.bodies)
    }

    /// The hazard map of a tile map: water bodies (see [`crate::water`]), then one record
    /// per observed cell with class, hazard, water probability, z (the fitted water surface
    /// for water cells, else the terrain elevation, else the cues' water level) and depth
    /// (0 dry, NaN where unknown). Body ids start at 1. The fusion rule is `cfg`'s,
    /// measured on the map's logs ([`HazardConfig::measured_on`]).
    pub fn from_tiles(tiles: &TileMap, cfg: &HazardConfig) -> Result<Self> {
        Self::from_tiles_after(tiles, cfg, &[])
    }

    /// As [`HazardMap::from_tiles`], with body ids carried over from the bodies of an
    /// earlier snapshot (a body that grew or merged keeps its largest ancestor's id).
    pub(crate) fn from_tiles_after(
        tiles: &TileMap,
        cfg: &HazardConfig,
        previous: &[WaterBody],
    ) -> Result<Self> {
        Self::from_cells_after(tiles, tiles.observed().collect(), cfg, previous)
    }

    /// [`HazardMap::from_tiles`] of the cells `observed` (unique keys, in the order the
    /// map's cells should have), with body ids carried over from the bodies of an earlier
    /// snapshot, `previous` (a body that grew or merged keeps its largest ancestor's id); of
    /// `tiles` only the resolution, the reference height and the false alarms
    /// ([`HazardConfig::measured_on`]) are read. The mapper's window snapshot takes this
    /// path with an empty tile map, skipping the copy of the window into tiles.
    pub fn from_cells_after(
        tiles: &TileMap,
        observed: Vec<(CellKey, CellStats)>,
        cfg: &HazardConfig,
        previous: &[WaterBody],
    ) -> Result<Self> {
        let cfg = &cfg.measured_on(tiles);
        cfg.validate()?;
        let (bodies, void) =
            find_bodies_and_void(tiles, &observed, &cfg.fusion, &cfg.water, previous);
        let res = tiles.resolution();
        let water = water_surface(&bodies, res);
        let cells = cell_records(tiles, &observed, cfg, &water, &void, |_| true);
        Ok(HazardMap {
            resolution: res,
            cells,
            bodies,
        })
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
    use super::dry::weight;
    use super::terrain::{centre_std, window_gradient, Window};
    use super::*;
    use crate::grid::Evidence;

    #[test]
    fn centre_std_adds_the_gradient_across_the_cell() {
        let res = 0.1;
        // A plane rising 0.5 m per metre along x, every neighbour dry and exact.
        let s = centre_std(0.0, 0.0, 0.0, &plane5(0.5, 0.0, res, 0.0), res);
        let want = (0.25f64 * res * res / 12.0 + 1e-6 / 12.0).sqrt();
        assert!((s - want).abs() < 1e-12, "{s} {want}");
        // Level ground: the cell's own σ and the millimetre only; no neighbour: the same.
        let flat = plane5(0.0, 0.0, res, 0.0);
        let own = (1e-4f64 + 1e-6 / 12.0).sqrt();
        assert!((centre_std(0.01, 0.05, 0.0, &flat, res) - own).abs() < 1e-12);
        let alone: Window =
            std::array::from_fn(|j| if j == 12 { (0.0, 0.0) } else { (f64::NAN, 0.0) });
        assert_eq!(
            centre_std(0.01, 0.05, 0.0, &alone, res),
            centre_std(0.01, 0.05, 0.0, &flat, res)
        );
    }

    /// On a slope, a range error moves a point along its ray to where the terrain stands
    /// higher or lower: the σ takes the slope times the range-bound σ on top of the
    /// vertical one. A bank rising 1 m per metre, seen with a vertical σ of 2 mm and a
    /// range-bound σ of 3 cm, is uncertain by 3.2 cm, not 2 mm (the squared slope less nine
    /// times its estimate's variance: the cells' (2 mm)² and the millimetre's over the
    /// window's Σ dx² = 50 cells²).
    #[test]
    fn centre_std_takes_the_range_error_along_a_slope() {
        let res = 0.1;
        let s = centre_std(0.002, 0.03, 0.0, &plane5(1.0, 0.0, res, 0.002), res);
        let var = 4e-6 + 1e-6 / 12.0;
        let along = 0.002 + (1.0f64 - 9.0 * var / (50.0 * res * res)).sqrt() * 0.03;
        let want = (along * along + res * res / 12.0 + 1e-6 / 12.0).sqrt();
        assert!((s - want).abs() < 1e-12, "{s} {want}");
        // Along the other axis, the same.
        let t = centre_std(0.002, 0.03, 0.0, &plane5(0.0, -1.0, res, 0.002), res);
        assert!((t - want).abs() < 1e-12, "{t} {want}");
    }

    /// A window whose cells differ by less than three σ of their noise shows no slope
    /// along the rays: noisy far cells on level ground keep their own σ and the position
    /// term of their raw gradient.
    #[test]
    fn centre_std_reads_no_slope_into_neighbours_noise() {
        let res = 0.1;
        // A rise of 0.1 per metre, against a cell σ of 3 cm: the window's gradient has a
        // σ of 3 cm / √(50·res²) = 0.042, so 3σ is 0.13.
        let noisy = plane5(0.1, 0.0, res, 0.03);
        let want = (0.03f64 * 0.03 + 0.01 * res * res / 12.0 + 1e-6 / 12.0).sqrt();
        let s = centre_std(0.03, 0.3, 0.0, &noisy, res);
        assert!((s - want).abs() < 1e-12, "{s} {want}");
        // Beyond it, the slope counts.
        assert!(centre_std(0.03, 0.3, 0.0, &plane5(1.0, 0.0, res, 0.03), res) > 0.25);
    }

    /// A far scan leaves cells apart: its columns every other cell, its rings metres
    /// apart. The window's gradient reads the plane through whatever cells it holds; on
    /// a line of cells (one ring) the slope along it stands for the slope across it too.
    #[test]
    fn the_gradient_is_read_from_sparse_and_collinear_cells() {
        let res = 0.1;
        let full = plane5(0.2, -0.1, res, 0.0);
        let every_other: Window =
            std::array::from_fn(|j| if j % 2 == 0 { full[j] } else { (f64::NAN, 0.0) });
        let (g2, _) = window_gradient(&every_other, res);
        assert!((g2 - 0.05).abs() < 1e-12, "{g2}");
        // One ring along x through the cell, two cells either side.
        let ring: Window =
            std::array::from_fn(|j| if j / 5 == 2 { full[j] } else { (f64::NAN, 0.0) });
        let (g2, slope2) = window_gradient(&ring, res);
        assert!((g2 - 2.0 * 0.04).abs() < 1e-12, "{g2}");
        assert!((slope2 - 2.0 * 0.04).abs() < 1e-4, "{slope2}");
        // A diagonal line, the same from its own slope.
        let diag: Window =
            std::array::from_fn(|j| if j % 6 == 0 { full[j] } else { (f64::NAN, 0.0) });
        let g = (0.2 - 0.1) / 2f64.sqrt();
        let (g2, _) = window_gradient(&diag, res);
        assert!((g2 - 2.0 * g * g).abs() < 1e-12, "{g2}");
    }

    /// A lidar cell amid far stereo cells: its slope is read from the lidar cells beside
    /// it, whose σ is a millimetre, not from the stereo cells' decimetres of noise.
    #[test]
    fn the_gradient_weighs_each_cell_by_its_own_noise() {
        let res = 0.1;
        let plane = plane5(0.05, 0.0, res, 0.001);
        let win: Window = std::array::from_fn(|j| match j {
            11 | 12 | 13 | 17 => plane[j],
            // The stereo cells right of the centre 0.3 m high, those left of it as low.
            _ => (
                plane[j].0 + 0.3 * ((j % 5) as f64 - 2.0).signum(),
                weight(0.3),
            ),
        });
        let (g2, slope2) = window_gradient(&win, res);
        assert!((g2 - 0.0025).abs() < 1e-4, "{g2}");
        assert!(slope2 > 0.0 && slope2 <= g2, "{slope2}");
        // Weighted alike, their noise would read as a slope of metres per metre.
        let equal: Window = std::array::from_fn(|j| (win[j].0, weight(0.3)));
        assert!(window_gradient(&equal, res).0 > 1.0);
    }

    proptest::proptest! {
        /// Never below the cell's own σ, and finite for finite input, whatever the
        /// window (some cells missing, absurd but finite heights).
        #[test]
        fn centre_std_is_at_least_the_cells_own(
            sd in 0.0f64..10.0,
            rb in 0.0f64..10.0,
            zs in proptest::array::uniform25(proptest::option::of(-1e6f64..1e6)),
            ss in proptest::array::uniform25(0.0f64..5.0),
        ) {
            let win: Window = std::array::from_fn(|j| {
                (if j == 12 { Some(0.0) } else { zs[j] }.unwrap_or(f64::NAN), weight(ss[j]))
            });
            let s = centre_std(sd, rb, 0.0, &win, 0.1);
            proptest::prop_assert!(s.is_finite() && s >= sd, "{s} {sd}");
        }

        /// Any three or more cells of a plane, not on one line, give its gradient.
        #[test]
        fn the_gradient_of_a_plane_is_exact_on_any_cells_not_on_a_line(
            gx in -5.0f64..5.0,
            gy in -5.0f64..5.0,
            mask in proptest::array::uniform25(proptest::bool::ANY),
        ) {
            let res = 0.1;
            let full = plane5(gx, gy, res, 0.0);
            let win: Window = std::array::from_fn(|j| {
                if j == 12 || mask[j] { full[j] } else { (f64::NAN, 0.0) }
            });
            let at: Vec<usize> = (0..25).filter(|&j| !win[j].0.is_nan()).collect();
            let xy = |j: usize| ((j % 5) as i64, (j / 5) as i64);
            let (x0, y0) = xy(at[0]);
            let on_a_line = at.iter().all(|&a| {
                at.iter().all(|&b| {
                    let ((xa, ya), (xb, yb)) = (xy(a), xy(b));
                    (xa - x0) * (yb - y0) == (ya - y0) * (xb - x0)
                })
            });
            proptest::prop_assume!(!on_a_line);
            let (g2, _) = window_gradient(&win, res);
            let want = gx * gx + gy * gy;
            proptest::prop_assert!((g2 - want).abs() <= 1e-9 * (1.0 + want), "{g2} {want}");
        }
    }

    /// The 5 × 5 window of a cell of a plane rising `gx`, `gy` per metre, at `res` m, all
    /// with σ `s` (so of [`weight`] of it), the cell's own elevation 0.
    fn plane5(gx: f64, gy: f64, res: f64, s: f64) -> Window {
        std::array::from_fn(|j| {
            let (dx, dy) = ((j % 5) as f64 - 2.0, (j / 5) as f64 - 2.0);
            ((dx * gx + dy * gy) * res, weight(s))
        })
    }

    /// The neighbourhood of a cell of a plane rising `gx`, `gy` per metre, at `res` m, all
    /// with σ `s`, the cell's own elevation 0.
    fn plane(gx: f64, gy: f64, res: f64, s: f64) -> Neighbourhood {
        std::array::from_fn(|j| {
            let (dx, dy) = ((j % 3) as f64 - 1.0, (j / 3) as f64 - 1.0);
            ((dx * gx + dy * gy) * res, s)
        })
    }

    const STEP: f64 = 0.25;

    fn grad(deg: f64) -> f64 {
        deg.to_radians().tan()
    }

    fn hazard_of(nb: &Neighbourhood, s: f64) -> (Class, Hazard) {
        terrain_hazard(nb, (nb[4].0, s), 0.1, STEP, grad(25.0))
    }

    #[test]
    fn a_step_beyond_the_limit_is_an_obstacle_on_its_upper_side() {
        // 0.4 m down to the +x column.
        let mut nb = plane(0.0, 0.0, 0.1, 0.01);
        for j in [2, 5, 8] {
            nb[j].0 = -0.4;
        }
        assert_eq!(hazard_of(&nb, 0.01), (Class::Obstacle, Hazard::Obstacle));
        // The cell below it: the step rises on one side only, no slope of its own.
        let mut low = plane(0.0, 0.0, 0.1, 0.01);
        for j in [2, 5, 8] {
            low[j].0 = 0.4;
        }
        assert_eq!(hazard_of(&low, 0.01), (Class::Ground, Hazard::Free));
        // A step under the limit is none.
        for j in [2, 5, 8] {
            nb[j].0 = -0.2;
        }
        assert_ne!(hazard_of(&nb, 0.01).0, Class::Obstacle);
    }

    #[test]
    fn a_step_counts_only_beyond_the_noise_of_the_difference() {
        // 0.3 m down to one neighbour: beyond the limit by 0.05 m.
        let mut nb = plane(0.0, 0.0, 0.1, 0.005);
        nb[5].0 = -0.3;
        assert_eq!(hazard_of(&nb, 0.005).1, Hazard::Obstacle);
        // With σ 0.05 m on both cells the difference's 2σ margin is 0.14 m: 0.16 m left.
        nb[5].1 = 0.05;
        assert_eq!(hazard_of(&nb, 0.05), (Class::Ground, Hazard::Free));
    }

    #[test]
    fn a_slope_is_a_tilt_on_both_sides_of_the_cell() {
        for (deg, want) in [(30.0, Hazard::Obstacle), (20.0, Hazard::Free)] {
            for (gx, gy) in [(1.0, 0.0), (0.0, -1.0), (0.6, 0.8)] {
                let g = grad(deg);
                let nb = plane(gx * g, gy * g, 0.1, 0.002);
                assert_eq!(
                    hazard_of(&nb, 0.002),
                    (Class::Ground, want),
                    "{deg} {gx} {gy}"
                );
            }
        }
        // On the edge of what was seen one side cannot tell a slope from a bump: no tilt
        // along that axis, the other axis still counts.
        let mut edge = plane(grad(30.0), 0.0, 0.1, 0.002);
        for j in [0, 3, 6] {
            edge[j].0 = f64::NAN;
        }
        assert_eq!(hazard_of(&edge, 0.002).1, Hazard::Free);
        let mut edge = plane(0.0, grad(30.0), 0.1, 0.002);
        for j in [0, 3, 6] {
            edge[j].0 = f64::NAN;
        }
        assert_eq!(hazard_of(&edge, 0.002).1, Hazard::Obstacle);
        // One neighbour 0.75 m up (a bump of misplaced returns) makes no slope of the
        // level cells beside it; the bump itself is a step.
        let mut bump = plane(0.0, 0.0, 0.1, 0.043);
        bump[8].0 = 0.75;
        assert_eq!(hazard_of(&bump, 0.043), (Class::Ground, Hazard::Free));
        let top: Neighbourhood = std::array::from_fn(|j| (if j == 4 { 0.75 } else { 0.0 }, 0.043));
        assert_eq!(hazard_of(&top, 0.043).0, Class::Obstacle);
        // A valley floor (both sides rising) is no slope either.
        let valley: Neighbourhood =
            std::array::from_fn(|j| (if j % 3 == 1 { 0.0 } else { 0.2 }, 0.002));
        assert_eq!(hazard_of(&valley, 0.002).1, Hazard::Free);
    }

    proptest::proptest! {
        #[test]
        fn a_noisy_flat_surface_has_no_obstacle(
            s in 0.005f64..0.2,
            tilt in -0.3f64..0.3,
            noise in proptest::collection::vec(-1.0f64..1.0, 9),
        ) {
            // Level or gently tilted ground (under 17°), each cell off by up to √2 σ.
            let mut nb = plane(tilt, 0.5 * tilt, 0.1, s);
            for (c, e) in nb.iter_mut().zip(&noise) {
                c.0 += e * std::f64::consts::SQRT_2 * s;
            }
            let z = nb[4].0;
            let got = terrain_hazard(&nb, (z, s), 0.1, STEP, grad(25.0));
            proptest::prop_assert_eq!(got, (Class::Ground, Hazard::Free));
        }
    }

    #[test]
    fn dry_cells_dense_and_sparse_answer_alike() {
        // A compact patch (dense array) and the same patch plus a cell far away (hash map).
        let patch: Vec<(CellKey, Dry)> = (0..20)
            .flat_map(|x| {
                (0..10).map(move |y| {
                    (
                        CellKey::new(x - 7, y + 3),
                        (x as f64, y as f64, 0.5 * y as f64),
                    )
                })
            })
            .filter(|(k, _)| (k.x + k.y) % 7 != 0)
            .collect();
        let mut far = patch.clone();
        far.push((CellKey::new(1_000_000, -5), (1.0, 2.0, 3.0)));
        let (dense, sparse) = (DryCells::new(patch.clone()), DryCells::new(far));
        assert!(matches!(dense, DryCells::Dense { .. }));
        assert!(matches!(sparse, DryCells::Sparse(_)));
        let truth: HashMap<CellKey, Dry> = patch.into_iter().collect();
        for x in -10..16 {
            for y in 0..16 {
                let k = CellKey::new(x, y);
                assert_eq!(dense.get(k), truth.get(&k).copied());
                assert_eq!(sparse.get(k), truth.get(&k).copied());
            }
        }
        assert_eq!(
            sparse.get(CellKey::new(1_000_000, -5)),
            Some((1.0, 2.0, 3.0))
        );
        // The neighbourhoods too, inside the dense array and at its edges.
        let bits = |nb: Neighbourhood| nb.map(|(z, s)| (z.to_bits(), s.to_bits()));
        for x in -10..16 {
            for y in 0..16 {
                let k = CellKey::new(x, y);
                let want: Neighbourhood = std::array::from_fn(|j| {
                    let d = CellKey::new(x + j as i64 % 3 - 1, y + j as i64 / 3 - 1);
                    let (z, sz, _) = truth.get(&d).copied().unwrap_or(NOT_DRY);
                    (z, sz)
                });
                assert_eq!(bits(dense.neighbourhood(k)), bits(want));
                assert_eq!(bits(sparse.neighbourhood(k)), bits(want));
                // The 5 × 5 window: elevation and weight.
                let w = |win: Window| win.map(|(z, s)| (z.to_bits(), s.to_bits()));
                let want: Window = std::array::from_fn(|j| {
                    let d = CellKey::new(x + j as i64 % 5 - 2, y + j as i64 / 5 - 2);
                    let (z, _, w) = truth.get(&d).copied().unwrap_or(NOT_DRY);
                    (z, w)
                });
                assert_eq!(w(dense.window(k)), w(want));
                assert_eq!(w(sparse.window(k)), w(want));
            }
        }
        assert_eq!(DryCells::new(Vec::new()).get(CellKey::new(0, 0)), None);
    }

    #[test]
    fn water_evidence_reaches_the_map() {
        let mut t = TileMap::new(0.1, 0.0).unwrap();
        let mut ground = CellStats::default();
        ground.add(100, 65536);
        t.add(CellKey::new(0, 0), &ground);
        // Observed with no return only: no elevation, a level of 0.05 m, water; 5 × 5
        // cells, the smallest body kept (0.25 m²).
        let mut ev = Evidence {
            noret: 20,
            ..Evidence::default()
        };
        ev.add_level(50);
        ev.add_depth(0.2);
        for x in 1..6 {
            for y in 0..5 {
                let c = CellStats {
                    ev,
                    ..CellStats::default()
                };
                t.add(CellKey::new(x, y), &c);
            }
        }
        let m = HazardMap::from_tiles(&t, &HazardConfig::default()).unwrap();
        assert_eq!(m.cells.len(), 26);
        let g = m
            .cells
            .iter()
            .find(|c| c.key == CellKey::new(0, 0))
            .unwrap();
        let w = m
            .cells
            .iter()
            .find(|c| c.key == CellKey::new(1, 0))
            .unwrap();
        assert_eq!(g.class, Class::Ground);
        assert!((g.water - 0.05).abs() < 1e-6 && g.depth == 0.0);
        assert_eq!(w.class, Class::Water);
        assert_eq!(w.hazard, Hazard::ShallowWater);
        assert!((w.z - 0.05).abs() < 1e-9 && (w.depth - 0.2).abs() < 1e-6);
        // The geometry-only map leaves the evidence-only cell out.
        assert_eq!(HazardMap::from_elevation(&t).cells.len(), 1);
    }
}
