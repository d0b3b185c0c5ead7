//! Pass 2 of ingest for a dense bucket (several samples a cell): each sample accumulated
//! straight into its cell's one-line accumulator, no sort.

use super::fuse::ElevMut;
use super::gate::{fast_threshold, is_below, prior_gate, split_and_merge};
use super::sample::Sample;
use super::{Binned, BUCKET_CELLS};
use crate::grid::Elev;

/// A dense bucket's accumulator for one cell: elevation only (ingest never writes
/// evidence), with the cell's gate threshold cached, in exactly one 64-byte cache line.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
pub(super) struct Acc {
    hits: u32,
    below: u32,
    zmin: i32,
    zmax: i32,
    sw: u64,
    /// Points at or above this height (mm) are fused without evaluating the gate (it is
    /// the gate with the point's own noise left out, which can only be nearer); `i32::MIN`
    /// when the prior cannot gate. Set when the cell is first touched in a batch.
    gate_fast: i32,
    /// Index of the cell's group in the split pass (`u32::MAX` when not flagged).
    pub(super) group: u32,
    swz: i128,
    swzz: i128,
}

impl Default for Acc {
    fn default() -> Self {
        Acc {
            hits: 0,
            below: 0,
            zmin: i32::MAX,
            zmax: i32::MIN,
            sw: 0,
            gate_fast: i32::MIN,
            group: u32::MAX,
            swz: 0,
            swzz: 0,
        }
    }
}

impl Acc {
    #[inline]
    pub(super) fn is_untouched(&self) -> bool {
        self.hits == 0 && self.below == 0
    }

    /// [`Elev::add`]'s arithmetic, repeated (without the vertical weights, kept beside the
    /// accumulators): an `Acc` holding an `Elev` would take two cache lines.
    #[inline]
    fn add(&mut self, z_mm: i32, w: u32) {
        // |w·z| < 2^55 fits i64; the square needs one widening multiply.
        let wz = w as i64 * z_mm as i64;
        self.hits += 1;
        self.sw += w as u64;
        self.swz += wz as i128;
        self.swzz += wz as i128 * z_mm as i128;
        self.zmin = self.zmin.min(z_mm);
        self.zmax = self.zmax.max(z_mm);
    }

    /// The statistics accumulated, with the vertical weights `swv` kept beside them.
    #[inline]
    fn elev(&self, swv: u64) -> Elev {
        Elev {
            hits: self.hits,
            below: self.below,
            zmin: self.zmin,
            zmax: self.zmax,
            sw: self.sw,
            swv,
            swz: self.swz,
            swzz: self.swzz,
        }
    }
}

/// A dense bucket's accumulators: one cache line a cell, and the cells' sums of vertical
/// weights beside them (eight to a line), which no gate reads.
#[derive(Debug, Clone, Default)]
pub(super) struct Dense {
    pub(super) cells: Vec<Acc>,
    pub(super) swv: Vec<u64>,
}

/// Pass 2 for a dense bucket `bi`, through its accumulators `acc` (all default on entry
/// and on return): returns (fused, below) point counts. The same rules as
/// [`fuse_bucket`](super::fuse::fuse_bucket), sample by sample.
#[inline(never)]
pub(super) fn fuse_dense(
    binned: &[Binned],
    bi: usize,
    lay: &mut ElevMut,
    acc: &mut Dense,
    k: f64,
    min_mm: f64,
    support: u32,
) -> (u64, u64) {
    let Dense { cells, swv } = acc;
    let mask = (BUCKET_CELLS - 1) as u32;
    let samples = || binned.iter().flat_map(|p| &p.buckets[bi]);
    let mut touched: Vec<u32> = Vec::new();
    let (mut fused, mut below) = (0u64, 0u64);
    for s in samples() {
        let l = (s.idx & mask) as usize;
        let a = &mut cells[l];
        if a.is_untouched() {
            touched.push(l as u32);
            a.gate_fast = fast_threshold(prior_gate(lay, l, support), k, min_mm);
        }
        if s.z_mm < a.gate_fast && is_below(lay, l, support, s, k, min_mm) {
            a.below += 1;
            below += 1;
            continue;
        }
        a.add(s.z_mm, s.w());
        swv[l] += u64::from(s.q());
        fused += 1;
    }

    // Decide each touched cell: merge, or split the batch's points at height gaps.
    let mut flagged: Vec<u32> = Vec::new();
    for &l in &touched {
        let l = l as usize;
        let b = cells[l];
        let needs_split =
            lay.elev[l].hits < support && b.hits >= 2 && (b.zmax as f64 - b.zmin as f64) > min_mm;
        if needs_split {
            cells[l].group = flagged.len() as u32;
            flagged.push(l as u32);
        } else {
            lay.merge(l, &b.elev(swv[l]));
            cells[l] = Acc::default();
            swv[l] = 0;
        }
    }
    if !flagged.is_empty() {
        // Only cells seen for the first time with a wide spread: gather their points and
        // split each cell's points at height gaps.
        let mut groups: Vec<Vec<Sample>> = vec![Vec::new(); flagged.len()];
        for s in samples() {
            let g = cells[(s.idx & mask) as usize].group;
            if g != u32::MAX {
                groups[g as usize].push(*s);
            }
        }
        for (g, &l) in groups.iter_mut().zip(&flagged) {
            let l = l as usize;
            let nbelow = split_and_merge(lay, l, g, k, min_mm);
            fused -= nbelow as u64;
            below += nbelow as u64;
            cells[l] = Acc::default();
            swv[l] = 0;
        }
    }
    (fused, below)
}
