//! How often each water cue fires on true water and on dry ground: the measured side of the
//! fusion rule's likelihoods ([`tarn::grid::Fusion`]).
//!
//! Read from a build's tile set (`tarn build --tiles` writes `tiles.bin`: every cell's
//! evidence counts before the water stage). A tile-set cell is scored by the truth cell
//! containing its centre, in a range band from the path, like the map's cells: on true
//! water, or on dry ground off the shore (farther than [`super::SHORE_MARGIN_M`] from all
//! water); cells near the shore count for neither.
//!
//! The counts are what each cue's likelihood stands for:
//!
//! - image votes (colour, SWIR, MWIR; one per cell and frame): votes for water and votes
//!   against, so P(vote for water | water) and P(vote for water | dry) are ratios of votes;
//! - diagnostic lidar beams: no return and return, likewise;
//! - reflectivity, one observation per cell (dark when most of its returns are): dark and
//!   lit cells;
//! - reflection rays and bottom returns, which have no "looked, and found none": the events
//!   and the cells with at least one.

use serde::Serialize;

use super::{distance_to_path, KeyMap, Shore};
use crate::error::{Error, Result};
use crate::grid::{CellKey, TileMap};
use crate::hazard::{Class, HazardMap, MapCell};
use crate::sim::TruthInfo;

/// Counts of one cue on true water and on dry ground off the shore.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct CueTally {
    /// On true water: [events for water, events against] (for a cue with no event
    /// against: [events, cells with at least one]).
    pub water: [u64; 2],
    /// On dry ground off the shore, the same.
    pub dry: [u64; 2],
}

impl CueTally {
    fn add(&mut self, water: bool, n: [u64; 2]) {
        let t = if water {
            &mut self.water
        } else {
            &mut self.dry
        };
        t[0] += n[0];
        t[1] += n[1];
    }
}

/// Each cue's counts over the tile-set cells of one range band.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct CueRates {
    /// The band, "lo-hi" metres from the path.
    pub range: String,
    /// Tile-set cells scored: [on true water, on dry ground off the shore].
    pub cells: [u64; 2],
    pub colour: CueTally,
    pub swir: CueTally,
    pub mwir: CueTally,
    /// Diagnostic lidar beams: [no return, return].
    pub noret: CueTally,
    /// Cells tested for reflectivity: [dark, lit].
    pub reflectivity: CueTally,
    /// Reflection rays: [rays, cells with one].
    pub reflect: CueTally,
    /// Refraction-corrected bottom returns: [returns, cells with one].
    pub bottom: CueTally,
}

impl CueRates {
    fn add(&mut self, water: bool, e: &crate::grid::Evidence) {
        self.cells[usize::from(!water)] += 1;
        let n = |a: u32, b: u32| [u64::from(a), u64::from(b)];
        self.colour
            .add(water, n(e.colour_water.into(), e.colour_dry.into()));
        self.swir
            .add(water, n(e.swir_dark.into(), e.swir_lit.into()));
        self.mwir
            .add(water, n(e.mwir_water.into(), e.mwir_dry.into()));
        self.noret.add(water, n(e.noret.into(), e.diag_ret.into()));
        if e.dark > 0 || e.lit > 0 {
            let dark = e.dark > e.lit;
            self.reflectivity.add(water, n(dark.into(), (!dark).into()));
        }
        self.reflect
            .add(water, n(e.reflect.into(), (e.reflect > 0).into()));
        self.bottom.add(water, n(e.depth_n, (e.depth_n > 0).into()));
    }
}

/// The cue counts of `tiles` in each band `[lo, hi)` m from the path of `info`.
pub fn cue_rates(
    tiles: &TileMap,
    truth: &HazardMap,
    info: &TruthInfo,
    bands: &[(f64, f64)],
) -> Result<Vec<CueRates>> {
    let res = truth.resolution;
    if !(res > 0.0 && res.is_finite()) {
        return Err(Error::invalid(
            "truth",
            format!("resolution {res} must be > 0"),
        ));
    }
    for &(lo, hi) in bands {
        super::check_band(lo, hi)?;
    }
    let index: KeyMap<&MapCell> = truth.cells.iter().map(|c| (c.key, c)).collect();
    let shore = Shore::new(truth);
    let path: Vec<[f64; 2]> = info.trajectory.iter().map(|p| [p.x, p.y]).collect();
    let mut out: Vec<CueRates> = bands
        .iter()
        .map(|(lo, hi)| CueRates {
            range: format!("{lo}-{hi}"),
            ..Default::default()
        })
        .collect();
    for (k, c) in tiles.observed() {
        let (x, y) = tiles.centre_of(k);
        let tk = CellKey::new((x / res).floor() as i64, (y / res).floor() as i64);
        let Some(t) = index.get(&tk) else { continue };
        let water = t.class == Class::Water;
        if !water && shore.near(tk) {
            continue;
        }
        let d = distance_to_path(&path, x, y);
        for (r, &(lo, hi)) in out.iter_mut().zip(bands) {
            if d >= lo && d < hi {
                r.add(water, &c.ev);
            }
        }
    }
    Ok(out)
}

/// [`cue_rates`] over the matrix's bands ([`super::MATRIX_BANDS`] and their union), from
/// `MAPDIR/tiles.bin`; `None` when the build wrote no tile set.
pub fn cue_rates_of_dir(
    map_dir: &std::path::Path,
    truth: &HazardMap,
    info: &TruthInfo,
) -> Result<Option<Vec<CueRates>>> {
    let p = map_dir.join("tiles.bin");
    if !p.exists() {
        return Ok(None);
    }
    let bytes = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
    let tiles =
        TileMap::from_bytes(&bytes).map_err(|e| Error::format(&p, "tile set", e.to_string()))?;
    let bands = super::matrix_bands_and_union();
    cue_rates(&tiles, truth, info, &bands).map(Some)
}

#[cfg(test)]
mod tests {
    use super::super::tests::{info, raster};
    use super::*;
    use crate::grid::{CellStats, Evidence};

    /// Water at x 0–1 m, dry beyond, a path 2 m off: votes are counted by the truth
    /// under the cell, and a dry cell within the shore margin counts for neither side.
    #[test]
    fn votes_are_counted_by_the_truth_under_the_cell() {
        let truth = raster(0.1, 200, 1, |x, _| x < 10);
        let info = info(0.1, &[[0.0, -2.0], [20.0, -2.0]], None);
        let mut tiles = TileMap::new(0.1, 0.0).unwrap();
        let mut put = |x: i64, ev: Evidence| {
            let c = CellStats {
                ev,
                ..CellStats::default()
            };
            tiles.add(CellKey::new(x, 0), &c);
        };
        put(
            5,
            Evidence {
                colour_water: 3,
                colour_dry: 1,
                noret: 1,
                reflect: 2,
                ..Evidence::default()
            },
        );
        // 0.2 m from the water: inside the shore margin.
        put(
            11,
            Evidence {
                colour_water: 5,
                ..Evidence::default()
            },
        );
        put(
            150,
            Evidence {
                colour_water: 1,
                colour_dry: 4,
                diag_ret: 1,
                dark: 2,
                lit: 1,
                ..Evidence::default()
            },
        );
        let r = cue_rates(&tiles, &truth, &info, &[(0.0, 1.0), (0.0, 30.0)]).unwrap();
        assert_eq!(r[0].range, "0-1");
        assert_eq!(r[0].cells, [0, 0]);
        assert_eq!(r[1].cells, [1, 1]);
        assert_eq!(r[1].colour.water, [3, 1]);
        assert_eq!(r[1].colour.dry, [1, 4]);
        assert_eq!(r[1].noret.water, [1, 0]);
        assert_eq!(r[1].noret.dry, [0, 1]);
        assert_eq!(r[1].reflect.water, [2, 1]);
        assert_eq!(r[1].reflectivity.dry, [1, 0]);
        assert!(cue_rates(&tiles, &truth, &info, &[(5.0, 1.0)]).is_err());
    }
}
