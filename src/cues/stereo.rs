//! Stereo reflections in still water (paper section 2.3, Figure 4).
//!
//! Stereo matches the reflection of a tree in a pond as if it were a real object: the
//! triangulated points are the tree's *virtual image*, mirrored below the water level. Up
//! an image column (bottom to top, increasing range on the ground) they show as a run of
//! points below the local ground, behind a gap (the water between the shore and where the
//! reflection's points sit), whose range *wraps backward* (the reflection of the tree top
//! is seen first, closest to the camera in the image, and is the farthest point).
//!
//! For a confirmed run, with water level `L`:
//! * the ray to each reflected point crosses `z = L` where the water is: that cell gets a
//!   reflection count (and a level sample);
//! * the point mirrored about `L` is the real object: [`StereoCues::corrected`] holds the
//!   cloud with every reflected point replaced by its mirror image;
//! * `L` starts at the shore level (the last ground before the run). The near bank may
//!   face away from the camera and hide the water's edge, so that the shore is the bank's
//!   top, above the water. The *waterline* corrects it: a run that terrain nearer than it
//!   ends has met the far shore, which faces the camera and is seen down to the water, so
//!   that shore's height is a level sample taken where the vertical part of the range error
//!   is small. The frame's waterline level is the median of these (at least
//!   `min_far_shores`; a far shore more than `level_tolerance_m` plus its noise below the
//!   near shore is a reflection point that range noise pulled nearer, and is left out).
//! * `L` is also refined by symmetry, from the waterline level when there is one: each
//!   mirrored point is paired with its nearest real point (kiddo k-d tree), and `L` moves
//!   by half the median height difference, a few times (a one-parameter ICP). A vertical
//!   surface (a wall, a trunk, the side of a crown) pairs a mirrored point with a real
//!   point at its own height whatever `L` is, so it constrains `L` only at its edges; where
//!   such surfaces dominate, or the range noise along the rays exceeds the pairing radius
//!   (stereo at 20 m and more), the median difference barely depends on `L` and the ICP
//!   stays near where it started. Measured on the simulated `fig4_reflections` pond
//!   without noise, the median difference moved 0.03 m while `L` moved 0.4 m, where an
//!   informative pairing moves it 0.8 m. The runs therefore take the waterline level when
//!   there is one, and the symmetry level only without it;
//! * the frame's level replaces the shore level of a run when it lies below it (water
//!   stands at or below its shores: the shore is a bank above the water, or a point seen
//!   a little up the bank); a frame level above the shore is not this run's water;
//! * up a column with a confirmed run, once the frame has a level, every later point is
//!   judged against that level alone: below it by more than its vertical noise, or below
//!   it with its `level_window` neighbours below it on average by more than the noise of
//!   their mean, it is a reflection whatever the run structure; the cells between
//!   consecutive reflection crossings up a column get evidence too (one cloud row spans
//!   more than a metre of water at 20 m);
//! * with the intensity image and camera model ([`MirrorCheck`]), the intensities of the
//!   reflected pixels must correlate (normalised cross-correlation ≥ `min_ncc`) with those
//!   of the pixels where the mirrored points project; a run whose pixels have no texture
//!   to correlate keeps its geometric verdict.

use nalgebra::Point3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{CueRun, EvidenceMap};
use crate::error::{Error, Result};
use crate::geom::{CameraModel, PointCloud, Pose};
use crate::grid::RangeNoise;

mod level;
mod reflect;
mod runs;

use reflect::Marks;

/// A single-channel image (row-major, `width × height`), e.g. the left camera's intensity.
#[derive(Debug, Clone, PartialEq)]
pub struct GrayImage {
    /// Columns, pixels.
    pub width: usize,
    /// Rows, pixels.
    pub height: usize,
    /// Intensities, row major.
    pub pixels: Vec<f32>,
}

impl GrayImage {
    /// An image of `width × height` pixels. Fails when `pixels` does not fill it or a side is 0.
    pub fn new(width: usize, height: usize, pixels: Vec<f32>) -> Result<Self> {
        if width.checked_mul(height) != Some(pixels.len()) || width == 0 || height == 0 {
            return Err(Error::invalid(
                "gray image",
                format!("{} pixels do not fill {width} × {height}", pixels.len()),
            ));
        }
        Ok(GrayImage {
            width,
            height,
            pixels,
        })
    }

    /// Bilinear sample at pixel coordinates (pixel centres at integers); `None` outside.
    pub fn sample(&self, u: f64, v: f64) -> Option<f64> {
        if !(u >= 0.0 && v >= 0.0 && u <= (self.width - 1) as f64 && v <= (self.height - 1) as f64)
        {
            return None;
        }
        let (x0, y0) = (u.floor() as usize, v.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = (u - x0 as f64, v - y0 as f64);
        let p = |x: usize, y: usize| self.pixels[y * self.width + x] as f64;
        let top = p(x0, y0) * (1.0 - fx) + p(x1, y0) * fx;
        let bot = p(x0, y1) * (1.0 - fx) + p(x1, y1) * fx;
        Some(top * (1.0 - fy) + bot * fy)
    }
}

/// The image and camera for the mirror-image correlation check. The stereo cloud may be a
/// whole-factor downsample of the image: element (row, col) lies on the ray of pixel
/// `(k·col + (k−1)/2, k·row + (k−1)/2)` with `k = image width / cloud width`.
#[derive(Debug, Clone, Copy)]
pub struct MirrorCheck<'a> {
    /// The left camera of the pair.
    pub camera: &'a CameraModel,
    /// Its image, at the camera's resolution.
    pub image: &'a GrayImage,
}

/// Settings of the stereo reflection cue.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StereoCueConfig {
    /// Range noise of the stereo points (sets the below-ground gate).
    pub noise: RangeNoise,
    /// A point starts a run when more than `max(gate_min_m, gate_sigma·σ_v)` below the
    /// local ground, `σ_v = σ(r)·|sin δ|` the vertical part of the range error along a ray
    /// of depression `δ`.
    pub gate_sigma: f64,
    /// Smallest depth below the local ground that starts a run, metres.
    pub gate_min_m: f64,
    /// Points more than this above the local ground are objects, not ground (m).
    pub above_gate_m: f64,
    /// Horizontal jump from the last ground to the first point of a run that makes a gap (m).
    pub gap_min_m: f64,
    /// Fewest points in a run.
    pub min_run: usize,
    /// For a run with no terrain after it in its column: the fraction of its steps whose
    /// range must decrease (wrap backward).
    pub wrap_fraction: f64,
    /// Pairing radius of mirrored points and their sources (m).
    pub pair_radius_m: f64,
    /// Fewest pairs for a symmetry level.
    pub min_pairs: usize,
    /// A far shore more than this (and its noise) below the near one is not taken for the
    /// water's edge (m).
    pub level_tolerance_m: f64,
    /// Fewest far shores for a waterline level.
    pub min_far_shores: usize,
    /// Smallest normalised cross-correlation that confirms a run (with an image).
    pub min_ncc: f64,
    /// Up a column with confirmed water, a point below the level within its own noise is
    /// a reflection when, with this many valid points either side of it, the weighted mean
    /// lies below the level by more than the mean's noise (0: single points only).
    pub level_window: usize,
}

impl Default for StereoCueConfig {
    fn default() -> Self {
        StereoCueConfig {
            noise: RangeNoise::STEREO,
            gate_sigma: 3.0,
            gate_min_m: 0.15,
            above_gate_m: 0.30,
            gap_min_m: 0.5,
            min_run: 3,
            wrap_fraction: 0.6,
            pair_radius_m: 0.3,
            min_pairs: 10,
            level_tolerance_m: 0.3,
            min_far_shores: 5,
            min_ncc: 0.5,
            level_window: 2,
        }
    }
}

impl StereoCueConfig {
    /// Checks the noise model and every setting's range (`Error::Invalid`).
    pub fn validate(&self) -> Result<()> {
        self.noise.validate()?;
        let pos = |v: f64| v.is_finite() && v >= 0.0;
        let ok = pos(self.gate_sigma)
            && pos(self.gate_min_m)
            && pos(self.above_gate_m)
            && pos(self.gap_min_m)
            && (0.0..=1.0).contains(&self.wrap_fraction)
            && self.pair_radius_m.is_finite()
            && self.pair_radius_m > 0.0
            && pos(self.level_tolerance_m)
            && (-1.0..=1.0).contains(&self.min_ncc)
            && self.min_run >= 2;
        if ok {
            Ok(())
        } else {
            Err(Error::invalid(
                "stereo cue config",
                format!("{self:?}: gates and radii must be finite and ≥ 0, min_run ≥ 2, fractions in range"),
            ))
        }
    }
}

/// The output of [`stereo_reflections`].
#[derive(Debug, Clone)]
pub struct StereoCues {
    /// Water evidence of the confirmed runs, by cell.
    pub evidence: EvidenceMap,
    /// The input cloud with every reflected point replaced by its mirror image (the real
    /// object), in the cloud's frame: fuse this instead of the raw cloud.
    pub corrected: PointCloud,
    /// The water level from reflection symmetry, if enough pairs were found (map z, m).
    pub symmetry_level: Option<f64>,
    /// Reflected/source pairs behind `symmetry_level`.
    pub pairs: usize,
    /// The water level at the waterline: the median height of the far shores that ended
    /// runs (at least `min_far_shores` of them); the level the runs use when present.
    pub waterline_level: Option<f64>,
    /// Runs ended by a far shore within the tolerance of their near shore.
    pub far_shores: usize,
    /// Runs confirmed, runs rejected by geometry, runs rejected by the image check.
    pub runs: usize,
    /// Runs rejected by geometry.
    pub rejected_geometry: usize,
    /// Runs rejected by the image check.
    pub rejected_image: usize,
    /// Points found to be reflections (in runs and below the known level).
    pub reflected_points: usize,
    /// Of those, the points found against the frame's level alone, up a column that has
    /// confirmed water, outside any run.
    pub level_points: usize,
    /// Cells strictly between consecutive reflection crossings up a column, counted once
    /// per span.
    pub span_cells: usize,
    /// What each element says of the surface under its pixel ([`StereoSeen`]), for the
    /// colour labels' check: empty unless [`stereo_reflections`] was asked for it.
    pub seen: Vec<StereoSeen>,
}

/// What one element of a stereo cloud says of the surface under its pixel. Still water
/// gives stereo no point at its level: it mirrors what stands above it, so the match is
/// the virtual image below the level (by the object's height), or no match at all where it
/// mirrors the sky. Textured dry ground gives a point at the level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StereoSeen {
    /// Nothing to say: an object above the ground, a point below it that no confirmed run
    /// explains, a point of a run that was not confirmed, the sky, no match beyond the
    /// farthest ground the column matched.
    #[default]
    Nothing,
    /// A point at the local ground level within its own vertical noise `σ_v` (see
    /// [`StereoCueConfig::gate_sigma`]), not a reflection, and not below the frame's water
    /// level up a column with confirmed water (there a shallow reflection, of the bank
    /// just beyond the water, lies within the noise of the level).
    Ground,
    /// A reflection: not seen to be dry ground. (No match at all says nothing: still water
    /// mirroring the sky gives none, and neither does snow or pale concrete without
    /// texture.)
    NotGround,
}

/// Finds reflections in an organized stereo cloud (rows top to bottom as in the image),
/// filling [`StereoCues::seen`] only when `run.surface_points` (the image labels' colour
/// check reads it; the cue reads no prior).
///
/// A frame goes through four phases, in the order its data flows: the candidate runs up
/// each column; the frame's water level, at the waterline and by symmetry; the runs
/// confirmed against that level and the image, with their evidence and mirrored points;
/// and the points below the known level up the columns with confirmed water.
pub fn stereo_reflections(
    cloud: &PointCloud,
    run: &CueRun,
    check: Option<MirrorCheck<'_>>,
    cfg: &StereoCueConfig,
) -> Result<StereoCues> {
    let CueRun {
        resolution,
        z_ref,
        surface_points,
        ..
    } = *run;
    cloud.validate()?;
    cfg.validate()?;
    if !cloud.is_organized() {
        return Err(Error::invalid(
            "stereo cloud",
            "the reflection cue needs an organized cloud (rows × cols)",
        ));
    }
    let k = image_factor(cloud, check)?;
    let frame = Frame::new(cloud, cfg);

    // 1. Candidate runs up each column.
    let candidates = frame.candidate_runs(surface_points);
    let runs = &candidates.runs;

    // 2. The frame's water level: at the waterline, and by symmetry.
    let in_run = runs::in_run(cloud.len(), runs);
    let (far_shores, waterline_level) = level::waterline_level(runs, cfg);
    let (symmetry_level, pairs) = frame.symmetry_level(runs, &in_run, waterline_level)?;
    let frame_level = waterline_level.or(symmetry_level);

    // 3. Image check, evidence, corrected points.
    let mut marks = Marks::new(cloud, resolution, z_ref);
    let confirmed = frame.confirm_runs(
        runs,
        &in_run,
        frame_level,
        check.map(|c| (c, k)),
        &mut marks,
    );

    // 4. Below the known level (a level at or above the camera has no crossings in front
    // of it).
    let (level_points, span_cells) = match frame_level.filter(|&l| l < frame.o.z) {
        Some(l) => frame.below_known_level(l, &confirmed.water_from, resolution, &mut marks),
        None => (0, 0),
    };
    let seen = if surface_points {
        reflect::seen_of(
            cloud.cols,
            &frame.pts,
            &candidates.at_level,
            &in_run,
            &marks.reflected,
            &confirmed.water_from,
            frame_level,
        )
    } else {
        Vec::new()
    };
    Ok(StereoCues {
        evidence: marks.ev,
        corrected: marks.corrected,
        symmetry_level,
        pairs,
        waterline_level,
        far_shores,
        runs: confirmed.runs,
        level_points,
        span_cells,
        rejected_geometry: candidates.rejected_geometry + confirmed.rejected_geometry,
        rejected_image: confirmed.rejected_image,
        reflected_points: marks.reflected_points,
        seen,
    })
}

/// The whole factor `k` by which the check's image upsamples the cloud (1 without a
/// check); an error when the image is not such an upsample.
fn image_factor(cloud: &PointCloud, check: Option<MirrorCheck<'_>>) -> Result<usize> {
    Ok(match check {
        Some(c) => {
            if c.image.width % cloud.cols != 0
                || c.image.width / cloud.cols == 0
                || c.image.height != cloud.rows * (c.image.width / cloud.cols)
            {
                return Err(Error::invalid(
                    "stereo image",
                    format!(
                        "a {}×{} image is not a whole-factor upsample of the {}×{} cloud",
                        c.image.width, c.image.height, cloud.cols, cloud.rows
                    ),
                ));
            }
            c.image.width / cloud.cols
        }
        None => 1,
    })
}

/// One frame as every phase reads it: the cloud, its points in the map frame, the
/// camera's position and the cue's settings.
struct Frame<'a> {
    cloud: &'a PointCloud,
    cfg: &'a StereoCueConfig,
    rows: usize,
    cols: usize,
    /// The camera's position, map frame.
    o: Point3<f64>,
    /// Every element's point, map frame (NaN where the element is invalid).
    pts: Vec<Point3<f64>>,
    /// Map frame to the cloud's frame.
    to_frame: Pose,
}

impl<'a> Frame<'a> {
    fn new(cloud: &'a PointCloud, cfg: &'a StereoCueConfig) -> Self {
        let pts: Vec<Point3<f64>> = (0..cloud.len())
            .into_par_iter()
            .with_min_len(4096)
            .map(|i| cloud.point_in_map(i))
            .collect();
        Frame {
            cloud,
            cfg,
            rows: cloud.rows,
            cols: cloud.cols,
            o: cloud.sensor_origin_in_map(),
            pts,
            to_frame: cloud.frame_to_map.inverse(),
        }
    }
}

/// Whether `p` lies below `level` by more than its noise: `max(gate_min_m, gate_sigma·σ_v)`,
/// `σ_v` the vertical part of the range error along the ray from `o`.
fn below_level(p: Point3<f64>, o: Point3<f64>, level: f64, cfg: &StereoCueConfig) -> bool {
    p.z < o.z && p.z < level - gate_of(p, o, cfg)
}

/// `max(gate_min_m, gate_sigma·σ_v)` of a point seen from `o`.
fn gate_of(p: Point3<f64>, o: Point3<f64>, cfg: &StereoCueConfig) -> f64 {
    let range = (p - o).norm();
    let vertical = cfg.noise.sigma(range) * ((o.z - p.z).abs() / range.max(1e-9));
    cfg.gate_min_m.max(cfg.gate_sigma * vertical)
}

/// Whether the points `window` lie below `level` on average, weighted by `1/σ_v²`, by more
/// than `max(gate_min_m, gate_sigma·σ)` with `σ = 1/√Σw` the noise of that mean.
fn mean_below_level(
    window: &[usize],
    pts: &[Point3<f64>],
    o: Point3<f64>,
    level: f64,
    cfg: &StereoCueConfig,
) -> bool {
    let (mut sw, mut swd) = (0.0, 0.0);
    for &t in window {
        let q = pts[t];
        let range = (q - o).norm();
        let sv = cfg.noise.sigma(range) * ((o.z - q.z).abs() / range.max(1e-9));
        let w = 1.0 / (sv * sv).max(1e-12);
        sw += w;
        swd += w * (level - q.z);
    }
    sw > 0.0 && swd / sw > cfg.gate_min_m.max(cfg.gate_sigma / sw.sqrt())
}

#[cfg(test)]
mod tests;
