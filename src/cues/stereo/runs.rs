//! The first phase of the stereo reflection cue: candidate runs of points below the local
//! ground, found walking up each image column.

use rayon::prelude::*;

use super::Frame;

/// One candidate run: slots (bottom to top) and the shore level before it.
pub(super) struct Run {
    pub(super) slots: Vec<usize>,
    pub(super) shore: f64,
    /// The height of the terrain that ended the run (the far shore, where the reflection
    /// meets what it reflects), when terrain nearer than the run ended it.
    pub(super) far: Option<f64>,
}

/// The candidate runs of a frame (or of one column), and what the walk found besides.
pub(super) struct Candidates {
    /// Runs that passed the walk's geometry, bottom row first, columns in order.
    pub(super) runs: Vec<Run>,
    /// Runs the walk rejected by geometry.
    pub(super) rejected_geometry: usize,
    /// Points at the local ground level within their own vertical noise `σ_v` (gathered
    /// only when the surface points are asked for).
    pub(super) at_level: Vec<usize>,
}

/// The run being gathered up a column: its slots, whether it follows a gap, the shore
/// level before it and the least horizontal distance of its points.
struct OpenRun {
    slots: Vec<usize>,
    gap: bool,
    shore: f64,
    min_h: f64,
}

/// Which slots belong to a candidate run, for a cloud of `len` elements.
pub(super) fn in_run(len: usize, runs: &[Run]) -> Vec<bool> {
    let mut in_run = vec![false; len];
    for r in runs {
        for &s in &r.slots {
            in_run[s] = true;
        }
    }
    in_run
}

impl Frame<'_> {
    /// Candidate runs up each column (columns are independent: in parallel, and gathered
    /// in column order so the result does not depend on the threads).
    pub(super) fn candidate_runs(&self, surface_points: bool) -> Candidates {
        let per_column: Vec<Candidates> = (0..self.cols)
            .into_par_iter()
            .map(|c| self.column_runs(c, surface_points))
            .collect();
        let rejected_geometry: usize = per_column.iter().map(|c| c.rejected_geometry).sum();
        let mut at_level: Vec<usize> = Vec::new();
        let mut runs: Vec<Run> = Vec::new();
        for col in per_column {
            runs.extend(col.runs);
            at_level.extend(col.at_level);
        }
        Candidates {
            runs,
            rejected_geometry,
            at_level,
        }
    }

    /// The walk up column `c`, bottom row first, keeping the local ground level (the last
    /// point within the gates of the ground before it). A point more than its gate below
    /// the level starts a run; the run goes on while its points stay below, or below the
    /// level with their range wrapping backward, until terrain much nearer than it ends it.
    fn column_runs(&self, c: usize, surface_points: bool) -> Candidates {
        let (pts, o, cfg) = (&self.pts, self.o, self.cfg);
        let mut col = Candidates {
            runs: Vec::new(),
            rejected_geometry: 0,
            at_level: Vec::new(),
        };
        let mut z_g: Option<f64> = None;
        let mut h_g = 0.0;
        let mut invalid_since_ground = 0usize;
        let mut run = OpenRun {
            slots: Vec::new(),
            gap: false,
            shore: 0.0,
            min_h: f64::INFINITY,
        };
        for r in (0..self.rows).rev() {
            let s = r * self.cols + c;
            if !self.cloud.is_valid(s) {
                if run.slots.is_empty() {
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
                col.at_level.push(s);
            }
            if let Some(&last) = run.slots.last() {
                // Inside a run, points below the level whose range keeps wrapping backward
                // are the upper part of the same virtual image.
                // Terrain much nearer than the run (the far shore) ends it.
                let wrapping = range < (pts[last] - o).norm();
                let nearer = h < run.min_h - cfg.gap_min_m;
                if !nearer && (below || (p.z < zg && wrapping)) {
                    run.min_h = run.min_h.min(h);
                    run.slots.push(s);
                    continue;
                }
                self.close_run(&mut run, Some((h, p.z, vertical)), &mut col);
            }
            if below {
                // A new run (also right after one that nearer terrain ended).
                run.gap = h - h_g > cfg.gap_min_m || (invalid_since_ground > 0 && h > h_g);
                run.shore = zg;
                run.min_h = h;
                run.slots.push(s);
                continue;
            }
            if p.z - zg <= cfg.above_gate_m {
                z_g = Some(p.z);
                h_g = h;
                invalid_since_ground = 0;
            }
        }
        self.close_run(&mut run, None, &mut col);
        col
    }

    /// Ends the open run (if any), keeping it as a candidate or counting it rejected.
    /// `next` is the terrain that ended it (horizontal distance, height, vertical noise),
    /// `None` at the top of the column.
    ///
    /// A run is a reflection when it follows a gap and the terrain seen after it, up the
    /// column, is *nearer* than the run (by `gap_min_m` than its median distance: range
    /// wraps backward, the virtual image lies beyond the far shore; the bottom of a ditch
    /// lies before its far side). With nothing after it, its own ranges must wrap.
    fn close_run(&self, run: &mut OpenRun, next: Option<(f64, f64, f64)>, col: &mut Candidates) {
        if run.slots.is_empty() {
            return;
        }
        let (pts, o, cfg) = (&self.pts, self.o, self.cfg);
        let (gap, shore) = (run.gap, run.shore);
        let slots = std::mem::take(&mut run.slots);
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
            col.runs.push(Run {
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
            col.rejected_geometry += 1;
        }
    }
}
