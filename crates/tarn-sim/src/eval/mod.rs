//! Scoring a map against ground truth, by range from the vehicle's path.
//!
//! Only observed cells count (cells present in the map). Each map cell is compared with the
//! truth cell containing its centre. A cell "is called water" when its class is water.
//! Per range bin (distance from the cell centre to the polyline of the trajectory in
//! `truth.json`: 0–5, 5–10, 10–20, 20–30, 30+ m):
//!
//! - water recall: true water cells called water / true water cells observed;
//! - false-positive rate: dry cells called water / dry cells observed;
//! - water surface error: RMS of map z − true surface over true water cells called water;
//! - depth error: RMS of map depth − true depth where the map calls water and gives a
//!   finite depth;
//! - terrain error: RMS of map z − true terrain over true dry ground (ground or snow/ice
//!   cells, not objects) the map does not call water;
//! - seen recall: true water cells that some sensor saw ([`TruthInfo::seen_water`]) and the
//!   map calls water / those seen. These are counted from the truth, binned by the truth
//!   cell's own centre, so seen water the map has no cell for counts as missed. Truth
//!   without `seen_water` falls back to the observed water cells (same as water recall);
//! - off-shore false rate: like the false-positive rate, but over the dry cells farther than
//!   [`SHORE_MARGIN_M`] from all water, so that calling the water's edge wet is not counted;
//! - precision: map cells called water whose truth is water / map cells called water;
//! - obstacle recall and precision: a map cell "is called an obstacle" when its hazard is
//!   obstacle (a step, or a slope on ground). Its truth is an obstacle when the truth cell
//!   containing its centre is an obstacle in the truth raster (an object that is an
//!   obstacle), or when the true terrain around it has a step or slope beyond the vehicle's
//!   limits ([`ObstacleLimits`]) by the mapper's own rule, at the map's resolution: the true
//!   elevations at the centre of the map cell and at the centres of its eight neighbours
//!   (dry truth cells only, like the mapper's dry neighbourhood), with no noise margin.
//!   Obstacle recall: true obstacles called obstacles / true obstacles observed; obstacle
//!   precision: cells called obstacles whose truth is one / cells called obstacles.
//!
//! [`evaluate_matrix_bands`] scores the range bands of the evaluation matrix
//! ([`MATRIX_BANDS`]) and their union.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::grid::{BuildKeyHasher, CellKey};
use crate::hazard::{terrain_hazard, Class, Hazard, HazardMap, MapCell};
use crate::sim::{ColourView, TruthInfo};

pub mod rates;

/// Hash maps and sets of cell keys with a fast hasher (truth rasters run to millions of
/// cells).
type KeyMap<V> = HashMap<CellKey, V, BuildKeyHasher>;
type KeySet = HashSet<CellKey, BuildKeyHasher>;

/// Upper edges of the range bins (m); the last bin is open.
pub const BIN_EDGES: [f64; 4] = [5.0, 10.0, 20.0, 30.0];

/// Metrics of one range bin (or of all cells).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct BinMetrics {
    /// "0-5", "5-10", ..., "30+", or "all".
    pub range: String,
    pub observed_cells: usize,
    /// Map cells outside the truth raster (not scored).
    pub outside_truth: usize,
    pub water_cells: usize,
    pub water_detected: usize,
    pub water_recall: Option<f64>,
    pub dry_cells: usize,
    pub false_water: usize,
    pub false_positive_rate: Option<f64>,
    pub surface_cells: usize,
    pub surface_rms_m: Option<f64>,
    pub depth_cells: usize,
    pub depth_rms_m: Option<f64>,
    pub terrain_cells: usize,
    pub terrain_rms_m: Option<f64>,
    /// Of `terrain_cells` with a finite `elevation_std` σ, those whose error is within 1σ,
    /// 2σ and 3σ of the truth (a Gaussian puts 68.3, 95.4 and 99.7 % there), and how many
    /// had a σ.
    pub terrain_sigma_cells: usize,
    pub terrain_within_sigma: [usize; 3],
    /// `terrain_within_sigma / terrain_sigma_cells`.
    pub terrain_within_sigma_frac: [Option<f64>; 3],
    /// Of `terrain_cells`, those whose σ is at most [`CONFIDENT_SIGMA_M`], and the RMS error
    /// over them: what a planner trusting a small σ gets.
    pub terrain_confident_cells: usize,
    pub terrain_confident_rms_m: Option<f64>,
    /// Reliability of the water probability: per decile of `water` (0–0.1, …, 0.9–1), the
    /// observed cells with a truth cell, their mean probability and the fraction whose
    /// truth is water.
    pub water_reliability: Vec<Reliability>,
    /// Of `terrain_cells`, those where a lidar return the mapper fused fell ([`lidar_cells`]),
    /// off the edges of objects (no truth obstacle within one map cell: a cell astride a
    /// wall holds the wall's returns): the dry ground the lidar saw. 0 without the log's
    /// lidar.
    pub terrain_lidar_cells: usize,
    /// RMS error of the map's elevation over `terrain_lidar_cells`.
    pub terrain_lidar_rms_m: Option<f64>,
    /// Dry truth cells whose map z is more than [`SUNK_M`] below the true terrain.
    pub sunk_cells: usize,
    /// True water cells of the truth that some sensor saw ([`TruthInfo::seen_water`]), in
    /// the bin by the distance of their own centre to the path, whether or not the map has
    /// a cell there. Truth without `seen_water`: `water_cells` (the observed water).
    pub seen_water_cells: usize,
    /// Of `seen_water_cells`, those whose map cell (the one containing the truth cell's
    /// centre) is called water. Truth without `seen_water`: `water_detected`.
    pub seen_water_detected: usize,
    /// `seen_water_detected / seen_water_cells`.
    pub seen_recall: Option<f64>,
    /// Of `seen_water_cells`, those the colour camera saw reflecting the sky in some frame
    /// ([`ColourView::sky`]): what a colour classifier can call water. 0 when the truth
    /// does not record the colour camera's view.
    pub seen_sky_cells: usize,
    /// Of `seen_sky_cells`, those called water.
    pub seen_sky_detected: usize,
    /// `seen_sky_detected / seen_sky_cells`.
    pub seen_sky_recall: Option<f64>,
    /// Observed cells whose truth cell is off shore: not water, and farther than
    /// [`SHORE_MARGIN_M`] from the centre of every true water cell.
    pub dry_offshore_cells: usize,
    /// Of `dry_offshore_cells`, those called water.
    pub false_water_offshore: usize,
    /// `false_water_offshore / dry_offshore_cells`.
    pub false_rate_offshore: Option<f64>,
    /// Observed cells called water that have a truth cell.
    pub called_water: usize,
    /// Of `called_water`, those whose truth cell is water.
    pub called_true: usize,
    /// `called_true / called_water`.
    pub precision: Option<f64>,
    /// Observed cells with a truth cell whose truth is an obstacle (see the module's
    /// documentation).
    pub obstacle_cells: usize,
    /// Of `obstacle_cells`, those the map calls obstacles (hazard obstacle).
    pub obstacle_detected: usize,
    /// `obstacle_detected / obstacle_cells`.
    pub obstacle_recall: Option<f64>,
    /// Observed cells with a truth cell that the map calls obstacles.
    pub called_obstacle: usize,
    /// Of `called_obstacle`, those whose truth is no obstacle.
    pub false_obstacle: usize,
    /// `(called_obstacle − false_obstacle) / called_obstacle`.
    pub obstacle_precision: Option<f64>,
}

/// One decile of the water probability and what the truth says of its cells.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Reliability {
    /// The decile's lower edge (0.0, 0.1, …, 0.9).
    pub p_from: f64,
    pub cells: usize,
    /// Mean water probability of its cells.
    pub mean_p: Option<f64>,
    /// Fraction of its cells whose truth is water.
    pub water_fraction: Option<f64>,
}

/// A terrain cell is confident when its `elevation_std` is at most this (m).
pub const CONFIDENT_SIGMA_M: f64 = 0.05;

/// How far below the true terrain a dry cell's map z must be to count as sunk (m).
pub const SUNK_M: f64 = 0.15;

/// How far (m) the centre of a dry truth cell must be from the centre of every true water
/// cell for the cell to be off shore. Nearer cells are the water's edge, where a map cell
/// may straddle the shoreline and calling it water is no real false alarm.
pub const SHORE_MARGIN_M: f64 = 0.5;

/// The range bands of the evaluation matrix (m from the path, `[lo, hi)`);
/// [`evaluate_matrix_bands`] scores them and their union.
pub const MATRIX_BANDS: [(f64, f64); 3] = [(5.0, 10.0), (10.0, 20.0), (20.0, 30.0)];

#[derive(Debug, Clone, Default)]
struct Acc {
    m: BinMetrics,
    surface2: f64,
    depth2: f64,
    terrain2: f64,
    terrain_lidar2: f64,
    confident2: f64,
    /// Per decile of p: cells, sum of p, water cells.
    deciles: [(usize, f64, usize); 10],
}

impl Acc {
    /// One observed map cell, its truth cell, whether that is off shore and whether its
    /// truth is an obstacle.
    fn add(&mut self, s: &Scored) {
        let (cell, truth, offshore, obstacle) = (s.cell, s.truth, s.offshore, s.obstacle);
        self.m.observed_cells += 1;
        let Some(t) = truth else {
            self.m.outside_truth += 1;
            return;
        };
        let called_obstacle = cell.hazard == Hazard::Obstacle;
        if obstacle {
            self.m.obstacle_cells += 1;
            self.m.obstacle_detected += usize::from(called_obstacle);
        }
        if called_obstacle {
            self.m.called_obstacle += 1;
            self.m.false_obstacle += usize::from(!obstacle);
        }
        let called = cell.class == Class::Water;
        let p = cell.water as f64;
        if p.is_finite() {
            let d = &mut self.deciles[((p * 10.0).floor() as usize).min(9)];
            d.0 += 1;
            d.1 += p;
            d.2 += usize::from(t.class == Class::Water);
        }
        if called {
            self.m.called_water += 1;
            self.m.called_true += usize::from(t.class == Class::Water);
        }
        if t.class != Class::Water && offshore {
            self.m.dry_offshore_cells += 1;
            self.m.false_water_offshore += usize::from(called);
        }
        if t.class == Class::Water {
            self.m.water_cells += 1;
            if called {
                self.m.water_detected += 1;
                self.m.surface_cells += 1;
                self.surface2 += (cell.z - t.z).powi(2);
                if cell.depth.is_finite() {
                    self.m.depth_cells += 1;
                    self.depth2 += (cell.depth as f64 - t.depth as f64).powi(2);
                }
            }
        } else {
            self.m.dry_cells += 1;
            if cell.z < t.z - SUNK_M {
                self.m.sunk_cells += 1;
            }
            if called {
                self.m.false_water += 1;
            } else if matches!(t.class, Class::Ground | Class::SnowIce) {
                self.m.terrain_cells += 1;
                let err = cell.z - t.z;
                self.terrain2 += err.powi(2);
                let sd = cell.elevation_std;
                if sd.is_finite() && sd > 0.0 {
                    self.m.terrain_sigma_cells += 1;
                    for (k, n) in self.m.terrain_within_sigma.iter_mut().enumerate() {
                        *n += usize::from(err.abs() <= (k + 1) as f64 * sd);
                    }
                    if sd <= CONFIDENT_SIGMA_M {
                        self.m.terrain_confident_cells += 1;
                        self.confident2 += err.powi(2);
                    }
                }
                if s.lidar && !s.near_object {
                    self.m.terrain_lidar_cells += 1;
                    self.terrain_lidar2 += (cell.z - t.z).powi(2);
                }
            }
        }
    }

    /// One seen true-water truth cell, called water by the map or not, and whether the
    /// colour camera saw it reflecting the sky.
    fn add_seen(&mut self, called: bool, sky: bool) {
        self.m.seen_water_cells += 1;
        self.m.seen_water_detected += usize::from(called);
        if sky {
            self.m.seen_sky_cells += 1;
            self.m.seen_sky_detected += usize::from(called);
        }
    }

    /// The rates and errors; `seen_recorded` false (truth without `seen_water`) takes the
    /// seen water from the observed water.
    fn finish(mut self, seen_recorded: bool) -> BinMetrics {
        let rms = |s: f64, n: usize| (n > 0).then(|| (s / n as f64).sqrt());
        if !seen_recorded {
            self.m.seen_water_cells = self.m.water_cells;
            self.m.seen_water_detected = self.m.water_detected;
        }
        self.m.water_recall = ratio(self.m.water_detected, self.m.water_cells);
        self.m.false_positive_rate = ratio(self.m.false_water, self.m.dry_cells);
        self.m.seen_recall = ratio(self.m.seen_water_detected, self.m.seen_water_cells);
        self.m.seen_sky_recall = ratio(self.m.seen_sky_detected, self.m.seen_sky_cells);
        self.m.false_rate_offshore = ratio(self.m.false_water_offshore, self.m.dry_offshore_cells);
        self.m.precision = ratio(self.m.called_true, self.m.called_water);
        self.m.obstacle_recall = ratio(self.m.obstacle_detected, self.m.obstacle_cells);
        self.m.obstacle_precision = ratio(
            self.m.called_obstacle - self.m.false_obstacle,
            self.m.called_obstacle,
        );
        self.m.surface_rms_m = rms(self.surface2, self.m.surface_cells);
        self.m.depth_rms_m = rms(self.depth2, self.m.depth_cells);
        self.m.terrain_rms_m = rms(self.terrain2, self.m.terrain_cells);
        self.m.terrain_lidar_rms_m = rms(self.terrain_lidar2, self.m.terrain_lidar_cells);
        self.m.terrain_confident_rms_m = rms(self.confident2, self.m.terrain_confident_cells);
        self.m.terrain_within_sigma_frac = self
            .m
            .terrain_within_sigma
            .map(|n| ratio(n, self.m.terrain_sigma_cells));
        self.m.water_reliability = self
            .deciles
            .iter()
            .enumerate()
            .map(|(k, &(n, sp, w))| Reliability {
                p_from: k as f64 / 10.0,
                cells: n,
                mean_p: (n > 0).then(|| sp / n as f64),
                water_fraction: ratio(w, n),
            })
            .collect();
        self.m
    }
}

fn ratio(a: usize, b: usize) -> Option<f64> {
    (b > 0).then(|| a as f64 / b as f64)
}

/// The vehicle's limits that make true terrain an obstacle: the mapper's defaults
/// ([`crate::water::Vehicle`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ObstacleLimits {
    pub max_step_m: f64,
    pub max_slope_deg: f64,
}

impl Default for ObstacleLimits {
    fn default() -> Self {
        let v = crate::water::Vehicle::default();
        ObstacleLimits {
            max_step_m: v.max_step_m,
            max_slope_deg: v.max_slope_deg,
        }
    }
}

impl ObstacleLimits {
    /// Whether the true terrain makes the map cell centred at (x, y), of `mres` m, an
    /// obstacle: its truth cell is one (an object), or the mapper's step and slope rule
    /// over the true elevations at the centres of the cell and its eight neighbours says
    /// so. Water truth cells are not terrain: a water centre is no obstacle, a water
    /// neighbour is left out.
    fn truth_obstacle(
        &self,
        index: &KeyMap<&MapCell>,
        res: f64,
        mres: f64,
        x: f64,
        y: f64,
    ) -> bool {
        let at = |x: f64, y: f64| index.get(&tarn::grid::key_of(res, x, y)).copied();
        let Some(t) = at(x, y) else {
            return false;
        };
        if t.hazard == Hazard::Obstacle {
            return true;
        }
        if t.class == Class::Water {
            return false;
        }
        let nb: crate::hazard::Neighbourhood = std::array::from_fn(|j| {
            let (dx, dy) = neighbour_offset(j);
            let z = at(x + dx * mres, y + dy * mres)
                .filter(|n| n.class != Class::Water)
                .map_or(f64::NAN, |n| n.z);
            (z, 0.0)
        });
        let grad = self.max_slope_deg.to_radians().tan();
        terrain_hazard(&nb, (t.z, 0.0), mres, self.max_step_m, grad).1 == Hazard::Obstacle
    }
}

/// Offset (−1, 0 or 1 in x and y) of neighbour `j` of a 3 × 3 neighbourhood, row by row
/// from the lower left (the order of [`crate::hazard::Neighbourhood`]).
fn neighbour_offset(j: usize) -> (f64, f64) {
    ((j % 3) as f64 - 1.0, (j / 3) as f64 - 1.0)
}

/// What `tarn eval` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    pub scene: String,
    pub map_resolution: f64,
    pub truth_resolution: f64,
    /// The limits the obstacle truth is drawn with.
    pub obstacle_limits: ObstacleLimits,
    pub bins: Vec<BinMetrics>,
    pub all: BinMetrics,
    /// Water recall split by what the colour camera saw of each water cell (all ranges),
    /// when the truth records it ([`crate::sim::ColourView`]).
    pub colour_view: Option<ColourViewRecall>,
}

/// Observed true-water map cells and those called water, by what the colour camera saw of
/// their truth cell: a sky reflection in some frame, only terrain reflections, or nothing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ColourViewRecall {
    pub sky: ViewCount,
    pub terrain: ViewCount,
    pub unseen: ViewCount,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ViewCount {
    pub water_cells: usize,
    pub water_detected: usize,
    pub recall: Option<f64>,
}

impl ViewCount {
    fn add(&mut self, called: bool) {
        self.water_cells += 1;
        self.water_detected += usize::from(called);
        self.recall = ratio(self.water_detected, self.water_cells);
    }
}

impl ColourViewRecall {
    fn of(map: &HazardMap, index: &KeyMap<&MapCell>, res: f64, v: &ColourView) -> Self {
        let sky: HashSet<[i64; 2]> = v.sky.iter().copied().collect();
        let terrain: HashSet<[i64; 2]> = v.terrain.iter().copied().collect();
        let mut r = ColourViewRecall::default();
        for c in &map.cells {
            let k = [(c.x / res).floor() as i64, (c.y / res).floor() as i64];
            if index
                .get(&CellKey::new(k[0], k[1]))
                .is_some_and(|t| t.class == Class::Water)
            {
                let called = c.class == Class::Water;
                match (sky.contains(&k), terrain.contains(&k)) {
                    (true, _) => r.sky.add(called),
                    (false, true) => r.terrain.add(called),
                    _ => r.unseen.add(called),
                }
            }
        }
        r
    }
}

impl EvalReport {
    /// True when every scored cell agrees exactly: recall 1, no false water, zero errors.
    pub fn is_perfect(&self) -> bool {
        let m = &self.all;
        m.water_recall.is_none_or(|r| r == 1.0)
            && m.false_water == 0
            && [m.surface_rms_m, m.depth_rms_m, m.terrain_rms_m]
                .iter()
                .all(|e| e.is_none_or(|e| e == 0.0))
    }

    /// Water recall by what the colour camera saw, in one line (`None` without the truth).
    pub fn colour_view_line(&self) -> Option<String> {
        let v = self.colour_view.as_ref()?;
        let f = |c: &ViewCount| {
            let rec = c.recall.map_or("–".to_string(), |v| format!("{v:.3}"));
            format!("{rec} ({} of {})", c.water_detected, c.water_cells)
        };
        Some(format!(
            "water recall by what the colour camera saw: sky reflection {}, terrain reflection only {}, never seen {}",
            f(&v.sky),
            f(&v.terrain),
            f(&v.unseen)
        ))
    }

    /// A Markdown table of the obstacle metrics by bin.
    pub fn obstacle_markdown(&self) -> String {
        let f = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3}"));
        let mut s = String::from(
            "| range (m) | true obstacles | detected | obstacle recall | called obstacles | false obstacles | obstacle precision |\n\
             | --- | ---: | ---: | ---: | ---: | ---: | ---: |\n",
        );
        for b in self.bins.iter().chain(std::iter::once(&self.all)) {
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} |\n",
                b.range,
                b.obstacle_cells,
                b.obstacle_detected,
                f(b.obstacle_recall),
                b.called_obstacle,
                b.false_obstacle,
                f(b.obstacle_precision)
            ));
        }
        s
    }

    /// A Markdown table of the bins (for READMEs).
    pub fn markdown(&self) -> String {
        let f = |v: Option<f64>, d: usize| v.map_or("–".to_string(), |v| format!("{v:.d$}"));
        let mut s = String::from(
            "| range (m) | observed | water | recall | seen recall | dry | false-positive rate | off-shore false rate | precision | surface RMS (m) | depth RMS (m) | terrain RMS (m) |\n\
             | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n",
        );
        for b in self.bins.iter().chain(std::iter::once(&self.all)) {
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                b.range,
                b.observed_cells,
                b.water_cells,
                f(b.water_recall, 3),
                f(b.seen_recall, 3),
                b.dry_cells,
                f(b.false_positive_rate, 4),
                f(b.false_rate_offshore, 4),
                f(b.precision, 3),
                f(b.surface_rms_m, 3),
                f(b.depth_rms_m, 3),
                f(b.terrain_rms_m, 3)
            ));
        }
        s
    }
}

/// Distance from (x, y) to the polyline through `path` (a single point is allowed).
pub fn distance_to_path(path: &[[f64; 2]], x: f64, y: f64) -> f64 {
    match path {
        [] => f64::INFINITY,
        [p] => (x - p[0]).hypot(y - p[1]),
        _ => path
            .windows(2)
            .map(|s| {
                let (a, b) = (s[0], s[1]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let l2 = dx * dx + dy * dy;
                let t = if l2 > 0.0 {
                    (((x - a[0]) * dx + (y - a[1]) * dy) / l2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (x - a[0] - t * dx).hypot(y - a[1] - t * dy)
            })
            .fold(f64::INFINITY, f64::min),
    }
}

fn bin_name(i: usize) -> String {
    match i {
        0 => format!("0-{}", BIN_EDGES[0]),
        i if i < BIN_EDGES.len() => format!("{}-{}", BIN_EDGES[i - 1], BIN_EDGES[i]),
        _ => format!("{}+", BIN_EDGES[BIN_EDGES.len() - 1]),
    }
}

/// The bin of a distance to the path: its index in [`BIN_EDGES`], or the open last bin.
fn bin_of(d: f64) -> usize {
    BIN_EDGES
        .iter()
        .position(|&e| d < e)
        .unwrap_or(BIN_EDGES.len())
}

/// The truth cells within [`SHORE_MARGIN_M`] of the centre of a true water cell: the water
/// mask dilated by a disc. A dense array over the truth raster's bounding box, or a hash
/// set when the truth is sparse (a box over four times its cells).
enum Shore {
    Dense {
        lo: CellKey,
        width: i64,
        height: i64,
        /// One flag per cell of the box, row by row.
        near: Vec<bool>,
    },
    Sparse(KeySet),
}

impl Shore {
    fn new(truth: &HazardMap) -> Self {
        let res = truth.resolution;
        let water: KeySet = truth
            .cells
            .iter()
            .filter(|c| c.class == Class::Water)
            .map(|c| c.key)
            .collect();
        // Offsets whose centres are within the margin (a hair of slack for rounding).
        let r = (SHORE_MARGIN_M / res).ceil() as i64;
        let disc: Vec<(i64, i64)> = (-r..=r)
            .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
            .filter(|&(dx, dy)| (dx as f64).hypot(dy as f64) * res <= SHORE_MARGIN_M + 1e-9)
            .collect();
        let mut s = match truth.cells.first() {
            None => Shore::Sparse(KeySet::default()),
            Some(first) => {
                let (lo, hi) = truth
                    .cells
                    .iter()
                    .fold((first.key, first.key), |(lo, hi), c| {
                        (
                            CellKey::new(lo.x.min(c.key.x), lo.y.min(c.key.y)),
                            CellKey::new(hi.x.max(c.key.x), hi.y.max(c.key.y)),
                        )
                    });
                let (width, height) = (hi.x - lo.x + 1, hi.y - lo.y + 1);
                if width.saturating_mul(height) <= 4 * truth.cells.len() as i64 {
                    Shore::Dense {
                        lo,
                        width,
                        height,
                        near: vec![false; (width * height) as usize],
                    }
                } else {
                    Shore::Sparse(KeySet::default())
                }
            }
        };
        // The water cell nearest a dry cell has a neighbour (the step towards the dry
        // cell) that is not water, else that neighbour would be nearer: only water cells
        // on a boundary need stamping.
        let boundary = |k: &&CellKey| {
            [(1, 0), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .any(|(dx, dy)| !water.contains(&CellKey::new(k.x + dx, k.y + dy)))
        };
        for k in water.iter().filter(boundary) {
            for (dx, dy) in &disc {
                s.mark(CellKey::new(k.x + dx, k.y + dy));
            }
        }
        s
    }

    /// The index of `k` in a dense box of `width` × `height` from `lo`, if it is inside.
    fn slot(lo: CellKey, width: i64, height: i64, k: CellKey) -> Option<usize> {
        let (x, y) = (k.x.checked_sub(lo.x)?, k.y.checked_sub(lo.y)?);
        ((0..width).contains(&x) && (0..height).contains(&y)).then(|| (y * width + x) as usize)
    }

    fn mark(&mut self, k: CellKey) {
        match self {
            Shore::Dense {
                lo,
                width,
                height,
                near,
            } => {
                if let Some(i) = Shore::slot(*lo, *width, *height, k) {
                    near[i] = true;
                }
            }
            Shore::Sparse(set) => {
                set.insert(k);
            }
        }
    }

    /// Whether the centre of truth cell `k` is within [`SHORE_MARGIN_M`] of a water cell's.
    fn near(&self, k: CellKey) -> bool {
        match self {
            Shore::Dense {
                lo,
                width,
                height,
                near,
            } => Shore::slot(*lo, *width, *height, k).is_some_and(|i| near[i]),
            Shore::Sparse(set) => set.contains(&k),
        }
    }
}

/// One observed map cell ready to score.
struct Scored<'a> {
    cell: &'a MapCell,
    /// The truth cell containing the map cell's centre.
    truth: Option<&'a MapCell>,
    /// The truth cell is off shore (see [`BinMetrics::dry_offshore_cells`]).
    offshore: bool,
    /// Distance of the map cell's centre to the path (m).
    d: f64,
    /// The true terrain makes the cell an obstacle ([`ObstacleLimits`]).
    obstacle: bool,
    /// A lidar return of the log fell in the cell ([`lidar_cells`]).
    lidar: bool,
    /// A truth cell within one map cell of the cell's centre is an obstacle.
    near_object: bool,
}

/// What every bin and band is scored from, computed once per map and truth.
struct Scorer<'a> {
    /// Truth cells by key (at the truth's resolution).
    index: KeyMap<&'a MapCell>,
    cells: Vec<Scored<'a>>,
    /// The seen true-water truth cells: distance of the centre to the path, whether the
    /// map calls the cell containing that centre water, and whether the colour camera saw
    /// the cell reflecting the sky. `None` without [`TruthInfo::seen_water`].
    seen: Option<Vec<(f64, bool, bool)>>,
}

impl<'a> Scorer<'a> {
    fn new(map: &'a HazardMap, truth: &'a HazardMap, info: &TruthInfo) -> Result<Self> {
        if truth.resolution.is_nan() || truth.resolution <= 0.0 {
            return Err(Error::invalid(
                "truth",
                format!("resolution {} must be > 0", truth.resolution),
            ));
        }
        let res = truth.resolution;
        let index: KeyMap<&MapCell> = truth.cells.iter().map(|c| (c.key, c)).collect();
        let path: Vec<[f64; 2]> = info.trajectory.iter().map(|p| [p.x, p.y]).collect();
        let shore = Shore::new(truth);
        let limits = ObstacleLimits::default();
        let mres = map.resolution;
        let cells = map
            .cells
            .iter()
            .map(|c| {
                let key = tarn::grid::key_of(res, c.x, c.y);
                let t = index.get(&key).copied();
                Scored {
                    cell: c,
                    truth: t,
                    offshore: t.is_some_and(|t| t.class != Class::Water && !shore.near(key)),
                    d: distance_to_path(&path, c.x, c.y),
                    obstacle: limits.truth_obstacle(&index, res, mres, c.x, c.y),
                    lidar: false,
                    near_object: (0..9).any(|j| {
                        let (dx, dy) = neighbour_offset(j);
                        let k = tarn::grid::key_of(res, c.x + dx * mres, c.y + dy * mres);
                        index.get(&k).is_some_and(|t| t.hazard == Hazard::Obstacle)
                    }),
                }
            })
            .collect();
        let seen = match &info.seen_water {
            None => None,
            Some(keys) => {
                let mres = map.resolution;
                if !(mres > 0.0 && mres.is_finite()) {
                    return Err(Error::invalid(
                        "map",
                        format!("resolution {mres} must be > 0"),
                    ));
                }
                // A map cell is called water when any cell of the map with its key is.
                let mut called: KeyMap<bool> = KeyMap::default();
                for c in &map.cells {
                    *called.entry(c.key).or_default() |= c.class == Class::Water;
                }
                let keys: KeySet = keys.iter().map(|k| CellKey::new(k[0], k[1])).collect();
                let sky: KeySet = info
                    .colour_view
                    .iter()
                    .flat_map(|v| &v.sky)
                    .map(|k| CellKey::new(k[0], k[1]))
                    .collect();
                Some(
                    keys.into_iter()
                        .filter(|k| index.get(k).is_some_and(|t| t.class == Class::Water))
                        .map(|k| {
                            let (x, y) = ((k.x as f64 + 0.5) * res, (k.y as f64 + 0.5) * res);
                            let mk =
                                CellKey::new((x / mres).floor() as i64, (y / mres).floor() as i64);
                            (
                                distance_to_path(&path, x, y),
                                called.get(&mk).copied().unwrap_or(false),
                                sky.contains(&k),
                            )
                        })
                        .collect(),
                )
            }
        };
        Ok(Scorer { index, cells, seen })
    }

    /// The metrics of the cells (map cells by their centre, seen truth cells by theirs)
    /// whose distance to the path `keep` accepts.
    fn score(&self, keep: impl Fn(f64) -> bool) -> BinMetrics {
        let mut acc = Acc::default();
        for s in self.cells.iter().filter(|s| keep(s.d)) {
            acc.add(s);
        }
        for &(_, called, sky) in self.seen.iter().flatten().filter(|(d, ..)| keep(*d)) {
            acc.add_seen(called, sky);
        }
        acc.finish(self.seen.is_some())
    }

    /// Marks the map cells (keys at the map's resolution) where the lidar returned.
    fn with_lidar(mut self, lidar: Option<&KeySet>) -> Self {
        if let Some(keys) = lidar {
            for s in &mut self.cells {
                s.lidar = keys.contains(&s.cell.key);
            }
        }
        self
    }

    /// The metrics of the band `[lo, hi)` m, named "lo-hi".
    fn band(&self, lo: f64, hi: f64) -> BinMetrics {
        let mut m = self.score(|d| d >= lo && d < hi);
        m.range = format!("{lo}-{hi}");
        m
    }
}

/// Scores `map` against the truth raster and the trajectory of `info`.
pub fn evaluate(map: &HazardMap, truth: &HazardMap, info: &TruthInfo) -> Result<EvalReport> {
    let s = Scorer::new(map, truth, info)?;
    Ok(EvalReport {
        scene: info.scene.clone(),
        map_resolution: map.resolution,
        truth_resolution: truth.resolution,
        obstacle_limits: ObstacleLimits::default(),
        bins: (0..=BIN_EDGES.len())
            .map(|i| {
                let mut m = s.score(|d| bin_of(d) == i);
                m.range = bin_name(i);
                m
            })
            .collect(),
        all: {
            let mut m = s.score(|_| true);
            m.range = "all".into();
            m
        },
        colour_view: info
            .colour_view
            .as_ref()
            .map(|v| ColourViewRecall::of(map, &s.index, truth.resolution, v)),
    })
}

fn check_band(lo: f64, hi: f64) -> Result<()> {
    if !(lo >= 0.0 && hi > lo) {
        return Err(Error::invalid(
            "range band",
            format!("{lo}-{hi} m must satisfy 0 ≤ lo < hi"),
        ));
    }
    Ok(())
}

/// Scores the cells whose distance to the path is in `[lo, hi)` m, like one bin of
/// [`evaluate`] (`range` is "lo-hi").
pub fn evaluate_band(
    map: &HazardMap,
    truth: &HazardMap,
    info: &TruthInfo,
    lo: f64,
    hi: f64,
) -> Result<BinMetrics> {
    check_band(lo, hi)?;
    Ok(Scorer::new(map, truth, info)?.band(lo, hi))
}

/// Scores the bands of the evaluation matrix: the three [`MATRIX_BANDS`] ("5-10",
/// "10-20", "20-30") and then their union ("5-30"), each like [`evaluate_band`]; with
/// `lidar` (the map cells the log's lidar returned from, [`lidar_cells`]) the terrain
/// error where the lidar saw the ground too.
pub fn evaluate_matrix_bands(
    map: &HazardMap,
    truth: &HazardMap,
    info: &TruthInfo,
    lidar: Option<&KeySet>,
) -> Result<Vec<BinMetrics>> {
    let s = Scorer::new(map, truth, info)?.with_lidar(lidar);
    Ok(matrix_bands_and_union()
        .into_iter()
        .map(|(lo, hi)| s.band(lo, hi))
        .collect())
}

/// The bands of the evaluation matrix, [`MATRIX_BANDS`] and then their union.
fn matrix_bands_and_union() -> Vec<(f64, f64)> {
    let all = (MATRIX_BANDS[0].0, MATRIX_BANDS[MATRIX_BANDS.len() - 1].1);
    MATRIX_BANDS.iter().copied().chain([all]).collect()
}

/// The cells (keys at `grid.resolution` m) where a lidar return of the log at `log` fell
/// inside that frame's rolling window (`grid`'s, placed as the mapper places it,
/// [`tarn::mapper::window_centre`]): the returns a mapper with that window fused. A return
/// outside the window is dropped by the mapper, so the cell it fell in is not ground the
/// lidar saw. Empty when the log has no lidar topic (the default
/// [`LogConfig`](tarn_log::frames::LogConfig)'s).
pub fn lidar_cells(log: &Path, grid: &tarn::grid::GridConfig) -> Result<KeySet> {
    use tarn_log::frames::{FrameStream, LogConfig};
    grid.validate()?;
    let (res, n) = (grid.resolution, grid.size_cells as i64);
    let mut keys = KeySet::default();
    for f in FrameStream::open(log, &LogConfig::default())? {
        let f = f?;
        let Some(c) = &f.lidar else { continue };
        let (cx, cy) = tarn::mapper::window_centre(grid, &f.base_to_map);
        let CellKey { x: x0, y: y0 } = tarn::grid::window_origin(grid, cx, cy);
        for i in (0..c.len()).filter(|&i| c.is_valid(i)) {
            let p = c.point_in_map(i);
            let k = tarn::grid::key_of(res, p.x, p.y);
            if (x0..x0 + n).contains(&k.x) && (y0..y0 + n).contains(&k.y) {
                keys.insert(k);
            }
        }
    }
    Ok(keys)
}

/// Reads `MAPDIR/map.ply`, `TRUTHDIR/truth.ply` and `TRUTHDIR/truth.json`.
pub fn read_dirs(map_dir: &Path, truth_dir: &Path) -> Result<(HazardMap, HazardMap, TruthInfo)> {
    let map = crate::io::mapfile::read_map_ply(&map_dir.join("map.ply"))?;
    let truth = crate::io::mapfile::read_map_ply(&truth_dir.join("truth.ply"))?;
    let jp = truth_dir.join("truth.json");
    let text = std::fs::read_to_string(&jp).map_err(|e| Error::io(&jp, e))?;
    let info: TruthInfo = serde_json::from_str(&text)
        .map_err(|e| Error::format(&jp, format!("line {}", e.line()), e.to_string()))?;
    Ok((map, truth, info))
}

/// Reads `MAPDIR/map.ply`, `TRUTHDIR/truth.ply` and `TRUTHDIR/truth.json` and scores.
pub fn evaluate_dirs(map_dir: &Path, truth_dir: &Path) -> Result<EvalReport> {
    let (map, truth, info) = read_dirs(map_dir, truth_dir)?;
    evaluate(&map, &truth, &info)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hazard::Hazard;
    use crate::sim::TruthPose;
    use proptest::prelude::*;

    #[test]
    fn distance_to_a_polyline() {
        let p = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]];
        assert_eq!(distance_to_path(&p, 5.0, 3.0), 3.0);
        assert_eq!(distance_to_path(&p, 13.0, 5.0), 3.0);
        assert_eq!(distance_to_path(&p, -4.0, 3.0), 5.0);
        assert_eq!(distance_to_path(&p[..1], 3.0, 4.0), 5.0);
    }

    #[test]
    fn a_band_scores_only_its_cells_and_counts_sunk_ones() {
        let cell = |kx: i64, z: f64, class: Class| MapCell {
            key: CellKey::new(kx, 0),
            x: (kx as f64 + 0.5) * 1.0,
            y: 0.5,
            z,
            elevation_std: 0.0,
            water: 0.0,
            depth: 0.0,
            class,
            hazard: Hazard::Free,
            hits: 1,
            below: 0,
        };
        let truth = HazardMap::new(
            1.0,
            (0..40)
                .map(|k| cell(k, 0.0, if k == 12 { Class::Water } else { Class::Ground }))
                .collect(),
        );
        // Ground at 0; the map sinks cell 8 (a reflection fused as terrain) and calls 12 water.
        let mut map = truth.clone();
        map.cells[8].z = -0.5;
        map.cells[20].z = -0.1;
        let info = TruthInfo {
            scene: "t".into(),
            description: String::new(),
            seed: 0,
            resolution: 1.0,
            fording_depth_m: 0.3,
            origin: [0.0, 0.0],
            size: [40.0, 1.0],
            trajectory: vec![TruthPose {
                stamp: 0.0,
                x: 0.0,
                y: 0.5,
                z: 0.0,
                yaw: 0.0,
            }],
            water_bodies: Vec::new(),
            class_counts: [0; 6],
            topics: Vec::new(),
            colour_view: None,
            seen_water: None,
        };
        // Recall by what the camera saw: cell 12 seen as sky, 13 (water too) only as
        // terrain, 14 never; the map calls 12 and 14 water.
        let mut t2 = truth.clone();
        t2.cells[13].class = Class::Water;
        t2.cells[14].class = Class::Water;
        let mut m2 = t2.clone();
        m2.cells[13].class = Class::Ground;
        let info2 = TruthInfo {
            colour_view: Some(ColourView {
                sky: vec![[12, 0], [30, 0]],
                terrain: vec![[13, 0]],
            }),
            ..info.clone()
        };
        let v = evaluate(&m2, &t2, &info2).unwrap().colour_view.unwrap();
        assert_eq!((v.sky.water_cells, v.sky.water_detected), (1, 1));
        assert_eq!((v.terrain.water_cells, v.terrain.recall), (1, Some(0.0)));
        assert_eq!((v.unseen.water_cells, v.unseen.water_detected), (1, 1));
        assert!(evaluate(&m2, &t2, &info).unwrap().colour_view.is_none());
        let b = evaluate_band(&map, &truth, &info, 5.0, 25.0).unwrap();
        // Cells 5..=24 have centres at 5.5..24.5 m.
        assert_eq!(b.observed_cells, 20);
        assert_eq!((b.water_cells, b.water_detected), (1, 1));
        assert_eq!(b.sunk_cells, 1);
        assert_eq!(b.range, "5-25");
        assert!(evaluate_band(&map, &truth, &info, 5.0, 5.0).is_err());
    }

    /// A cell at key (kx, ky) of a grid of `res` m cells, z 0.
    fn cell(res: f64, kx: i64, ky: i64, class: Class) -> MapCell {
        MapCell {
            key: CellKey::new(kx, ky),
            x: (kx as f64 + 0.5) * res,
            y: (ky as f64 + 0.5) * res,
            z: 0.0,
            elevation_std: 0.0,
            water: 0.0,
            depth: 0.0,
            class,
            hazard: Hazard::Free,
            hits: 1,
            below: 0,
        }
    }

    /// A raster of `nx` × `ny` cells of `res` m from key (0, 0); `water` says which are.
    pub(super) fn raster(
        res: f64,
        nx: i64,
        ny: i64,
        water: impl Fn(i64, i64) -> bool,
    ) -> HazardMap {
        let cells = (0..ny)
            .flat_map(|ky| (0..nx).map(move |kx| (kx, ky)))
            .map(|(kx, ky)| {
                let class = if water(kx, ky) {
                    Class::Water
                } else {
                    Class::Ground
                };
                cell(res, kx, ky, class)
            })
            .collect();
        HazardMap::new(res, cells)
    }

    /// Truth with a trajectory through `path` and the given seen water.
    pub(super) fn info(res: f64, path: &[[f64; 2]], seen: Option<Vec<[i64; 2]>>) -> TruthInfo {
        TruthInfo {
            scene: "t".into(),
            description: String::new(),
            seed: 0,
            resolution: res,
            fording_depth_m: 0.3,
            origin: [0.0, 0.0],
            size: [1.0, 1.0],
            trajectory: path
                .iter()
                .map(|p| TruthPose {
                    stamp: 0.0,
                    x: p[0],
                    y: p[1],
                    z: 0.0,
                    yaw: 0.0,
                })
                .collect(),
            water_bodies: Vec::new(),
            class_counts: [0; 6],
            topics: Vec::new(),
            colour_view: None,
            seen_water: seen,
        }
    }

    fn set_class(map: &mut HazardMap, kx: i64, ky: i64, class: Class) {
        let c = map.cells.iter_mut().find(|c| c.key == CellKey::new(kx, ky));
        c.unwrap().class = class;
    }

    #[test]
    fn the_maps_sigma_and_water_probability_are_scored() {
        // 1 m cells along x, 10..20 m from the path: ten dry cells with errors 0.05·k and
        // σ 0.1, so errors 0, .05, .1 lie within 1σ (3), up to .2 within 2σ (5), up to .3
        // within 3σ (7); water cells 20..30 of p 0.95, dry ones of p 0.05 and 0.15.
        let truth = raster(1.0, 40, 1, |kx, _| (20..30).contains(&kx));
        let mut map = truth.clone();
        for c in map.cells.iter_mut() {
            let k = c.key.x;
            c.elevation_std = if k == 19 { f64::NAN } else { 0.1 };
            if (10..20).contains(&k) {
                c.z = 0.05 * (k - 10) as f64;
            }
            c.water = match k {
                20..=29 => 0.95,
                0..=4 => 0.15,
                _ => 0.05,
            };
        }
        let info = info(1.0, &[[0.0, 0.5]], None);
        let b = evaluate_band(&map, &truth, &info, 10.0, 20.0).unwrap();
        // Cell 19 has no σ: nine scored, errors 0 … 0.40.
        assert_eq!(b.terrain_sigma_cells, 9);
        assert_eq!(b.terrain_within_sigma, [3, 5, 7]);
        assert_eq!(b.terrain_within_sigma_frac[0], Some(3.0 / 9.0));
        assert_eq!(b.terrain_confident_cells, 0);
        let all = evaluate(&map, &truth, &info).unwrap().all;
        let r = &all.water_reliability;
        assert_eq!(r.len(), 10);
        assert_eq!((r[0].cells, r[0].water_fraction), (25, Some(0.0)));
        assert_eq!((r[1].cells, r[1].water_fraction), (5, Some(0.0)));
        assert_eq!((r[9].cells, r[9].water_fraction), (10, Some(1.0)));
        assert!((r[9].mean_p.unwrap() - 0.95).abs() < 1e-6);
        assert_eq!((r[5].cells, r[5].mean_p), (0, None));
    }

    #[test]
    fn seen_water_the_map_lacks_counts_as_missed() {
        // 1 m cells along x, the path at the origin: cell k is k + 0.5 m away. Water 12..=15.
        let truth = raster(1.0, 40, 1, |kx, _| (12..=15).contains(&kx));
        let mut map = truth.clone();
        map.cells.retain(|c| c.key.x != 14);
        set_class(&mut map, 15, 0, Class::Ground);
        // Seen: the four water cells (14 twice), a dry cell and one outside the truth; the
        // last two are no water and do not count.
        let seen = vec![
            [12, 0],
            [13, 0],
            [14, 0],
            [15, 0],
            [14, 0],
            [30, 0],
            [99, 0],
        ];
        let info = info(1.0, &[[0.0, 0.5]], Some(seen));
        let b = evaluate_band(&map, &truth, &info, 10.0, 20.0).unwrap();
        assert_eq!((b.seen_water_cells, b.seen_water_detected), (4, 2));
        assert_eq!(b.seen_recall, Some(0.5));
        // Recall over the observed water does not see the missing cell.
        assert_eq!((b.water_cells, b.water_detected), (3, 2));
        assert_eq!(b.water_recall, Some(2.0 / 3.0));
        assert_eq!(
            (b.called_water, b.called_true, b.precision),
            (2, 2, Some(1.0))
        );
        let r = evaluate(&map, &truth, &info).unwrap();
        assert_eq!(r.bins[2].range, "10-20");
        assert_eq!(r.bins[2].seen_recall, Some(0.5));
        assert_eq!(r.all.seen_water_cells, 4);
        assert_eq!(
            (r.bins[3].seen_water_cells, r.bins[3].seen_recall),
            (0, None)
        );
        assert_eq!((r.bins[3].called_water, r.bins[3].precision), (0, None));
        // Without the colour camera's view no seen cell is a sky reflection.
        assert_eq!((b.seen_sky_cells, b.seen_sky_recall), (0, None));

        // The camera saw 12 (called) and 14 (missing) reflecting the sky, 13 only terrain,
        // and the dry cell 30 the sky: of the seen water, two reflected the sky, one found.
        let mut info = info;
        info.colour_view = Some(ColourView {
            sky: vec![[12, 0], [14, 0], [30, 0]],
            terrain: vec![[13, 0]],
        });
        let b = evaluate_band(&map, &truth, &info, 10.0, 20.0).unwrap();
        assert_eq!((b.seen_sky_cells, b.seen_sky_detected), (2, 1));
        assert_eq!(b.seen_sky_recall, Some(0.5));
        assert_eq!((b.seen_water_cells, b.seen_water_detected), (4, 2));
    }

    #[test]
    fn water_called_at_the_shore_is_not_off_shore() {
        // 0.5 m cells, 60 × 3; water at (30..=33, 1). Within 0.5 m of it (the shore): the
        // dry cells beside it in x and y, not the diagonal ones (0.71 m).
        let truth = raster(0.5, 60, 3, |kx, ky| ky == 1 && (30..=33).contains(&kx));
        let mut map = truth.clone();
        set_class(&mut map, 29, 1, Class::Water); // shore, beside
        set_class(&mut map, 30, 0, Class::Water); // shore, below
        set_class(&mut map, 29, 0, Class::Water); // diagonal: off shore
        set_class(&mut map, 50, 1, Class::Water); // far: off shore
        map.cells.push(cell(0.5, 200, 1, Class::Water)); // outside the truth: not scored
        let r = evaluate(&map, &truth, &info(0.5, &[[0.0, 0.75]], None)).unwrap();
        let m = &r.all;
        assert_eq!(m.outside_truth, 1);
        assert_eq!((m.dry_cells, m.false_water), (176, 4));
        // 10 shore cells: 2 beside, 4 above and 4 below.
        assert_eq!((m.dry_offshore_cells, m.false_water_offshore), (166, 2));
        assert_eq!(m.false_rate_offshore, Some(2.0 / 166.0));
        // Precision: 4 true water of the 8 cells called water that have truth.
        assert_eq!((m.called_water, m.called_true), (8, 4));
        assert_eq!(m.precision, Some(0.5));
    }

    #[test]
    fn the_shore_is_a_disc_of_half_a_metre() {
        // 0.25 m cells: the margin is two cells along an axis, one diagonally.
        let truth = raster(0.25, 20, 20, |kx, ky| (kx, ky) == (10, 10));
        let s = Shore::new(&truth);
        let near = |dx: i64, dy: i64| s.near(CellKey::new(10 + dx, 10 + dy));
        assert!(near(2, 0) && near(0, -2) && near(1, 1) && near(-1, 1));
        assert!(!near(2, 1) && !near(3, 0) && !near(2, 2) && !near(-1, -2));
        // Outside the raster nothing is near.
        assert!(!s.near(CellKey::new(-1, -1)) && !s.near(CellKey::new(i64::MIN, 0)));
        // A sparse truth (two far cells) gives the same answers.
        let mut sparse = truth.clone();
        sparse.cells.retain(|c| c.key.x == 10 || c.key.y == 10);
        sparse.cells.push(cell(0.25, 1000, 1000, Class::Ground));
        let s2 = Shore::new(&sparse);
        assert!(matches!(s2, Shore::Sparse(_)));
        assert!(s2.near(CellKey::new(12, 10)) && !s2.near(CellKey::new(13, 10)));
    }

    /// Truth of 0.5 m cells, 80 × 2, water at x 10–13 m (keys 20..=25); a map of 1 m cells
    /// calling water at x 10–12 m (keys 10 and 11, not 12); the path the line x = 0.5 m.
    fn two_resolutions(seen: bool) -> (HazardMap, HazardMap, TruthInfo) {
        let truth = raster(0.5, 80, 2, |kx, _| (20..=25).contains(&kx));
        let map = raster(1.0, 40, 1, |kx, _| kx == 10 || kx == 11);
        let seen = seen.then(|| {
            (20..=25)
                .flat_map(|kx| (0..2).map(move |ky| [kx, ky]))
                .collect()
        });
        let path = [[0.5, -100.0], [0.5, 100.0]];
        (map, truth, info(0.5, &path, seen))
    }

    #[test]
    fn truth_cells_are_banded_by_their_own_centres() {
        let (map, truth, info) = two_resolutions(true);
        // Truth key 20 (centre 10.25 m, 9.75 m from the path) is in 5-10 though its map
        // cell (key 10, centre 10.5 m, 10 m away) is in 10-20; the map calls it water.
        let b = evaluate_band(&map, &truth, &info, 5.0, 10.0).unwrap();
        assert_eq!((b.seen_water_cells, b.seen_water_detected), (2, 2));
        assert_eq!((b.water_cells, b.water_recall), (0, None));
        // Keys 21..=25 are 10.25–12.25 m away; 24 and 25 are in map cell 12, not water.
        let b = evaluate_band(&map, &truth, &info, 10.0, 20.0).unwrap();
        assert_eq!((b.seen_water_cells, b.seen_water_detected), (10, 6));
        assert_eq!(b.seen_recall, Some(0.6));
        // Map cells 10, 11, 12 meet truth keys 21, 23, 25 (their centres' cells).
        assert_eq!((b.water_cells, b.water_detected), (3, 2));
        let r = evaluate(&map, &truth, &info).unwrap();
        assert_eq!(
            (r.bins[1].range.as_str(), r.bins[1].seen_water_cells),
            ("5-10", 2)
        );
        assert_eq!(r.bins[2].seen_water_detected, 6);
        assert_eq!((r.all.seen_water_cells, r.all.seen_water_detected), (12, 8));
    }

    #[test]
    fn without_seen_water_seen_recall_is_the_observed_recall() {
        let (map, truth, info) = two_resolutions(false);
        let r = evaluate(&map, &truth, &info).unwrap();
        let mut bins = r.bins.clone();
        bins.push(r.all.clone());
        bins.extend(evaluate_matrix_bands(&map, &truth, &info, None).unwrap());
        for b in &bins {
            assert_eq!(b.seen_water_cells, b.water_cells, "{}", b.range);
            assert_eq!(b.seen_water_detected, b.water_detected, "{}", b.range);
            assert_eq!(b.seen_recall, b.water_recall, "{}", b.range);
        }
        assert_eq!(r.all.seen_recall, Some(2.0 / 3.0));
    }

    #[test]
    fn matrix_bands_are_the_three_bands_and_their_union() {
        let (map, truth, info) = two_resolutions(true);
        let m = evaluate_matrix_bands(&map, &truth, &info, None).unwrap();
        let names: Vec<_> = m.iter().map(|b| b.range.as_str()).collect();
        assert_eq!(names, ["5-10", "10-20", "20-30", "5-30"]);
        for (b, &(lo, hi)) in m.iter().zip(&MATRIX_BANDS) {
            assert_eq!(*b, evaluate_band(&map, &truth, &info, lo, hi).unwrap());
        }
        let sum = |f: fn(&BinMetrics) -> usize| m[..3].iter().map(f).sum::<usize>();
        let u = &m[3];
        assert_eq!(u.observed_cells, sum(|b| b.observed_cells));
        assert_eq!(u.seen_water_cells, sum(|b| b.seen_water_cells));
        assert_eq!(u.seen_water_detected, sum(|b| b.seen_water_detected));
        assert_eq!(u.dry_offshore_cells, sum(|b| b.dry_offshore_cells));
        assert_eq!(u.called_water, sum(|b| b.called_water));
        assert_eq!((u.seen_water_cells, u.seen_water_detected), (12, 8));
    }

    /// A random case: truth of 0.5 m cells (12 × 6) with random water, a map at 0.25, 0.5
    /// or 1 m over and around it (random cells, classes and z in quarter metres, so that
    /// sums of squares are exact in any order), random seen water, a random path; and the
    /// map's cells in a shuffled order.
    fn case() -> impl Strategy<Value = (HazardMap, TruthInfo, HazardMap, HazardMap)> {
        (
            prop::collection::vec(any::<bool>(), 72),
            prop::option::of(prop::collection::vec((-1i64..14, -1i64..8), 0..30)),
            prop_oneof![Just(0.25), Just(0.5), Just(1.0)],
            prop::collection::vec(prop::option::of((any::<bool>(), -8i8..8)), 32 * 20),
            prop::collection::vec((-40i8..60, -40i8..40), 1..4),
        )
            .prop_flat_map(|(water, seen, mres, cells, path)| {
                let truth = raster(0.5, 12, 6, |kx, ky| water[(ky * 12 + kx) as usize]);
                let seen = seen.map(|v| v.into_iter().map(|(x, y)| [x, y]).collect());
                let path: Vec<[f64; 2]> = path
                    .iter()
                    .map(|&(x, y)| [x as f64 / 4.0, y as f64 / 4.0])
                    .collect();
                let info = info(0.5, &path, seen);
                // Keys over -1 .. 7 m × -1 .. 4 m at the map's resolution.
                let (w, h) = ((8.0 / mres) as i64, (5.0 / mres) as i64);
                let cells: Vec<MapCell> = (0..w * h)
                    .filter_map(|i| {
                        let (called, z) = cells[i as usize]?;
                        let class = if called { Class::Water } else { Class::Ground };
                        let mut c = cell(
                            mres,
                            i % w - (1.0 / mres) as i64,
                            i / w - (1.0 / mres) as i64,
                            class,
                        );
                        c.z = z as f64 / 4.0;
                        Some(c)
                    })
                    .collect();
                let map = HazardMap::new(mres, cells.clone());
                let shuffled = Just(cells)
                    .prop_shuffle()
                    .prop_map(move |c| HazardMap::new(mres, c));
                (Just(truth), Just(info), Just(map), shuffled)
            })
    }

    proptest! {
        #[test]
        fn new_rates_are_rates_and_ignore_the_map_order((truth, info, map, shuffled) in case()) {
            let r = evaluate(&map, &truth, &info).unwrap();
            let m = evaluate_matrix_bands(&map, &truth, &info, None).unwrap();
            for b in r.bins.iter().chain([&r.all]).chain(&m) {
                for v in [b.seen_recall, b.false_rate_offshore, b.precision].into_iter().flatten() {
                    prop_assert!((0.0..=1.0).contains(&v), "{b:?}");
                }
                prop_assert!(b.seen_water_detected <= b.seen_water_cells);
                prop_assert!(b.false_water_offshore <= b.dry_offshore_cells);
                prop_assert!(b.dry_offshore_cells <= b.dry_cells);
                prop_assert!(b.called_true <= b.called_water);
            }
            // Off shore by brute force: every water centre farther than the margin.
            let water: Vec<&MapCell> = truth.cells.iter().filter(|c| c.class == Class::Water).collect();
            let offshore = map.cells.iter().filter(|c| {
                let k = CellKey::new((c.x / 0.5).floor() as i64, (c.y / 0.5).floor() as i64);
                truth.cells.iter().find(|t| t.key == k).is_some_and(|t| {
                    t.class != Class::Water
                        && water.iter().all(|w| (w.x - t.x).hypot(w.y - t.y) > SHORE_MARGIN_M)
                })
            });
            prop_assert_eq!(r.all.dry_offshore_cells, offshore.count());
            prop_assert_eq!(&evaluate(&shuffled, &truth, &info).unwrap(), &r);
            prop_assert_eq!(&evaluate_matrix_bands(&shuffled, &truth, &info, None).unwrap(), &m);
        }
    }

    #[test]
    fn obstacles_are_scored_against_the_true_terrain_and_objects() {
        // 0.25 m cells, 40 × 5: ground at 0 up to key 19, a 0.5 m step up from key 20 on
        // (beyond the 0.25 m limit); key 35 is an object (truth hazard obstacle); key 30
        // is water. The mapper's rule makes 20 (the upper side) a step: the true obstacles
        // are keys 20 and 35.
        let mut truth = raster(0.25, 40, 5, |kx, _| kx == 30);
        for c in &mut truth.cells {
            if c.key.x >= 20 {
                c.z = 0.5;
            }
            if c.key.x == 35 {
                c.class = Class::Obstacle;
                c.hazard = Hazard::Obstacle;
            }
        }
        let true_keys = [20, 35];
        // The map calls the step's upper side (20) and a flat cell (5) obstacles.
        let mut map = truth.clone();
        for c in &mut map.cells {
            c.class = Class::Ground;
            c.hazard = if c.key.x == 20 || c.key.x == 5 {
                Hazard::Obstacle
            } else {
                Hazard::Free
            };
        }
        let r = evaluate(&map, &truth, &info(0.25, &[[0.0, 0.625]], None)).unwrap();
        let a = &r.all;
        assert_eq!(a.obstacle_cells, true_keys.len() * 5);
        assert_eq!((a.obstacle_detected, a.obstacle_recall), (5, Some(0.5)));
        assert_eq!((a.called_obstacle, a.false_obstacle), (10, 5));
        assert_eq!(a.obstacle_precision, Some(0.5));
        // By range: key 5 (1.375 m) in 0-5, keys 20, 35 (5.125, 8.875 m) in 5-10.
        assert_eq!((r.bins[0].obstacle_cells, r.bins[0].false_obstacle), (0, 5));
        assert_eq!(
            (r.bins[1].obstacle_cells, r.bins[1].obstacle_detected),
            (10, 5)
        );
        assert_eq!(r.bins[1].obstacle_precision, Some(1.0));
        // A noisy flat map of a flat truth has no true obstacle and scores none.
        let flat = raster(0.25, 40, 5, |_, _| false);
        let r = evaluate(&flat, &flat, &info(0.25, &[[0.0, 0.625]], None)).unwrap();
        assert_eq!((r.all.obstacle_cells, r.all.called_obstacle), (0, 0));
        assert_eq!(
            (r.all.obstacle_recall, r.all.obstacle_precision),
            (None, None)
        );
        assert_eq!(r.obstacle_limits, ObstacleLimits::default());
    }

    #[test]
    fn bin_names() {
        let n: Vec<_> = (0..5).map(bin_name).collect();
        assert_eq!(n, ["0-5", "5-10", "10-20", "20-30", "30+"]);
    }
}
