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
use crate::hazard::{Class, HazardMap, MapCell};
use crate::sim::{ColourView, TruthInfo};

pub mod rates;
mod score;
mod shore;
#[cfg(test)]
mod tests;

use score::Scorer;
use shore::Shore;

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

/// `a / b`, `None` when `b` is 0.
fn ratio(a: usize, b: usize) -> Option<f64> {
    (b > 0).then(|| a as f64 / b as f64)
}

/// The vehicle's limits that make true terrain an obstacle: the mapper's defaults
/// ([`crate::hazard::Vehicle`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ObstacleLimits {
    pub max_step_m: f64,
    pub max_slope_deg: f64,
}

impl Default for ObstacleLimits {
    fn default() -> Self {
        let v = crate::hazard::Vehicle::default();
        ObstacleLimits {
            max_step_m: v.max_step_m,
            max_slope_deg: v.max_slope_deg,
        }
    }
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
    let map = crate::io::read_map_ply(&map_dir.join("map.ply"))?;
    let truth = crate::io::read_map_ply(&truth_dir.join("truth.ply"))?;
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
