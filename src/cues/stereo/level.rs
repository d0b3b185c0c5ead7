//! The second phase of the stereo reflection cue: the frame's water level, at the
//! waterline (the far shores that ended runs) and by the symmetry of the reflections.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use super::runs::Run;
use super::{Frame, StereoCueConfig};
use crate::error::{Error, Result};

/// The waterline: where a run meets the far shore that ended it. A bank facing the camera
/// is seen down to the water, and points there are near the level, where the vertical part
/// of the range error is smallest; the near bank may face away and hide the water's edge.
/// Gives the number of far shores, and their median when there are at least
/// `min_far_shores`.
pub(super) fn waterline_level(runs: &[Run], cfg: &StereoCueConfig) -> (usize, Option<f64>) {
    let mut fars: Vec<f64> = runs.iter().filter_map(|r| r.far).collect();
    let far_shores = fars.len();
    let waterline_level = (far_shores >= cfg.min_far_shores.max(1)).then(|| {
        let m = fars.len() / 2;
        *fars.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1
    });
    (far_shores, waterline_level)
}

impl Frame<'_> {
    /// Water level by symmetry (one-parameter ICP against the non-reflected points), and
    /// the pairs behind it: each mirrored point of the runs is paired with its nearest real
    /// point, and the level moves by half the median height difference, up to six times.
    /// `(None, 0)` without runs or without enough sources and pairs.
    pub(super) fn symmetry_level(
        &self,
        runs: &[Run],
        in_run: &[bool],
        waterline_level: Option<f64>,
    ) -> Result<(Option<f64>, usize)> {
        let (pts, cfg) = (&self.pts, self.cfg);
        let (mut symmetry_level, mut pairs) = (None, 0);
        if runs.is_empty() {
            return Ok((symmetry_level, pairs));
        }
        let mut shores: Vec<f64> = runs.iter().map(|r| r.shore).collect();
        let m = shores.len() / 2;
        shores.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
        // Water stands at or below its shores: start from the lower of the two.
        let mut level = waterline_level.map_or(shores[m], |w| w.min(shores[m]));
        // Reflected points to pair: at most 4096, by a fixed stride (deterministic).
        let all: Vec<usize> = runs.iter().flat_map(|r| r.slots.iter().copied()).collect();
        let stride = all.len().div_ceil(4096).max(1);
        let reflected: Vec<usize> = all.iter().copied().step_by(stride).collect();
        let sources = self.pairing_sources(&reflected, in_run, level);
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
        Ok((symmetry_level, pairs))
    }

    /// Sources for the pairing: real points (valid, in no run) above `level` less the
    /// tolerance, inside the footprint of the `reflected` points padded by the pairing
    /// radius.
    fn pairing_sources(&self, reflected: &[usize], in_run: &[bool], level: f64) -> Vec<[f64; 3]> {
        let (pts, cfg) = (&self.pts, self.cfg);
        let (mut x0, mut y0, mut x1, mut y1) = (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        );
        for &s in reflected {
            x0 = x0.min(pts[s].x);
            y0 = y0.min(pts[s].y);
            x1 = x1.max(pts[s].x);
            y1 = y1.max(pts[s].y);
        }
        let pad = cfg.pair_radius_m;
        (0..self.cloud.len())
            .filter(|&s| {
                self.cloud.is_valid(s)
                    && !in_run[s]
                    && pts[s].z > level - cfg.level_tolerance_m
                    && pts[s].x >= x0 - pad
                    && pts[s].x <= x1 + pad
                    && pts[s].y >= y0 - pad
                    && pts[s].y <= y1 + pad
            })
            .map(|s| [pts[s].x, pts[s].y, pts[s].z])
            .collect()
    }
}
