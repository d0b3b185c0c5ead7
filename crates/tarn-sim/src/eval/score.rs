//! Scoring itself: every observed map cell with its truth, accumulated into the metrics of
//! a range bin or band.

use super::shore::Shore;
use super::{
    distance_to_path, ratio, BinMetrics, KeyMap, KeySet, ObstacleLimits, Reliability,
    CONFIDENT_SIGMA_M, SUNK_M,
};
use crate::error::{Error, Result};
use crate::grid::CellKey;
use crate::hazard::{terrain_hazard, Class, Hazard, HazardMap, MapCell};
use crate::sim::TruthInfo;

/// The counts and sums of one bin or band, finished into its [`BinMetrics`].
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
    /// A lidar return of the log fell in the cell ([`lidar_cells`](super::lidar_cells)).
    lidar: bool,
    /// A truth cell within one map cell of the cell's centre is an obstacle.
    near_object: bool,
}

/// What every bin and band is scored from, computed once per map and truth.
pub(super) struct Scorer<'a> {
    /// Truth cells by key (at the truth's resolution).
    pub(super) index: KeyMap<&'a MapCell>,
    cells: Vec<Scored<'a>>,
    /// The seen true-water truth cells: distance of the centre to the path, whether the
    /// map calls the cell containing that centre water, and whether the colour camera saw
    /// the cell reflecting the sky. `None` without [`TruthInfo::seen_water`].
    seen: Option<Vec<(f64, bool, bool)>>,
}

impl<'a> Scorer<'a> {
    pub(super) fn new(map: &'a HazardMap, truth: &'a HazardMap, info: &TruthInfo) -> Result<Self> {
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
    pub(super) fn score(&self, keep: impl Fn(f64) -> bool) -> BinMetrics {
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
    pub(super) fn with_lidar(mut self, lidar: Option<&KeySet>) -> Self {
        if let Some(keys) = lidar {
            for s in &mut self.cells {
                s.lidar = keys.contains(&s.cell.key);
            }
        }
        self
    }

    /// The metrics of the band `[lo, hi)` m, named "lo-hi".
    pub(super) fn band(&self, lo: f64, hi: f64) -> BinMetrics {
        let mut m = self.score(|d| d >= lo && d < hi);
        m.range = format!("{lo}-{hi}");
        m
    }
}
