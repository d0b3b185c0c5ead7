//! The label stage's z-buffer: how far along each sampled pixel's ray the march over the
//! map ([`GridSurface::cast_through_holes`]) can start, found by drawing the map into the
//! image once rather than by marching every ray from the camera.
//!
//! The march sees each observed cell as a flat top at its elevation, and places a ray in a
//! hole (unobserved cells) where it drops below the lower of the hole's two rims along it.
//! The z-buffer draws a surface that is nowhere below either: a mesh over the cells' corners
//! (two triangles per cell), each corner as high as the highest of the cells that share it,
//! where a hole cell counts as high as the highest rim (an observed cell beside a hole)
//! within [`REACH_M`]. A ray meets that surface no later than the march meets anything, so
//! the march resumed there ([`GridSurface::cast_through_holes_after`]) gives what the whole
//! march gives, in a few steps. A ray that meets nothing drawn meets no observed ground in
//! the march either; it can only drop into a hole too wide to be drawn, which only a water
//! pixel is placed in. The label stage's votes are the march's.
//!
//! Far away, where many cells fall between two sampled pixels, the cells are pooled by
//! their maximum, 2 × 2 beyond [`LOD_CELLS`]`[0]` cells and 4 × 4 beyond `[1]`: the mesh
//! stays nowhere below a cell's top, and the march resumes a little sooner. The levels'
//! rings overlap, so no ray slips between them.
//!
//! Every corner within the label range and the camera's field of view is projected once;
//! each triangle is filled into the sampled pixels whose centres it covers, and a sample
//! keeps the nearest distance along its own ray (the triangle's plane met by the pixel's
//! exact ray). Bands of cell rows are drawn in parallel, each into its own buffer, and the
//! buffers are merged by their minimum: the result does not depend on the thread count.

use nalgebra::{Point3, Rotation3, Vector3};
use rayon::prelude::*;

use super::surface::GridSurface;
use crate::geom::{ceil_i64, floor_i64, CameraModel, Pose};
use crate::grid::CellKey;

/// Cells per side of the blocks over which the rims' heights are taken.
const BLOCK: usize = 8;
/// A hole is drawn at the highest rim within about this distance (metres).
const REACH_M: f64 = 6.0;
/// A sample this close to a triangle (in sample spacings) counts as covered by it: the
/// lens bends the triangle's edges, which are drawn straight between its corners.
const TOLERANCE: f64 = 0.05;
/// Beyond these distances (in cells) the map is drawn from its cells pooled 2 × 2, then
/// 4 × 4.
const LOD_CELLS: [f64; 2] = [60.0, 150.0];
/// Bands of cell rows drawn in parallel.
const BANDS: usize = 4;

/// The z-buffer's storage, kept from frame to frame (sizes follow the label range and the
/// image, not the window).
#[derive(Debug, Clone, Default)]
pub(crate) struct ZBuffer {
    /// Per band, per sample: the distance along its ray of the nearest surface met (∞:
    /// none). The first band's holds the merged result.
    t: Vec<Vec<f32>>,
    /// Per block of the drawn region: its highest rim cell, then its holes' cover.
    rim: Vec<f32>,
    cover: Vec<f32>,
    blocks_wide: usize,
    /// The region drawn: first column and row (window cells) and its size.
    region: [usize; 4],
}

/// The horizontal field of view as a wedge: apex and the unit directions of its two sides
/// (counter-clockwise from `lo` to `hi`).
struct Wedge {
    apex: [f64; 2],
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Wedge {
    /// The wedge of the rays' horizontal directions, widened by a margin and with its apex
    /// moved back by a few cells, so that a triangle at the image's edge is drawn whole.
    /// `None` when the rays span nearly half a turn or more, or one of them is vertical.
    fn of_rays(rays: &[Vector3<f64>], origin: &Point3<f64>, res: f64) -> Option<Self> {
        let mut m = [0.0, 0.0];
        for r in rays {
            let h = r.xy().norm();
            if h.is_nan() || h < 1e-6 {
                return None;
            }
            m[0] += r.x / h;
            m[1] += r.y / h;
        }
        let mn = (m[0] * m[0] + m[1] * m[1]).sqrt();
        if mn.is_nan() || mn < 1e-9 {
            return None;
        }
        let m = [m[0] / mn, m[1] / mn];
        let (mut a_lo, mut a_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for r in rays {
            let a = (m[0] * r.y - m[1] * r.x).atan2(m[0] * r.x + m[1] * r.y);
            a_lo = a_lo.min(a);
            a_hi = a_hi.max(a);
        }
        let margin = 2f64.to_radians();
        let (a_lo, a_hi) = (a_lo - margin, a_hi + margin);
        if !(a_lo > -85f64.to_radians() && a_hi < 85f64.to_radians()) {
            return None;
        }
        let rot = |a: f64| {
            let (s, c) = a.sin_cos();
            [c * m[0] - s * m[1], s * m[0] + c * m[1]]
        };
        let back = 4.0 * res;
        Some(Wedge {
            apex: [origin.x - back * m[0], origin.y - back * m[1]],
            lo: rot(a_lo),
            hi: rot(a_hi),
        })
    }

    #[inline]
    fn contains(&self, x: f64, y: f64) -> bool {
        let (qx, qy) = (x - self.apex[0], y - self.apex[1]);
        self.lo[0] * qy - self.lo[1] * qx >= 0.0 && qx * self.hi[1] - qy * self.hi[0] >= 0.0
    }

    /// The bounding box (x0, x1, y0, y1) of the wedge cut at `range` from its apex.
    fn bounds(&self, range: f64) -> [f64; 4] {
        let a0 = self.lo[1].atan2(self.lo[0]);
        let mut a1 = self.hi[1].atan2(self.hi[0]);
        if a1 < a0 {
            a1 += std::f64::consts::TAU;
        }
        let mut b = [self.apex[0], self.apex[0], self.apex[1], self.apex[1]];
        let mut add = |a: f64| {
            let (x, y) = (
                self.apex[0] + range * a.cos(),
                self.apex[1] + range * a.sin(),
            );
            b = [b[0].min(x), b[1].max(x), b[2].min(y), b[3].max(y)];
        };
        add(a0);
        add(a1);
        // The axis directions inside the wedge bound it too.
        let mut q = (a0 / std::f64::consts::FRAC_PI_2).ceil() * std::f64::consts::FRAC_PI_2;
        while q < a1 {
            add(q);
            q += std::f64::consts::FRAC_PI_2;
        }
        b
    }
}

/// The sampled pixels: columns every `col_step` from `cols0`, and rows (sorted; uniform
/// with `row_step` when it is `Some`).
#[derive(Clone, Copy)]
struct Samples<'a> {
    rows: &'a [usize],
    row_step: Option<usize>,
    cols0: usize,
    col_step: usize,
    nc: usize,
    width: usize,
}

impl<'a> Samples<'a> {
    /// The samples `rows` × `cols` of an image `width` pixels wide (`cols` evenly spaced).
    fn of(rows: &'a [usize], cols: &'a [usize], width: usize) -> Self {
        let uniform = |v: &[usize]| {
            let s = v.get(1).map_or(1, |b| b - v[0]);
            (s > 0 && v.windows(2).all(|p| p[1] - p[0] == s)).then_some(s)
        };
        Samples {
            rows,
            row_step: uniform(rows),
            cols0: cols[0],
            col_step: uniform(cols).unwrap_or(1),
            nc: cols.len(),
            width,
        }
    }

    /// The sampled rows with `lo ≤ y ≤ hi`, as a range of row indices; `y` is the row
    /// index itself when the rows are uniform, else the pixel row.
    #[inline]
    fn rows_within(&self, lo: f64, hi: f64) -> std::ops::Range<usize> {
        let n = self.rows.len();
        match self.row_step {
            Some(_) => {
                let r0 = ceil_i64(lo).clamp(0, n as i64);
                let r1 = (floor_i64(hi) + 1).clamp(r0, n as i64);
                r0 as usize..r1 as usize
            }
            None => {
                let r0 = self.rows.partition_point(|&y| (y as f64) < lo);
                let r1 = self.rows.partition_point(|&y| (y as f64) <= hi);
                r0..r1.max(r0)
            }
        }
    }
}

impl ZBuffer {
    /// Bytes held between frames.
    pub(crate) fn heap_bytes(&self) -> usize {
        self.t
            .iter()
            .map(|t| t.capacity() * std::mem::size_of::<f32>())
            .sum::<usize>()
            + (self.rim.capacity() + self.cover.capacity()) * 4
    }

    /// Draws `surface` into the samples (`rows` × `cols` pixels of `camera` at `cam_to_map`,
    /// `cols` evenly spaced; `map_rays` the image's unit pixel rays in the map frame,
    /// row-major), within `max_range` metres along each ray.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn draw(
        &mut self,
        surface: &GridSurface,
        camera: &CameraModel,
        cam_to_map: &Pose,
        map_rays: &[Option<Vector3<f64>>],
        rows: &[usize],
        cols: &[usize],
        max_range: f64,
    ) {
        let (nr, nc) = (rows.len(), cols.len());
        self.t.resize_with(BANDS, Vec::new);
        for t in &mut self.t {
            t.clear();
            t.resize(nr * nc, f32::INFINITY);
        }
        self.region = [0; 4];
        let origin = Point3::from(cam_to_map.translation.vector);
        let (n, res) = (surface.size(), surface.resolution());
        if nr == 0 || nc == 0 || n == 0 || !origin.coords.iter().all(|v| v.is_finite()) {
            return;
        }
        // The horizontal field of view, from the sampled rays on the image's border.
        let w = camera.width;
        let border: Vec<Vector3<f64>> = (0..nr)
            .flat_map(|r| [(r, 0), (r, nc - 1)])
            .chain((0..nc).flat_map(|c| [(0, c), (nr - 1, c)]))
            .filter_map(|(r, c)| map_rays[rows[r] * w + cols[c]])
            .collect();
        let wedge = Wedge::of_rays(&border, &origin, res);
        let reach = max_range + 2.0 * res;
        if !self.set_region(surface, wedge.as_ref(), &origin, reach) {
            return;
        }
        self.find_covers(surface.raster(), n, res);
        let view = View::new(
            camera,
            cam_to_map,
            map_rays,
            Samples::of(rows, cols, w),
            &border,
            wedge,
            reach,
            surface,
            self.region,
        );
        // The heights drawn, per cell of the region: its elevation, or its hole's cover
        // (NaN: not drawn); then the same pooled by their maximum over 2 × 2 and 4 × 4
        // cells, drawn farther away where a cell is much smaller than a sample (the mesh
        // stays nowhere below the cells' tops).
        let [_, _, sw, sh] = self.region;
        let fine = self.heights(surface.raster(), n);
        let (half, hw2, hh2) = pool(&fine, sw, sh);
        let (quarter, hw4, hh4) = pool(&half, hw2, hh2);
        let lod = |m: f64| m * res;
        let levels = [
            Level {
                h: &fine,
                w: sw,
                hh: sh,
                sc: 1,
                rmin: 0.0,
                rmax: lod(LOD_CELLS[0]) + 4.0 * res,
            },
            Level {
                h: &half,
                w: hw2,
                hh: hh2,
                sc: 2,
                rmin: lod(LOD_CELLS[0]) - 8.0 * res,
                rmax: lod(LOD_CELLS[1]) + 8.0 * res,
            },
            Level {
                h: &quarter,
                w: hw4,
                hh: hh4,
                sc: 4,
                rmin: lod(LOD_CELLS[1]) - 16.0 * res,
                rmax: f64::INFINITY,
            },
        ];
        let mut bufs = std::mem::take(&mut self.t);
        for level in &levels {
            view.draw_level(&mut bufs, level);
        }
        // The nearest over the bands.
        let (first, rest) = bufs.split_at_mut(1);
        for other in rest.iter() {
            for (a, &b) in first[0].iter_mut().zip(other) {
                *a = a.min(b);
            }
        }
        self.t = bufs;
    }

    /// Sets the region drawn: the window's cells within `reach` (and the `wedge`) of
    /// `origin`, with a margin. Returns whether it holds a square of cells.
    fn set_region(
        &mut self,
        surface: &GridSurface,
        wedge: Option<&Wedge>,
        origin: &Point3<f64>,
        reach: f64,
    ) -> bool {
        let (n, res, o) = (surface.size(), surface.resolution(), surface.origin());
        let [x0, x1, y0, y1] = wedge.map_or(
            [
                origin.x - reach,
                origin.x + reach,
                origin.y - reach,
                origin.y + reach,
            ],
            |w| w.bounds(reach + 16.0 * res),
        );
        let span = |lo: f64, hi: f64, o: i64| {
            let a = floor_i64(lo / res) - 1 - o;
            let b = ceil_i64(hi / res) + 1 - o;
            (a.clamp(0, n as i64) as usize, b.clamp(0, n as i64) as usize)
        };
        let (i0, i1) = span(x0, x1, o.x);
        let (j0, j1) = span(y0, y1, o.y);
        if i0 + 1 >= i1 || j0 + 1 >= j1 {
            return false;
        }
        self.region = [i0, j0, i1 - i0, j1 - j0];
        true
    }

    /// Per cell of the region, row-major: its elevation in the raster `z` (`n` cells
    /// wide), or for a hole its cover (NaN: not drawn).
    fn heights(&self, z: &[f32], n: usize) -> Vec<f32> {
        let [i0, j0, sw, sh] = self.region;
        let mut fine = Vec::with_capacity(sw * sh);
        for j in j0..j0 + sh {
            fine.extend((i0..i0 + sw).map(|i| {
                let v = z[j * n + i];
                if v.is_nan() {
                    self.cover(i, j)
                } else {
                    v
                }
            }));
        }
        fine
    }

    /// Each hole block's cover: per block of [`BLOCK`] × [`BLOCK`] cells of the region its
    /// highest rim cell (an observed cell beside an unobserved one), then the highest such
    /// block within [`REACH_M`] (a square of blocks); NaN where there is none.
    fn find_covers(&mut self, z: &[f32], n: usize, res: f64) {
        let [i0, j0, sw, sh] = self.region;
        let (bw, bh) = (sw.div_ceil(BLOCK), sh.div_ceil(BLOCK));
        self.rim.clear();
        self.rim.resize(bw * bh, f32::NEG_INFINITY);
        let at = |i: usize, j: usize| z[j * n + i];
        for j in j0..j0 + sh {
            for i in i0..i0 + sw {
                let v = at(i, j);
                if v.is_nan() {
                    continue;
                }
                let rim = (i > 0 && at(i - 1, j).is_nan())
                    || (i + 1 < n && at(i + 1, j).is_nan())
                    || (j > 0 && at(i, j - 1).is_nan())
                    || (j + 1 < n && at(i, j + 1).is_nan());
                if rim {
                    let b = ((j - j0) / BLOCK) * bw + (i - i0) / BLOCK;
                    self.rim[b] = self.rim[b].max(v);
                }
            }
        }
        // The highest within `k` blocks: along rows, then along columns.
        let k = (REACH_M / (BLOCK as f64 * res)).ceil() as usize;
        self.cover.clear();
        self.cover.resize(bw * bh, f32::NEG_INFINITY);
        for bj in 0..bh {
            let row = &self.rim[bj * bw..(bj + 1) * bw];
            for bi in 0..bw {
                self.cover[bj * bw + bi] = row[bi.saturating_sub(k)..(bi + k + 1).min(bw)]
                    .iter()
                    .fold(f32::NEG_INFINITY, |a, &b| a.max(b));
            }
        }
        std::mem::swap(&mut self.rim, &mut self.cover);
        for bj in 0..bh {
            for bi in 0..bw {
                let v = (bj.saturating_sub(k)..(bj + k + 1).min(bh))
                    .map(|r| self.rim[r * bw + bi])
                    .fold(f32::NEG_INFINITY, f32::max);
                self.cover[bj * bw + bi] = if v.is_finite() { v } else { f32::NAN };
            }
        }
        self.blocks_wide = bw;
    }

    /// The height a hole cell (i, j) of the window is drawn at (NaN: not drawn).
    #[inline]
    fn cover(&self, i: usize, j: usize) -> f32 {
        let [i0, j0, sw, sh] = self.region;
        if i < i0 || j < j0 || i >= i0 + sw || j >= j0 + sh {
            return f32::NAN;
        }
        self.cover[((j - j0) / BLOCK) * self.blocks_wide + (i - i0) / BLOCK]
    }

    /// How far along sample `k`'s ray it first meets the drawn map, if it does: the march
    /// meets nothing before.
    pub(crate) fn first(&self, k: usize) -> Option<f64> {
        let t = *self.t.first()?.get(k)?;
        t.is_finite().then_some(t as f64)
    }
}

/// The heights `h` (`w` × `hh`) pooled by their maximum over 2 × 2 cells, with the pooled
/// width and height.
fn pool(h: &[f32], w: usize, hh: usize) -> (Vec<f32>, usize, usize) {
    let (pw, ph) = (w.div_ceil(2), hh.div_ceil(2));
    let mut out = vec![f32::NAN; pw * ph];
    for j in 0..hh {
        for i in 0..w {
            // `max` passes over NaN (not drawn) on either side.
            let o = &mut out[(j / 2) * pw + i / 2];
            *o = o.max(h[j * w + i]);
        }
    }
    (out, pw, ph)
}

/// One level of detail of the region's heights.
struct Level<'a> {
    /// Heights, row-major (NaN: not drawn).
    h: &'a [f32],
    /// Width and height, in pooled cells.
    w: usize,
    hh: usize,
    /// Cells per side of a pooled cell.
    sc: usize,
    /// The nearest and farthest horizontal distance (metres) this level is drawn at.
    rmin: f64,
    rmax: f64,
}

impl Level<'_> {
    /// The heights of row `j` of this level into `v` (NaN: not drawn, or outside).
    fn cell_row(&self, v: &mut Vec<f32>, j: usize) {
        v.clear();
        if j < self.hh {
            v.extend_from_slice(&self.h[j * self.w..(j + 1) * self.w]);
        } else {
            v.resize(self.w, f32::NAN);
        }
    }
}

/// What drawing the region into the samples needs of the camera and the map: the
/// transform into the optical frame, the field of view, the samples.
struct View<'a> {
    camera: &'a CameraModel,
    map_rays: &'a [Option<Vector3<f64>>],
    samples: Samples<'a>,
    wedge: Option<Wedge>,
    origin: Point3<f64>,
    /// Map frame to optical frame, and its rotation and the map's z axis in it.
    to_cam: Pose,
    rot: Rotation3<f64>,
    ez: Vector3<f64>,
    /// Corners farther than this (plus two cells) are not drawn.
    reach: f64,
    /// The field of view's largest |x/z| in the optical frame, widened.
    lim_x: f64,
    /// The lens's largest radius (|(x, y)|/z) that still projects.
    r_max: f64,
    /// The surface's cell size and origin, and the region's first cell (window column, row).
    res: f64,
    o: CellKey,
    i0: usize,
    j0: usize,
}

impl<'a> View<'a> {
    #[allow(clippy::too_many_arguments)]
    fn new(
        camera: &'a CameraModel,
        cam_to_map: &Pose,
        map_rays: &'a [Option<Vector3<f64>>],
        samples: Samples<'a>,
        border: &[Vector3<f64>],
        wedge: Option<Wedge>,
        reach: f64,
        surface: &GridSurface,
        region: [usize; 4],
    ) -> Self {
        let to_cam = cam_to_map.inverse();
        // The horizontal field of view in the optical frame: the sampled border rays'
        // largest |x/z|, widened so that a triangle at the image's edge keeps its corners
        // outside it (a cell 0.5 m from the camera spans 0.2 of these units at 0.1 m).
        // Corners above or below the image are kept: a tree's crown stands above it, and
        // its side is drawn from there.
        let lim_x = border
            .iter()
            .map(|r| to_cam.rotation * r)
            .filter(|c| c.z > 1e-6)
            .fold(0.0f64, |m, c| m.max((c.x / c.z).abs()))
            * 1.2
            + 0.25;
        let rot = to_cam.rotation.to_rotation_matrix();
        let ez = rot * Vector3::z();
        View {
            camera,
            map_rays,
            samples,
            wedge,
            origin: Point3::from(cam_to_map.translation.vector),
            to_cam,
            rot,
            ez,
            reach,
            lim_x,
            r_max: camera.fold_radius(),
            res: surface.resolution(),
            o: surface.origin(),
            i0: region[0],
            j0: region[1],
        }
    }

    /// Draws `level` into the bands' buffers `bufs`: bands of cell rows, each into its own
    /// buffer (a band's last row of squares reaches into the next band's first row of
    /// corners).
    fn draw_level(&self, bufs: &mut [Vec<f32>], level: &Level<'_>) {
        let cres = level.sc as f64 * self.res;
        let ex = self.rot * Vector3::new(cres, 0.0, 0.0);
        let hw = level.w;
        let rows_per = level.hh.div_ceil(BANDS).max(1);
        bufs.par_iter_mut().enumerate().for_each(|(b, t)| {
            let ja = b * rows_per;
            let jb = (ja + rows_per).min(level.hh);
            if ja >= jb {
                return;
            }
            let mut prev: Vec<Vertex> = Vec::with_capacity(hw + 1);
            let mut cur: Vec<Vertex> = Vec::with_capacity(hw + 1);
            let (mut below, mut above) = (Vec::new(), Vec::new());
            level.cell_row(&mut below, ja.wrapping_sub(1));
            level.cell_row(&mut above, ja);
            self.corner_row(&mut prev, level, &ex, &below, &above, ja);
            for j in ja + 1..=jb {
                std::mem::swap(&mut below, &mut above);
                level.cell_row(&mut above, j);
                self.corner_row(&mut cur, level, &ex, &below, &above, j);
                for k in 0..hw {
                    self.fill_square(t, [prev[k], prev[k + 1], cur[k], cur[k + 1]], cres);
                }
                std::mem::swap(&mut prev, &mut cur);
            }
        });
    }

    /// Corner row `j` of `level` (between its cell rows j - 1, `below`, and j, `above`;
    /// `ex` a pooled cell's step along x in the optical frame), projected into `v`:
    /// sample-space coordinates (column index, row index when rows are uniform, else the
    /// pixel row), NaN where not drawn.
    fn corner_row(
        &self,
        v: &mut Vec<Vertex>,
        level: &Level<'_>,
        ex: &Vector3<f64>,
        below: &[f32],
        above: &[f32],
        j: usize,
    ) {
        let (o, res, origin, reach) = (self.o, self.res, self.origin, self.reach);
        let (rmin, rmax) = (level.rmin, level.rmax);
        let cres = level.sc as f64 * res;
        let samples = &self.samples;
        let (row_step, col_step) = (samples.row_step, samples.col_step as f64);
        v.clear();
        let y = (o.y + (self.j0 + level.sc * j) as i64) as f64 * res;
        let x0 = (o.x + self.i0 as i64) as f64 * res;
        let base = self.to_cam * Point3::new(x0, y, 0.0);
        let dy2 = (y - origin.y) * (y - origin.y);
        v.extend((0..=level.w).map(|k| {
            let x = x0 + k as f64 * cres;
            let dx = x - origin.x;
            let d2 = dx * dx + dy2;
            let off = ([f64::NAN; 2], Point3::new(x, y, f64::NAN));
            if d2 > (reach + 2.0 * cres) * (reach + 2.0 * cres)
                || d2 < rmin * rmin
                || d2 > rmax * rmax
                || self.wedge.as_ref().is_some_and(|w| !w.contains(x, y))
            {
                return off;
            }
            // The corner's height: the highest of the (up to four) cells that
            // share it, so that the mesh is nowhere below a cell's flat top.
            let mut zc = f32::NEG_INFINITY;
            for row in [below, above] {
                for h in [k.checked_sub(1).map(|c| row[c]), row.get(k).copied()] {
                    if let Some(h) = h.filter(|&h| h > zc) {
                        zc = h;
                    }
                }
            }
            let zv = zc as f64;
            if !zv.is_finite() {
                return off;
            }
            let p = Point3::new(x, y, zv);
            let pc = base + ex * k as f64 + self.ez * zv;
            if pc.z < 0.05
                || pc.x.abs() > self.lim_x * pc.z
                || (pc.x * pc.x + pc.y * pc.y).sqrt() > self.r_max * pc.z
            {
                return off;
            }
            let [u, vv] = self.camera.project(&pc).unwrap_or([f64::NAN; 2]);
            let su = (u - samples.cols0 as f64) / col_step;
            let sv = match row_step {
                Some(rs) => (vv - samples.rows[0] as f64) / rs as f64,
                None => vv,
            };
            ([su, sv], p)
        }));
    }

    /// Fills the square of projected corners `q` (row j: 0, 1; row j + 1: 2, 3) into the
    /// band's buffer `t` as two triangles, unless no sample lies in its box.
    #[inline]
    fn fill_square(&self, t: &mut [f32], q: [Vertex; 4], cres: f64) {
        // No sample in the square's box: nothing to fill (most squares far away are
        // smaller than the sample spacing). NaN fails every test.
        let (mut u0, mut u1, mut v0, mut v1) = (q[0].0[0], q[0].0[0], q[0].0[1], q[0].0[1]);
        for (s, _) in &q[1..] {
            u0 = u0.min(s[0]);
            u1 = u1.max(s[0]);
            v0 = v0.min(s[1]);
            v1 = v1.max(s[1]);
        }
        if q.iter().any(|v| v.0[0].is_nan())
            || ceil_i64(u0 - TOLERANCE) > floor_i64(u1 + TOLERANCE)
            || (self.samples.row_step.is_some()
                && ceil_i64(v0 - TOLERANCE) > floor_i64(v1 + TOLERANCE))
        {
            return;
        }
        for tri in [[0, 1, 3], [0, 3, 2]] {
            let v = tri.map(|i| q[i]);
            fill(t, v, &self.origin, self.map_rays, &self.samples, cres);
        }
    }
}

/// A projected cell corner: its sample-space position (NaN: not drawn) and its point.
type Vertex = ([f64; 2], Point3<f64>);

/// Fills the triangle `v` (pixel corners and map corners) into the samples whose pixel
/// centres it covers, keeping per sample the nearest distance along the sample's ray to the
/// triangle's plane.
#[inline]
fn fill(
    t: &mut [f32],
    v: [Vertex; 3],
    origin: &Point3<f64>,
    map_rays: &[Option<Vector3<f64>>],
    s: &Samples<'_>,
    res: f64,
) {
    let [(a, pa), (b, pb), (c, pc)] = v;
    let area = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
    if area.is_nan() || area == 0.0 {
        return;
    }
    let (u0, u1) = (a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]));
    let (v0, v1) = (a[1].min(b[1]).min(c[1]), a[1].max(b[1]).max(c[1]));
    // The samples within `TOLERANCE` of the triangle's box (see `edge`).
    let nc = s.nc as i64;
    let cc = ceil_i64(u0 - TOLERANCE).clamp(0, nc) as usize
        ..(floor_i64(u1 + TOLERANCE) + 1).clamp(0, nc) as usize;
    let pad = if s.row_step.is_some() { TOLERANCE } else { 0.0 };
    let rr = s.rows_within(v0 - pad, v1 + pad);
    if rr.is_empty() || cc.is_empty() {
        return;
    }
    let normal = (pb - pa).cross(&(pc - pa));
    let num = normal.dot(&(pa - origin));
    let sign = area.signum();
    // A sample within `TOLERANCE` of the triangle counts as covered.
    let edge = |p: [f64; 2], q: [f64; 2], x: f64, y: f64| {
        let (ex, ey) = (q[0] - p[0], q[1] - p[1]);
        (ex * (y - p[1]) - ey * (x - p[0])) * sign + TOLERANCE * (ex * ex + ey * ey).sqrt()
    };
    // Where the sample's ray meets the triangle lies between its corners' horizontal
    // distances from the camera (give or take a cell): a plane met nearly edge-on gives
    // a distance outside that, and the nearest is taken instead.
    let h = |p: &Point3<f64>| (p - origin).xy().norm();
    let (h0, h1) = (
        h(&pa).min(h(&pb)).min(h(&pc)) - res,
        h(&pa).max(h(&pb)).max(h(&pc)) + res,
    );
    for r in rr {
        let y = s.rows[r];
        let yf = match s.row_step {
            Some(_) => r as f64,
            None => y as f64,
        };
        for col in cc.clone() {
            let x = s.cols0 + col * s.col_step;
            let xf = col as f64;
            if edge(a, b, xf, yf) < 0.0 || edge(b, c, xf, yf) < 0.0 || edge(c, a, xf, yf) < 0.0 {
                continue;
            }
            let Some(d) = map_rays[y * s.width + x] else {
                continue;
            };
            let hd = d.xy().norm();
            let (lo, hi) = (h0.max(0.0) / hd, h1 / hd);
            let tt = num / normal.dot(&d);
            let tt = if tt >= lo && tt <= hi { tt } else { lo };
            let k = r * s.nc + col;
            let near = tt as f32;
            // Not cut at the label range: the march's last step may pass it.
            if tt > 0.0 && near < t[k] {
                t[k] = near;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::optical_pose;
    use crate::geom::{pose_xyz_rpy, Distortion};
    use crate::grid::CellKey;

    /// A 40 m window of 0.1 m cells around the origin, heights from `f`, NaN where `hole`.
    fn surface(f: impl Fn(f64, f64) -> f64, hole: impl Fn(f64, f64) -> bool) -> GridSurface {
        let (n, res) = (400usize, 0.1);
        let o = CellKey::new(-200, -200);
        let z = (0..n * n)
            .map(|k| {
                let (x, y) = (
                    (o.x + (k % n) as i64) as f64 * res + 0.05,
                    (o.y + (k / n) as i64) as f64 * res + 0.05,
                );
                if hole(x, y) {
                    f32::NAN
                } else {
                    f(x, y) as f32
                }
            })
            .collect();
        GridSurface::from_raster(n, res, o, z).unwrap()
    }

    fn camera() -> (CameraModel, Pose) {
        let cam = CameraModel::new(
            160,
            120,
            [120.0, 120.0, 79.5, 59.5],
            Distortion::PlumbBob([-0.1, 0.01, 0.0, 0.0, 0.0]),
            "cam",
        )
        .unwrap();
        (
            cam,
            optical_pose(&pose_xyz_rpy(0.3, -0.2, 1.6, 0.0, 8f64.to_radians(), 0.2)),
        )
    }

    /// Per sample (stride 2 both ways): the whole march, and the march resumed where the
    /// z-buffer says the ray first meets the drawn map (`None`: it meets nothing drawn).
    #[allow(clippy::type_complexity)]
    fn both(
        s: &GridSurface,
        rows: &[usize],
    ) -> Vec<(
        Option<(Point3<f64>, usize, Option<f64>)>,
        Option<Option<(Point3<f64>, usize, Option<f64>)>>,
    )> {
        let (cam, pose) = camera();
        let rays: Vec<_> = cam
            .pixel_rays()
            .into_iter()
            .map(|r| r.map(|r| pose.rotation * r))
            .collect();
        let cols: Vec<usize> = (0..cam.width).step_by(2).collect();
        let mut zb = ZBuffer::default();
        zb.draw(s, &cam, &pose, &rays, rows, &cols, 18.0);
        let o = Point3::from(pose.translation.vector);
        let mut out = Vec::new();
        for (r, &y) in rows.iter().enumerate() {
            for (c, &x) in cols.iter().enumerate() {
                let Some(d) = rays[y * cam.width + x] else {
                    continue;
                };
                let resumed = zb
                    .first(r * cols.len() + c)
                    .map(|t| s.cast_through_holes_after(&o, &d, 18.0, t));
                out.push((s.cast_through_holes(&o, &d, 18.0), resumed));
            }
        }
        out
    }

    /// The march resumed from the z-buffer gives the whole march's answer on every sample,
    /// and a sample whose ray meets nothing drawn meets no ground in the march either.
    /// Returns the samples resumed and those with nothing drawn.
    fn resumes_exactly(s: &GridSurface) -> (usize, usize) {
        let (mut resumed, mut none) = (0, 0);
        // Every other row, and rows as `sampled_rows` picks them with wide rows (uneven).
        let even: Vec<usize> = (0..120).step_by(2).collect();
        let uneven: Vec<usize> = (0..120)
            .filter(|y| y % 3 == 0 || (50..60).contains(y))
            .collect();
        for (whole, z) in both(s, &even).into_iter().chain(both(s, &uneven)) {
            match z {
                Some(r) => {
                    assert_eq!(r, whole);
                    resumed += 1;
                }
                None => {
                    assert!(whole.is_none_or(|(_, _, hole)| hole.is_some()), "{whole:?}");
                    none += 1;
                }
            }
        }
        (resumed, none)
    }

    #[test]
    fn the_march_resumed_from_the_z_buffer_is_the_whole_march_on_rolling_ground() {
        let s = surface(
            |x, y| 0.3 * (0.4 * x).sin() + 0.2 * (0.3 * y).cos(),
            |_, _| false,
        );
        let (resumed, _) = resumes_exactly(&s);
        assert!(resumed > 2000, "{resumed}");
    }

    #[test]
    fn the_march_resumed_from_the_z_buffer_is_the_whole_march_over_holes_and_posts() {
        // A pond 0.4 m below its banks, unobserved; gaps beyond it like a lidar's rings; a
        // row of 2 m posts one cell wide (thin occluders a mesh through the cell centres
        // would miss).
        let s = surface(
            |x, y| {
                if (3.0..3.1).contains(&x) && (y * 2.0).fract().abs() < 0.05 {
                    2.0
                } else if x > 6.0 {
                    -0.1
                } else {
                    0.0
                }
            },
            |x, y| ((5.0..9.0).contains(&x) && y.abs() < 3.0) || (x > 12.0 && (x % 2.0) < 0.3),
        );
        let (resumed, none) = resumes_exactly(&s);
        assert!(resumed > 1000 && none > 0, "{resumed} {none}");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
        /// A march resumed anywhere before what the whole march meets gives what it gives.
        #[test]
        fn a_resumed_march_gives_the_whole_march(
            seed in 0u64..1000,
            yaw in -0.6f64..0.6,
            down in 0.02f64..0.3,
            frac in 0.0f64..1.0,
        ) {
            let h = |x: f64, y: f64| {
                let v = ((x * 3.1 + seed as f64).sin() * (y * 2.3 - seed as f64).cos()).abs();
                v > 0.7
            };
            let s = surface(|x, y| 0.2 * (0.5 * x + seed as f64).sin() + 0.05 * y.cos(), h);
            let o = Point3::new(0.2, 0.1, 1.6);
            let d = Vector3::new(yaw.cos(), yaw.sin(), -down).normalize();
            let whole = s.cast_through_holes(&o, &d, 18.0);
            let end = whole.map_or(18.0, |(p, _, _)| (p - o).norm());
            let resumed = s.cast_through_holes_after(&o, &d, 18.0, frac * end);
            proptest::prop_assert_eq!(whole, resumed);
        }
    }
}
