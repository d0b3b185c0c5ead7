//! What one update did: the cues' reports, ingest counts, calibration and stage times.

use serde::{Deserialize, Serialize};

use crate::calib::{CalibrationReport, Source};
use crate::cues::FrameCuesReport;
use crate::grid::{IngestStats, RangeNoise};

/// Wall time of each stage of one update, seconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StageTimes {
    /// Moving the window with the vehicle and handing cells that leave it to the global map.
    pub recentre: f64,
    /// Lidar cues and the ingest of the (corrected) scan.
    pub lidar: f64,
    /// Stereo reflections and the ingest of the (corrected) cloud.
    pub stereo: f64,
    /// Image labels: classification, projection and votes (0 when none is configured).
    pub labels: f64,
    /// The window's hazard map, published as the snapshot.
    pub water: f64,
    /// The whole update.
    pub total: f64,
}

impl StageTimes {
    /// Stage names, in the order of [`StageTimes::values`].
    pub const NAMES: [&'static str; 6] =
        ["recentre", "lidar", "stereo", "labels", "water", "total"];

    /// The stage times, in the order of [`StageTimes::NAMES`].
    pub fn values(&self) -> [f64; 6] {
        [
            self.recentre,
            self.lidar,
            self.stereo,
            self.labels,
            self.water,
            self.total,
        ]
    }

    /// Adds another update's times, stage by stage.
    pub fn add(&mut self, o: &StageTimes) {
        self.recentre += o.recentre;
        self.lidar += o.lidar;
        self.stereo += o.stereo;
        self.labels += o.labels;
        self.water += o.water;
        self.total += o.total;
    }
}

/// What one frame contributed.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FrameReport {
    /// Stamp of the frame, seconds.
    pub stamp: f64,
    /// Frames fused so far, this one included.
    pub frame_index: u64,
    /// Raw ingest of a scan or cloud whose cue did not run.
    pub lidar_ingest: Option<IngestStats>,
    /// Raw ingest of a stereo cloud whose cue did not run.
    pub stereo_ingest: Option<IngestStats>,
    /// What the cues did (their ingest of corrected clouds included).
    pub cues: FrameCuesReport,
    /// The lidar height used by the cue model (given or estimated), once known.
    pub lidar_height_m: Option<f64>,
    /// The stereo cloud's range noise and where its c came from (a frame with a stereo
    /// cloud).
    pub stereo_noise: Option<(RangeNoise, Source)>,
    /// Every sensor value used so far, its source, and what the log measured
    /// ([`crate::calib`]).
    pub calibration: CalibrationReport,
    /// Cells of the published snapshot.
    pub snapshot_cells: usize,
    /// Snapshot cells called water.
    pub snapshot_water_cells: usize,
    /// What the image labels contributed (`None`: not configured).
    pub labels: Option<crate::project::FrameLabelsReport>,
    /// Wall time of each stage of the update.
    pub times_s: StageTimes,
    /// Lidar and stereo points beyond their sensor's `max_range_m`, dropped.
    pub beyond_max_range: [u64; 2],
    /// What the plausibility checks dropped from this frame, with the values.
    pub warnings: Vec<String>,
}

impl FrameReport {
    /// Points of the frame's lidar scan offered to the grid (raw or corrected).
    pub fn lidar_points(&self) -> Option<&IngestStats> {
        self.cues
            .lidar_ingest
            .as_ref()
            .or(self.lidar_ingest.as_ref())
    }

    /// Points of the frame's stereo cloud offered to the grid (raw or corrected).
    pub fn stereo_points(&self) -> Option<&IngestStats> {
        self.cues
            .stereo_ingest
            .as_ref()
            .or(self.stereo_ingest.as_ref())
    }
}
