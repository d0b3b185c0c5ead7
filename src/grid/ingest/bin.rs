//! Pass 1 of ingest: classifying a chunk of points into buckets of cells, a lane of
//! points at a time on the fast path ([`Ctx::classify_lanes`]), one at a time off it.

use super::sample::{share_code, vertical_share, Sample, W_BITS};
use super::{weight_of, Binned, IngestStats, RangeNoise, RollingGrid, BUCKET_SHIFT};
use crate::geom::{cell_coord, PointCloud};
use crate::grid::cell::{quantize_mm, SIGMA_REF_M, W_MAX, W_UNIT};

/// What [`Ctx::classify`] makes of one point.
pub(super) enum Classified {
    Sample(Sample),
    NonFinite,
    Outside,
}

/// Everything the per-point work needs, read-only.
pub(super) struct Ctx<'a> {
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
pub(super) fn floor_small(q: f64) -> (f64, i32) {
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
    pub(super) fn classify(&self, i: usize) -> Classified {
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

impl RollingGrid {
    /// What classifying `cloud`'s points into this grid needs.
    pub(super) fn ctx<'a>(&self, cloud: &'a PointCloud, noise: &RangeNoise) -> Ctx<'a> {
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
}

/// Pass 1 for the points `range`: classify them into `p`'s buckets. Where the CPU has AVX2
/// (detected at run time) the same code is compiled for it: twice the lanes per vector
/// instruction, and the same results (the same IEEE operations, no fused multiply-add).
pub(super) fn bin_chunk(ctx: &Ctx, range: std::ops::Range<usize>, nbuckets: usize, p: &mut Binned) {
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
pub(super) fn bin_chunk_baseline(
    ctx: &Ctx,
    range: std::ops::Range<usize>,
    nbuckets: usize,
    p: &mut Binned,
) {
    bin_chunk_impl(ctx, range, nbuckets, p)
}

/// [`bin_chunk`] compiled for AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline(never)]
pub(super) unsafe fn bin_chunk_avx2(
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
