//! The map product: one record per observed cell, with the classes and hazards of the
//! export contract (DESIGN.md, "Map export").

use std::collections::{BTreeSet, HashMap};

use serde::{Deserialize, Serialize};

use crate::cues::prior::{PriorLevel, WaterPrior};
use crate::error::Result;
use crate::grid::{centre_of, BuildKeyHasher, CellKey, CellStats, Evidence, FusionLogs, TileMap};
use crate::water::{find_bodies_and_void, HazardConfig, WaterBody};

mod region;
mod window;

pub use region::{finish_by_regions, finish_region, join_regions, RegionMap, SplitStats, TileKey};

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
struct Seen {
    key: CellKey,
    /// [`CellStats::elevation_std_m`], NaN without an elevation.
    elevation_std: f64,
    /// [`CellStats::excess_spread_var_m2`], 0 without an elevation.
    excess_var: f64,
    hits: u32,
    below: u32,
    /// Water probability.
    water: f32,
}

impl Seen {
    fn of(key: CellKey, c: &CellStats, water: f32) -> Self {
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
    fn record(self, res: f64, z: f64, depth: f32, class: Class, hazard: Hazard) -> MapCell {
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

/// A dry cell's elevation (m), its range-bound σ (m) and the weight of its elevation in its
/// neighbours' gradient (m⁻², [`dry_terrain`]).
type Dry = (f64, f64, f64);

/// What [`DryCells`] holds where a cell is not dry.
const NOT_DRY: Dry = (f64::NAN, 0.0, 0.0);

/// The dry cells ([`Dry`]), looked up by key: a dense array over the cells' bounding box
/// when that is at most four times the cells (a window), else a hash map (a sparse global
/// map). The step and slope test asks nine cells per cell, the σ twenty-five.
enum DryCells {
    Dense {
        lo: CellKey,
        width: i64,
        height: i64,
        /// NaN elevation: not a dry cell.
        cells: Vec<Dry>,
    },
    Sparse(CellMap<Dry>),
}

impl DryCells {
    fn new(dry: Vec<(CellKey, Dry)>) -> Self {
        let Some(&(first, _)) = dry.first() else {
            return DryCells::Sparse(CellMap::default());
        };
        let (lo, hi) = dry.iter().fold((first, first), |(lo, hi), (k, _)| {
            (
                CellKey::new(lo.x.min(k.x), lo.y.min(k.y)),
                CellKey::new(hi.x.max(k.x), hi.y.max(k.y)),
            )
        });
        let (width, height) = (hi.x - lo.x + 1, hi.y - lo.y + 1);
        if width.saturating_mul(height) > 4 * dry.len() as i64 {
            return DryCells::Sparse(dry.into_iter().collect());
        }
        let mut cells = vec![NOT_DRY; (width * height) as usize];
        for (k, v) in dry {
            cells[((k.y - lo.y) * width + (k.x - lo.x)) as usize] = v;
        }
        DryCells::Dense {
            lo,
            width,
            height,
            cells,
        }
    }

    fn get(&self, k: CellKey) -> Option<Dry> {
        match self {
            DryCells::Dense {
                lo,
                width,
                height,
                cells,
            } => {
                let (x, y) = (k.x - lo.x, k.y - lo.y);
                if x < 0 || y < 0 || x >= *width || y >= *height {
                    return None;
                }
                let v = cells[(y * width + x) as usize];
                (!v.0.is_nan()).then_some(v)
            }
            DryCells::Sparse(m) => m.get(&k).copied(),
        }
    }

    /// The dry 3 × 3 neighbourhood of `k`: elevation and range-bound σ.
    #[inline]
    fn neighbourhood(&self, k: CellKey) -> Neighbourhood {
        let mut nb = [(f64::NAN, 0.0); 9];
        self.square(k, 1, |d| (d.0, d.1), &mut nb);
        nb
    }

    /// The dry 5 × 5 window around `k` (row by row from its lower-left cell): elevation and
    /// weight, NaN elevation where the cell is not dry.
    #[inline]
    fn window(&self, k: CellKey) -> Window {
        let mut win = [(f64::NAN, 0.0); 25];
        self.square(k, 2, |d| (d.0, d.2), &mut win);
        win
    }

    /// `pick` of the cells within `r` of `k` into `out` (row by row from the lower-left,
    /// `(2r + 1)²` of them; [`NOT_DRY`] where a cell is not dry): slices of the dense array
    /// where the square lies inside it.
    #[inline]
    fn square(&self, k: CellKey, r: i64, pick: impl Fn(Dry) -> (f64, f64), out: &mut [(f64, f64)]) {
        let side = (2 * r + 1) as usize;
        if let DryCells::Dense {
            lo,
            width,
            height,
            cells,
        } = self
        {
            let (x, y) = (k.x - lo.x, k.y - lo.y);
            if x >= r && y >= r && x < width - r && y < height - r {
                for (i, row) in out.chunks_mut(side).enumerate() {
                    let at = ((y - r + i as i64) * width + x - r) as usize;
                    for (o, &d) in row.iter_mut().zip(&cells[at..at + side]) {
                        *o = pick(d);
                    }
                }
                return;
            }
        }
        for (j, o) in out.iter_mut().enumerate() {
            let (dx, dy) = ((j % side) as i64 - r, (j / side) as i64 - r);
            *o = pick(
                self.get(CellKey::new(k.x + dx, k.y + dy))
                    .unwrap_or(NOT_DRY),
            );
        }
    }
}

/// The dry 3 × 3 neighbourhood of a cell (itself included), row by row from its lower-left
/// neighbour: elevation and σ, NaN elevation where the neighbour is not a dry cell.
pub type Neighbourhood = [(f64, f64); 9];

/// The dry 5 × 5 window around a cell (itself at index 12), row by row from its lower-left
/// cell: elevation and weight (the inverse variance of its vertical σ and the millimetre,
/// [`dry_terrain`]), NaN elevation where the cell is not dry. What the cell's σ reads its
/// terrain's gradient from.
type Window = [(f64, f64); 25];

/// Class and hazard of a dry cell with elevation `z` ± `sz` from its dry neighbourhood
/// `nb`: the upper side of a step higher than `max_step` is an obstacle (class and
/// hazard), a slope steeper than `max_grad` (rise over run) is a hazard on ground. Only
/// what the elevations show beyond their noise counts: each difference to a neighbour is
/// shrunk towards zero by two standard deviations of that difference, so far cells seen by
/// a few noisy stereo points do not turn into obstacles.
///
/// The slope along each axis is read on both sides of the cell: the mean rise from the
/// column (row) of neighbours behind it and from the one ahead. The tilt is their mean
/// (the least-squares slope) when both sides rise the same way, and none when one side is
/// level or they disagree: a single cell above or
/// below the cell (a step, a post, a phantom bump or hole of misplaced returns) tilts only
/// one side and is the step test's business, not a slope of the cell. Where one side has
/// no dry neighbour (the edge of what was seen) there is no tilt along that axis: one side
/// cannot tell a slope from a bump.
#[inline]
pub fn terrain_hazard(
    nb: &Neighbourhood,
    (z, sz): (f64, f64),
    res: f64,
    max_step: f64,
    max_grad: f64,
) -> (Class, Hazard) {
    // The margins apart from the sums below, so that they vectorise.
    let margin: [f64; 9] = std::array::from_fn(|j| {
        let sn = nb[j].1;
        2.0 * (sz * sz + sn * sn).sqrt()
    });
    // Sums and counts of the shrunk rises towards −x, +x, −y, +y.
    let mut step = 0.0f64;
    let (mut sum, mut n) = ([0.0f64; 4], [0u32; 4]);
    for (j, (&(zn, _), &margin)) in nb.iter().zip(&margin).enumerate() {
        if zn.is_nan() {
            continue;
        }
        let (dx, dy) = (j as i64 % 3 - 1, j as i64 / 3 - 1);
        let d = zn - z;
        let d = d.signum() * (d.abs() - margin).max(0.0);
        step = step.max(-d);
        for (side, on) in [(0, dx < 0), (1, dx > 0), (2, dy < 0), (3, dy > 0)] {
            if on {
                sum[side] += d;
                n[side] += 1;
            }
        }
    }
    if step > max_step {
        return (Class::Obstacle, Hazard::Obstacle);
    }
    // Rise per metre going forward along the axis, from the side behind (−) and ahead (+).
    let tilt = |behind: usize, ahead: usize| {
        let g = |side: usize, sign: f64| {
            (n[side] > 0).then(|| sign * sum[side] / (n[side] as f64 * res))
        };
        match (g(behind, -1.0), g(ahead, 1.0)) {
            (Some(a), Some(b)) if a * b > 0.0 => 0.5 * (a + b),
            _ => 0.0,
        }
    };
    let grad = tilt(0, 1).hypot(tilt(2, 3));
    if grad > max_grad {
        (Class::Ground, Hazard::Obstacle)
    } else {
        (Class::Ground, Hazard::Free)
    }
}

/// The σ of a dry cell's elevation as the elevation of its centre, from the cell's vertical
/// σ `sd` ([`CellStats::elevation_std_m`]) and its range-bound σ `s_rb`
/// ([`CellStats::range_bound_std_m`]), on terrain of gradient g read from the dry cells
/// of its 5 × 5 window ([`window_gradient`]):
///
/// * a point moved along its ray by a range error lands in the map at another place, where
///   sloping terrain stands higher or lower: against the terrain there, the error is the
///   range error times `s + g_r·c` (s, c the ray's vertical and horizontal shares, g_r the
///   gradient along the ray), not times the vertical share s alone. Over the cell's points
///   that is at most `sd + |g|·s_rb` (Cauchy–Schwarz over the points, c ≤ 1): a bank seen
///   at grazing incidence is as uncertain as its range errors, level ground only by their
///   vertical part. Only a slope the window shows beyond three σ of its own noise counts
///   here (each axis's g² less nine times its estimate's variance), or noisy far cells on
///   level ground would read a slope out of their noise and multiply it by a range-bound σ
///   of decimetres;
/// * the points' mean lies where they fell in the cell, not at its centre: g times an
///   offset spread over the cell, variance `g²·res²/12` along each axis;
/// * the terrain varies within the cell beyond that plane (roughness, a kerb's edge): the
///   centre differs from the points' mean by what their spread shows beyond their noise
///   (`excess`, [`CellStats::excess_spread_var_m2`]) less the plane's `g²·res²/12`;
/// * the elevations are whole millimetres (variance 1/12 mm²).
fn centre_std(sd: f64, s_rb: f64, excess: f64, win: &Window, res: f64) -> f64 {
    let (g2, slope2) = window_gradient(win, res);
    let along_rays = sd + slope2.sqrt() * s_rb.max(sd);
    let across = g2 * res * res / 12.0;
    let rough = (excess - across).max(0.0);
    (along_rays * along_rays + across + rough + 1e-6 / 12.0).sqrt()
}

/// The terrain's squared gradient at the centre of `win` and the part of it beyond three
/// σ of the estimate's noise: `(|g|², Σ_axes max(0, g_a² − 9·var(g_a)))`. The gradient is
/// the least-squares plane through the window's dry cells (the centre's own among them),
/// each weighted by its own vertical σ and the millimetre, so that a lidar cell amid far
/// stereo cells reads its slope from its like and not from their noise. A sparse scan (the
/// rings of a far lidar, metres apart; its columns, every other cell) leaves many cells
/// without a neighbour on some side of the 3 × 3 around them, but seldom without one in the
/// 5 × 5. Where the window's cells lie on a line, the slope across it is not seen, and is
/// taken as the one along it (no direction of slope preferred); with no neighbour at all
/// there is none.
fn window_gradient(win: &Window, res: f64) -> (f64, f64) {
    // The dry cells: (dx, dy) in cells, dz (m), weight 1/σ² (m⁻²).
    let mut at = [(0.0, 0.0, 0.0, 0.0); 25];
    let mut len = 0;
    for (j, &(z, w)) in win.iter().enumerate() {
        if !z.is_nan() {
            let (dx, dy) = ((j % 5) as f64 - 2.0, (j / 5) as f64 - 2.0);
            at[len] = (dx, dy, z - win[12].0, w);
            len += 1;
        }
    }
    let cells = &at[..len];
    let (mut n, mut sw, mut sx, mut sy, mut sz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(dx, dy, dz, w) in cells {
        n += 1.0;
        sw += w;
        sx += w * dx;
        sy += w * dy;
        sz += w * dz;
    }
    if n < 2.0 {
        return (0.0, 0.0);
    }
    let (mx, my, mz) = (sx / sw, sy / sw, sz / sw);
    // Weighted centred moments, offsets in cells (the gradient per cell, scaled below),
    // and the unweighted determinant of the cells' layout.
    let (mut xx, mut xy, mut yy, mut xz, mut yz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut ux, mut uy, mut uxx, mut uxy, mut uyy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(dx, dy, dz, w) in cells {
        (ux, uy, uxx, uxy, uyy) = (
            ux + dx,
            uy + dy,
            uxx + dx * dx,
            uxy + dx * dy,
            uyy + dy * dy,
        );
        let (dx, dy, dz) = (dx - mx, dy - my, dz - mz);
        xx += w * dx * dx;
        xy += w * dx * dy;
        yy += w * dy * dy;
        xz += w * dx * dz;
        yz += w * dy * dz;
    }
    // n²·det of the unweighted layout is n times the sum of the squared doubled areas of
    // the triangles the cells make (Binet–Cauchy): at least n unless they lie on a line.
    let layout = (n * uxx - ux * ux) * (n * uyy - uy * uy) - (n * uxy - ux * uy).powi(2);
    let beyond = |g: f64, v: f64| (g * g - 9.0 * v).max(0.0);
    let (g2, slope2) = if layout > 0.5 * n {
        let det = xx * yy - xy * xy;
        let (gx, gy) = ((yy * xz - xy * yz) / det, (xx * yz - xy * xz) / det);
        let (vx, vy) = (yy / det, xx / det);
        (gx * gx + gy * gy, beyond(gx, vx) + beyond(gy, vy))
    } else {
        // On a line through the cells: the slope along it, taken across it too.
        let l = xx + yy;
        let g = (xz * xx.sqrt() + yz * xy.signum() * yy.sqrt()) / (l * l.sqrt());
        (2.0 * g * g, 2.0 * beyond(g, 1.0 / l))
    };
    (g2 / (res * res), slope2 / (res * res))
}

/// Elevation (m) of a cell with fused points, its range-bound σ for the step and slope
/// tests (0 when unknown), and the weight its elevation has in its neighbours' gradient:
/// the inverse of its vertical variance and the millimetre's ([`window_gradient`]).
fn dry_terrain(c: &CellStats, z_ref: f64) -> Option<Dry> {
    let finite = |s: Option<f64>| s.filter(|s| s.is_finite()).unwrap_or(0.0);
    Some((
        c.mean_mm().map(|m| z_ref + m * 1e-3)?,
        finite(c.range_bound_std_m()),
        weight(finite(c.elevation_std_m())),
    ))
}

/// The weight of an elevation of σ `s` (m) in a gradient: the inverse of its variance and
/// the millimetre's it is stored to.
fn weight(s: f64) -> f64 {
    1.0 / (s * s + 1e-6 / 12.0)
}

/// Surface z and depth of the water cells of `bodies`.
fn water_surface<'a>(
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
struct CellRule<'a> {
    res: f64,
    z_ref: f64,
    fording_depth_m: f64,
    max_step_m: f64,
    max_grad: f64,
    water: &'a CellMap<(f64, f32)>,
    dry: &'a DryCells,
}

impl<'a> CellRule<'a> {
    fn new(
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
    fn record(&self, c: Seen, level_mm: impl FnOnce() -> Option<f64>) -> Option<MapCell> {
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
fn voided_water(
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
fn cell_records(
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
    /// (0 dry, NaN where unknown). Body ids start at 1.
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

    /// [`HazardMap::from_tiles_after`] of the cells `observed` (unique keys, in the order the
    /// map's cells should have); of `tiles` only the resolution and reference height are
    /// read. The mapper's window snapshot takes this path with an empty tile map, skipping
    /// the copy of the window into tiles.
    pub fn from_cells_after(
        tiles: &TileMap,
        observed: Vec<(CellKey, CellStats)>,
        cfg: &HazardConfig,
        previous: &[WaterBody],
    ) -> Result<Self> {
        let (bodies, void) = find_bodies_and_void(tiles, &observed, cfg, previous)?;
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

    /// The key of the cell under map position (x, y).
    pub(crate) fn key_at(&self, x: f64, y: f64) -> CellKey {
        crate::grid::key_of(self.resolution, x, y)
    }

    /// The observed cell under map position (x, y), if any: one query, a scan of the
    /// cells. A planner asking many positions takes [`HazardMap::index`] once.
    pub fn at(&self, x: f64, y: f64) -> Option<&MapCell> {
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        let key = self.key_at(x, y);
        self.cells.iter().find(|c| c.key == key)
    }

    /// The cells and water bodies looked up by position, built once (linear in the cells)
    /// for a map that does not change while the index lives.
    pub fn index(&self) -> MapIndex<'_> {
        MapIndex {
            map: self,
            lookup: MapLookup::of(self),
        }
    }
}

/// A [`HazardMap`] looked up by position ([`HazardMap::index`]): what a planner asks of a
/// point it may drive over.
#[derive(Debug, Clone)]
pub struct MapIndex<'a> {
    map: &'a HazardMap,
    lookup: MapLookup,
}

impl<'a> MapIndex<'a> {
    /// The observed cell `key`, if any.
    pub fn cell(&self, key: CellKey) -> Option<&'a MapCell> {
        self.lookup.cell(self.map, key)
    }

    /// The observed cell under map position (x, y), if any (its class, hazard, water
    /// probability, elevation, σ and depth).
    pub fn at(&self, x: f64, y: f64) -> Option<&'a MapCell> {
        self.lookup.at(self.map, x, y)
    }

    /// The water body holding the cell under map position (x, y), if any.
    pub fn body_at(&self, x: f64, y: f64) -> Option<&'a WaterBody> {
        self.lookup.body_at(self.map, x, y)
    }
}

/// The tables of a [`MapIndex`] without the map they index, for an owner that keeps the
/// map beside them (a struct cannot hold a map and a borrow of it): each query takes the
/// map it was built from.
#[derive(Debug, Clone)]
pub struct MapLookup {
    /// Cell key → position in `map.cells`.
    cells: CellMap<u32>,
    /// Cell key → position in `map.bodies`.
    bodies: CellMap<u32>,
}

impl MapLookup {
    /// The tables of `map` (linear in its cells).
    pub fn of(map: &HazardMap) -> Self {
        let cells = map
            .cells
            .iter()
            .enumerate()
            .map(|(i, c)| (c.key, i as u32))
            .collect();
        let bodies = map
            .bodies
            .iter()
            .enumerate()
            .flat_map(|(b, body)| body.cells.iter().map(move |&k| (k, b as u32)))
            .collect();
        MapLookup { cells, bodies }
    }

    /// [`MapIndex::cell`] of `map`, the map these tables were built from.
    pub fn cell<'a>(&self, map: &'a HazardMap, key: CellKey) -> Option<&'a MapCell> {
        self.cells.get(&key).map(|&i| &map.cells[i as usize])
    }

    /// [`MapIndex::at`] of `map`, the map these tables were built from.
    pub fn at<'a>(&self, map: &'a HazardMap, x: f64, y: f64) -> Option<&'a MapCell> {
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        self.cell(map, map.key_at(x, y))
    }

    /// [`MapIndex::body_at`] of `map`, the map these tables were built from.
    pub fn body_at<'a>(&self, map: &'a HazardMap, x: f64, y: f64) -> Option<&'a WaterBody> {
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        let k = map.key_at(x, y);
        self.bodies.get(&k).map(|&b| &map.bodies[b as usize])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
