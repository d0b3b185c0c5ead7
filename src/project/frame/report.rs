//! What the label stage contributed, per sensor and frame and summed over a log.

use serde::{Deserialize, Serialize};

use crate::grid::{FalseAlarms, LabelFalseAlarms};

/// What one sensor contributed in one frame (or, summed, over a log).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SensorLabelStats {
    /// Frames the sensor was used in.
    pub frames: u64,
    /// Configured but not usable in a frame (no image, camera info or pose).
    pub frames_skipped: u64,
    /// Pixels labelled water.
    pub pixels_water: u64,
    /// Pixels labelled other or snow/ice.
    pub pixels_not_water: u64,
    /// Pixels placed through a stereo point.
    pub via_point: u64,
    /// Pixels placed by a ray march through the map.
    pub via_ray: u64,
    /// Pixels not placed (the ray met nothing).
    pub no_hit: u64,
    /// Per-frame cell votes for water.
    pub cells_water: u64,
    /// Per-frame cell votes for dry.
    pub cells_dry: u64,
    /// Colour water pixels brighter than a reflection of the sky could be
    /// ([`reflection_check`](super::reflection_check)).
    pub reflection_vetoed: u64,
    /// Water pixels whose ray crossed a hole in the map beyond the lidar's dry reach
    /// ([`crate::cues::DryReach`]): a hole that range alone explains places no vote.
    pub beyond_reach: u64,
    /// Colour water pixels whose colour the log's lidar finds on dry ground
    /// (`ColourCheck`): no vote.
    pub colour_check_vetoed: u64,
    /// Of the dry ground the log's lidar sampled in the image, the samples whose
    /// pixel was labelled, and those labelled water (`ColourCheck`): the labels' measured
    /// false-alarm rate.
    #[serde(default)]
    pub false_alarms: FalseAlarms,
    /// Water cell votes dropped because the other camera (colour or SWIR) voted not water
    /// in the same cell and frame (the cross-spectral check).
    #[serde(default)]
    pub cross_vetoed: u64,
    /// MWIR frames skipped for want of a local solar hour (no hour given, no longitude).
    #[serde(default)]
    pub frames_no_hour: u64,
    /// MWIR frames whose solar hour came from their stamp and the longitude.
    #[serde(default)]
    pub frames_hour_from_stamp: u64,
}

impl SensorLabelStats {
    /// Adds another frame's counts.
    pub fn merge(&mut self, o: &SensorLabelStats) {
        self.frames += o.frames;
        self.frames_skipped += o.frames_skipped;
        self.pixels_water += o.pixels_water;
        self.pixels_not_water += o.pixels_not_water;
        self.via_point += o.via_point;
        self.via_ray += o.via_ray;
        self.no_hit += o.no_hit;
        self.cells_water += o.cells_water;
        self.cells_dry += o.cells_dry;
        self.reflection_vetoed += o.reflection_vetoed;
        self.beyond_reach += o.beyond_reach;
        self.colour_check_vetoed += o.colour_check_vetoed;
        self.false_alarms.merge(&o.false_alarms);
        self.cross_vetoed += o.cross_vetoed;
        self.frames_no_hour += o.frames_no_hour;
        self.frames_hour_from_stamp += o.frames_hour_from_stamp;
    }
}

/// What one frame contributed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameLabelsReport {
    /// What the colour camera contributed (`None`: not configured).
    pub colour: Option<SensorLabelStats>,
    /// What the SWIR camera contributed (`None`: not configured).
    pub swir: Option<SensorLabelStats>,
    /// What the MWIR camera contributed (`None`: not configured).
    pub mwir: Option<SensorLabelStats>,
    /// The earliest and latest local solar hour the MWIR images were classified at.
    #[serde(default)]
    pub mwir_hours: Option<[f64; 2]>,
    /// Cell votes that fell outside the window (dropped).
    pub dropped: u64,
}

impl FrameLabelsReport {
    /// The colour and SWIR labels' false alarms the frame (or log) measured.
    pub fn false_alarms(&self) -> LabelFalseAlarms {
        let of = |s: &Option<SensorLabelStats>| s.map(|s| s.false_alarms).unwrap_or_default();
        LabelFalseAlarms {
            colour: of(&self.colour),
            swir: of(&self.swir),
        }
    }

    /// Adds another frame's counts, sensor by sensor.
    pub fn merge(&mut self, o: &FrameLabelsReport) {
        for (a, b) in [
            (&mut self.colour, &o.colour),
            (&mut self.swir, &o.swir),
            (&mut self.mwir, &o.mwir),
        ] {
            if let Some(b) = b {
                a.get_or_insert_with(Default::default).merge(b);
            }
        }
        if let Some([lo, hi]) = o.mwir_hours {
            let h = self.mwir_hours.get_or_insert([lo, hi]);
            *h = [h[0].min(lo), h[1].max(hi)];
        }
        self.dropped += o.dropped;
    }
}
