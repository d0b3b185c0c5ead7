//! `report.json` of a log build, and the parts it is made of.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::grid::IngestStats;
use crate::hazard::HazardMap;
use crate::mapper::StageTimes;

use super::*;

/// `report.json` of a build from a ROS 2 log.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LogBuildReport {
    /// Version of tarn that wrote the report.
    pub tarn_version: String,
    /// The log read.
    pub input: PathBuf,
    /// The output directory.
    pub output: PathBuf,
    /// Cell side, metres.
    pub resolution_m: f64,
    /// Side of the rolling window, cells.
    pub window_cells: usize,
    /// Topic whose messages made frames.
    pub frame_topic: String,
    /// Frames fused into the map.
    pub frames_fused: u64,
    /// Log duration, seconds.
    pub log_duration_s: f64,
    /// Log duration over build time (offline speed).
    pub x_realtime: f64,
    /// Whether the window's hazard map was published after every frame
    /// ([`BuildOptions::per_frame_maps`]); the `water` stage's latency is zero otherwise.
    #[serde(default)]
    pub per_frame_maps: bool,
    /// The cues that ran (`lidar`, `reflectivity`, `stereo`, `mirror`).
    pub cues: Vec<String>,
    /// The lidar height the cue model used (given, or estimated from the first scans).
    pub lidar_height_m: Option<f64>,
    /// The lidar cues' no-return diagnostic interval (lookahead, m).
    pub diagnostic_interval_m: Option<(f64, f64)>,
    /// Every sensor value the mapper used, its source (log, config or rig file, measured,
    /// default), the measurement beside any stated value, the cues that waited for a value
    /// and the stated values the log contradicts ([`crate::calib`]).
    #[serde(default)]
    pub calibration: crate::calib::CalibrationReport,
    /// The fusion rule the map was built with: the config's, the colour and SWIR labels'
    /// false-alarm rates measured from the log where its lidar sampled dry ground
    /// (`labels.colour.false_alarms`, `labels.swir.false_alarms`,
    /// [`crate::grid::Fusion::measured`]).
    #[serde(default)]
    pub fusion: crate::grid::Fusion,
    /// What happened to the lidar points, summed over frames.
    pub lidar_points: IngestStats,
    /// What happened to the stereo points, summed over frames.
    pub stereo_points: IngestStats,
    /// What the cues found, summed over frames.
    pub cue_counts: CueCounts,
    /// What the frame stream read, built and skipped.
    pub frames: crate::frames::FrameStats,
    /// Messages or frames that could not be used, with where and why.
    pub errors: Vec<String>,
    /// What the build noticed but went on past: what the plausibility checks dropped from
    /// frames that were fused, one line per kind with the frames it happened in (the
    /// first [`MAX_WARNINGS`] kinds), then the build's own.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Lidar and stereo points beyond their sensor's `max_range_m`, dropped.
    #[serde(default)]
    pub points_beyond_max_range: BeyondRange,
    /// The damaged parts of the log, skipped: exact byte ranges, what was wrong, and the
    /// log times they held. Empty for an undamaged log; a map built from a damaged log
    /// holds everything else.
    #[serde(default)]
    pub damaged: Vec<crate::mcap_log::DamagedRange>,
    /// What the image labels contributed (`None`: not configured).
    #[serde(default)]
    pub labels: Option<crate::project::FrameLabelsReport>,
    /// Observed cells of the map.
    pub cells_observed: usize,
    /// Tiles of the global map.
    pub tiles: usize,
    /// Lowest and highest cell elevation, map z in metres; `None` for an empty map.
    pub elevation_range_m: Option<(f64, f64)>,
    /// What the map holds: water cells, area, depths, hazards.
    pub water: WaterSummary,
    /// The outputs written beside the contract's files (`map.mcap`, `map.tif`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub extra_outputs: Vec<String>,
    /// Wall time of each step, seconds.
    pub timings_s: Timings,
    /// Sum over frames of each stage of [`crate::mapper::Mapper::update`] (s).
    pub stage_totals_s: StageTimes,
    /// Per-frame latency of each stage (ms).
    pub stage_latency_ms: Vec<StageLatency>,
}

/// Warnings kept in a log build's report.
pub const MAX_WARNINGS: usize = 100;

/// Points dropped as beyond their sensor's maximum range.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct BeyondRange {
    /// Lidar points dropped.
    pub lidar: u64,
    /// Stereo points dropped.
    pub stereo: u64,
}

/// Cue events summed over a build.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CueCounts {
    /// Missing lidar beams meeting the ground inside the diagnostic interval.
    pub lidar_noret: u64,
    /// Nearest and farthest lookahead of the no-return beams' ground hits (mm).
    pub lidar_noret_lookahead_mm: Option<[u64; 2]>,
    /// Lidar ground returns inside the diagnostic interval.
    pub lidar_diag_ret: u64,
    /// Lidar returns from under the water surface (bottom returns, their depth kept as evidence).
    pub lidar_bottom: u64,
    /// Lidar returns mirrored by the water surface: reflection evidence, left out of the terrain.
    pub lidar_specular: u64,
    /// Lidar returns below the walked level that the scan saw nothing above: ground below
    /// the level (a depression's far bank), kept in the terrain.
    #[serde(default)]
    pub lidar_below_ground: u64,
    /// Lidar ground returns darker than the scan's dark threshold (reflectivity cue).
    pub lidar_dark: u64,
    /// Stereo reflection runs confirmed.
    pub stereo_runs: u64,
    /// Stereo points found to be reflections.
    pub stereo_reflected_points: u64,
    /// Evidence cells merged into the window.
    pub evidence_cells: u64,
    /// Evidence cells dropped outside the window.
    pub evidence_dropped: u64,
}

impl CueCounts {
    pub(super) fn add(&mut self, r: &crate::cues::FrameCuesReport) {
        if let Some(l) = &r.lidar {
            self.lidar_noret += l.noret;
            if let Some([lo, hi]) = l.noret_lookahead_mm {
                let [a, b] = self.lidar_noret_lookahead_mm.unwrap_or([lo, hi]);
                self.lidar_noret_lookahead_mm = Some([a.min(lo), b.max(hi)]);
            }
            self.lidar_diag_ret += l.diag_ret;
            self.lidar_bottom += l.bottom;
            self.lidar_specular += l.specular;
            self.lidar_below_ground += l.below_ground;
            self.lidar_dark += l.dark;
        }
        self.stereo_runs += r.stereo_runs as u64;
        self.stereo_reflected_points += r.stereo_reflected_points as u64;
        self.evidence_cells += r.evidence_cells as u64;
        self.evidence_dropped += r.evidence_dropped as u64;
    }
}

/// Cells per hazard code of `map.ply` (0 to 3).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct HazardCells {
    /// Free to drive (0).
    pub free: usize,
    /// Shallow water within fording depth (1).
    pub shallow_water: usize,
    /// Deep or unknown-depth water (2).
    pub deep_water: usize,
    /// A geometric obstacle (3).
    pub obstacle: usize,
}

/// The water in a hazard map.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct WaterSummary {
    /// Cells classified water.
    pub water_cells: usize,
    /// Area of the water cells, square metres.
    pub water_area_m2: f64,
    /// Water cells with a measured depth, and their depths.
    pub depth_cells: usize,
    /// Mean depth of those cells, metres; `None` when no depth was measured.
    pub depth_mean_m: Option<f64>,
    /// Greatest depth of those cells, metres; `None` when no depth was measured.
    pub depth_max_m: Option<f64>,
    /// Cells per hazard code.
    pub hazard_cells: HazardCells,
    /// Cells with any water evidence (probability above the prior).
    pub cells_with_evidence: usize,
    /// The water bodies ([`crate::water::WaterBody::report`]): area, volume, depth, the
    /// surface model and the residuals that chose it.
    #[serde(default)]
    pub bodies: serde_json::Value,
}

impl WaterSummary {
    /// Summarises `map`; `fusion` gives the prior above which a cell counts as having evidence.
    pub fn of(map: &HazardMap, fusion: &crate::grid::Fusion) -> Self {
        use crate::hazard::Class;
        let mut s = WaterSummary {
            bodies: map.water_report(),
            ..Default::default()
        };
        let mut depths = Vec::new();
        for c in &map.cells {
            let h = &mut s.hazard_cells;
            *match c.hazard {
                crate::hazard::Hazard::Free => &mut h.free,
                crate::hazard::Hazard::ShallowWater => &mut h.shallow_water,
                crate::hazard::Hazard::DeepWater => &mut h.deep_water,
                crate::hazard::Hazard::Obstacle => &mut h.obstacle,
            } += 1;
            if c.water as f64 > fusion.prior + 1e-6 {
                s.cells_with_evidence += 1;
            }
            if c.class == Class::Water {
                s.water_cells += 1;
                if c.depth.is_finite() {
                    depths.push(c.depth as f64);
                }
            }
        }
        s.water_area_m2 = s.water_cells as f64 * map.resolution * map.resolution;
        s.depth_cells = depths.len();
        if !depths.is_empty() {
            s.depth_mean_m = Some(depths.iter().sum::<f64>() / depths.len() as f64);
            s.depth_max_m = depths.iter().copied().reduce(f64::max);
        }
        s
    }
}

/// Median, 95th percentile and maximum of one stage's per-frame time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageLatency {
    /// Stage name, one of [`StageTimes::NAMES`].
    pub stage: String,
    /// Median per-frame time, milliseconds.
    pub median_ms: f64,
    /// 95th percentile (nearest rank), milliseconds.
    pub p95_ms: f64,
    /// Largest per-frame time, milliseconds.
    pub max_ms: f64,
}

/// Latency statistics per stage of a sequence of per-frame stage times (nearest-rank
/// percentiles).
pub fn stage_latency(times: &[StageTimes]) -> Vec<StageLatency> {
    StageTimes::NAMES
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let mut v: Vec<f64> = times.iter().map(|t| t.values()[k] * 1e3).collect();
            v.sort_by(f64::total_cmp);
            let rank = |q: f64| {
                if v.is_empty() {
                    0.0
                } else {
                    v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1]
                }
            };
            StageLatency {
                stage: name.to_string(),
                median_ms: rank(0.5),
                p95_ms: rank(0.95),
                max_ms: v.last().copied().unwrap_or(0.0),
            }
        })
        .collect()
}
