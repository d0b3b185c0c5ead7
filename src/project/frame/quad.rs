//! A sampled pixel's votes: every cell the quad between its hit and its neighbours' covers
//! ([`quad_votes`], [`quad_cells`]).

use nalgebra::Vector4;
use rayon::prelude::*;

use super::place::Hit;
use crate::geom::{ceil_i64, floor_i64};
use crate::grid::CellKey;
use crate::project::GridSurface;

/// Largest side (metres) of a pixel's quad that votes over the cells it covers: larger
/// ones straddle an occlusion edge.
const QUAD_MAX_M: f64 = 3.0;

/// The cell votes (raster index, water, level) of each sampled row of `hits` (`nr` × `nc`)
/// into `votes`, rows in parallel. Each sampled pixel stands for the quad spanned by its
/// hit and those of its right, lower and diagonal neighbours: when all four agree and the
/// quad is no larger than [`QUAD_MAX_M`], every cell the quad overlaps gets the vote once
/// (a pixel row covers a metre of ground at 20 m, far more than a cell; [`quad_cells`]);
/// otherwise only the pixel's own cell.
pub(super) fn quad_votes(
    surface: &GridSurface,
    hits: &[Option<Hit>],
    nr: usize,
    nc: usize,
    votes: &mut Vec<Vec<(u32, bool, f32)>>,
) {
    if votes.len() < nr {
        votes.resize_with(nr, Vec::new);
    }
    votes[..nr].par_iter_mut().enumerate().for_each(|(r, out)| {
        out.clear();
        let row = &hits[r * nc..(r + 1) * nc];
        let next = hits.get((r + 1) * nc..(r + 2) * nc);
        for c in 0..nc {
            row_vote(surface, row, next, c, out);
        }
    });
}

/// The votes of sampled pixel `c` of `row` (the next row below: `next`) into `out`.
fn row_vote(
    surface: &GridSurface,
    row: &[Option<Hit>],
    next: Option<&[Option<Hit>]>,
    c: usize,
    out: &mut Vec<(u32, bool, f32)>,
) {
    let Some(h00) = row[c] else { return };
    let wet = h00.wet;
    let quad = next.and_then(|nx| {
        let q = [*row.get(c + 1)?.as_ref()?, nx[c]?, (*nx.get(c + 1)?)?];
        q.iter()
            .all(|h| h.wet == wet)
            .then_some([h00, q[0], q[1], q[2]])
    });
    // |a − b| ≤ QUAD_MAX_M as |a − b|² ≤ QUAD_MAX_M², the same verdict: the root is
    // correctly rounded and QUAD_MAX_M² exact.
    let quad = quad.filter(|q| {
        [(0, 1), (0, 2), (1, 3), (2, 3)]
            .iter()
            .all(|&(a, b)| (q[a].p - q[b].p).norm_squared() <= QUAD_MAX_M * QUAD_MAX_M)
    });
    match quad {
        None => {
            if let Some(j) = surface.index_of(h00.p.x, h00.p.y) {
                out.push((j as u32, wet, h00.level as f32));
            }
        }
        Some(q) => {
            let before = out.len();
            quad_cells(
                surface,
                q.map(|h| Vector4::new(h.p.x, h.p.y, h.p.z, h.level)),
                |j, level| out.push((j as u32, wet, level as f32)),
            );
            if out.len() == before {
                // A degenerate quad (no area, or a corner not finite): the pixel's own
                // cell.
                if let Some(j) = surface.index_of(h00.p.x, h00.p.y) {
                    out.push((j as u32, wet, h00.level as f32));
                }
            }
        }
    }
}

/// Calls `f(raster index, level)` once for every cell of `surface` that the quad of pixel
/// hits `q` = [a, b, c, d] overlaps (a = pixel (x, y), b = (x + s, y), c = (x, y + s),
/// d = (x + s, y + s); each (x, y, z, level)): the quad stands for the ground between the
/// four hits, and every cell it covers, even in part, gets the pixel's vote once. The quad
/// is split into the triangles a-b-d and a-d-c; a cell overlaps a triangle when no axis
/// separates them (x, y and the three edge normals). The level is interpolated linearly
/// over the triangle at the cell's centre. A cell that overlaps both triangles counts once.
pub(super) fn quad_cells(
    surface: &GridSurface,
    q: [Vector4<f64>; 4],
    mut f: impl FnMut(usize, f64),
) {
    if !q.iter().all(|p| p.iter().all(|v| v.is_finite())) {
        return;
    }
    let [a, b, c, d] = q;
    let res = surface.resolution();
    let (o, n) = (surface.origin(), surface.size() as i64);
    // The quad is split into the triangles a-b-d and a-d-c. Everything of a triangle that
    // does not depend on the cell is taken once (the same arithmetic, in the same order,
    // as a cell-by-cell barycentric test: the results are bit for bit those).
    let tris = [
        Tri::new([a, b, d], res, o, n),
        Tri::new([a, d, c], res, o, n),
    ];
    for (k, t) in tris.iter().enumerate() {
        let Some(t) = t else { continue };
        let [i0, i1, j0, j1] = t.range;
        for j in j0..=j1 {
            let y = (j as f64 + 0.5) * res;
            for i in i0..=i1 {
                let x = (i as f64 + 0.5) * res;
                let Some(l) = t.bary(x, y) else { continue };
                // A cell that overlaps both triangles counts once, with the first.
                if k == 1 && tris[0].as_ref().is_some_and(|t0| t0.overlaps(i, j, x, y)) {
                    continue;
                }
                let level = l[0] * t.p[0].w + l[1] * t.p[1].w + l[2] * t.p[2].w;
                f(((j - o.y) * n + (i - o.x)) as usize, level);
            }
        }
    }
}

/// One triangle of [`quad_cells`]: what the test of a cell against it needs, taken once.
struct Tri {
    p: [Vector4<f64>; 3],
    /// p1 − p0 and p2 − p0 (x, y).
    u: [f64; 2],
    v: [f64; 2],
    det: f64,
    /// Per vertex i: −half·(|e.x| + |e.y|) for the edge e opposite it: how far outside
    /// that edge (times |det|·|e|⁻¹) a cell centre may lie while the cell still reaches it.
    reach: [f64; 3],
    /// Cells (global keys) whose centres lie within half a cell of the bounding box,
    /// clipped to the window: i0, i1, j0, j1.
    range: [i64; 4],
}

impl Tri {
    /// `None` for a triangle without area (no cell overlaps it).
    fn new(p: [Vector4<f64>; 3], res: f64, o: CellKey, n: i64) -> Option<Self> {
        let [p0, p1, p2] = p;
        let (u, v) = ([p1.x - p0.x, p1.y - p0.y], [p2.x - p0.x, p2.y - p0.y]);
        let det = u[0] * v[1] - v[0] * u[1];
        if det.abs() <= f64::EPSILON * res * res {
            return None;
        }
        let half = 0.5 * res;
        let reach = std::array::from_fn(|i| {
            let e = p[(i + 1) % 3] - p[(i + 2) % 3];
            -half * (e.x.abs() + e.y.abs())
        });
        let lo = |v: fn(&Vector4<f64>) -> f64| p.iter().map(v).fold(f64::INFINITY, f64::min);
        let hi = |v: fn(&Vector4<f64>) -> f64| p.iter().map(v).fold(f64::NEG_INFINITY, f64::max);
        let first = |m: f64, origin: i64| ceil_i64((m - half) / res - 0.5).max(origin);
        let last = |m: f64, origin: i64| floor_i64((m + half) / res - 0.5).min(origin + n - 1);
        let range = [
            first(lo(|p| p.x), o.x),
            last(hi(|p| p.x), o.x),
            first(lo(|p| p.y), o.y),
            last(hi(|p| p.y), o.y),
        ];
        Some(Tri {
            p,
            u,
            v,
            det,
            reach,
            range,
        })
    }

    /// Barycentric coordinates of the centre (x, y), if the cell overlaps the triangle:
    /// `l[i]·|det| / |e|` is the distance of the centre inside the edge e opposite vertex
    /// i, and the cell reaches `(|e.x| + |e.y|)·half / |e|` beyond its centre along that
    /// edge's normal.
    #[inline]
    fn bary(&self, x: f64, y: f64) -> Option<[f64; 3]> {
        let (p0, [ux, uy], [vx, vy], det) = (&self.p[0], self.u, self.v, self.det);
        let l1 = ((x - p0.x) * vy - vx * (y - p0.y)) / det;
        let l2 = (ux * (y - p0.y) - (x - p0.x) * uy) / det;
        let l = [1.0 - l1 - l2, l1, l2];
        let ad = det.abs();
        (0..3).all(|i| l[i] * ad >= self.reach[i]).then_some(l)
    }

    /// Whether cell (i, j), centre (x, y), is in the range and overlaps the triangle.
    #[inline]
    fn overlaps(&self, i: i64, j: i64, x: f64, y: f64) -> bool {
        let [i0, i1, j0, j1] = self.range;
        (i0..=i1).contains(&i) && (j0..=j1).contains(&j) && self.bary(x, y).is_some()
    }
}
