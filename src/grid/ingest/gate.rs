//! The below-surface gate (module documentation of `ingest`): a point against the
//! cell's prior surface, and a new cell's batch points split at height gaps.

use super::fuse::ElevMut;
use super::sample::Sample;
use crate::geom::floor_i64;
use crate::grid::cell::{CellStats, SIGMA_REF_M, W_UNIT};
use crate::grid::Elev;

/// The prior's gate reference for cell `i`: (mean mm, spread variance mm²), or `None` when
/// the prior has too few points to gate.
#[inline]
pub(super) fn prior_gate(prior: &ElevMut, i: usize, support: u32) -> Option<(f32, f32)> {
    let e = &prior.elev[i];
    (e.hits >= support).then(|| {
        let sw = e.sw as f64;
        let mean = i128_to_f64(e.swz) / sw;
        let var = (i128_to_f64(e.swzz) / sw - mean * mean).max(0.0);
        // The fused points' own noise too (their weights' harmonic mean variance, mm²):
        // a surface of a few far stereo points that happen to agree is not known to
        // their spread, and must not gate the lidar's ground below it.
        let noise = (SIGMA_REF_M * 1000.0).powi(2) * W_UNIT * f64::from(e.hits) / sw;
        (mean as f32, (var + noise) as f32)
    })
}

/// `v as f64` (rounded to nearest, ties to even), through the one-instruction `i64`
/// conversion whenever `v` fits in an `i64`: the same integer rounded by the same rule,
/// so the same value, without the library call the `i128` conversion is.
#[inline]
fn i128_to_f64(v: i128) -> f64 {
    match i64::try_from(v) {
        Ok(s) => s as f64,
        Err(_) => wide_to_f64(v),
    }
}

/// `v as f64` out of line: inlined, the compiler computes the library call on both arms
/// and selects, paying for it on every cell.
#[cold]
#[inline(never)]
fn wide_to_f64(v: i128) -> f64 {
    v as f64
}

/// A height (mm) at and above which no point is below the prior surface of `e`, whatever
/// its noise, or `None` when the prior cannot gate: the gate is never nearer than
/// `min_mm`, so a point below the surface lies below `mean − min_mm` ([`is_below`]
/// compares with the same rounded mean, and floating-point subtraction is monotonic).
#[inline]
pub(super) fn never_below(e: &Elev, support: u32, min_mm: f64) -> Option<f64> {
    (e.hits >= support).then(|| (i128_to_f64(e.swz) / e.sw as f64) as f32 as f64 - min_mm)
}

/// The height (mm) at and above which a point is fused whatever its own noise: the gate
/// with the point's σ left out is the nearest it can be, so `z ≥ ceil(mean − gate(var, 0))`
/// implies `z ≥ mean − gate(var, σ)` (every step is monotonic in floating point too).
#[inline]
pub(super) fn fast_threshold(gate: Option<(f32, f32)>, k: f64, min_mm: f64) -> i32 {
    let Some((mean, var)) = gate else {
        return i32::MIN;
    };
    let thr = mean as f64 - gate_mm(var as f64, 0.0, k, min_mm);
    if thr.is_nan() || thr <= i32::MIN as f64 {
        return i32::MIN;
    }
    if thr >= i32::MAX as f64 {
        return i32::MAX; // every point takes the exact test
    }
    (-floor_i64(-thr)) as i32
}

/// Gate distance (mm) below a surface of spread `var_mm2` for a point of noise `sigma_mm`.
#[inline]
fn gate_mm(var_mm2: f64, sigma_mm: f64, k: f64, min_mm: f64) -> f64 {
    (k * (var_mm2 + sigma_mm * sigma_mm).sqrt()).max(min_mm)
}

/// The exact gate test against the prior surface (taken only below the fast threshold).
#[cold]
pub(super) fn is_below(
    prior: &ElevMut,
    i: usize,
    support: u32,
    s: &Sample,
    k: f64,
    min_mm: f64,
) -> bool {
    match prior_gate(prior, i, support) {
        Some((mean, var)) => {
            (s.z_mm as f64) < mean as f64 - gate_mm(var as f64, s.sigma_mm as f64, k, min_mm)
        }
        None => false,
    }
}

/// Splits the batch points of cell `l` at height gaps and merges the result; returns the
/// number of points counted below the surface (all others are fused).
pub(super) fn split_and_merge(
    lay: &mut ElevMut,
    l: usize,
    pts: &mut [Sample],
    k: f64,
    min_mm: f64,
) -> u32 {
    let (kept, nbelow) = split_cell(pts, k, min_mm);
    // No point of a split cell was gated (its prior was unsupported), so the batch's
    // statistics are exactly `kept` and `nbelow`.
    let a = Elev {
        below: nbelow,
        ..Elev::of(&kept)
    };
    lay.merge(l, &a);
    nbelow
}

/// Splits one cell's batch points at height gaps; returns the fused statistics of the
/// surface cluster and everything above it, and the number of points below it.
fn split_cell(pts: &mut [Sample], k: f64, min_mm: f64) -> (CellStats, u32) {
    // A total order on what a sample holds, so ties cannot depend on arrival order.
    pts.sort_unstable_by_key(|s| (s.z_mm, s.wv, s.sigma_mm.to_bits()));
    // Cluster boundaries: a gap wider than the gate of the two points on either side.
    let mut starts = vec![0usize];
    for j in 1..pts.len() {
        let gap = (pts[j].z_mm as f64) - (pts[j - 1].z_mm as f64);
        let sig = pts[j].sigma_mm.max(pts[j - 1].sigma_mm) as f64;
        if gap > gate_mm(0.0, sig, k, min_mm) {
            starts.push(j);
        }
    }
    let weight = |a: usize, b: usize| pts[a..b].iter().map(|s| s.w() as u64).sum::<u64>();
    let total = weight(0, pts.len());
    let bounds: Vec<(usize, usize)> = starts
        .iter()
        .enumerate()
        .map(|(c, &s)| (s, starts.get(c + 1).copied().unwrap_or(pts.len())))
        .collect();
    // The highest cluster with at least a quarter of the weight; else the heaviest
    // (the highest among equals).
    let surface = bounds
        .iter()
        .rposition(|&(a, b)| 4 * weight(a, b) >= total)
        .unwrap_or_else(|| {
            let mut best = 0;
            for (c, &(a, b)) in bounds.iter().enumerate() {
                if weight(a, b) >= weight(bounds[best].0, bounds[best].1) {
                    best = c;
                }
            }
            best
        });
    let first_kept = bounds[surface].0;
    let mut c = CellStats::default();
    for s in &pts[first_kept..] {
        c.add_sample(s.z_mm, s.w(), s.q());
    }
    (c, first_kept as u32)
}
