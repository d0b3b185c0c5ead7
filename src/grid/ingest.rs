//! Fusing point clouds into the rolling grid.
//!
//! One call to [`RollingGrid::ingest`] is one batch (a scan, a stereo frame, a chunk of a
//! file). Points are range-weighted (σ grows with range, [`RangeNoise`]), each with the
//! share of its range noise that reaches its height (`vertical_share`), and fused as exact
//! integer sums in two passes: classify the points (in parallel over contiguous chunks of
//! the cloud) into buckets of cells, then fuse each bucket (in parallel over buckets: a
//! bucket's samples sorted by cell, each cell's one-line record read and written once).
//! Since the sums are exact, the result depends neither on how many threads ran nor on
//! how the cloud was cut.
//!
//! The below-surface gate. A point far below its cell's surface (a reflection seen in still
//! water, the floor of a hole) must not drag the elevation down, and must not be lost: it
//! is counted in the cell's `below` layer. The surface it is judged against is
//! * the cell's fused estimate from earlier batches, when it has at least `min_support`
//!   points: the gate is `max(gate_min, k·sqrt(spread² + σ_fused² + σ_point²))` below its
//!   mean, σ_fused² the fused points' mean variance (harmonic, from their weights): the
//!   difference of two noisy heights, so that far stereo points with σ of metres that
//!   happen to agree do not gate the lidar's ground a metre below them;
//! * otherwise the batch's own points: when they span more than `gate_min`, they are sorted
//!   by height and split into clusters at gaps wider than the gate; the surface is the
//!   highest cluster holding at least a quarter of the cell's weight, and lower clusters are
//!   counted as below-surface.
//!
//! Both rules depend only on what came before the batch and on the batch's multiset of
//! points, never on their order or on the thread count. Across batches the order matters,
//! as it does for any online mapper: a point that would be gated against a later surface
//! is fused if it arrived first.

mod bin;
mod dense;
mod fuse;
mod gate;
mod noise;
mod sample;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::cell::{SIGMA_REF_M, W_MAX, W_UNIT};
use super::RollingGrid;
use crate::error::Result;
use crate::geom::PointCloud;
use bin::bin_chunk;
use dense::{fuse_dense, Acc, Dense};
use fuse::{fuse_bucket, split_buckets, Task};
pub use noise::RangeNoise;
use sample::Sample;

/// What happened to the points of one or more batches.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct IngestStats {
    /// Point slots seen (missing returns included).
    pub points: u64,
    /// Fused into the elevation estimates.
    pub fused: u64,
    /// Counted in the below-surface layer.
    pub below: u64,
    /// NaN or infinite coordinates (missing returns): skipped, never fused.
    pub nonfinite: u64,
    /// Outside the window (or beyond the fixed-point height range).
    pub outside: u64,
}

impl IngestStats {
    /// Adds another batch's counts.
    pub fn merge(&mut self, o: &IngestStats) {
        self.points += o.points;
        self.fused += o.fused;
        self.below += o.below;
        self.nonfinite += o.nonfinite;
        self.outside += o.outside;
    }
}

/// Cells per bucket: a bucket's cell records (64 bytes each) take 256 KiB, so they stay in
/// a core's L2 cache while the bucket's points are fused, and its samples are sorted by
/// cell with one count per cell (16 KiB, in L1).
const BUCKET_SHIFT: u32 = 12;
const BUCKET_CELLS: usize = 1 << BUCKET_SHIFT;

/// A bucket with fewer than `BUCKET_CELLS / SPARSE` samples is sorted by comparison: its
/// samples cost less to sort than a pass over one count per cell of the bucket.
const SPARSE: usize = 16;

/// A bucket with at least `BUCKET_CELLS * DENSE` samples (several a cell, as in a dense
/// batch) is fused through one accumulator a cell of the bucket instead of being sorted:
/// each sample then costs one access to a line in L2, not three passes of sorting.
const DENSE: usize = 4;

/// One chunk of points after classification: its samples, bucketed by buffer index
/// (`idx >> BUCKET_SHIFT`), and what happened to the rest.
#[derive(Debug, Clone, Default)]
struct Binned {
    buckets: Vec<Vec<Sample>>,
    stats: IngestStats,
}

/// [`super::quantize_weight`] bit for bit, with the clamp before the conversion so the cast
/// is one signed f64 → i64 conversion (baseline x86-64 has no unsigned one): for
/// `w ≥ W_MAX` both give `W_MAX`, below it both truncate the same `w + 0.5 < 2⁶³`.
#[inline]
pub(crate) fn weight_of(sigma_m: f64) -> u32 {
    let r = SIGMA_REF_M / sigma_m;
    let w = W_UNIT * r * r;
    if w.is_nan() || w < 1.0 {
        return 1;
    }
    (w.min(W_MAX as f64) + 0.5) as i64 as u32
}

/// Reusable scratch memory of a grid's ingest.
#[derive(Debug, Clone, Default)]
pub(crate) struct Scratch {
    /// One per chunk of points.
    binned: Vec<Binned>,
    /// One per task of pass 2: the samples of the bucket it fuses, sorted by cell (dense
    /// buckets excepted, so at most `BUCKET_CELLS * DENSE` of them: 256 KiB a task, where a
    /// buffer for the whole batch took 16 bytes a point).
    sorted: Vec<Vec<Sample>>,
    /// One per task of pass 2: the accumulators of the dense bucket it fuses (`BUCKET_CELLS`
    /// of them, allocated when a task first meets a dense bucket), all default between
    /// buckets.
    acc: Vec<Dense>,
}

impl Scratch {
    /// Bytes allocated (capacities).
    pub(crate) fn heap_bytes(&self) -> usize {
        let buckets: usize = self
            .binned
            .iter()
            .map(|b| {
                b.buckets.capacity() * std::mem::size_of::<Vec<Sample>>()
                    + b.buckets
                        .iter()
                        .map(|v| v.capacity() * std::mem::size_of::<Sample>())
                        .sum::<usize>()
            })
            .sum();
        self.binned.capacity() * std::mem::size_of::<Binned>()
            + buckets
            + self.sorted.capacity() * std::mem::size_of::<Vec<Sample>>()
            + self
                .sorted
                .iter()
                .map(|v| v.capacity() * std::mem::size_of::<Sample>())
                .sum::<usize>()
            + self.acc.capacity() * std::mem::size_of::<Dense>()
            + self
                .acc
                .iter()
                .map(|a| {
                    a.cells.capacity() * std::mem::size_of::<Acc>()
                        + a.swv.capacity() * std::mem::size_of::<u64>()
                })
                .sum::<usize>()
    }
}

/// Smallest chunk handed to a thread: below this, threading costs more than it saves.
const MIN_CHUNK: usize = 32 * 1024;
impl RollingGrid {
    /// Fuses one batch of points (see the module documentation for the gate).
    pub fn ingest(&mut self, cloud: &PointCloud, noise: &RangeNoise) -> Result<IngestStats> {
        let chunks = cloud
            .len()
            .div_ceil(MIN_CHUNK)
            .clamp(1, rayon::current_num_threads().max(1));
        self.ingest_chunked(cloud, noise, chunks)
    }

    /// [`RollingGrid::ingest`] with the cloud cut into `chunks` contiguous chunks for
    /// classification. The result does not depend on `chunks`; tests check it.
    pub(crate) fn ingest_chunked(
        &mut self,
        cloud: &PointCloud,
        noise: &RangeNoise,
        chunks: usize,
    ) -> Result<IngestStats> {
        cloud.validate()?;
        noise.validate()?;
        let npts = cloud.len();
        if npts == 0 {
            return Ok(IngestStats::default());
        }
        let chunks = chunks.clamp(1, npts);
        let ctx = self.ctx(cloud, noise);
        let k = self.cfg.gate_sigma;
        let min_mm = self.cfg.gate_min_m * 1000.0;
        let support = self.cfg.min_support.max(1);

        let ncells = self.n * self.n;
        let nbuckets = ncells.div_ceil(BUCKET_CELLS);
        let RollingGrid {
            layers, scratch, ..
        } = self;
        if scratch.binned.len() < chunks {
            scratch.binned.resize_with(chunks, Binned::default);
        }
        let step = npts.div_ceil(chunks);

        // Pass 1, in parallel over contiguous chunks of points: classify every point and
        // bucket the samples by cell, so that pass 2 finds each bucket's accumulators in
        // cache instead of missing it on nearly every point.
        let binned = &mut scratch.binned[..chunks];
        if let [p] = binned {
            // One chunk: on this thread. (Handing it to the pool costs a wake-up, which on a
            // loaded machine can cost more than a small batch's whole ingest.)
            bin_chunk(&ctx, 0..npts, nbuckets, p);
        } else {
            binned.par_iter_mut().enumerate().for_each(|(ci, p)| {
                let lo = (ci * step).min(npts);
                let hi = ((ci + 1) * step).min(npts);
                bin_chunk(&ctx, lo..hi, nbuckets, p);
            });
        }
        let binned = &scratch.binned[..chunks];

        // Pass 2, in parallel over buckets (each owns its cells' records; a task sorts its
        // buckets one after another in its own buffer): sort the bucket's samples by cell, then walk the cells in
        // buffer order, each read and written once: gate its samples against the prior
        // surface, accumulate, and merge, or split its batch points at height gaps. All
        // sums are exact integers, so neither the chunking nor the order of the samples
        // changes a cell.
        let counts: Vec<usize> = (0..nbuckets)
            .map(|bi| binned.iter().map(|p| p.buckets[bi].len()).sum())
            .collect();
        let dense = |c: usize| c >= BUCKET_CELLS * DENSE;
        let sorted_len = |c: usize| if dense(c) { 0 } else { c };
        // Buckets are dealt to `chunks` tasks in turn (bucket `bi` to task `bi % chunks`),
        // each with its own sort buffer and dense accumulators; a bucket's result does not
        // depend on which task fuses it.
        if scratch.acc.len() < chunks {
            scratch.acc.resize_with(chunks, Dense::default);
        }
        if scratch.sorted.len() < chunks {
            scratch.sorted.resize_with(chunks, Vec::new);
        }
        for (t, buf) in scratch.sorted[..chunks].iter_mut().enumerate() {
            let most = (t..nbuckets)
                .step_by(chunks)
                .map(|bi| sorted_len(counts[bi]))
                .max()
                .unwrap_or(0);
            if buf.len() < most {
                buf.resize(most, Sample::ZERO);
            }
        }
        let mut tasks: Vec<Task> = (0..chunks).map(|_| Vec::new()).collect();
        for (bi, lay) in split_buckets(layers).into_iter().enumerate() {
            tasks[bi % chunks].push((bi, lay));
        }
        let add = |a: (u64, u64), b: (u64, u64)| (a.0 + b.0, a.1 + b.1);
        let run = |((task, acc), buf): ((Task, &mut Dense), &mut Vec<Sample>)| {
            let mut sum = (0, 0);
            for (bi, mut lay) in task {
                let out = &mut buf[..sorted_len(counts[bi])];
                let r = if dense(counts[bi]) {
                    if acc.cells.is_empty() {
                        acc.cells = vec![Acc::default(); BUCKET_CELLS];
                        acc.swv = vec![0; BUCKET_CELLS];
                    }
                    fuse_dense(binned, bi, &mut lay, acc, k, min_mm, support)
                } else {
                    let counting = out.len() >= BUCKET_CELLS / SPARSE;
                    fuse_bucket(binned, bi, &mut lay, out, counting, k, min_mm, support)
                };
                sum = add(sum, r);
            }
            sum
        };
        let pool = &mut scratch.acc[..chunks];
        let bufs = &mut scratch.sorted[..chunks];
        let (fused, below) = if chunks == 1 {
            // A batch too small to split into chunks is fused on this thread too.
            tasks
                .into_iter()
                .zip(pool)
                .zip(bufs)
                .map(run)
                .fold((0, 0), add)
        } else {
            tasks
                .into_par_iter()
                .zip(pool.par_iter_mut())
                .zip(bufs.par_iter_mut())
                .map(run)
                .reduce(|| (0, 0), add)
        };

        let mut stats = IngestStats::default();
        for p in binned {
            stats.merge(&p.stats);
        }
        stats.fused = fused;
        stats.below = below;
        Ok(stats)
    }
}

#[cfg(test)]
mod tests;
