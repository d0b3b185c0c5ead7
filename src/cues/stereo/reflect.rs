//! The last phases of the stereo reflection cue: the runs confirmed against the frame's
//! level and the image, then the points below the known level up the columns with
//! confirmed water; what they write (evidence where the rays cross the water, the mirrored
//! cloud), and what each element says of the surface under its pixel.

use nalgebra::Point3;
use rayon::prelude::*;

use super::runs::Run;
use super::{below_level, mean_below_level, Frame, MirrorCheck, StereoSeen};
use crate::cues::EvidenceMap;
use crate::geom::PointCloud;
use crate::grid::{key_of, CellKey};

/// What the confirmed reflections write: evidence by cell, the cloud with each reflected
/// point replaced by its mirror image, and which elements are reflections.
pub(super) struct Marks {
    pub(super) ev: EvidenceMap,
    pub(super) corrected: PointCloud,
    pub(super) reflected: Vec<bool>,
    /// Points found to be reflections (in runs and below the known level).
    pub(super) reflected_points: usize,
}

impl Marks {
    /// Nothing reflected yet: empty evidence on the grid, the cloud as it came.
    pub(super) fn new(cloud: &PointCloud, resolution: f64, z_ref: f64) -> Self {
        Marks {
            ev: EvidenceMap::new(resolution, z_ref),
            corrected: cloud.clone(),
            reflected: vec![false; cloud.len()],
            reflected_points: 0,
        }
    }
}

/// The verdicts on the candidate runs.
pub(super) struct Confirmed {
    /// Runs confirmed.
    pub(super) runs: usize,
    /// Runs with too few points below the level.
    pub(super) rejected_geometry: usize,
    /// Runs rejected by the image check.
    pub(super) rejected_image: usize,
    /// Each column's first row of confirmed water (its nearest confirmed run's bottom row).
    pub(super) water_from: Vec<Option<usize>>,
}

impl Frame<'_> {
    /// Evidence where the ray to reflected point `s` crosses the level, and the mirrored
    /// point `m` (map frame) in place of the raw one.
    fn reflect_at(&self, marks: &mut Marks, s: usize, level: f64, m: Point3<f64>) {
        let (p, o) = (self.pts[s], self.o);
        let t = (o.z - level) / (o.z - p.z);
        let cx = o.x + (p.x - o.x) * t;
        let cy = o.y + (p.y - o.y) * t;
        marks
            .ev
            .add_with_level(cx, cy, level, |e| e.reflect = e.reflect.saturating_add(1));
        let q = self.to_frame * m;
        marks.corrected.xyz[s] = [q.x as f32, q.y as f32, q.z as f32];
    }

    /// Judges each candidate run against the frame's level and, with `check` (and the
    /// image's upsampling factor), the image; marks the points of those confirmed.
    pub(super) fn confirm_runs(
        &self,
        runs: &[Run],
        in_run: &[bool],
        frame_level: Option<f64>,
        check: Option<(MirrorCheck<'_>, usize)>,
        marks: &mut Marks,
    ) -> Confirmed {
        let (pts, o, cfg, cols) = (&self.pts, self.o, self.cfg, self.cols);
        let mut out = Confirmed {
            runs: 0,
            rejected_geometry: 0,
            rejected_image: 0,
            water_from: vec![None; cols],
        };
        for run in runs {
            // Water stands at or below its shores. The frame's level (the waterline, else
            // symmetry) replaces the shore level when it lies below it, by any amount: the
            // shore is a bank that hides the water's edge, or a point seen a little up the
            // bank. A frame level above the shore cannot be this water's: the shore stands.
            // (With the shore kept whenever it was within its noise of the frame's level, or
            // the frame's level taken only within an absolute tolerance of 0.3 m, the
            // simulated fig4 pond, whose near bank is 0.3 m high, laid some runs'
            // reflections on the bank: 189 dry cells called water against 153.)
            let level = match frame_level {
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
                out.rejected_geometry += 1;
                continue;
            }
            let mirrored: Vec<Point3<f64>> = slots
                .iter()
                .map(|&s| Point3::new(pts[s].x, pts[s].y, 2.0 * level - pts[s].z))
                .collect();
            if let Some((chk, k)) = check {
                if let Some(r) = self.mirror_ncc(chk, k, &slots, &mirrored, in_run) {
                    if r < cfg.min_ncc {
                        out.rejected_image += 1;
                        continue;
                    }
                }
            }
            out.runs += 1;
            for (&s, m) in slots.iter().zip(&mirrored) {
                self.reflect_at(marks, s, level, *m);
                marks.reflected[s] = true;
                marks.reflected_points += 1;
            }
            // The column's water starts at its nearest confirmed run (the walk goes up the
            // column, bottom row first).
            let (row, col) = (run.slots[0] / cols, run.slots[0] % cols);
            out.water_from[col] = Some(out.water_from[col].map_or(row, |r: usize| r.max(row)));
        }
        out
    }

    /// The normalised cross-correlation of the image at the run's pixels (`slots`) with
    /// the image where their `mirrored` points project, over the pairs where the camera
    /// sees the mirrored point; `None` without enough pairs or texture. `k` is the image's
    /// upsampling of the cloud.
    fn mirror_ncc(
        &self,
        chk: MirrorCheck<'_>,
        k: usize,
        slots: &[usize],
        mirrored: &[Point3<f64>],
        in_run: &[bool],
    ) -> Option<f64> {
        let (pts, o, cfg) = (&self.pts, self.o, self.cfg);
        let (rows, cols) = (self.rows, self.cols);
        let kk = k as f64;
        let half = (kk - 1.0) / 2.0;
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for (&s, m) in slots.iter().zip(mirrored) {
            let (row, col) = (s / cols, s % cols);
            let here = chk
                .image
                .sample(kk * col as f64 + half, kk * row as f64 + half);
            // Use the mirrored point only where the camera sees it (the stereo point at
            // its pixel is the mirrored point itself, not something in front of it).
            let there = chk.camera.project(&(self.to_frame * m)).and_then(|[u, v]| {
                let (cr, cc) = (((v - half) / kk).round(), ((u - half) / kk).round());
                if !(cr >= 0.0 && cc >= 0.0 && (cr as usize) < rows && (cc as usize) < cols) {
                    return None;
                }
                let t = cr as usize * cols + cc as usize;
                let seen = self.cloud.is_valid(t) && !in_run[t] && {
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
        ncc(&a, &b)
    }

    /// Below the known level `l`. Once a column has met confirmed water (`water_from`) and
    /// the frame has a level, the points further up that column are judged against the
    /// level alone, whatever the run structure around them. Far out, where the rays graze
    /// the water and reflect the far bank and the grass a few decimetres above it, the
    /// virtual images lie within the gate of the local ground, their ranges need not wrap,
    /// and range noise scatters them past the far shore, so the runs miss them. A point is
    /// a reflection when it lies below the level by more than its vertical noise, or when
    /// it lies below the level and the `level_window` valid points either side of it in
    /// the column (with it) lie below the level on average by more than the noise of that
    /// weighted mean (`gate_sigma / √Σw`, `w = 1/σ_v²`): a virtual image 0.3 m deep at 22 m
    /// is within one point's 3σ_v, not within that of five. Only columns with a confirmed
    /// run take part: ground below the level elsewhere (the far side of a rise, a dry
    /// ditch) is not this water.
    ///
    /// Between two consecutive reflections up a column the level is crossed by every ray
    /// between theirs: at 20 m one cloud row spans more than a metre of water, which one
    /// crossing cell alone leaves unseen. Each cell strictly between the two crossings gets
    /// one reflection count. A point at or above the level between them (the surface
    /// itself, ground, an object) ends the span; a point below the level within its noise
    /// does not.
    ///
    /// Gives the points found against the level alone and the span cells counted.
    pub(super) fn below_known_level(
        &self,
        l: f64,
        water_from: &[Option<usize>],
        resolution: f64,
        marks: &mut Marks,
    ) -> (usize, usize) {
        let pts = &self.pts;
        let mut level_points = 0;
        let mut span_cells = 0;
        let per_column: Vec<(Vec<usize>, Vec<CellKey>)> = water_from
            .par_iter()
            .enumerate()
            .map(|(c, from)| match *from {
                Some(r0) => self.column_below_level(c, r0, l, resolution, &marks.reflected),
                None => (Vec::new(), Vec::new()),
            })
            .collect();
        for (new, span) in per_column {
            for s in new {
                let m = Point3::new(pts[s].x, pts[s].y, 2.0 * l - pts[s].z);
                self.reflect_at(marks, s, l, m);
                marks.reflected[s] = true;
                level_points += 1;
                marks.reflected_points += 1;
            }
            for k in span {
                let (x, y) = crate::grid::centre_of(resolution, k);
                marks
                    .ev
                    .add_with_level(x, y, l, |e| e.reflect = e.reflect.saturating_add(1));
                span_cells += 1;
            }
        }
        (level_points, span_cells)
    }

    /// Column `c` from its first row of confirmed water `r0` up: the reflections against
    /// the level `l` not already marked, and the cells strictly between consecutive
    /// crossings.
    fn column_below_level(
        &self,
        c: usize,
        r0: usize,
        l: f64,
        resolution: f64,
        reflected: &[bool],
    ) -> (Vec<usize>, Vec<CellKey>) {
        let (pts, o, cfg, cols) = (&self.pts, self.o, self.cfg, self.cols);
        let (mut new, mut span) = (Vec::new(), Vec::new());
        let valid: Vec<usize> = (0..=r0)
            .rev()
            .map(|r| r * cols + c)
            .filter(|&s| self.cloud.is_valid(s))
            .collect();
        let mut last: Option<(f64, f64)> = None;
        for (i, &s) in valid.iter().enumerate() {
            let p = pts[s];
            let w = cfg.level_window;
            let window = &valid[i.saturating_sub(w)..(i + w + 1).min(valid.len())];
            let is_reflection = reflected[s]
                || below_level(p, o, l, cfg)
                || (w > 0 && p.z < l && mean_below_level(window, pts, o, l, cfg));
            if is_reflection {
                if !reflected[s] {
                    new.push(s);
                }
                let here = self.crossing(s, l);
                if let Some(prev) = last {
                    span_cells_between(resolution, prev, here, &mut span);
                }
                last = Some(here);
            } else if p.z >= l {
                last = None;
            }
        }
        (new, span)
    }

    /// Where the ray to point `s` crosses the level `l` (map x, y).
    fn crossing(&self, s: usize, l: f64) -> (f64, f64) {
        let (p, o) = (self.pts[s], self.o);
        let t = (o.z - l) / (o.z - p.z);
        (o.x + (p.x - o.x) * t, o.y + (p.y - o.y) * t)
    }
}

/// [`StereoCues::seen`] from the walk's points at the ground level within their `σ_v`
/// (`at_level`, in any order), the points of candidate runs, the reflections, each
/// column's first row of confirmed water and the frame's water level.
pub(super) fn seen_of(
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
