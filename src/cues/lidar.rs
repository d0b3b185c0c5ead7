//! Lidar water cues (paper section 3): no-return regions inside the optics' diagnostic
//! interval, refraction-corrected bottom returns, specular returns from beyond the water,
//! and the reflectivity drop of wet ground.
//!
//! Each scan line (a column of a spinning lidar from the steepest ring out, or the row of a
//! single-row vertical scanner ordered by beam elevation) is walked in the order of
//! increasing lookahead, keeping the *local ground level*: the last return within
//! `below_gate_m`/`above_gate_m` of the ground expected there, starting from the sensor
//! height. The expected ground continues the level with the slope of the last ground
//! returns when it falls (least squares over 3 m, clamped to `max_ground_slope`): a
//! vehicle on a 3 % slope sees the ground behind it fall 0.8 m over 27 m, which a flat
//! level took for the bottom of water.
//! The water cues below still use the flat level: water lies level. Then:
//!
//! * a **missing** beam is cast against the level; if it meets it at a lookahead inside
//!   [`LidarCueModel::interval`] (the optics' diagnostic interval for water at least
//!   `min_depth_m` deep, for this sensor's height, wavelength and water clarity) the cell
//!   it meets gets a no-return count; outside the interval a missing return says nothing;
//! * a **ground** return inside the interval counts as a diagnostic beam that returned;
//! * a return **below** the level (by three standard deviations of the line's ground: the
//!   range noise and the spread its last ground returns showed, at most `below_gate_m`) is
//!   corrected for refraction and the speed of light
//!   ([`crate::optics::LidarWaterModel::correct_bottom_return`]); if the
//!   corrected depth is one the optics say this sensor can see at that lookahead, it is a
//!   bottom return (a depth sample for the corrected point's cell, with its gain
//!   d(depth)/d(level), so that the water stage can move the depth onto the water surface
//!   it finds: the level here is the last ground the scan line walked, which on a bank
//!   that falls to the water is the bank, not the water); otherwise it cannot
//!   come from the bottom and is a specular return from beyond the water: the cell where
//!   its ray crosses the level gets reflection evidence, and the point is left out of the
//!   terrain. Mirrored about the walked level it would land where the object is only if
//!   the water lay at that level; below a bank it lands too high by twice the bank's
//!   height over the water (0.7 m on a bank 0.35 m above a pond), a raised row of cells
//!   as consistent as real ground, and an object to the step test. The object is seen
//!   directly by other beams. Where the scan line's higher beams instead pass through the
//!   space above the return empty, there is no object to mirror: the return is ground
//!   below the level (the far bank of a depression), kept in the terrain
//!   (`mirror_refuted`).

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{CueRun, EvidenceMap};
use crate::error::{Error, Result};
use crate::geom::PointCloud;

mod beams;
mod below;
mod bright;
mod model;
mod reach;
mod tally;
mod walk;

pub use beams::{beam_directions, estimate_sensor_height};
pub use model::LidarCueModel;
pub use reach::DryReach;

use beams::{beam_directions_into, scan_lines};
use tally::Tally;
use walk::Event;

/// Where the directions of missing beams come from.
#[derive(Debug, Clone, PartialEq)]
pub enum BeamModel {
    /// Inferred from the organized scan itself: the direction of a missing slot is
    /// interpolated (azimuth and elevation, linearly in column index) between the nearest
    /// valid slots of its row, across at most `max_gap_fraction` of the row (cyclic for a
    /// multi-row spinning scan). Slots with no valid neighbour on both sides say nothing.
    /// A single-column scan (a vertical scanner published one beam per row) has no row
    /// neighbours: its beams are evenly spaced in elevation, so the elevation of every row
    /// is the least-squares line through the valid rows (when they fit it within 0.1°),
    /// which also reaches the missing beams past the last return, over water.
    Infer {
        /// Widest gap interpolated across, as a fraction of a row's slots (≥ 0).
        max_gap_fraction: f64,
    },
    /// A spinning lidar: elevation per row (rad) and azimuth of column `c`
    /// `azimuth0_rad ∓ 2π c / cols` (minus when `clockwise`).
    Spinning {
        /// Elevation of each row's beam, radians.
        elevations_rad: Vec<f64>,
        /// Azimuth of column 0, radians.
        azimuth0_rad: f64,
        /// Whether the azimuth decreases with the column.
        clockwise: bool,
    },
    /// One direction per slot (row-major), in the cloud's frame; need not be unit length.
    Directions(Vec<[f32; 3]>),
}

impl Default for BeamModel {
    fn default() -> Self {
        BeamModel::Infer {
            max_gap_fraction: 0.25,
        }
    }
}

/// Gates and thresholds of the lidar cues.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LidarCueConfig {
    /// Shallowest water whose missing returns are to be diagnostic (m); 0 gives the
    /// interval from the zero-depth cutoff to the dry-ground limit.
    pub min_depth_m: f64,
    /// A return more than this below the local ground level is always a below-level
    /// return (m); one less deep is when it lies more than three standard deviations of
    /// the scan line's ground below the level ([`LidarCueModel::with_range_noise`]).
    pub below_gate_m: f64,
    /// A return more than this above the local ground level is not ground (vegetation,
    /// obstacles); it neither moves the level nor counts as a diagnostic return (m).
    pub above_gate_m: f64,
    /// Slack on the optics' greatest visible depth when telling bottom from specular (m).
    pub depth_tolerance_m: f64,
    /// A below-level return too deep for a bottom return is taken as specular only when
    /// at least this far below the level (m): the mirror image of an object, not rough
    /// ground or vegetation dipping under the last ground return. Shallower ones are
    /// counted as unexplained and give no evidence.
    pub specular_min_depth_m: f64,
    /// Steepest ground slope (rise over run) the local ground level follows along a scan
    /// line. A falling level is extrapolated with the least-squares slope of the last 3 m
    /// of ground returns, clamped to this, so dry ground falling away gently (a road
    /// downhill) is not taken for the bottom of water; water lies level, so its bottom
    /// returns still fall below.
    pub max_ground_slope: f64,
    /// The scan's own dry limit: a missing beam is no-return evidence only where dry
    /// ground along its scan line (its azimuth) returned from at least as far. Smooth or dark ground stops returning long before the configured
    /// sensitivity says (pavement at grazing incidence), and there a missing return says
    /// nothing about water. Off: the optics' interval alone.
    pub scan_dry_limit: bool,
    /// Read by the mapper: every this many frames, the window's water bodies become the
    /// prior the lidar cue reads in the frames that follow ([`WaterPrior`](super::prior::WaterPrior)); 0: no prior.
    pub prior_every_frames: u32,
    /// How far beyond its bodies' cells the prior carries their level (m).
    pub prior_reach_m: f64,
}

impl Default for LidarCueConfig {
    fn default() -> Self {
        LidarCueConfig {
            min_depth_m: 0.0,
            below_gate_m: 0.10,
            above_gate_m: 0.30,
            depth_tolerance_m: 0.05,
            specular_min_depth_m: 0.5,
            max_ground_slope: 0.08,
            scan_dry_limit: true,
            prior_every_frames: 0,
            prior_reach_m: 1.0,
        }
    }
}

impl LidarCueConfig {
    /// Checks that every depth, gate, tolerance and slope is finite and non-negative; the
    /// error names the first that is not.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("min_depth_m", self.min_depth_m),
            ("below_gate_m", self.below_gate_m),
            ("above_gate_m", self.above_gate_m),
            ("depth_tolerance_m", self.depth_tolerance_m),
            ("specular_min_depth_m", self.specular_min_depth_m),
            ("max_ground_slope", self.max_ground_slope),
            ("prior_reach_m", self.prior_reach_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(
                    format!("lidar cue {name}"),
                    format!("{v} is not a finite number ≥ 0"),
                ));
            }
        }
        Ok(())
    }
}

/// Counts of what the lidar cues saw in one scan.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct LidarCueStats {
    /// Point slots of the scan, missing returns included.
    pub slots: u64,
    /// Slots without a return.
    pub missing: u64,
    /// Missing slots whose direction could not be known (no model, no neighbours).
    pub no_direction: u64,
    /// Missing beams that meet the ground level at all.
    pub missing_cast: u64,
    /// Missing beams meeting the ground inside the diagnostic interval.
    pub noret: u64,
    /// Nearest and farthest lookahead of those beams' ground hits (mm): they lie inside the
    /// interval by construction, and this shows where in it.
    pub noret_lookahead_mm: Option<[u64; 2]>,
    /// Ground returns inside the diagnostic interval.
    pub diag_ret: u64,
    /// Missing beams inside the interval but farther than dry ground along their scan line
    /// returned from ([`LidarCueConfig::scan_dry_limit`]): no evidence.
    pub noret_beyond_dry: u64,
    /// Returns from under the water surface, refraction-corrected into bottom evidence.
    pub bottom: u64,
    /// Of `bottom`, those found under the water level of the prior ([`WaterPrior`](super::prior::WaterPrior)).
    pub bottom_under_prior: u64,
    /// Returns mirrored by the water surface, put back where the object is.
    pub specular: u64,
    /// Below-level returns neither bottom nor deep enough to be specular.
    pub unexplained: u64,
    /// Below-level returns too deep for a bottom return whose mirror image the scan line's
    /// own beams saw empty space at: ground below the walked level (a depression's far
    /// bank), kept in the terrain rather than taken as specular.
    #[serde(default)]
    pub below_ground: u64,
    /// Ground returns darker than the scan's threshold (reflectivity cue).
    pub dark: u64,
    /// Ground returns tested for reflectivity and not dark.
    pub lit: u64,
}

/// The output of [`LidarCueModel::run`].
#[derive(Debug, Clone)]
pub struct LidarCues {
    /// Water evidence of the scan, by cell.
    pub evidence: EvidenceMap,
    /// The input cloud with specular and bottom returns removed (NaN: their reflection and
    /// depth are in the evidence), ready to be fused into the elevation map instead of the
    /// raw cloud.
    pub corrected: PointCloud,
    /// What the cues saw.
    pub stats: LidarCueStats,
    /// The scan's dark threshold (the `dark_quantile` of its ground returns' residuals from
    /// the channel's fitted law, natural log) when the reflectivity cue ran.
    pub reflectivity_threshold: Option<f64>,
    /// The channel's law fitted to this scan's ground returns, when the reflectivity cue
    /// ran.
    pub reflectivity_law: Option<super::reflectivity::ChannelLaw>,
    /// What the scan says of the surface, for the image labels that follow.
    pub surface: ScanSurface,
}

/// Storage of [`LidarCueModel::run`] kept from scan to scan: the beam directions, and
/// the evidence map and corrected cloud of a run once given back
/// ([`LidarBuffers::recycle`]).
#[derive(Debug, Clone, Default)]
pub struct LidarBuffers {
    dirs: Vec<Option<Vector3<f64>>>,
    evidence: Option<EvidenceMap>,
    corrected: Option<PointCloud>,
}

impl LidarBuffers {
    /// Keeps a used run's evidence map and corrected cloud for the next run's.
    pub fn recycle(&mut self, evidence: EvidenceMap, corrected: PointCloud) {
        self.evidence = Some(evidence);
        self.corrected = Some(corrected);
    }
}

/// What a frame's range sensor says of the surface, for the image labels
/// ([`crate::project::FrameLabels`]): from a lidar scan, how far dry ground returned and
/// points (map frame) where it found dry ground or water; from stereo, what each element
/// says of the surface under its pixel.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ScanSurface {
    /// How far dry ground returned along each azimuth of this scan
    /// ([`LidarCueConfig::scan_dry_limit`]; `None` when that is off).
    pub reach: Option<DryReach>,
    /// Ground returns brighter than any water there allows (at the walked level, or at
    /// the depth below it they lie): returns no water could have given. (Inside the
    /// diagnostic interval water shallower than the least depth the interval is drawn for
    /// still returns, so a dim return there is not counted.)
    pub dry: Vec<Point3<f64>>,
    /// Where missing beams inside the interval (and short of the scan's dry limit) meet
    /// the ground level, and where bottom and specular returns' beams cross the water.
    pub wet: Vec<Point3<f64>>,
    /// What each element of the frame's stereo cloud says of the surface under its pixel
    /// ([`super::stereo::StereoCues::seen`]); empty without one.
    pub stereo: Vec<super::stereo::StereoSeen>,
}

impl LidarCueModel {
    /// Runs the cues on one organized scan, in the storage of earlier scans (`bufs`, which
    /// may be fresh; give a run's evidence map and corrected cloud back with
    /// [`LidarBuffers::recycle`] once used): the same result, without a scan's worth of
    /// fresh memory.
    ///
    /// Each scan line is walked on its own (in parallel); their
    /// events are then tallied in line order, the reflectivity cue reads the ground
    /// returns, and the lines' dry reach closes the scan's surface.
    pub fn run(
        &self,
        cloud: &PointCloud,
        run: &CueRun,
        bufs: &mut LidarBuffers,
    ) -> Result<LidarCues> {
        let CueRun {
            resolution,
            z_ref,
            surface_points,
            prior,
        } = *run;
        cloud.validate()?;
        self.check_beams_fit(cloud)?;
        beam_directions_into(cloud, &self.beams, &mut bufs.dirs);
        let dirs = &bufs.dirs;
        let lines = scan_lines(cloud, dirs);
        let o = cloud.sensor_origin_in_map();
        let level0 = o.z - self.optics.config().height_m;
        let walked: Vec<(Vec<Event>, f64)> = lines
            .par_iter()
            .map(|line| self.walk(cloud, dirs, line, o, level0, prior))
            .collect();

        let ev = match bufs.evidence.take() {
            Some(mut e) => {
                e.reset(resolution, z_ref);
                e
            }
            None => EvidenceMap::new(resolution, z_ref),
        };
        let corrected = match bufs.corrected.take() {
            Some(mut c) => {
                c.clone_from(cloud);
                c
            }
            None => cloud.clone(),
        };
        let mut tally = Tally::new(
            cloud,
            dirs,
            surface_points,
            self.reflectivity.is_some(),
            ev,
            corrected,
        );
        for (events, far) in &walked {
            // The scan's own dry limit per line: the farthest lookahead its dry ground
            // returned from (a vertical scanner's one line likewise).
            let limit = if self.cfg.scan_dry_limit {
                *far
            } else {
                f64::INFINITY
            };
            for e in events {
                tally.add(e, limit);
            }
        }
        let (reference, law) = tally.reflectivity(self.reflectivity.as_ref());
        tally.surface.reach = self.cfg.scan_dry_limit.then(|| {
            let az = lines.iter().map(|line| {
                line.iter()
                    .find_map(|&s| dirs[s as usize])
                    .map_or(f64::NAN, |u| u.y.atan2(u.x))
            });
            DryReach::new([o.x, o.y], az.zip(walked.iter().map(|w| w.1)))
        });
        Ok(tally.into_cues(reference, law))
    }

    /// Checks that an explicit beam model fits the scan: one direction per slot, one ring
    /// elevation per row.
    fn check_beams_fit(&self, cloud: &PointCloud) -> Result<()> {
        let n = cloud.len();
        if let BeamModel::Directions(d) = &self.beams {
            if d.len() != n {
                return Err(Error::invalid(
                    "beam model",
                    format!("{} directions for a scan of {n} slots", d.len()),
                ));
            }
        }
        if let BeamModel::Spinning { elevations_rad, .. } = &self.beams {
            if elevations_rad.len() != cloud.rows {
                return Err(Error::invalid(
                    "beam model",
                    format!(
                        "{} ring elevations for a scan of {} rows",
                        elevations_rad.len(),
                        cloud.rows
                    ),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
