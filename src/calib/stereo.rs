//! The stereo cloud's range noise, measured from the log.
//!
//! Stereo measures disparity, and the disparity error is Gaussian (σ_d pixels of the
//! disparity image) whatever the range. Depth is z = f_k·B/d (f_k the focal length of the
//! disparity image, the camera's over the binning), so the *inverse* depth carries that
//! error unchanged in shape: 1/z_measured − 1/z_true = δd/(f_k·B), a Gaussian of σ
//! c = σ_d/(f_k·B) = σ_d·k/(f·B), the very coefficient of σ_z = a + c·z². One number,
//! at every range: the estimators below measure the spread of inverse-depth errors.
//!
//! - **Against the lidar** ([`StereoMethod::LidarSurface`]): where the lidar returned from
//!   flat ground in the same frame, each stereo pixel's ray is intersected with that ground
//!   (a fixed point of "cell under the crossing → height → crossing"), which gives the true
//!   depth along the same ray. The lidar surface's own height error, carried along the
//!   ray, is known per sample (`δ(1/z) = u_z·δh/(|d_z|·z²)`), so samples where it would
//!   matter are left out; what remains can only make the estimate larger.
//! - **From the cloud alone** ([`StereoMethod::Planes`]): on a plane, inverse depth is an
//!   affine function of the normalised image coordinates (X/Z, Y/Z), and the points of a
//!   row of the organized (rectified) cloud are equally spaced in X/Z. The second
//!   difference `w[c−1] − 2·w[c] + w[c+1]` of inverse depth along a row is therefore the
//!   noise alone on any locally planar surface, with variance 6·c²; an outlier touches
//!   only the three differences around it. Ground that is not planar (edges, vegetation)
//!   makes the estimate larger, never smaller. Disparity noise correlated across
//!   neighbouring pixels (block matchers) would make it smaller: the lidar method has no
//!   such bias, and is preferred where it exists.
//!
//! Both are robust (medians of absolute deviations): reflections on water, mixed pixels
//! at depth edges and rays that meet a trunk before the ground are a minority of outliers.
//! Matches whose disparity nears the matcher's minimum are truncated, which would bias the
//! spread low. The farthest depth the cloud reports, z_far, is where the disparity reaches
//! that minimum d_min (z_far = f_k·B/d_min), so σ_d = c·z_far·d_min: only samples whose
//! disparity lies three σ_d above the minimum, at depths z ≤ z_far/(1 + 3·c·z_far), are
//! used, with c the estimate itself (starting from z_far/4, a disparity of four times the
//! minimum). The depth a sample is judged by is free of its own noise: the lidar's, or
//! the mean of the three points of a second difference.

use serde::{Deserialize, Serialize};

use super::robust::{mad_sigma, Pool};
use crate::geom::PointCloud;

/// Side of the lidar ground cells the stereo rays are intersected with, metres.
const CELL_M: f64 = 0.25;
/// A lidar cell is flat ground when its heights spread by at most this (one σ, metres).
const FLAT_SD_M: f64 = 0.03;
/// Fewest lidar returns in a flat cell.
const CELL_MIN_RETURNS: u32 = 3;
/// Stereo pixels examined per frame, at most (a stride over the cloud).
const PIXELS_PER_FRAME: usize = 30_000;
/// Samples kept per method (the newest).
const POOL: usize = 60_000;
/// Samples a method needs before its estimate counts.
pub(crate) const MIN_SAMPLES: usize = 1_000;

/// How a stereo noise measurement was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StereoMethod {
    /// Stereo rays against the flat ground the lidar measured in the same frames.
    LidarSurface,
    /// Local planes of the stereo cloud's own inverse depth (second differences along its
    /// rows).
    Planes,
}

/// A measured stereo noise coefficient.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StereoMeasurement {
    /// c of σ_z = a + c·z² (1/m): the σ of inverse depth.
    pub per_m2: f64,
    /// How it was measured.
    pub method: StereoMethod,
    /// Samples it rests on.
    pub samples: usize,
}

/// Measures the stereo noise coefficient over the frames it is shown.
#[derive(Debug, Clone)]
pub(crate) struct StereoNoiseEstimator {
    /// Inverse-depth error against the lidar, the lidar surface's share of it, and the
    /// lidar's depth.
    lidar: Pool<[f32; 3]>,
    /// Second differences of inverse depth along rows, over √6, and the triple's depth.
    planes: Pool<[f32; 2]>,
    /// Farthest stereo depth seen, metres.
    far: f64,
    cells: LidarCells,
}

impl Default for StereoNoiseEstimator {
    fn default() -> Self {
        StereoNoiseEstimator {
            lidar: Pool::new(POOL),
            planes: Pool::new(POOL),
            far: 0.0,
            cells: LidarCells::default(),
        }
    }
}

impl StereoNoiseEstimator {
    /// Adds one frame: its stereo cloud (in the left camera's optical frame, z forward),
    /// and its lidar scan when the frame has one.
    pub(crate) fn observe(&mut self, stereo: &PointCloud, lidar: Option<&PointCloud>) {
        for p in &stereo.xyz {
            let z = (p[2] as f64) - stereo.sensor_origin.z;
            if p.iter().all(|v| v.is_finite()) && z.is_finite() && z > self.far {
                self.far = z;
            }
        }
        let z_max = self.far;
        if z_max <= 0.0 {
            return;
        }
        if let Some(l) = lidar {
            self.cells.rebuild(l);
            if !self.cells.is_empty() {
                self.against_lidar(stereo, z_max);
            }
        }
        if stereo.is_organized() {
            self.planes_of(stereo, z_max);
        }
    }

    /// The stereo rays of `stereo` against the lidar cells.
    fn against_lidar(&mut self, stereo: &PointCloud, z_max: f64) {
        let o = stereo.sensor_origin_in_map();
        let rot = stereo.frame_to_map.rotation;
        let stride = stereo.len().div_ceil(PIXELS_PER_FRAME).max(1);
        for i in (0..stereo.len()).step_by(stride) {
            if !stereo.is_valid(i) {
                continue;
            }
            let q = stereo.xyz[i];
            let v = nalgebra::Vector3::new(q[0] as f64, q[1] as f64, q[2] as f64)
                - stereo.sensor_origin.coords;
            let (z_s, norm) = (v.z, v.norm());
            // The cut to near depths is on the lidar's depth below, never on the noisy
            // stereo depth, which would truncate the very spread being measured.
            if !(z_s > 0.0 && norm > 0.0) {
                continue;
            }
            let u = v / norm;
            let d = rot * u;
            if d.z > -0.02 {
                continue;
            }
            // Start from the scan's typical ground level, never from the stereo point:
            // where the noisy point lands must not decide which samples are kept.
            let t0 = (self.cells.level - o.z) / d.z;
            if t0.is_nan() || t0 <= 0.0 {
                continue;
            }
            let x0 = o + d * t0;
            let Some(mut cell) = self.cells.at(x0.x, x0.y) else {
                continue;
            };
            let mut t = 0.0;
            let mut converged = false;
            for _ in 0..6 {
                t = (cell.h - o.z) / d.z;
                if t.is_nan() || t <= 0.0 {
                    break;
                }
                let x = o + d * t;
                match self.cells.at(x.x, x.y) {
                    Some(c) if (c.h - cell.h).abs() < 1e-4 => {
                        converged = true;
                        break;
                    }
                    Some(c) => cell = c,
                    None => break,
                }
            }
            if !converged {
                continue;
            }
            let z_l = t * u.z;
            if !(z_l > 0.0 && z_l <= z_max) {
                continue;
            }
            let e = 1.0 / z_s - 1.0 / z_l;
            let share = u.z * cell.sd / (-d.z * z_l * z_l);
            self.lidar.push([e as f32, share as f32, z_l as f32]);
        }
    }

    /// Second differences of inverse depth along the rows of the organized cloud.
    fn planes_of(&mut self, stereo: &PointCloud, z_max: f64) {
        if stereo.cols < 3 {
            return;
        }
        let w = |i: usize| -> Option<f64> {
            if !stereo.is_valid(i) {
                return None;
            }
            let z = stereo.xyz[i][2] as f64 - stereo.sensor_origin.z;
            (z > 0.0).then(|| 1.0 / z)
        };
        let stride = stereo.len().div_ceil(PIXELS_PER_FRAME).max(1);
        let mut n = 0usize;
        for r in 0..stereo.rows {
            for c in 1..stereo.cols - 1 {
                n += 1;
                if n % stride != 0 {
                    continue;
                }
                let i = stereo.index(r, c);
                let (Some(a), Some(b), Some(d)) = (w(i - 1), w(i), w(i + 1)) else {
                    continue;
                };
                // Near triples only, judged by their mean, which is independent of the
                // second difference (for Gaussian noise): a cut on the noisy middle point
                // would truncate the spread being measured.
                let w = (a + b + d) / 3.0;
                if w * z_max >= 1.0 {
                    self.planes
                        .push([((a - 2.0 * b + d) / 6f64.sqrt()) as f32, (1.0 / w) as f32]);
                }
            }
        }
    }

    /// The noise coefficient measured so far: against the lidar when that has enough
    /// samples, else from the cloud's local planes; `None` until either has
    /// [`MIN_SAMPLES`]. ([`super::Calibration`] asks each method itself, to report both.)
    #[cfg(test)]
    pub(crate) fn estimate(&self) -> Option<StereoMeasurement> {
        self.by_lidar().or_else(|| self.by_planes())
    }

    /// The depth below which matches are free of the matcher's truncation, for a noise
    /// coefficient `c` (`None`: the first guess, a quarter of the farthest depth).
    fn untruncated(&self, c: Option<f64>) -> f64 {
        match c {
            Some(c) => self.far / (1.0 + 3.0 * c * self.far),
            None => self.far / 4.0,
        }
    }

    /// `estimate` over the samples nearer than the untruncated depth, refined twice with
    /// the coefficient it gives.
    fn with_cut<T: Copy>(
        &self,
        pool: &Pool<T>,
        depth: impl Fn(&T) -> f64,
        estimate: impl Fn(&[T]) -> Option<f64>,
    ) -> Option<(f64, usize)> {
        let mut c = None;
        let mut n = 0;
        for _ in 0..3 {
            let cut = self.untruncated(c);
            let kept: Vec<T> = pool.iter().copied().filter(|s| depth(s) <= cut).collect();
            if kept.len() < MIN_SAMPLES {
                return c.map(|c| (c, n));
            }
            n = kept.len();
            c = Some(estimate(&kept)?);
        }
        c.map(|c| (c, n))
    }

    /// The measurement against the lidar alone (`None` below [`MIN_SAMPLES`]).
    pub(crate) fn by_lidar(&self) -> Option<StereoMeasurement> {
        let (c, samples) = self.with_cut(
            &self.lidar,
            |s| s[2] as f64,
            |kept| {
                let c0 = mad_sigma(kept.iter().map(|s| s[0] as f64))?;
                // Where the lidar surface's error would be a noticeable part of the
                // spread, leave the sample out: what remains adds at most 5 % (in
                // quadrature), never subtracted.
                let near: Vec<f64> = kept
                    .iter()
                    .filter(|s| (s[1] as f64) <= 0.3 * c0)
                    .map(|s| s[0] as f64)
                    .collect();
                if near.len() < MIN_SAMPLES {
                    return None;
                }
                mad_sigma(near.into_iter())
            },
        )?;
        (c.is_finite() && c > 0.0).then_some(StereoMeasurement {
            per_m2: c,
            method: StereoMethod::LidarSurface,
            samples,
        })
    }

    /// The measurement from the cloud's local planes alone (`None` below [`MIN_SAMPLES`]).
    pub(crate) fn by_planes(&self) -> Option<StereoMeasurement> {
        let (c, samples) = self.with_cut(
            &self.planes,
            |s| s[1] as f64,
            |kept| mad_sigma(kept.iter().map(|s| s[0] as f64)),
        )?;
        (c.is_finite() && c > 0.0).then_some(StereoMeasurement {
            per_m2: c,
            method: StereoMethod::Planes,
            samples,
        })
    }
}

/// One flat lidar ground cell: its mean height and the spread of its returns (m).
#[derive(Debug, Clone, Copy)]
struct Cell {
    h: f64,
    sd: f64,
}

/// The flat ground cells of one lidar scan, in the map frame, sorted by key.
#[derive(Debug, Clone, Default)]
struct LidarCells {
    /// The median height of the flat cells.
    level: f64,
    keys: Vec<(i64, i64)>,
    cells: Vec<Cell>,
    scratch: Vec<((i64, i64), f64)>,
}

impl LidarCells {
    fn key(x: f64, y: f64) -> (i64, i64) {
        (
            crate::geom::floor_i64(x / CELL_M),
            crate::geom::floor_i64(y / CELL_M),
        )
    }

    fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    fn rebuild(&mut self, lidar: &PointCloud) {
        self.keys.clear();
        self.cells.clear();
        self.scratch.clear();
        for i in 0..lidar.len() {
            if lidar.is_valid(i) {
                let p = lidar.point_in_map(i);
                if p.iter().all(|v| v.is_finite() && v.abs() < 1e9) {
                    self.scratch.push((Self::key(p.x, p.y), p.z));
                }
            }
        }
        self.scratch
            .sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
        let mut i = 0;
        while i < self.scratch.len() {
            let k = self.scratch[i].0;
            let j = i + self.scratch[i..].partition_point(|s| s.0 == k);
            let zs = &self.scratch[i..j];
            let n = zs.len() as f64;
            if zs.len() as u32 >= CELL_MIN_RETURNS {
                let h = zs.iter().map(|s| s.1).sum::<f64>() / n;
                let sd = (zs.iter().map(|s| (s.1 - h).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
                if sd <= FLAT_SD_M {
                    self.keys.push(k);
                    self.cells.push(Cell {
                        h,
                        sd: sd.max(0.003),
                    });
                }
            }
            i = j;
        }
        let mut h: Vec<f64> = self.cells.iter().map(|c| c.h).collect();
        self.level = super::robust::median(&mut h).unwrap_or(0.0);
    }

    fn at(&self, x: f64, y: f64) -> Option<Cell> {
        self.keys
            .binary_search(&Self::key(x, y))
            .ok()
            .map(|i| self.cells[i])
    }
}
