//! The per-cell record rules: what a map record keeps of an observed cell ([`Seen`]), and
//! its class, hazard and surface given the water and dry cells around it ([`CellRule`]).

use std::collections::BTreeSet;

use super::dry::{dry_terrain, DryCells};
use super::terrain::{centre_std, terrain_hazard};
use super::{CellMap, Class, Hazard, HazardConfig, MapCell};
use crate::grid::{centre_of, CellKey, CellStats, Evidence, FusionLogs, TileMap};
use crate::water::WaterBody;

/// The depth written for a cell outside every water body: 0 (dry) where its water
/// probability is below one half, else unknown (NaN): evidence says water, but no body
/// gives it a surface, so its depth is not known to be 0.
fn dry_depth(water: f32) -> f32 {
    if water < 0.5 {
        0.0
    } else {
        f32::NAN
    }
}

/// What a map record keeps of an observed cell, whatever its class.
#[derive(Debug, Clone, Copy)]
pub(super) struct Seen {
    pub(super) key: CellKey,
    /// [`CellStats::elevation_std_m`], NaN without an elevation.
    pub(super) elevation_std: f64,
    /// [`CellStats::excess_spread_var_m2`], 0 without an elevation.
    pub(super) excess_var: f64,
    pub(super) hits: u32,
    pub(super) below: u32,
    /// Water probability.
    pub(super) water: f32,
}

impl Seen {
    pub(super) fn of(key: CellKey, c: &CellStats, water: f32) -> Self {
        Seen {
            key,
            elevation_std: c.elevation_std_m().unwrap_or(f64::NAN),
            excess_var: c.excess_spread_var_m2().unwrap_or(0.0),
            hits: c.hits,
            below: c.below,
            water,
        }
    }

    /// The record of the cell at resolution `res` with the given surface and class.
    pub(super) fn record(
        self,
        res: f64,
        z: f64,
        depth: f32,
        class: Class,
        hazard: Hazard,
    ) -> MapCell {
        let (x, y) = centre_of(res, self.key);
        MapCell {
            key: self.key,
            x,
            y,
            z,
            elevation_std: self.elevation_std,
            water: self.water,
            depth,
            class,
            hazard,
            hits: self.hits,
            below: self.below,
        }
    }
}

/// Surface z and depth of the water cells of `bodies`.
pub(super) fn water_surface<'a>(
    bodies: impl IntoIterator<Item = &'a WaterBody>,
    res: f64,
) -> CellMap<(f64, f32)> {
    let mut water: CellMap<(f64, f32)> = CellMap::default();
    for b in bodies {
        let s = b.surface.evaluator();
        for (&k, &d) in b.cells.iter().zip(&b.cell_depth_m) {
            let (x, y) = centre_of(res, k);
            water.insert(k, (s.at(x, y), d));
        }
    }
    water
}

/// The class, hazard and surface of an observed cell given the water and dry cells
/// around it (module `water`, "Hazards").
pub(super) struct CellRule<'a> {
    res: f64,
    z_ref: f64,
    fording_depth_m: f64,
    max_step_m: f64,
    max_grad: f64,
    water: &'a CellMap<(f64, f32)>,
    dry: &'a DryCells,
}

impl<'a> CellRule<'a> {
    pub(super) fn new(
        cfg: &HazardConfig,
        res: f64,
        z_ref: f64,
        water: &'a CellMap<(f64, f32)>,
        dry: &'a DryCells,
    ) -> Self {
        let v = &cfg.vehicle;
        CellRule {
            res,
            z_ref,
            fording_depth_m: v.fording_depth_m,
            max_step_m: v.max_step_m,
            max_grad: v.max_slope_deg.to_radians().tan(),
            water,
            dry,
        }
    }

    /// The record of the observed cell `c`: water (from its body), dry terrain, or, seen
    /// through water evidence only and not water, at its water level (`level_mm`, read
    /// only then); `None` without any of these. (`dry` holds no water cell, so the order
    /// of the first two tests does not matter.)
    #[inline]
    pub(super) fn record(
        &self,
        c: Seen,
        level_mm: impl FnOnce() -> Option<f64>,
    ) -> Option<MapCell> {
        if let Some((z, sz, _)) = self.dry.get(c.key) {
            let nb = self.dry.neighbourhood(c.key);
            let (class, hazard) =
                terrain_hazard(&nb, (z, sz), self.res, self.max_step_m, self.max_grad);
            let win = self.dry.window(c.key);
            let c = Seen {
                elevation_std: centre_std(c.elevation_std, sz, c.excess_var, &win, self.res),
                ..c
            };
            return Some(c.record(self.res, z, dry_depth(c.water), class, hazard));
        }
        if let Some(&(z, depth)) = self.water.get(&c.key) {
            let hazard = if depth.is_finite() && depth as f64 <= self.fording_depth_m {
                Hazard::ShallowWater
            } else {
                Hazard::DeepWater
            };
            return Some(c.record(self.res, z, depth, Class::Water, hazard));
        }
        let z = level_mm().map(|mm| self.z_ref + mm * 1e-3)?;
        Some(c.record(
            self.res,
            z,
            dry_depth(c.water),
            Class::Unknown,
            Hazard::Free,
        ))
    }
}

/// The water probability a map publishes for the cell `key` with evidence `ev` in place of
/// its evidence's, if any: for a cell outside every body (not in `water`) whose bottom
/// returns the water stage found to be no evidence (`void`, from
/// [`crate::water::bodies_from`]: ground at the level of a body that stood on them alone),
/// its probability without them. A cell another cue keeps in a body is water, its
/// probability all its evidence's.
pub(super) fn voided_water(
    key: CellKey,
    ev: &Evidence,
    logs: &FusionLogs,
    void: &BTreeSet<CellKey>,
    water: &CellMap<(f64, f32)>,
) -> Option<f32> {
    (ev.depth_n > 0 && void.contains(&key) && !water.contains_key(&key))
        .then(|| ev.water_probability_without_bottom_in(logs) as f32)
}

/// The records of the `observed` cells (unique keys, in map order) that `keep` selects,
/// given the water cells of the map's bodies (`water`, from [`water_surface`]) and the cells
/// whose bottom returns the water stage voided (`void`); the step and slope tests read the
/// dry cells among all of `observed`. Of `tiles` only the resolution and reference height
/// are read.
pub(super) fn cell_records(
    tiles: &TileMap,
    observed: &[(CellKey, CellStats)],
    cfg: &HazardConfig,
    water: &CellMap<(f64, f32)>,
    void: &BTreeSet<CellKey>,
    keep: impl Fn(CellKey) -> bool,
) -> Vec<MapCell> {
    let res = tiles.resolution();
    // Dry terrain for the step and slope tests.
    let dry = DryCells::new(
        observed
            .iter()
            .filter(|(k, _)| !water.contains_key(k))
            .filter_map(|&(k, c)| Some((k, dry_terrain(&c, tiles.z_ref())?)))
            .collect(),
    );
    let rule = CellRule::new(cfg, res, tiles.z_ref(), water, &dry);
    let logs = cfg.fusion.logs();
    observed
        .iter()
        .filter(|(key, _)| keep(*key))
        .filter_map(|(key, c)| {
            let p = voided_water(*key, &c.ev, &logs, void, water)
                .unwrap_or_else(|| c.ev.water_probability_in(&logs) as f32);
            rule.record(Seen::of(*key, c, p), || c.ev.level_mm())
        })
        .collect()
}
