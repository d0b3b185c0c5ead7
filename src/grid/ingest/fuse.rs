//! Pass 2 of ingest for a bucket of few samples a cell: the samples sorted by cell (by
//! counting, or by comparison when they are sparse), then each cell's run fused into its
//! record; and the buckets' records cut from the layers.

use super::gate::{fast_threshold, is_below, never_below, prior_gate, split_and_merge};
use super::sample::Sample;
use super::{Binned, BUCKET_CELLS};
use crate::grid::{Elev, Layers};

/// The buckets one task of pass 2 fuses: each with its index and its cells' records.
pub(super) type Task<'a> = Vec<(usize, ElevMut<'a>)>;

/// The elevation records of one bucket's cells (indices local to the bucket).
pub(super) struct ElevMut<'a> {
    pub(super) occupied: &'a mut [bool],
    pub(super) elev: &'a mut [Elev],
}

impl ElevMut<'_> {
    /// [`Layers::merge_at`] for a cell without evidence.
    #[inline]
    pub(super) fn merge(&mut self, i: usize, a: &Elev) {
        self.elev[i].merge(a);
        self.occupied[i] |= !a.no_points();
    }
}

/// The layers cut into buckets of `BUCKET_CELLS` cells.
pub(super) fn split_buckets(layers: &mut Layers) -> Vec<ElevMut<'_>> {
    let b = BUCKET_CELLS;
    layers
        .elev
        .chunks_mut(b)
        .zip(layers.occupied.chunks_mut(b))
        .map(|(elev, occupied)| ElevMut { occupied, elev })
        .collect()
}

/// How many samples ahead of the cell being fused [`fuse_bucket`] prefetches a record.
const PREFETCH_SAMPLES: usize = 16;

/// Asks for the cache line at `p` (a hint; nothing where the target has no such hint).
#[inline(always)]
fn prefetch<T>(p: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch reads nothing architecturally and cannot fault; `p` is valid.
    #[allow(unused_unsafe)]
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>((p as *const T).cast::<i8>());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Pass 2 for bucket `bi`: sorts its samples by cell into `out` (which holds exactly
/// their number), by counting or else by comparison, then fuses each cell's run; returns
/// (fused, below) point counts.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
pub(super) fn fuse_bucket(
    binned: &[Binned],
    bi: usize,
    lay: &mut ElevMut,
    out: &mut [Sample],
    counting: bool,
    k: f64,
    min_mm: f64,
    support: u32,
) -> (u64, u64) {
    if out.is_empty() {
        return (0, 0);
    }
    let mask = (BUCKET_CELLS - 1) as u32;
    let samples = || binned.iter().flat_map(|p| &p.buckets[bi]);
    if !counting {
        for (o, s) in out.iter_mut().zip(samples()) {
            *o = *s;
        }
        out.sort_unstable_by_key(|s| s.idx);
    } else {
        // Counting sort on the cell's index within the bucket.
        let mut next = [0u32; BUCKET_CELLS];
        for s in samples() {
            next[(s.idx & mask) as usize] += 1;
        }
        let mut at = 0u32;
        for n in next.iter_mut() {
            let c = *n;
            *n = at;
            at += c;
        }
        for s in samples() {
            let n = &mut next[(s.idx & mask) as usize];
            out[*n as usize] = *s;
            *n += 1;
        }
    }
    let (mut fused, mut below) = (0u64, 0u64);
    let mut i = 0;
    while i < out.len() {
        let idx = out[i].idx;
        let mut j = i + 1;
        while j < out.len() && out[j].idx == idx {
            j += 1;
        }
        // The record a few cells on is asked for now: the cells are visited in buffer
        // order but sparsely, where the hardware prefetcher does not follow.
        if let Some(s) = out.get(j + PREFETCH_SAMPLES) {
            prefetch(&lay.elev[(s.idx & mask) as usize]);
        }
        let run = &mut out[i..j];
        i = j;
        let l = (idx & mask) as usize;
        // Every point fused; then, only if one of them may lie below the prior surface,
        // again through the gate.
        let mut a = Elev::default();
        for s in run.iter() {
            a.add(s.z_mm, s.w(), s.q());
        }
        fused += a.hits as u64;
        if never_below(&lay.elev[l], support, min_mm).is_some_and(|h| (a.zmin as f64) < h) {
            let gate_fast = fast_threshold(prior_gate(lay, l, support), k, min_mm);
            fused -= a.hits as u64;
            a = Elev::default();
            for s in run.iter() {
                if s.z_mm < gate_fast && is_below(lay, l, support, s, k, min_mm) {
                    a.below += 1;
                    below += 1;
                    continue;
                }
                a.add(s.z_mm, s.w(), s.q());
                fused += 1;
            }
        }
        let needs_split =
            lay.elev[l].hits < support && a.hits >= 2 && (a.zmax as f64 - a.zmin as f64) > min_mm;
        if needs_split {
            // A cell seen for the first time with a wide spread: split its points at
            // height gaps.
            let nbelow = split_and_merge(lay, l, run, k, min_mm);
            fused -= nbelow as u64;
            below += nbelow as u64;
        } else {
            lay.merge(l, &a);
        }
    }
    (fused, below)
}
