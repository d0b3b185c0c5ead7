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

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::cell::{quantize_mm, vertical_weight, CellStats, SIGMA_REF_M, W_MAX, W_UNIT};
use super::{Elev, Layers, RollingGrid};
use crate::error::{Error, Result};
use crate::geom::{cell_coord, floor_i64, PointCloud};

/// Elevation noise of a range sensor against range `r` (metres from the sensor):
/// `σ(r) = sigma0 + per_m·r + per_m2·r²`. Lidar is close to constant (beam divergence adds a
/// little per metre); stereo grows with the square of range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangeNoise {
    /// Noise at zero range, metres.
    pub sigma0: f64,
    /// Coefficient of `r` (metres of σ per metre of range).
    pub per_m: f64,
    /// Coefficient of `r²`, per metre.
    pub per_m2: f64,
}

impl RangeNoise {
    /// A spinning lidar: 2 cm, plus 1 mm per metre.
    pub const LIDAR: RangeNoise = RangeNoise {
        sigma0: 0.02,
        per_m: 0.001,
        per_m2: 0.0,
    };
    /// A stereo camera (f·B ≈ 150 px·m, 0.25 px disparity noise): σ_z ≈ r²·0.25/150.
    pub const STEREO: RangeNoise = RangeNoise {
        sigma0: 0.005,
        per_m: 0.0,
        per_m2: 0.0017,
    };

    /// A range-independent noise.
    pub const fn constant(sigma: f64) -> Self {
        RangeNoise {
            sigma0: sigma,
            per_m: 0.0,
            per_m2: 0.0,
        }
    }

    /// Elevation standard deviation at range `r` metres, metres.
    #[inline]
    pub fn sigma(&self, r: f64) -> f64 {
        self.sigma0 + r * (self.per_m + r * self.per_m2)
    }

    /// Checks that `sigma0` is positive and every term finite and non-negative.
    pub fn validate(&self) -> Result<()> {
        let ok = self.sigma0.is_finite()
            && self.sigma0 > 0.0
            && self.per_m.is_finite()
            && self.per_m >= 0.0
            && self.per_m2.is_finite()
            && self.per_m2 >= 0.0;
        if ok {
            Ok(())
        } else {
            Err(Error::invalid(
                "range noise",
                format!(
                    "sigma0 {} m, per_m {}, per_m2 {} (sigma0 must be > 0, all finite and >= 0)",
                    self.sigma0, self.per_m, self.per_m2
                ),
            ))
        }
    }
}

impl Default for RangeNoise {
    fn default() -> Self {
        RangeNoise::LIDAR
    }
}

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

/// A dense bucket's accumulator for one cell: elevation only (ingest never writes
/// evidence), with the cell's gate threshold cached, in exactly one 64-byte cache line.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
struct Acc {
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
    group: u32,
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
    fn is_untouched(&self) -> bool {
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

/// The prior's gate reference for cell `i`: (mean mm, spread variance mm²), or `None` when
/// the prior has too few points to gate.
#[inline]
fn prior_gate(prior: &ElevMut, i: usize, support: u32) -> Option<(f32, f32)> {
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
fn never_below(e: &Elev, support: u32, min_mm: f64) -> Option<f64> {
    (e.hits >= support).then(|| (i128_to_f64(e.swz) / e.sw as f64) as f32 as f64 - min_mm)
}

/// The height (mm) at and above which a point is fused whatever its own noise: the gate
/// with the point's σ left out is the nearest it can be, so `z ≥ ceil(mean − gate(var, 0))`
/// implies `z ≥ mean − gate(var, σ)` (every step is monotonic in floating point too).
#[inline]
fn fast_threshold(gate: Option<(f32, f32)>, k: f64, min_mm: f64) -> i32 {
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
    /// The batch's samples sorted by cell, bucket after bucket (dense buckets excepted).
    sorted: Vec<Sample>,
    /// One per task of pass 2: the accumulators of the dense bucket it fuses (`BUCKET_CELLS`
    /// of them, allocated when a task first meets a dense bucket), all default between
    /// buckets.
    acc: Vec<Dense>,
}

/// A dense bucket's accumulators: one cache line a cell, and the cells' sums of vertical
/// weights beside them (eight to a line), which no gate reads.
#[derive(Debug, Clone, Default)]
struct Dense {
    cells: Vec<Acc>,
    swv: Vec<u64>,
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
            + self.sorted.capacity() * std::mem::size_of::<Sample>()
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

/// The buckets one task of pass 2 fuses: each with its index, its cells' records and its
/// part of the sort buffer.
type Task<'a> = Vec<(usize, ElevMut<'a>, &'a mut [Sample])>;

/// The elevation records of one bucket's cells (indices local to the bucket).
struct ElevMut<'a> {
    occupied: &'a mut [bool],
    elev: &'a mut [Elev],
}

impl ElevMut<'_> {
    /// [`Layers::merge_at`] for a cell without evidence.
    #[inline]
    fn merge(&mut self, i: usize, a: &Elev) {
        self.elev[i].merge(a);
        self.occupied[i] |= !a.no_points();
    }
}

/// The layers cut into buckets of `BUCKET_CELLS` cells.
fn split_buckets(layers: &mut Layers) -> Vec<ElevMut<'_>> {
    let b = BUCKET_CELLS;
    layers
        .elev
        .chunks_mut(b)
        .zip(layers.occupied.chunks_mut(b))
        .map(|(elev, occupied)| ElevMut { occupied, elev })
        .collect()
}

/// A point reduced to what the grid needs.
#[derive(Debug, Clone, Copy)]
struct Sample {
    idx: u32,
    z_mm: i32,
    /// The weight (low [`W_BITS`] bits) and the code of the share of the point's noise
    /// that reaches its height (the rest, [`share_code`]): one word, so that a sample
    /// stays 16 bytes.
    wv: u32,
    sigma_mm: f32,
}

/// Bits of [`Sample::wv`] that hold the weight (up to [`W_MAX`] = 2²⁴).
const W_BITS: u32 = 25;

/// The vertical share `s` (0.05..1) as a 7-bit code: `round(127·√s)`, which keeps the
/// share to 4 % and its square to 7 % at the 0.05 floor, less above it.
#[inline]
fn share_code(share: f64) -> u32 {
    floor_small(127.0 * share.sqrt() + 0.5).1 as u32
}

impl Sample {
    #[inline]
    fn w(&self) -> u32 {
        self.wv & ((1 << W_BITS) - 1)
    }

    /// The vertical weight ([`vertical_weight`]) from the weight, the share's code and
    /// the range noise.
    #[inline]
    fn q(&self) -> u32 {
        let c = f64::from(self.wv >> W_BITS) / 127.0;
        vertical_weight(self.w(), c * c, f64::from(self.sigma_mm) * 1e-3)
    }

    /// Filler of the sort buffer (every slot is written before it is read).
    const ZERO: Sample = Sample {
        idx: 0,
        z_mm: 0,
        wv: 0,
        sigma_mm: 0.0,
    };
}

enum Classified {
    Sample(Sample),
    NonFinite,
    Outside,
}

/// Everything the per-point work needs, read-only.
struct Ctx<'a> {
    cloud: &'a PointCloud,
    rot: [[f64; 3]; 3],
    t: [f64; 3],
    so: [f32; 3],
    /// The sensor origin's height in the map.
    so_z_map: f64,
    res: f64,
    inv_res: f64,
    z_ref: f64,
    n: i64,
    origin: (i64, i64),
    shift: (i64, i64),
    noise: RangeNoise,
}

/// Points classified together by [`Ctx::classify_lanes`].
const LANES: usize = 64;

/// [`Ctx::classify_lanes`]'s per-lane results of the branch-free pass.
struct Lanes {
    /// [`LANE_SAMPLE`], [`LANE_OUTSIDE`] or [`LANE_SCALAR`].
    kind: [u32; LANES],
    idx: [u32; LANES],
    z_mm: [i32; LANES],
    w: [u32; LANES],
    code: [u32; LANES],
    sigma_mm: [f32; LANES],
}

const LANE_SAMPLE: u32 = 0;
const LANE_OUTSIDE: u32 = 1;
/// Off the fast path: non-finite, too near a cell edge, or a height out of range.
const LANE_SCALAR: u32 = 2;

impl Default for Lanes {
    fn default() -> Self {
        Lanes {
            kind: [0; LANES],
            idx: [0; LANES],
            z_mm: [0; LANES],
            w: [0; LANES],
            code: [0; LANES],
            sigma_mm: [0.0; LANES],
        }
    }
}

/// 1.5 · 2⁵²: for |q| < 2⁵¹, `q + MAGIC` rounds `q` to the nearest integer `r` and holds
/// `r` in the low bits of its representation (the exponent is the same for all such sums).
const MAGIC: f64 = 6_755_399_441_055_744.0;

/// `(floor(q) as f64, floor(q) as i32)` for |q| < 2³¹ (unspecified values otherwise),
/// without branches or saturating conversions, so that a loop of it vectorises.
#[inline(always)]
fn floor_small(q: f64) -> (f64, i32) {
    let t = q + MAGIC;
    let r = t - MAGIC;
    let up = r > q;
    (
        r - if up { 1.0 } else { 0.0 },
        (t.to_bits() as u32 as i32).wrapping_sub(up as i32),
    )
}

impl Ctx<'_> {
    /// True when the window's origin is small enough for [`Ctx::classify_lanes`]'s
    /// floating-point window test to be exact integer arithmetic (always, short of a
    /// window 2⁴⁰ cells from the map origin; beyond that every point takes the scalar path).
    fn lanes_exact(&self) -> bool {
        self.origin.0.unsigned_abs() < 1 << 40 && self.origin.1.unsigned_abs() < 1 << 40
    }

    /// [`Ctx::classify`] of the `LANES` points from `i0`, bit for bit, for the lanes whose
    /// kind is not [`LANE_SCALAR`]: a branch-free pass over all lanes (which the compiler
    /// vectorises) computes the transform, the floors, the window test, the height and the
    /// weight. Lanes off the fast path (non-finite points, a product too close to a cell
    /// edge, a height out of range) are left to [`Ctx::classify`].
    #[inline(always)]
    fn classify_lanes(&self, i0: usize, l: &mut Lanes) {
        let pts: &[[f32; 3]; LANES] = self.cloud.xyz[i0..i0 + LANES]
            .try_into()
            .expect("LANES points");
        let r = &self.rot;
        let inv = self.inv_res;
        let nf = self.n as f64;
        let (ox, oy) = (self.origin.0 as f64, self.origin.1 as f64);
        let (sx, sy) = (self.shift.0 as f64, self.shift.1 as f64);
        // `cell_coord`'s test that the product's floor is the quotient's.
        let edge_ok = |q: f64, f: f64| {
            let frac = q - f;
            frac > 1e-6 && frac < 1.0 - 1e-6 && q.abs() < 1e9
        };
        // Window offset of a cell coordinate, its buffer coordinate, and whether it is in.
        let wrap = |f: f64, o: f64, s: f64| {
            let d = f - o;
            let b = d + s;
            (b - if b >= nf { nf } else { 0.0 }, d >= 0.0 && d < nf)
        };
        for (j, &[x, y, z]) in pts.iter().enumerate() {
            let finite = x.is_finite() & y.is_finite() & z.is_finite();
            let (xd, yd, zd) = (x as f64, y as f64, z as f64);
            let wx = r[0][0] * xd + r[0][1] * yd + r[0][2] * zd + self.t[0];
            let wy = r[1][0] * xd + r[1][1] * yd + r[1][2] * zd + self.t[1];
            let wz = r[2][0] * xd + r[2][1] * yd + r[2][2] * zd + self.t[2];
            let (qx, qy) = (wx * inv, wy * inv);
            let (fx, fy) = (floor_small(qx).0, floor_small(qy).0);
            let (bx, in_x) = wrap(fx, ox, sx);
            let (by, in_y) = wrap(fy, oy, sy);
            // Exact: both below 2¹⁵, the index below 2³⁰.
            l.idx[j] = floor_small(by * nf + bx).1 as u32;
            // `quantize_mm`.
            let mm = (wz - self.z_ref) * 1000.0 + 0.5;
            let z_ok = mm > -(i32::MAX as f64) && mm < i32::MAX as f64;
            l.z_mm[j] = floor_small(mm).1;
            let fast = finite & edge_ok(qx, fx) & edge_ok(qy, fy) & z_ok;
            l.kind[j] = if !fast {
                LANE_SCALAR
            } else if in_x & in_y {
                LANE_SAMPLE
            } else {
                LANE_OUTSIDE
            };
            let (ex, ey, ez) = (x - self.so[0], y - self.so[1], z - self.so[2]);
            let range = ((ex * ex + ey * ey + ez * ez) as f64).sqrt();
            let sigma = self.noise.sigma(range);
            // `weight_of`: for w ≥ 1 the rounded value is positive and below 2³¹, so its
            // floor is the truncation `as i64` makes.
            let rr = SIGMA_REF_M / sigma;
            let w = W_UNIT * rr * rr;
            let wr = if w >= 1.0 {
                w.min(W_MAX as f64) + 0.5
            } else {
                1.0
            };
            l.w[j] = floor_small(wr).1 as u32;
            l.code[j] = share_code(vertical_share(wz - self.so_z_map, range));
            l.sigma_mm[j] = (sigma * 1000.0) as f32;
        }
    }

    #[inline]
    fn classify(&self, i: usize) -> Classified {
        let [x, y, z] = self.cloud.xyz[i];
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            return Classified::NonFinite;
        }
        let (xd, yd, zd) = (x as f64, y as f64, z as f64);
        let r = &self.rot;
        let wx = r[0][0] * xd + r[0][1] * yd + r[0][2] * zd + self.t[0];
        let wy = r[1][0] * xd + r[1][1] * yd + r[1][2] * zd + self.t[1];
        let wz = r[2][0] * xd + r[2][1] * yd + r[2][2] * zd + self.t[2];
        // A finite point far beyond any window (1e30 m) has a cell coordinate near i64::MAX:
        // the offset from the window overflows, and such a point is outside.
        let (Some(dx), Some(dy)) = (
            cell_coord(wx, self.inv_res, self.res).checked_sub(self.origin.0),
            cell_coord(wy, self.inv_res, self.res).checked_sub(self.origin.1),
        ) else {
            return Classified::Outside;
        };
        if dx < 0 || dx >= self.n || dy < 0 || dy >= self.n {
            return Classified::Outside;
        }
        let Some(z_mm) = quantize_mm(wz - self.z_ref) else {
            return Classified::Outside;
        };
        let mut bx = dx + self.shift.0;
        if bx >= self.n {
            bx -= self.n;
        }
        let mut by = dy + self.shift.1;
        if by >= self.n {
            by -= self.n;
        }
        let (ex, ey, ez) = (x - self.so[0], y - self.so[1], z - self.so[2]);
        let range = ((ex * ex + ey * ey + ez * ez) as f64).sqrt();
        let sigma = self.noise.sigma(range);
        let code = share_code(vertical_share(wz - self.so_z_map, range));
        Classified::Sample(Sample {
            idx: (by * self.n + bx) as u32,
            z_mm,
            wv: weight_of(sigma) | code << W_BITS,
            sigma_mm: (sigma * 1000.0) as f32,
        })
    }
}

/// Smallest share of a point's range noise that reaches its height: the sine of the
/// most grazing ray (about 3°) whose vertical error is still taken from its range error.
/// Below it, the beam's footprint and the ground's roughness across it, not the range
/// noise, decide the height, and they do not shrink with the angle.
const MIN_VERTICAL_SHARE: f64 = 0.05;

/// The share of a point's range noise that reaches its height: a range sensor errs along
/// its ray, so a point `dz` metres above or below the sensor at `range` is `|dz|/range`
/// of its range error off in height (at least [`MIN_VERTICAL_SHARE`]). A grazing lidar
/// return at 20 m is a few millimetres off in height although its range is centimetres
/// off; a point straight below the sensor carries all of it.
#[inline]
#[allow(clippy::manual_clamp)] // `clamp` would keep a NaN
fn vertical_share(dz: f64, range: f64) -> f64 {
    // `f64::max` takes the floor over a NaN (a point at the sensor).
    (dz.abs() / range).max(MIN_VERTICAL_SHARE).min(1.0)
}

/// Gate distance (mm) below a surface of spread `var_mm2` for a point of noise `sigma_mm`.
#[inline]
fn gate_mm(var_mm2: f64, sigma_mm: f64, k: f64, min_mm: f64) -> f64 {
    (k * (var_mm2 + sigma_mm * sigma_mm).sqrt()).max(min_mm)
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

    /// What classifying `cloud`'s points into this grid needs.
    fn ctx<'a>(&self, cloud: &'a PointCloud, noise: &RangeNoise) -> Ctx<'a> {
        let n = self.n as i64;
        let m = cloud.frame_to_map.to_homogeneous();
        Ctx {
            cloud,
            rot: [
                [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
                [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
                [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
            ],
            t: [m[(0, 3)], m[(1, 3)], m[(2, 3)]],
            so: [
                cloud.sensor_origin.x as f32,
                cloud.sensor_origin.y as f32,
                cloud.sensor_origin.z as f32,
            ],
            so_z_map: cloud.sensor_origin_in_map().z,
            res: self.cfg.resolution,
            inv_res: 1.0 / self.cfg.resolution,
            z_ref: self.cfg.z_ref,
            n,
            origin: (self.origin.x, self.origin.y),
            shift: (self.origin.x.rem_euclid(n), self.origin.y.rem_euclid(n)),
            noise: *noise,
        }
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

        // Pass 2, in parallel over buckets (each owns its cells' records and its part of
        // the sort buffer): sort the bucket's samples by cell, then walk the cells in
        // buffer order, each read and written once: gate its samples against the prior
        // surface, accumulate, and merge, or split its batch points at height gaps. All
        // sums are exact integers, so neither the chunking nor the order of the samples
        // changes a cell.
        let counts: Vec<usize> = (0..nbuckets)
            .map(|bi| binned.iter().map(|p| p.buckets[bi].len()).sum())
            .collect();
        let dense = |c: usize| c >= BUCKET_CELLS * DENSE;
        let sorted_len = |c: usize| if dense(c) { 0 } else { c };
        let total: usize = counts.iter().map(|&c| sorted_len(c)).sum();
        if scratch.sorted.len() < total {
            scratch.sorted.resize(total, Sample::ZERO);
        }
        // Buckets are dealt to `chunks` tasks in turn (bucket `bi` to task `bi % chunks`),
        // each with its own dense accumulators; a bucket's result does not depend on which
        // task fuses it.
        if scratch.acc.len() < chunks {
            scratch.acc.resize_with(chunks, Dense::default);
        }
        let mut rest = &mut scratch.sorted[..total];
        let mut tasks: Vec<Task> = (0..chunks).map(|_| Vec::new()).collect();
        for (bi, (lay, &c)) in split_buckets(layers).into_iter().zip(&counts).enumerate() {
            let (out, r) = std::mem::take(&mut rest).split_at_mut(sorted_len(c));
            rest = r;
            tasks[bi % chunks].push((bi, lay, out));
        }
        let add = |a: (u64, u64), b: (u64, u64)| (a.0 + b.0, a.1 + b.1);
        let run = |(task, acc): (Task, &mut Dense)| {
            let mut sum = (0, 0);
            for (bi, mut lay, out) in task {
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
        let (fused, below) = if chunks == 1 {
            // A batch too small to split into chunks is fused on this thread too.
            tasks.into_iter().zip(pool).map(run).fold((0, 0), add)
        } else {
            tasks
                .into_par_iter()
                .zip(pool.par_iter_mut())
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

/// Pass 1 for the points `range`: classify them into `p`'s buckets. Where the CPU has AVX2
/// (detected at run time) the same code is compiled for it: twice the lanes per vector
/// instruction, and the same results (the same IEEE operations, no fused multiply-add).
fn bin_chunk(ctx: &Ctx, range: std::ops::Range<usize>, nbuckets: usize, p: &mut Binned) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        return unsafe { bin_chunk_avx2(ctx, range, nbuckets, p) };
    }
    bin_chunk_baseline(ctx, range, nbuckets, p)
}

/// [`bin_chunk`] for the baseline target. (Not inlined: the profile then tells the two
/// passes apart, and the call is once per chunk.)
#[inline(never)]
fn bin_chunk_baseline(ctx: &Ctx, range: std::ops::Range<usize>, nbuckets: usize, p: &mut Binned) {
    bin_chunk_impl(ctx, range, nbuckets, p)
}

/// [`bin_chunk`] compiled for AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline(never)]
unsafe fn bin_chunk_avx2(
    ctx: &Ctx,
    range: std::ops::Range<usize>,
    nbuckets: usize,
    p: &mut Binned,
) {
    bin_chunk_impl(ctx, range, nbuckets, p)
}

#[inline(always)]
fn bin_chunk_impl(ctx: &Ctx, range: std::ops::Range<usize>, nbuckets: usize, p: &mut Binned) {
    p.buckets.resize_with(nbuckets, Vec::new);
    for b in &mut p.buckets {
        b.clear();
    }
    let mut st = IngestStats {
        points: range.len() as u64,
        ..Default::default()
    };
    let buckets = &mut p.buckets;
    let mut emit = |c: Classified| match c {
        Classified::Sample(s) => buckets[(s.idx >> BUCKET_SHIFT) as usize].push(s),
        Classified::NonFinite => st.nonfinite += 1,
        Classified::Outside => st.outside += 1,
    };
    let mut i = range.start;
    let mut l = Lanes::default();
    while i + LANES <= range.end && ctx.lanes_exact() {
        ctx.classify_lanes(i, &mut l);
        for j in 0..LANES {
            // Field by field: a `Classified` built and moved here costs a store-forwarding
            // stall per point.
            match l.kind[j] {
                LANE_SAMPLE => emit(Classified::Sample(Sample {
                    idx: l.idx[j],
                    z_mm: l.z_mm[j],
                    wv: l.w[j] | l.code[j] << W_BITS,
                    sigma_mm: l.sigma_mm[j],
                })),
                LANE_OUTSIDE => emit(Classified::Outside),
                _ => emit(ctx.classify(i + j)),
            }
        }
        i += LANES;
    }
    for i in i..range.end {
        emit(ctx.classify(i));
    }
    p.stats = st;
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
fn fuse_bucket(
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

/// Pass 2 for a dense bucket `bi`, through its accumulators `acc` (all default on entry
/// and on return): returns (fused, below) point counts. The same rules as
/// [`fuse_bucket`], sample by sample.
#[inline(never)]
fn fuse_dense(
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

/// Splits the batch points of cell `l` at height gaps and merges the result; returns the
/// number of points counted below the surface (all others are fused).
fn split_and_merge(lay: &mut ElevMut, l: usize, pts: &mut [Sample], k: f64, min_mm: f64) -> u32 {
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

/// The exact gate test against the prior surface (taken only below the fast threshold).
#[cold]
fn is_below(prior: &ElevMut, i: usize, support: u32, s: &Sample, k: f64, min_mm: f64) -> bool {
    match prior_gate(prior, i, support) {
        Some((mean, var)) => {
            (s.z_mm as f64) < mean as f64 - gate_mm(var as f64, s.sigma_mm as f64, k, min_mm)
        }
        None => false,
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::pose_xyz_rpy;
    use crate::grid::GridConfig;
    use proptest::prelude::*;

    /// A sample as (idx, z_mm, weight and share, σ bits).
    type Bits = (u32, i32, u32, u32);

    /// Everything a binning produced, comparable (σ by its bits).
    fn outcome(p: &Binned) -> (IngestStats, Vec<Vec<Bits>>) {
        let b = p
            .buckets
            .iter()
            .map(|v| {
                v.iter()
                    .map(|s| (s.idx, s.z_mm, s.wv, s.sigma_mm.to_bits()))
                    .collect()
            })
            .collect();
        (p.stats, b)
    }

    /// Coordinates that stress the fast path: cell edges (exact multiples of the
    /// resolution), values a hair off them, non-finite and huge values.
    fn coord() -> impl Strategy<Value = f32> {
        prop_oneof![
            4 => -25.0f32..25.0,
            2 => (-250i32..250).prop_map(|k| k as f32 * 0.1),
            1 => (-250i32..250, -3i32..=3).prop_map(|(k, u)| f32::from_bits(
                ((k as f32 * 0.1).to_bits() as i32 + u) as u32
            )),
            1 => Just(f32::NAN),
            1 => Just(f32::INFINITY),
            1 => prop_oneof![Just(1e30f32), Just(-3e9), Just(2.1e9), Just(1e-40)],
        ]
    }

    /// Pass 2 of `cloud` into `g` with every bucket fused by one path: 0 sorts by
    /// comparison, 1 by counting, 2 through dense accumulators.
    fn fuse_by(g: &mut RollingGrid, cloud: &PointCloud, path: u8) -> (u64, u64) {
        let ctx = g.ctx(cloud, &RangeNoise::LIDAR);
        let nb = (g.n * g.n).div_ceil(BUCKET_CELLS);
        let mut p = Binned::default();
        bin_chunk(&ctx, 0..cloud.len(), nb, &mut p);
        let binned = [p];
        let (k, min_mm) = (g.cfg.gate_sigma, g.cfg.gate_min_m * 1000.0);
        let support = g.cfg.min_support.max(1);
        let mut acc = Dense {
            cells: vec![Acc::default(); BUCKET_CELLS],
            swv: vec![0; BUCKET_CELLS],
        };
        let mut sum = (0, 0);
        for (bi, mut lay) in split_buckets(&mut g.layers).into_iter().enumerate() {
            let mut out = vec![Sample::ZERO; binned[0].buckets[bi].len()];
            let (f, b) = match path {
                2 => fuse_dense(&binned, bi, &mut lay, &mut acc, k, min_mm, support),
                _ => fuse_bucket(
                    &binned,
                    bi,
                    &mut lay,
                    &mut out,
                    path == 1,
                    k,
                    min_mm,
                    support,
                ),
            };
            assert!(acc
                .cells
                .iter()
                .all(|a| a.is_untouched() && a.group == u32::MAX));
            assert!(acc.swv.iter().all(|&v| v == 0));
            sum = (sum.0 + f, sum.1 + b);
        }
        sum
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The three ways pass 2 fuses a bucket (sorted by comparison, sorted by counting,
        /// dense accumulators) give the same grid and the same counts, batch after batch:
        /// the prior gate (second batch) and the first batch's split both run.
        #[test]
        fn every_fuse_path_gives_the_same_grid(
            pts in prop::collection::vec(
                (-1.0f32..1.0, -1.0f32..1.0, -0.05f32..0.05, 0u8..8), 1..3000),
            cut in 0usize..3000,
        ) {
            let xyz: Vec<[f32; 3]> = pts
                .iter()
                .map(|&(x, y, dz, kind)| {
                    [x, y, 0.2 * (x * 0.5).sin() + dz - if kind == 0 { 0.9 } else { 0.0 }]
                })
                .collect();
            let cut = cut % xyz.len();
            let batches = [
                PointCloud::unorganized(xyz[..cut].to_vec()),
                PointCloud::unorganized(xyz[cut..].to_vec()),
            ];
            let cfg = GridConfig { size_cells: 100, ..GridConfig::default() };
            let run = |path: u8| {
                let mut g = RollingGrid::new(cfg.clone(), 0.0, 0.0).unwrap();
                let counts: Vec<_> = batches.iter().map(|b| fuse_by(&mut g, b, path)).collect();
                (g, counts)
            };
            let (g0, c0) = run(0);
            // Cells of 0.1 m: a few points a cell, so that the prior gates the second
            // batch (whose reflections are counted below) once the first is large.
            if cut >= 2000 && xyz.len() - cut >= 200 {
                prop_assert!(c0[1].1 > 0, "no point of the second batch was gated");
            }
            for path in [1, 2] {
                let (g, c) = run(path);
                prop_assert_eq!(&c, &c0, "path {}", path);
                prop_assert!(g == g0, "grids differ on path {}", path);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        /// The lane classifier (baseline and, where the CPU has it, AVX2) bins every point
        /// exactly as the scalar classifier does.
        #[test]
        fn lane_classifier_is_the_scalar_one(
            pts in prop::collection::vec((coord(), coord(), coord()), 0..400),
            pose in (-1e4f64..1e4, -1e4f64..1e4, -50f64..50.0, -0.2f64..0.2, 0f64..6.3),
            centre in prop_oneof![Just((0.0, 0.0)), (-1e6f64..1e6, -1e6f64..1e6)],
            z_ref in -100f64..100.0,
            noise in prop_oneof![
                Just(RangeNoise::LIDAR),
                Just(RangeNoise::STEREO),
                (1e-4f64..1.0).prop_map(RangeNoise::constant),
            ],
            size in prop_oneof![Just(16usize), Just(400), Just(700)],
            moved in any::<bool>(),
        ) {
            let cfg = GridConfig { size_cells: size, z_ref, ..GridConfig::default() };
            let g = RollingGrid::new(cfg, centre.0, centre.1).unwrap();
            let mut cloud = PointCloud::unorganized(
                pts.iter().map(|&(x, y, z)| [x, y, z]).collect(),
            );
            if moved {
                cloud.frame_to_map = pose_xyz_rpy(
                    pose.0 + centre.0, pose.1 + centre.1, pose.2, pose.3, 0.0, pose.4,
                );
                cloud.sensor_origin = nalgebra::Point3::new(0.5, -0.25, 1.5);
            }
            let ctx = g.ctx(&cloud, &noise);
            let nb = (size * size).div_ceil(BUCKET_CELLS);
            let mut want = Binned::default();
            want.buckets.resize_with(nb, Vec::new);
            want.stats.points = cloud.len() as u64;
            for i in 0..cloud.len() {
                match ctx.classify(i) {
                    Classified::Sample(s) => {
                        want.buckets[(s.idx >> BUCKET_SHIFT) as usize].push(s)
                    }
                    Classified::NonFinite => want.stats.nonfinite += 1,
                    Classified::Outside => want.stats.outside += 1,
                }
            }
            let mut got = Binned::default();
            bin_chunk_baseline(&ctx, 0..cloud.len(), nb, &mut got);
            prop_assert_eq!(outcome(&got), outcome(&want));
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                let mut got = Binned::default();
                // SAFETY: checked just above.
                unsafe { bin_chunk_avx2(&ctx, 0..cloud.len(), nb, &mut got) };
                prop_assert_eq!(outcome(&got), outcome(&want));
            }
        }
    }
}
