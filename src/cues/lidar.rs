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

use std::collections::VecDeque;

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::prior::WaterPrior;
use super::reflectivity::{normalised_reflectivity, ReflectivityConfig, ReflectivitySample};
use super::EvidenceMap;
use crate::error::{Error, Result};
use crate::geom::PointCloud;
use crate::grid::RangeNoise;
use crate::optics::{LidarModelConfig, LidarWaterModel};

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

/// Shortest run over which the local ground's slope is measured (m).
const SLOPE_BASELINE_M: f64 = 1.0;
/// The local ground's slope is that of the ground returns of this much lookahead (m).
const SLOPE_WINDOW_M: f64 = 3.0;

/// Least-squares line through (x, y) pairs: (mean x, mean y, slope dy/dx); `None` without
/// spread in x.
fn fit_line(pts: impl Iterator<Item = (f64, f64)> + Clone) -> Option<(f64, f64, f64)> {
    let n = pts.clone().count() as f64;
    let (mx, my) = pts
        .clone()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let (sxy, sxx) = pts.fold((0.0, 0.0), |(a, b), (x, y)| {
        (a + (x - mx) * (y - my), b + (x - mx) * (x - mx))
    });
    (sxx > 1e-12).then(|| (mx, my, sxy / sxx))
}

/// The ground returns of a scan line's last [`SLOPE_WINDOW_M`] with running sums, so that
/// their least-squares slope costs the same however many returns the window holds (the
/// steep rings of a 64-ring lidar put 20 returns within 3 m, and refitting them at every
/// return was most of the walk). Sums are of offsets from the first point, so that a map
/// kilometres from its origin, or a level far from zero, loses no precision to them.
#[derive(Debug)]
struct SlopeWindow {
    pts: VecDeque<(f64, f64)>,
    origin: (f64, f64),
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
}

impl SlopeWindow {
    fn new(first: (f64, f64)) -> SlopeWindow {
        SlopeWindow {
            pts: VecDeque::from([first]),
            origin: first,
            sx: 0.0,
            sy: 0.0,
            sxx: 0.0,
            sxy: 0.0,
        }
    }

    fn offset(&self, (x, y): (f64, f64)) -> (f64, f64) {
        (x - self.origin.0, y - self.origin.1)
    }

    /// Adds the return `p` = (lookahead, z), then drops the oldest while more than two
    /// remain and the oldest lies more than [`SLOPE_WINDOW_M`] behind `p`.
    fn push(&mut self, p: (f64, f64)) {
        let (x, y) = self.offset(p);
        (self.sx, self.sy, self.sxx, self.sxy) =
            (self.sx + x, self.sy + y, self.sxx + x * x, self.sxy + x * y);
        self.pts.push_back(p);
        while self.pts.len() > 2 && self.pts.front().is_some_and(|f| p.0 - f.0 > SLOPE_WINDOW_M) {
            if let Some(f) = self.pts.pop_front() {
                let (x, y) = self.offset(f);
                (self.sx, self.sy, self.sxx, self.sxy) =
                    (self.sx - x, self.sy - y, self.sxx - x * x, self.sxy - x * y);
            }
        }
    }

    /// The least-squares slope dy/dx of the window once it spans [`SLOPE_BASELINE_M`] of
    /// lookahead; `None` before, or without spread in x.
    fn slope(&self) -> Option<f64> {
        let (first, last) = (self.pts.front()?, self.pts.back()?);
        if last.0 - first.0 < SLOPE_BASELINE_M {
            return None;
        }
        let n = self.pts.len() as f64;
        let sxx = self.sxx - self.sx * self.sx / n;
        let sxy = self.sxy - self.sx * self.sy / n;
        (sxx > 1e-12).then(|| sxy / sxx)
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
    /// prior the lidar cue reads in the frames that follow ([`WaterPrior`]); 0: no prior.
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
    /// Of `bottom`, those found under the water level of the prior ([`WaterPrior`]).
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

/// Storage of [`LidarCueModel::run_in`] kept from scan to scan: the beam directions, and
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

/// How far dry ground returned along each azimuth of one scan: the farthest lookahead of a
/// ground return per azimuth bin, from the sensor's position. A cell that no sensor saw
/// (a hole in the map) inside that reach is a hole where dry ground would have returned,
/// which water explains; a hole beyond it is explained by range alone (smooth or dark ground
/// at grazing incidence stops returning) and says nothing of water.
#[derive(Debug, Clone, PartialEq)]
pub struct DryReach {
    origin: [f64; 2],
    /// Farthest ground-return lookahead per azimuth bin (m): 0 where lines of the scan
    /// returned no ground, NaN where the scan has no line (a sensor that does not look
    /// there says nothing of it).
    bins: Vec<f32>,
}

impl DryReach {
    /// Azimuth bins over the full turn (0.5° each).
    pub const BINS: usize = 720;

    /// From each scan line's azimuth (rad, map frame) and the farthest lookahead its dry
    /// ground returned from (0 for none). Each bin holds the farthest of its lines; lines
    /// with a non-finite azimuth are ignored, a non-finite or negative reach counts as 0.
    pub fn new(origin: [f64; 2], lines: impl IntoIterator<Item = (f64, f64)>) -> Self {
        let mut bins = vec![f32::NAN; Self::BINS];
        for (az, far) in lines {
            if let Some(b) = Self::bin(az) {
                let far = if far.is_finite() && far > 0.0 {
                    far as f32
                } else {
                    0.0
                };
                // `f32::max` takes the other operand over a NaN.
                bins[b] = bins[b].max(far);
            }
        }
        DryReach { origin, bins }
    }

    fn bin(az: f64) -> Option<usize> {
        if !az.is_finite() {
            return None;
        }
        let t = az.rem_euclid(std::f64::consts::TAU) / std::f64::consts::TAU;
        Some(((t * Self::BINS as f64) as usize).min(Self::BINS - 1))
    }

    /// The reach (m) towards map point (x, y): the farthest of its bin and the two beside
    /// it (a column between two scan lines is seen by both); 0 where lines there returned
    /// no ground, infinite where the scan has no line there (a vertical scanner looks one
    /// way only).
    pub fn reach_towards(&self, x: f64, y: f64) -> f64 {
        let (dx, dy) = (x - self.origin[0], y - self.origin[1]);
        let Some(b) = Self::bin(dy.atan2(dx)) else {
            return 0.0;
        };
        let n = Self::BINS;
        let near = [(b + n - 1) % n, b, (b + 1) % n].map(|i| self.bins[i]);
        if near.iter().all(|v| v.is_nan()) {
            return f64::INFINITY;
        }
        near.into_iter().fold(0f32, f32::max) as f64
    }

    /// Whether map point (x, y) lies within the reach of dry ground along its azimuth,
    /// with `margin` metres of slack.
    pub fn covers(&self, x: f64, y: f64, margin: f64) -> bool {
        let d = crate::geom::hypot(x - self.origin[0], y - self.origin[1]);
        d <= self.reach_towards(x, y) + margin
    }
}

/// A lidar sensor's cue model: the optics for its height, wavelength and water clarity,
/// the diagnostic interval, a table of the greatest visible depth against lookahead, and
/// its beam model. Build it once per sensor (and again if its height changes).
#[derive(Debug, Clone)]
pub struct LidarCueModel {
    optics: LidarWaterModel,
    beams: BeamModel,
    cfg: LidarCueConfig,
    reflectivity: Option<ReflectivityConfig>,
    interval: Option<(f64, f64)>,
    table_step: f64,
    depth_table: Vec<f64>,
    noise: RangeNoise,
}

impl LidarCueModel {
    /// `optics.height_m` is the sensor's height above the ground (and a water level there).
    pub fn new(
        optics: LidarModelConfig,
        beams: BeamModel,
        cfg: LidarCueConfig,
        reflectivity: Option<ReflectivityConfig>,
    ) -> Result<Self> {
        cfg.validate()?;
        if let Some(r) = &reflectivity {
            r.validate()?;
        }
        match &beams {
            BeamModel::Infer { max_gap_fraction }
                if max_gap_fraction.is_nan() || *max_gap_fraction < 0.0 =>
            {
                return Err(Error::invalid(
                    "beam model max_gap_fraction",
                    format!("{max_gap_fraction} is not a number ≥ 0"),
                ))
            }
            BeamModel::Spinning {
                elevations_rad,
                azimuth0_rad,
                ..
            } if !(elevations_rad.iter().all(|v| v.is_finite()) && azimuth0_rad.is_finite()) => {
                return Err(Error::invalid("beam model", "non-finite beam angle"))
            }
            BeamModel::Directions(d) if !d.iter().flatten().all(|v| v.is_finite()) => {
                return Err(Error::invalid("beam model", "non-finite beam direction"))
            }
            _ => {}
        }
        let optics = LidarWaterModel::new(optics)?;
        let interval = optics.diagnostic_interval(cfg.min_depth_m)?;
        let end = optics
            .dry_limit()
            .unwrap_or(optics.config().height_m)
            .max(1.0)
            * 1.2;
        let table_step = (end / 400.0).max(0.02);
        let n = (end / table_step).ceil() as usize + 2;
        let depth_table = (0..n)
            .map(|i| optics.max_depth(i as f64 * table_step))
            .collect::<Result<Vec<_>>>()?;
        Ok(LidarCueModel {
            optics,
            beams,
            cfg,
            reflectivity,
            interval,
            table_step,
            depth_table,
            noise: RangeNoise::LIDAR,
        })
    }

    /// The range noise of the scans' returns (default [`RangeNoise::LIDAR`]): it sets the
    /// below-level gate's noise floor ([`LidarCueConfig::below_gate_m`]).
    pub fn with_range_noise(mut self, noise: RangeNoise) -> Self {
        self.set_range_noise(noise);
        self
    }

    /// Sets whether the strength channel is range-compensated, as measured from the log
    /// ([`ReflectivityConfig::range_compensated`]; `None`: by the channel's name).
    pub fn set_range_compensated(&mut self, compensated: Option<bool>) {
        if let Some(r) = self.reflectivity.as_mut() {
            r.range_compensated = compensated;
        }
    }

    /// Sets the range noise of the returns in place ([`LidarCueModel::with_range_noise`]).
    pub fn set_range_noise(&mut self, noise: RangeNoise) {
        self.noise = noise;
    }

    /// The water optics model the cue uses.
    pub fn optics(&self) -> &LidarWaterModel {
        &self.optics
    }

    /// The cue's settings.
    pub fn config(&self) -> &LidarCueConfig {
        &self.cfg
    }

    /// Lookaheads (m) where a missing return is diagnostic of water.
    pub fn interval(&self) -> Option<(f64, f64)> {
        self.interval
    }

    /// Greatest depth (m) whose bottom returns at `lookahead` (table, linear in between;
    /// 0 beyond the table).
    pub fn max_visible_depth(&self, lookahead: f64) -> f64 {
        if lookahead.is_nan() || lookahead < 0.0 {
            return 0.0;
        }
        let t = lookahead / self.table_step;
        // Checked before the cast: a lookahead of 1e20 m saturates `as usize`.
        if t.is_nan() || t >= self.depth_table.len().saturating_sub(1) as f64 {
            return 0.0;
        }
        let i = t as usize;
        let f = t - i as f64;
        self.depth_table[i] * (1.0 - f) + self.depth_table[i + 1] * f
    }

    #[inline]
    fn in_interval(&self, d: f64) -> bool {
        matches!(self.interval, Some((a, b)) if d >= a && d <= b)
    }

    /// Runs the cues on one organized scan. `resolution` and `z_ref` are the grid's.
    pub fn run(&self, cloud: &PointCloud, resolution: f64, z_ref: f64) -> Result<LidarCues> {
        self.run_with(cloud, resolution, z_ref, true, None)
    }

    /// [`Self::run`], collecting the dry and wet points of [`ScanSurface`] only when
    /// `surface_points` (the image labels' colour check reads them; nothing else does), and
    /// reading the water level an earlier map found where `prior` has one: a return under
    /// it by more than the noise of both is a bottom return.
    pub fn run_with(
        &self,
        cloud: &PointCloud,
        resolution: f64,
        z_ref: f64,
        surface_points: bool,
        prior: Option<&WaterPrior>,
    ) -> Result<LidarCues> {
        let mut bufs = LidarBuffers::default();
        self.run_in(cloud, resolution, z_ref, surface_points, prior, &mut bufs)
    }

    /// [`Self::run_with`] in the storage of earlier scans (`bufs`; give a run's evidence map
    /// and corrected cloud back with [`LidarBuffers::recycle`] once used): the same
    /// result, without a scan's worth of fresh memory.
    pub fn run_in(
        &self,
        cloud: &PointCloud,
        resolution: f64,
        z_ref: f64,
        surface_points: bool,
        prior: Option<&WaterPrior>,
        bufs: &mut LidarBuffers,
    ) -> Result<LidarCues> {
        cloud.validate()?;
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
        beam_directions_into(cloud, &self.beams, &mut bufs.dirs);
        let dirs = &bufs.dirs;
        let lines = scan_lines(cloud, dirs);
        let o = cloud.sensor_origin_in_map();
        let level0 = o.z - self.optics.config().height_m;
        let walked: Vec<(Vec<Event>, f64)> = lines
            .par_iter()
            .map(|line| self.walk(cloud, dirs, line, o, level0, prior))
            .collect();
        // The scan's own dry limit per line: the farthest lookahead its dry ground returned
        // from (a vertical scanner's one line likewise).
        let dry_limit: Vec<f64> = walked
            .iter()
            .map(|w| {
                if self.cfg.scan_dry_limit {
                    w.1
                } else {
                    f64::INFINITY
                }
            })
            .collect();

        let mut ev = match bufs.evidence.take() {
            Some(mut e) => {
                e.reset(resolution, z_ref);
                e
            }
            None => EvidenceMap::new(resolution, z_ref),
        };
        let mut corrected = match bufs.corrected.take() {
            Some(mut c) => {
                c.clone_from(cloud);
                c
            }
            None => cloud.clone(),
        };
        let mut stats = LidarCueStats {
            slots: n as u64,
            missing: (n - cloud.valid_count()) as u64,
            no_direction: dirs
                .iter()
                .enumerate()
                .filter(|(i, d)| d.is_none() && !cloud.is_valid(*i))
                .count() as u64,
            ..LidarCueStats::default()
        };
        let mut samples: Vec<ReflectivitySample> = Vec::new();
        let mut surface = ScanSurface::default();
        let events = walked
            .iter()
            .zip(&dry_limit)
            .flat_map(|((ev, _), limit)| ev.iter().map(move |e| (e, *limit)));
        for (e, limit) in events {
            match *e {
                Event::MissingCast => stats.missing_cast += 1,
                Event::Unexplained => stats.unexplained += 1,
                Event::BelowGround => stats.below_ground += 1,
                Event::NoRet { d, .. } if d > limit => {
                    stats.missing_cast += 1;
                    stats.noret_beyond_dry += 1;
                }
                Event::NoRet { x, y, level, d } => {
                    stats.missing_cast += 1;
                    stats.noret += 1;
                    let mm = (d * 1000.0).round() as u64;
                    let [lo, hi] = stats.noret_lookahead_mm.unwrap_or([mm, mm]);
                    stats.noret_lookahead_mm = Some([lo.min(mm), hi.max(mm)]);
                    ev.add_with_level(x, y, level, |e| e.noret = e.noret.saturating_add(1));
                    if surface_points {
                        surface.wet.push(Point3::new(x, y, level));
                    }
                }
                Event::Ground {
                    slot,
                    x,
                    y,
                    diag,
                    bright,
                    cos_inc,
                    range,
                } => {
                    if bright && surface_points {
                        surface.dry.push(cloud.point_in_map(slot));
                    }
                    if diag {
                        stats.diag_ret += 1;
                        if let Some(e) = ev.at(x, y) {
                            e.diag_ret = e.diag_ret.saturating_add(1);
                        }
                    }
                    if self.reflectivity.is_some() {
                        samples.push(ReflectivitySample {
                            slot,
                            x,
                            y,
                            cos_inc,
                            range,
                        });
                    }
                }
                Event::Bottom {
                    slot,
                    x,
                    y,
                    level,
                    depth,
                    gain,
                    prior,
                } => {
                    stats.bottom += 1;
                    stats.bottom_under_prior += prior as u64;
                    let mm = ev.level_mm(level);
                    ev.add_with_level(x, y, level, |e| match mm {
                        Some(mm) => e.add_bottom_return(depth, mm, gain),
                        None => e.add_depth(depth),
                    });
                    corrected.xyz[slot] = [f32::NAN; 3];
                    if surface_points {
                        surface.wet.push(Point3::new(x, y, level));
                    }
                }
                Event::Specular {
                    slot,
                    cx,
                    cy,
                    level,
                } => {
                    stats.specular += 1;
                    ev.add_with_level(cx, cy, level, |e| e.reflect = e.reflect.saturating_add(1));
                    if surface_points {
                        surface.wet.push(Point3::new(cx, cy, level));
                    }
                    corrected.xyz[slot] = [f32::NAN; 3];
                }
            }
        }
        let (mut reference, mut law) = (None, None);
        if let Some(rc) = &self.reflectivity {
            if let Some(r) = super::reflectivity::apply(cloud, rc, &samples, &mut ev) {
                stats.dark = r.dark;
                stats.lit = r.lit;
                reference = Some(r.threshold);
                law = Some(r.law);
            }
        }
        surface.reach = self.cfg.scan_dry_limit.then(|| {
            let az = lines.iter().map(|line| {
                line.iter()
                    .find_map(|&s| dirs[s as usize])
                    .map_or(f64::NAN, |u| u.y.atan2(u.x))
            });
            DryReach::new([o.x, o.y], az.zip(walked.iter().map(|w| w.1)))
        });
        Ok(LidarCues {
            evidence: ev,
            corrected,
            stats,
            reflectivity_threshold: reference,
            reflectivity_law: law,
            surface,
        })
    }

    /// A return under the water surface `prior` knows at its cell, by more than the
    /// line's below-level `gate` and three standard deviations of the surface together, at
    /// a depth the optics say this sensor can see there: a bottom return at that level.
    fn under_prior(
        &self,
        prior: &WaterPrior,
        slot: usize,
        o: Point3<f64>,
        p: Point3<f64>,
        gate: impl FnOnce() -> f64,
    ) -> Option<Event> {
        let l = prior.level_at(p.x, p.y)?;
        if p.z >= o.z || o.z <= l.z || p.z >= l.z - gate().hypot(3.0 * l.sigma) {
            return None;
        }
        self.against_level(slot, o, p, l.z, true)?.1
    }

    /// A return `p` below the water level `level`, read through it: where its beam crosses
    /// the level and, when its refraction-corrected depth is one the optics say this
    /// sensor can see there, the bottom return (`prior`: the level is the prior's). `None`
    /// when the return cannot be corrected.
    fn against_level(
        &self,
        slot: usize,
        o: Point3<f64>,
        p: Point3<f64>,
        level: f64,
        prior: bool,
    ) -> Option<(Point3<f64>, Option<Event>)> {
        let v = p - o;
        let u = v / v.norm();
        let c = o + u * ((o.z - level) / -u.z);
        let d_c = crate::geom::hypot(c.x - o.x, c.y - o.y);
        let q = self.optics.correct_bottom_return(o, p, level).ok()?;
        let depth = level - q.z;
        let visible = depth <= self.max_visible_depth(d_c) + self.cfg.depth_tolerance_m;
        let bottom = visible.then(|| Event::Bottom {
            slot,
            x: q.x,
            y: q.y,
            level,
            depth,
            gain: crate::optics::bottom_depth_gain(o, p, self.optics.config().n_water)
                .unwrap_or(0.0),
            prior,
        });
        Some((c, bottom))
    }

    /// The optics' loss through the shallowest water at lookahead `d`:
    /// [`LidarWaterModel::return_ratio`] at zero depth over
    /// [`LidarWaterModel::dry_ratio`] (Fresnel transmission in and out, and the steeper
    /// refracted beam on the bottom). NaN where the optics give none.
    fn shallowest_loss(&self, d: f64) -> f64 {
        match (self.optics.return_ratio(d, 0.0), self.optics.dry_ratio(d)) {
            (Ok(w), Ok(g)) if g > 0.0 => w / g,
            _ => f64::NAN,
        }
    }

    fn walk(
        &self,
        cloud: &PointCloud,
        dirs: &[Option<Vector3<f64>>],
        line: &[u32],
        o: Point3<f64>,
        level0: f64,
        prior: Option<&WaterPrior>,
    ) -> (Vec<Event>, f64) {
        let cfg = &self.cfg;
        let g_max = cfg.max_ground_slope;
        // The local ground: `level` at lookahead `d_level`, falling or rising with `slope`
        // beyond it. Under the vehicle the slope is not known yet: the first return may lie
        // anywhere within ±g_max of level ground.
        let mut level = level0;
        let mut d_level = 0.0;
        let mut slope: Option<f64> = None;
        // (lookahead, z) of the ground returns of the last SLOPE_WINDOW_M, starting with the
        // ground under the sensor: the slope is their least-squares line, so 1 cm of range
        // noise does not tilt it by the 6 % it would between two returns 25 cm apart.
        let mut recent = SlopeWindow::new((0.0, level0));
        let mut out = Vec::new();
        // The farthest lookahead dry ground returned from along this line.
        let mut far = 0.0f64;
        // Normalised reflectivity of the line's last ground returns (`BRIGHT_WINDOW`): the
        // brightest is what the bottom of water there could at most return, before the
        // water's losses.
        let channel = self.reflectivity.unwrap_or_default();
        let mut bright: VecDeque<f64> = VecDeque::with_capacity(BRIGHT_WINDOW);
        // How far the line's last ground returns fell from the level they were judged by
        // (`GATE_WINDOW`): the dry ground's own spread, for the below-level gate.
        let mut drops: VecDeque<f64> = VecDeque::with_capacity(GATE_WINDOW);
        for &s in line {
            let s = s as usize;
            if cloud.is_valid(s) {
                let p = cloud.point_in_map(s);
                let v = p - o;
                let range = v.norm();
                let d = crate::geom::hypot(v.x, v.y);
                let cos_inc = if range > 0.0 { -v.z / range } else { 0.0 };
                let run = (d - d_level).max(0.0);
                // Only a falling slope is followed: ground rising ahead moves the level up
                // through the above-gate anyway, while a rising slope carried over a long
                // run would put level ground beyond it "below" and call it a bottom.
                let expected = level + slope.unwrap_or(0.0).min(0.0) * run;
                let slack = if slope.is_some() { 0.0 } else { g_max * run };
                let dz = p.z - expected;
                // The gate is never negative: only a return below the level and its slack
                // needs it measured.
                let gate = || {
                    let sigma_v = self.noise.sigma(range) * (-v.z / range.max(1e-9)).max(0.0);
                    below_gate(&drops, sigma_v, cfg.below_gate_m)
                };
                if let Some(e) = prior.and_then(|w| self.under_prior(w, s, o, p, gate)) {
                    out.push(e);
                    continue;
                }
                let below = v.z < 0.0 && o.z > level && dz < -slack && dz < -(gate() + slack);
                let ground = if below {
                    // Below the level: bottom or specular, or ground below the level.
                    let Some((c, bottom)) = self.against_level(s, o, p, level, false) else {
                        continue;
                    };
                    if let Some(e) = bottom {
                        out.push(e);
                        false
                    } else if level - p.z < cfg.specular_min_depth_m {
                        out.push(Event::Unexplained);
                        false
                    } else if mirror_refuted(
                        &ScanLine {
                            cloud,
                            dirs,
                            slots: line,
                            o,
                        },
                        p,
                        level,
                        self.noise.sigma(range),
                        cfg.above_gate_m,
                    ) {
                        out.push(Event::BelowGround);
                        true
                    } else {
                        out.push(Event::Specular {
                            slot: s,
                            cx: c.x,
                            cy: c.y,
                            level,
                        });
                        false
                    }
                } else {
                    dz <= cfg.above_gate_m + slack
                };
                if ground {
                    // Ground. The slope of the recent ground, once it spans enough
                    // lookahead to measure one, clamped to what ground does.
                    if drops.len() == GATE_WINDOW {
                        drops.pop_front();
                    }
                    drops.push_back(dz.abs());
                    recent.push((d, p.z));
                    if let Some(g) = recent.slope() {
                        slope = Some(g.clamp(-g_max, g_max));
                    }
                    level = p.z;
                    d_level = d;
                    far = far.max(d);
                    let r = normalised_reflectivity(cloud, s, cos_inc, range, &channel);
                    // Brighter than the bottom of even the shallowest water there could
                    // return, with a bed [`BED_BRIGHTER`] than the recent ground: a return
                    // water would not give, as one inside the interval.
                    let dry_bright = r.is_some_and(|r| {
                        bright_reference(&bright)
                            .is_some_and(|b| r > BED_BRIGHTER * b * self.shallowest_loss(d))
                    });
                    if let Some(r) = r {
                        if bright.len() == BRIGHT_WINDOW {
                            bright.pop_front();
                        }
                        bright.push_back(r);
                    }
                    let diag = self.in_interval(d) || dry_bright;
                    // A ground return outside the interval matters only to the
                    // reflectivity cue: no event (and no allocation) without it.
                    if !diag && self.reflectivity.is_none() {
                        continue;
                    }
                    out.push(Event::Ground {
                        slot: s,
                        x: p.x,
                        y: p.y,
                        diag,
                        bright: dry_bright,
                        cos_inc,
                        range,
                    });
                }
            } else if let Some(u) = dirs[s] {
                if u.z >= -1e-6 || o.z <= level {
                    continue;
                }
                let t = (o.z - level) / -u.z;
                let hit = o + u * t;
                let d = crate::geom::hypot(hit.x - o.x, hit.y - o.y);
                if self.in_interval(d) {
                    out.push(Event::NoRet {
                        x: hit.x,
                        y: hit.y,
                        level,
                        d,
                    });
                } else {
                    out.push(Event::MissingCast);
                }
            }
        }
        (out, far)
    }
}

/// Beams of a scan line that must see the space above a below-level return empty before
/// it is taken for ground rather than a mirror image.
const MIRROR_FREE_BEAMS: usize = 2;

/// One scan line of an organized scan: its slots in order of lookahead, the scan, the
/// map-frame directions of its slots and the sensor's position.
#[derive(Clone, Copy)]
struct ScanLine<'a> {
    cloud: &'a PointCloud,
    dirs: &'a [Option<Vector3<f64>>],
    slots: &'a [u32],
    o: Point3<f64>,
}

/// Whether the below-level return `p` of a scan `line` (walked level `level`, range noise
/// `sigma_r`) cannot be a mirror image. A return mirrored by water at level `w` appears at
/// the mirror image of its object about the water plane: the object stands at the
/// return's own x, y, at height `2w − z`.
/// The water lies between the return and the walked level, so the object lies somewhere on
/// the vertical segment from the return up to `2·level − z`, in the same azimuth: the scan
/// line's own higher beams cross that segment. A beam that crosses it and stops at or
/// before the crossing (within three σ of range noise) may have met the object, and keeps
/// the mirror. If none does, at least [`MIRROR_FREE_BEAMS`] cross it, and the lowest of
/// them passes within `low` (the walk's above-ground gate) of the return's height (above a
/// margin of the beam's noise, so that the far bank rising just behind the return is not
/// taken for an object), the only object it could mirror is one lower than that crossing:
/// one the walk would take for ground at the return's place anyway. The return is ground
/// below the level, the far bank of a depression. Sparse rings at range that cross only
/// high leave it a mirror.
fn mirror_refuted(line: &ScanLine, p: Point3<f64>, level: f64, sigma_r: f64, low: f64) -> bool {
    let ScanLine {
        cloud,
        dirs,
        slots,
        o,
    } = *line;
    let d = crate::geom::hypot(p.x - o.x, p.y - o.y);
    let tol = 3.0 * sigma_r.max(0.01);
    // Above the return by a margin, so that a beam grazing the ground just behind it (the
    // far bank rising from the return) is not taken for an object.
    let (lo, hi) = (p.z + tol.max(0.1), 2.0 * level - p.z);
    let (mut free, mut lowest) = (0, f64::INFINITY);
    for &t in slots {
        let t = t as usize;
        let Some(u) = dirs.get(t).copied().flatten() else {
            continue;
        };
        let h = crate::geom::hypot(u.x, u.y);
        if h <= 1e-9 {
            continue;
        }
        // Where the beam reaches the return's horizontal distance.
        let along = d / h;
        let z = o.z + u.z * along;
        if !(lo..=hi).contains(&z) {
            continue;
        }
        if cloud.is_valid(t) && (cloud.point_in_map(t) - o).norm() <= along + tol {
            return false;
        }
        free += 1;
        lowest = lowest.min(z);
    }
    free >= MIRROR_FREE_BEAMS && lowest <= p.z + low
}

/// Ground returns along a scan line whose brightest bounds what the bottom of water there
/// could return ([`bright_reference`]).
const BRIGHT_WINDOW: usize = 16;

/// How much brighter than the ground before it the bed of water may be, at the lidar's
/// wavelength: natural surfaces span about 0.1 (wet dark soil) to 0.6 (pale sand, dry
/// concrete) in albedo, and a bed three times its bank (sand or gravel under soil and
/// grass) is allowed before a return at the level is called brighter than water allows.
const BED_BRIGHTER: f64 = 3.0;

/// The brightest of a line's recent ground returns after its two brightest: a return
/// normalised as level ground that is not (a kerb's vertical face, met head-on and divided
/// by the grazing incidence of the ground around it, comes out several times brighter
/// than the ground) is one or two beams of a line, and must not raise the bound the
/// ground after it is judged by. With fewer than three returns, the brightest.
fn bright_reference(bright: &VecDeque<f64>) -> Option<f64> {
    let mut top = [f64::NEG_INFINITY; 3];
    for &v in bright.iter().filter(|v| !v.is_nan()) {
        if v > top[0] {
            top = [v, top[0], top[1]];
        } else if v > top[1] {
            top = [top[0], v, top[1]];
        } else if v > top[2] {
            top[2] = v;
        }
    }
    match top {
        [a, _, _] if a == f64::NEG_INFINITY => None,
        [a, _, c] if c == f64::NEG_INFINITY => Some(a),
        [_, _, c] => Some(c),
    }
}

/// Ground returns along a scan line whose spread about the walked level sets the
/// below-level gate ([`below_gate`]).
const GATE_WINDOW: usize = 16;

/// Fewest such returns for a measured spread.
const GATE_MIN: usize = 5;

/// The depth below the walked level (m) beyond which a return is a below-level return:
/// three standard deviations of how far dry ground there falls from the level it is judged
/// by, and never more than `ceiling` (`below_gate_m`). That spread is the larger of the
/// range noise's vertical part `sigma_v` (times √2: the level is a return too) and the
/// spread the line's last [`GATE_WINDOW`] ground returns showed (1.4826 × their median
/// absolute fall `drops`: rough ground and noise together, measured on this scan). A line
/// with fewer than [`GATE_MIN`] ground returns so far uses the ceiling. Bottom returns of
/// a puddle 5 to 15 cm deep lie 1 to 4 cm below its surface at grazing incidence: a fixed
/// 10 cm gate fused them as ground and no depth was ever found.
///
/// Only ground returns are counted: with the returns below the gate counted too, a line
/// crossing a few metres of shallow water widened its gate to the ceiling after eight
/// bottom returns and fused the rest as ground. Dips in rough ground that fall beyond three
/// standard deviations become bottom returns here; the water stage keeps a cell's bottom
/// evidence only where it lies below the surface its body's shore gives.
fn below_gate(drops: &VecDeque<f64>, sigma_v: f64, ceiling: f64) -> f64 {
    let n = drops.len();
    if n < GATE_MIN {
        return ceiling;
    }
    let mut d = [0.0; GATE_WINDOW];
    for (a, b) in d.iter_mut().zip(drops) {
        *a = *b;
    }
    let med = *d[..n]
        .select_nth_unstable_by(n / 2, |a, b| a.total_cmp(b))
        .1;
    // `f64::max` and `min` take the other operand over a NaN: a NaN σ gives the measured
    // spread, never a NaN gate.
    let spread = (1.4826 * med).max(std::f64::consts::SQRT_2 * sigma_v);
    (3.0 * spread).min(ceiling)
}

/// What one slot of a scan line contributed.
#[derive(Debug, Clone, Copy)]
enum Event {
    MissingCast,
    Unexplained,
    /// A below-level return that the scan line saw nothing above ([`mirror_refuted`]):
    /// ground below the walked level, kept in the terrain.
    BelowGround,
    NoRet {
        x: f64,
        y: f64,
        level: f64,
        /// Lookahead of the ground hit (m).
        d: f64,
    },
    Ground {
        slot: usize,
        x: f64,
        y: f64,
        /// Inside the diagnostic interval, or brighter than water allows.
        diag: bool,
        /// Brighter than water allows.
        bright: bool,
        cos_inc: f64,
        range: f64,
    },
    Bottom {
        slot: usize,
        x: f64,
        y: f64,
        level: f64,
        depth: f64,
        /// d(depth)/d(level): how the depth would move against another level.
        gain: f64,
        /// Found under the prior's water level, not the walked level.
        prior: bool,
    },
    Specular {
        slot: usize,
        cx: f64,
        cy: f64,
        level: f64,
    },
}

/// Map-frame unit direction of every slot: from the point for real returns, from the beam
/// model for missing ones (`None` where it cannot be known).
pub fn beam_directions(cloud: &PointCloud, model: &BeamModel) -> Vec<Option<Vector3<f64>>> {
    let mut out = Vec::new();
    beam_directions_into(cloud, model, &mut out);
    out
}

/// [`beam_directions`] into `local`'s storage (its contents replaced).
fn beam_directions_into(
    cloud: &PointCloud,
    model: &BeamModel,
    local: &mut Vec<Option<Vector3<f64>>>,
) {
    let rot = cloud.frame_to_map.rotation;
    let so = cloud.sensor_origin;
    let (rows, cols) = (cloud.rows, cloud.cols);
    let from_point = |i: usize| {
        let [x, y, z] = cloud.xyz[i];
        let v = Vector3::new(x as f64 - so.x, y as f64 - so.y, z as f64 - so.z);
        let nv = v.norm();
        (nv > 0.0).then(|| v / nv)
    };
    let from_angles =
        |az: f64, el: f64| Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
    local.clear();
    local.extend((0..cloud.len()).map(|i| {
        if cloud.is_valid(i) {
            from_point(i)
        } else {
            None
        }
    }));
    match model {
        BeamModel::Directions(d) => {
            for (i, l) in local.iter_mut().enumerate() {
                if l.is_none() {
                    let v = Vector3::new(d[i][0] as f64, d[i][1] as f64, d[i][2] as f64);
                    let nv = v.norm();
                    *l = (nv > 0.0).then(|| v / nv);
                }
            }
        }
        BeamModel::Spinning {
            elevations_rad,
            azimuth0_rad,
            clockwise,
        } => {
            let sign = if *clockwise { -1.0 } else { 1.0 };
            for (r, &el) in elevations_rad.iter().enumerate().take(rows) {
                for c in 0..cols {
                    let i = r * cols + c;
                    if local[i].is_none() {
                        let az = azimuth0_rad
                            + sign * 2.0 * std::f64::consts::PI * c as f64 / cols as f64;
                        local[i] = Some(from_angles(az, el));
                    }
                }
            }
        }
        BeamModel::Infer { .. } if cols == 1 && rows > 2 => {
            infer_single_column(local);
        }
        BeamModel::Infer { max_gap_fraction } => {
            let cyclic = rows > 1;
            let max_gap = ((cols as f64 * max_gap_fraction).floor() as usize).max(1);
            let angles = |v: &Vector3<f64>| (v.y.atan2(v.x), v.z.clamp(-1.0, 1.0).asin());
            for r in 0..rows {
                let row = &local[r * cols..(r + 1) * cols];
                let valid: Vec<usize> = (0..cols).filter(|&c| row[c].is_some()).collect();
                if valid.is_empty() {
                    continue;
                }
                let mut fill: Vec<(usize, Vector3<f64>)> = Vec::new();
                // Consecutive valid pairs (and the wrap-around pair when cyclic).
                let mut pairs: Vec<(usize, usize)> =
                    valid.windows(2).map(|w| (w[0], w[1])).collect();
                if cyclic {
                    pairs.push((valid[valid.len() - 1], valid[0] + cols));
                }
                for (a, b) in pairs {
                    let gap = b - a;
                    if gap < 2 || gap - 1 > max_gap {
                        continue;
                    }
                    let (az_a, el_a) = angles(&row[a].unwrap());
                    let (az_b, el_b) = angles(&row[b % cols].unwrap());
                    let mut daz = az_b - az_a;
                    let tau = 2.0 * std::f64::consts::PI;
                    daz -= tau * (daz / tau).round();
                    for k in 1..gap {
                        let t = k as f64 / gap as f64;
                        fill.push((
                            (a + k) % cols,
                            from_angles(az_a + daz * t, el_a + (el_b - el_a) * t),
                        ));
                    }
                }
                for (c, v) in fill {
                    local[r * cols + c] = Some(v);
                }
            }
        }
    }
    for d in local.iter_mut() {
        *d = d.map(|v| rot * v);
    }
}

/// Fills the missing beams of a single-column scan (sensor frame, one beam per row) from
/// the least-squares line of elevation against row through the valid beams, at their median
/// azimuth; leaves them unknown when fewer than 3 beams returned or the beams do not lie on
/// a line within 0.1° RMS (not an evenly spaced scanner).
fn infer_single_column(local: &mut [Option<Vector3<f64>>]) {
    let pts: Vec<(f64, f64, f64)> = local
        .iter()
        .enumerate()
        .filter_map(|(r, v)| v.map(|v| (r as f64, v.z.clamp(-1.0, 1.0).asin(), v.y.atan2(v.x))))
        .collect();
    if pts.len() < 3 {
        return;
    }
    let n = pts.len() as f64;
    let Some((mr, me, slope)) = fit_line(pts.iter().map(|p| (p.0, p.1))) else {
        return;
    };
    let el = |r: f64| me + slope * (r - mr);
    let rms = (pts.iter().map(|p| (p.1 - el(p.0)).powi(2)).sum::<f64>() / n).sqrt();
    // Also refuses a NaN residual.
    if rms.is_nan() || rms > 0.1f64.to_radians() {
        return;
    }
    let mut az: Vec<f64> = pts.iter().map(|p| p.2).collect();
    let m = az.len() / 2;
    az.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
    let az = az[m];
    for (r, v) in local.iter_mut().enumerate() {
        if v.is_none() {
            let e = el(r as f64);
            if e.abs() < std::f64::consts::FRAC_PI_2 {
                *v = Some(Vector3::new(
                    e.cos() * az.cos(),
                    e.cos() * az.sin(),
                    e.sin(),
                ));
            }
        }
    }
}

/// Scan lines in order of increasing lookahead: columns ordered by each row's median
/// elevation (multi-row scans), or the single row ordered by slot elevation.
fn scan_lines(cloud: &PointCloud, dirs: &[Option<Vector3<f64>>]) -> Vec<Vec<u32>> {
    let (rows, cols) = (cloud.rows, cloud.cols);
    if rows <= 1 {
        let mut line: Vec<(f64, u32)> = dirs
            .iter()
            .enumerate()
            .filter_map(|(i, d)| d.map(|v| (v.z, i as u32)))
            .collect();
        line.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        return vec![line.into_iter().map(|(_, i)| i).collect()];
    }
    let mut order: Vec<(f64, usize)> = (0..rows)
        .filter_map(|r| {
            let mut el: Vec<f64> = (0..cols)
                .filter_map(|c| dirs[r * cols + c].map(|v| v.z))
                .collect();
            if el.is_empty() {
                return None;
            }
            let m = el.len() / 2;
            el.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
            Some((el[m], r))
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    (0..cols)
        .map(|c| {
            order
                .iter()
                .map(|&(_, r)| (r * cols + c) as u32)
                .filter(|&i| dirs[i as usize].is_some())
                .collect()
        })
        .collect()
}

/// The sensor's height above the ground, estimated from the scan itself: the median of
/// `sensor z − point z` over the returns of the steepest downward beams (depression
/// between 10° and 45°, the ground ring around the vehicle), in the map frame. `None`
/// when fewer than 20 such returns exist.
pub fn estimate_sensor_height(cloud: &PointCloud) -> Option<f64> {
    let o = cloud.sensor_origin_in_map();
    let (lo, hi) = (10f64.to_radians().sin(), 45f64.to_radians().sin());
    let mut h: Vec<f64> = (0..cloud.len())
        .filter(|&i| cloud.is_valid(i))
        .filter_map(|i| {
            let v = cloud.point_in_map(i) - o;
            let s = -v.z / v.norm();
            (s >= lo && s <= hi).then_some(-v.z)
        })
        .collect();
    if h.len() < 20 {
        return None;
    }
    // The ground is the lowest surface: take the median of the lower half, which ignores
    // vegetation and obstacles above it.
    h.sort_by(|a, b| b.total_cmp(a));
    let lower = &h[..h.len() / 2];
    Some(lower[lower.len() / 2])
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod reach_tests {
    use super::DryReach;
    use proptest::prelude::*;

    #[test]
    fn reach_is_per_azimuth_and_wraps_around() {
        let r = DryReach::new(
            [100.0, -50.0],
            [
                (0.0, 20.0),
                (std::f64::consts::FRAC_PI_2, 8.0),
                // Just below +π and just above −π: the same direction, two ends of the bins.
                (std::f64::consts::PI - 1e-4, 12.0),
                (f64::NAN, 99.0),
                (1.0, f64::INFINITY),
            ],
        );
        assert_eq!(r.reach_towards(115.0, -50.0), 20.0);
        assert_eq!(r.reach_towards(100.0, -40.0), 8.0);
        assert_eq!(r.reach_towards(90.0, -50.0 - 1e-6), 12.0);
        assert!(r.covers(119.0, -50.0, 0.0) && !r.covers(121.0, -50.0, 0.5));
        // No line towards −y: the scan says nothing there, and gates nothing.
        assert_eq!(r.reach_towards(100.0, -60.0), f64::INFINITY);
        assert!(r.covers(100.0, -1e6, 0.0));
        // A line that returned no ground: nothing covered along it.
        let none = DryReach::new([0.0, 0.0], [(0.0, 0.0), (0.1, f64::NAN)]);
        assert_eq!(none.reach_towards(5.0, 0.0), 0.0);
        assert!(!none.covers(5.0, 0.0, 0.2) && !none.covers(5.0, 0.5, 0.2));
    }

    proptest! {
        /// Whatever the lines, the reach towards any point is finite, non-negative, and at
        /// least that of a line pointing straight at it.
        #[test]
        fn reach_bounds(
            lines in prop::collection::vec((-10.0f64..10.0, -1e3f64..1e3), 0..50),
            x in -1e6f64..1e6, y in -1e6f64..1e6,
        ) {
            let r = DryReach::new([0.0, 0.0], lines.iter().copied());
            let got = r.reach_towards(x, y);
            prop_assert!(got >= 0.0 && (got.is_finite() || got == f64::INFINITY));
            let az = y.atan2(x);
            let direct = DryReach::new([0.0, 0.0], [(az, 5.0)]);
            prop_assert!(direct.reach_towards(x, y) == 5.0 || x == 0.0 && y == 0.0);
        }
    }
}
