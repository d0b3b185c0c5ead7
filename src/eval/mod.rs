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
//!   cells, not objects) the map does not call water.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::grid::CellKey;
use crate::hazard::{Class, HazardMap, MapCell};
use crate::sim::{ColourView, TruthInfo};

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
    /// Dry truth cells whose map z is more than [`SUNK_M`] below the true terrain.
    pub sunk_cells: usize,
}

/// How far below the true terrain a dry cell's map z must be to count as sunk (m).
pub const SUNK_M: f64 = 0.15;

#[derive(Debug, Clone, Default)]
struct Acc {
    m: BinMetrics,
    surface2: f64,
    depth2: f64,
    terrain2: f64,
}

impl Acc {
    fn add(&mut self, cell: &MapCell, truth: Option<&MapCell>) {
        self.m.observed_cells += 1;
        let Some(t) = truth else {
            self.m.outside_truth += 1;
            return;
        };
        let called = cell.class == Class::Water;
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
                self.terrain2 += (cell.z - t.z).powi(2);
            }
        }
    }

    fn finish(mut self) -> BinMetrics {
        let rms = |s: f64, n: usize| (n > 0).then(|| (s / n as f64).sqrt());
        self.m.water_recall = ratio(self.m.water_detected, self.m.water_cells);
        self.m.false_positive_rate = ratio(self.m.false_water, self.m.dry_cells);
        self.m.surface_rms_m = rms(self.surface2, self.m.surface_cells);
        self.m.depth_rms_m = rms(self.depth2, self.m.depth_cells);
        self.m.terrain_rms_m = rms(self.terrain2, self.m.terrain_cells);
        self.m
    }
}

fn ratio(a: usize, b: usize) -> Option<f64> {
    (b > 0).then(|| a as f64 / b as f64)
}

/// What `tarn eval` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    pub scene: String,
    pub map_resolution: f64,
    pub truth_resolution: f64,
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
    fn of(map: &HazardMap, index: &HashMap<CellKey, &MapCell>, res: f64, v: &ColourView) -> Self {
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

    /// A Markdown table of the bins (for READMEs).
    pub fn markdown(&self) -> String {
        let f = |v: Option<f64>, d: usize| v.map_or("–".to_string(), |v| format!("{v:.d$}"));
        let mut s = String::from(
            "| range (m) | observed | water | recall | dry | false-positive rate | surface RMS (m) | depth RMS (m) | terrain RMS (m) |\n\
             | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n",
        );
        for b in self.bins.iter().chain(std::iter::once(&self.all)) {
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                b.range,
                b.observed_cells,
                b.water_cells,
                f(b.water_recall, 3),
                b.dry_cells,
                f(b.false_positive_rate, 4),
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

/// Scores `map` against the truth raster and the trajectory of `info`.
pub fn evaluate(map: &HazardMap, truth: &HazardMap, info: &TruthInfo) -> Result<EvalReport> {
    if truth.resolution.is_nan() || truth.resolution <= 0.0 {
        return Err(Error::invalid(
            "truth",
            format!("resolution {} must be > 0", truth.resolution),
        ));
    }
    let res = truth.resolution;
    let index: HashMap<CellKey, &MapCell> = truth.cells.iter().map(|c| (c.key, c)).collect();
    let path: Vec<[f64; 2]> = info.trajectory.iter().map(|p| [p.x, p.y]).collect();
    let mut bins = vec![Acc::default(); BIN_EDGES.len() + 1];
    let mut all = Acc::default();
    for c in &map.cells {
        let key = CellKey::new((c.x / res).floor() as i64, (c.y / res).floor() as i64);
        let t = index.get(&key).copied();
        let d = distance_to_path(&path, c.x, c.y);
        let b = BIN_EDGES
            .iter()
            .position(|&e| d < e)
            .unwrap_or(BIN_EDGES.len());
        bins[b].add(c, t);
        all.add(c, t);
    }
    Ok(EvalReport {
        scene: info.scene.clone(),
        map_resolution: map.resolution,
        truth_resolution: res,
        bins: bins
            .into_iter()
            .enumerate()
            .map(|(i, a)| {
                let mut m = a.finish();
                m.range = bin_name(i);
                m
            })
            .collect(),
        all: {
            let mut m = all.finish();
            m.range = "all".into();
            m
        },
        colour_view: info
            .colour_view
            .as_ref()
            .map(|v| ColourViewRecall::of(map, &index, res, v)),
    })
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
    if truth.resolution.is_nan() || truth.resolution <= 0.0 {
        return Err(Error::invalid(
            "truth",
            format!("resolution {} must be > 0", truth.resolution),
        ));
    }
    if !(lo >= 0.0 && hi > lo) {
        return Err(Error::invalid(
            "range band",
            format!("{lo}-{hi} m must satisfy 0 ≤ lo < hi"),
        ));
    }
    let res = truth.resolution;
    let index: HashMap<CellKey, &MapCell> = truth.cells.iter().map(|c| (c.key, c)).collect();
    let path: Vec<[f64; 2]> = info.trajectory.iter().map(|p| [p.x, p.y]).collect();
    let mut acc = Acc::default();
    for c in &map.cells {
        let d = distance_to_path(&path, c.x, c.y);
        if d >= lo && d < hi {
            let key = CellKey::new((c.x / res).floor() as i64, (c.y / res).floor() as i64);
            acc.add(c, index.get(&key).copied());
        }
    }
    let mut m = acc.finish();
    m.range = format!("{lo}-{hi}");
    Ok(m)
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
        use crate::hazard::Hazard;
        use crate::sim::{TruthInfo, TruthPose};
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

    #[test]
    fn bin_names() {
        let n: Vec<_> = (0..5).map(bin_name).collect();
        assert_eq!(n, ["0-5", "5-10", "10-20", "20-30", "30+"]);
    }
}
