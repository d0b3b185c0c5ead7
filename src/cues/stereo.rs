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

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Point3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::EvidenceMap;
use crate::error::{Error, Result};
use crate::geom::camera::CameraModel;
use crate::geom::PointCloud;
use crate::grid::{key_of, CellKey, RangeNoise};

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
    /// colour labels' check: empty unless [`stereo_reflections_with`] was asked for it.
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

/// One candidate run: slots (bottom to top) and the shore level before it.
struct Run {
    slots: Vec<usize>,
    shore: f64,
    /// The height of the terrain that ended the run (the far shore, where the reflection
    /// meets what it reflects), when terrain nearer than the run ended it.
    far: Option<f64>,
}

/// Finds reflections in an organized stereo cloud (rows top to bottom as in the image).
/// `resolution` and `z_ref` are the grid's.
pub fn stereo_reflections(
    cloud: &PointCloud,
    resolution: f64,
    z_ref: f64,
    check: Option<MirrorCheck<'_>>,
    cfg: &StereoCueConfig,
) -> Result<StereoCues> {
    stereo_reflections_with(cloud, resolution, z_ref, check, cfg, false)
}

/// [`stereo_reflections`], filling [`StereoCues::seen`] only when `surface_points` (the
/// image labels' colour check reads it).
pub fn stereo_reflections_with(
    cloud: &PointCloud,
    resolution: f64,
    z_ref: f64,
    check: Option<MirrorCheck<'_>>,
    cfg: &StereoCueConfig,
    surface_points: bool,
) -> Result<StereoCues> {
    cloud.validate()?;
    cfg.validate()?;
    if !cloud.is_organized() {
        return Err(Error::invalid(
            "stereo cloud",
            "the reflection cue needs an organized cloud (rows × cols)",
        ));
    }
    let k = match check {
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
    };
    let (rows, cols) = (cloud.rows, cloud.cols);
    let o = cloud.sensor_origin_in_map();
    let pts: Vec<Point3<f64>> = (0..cloud.len())
        .into_par_iter()
        .with_min_len(4096)
        .map(|i| cloud.point_in_map(i))
        .collect();

    // 1. Candidate runs up each column (columns are independent: in parallel, and
    // gathered in column order so the result does not depend on the threads).
    let per_column: Vec<(Vec<Run>, usize, Vec<usize>)> = (0..cols)
        .into_par_iter()
        .map(|c| {
            let mut runs: Vec<Run> = Vec::new();
            let mut rejected_geometry = 0;
            // Points at the local ground level within their own vertical noise `σ_v`.
            let mut at_level: Vec<usize> = Vec::new();
            let mut z_g: Option<f64> = None;
            let mut h_g = 0.0;
            let mut invalid_since_ground = 0usize;
            let mut run: Vec<usize> = Vec::new();
            let mut run_gap = false;
            let mut run_shore = 0.0;
            let mut run_min_h = f64::INFINITY;
            // A run is a reflection when it follows a gap and the terrain seen after it, up
            // the column, is *nearer* than the run (by `gap_min_m` than its median distance:
            // range wraps backward, the virtual image lies beyond the far shore; the bottom
            // of a ditch lies before its far side). With nothing after it, its own ranges
            // must wrap.
            let close = |run: &mut Vec<usize>,
                         gap: bool,
                         shore: f64,
                         next: Option<(f64, f64, f64)>,
                         runs: &mut Vec<Run>,
                         rej: &mut usize| {
                if run.is_empty() {
                    return;
                }
                let slots = std::mem::take(run);
                let rng = |s: usize| (pts[s] - o).norm();
                let hor = |s: usize| crate::geom::hypot(pts[s].x - o.x, pts[s].y - o.y);
                let wraps = match next {
                    Some((hn, _, _)) => {
                        // The run's distance is its median: its nearest point is the one
                        // that range noise pulled nearest (σ ≈ 1 m at 20 m).
                        let mut hs: Vec<f64> = slots.iter().map(|&s| hor(s)).collect();
                        let m = hs.len() / 2;
                        let mid = *hs.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1;
                        hn < mid - cfg.gap_min_m
                    }
                    None => {
                        let steps = slots.len() - 1;
                        let back = slots.windows(2).filter(|w| rng(w[1]) < rng(w[0])).count();
                        steps > 0 && back as f64 >= cfg.wrap_fraction * steps as f64
                    }
                };
                if slots.len() >= cfg.min_run && gap && wraps {
                    runs.push(Run {
                        slots,
                        shore,
                        // A far shore more than the tolerance (and its noise) below the
                        // near one is not this water's edge: more reflection that range
                        // noise pulled nearer than the run ended it.
                        far: next.and_then(|(_, z, sv)| {
                            (z >= shore - cfg.level_tolerance_m - cfg.gate_sigma * sv).then_some(z)
                        }),
                    });
                } else {
                    *rej += 1;
                }
            };
            for r in (0..rows).rev() {
                let s = r * cols + c;
                if !cloud.is_valid(s) {
                    if run.is_empty() {
                        invalid_since_ground += 1;
                    }
                    continue;
                }
                let p = pts[s];
                let h = crate::geom::hypot(p.x - o.x, p.y - o.y);
                let Some(zg) = z_g else {
                    z_g = Some(p.z);
                    h_g = h;
                    continue;
                };
                // Stereo error lies along the ray: its vertical part is σ(r)·|sin(depression)|.
                let range = (p - o).norm();
                let vertical = cfg.noise.sigma(range) * ((o.z - p.z).abs() / range.max(1e-9));
                let gate = cfg.gate_min_m.max(cfg.gate_sigma * vertical);
                let below = p.z < zg - gate && p.z < o.z;
                if surface_points && p.z < o.z && (p.z - zg).abs() <= vertical {
                    at_level.push(s);
                }
                if let Some(&last) = run.last() {
                    // Inside a run, points below the level whose range keeps wrapping backward
                    // are the upper part of the same virtual image.
                    // Terrain much nearer than the run (the far shore) ends it.
                    let wrapping = range < (pts[last] - o).norm();
                    let nearer = h < run_min_h - cfg.gap_min_m;
                    if !nearer && (below || (p.z < zg && wrapping)) {
                        run_min_h = run_min_h.min(h);
                        run.push(s);
                        continue;
                    }
                    close(
                        &mut run,
                        run_gap,
                        run_shore,
                        Some((h, p.z, vertical)),
                        &mut runs,
                        &mut rejected_geometry,
                    );
                }
                if below {
                    // A new run (also right after one that nearer terrain ended).
                    run_gap = h - h_g > cfg.gap_min_m || (invalid_since_ground > 0 && h > h_g);
                    run_shore = zg;
                    run_min_h = h;
                    run.push(s);
                    continue;
                }
                if p.z - zg <= cfg.above_gate_m {
                    z_g = Some(p.z);
                    h_g = h;
                    invalid_since_ground = 0;
                }
            }
            close(
                &mut run,
                run_gap,
                run_shore,
                None,
                &mut runs,
                &mut rejected_geometry,
            );
            (runs, rejected_geometry, at_level)
        })
        .collect();
    let mut rejected_geometry: usize = per_column.iter().map(|c| c.1).sum();
    let mut at_level: Vec<usize> = Vec::new();
    let mut runs: Vec<Run> = Vec::new();
    for (r, _, l) in per_column {
        runs.extend(r);
        at_level.extend(l);
    }

    // 2. Water level by symmetry (one-parameter ICP against the non-reflected points).
    let mut in_run = vec![false; cloud.len()];
    for r in &runs {
        for &s in &r.slots {
            in_run[s] = true;
        }
    }
    // The waterline: where a run meets the far shore that ended it. A bank facing the
    // camera is seen down to the water, and points there are near the level, where the
    // vertical part of the range error is smallest; the near bank may face away and
    // hide the water's edge. The median of the far shores, when there are enough.
    let mut fars: Vec<f64> = runs.iter().filter_map(|r| r.far).collect();
    let far_shores = fars.len();
    let waterline_level = (far_shores >= cfg.min_far_shores.max(1)).then(|| {
        let m = fars.len() / 2;
        *fars.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1
    });
    let (mut symmetry_level, mut pairs) = (None, 0);
    if !runs.is_empty() {
        let mut shores: Vec<f64> = runs.iter().map(|r| r.shore).collect();
        let m = shores.len() / 2;
        shores.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
        // Water stands at or below its shores: start from the lower of the two.
        let mut level = waterline_level.map_or(shores[m], |w| w.min(shores[m]));
        // Reflected points to pair: at most 4096, by a fixed stride (deterministic).
        let all: Vec<usize> = runs.iter().flat_map(|r| r.slots.iter().copied()).collect();
        let stride = all.len().div_ceil(4096).max(1);
        let reflected: Vec<usize> = all.iter().copied().step_by(stride).collect();
        // Sources: real points above the level, inside the reflected points' footprint.
        let (mut x0, mut y0, mut x1, mut y1) = (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        );
        for &s in &reflected {
            x0 = x0.min(pts[s].x);
            y0 = y0.min(pts[s].y);
            x1 = x1.max(pts[s].x);
            y1 = y1.max(pts[s].y);
        }
        let pad = cfg.pair_radius_m;
        let sources: Vec<[f64; 3]> = (0..cloud.len())
            .filter(|&s| {
                cloud.is_valid(s)
                    && !in_run[s]
                    && pts[s].z > level - cfg.level_tolerance_m
                    && pts[s].x >= x0 - pad
                    && pts[s].x <= x1 + pad
                    && pts[s].y >= y0 - pad
                    && pts[s].y <= y1 + pad
            })
            .map(|s| [pts[s].x, pts[s].y, pts[s].z])
            .collect();
        if sources.len() >= cfg.min_pairs.max(1) {
            let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&sources)
                .map_err(|e| Error::invalid("stereo reflection pairing", format!("{e:?}")))?;
            let r2 = cfg.pair_radius_m * cfg.pair_radius_m;
            for _ in 0..6 {
                let mut dz: Vec<f64> = reflected
                    .par_iter()
                    .with_min_len(256)
                    .filter_map(|&s| {
                        let p = pts[s];
                        let q = [p.x, p.y, 2.0 * level - p.z];
                        let nn = tree
                            .query(&q)
                            .nearest_one::<SquaredEuclidean<f64>>()
                            .execute();
                        (nn.distance <= r2).then(|| sources[nn.item as usize][2] - q[2])
                    })
                    .collect();
                if dz.len() < cfg.min_pairs {
                    pairs = 0;
                    break;
                }
                pairs = dz.len();
                let m = dz.len() / 2;
                dz.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
                let step = 0.5 * dz[m];
                level += step;
                if step.abs() < 1e-4 {
                    break;
                }
            }
            if pairs >= cfg.min_pairs {
                symmetry_level = Some(level);
            }
        }
    }

    // 3. Image check, evidence, corrected points.
    let to_frame = cloud.frame_to_map.inverse();
    let mut ev = EvidenceMap::new(resolution, z_ref);
    let mut corrected = cloud.clone();
    let (mut confirmed, mut rejected_image, mut reflected_points) = (0, 0, 0);
    let mut reflected = vec![false; cloud.len()];
    let mut water_from: Vec<Option<usize>> = vec![None; cols];
    // Evidence where the ray to reflected point `s` crosses the level, and the mirrored
    // point `m` (map frame) in place of the raw one.
    let reflect_at =
        |ev: &mut EvidenceMap, corrected: &mut PointCloud, s: usize, level: f64, m: Point3<f64>| {
            let p = pts[s];
            let t = (o.z - level) / (o.z - p.z);
            let cx = o.x + (p.x - o.x) * t;
            let cy = o.y + (p.y - o.y) * t;
            ev.add_with_level(cx, cy, level, |e| e.reflect = e.reflect.saturating_add(1));
            let q = to_frame * m;
            corrected.xyz[s] = [q.x as f32, q.y as f32, q.z as f32];
        };
    for run in &runs {
        // Water stands at or below its shores. The frame's level (the waterline, else
        // symmetry) replaces the shore level when it lies below it, by any amount: the
        // shore is a bank that hides the water's edge, or a point seen a little up the
        // bank. A frame level above the shore cannot be this water's: the shore stands.
        // (With the shore kept whenever it was within its noise of the frame's level, or
        // the frame's level taken only within an absolute tolerance of 0.3 m, the
        // simulated fig4 pond, whose near bank is 0.3 m high, laid some runs'
        // reflections on the bank: 189 dry cells called water against 153.)
        let level = match waterline_level.or(symmetry_level) {
            Some(l) if l < run.shore => l,
            _ => run.shore,
        };
        // A reflection lies below the water: points of the run that are not below the
        // level by more than their vertical noise are terrain (a far shore lower than
        // the near bank), not a virtual image.
        let slots: Vec<usize> = run
            .slots
            .iter()
            .copied()
            .filter(|&s| below_level(pts[s], o, level, cfg))
            .collect();
        if slots.len() < cfg.min_run {
            rejected_geometry += 1;
            continue;
        }
        let mirrored: Vec<Point3<f64>> = slots
            .iter()
            .map(|&s| Point3::new(pts[s].x, pts[s].y, 2.0 * level - pts[s].z))
            .collect();
        if let Some(chk) = check {
            let kk = k as f64;
            let half = (kk - 1.0) / 2.0;
            let (mut a, mut b) = (Vec::new(), Vec::new());
            for (&s, m) in slots.iter().zip(&mirrored) {
                let (row, col) = (s / cols, s % cols);
                let here = chk
                    .image
                    .sample(kk * col as f64 + half, kk * row as f64 + half);
                // Use the mirrored point only where the camera sees it (the stereo point at
                // its pixel is the mirrored point itself, not something in front of it).
                let there = chk.camera.project(&(to_frame * m)).and_then(|[u, v]| {
                    let (cr, cc) = (((v - half) / kk).round(), ((u - half) / kk).round());
                    if !(cr >= 0.0 && cc >= 0.0 && (cr as usize) < rows && (cc as usize) < cols) {
                        return None;
                    }
                    let t = cr as usize * cols + cc as usize;
                    let seen = cloud.is_valid(t) && !in_run[t] && {
                        let d = (pts[t] - m).norm();
                        d <= cfg
                            .pair_radius_m
                            .max(cfg.gate_sigma * cfg.noise.sigma((m - o).norm()))
                    };
                    if seen {
                        chk.image.sample(u, v)
                    } else {
                        None
                    }
                });
                if let (Some(x), Some(y)) = (here, there) {
                    a.push(x);
                    b.push(y);
                }
            }
            if let Some(r) = ncc(&a, &b) {
                if r < cfg.min_ncc {
                    rejected_image += 1;
                    continue;
                }
            }
        }
        confirmed += 1;
        for (&s, m) in slots.iter().zip(&mirrored) {
            reflect_at(&mut ev, &mut corrected, s, level, *m);
            reflected[s] = true;
            reflected_points += 1;
        }
        // The column's water starts at its nearest confirmed run (the walk goes up the
        // column, bottom row first).
        let (row, col) = (run.slots[0] / cols, run.slots[0] % cols);
        water_from[col] = Some(water_from[col].map_or(row, |r: usize| r.max(row)));
    }

    // 4. Below the known level. Once a column has met confirmed water and the frame has a
    // level, the points further up that column are judged against the level alone,
    // whatever the run structure around them. Far out, where the rays graze the water and
    // reflect the far bank and the grass a few decimetres above it, the virtual images lie
    // within the gate of the local ground, their ranges need not wrap, and range noise
    // scatters them past the far shore, so the runs miss them. A point is a reflection
    // when it lies below the level by more than its vertical noise, or when it lies below
    // the level and the `level_window` valid points either side of it in the column (with
    // it) lie below the level on average by more than the noise of that weighted mean
    // (`gate_sigma / √Σw`, `w = 1/σ_v²`): a virtual image 0.3 m deep at 22 m is within one
    // point's 3σ_v, not within that of five. Only columns with a confirmed run take part:
    // ground below the level elsewhere (the far side of a rise, a dry ditch) is not this
    // water.
    //
    // Between two consecutive reflections up a column the level is crossed by every ray
    // between theirs: at 20 m one cloud row spans more than a metre of water, which one
    // crossing cell alone leaves unseen. Each cell strictly between the two crossings gets
    // one reflection count. A point at or above the level between them (the surface
    // itself, ground, an object) ends the span; a point below the level within its noise
    // does not.
    let mut level_points = 0;
    let mut span_cells = 0;
    // (A level at or above the camera has no crossings in front of it.)
    if let Some(l) = waterline_level.or(symmetry_level).filter(|&l| l < o.z) {
        let crossing = |s: usize| {
            let p = pts[s];
            let t = (o.z - l) / (o.z - p.z);
            (o.x + (p.x - o.x) * t, o.y + (p.y - o.y) * t)
        };
        let per_column: Vec<(Vec<usize>, Vec<CellKey>)> = water_from
            .par_iter()
            .enumerate()
            .map(|(c, from)| {
                let (mut new, mut span) = (Vec::new(), Vec::new());
                let Some(r0) = *from else {
                    return (new, span);
                };
                let valid: Vec<usize> = (0..=r0)
                    .rev()
                    .map(|r| r * cols + c)
                    .filter(|&s| cloud.is_valid(s))
                    .collect();
                let mut last: Option<(f64, f64)> = None;
                for (i, &s) in valid.iter().enumerate() {
                    let p = pts[s];
                    let w = cfg.level_window;
                    let window = &valid[i.saturating_sub(w)..(i + w + 1).min(valid.len())];
                    let is_reflection = reflected[s]
                        || below_level(p, o, l, cfg)
                        || (w > 0 && p.z < l && mean_below_level(window, &pts, o, l, cfg));
                    if is_reflection {
                        if !reflected[s] {
                            new.push(s);
                        }
                        let here = crossing(s);
                        if let Some(prev) = last {
                            span_cells_between(resolution, prev, here, &mut span);
                        }
                        last = Some(here);
                    } else if p.z >= l {
                        last = None;
                    }
                }
                (new, span)
            })
            .collect();
        for (new, span) in per_column {
            for s in new {
                let m = Point3::new(pts[s].x, pts[s].y, 2.0 * l - pts[s].z);
                reflect_at(&mut ev, &mut corrected, s, l, m);
                reflected[s] = true;
                level_points += 1;
                reflected_points += 1;
            }
            for k in span {
                let (x, y) = crate::grid::centre_of(resolution, k);
                ev.add_with_level(x, y, l, |e| e.reflect = e.reflect.saturating_add(1));
                span_cells += 1;
            }
        }
    }
    let seen = if surface_points {
        seen_of(
            cloud.cols,
            &pts,
            &at_level,
            &in_run,
            &reflected,
            &water_from,
            waterline_level.or(symmetry_level),
        )
    } else {
        Vec::new()
    };
    Ok(StereoCues {
        evidence: ev,
        corrected,
        symmetry_level,
        pairs,
        waterline_level,
        far_shores,
        runs: confirmed,
        level_points,
        span_cells,
        rejected_geometry,
        rejected_image,
        reflected_points,
        seen,
    })
}

/// [`StereoCues::seen`] from the walk's points at the ground level within their `σ_v`
/// (`at_level`, in any order), the points of candidate runs, the reflections, each
/// column's first row of confirmed water and the frame's water level.
fn seen_of(
    cols: usize,
    pts: &[Point3<f64>],
    at_level: &[usize],
    in_run: &[bool],
    reflected: &[bool],
    water_from: &[Option<usize>],
    level: Option<f64>,
) -> Vec<StereoSeen> {
    let mut seen: Vec<StereoSeen> = reflected
        .iter()
        .map(|&r| {
            if r {
                StereoSeen::NotGround
            } else {
                StereoSeen::Nothing
            }
        })
        .collect();
    for &s in at_level {
        let water_up = water_from[s % cols].is_some_and(|r0| s / cols <= r0);
        if in_run[s] || reflected[s] || (water_up && level.is_none_or(|l| pts[s].z < l)) {
            continue;
        }
        seen[s] = StereoSeen::Ground;
    }
    seen
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

/// Longest span between two consecutive level crossings that is filled, metres: neighbouring
/// rays of a stereo camera cross a level metres apart, not this far (a corrupted point would
/// otherwise make a walk of its whole distance).
const MAX_SPAN_M: f64 = 100.0;

/// The cells the segment `a`–`b` passes through, strictly between the cells of its ends,
/// in order from `a`. Nothing for a segment longer than [`MAX_SPAN_M`] (or not finite).
fn span_cells_between(res: f64, a: (f64, f64), b: (f64, f64), out: &mut Vec<CellKey>) {
    let len = (b.0 - a.0).hypot(b.1 - a.1);
    if len.is_nan() || len > MAX_SPAN_M {
        return;
    }
    let (ka, kb) = (key_of(res, a.0, a.1), key_of(res, b.0, b.1));
    let n = (len / (0.25 * res)).ceil() as usize;
    let mut prev = ka;
    for i in 1..n {
        let f = i as f64 / n as f64;
        let k = key_of(res, a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f);
        if k != prev && k != ka && k != kb {
            out.push(k);
        }
        prev = k;
    }
}

/// Normalised cross-correlation; `None` with fewer than 3 samples or no texture.
fn ncc(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len();
    if n < 3 {
        return None;
    }
    let ma = a.iter().sum::<f64>() / n as f64;
    let mb = b.iter().sum::<f64>() / n as f64;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    let scale = (ma.abs() + mb.abs()).max(1e-12);
    if saa.sqrt() < 1e-6 * scale * n as f64 || sbb.sqrt() < 1e-6 * scale * n as f64 {
        return None;
    }
    Some(sab / (saa * sbb).sqrt())
}

#[cfg(test)]
mod tests;
