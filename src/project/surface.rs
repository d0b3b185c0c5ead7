//! A cheap ray march over a snapshot of the grid's elevations, with water in the holes.
//!
//! [`GridSurface`] copies the window's mean elevations into a dense raster (NaN where a cell
//! holds no elevation). [`GridSurface::cast`] walks a pixel ray in steps of half a cell and
//! stops in the first cell whose elevation is at or above the ray: the surface is piecewise
//! constant per cell, so the hit is exact to the cell, which is all a vote needs. Occlusion
//! comes with the first hit, as with [`super::ElevationSurface`].
//!
//! Unobserved cells are where water usually is: lidar returns nothing from a pond beyond the
//! diagnostic interval, stereo rarely matches a sky reflection, and the near bank of a
//! depression that falls away faster than the ray is hidden from every sensor. A ray that
//! crosses such a hole, from an observed near rim to the first observed cell beyond it (the
//! far bank, which faces the sensor and is seen down to the waterline), stops where it drops
//! to the lower of the two rims' elevations inside the hole: water lies at or below both. If
//! it stays above that level it goes on and may hit the far bank. A ray that meets a hole
//! before any observed cell, or never leaves it, stops nowhere in it.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geom::floor_i64;
use crate::grid::{CellKey, RollingGrid};

/// Dense elevation snapshot of a [`RollingGrid`] window. See the module documentation.
#[derive(Debug, Clone)]
pub struct GridSurface {
    n: usize,
    resolution: f64,
    origin: CellKey,
    /// Elevations (map frame, metres) row-major from the window's lower-left key; NaN = none.
    z: Vec<f32>,
    /// Summary of each `BLOCK` × `BLOCK` block of cells, row-major, `nb` blocks per side.
    blocks: Vec<Block>,
    nb: usize,
    /// The same of each `SUPER` × `SUPER` cells (`SUPER / BLOCK` blocks a side), `ns` a
    /// side: a ray high above the ground crosses one in a step.
    supers: Vec<Block>,
    ns: usize,
}

/// Cells per side of a [`Block`].
const BLOCK: usize = 8;
/// Cells per side of a superblock (a whole number of blocks).
const SUPER: usize = 32;

/// What the march needs to know of a block of cells to cross it in one step: a ray above
/// its highest cell hits nothing in a block without holes, and a ray in a hole (or before
/// any observed cell) changes nothing while it crosses a block of holes.
#[derive(Debug, Clone, Copy)]
struct Block {
    /// Highest observed elevation (−∞ if none).
    top: f32,
    /// Some cell is unobserved.
    holes: bool,
    /// Every cell is unobserved.
    void: bool,
}

impl Block {
    /// Whether a ray at height `z` is above every observed cell of the block by more than
    /// the rounding of numbers of magnitude `scale`.
    fn clears(&self, z: f64, scale: f64) -> bool {
        let top = self.top as f64;
        self.void || z > top + 1e-9 * (scale + top.abs())
    }
}

impl GridSurface {
    /// The elevation snapshot of `grid`'s window, every observed cell included.
    pub fn from_grid(grid: &RollingGrid) -> Self {
        Self::from_grid_gated(grid, f64::INFINITY)
    }

    /// As [`Self::from_grid`], but a cell whose elevation σ bound
    /// ([`crate::grid::CellStats::range_bound_std_m`]) exceeds `max_std_m` counts as
    /// unobserved: a cell seen only by a few far stereo points (σ grows with range²) holds
    /// an elevation that may belong to a cell metres nearer, and would stop rays short.
    pub fn from_grid_gated(grid: &RollingGrid, max_std_m: f64) -> Self {
        Self::from_grid_gated_in(grid, max_std_m, Vec::new())
    }

    /// [`Self::from_grid_gated`] built in the storage of `z` (the raster of a surface no
    /// longer needed, [`Self::into_raster`]): a frame's surface without a fresh allocation.
    /// Rows in parallel.
    pub(crate) fn from_grid_gated_in(grid: &RollingGrid, max_std_m: f64, mut z: Vec<f32>) -> Self {
        let n = grid.size();
        let z_ref = grid.config().z_ref;
        z.clear();
        z.resize(n * n, f32::NAN);
        z.par_chunks_mut(n.max(1))
            .enumerate()
            .for_each(|(dy, row)| {
                for (dx, i) in grid.observed_in_row(dy) {
                    let c = grid.layers.elevation_stats(i);
                    let Some(m) = c.mean_mm() else { continue };
                    if c.range_bound_std_m().is_some_and(|sd| sd <= max_std_m) {
                        row[dx] = (z_ref + m * 1e-3) as f32;
                    }
                }
            });
        Self::with_blocks(n, grid.resolution(), grid.origin(), z)
    }

    /// The elevations, row-major from the window's lower-left key (NaN: none).
    pub(crate) fn raster(&self) -> &[f32] {
        &self.z
    }

    /// The raster's storage, for [`Self::from_grid_gated_in`].
    pub(crate) fn into_raster(self) -> Vec<f32> {
        self.z
    }

    fn with_blocks(n: usize, resolution: f64, origin: CellKey, z: Vec<f32>) -> Self {
        let nb = n.div_ceil(BLOCK);
        let empty = Block {
            top: f32::NEG_INFINITY,
            holes: false,
            void: true,
        };
        let mut blocks = vec![empty; nb * nb];
        // A row of blocks from `BLOCK` rows of cells, block rows in parallel.
        blocks
            .par_chunks_mut(nb.max(1))
            .zip(z.par_chunks((n * BLOCK).max(1)))
            .for_each(|(brow, rows)| {
                for row in rows.chunks(n) {
                    for (b, cells) in brow.iter_mut().zip(row.chunks(BLOCK)) {
                        for &v in cells {
                            if v.is_nan() {
                                b.holes = true;
                            } else {
                                b.void = false;
                                b.top = b.top.max(v);
                            }
                        }
                    }
                }
            });
        let ns = n.div_ceil(SUPER);
        let k = SUPER / BLOCK;
        let supers = (0..ns * ns)
            .map(|q| {
                let (si, sj) = (q % ns, q / ns);
                let mut sb = empty;
                for bj in sj * k..((sj + 1) * k).min(nb) {
                    for b in &blocks[bj * nb + si * k..bj * nb + ((si + 1) * k).min(nb)] {
                        sb.top = sb.top.max(b.top);
                        sb.holes |= b.holes;
                        sb.void &= b.void;
                    }
                }
                sb
            })
            .collect();
        GridSurface {
            n,
            resolution,
            origin,
            z,
            blocks,
            nb,
            supers,
            ns,
        }
    }

    /// A surface from a raster of elevations (row-major from `origin`; NaN = unobserved).
    pub fn from_raster(n: usize, resolution: f64, origin: CellKey, z: Vec<f32>) -> Result<Self> {
        if z.len() != n * n || !(resolution.is_finite() && resolution > 0.0) {
            return Err(Error::invalid(
                "grid surface",
                format!(
                    "{} elevations for {n} × {n} cells at {resolution} m",
                    z.len()
                ),
            ));
        }
        Ok(Self::with_blocks(n, resolution, origin, z))
    }

    /// Cells per side of the window.
    pub fn size(&self) -> usize {
        self.n
    }

    /// Key of the window's lower-left cell.
    pub fn origin(&self) -> CellKey {
        self.origin
    }

    /// Cell edge length, metres.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// Raster index of the cell under `(x, y)`, if inside the window.
    #[inline]
    pub(crate) fn index_of(&self, x: f64, y: f64) -> Option<usize> {
        self.cell_of(x, y).map(|(i, j)| j * self.n + i)
    }

    /// Column and row of the cell under `(x, y)`, if inside the window.
    #[inline]
    fn cell_of(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        // Checked: a point far beyond the window saturates the floor near i64::MAX.
        let i = floor_i64(x / self.resolution).checked_sub(self.origin.x)?;
        let j = floor_i64(y / self.resolution).checked_sub(self.origin.y)?;
        let n = self.n as i64;
        (i >= 0 && j >= 0 && i < n && j < n).then_some((i as usize, j as usize))
    }

    /// Elevation of the cell under `(x, y)` (NaN: unobserved or outside).
    pub fn elevation(&self, x: f64, y: f64) -> f32 {
        self.index_of(x, y).map_or(f32::NAN, |i| self.z[i])
    }

    /// The first hit of the unit ray `dir` from `origin` within `max_range` (horizontal
    /// travel is also limited to the window): the hit point and its raster index.
    pub fn cast(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        max_range: f64,
    ) -> Option<(Point3<f64>, usize)> {
        self.cast_through_holes(origin, dir, max_range)
            .map(|(p, i, _)| (p, i))
    }

    /// [`GridSurface::cast`], also saying whether the hit is where the ray crosses a
    /// hole's rim level (`Some`: no observed surface was met there; the hit is where water
    /// in the hole would be) rather than observed terrain, and then the distance along the
    /// ray of the last sample still in the hole: water in the hole lies at or below the
    /// hit's level, so anywhere from the hit to there. That distance is exactly
    /// `max_range` when the hole has no far rim within range or the window.
    pub fn cast_through_holes(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        max_range: f64,
    ) -> Option<(Point3<f64>, usize, Option<f64>)> {
        self.cast_through_holes_after(origin, dir, max_range, 0.0)
    }

    /// [`Self::cast_through_holes`] for a ray known to meet nothing before `t_after` along
    /// it (the label stage's z-buffer says so): the march starts from a little before
    /// `t_after`, with the rim level it would have carried there (the last observed cell
    /// it passed, found by walking back), and gives what the whole march gives.
    pub(crate) fn cast_through_holes_after(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        max_range: f64,
        t_after: f64,
    ) -> Option<(Point3<f64>, usize, Option<f64>)> {
        let horiz = dir.xy().norm();
        if horiz.is_nan() || horiz <= 1e-9 || !origin.coords.iter().all(|v| v.is_finite()) {
            return None;
        }
        // Steps of half a cell horizontally.
        let dt = 0.5 * self.resolution / horiz;
        let steps = (max_range / dt).ceil() as usize;
        let mut level = f64::NAN;
        // Where the ray entered the current hole (after an observed rim), if it is in one.
        let mut entry: Option<f64> = None;
        let mut was_inside = false;
        let mut s = 0;
        // Resume at sample `s0`, two cells before `t_after` (what the caller found the ray
        // meeting may be a smoother surface than the march's flat cells, which a ray can
        // meet up to a cell sooner): the state the march carries there is the last
        // observed sample's level, and a hole entered after it if it is not `s0`.
        let s0 = (floor_i64(t_after / dt) - 4).clamp(0, steps as i64) as usize;
        if s0 > 0 {
            let mut k = s0;
            while k > 0 {
                let p = sample(origin, dir, dt, k);
                match self.index_of(p.x, p.y) {
                    Some(c) if !self.z[c].is_nan() => {
                        level = self.z[c] as f64;
                        entry = (k < s0).then_some(k as f64 * dt);
                        break;
                    }
                    Some(_) => was_inside = true,
                    None if was_inside => break,
                    None => {}
                }
                k -= 1;
            }
            let p = sample(origin, dir, dt, s0);
            was_inside |= self.index_of(p.x, p.y).is_some();
            s = s0;
        }
        // The block the ray was last found to dip below the top of: no skipping there.
        let mut low = usize::MAX;
        let mut low_super = usize::MAX;
        // Magnitude of the heights and times compared, for the rounding margin.
        let scale = 1.0 + origin.z.abs() + dir.z.abs() * (steps as f64 * dt);
        while s < steps {
            s += 1;
            let t = s as f64 * dt;
            let p = sample(origin, dir, dt, s);
            let Some((ci, cj)) = self.cell_of(p.x, p.y) else {
                if was_inside {
                    break;
                }
                continue;
            };
            was_inside = true;
            let i = cj * self.n + ci;
            // Take the block's remaining samples at once when the ray stays above its top
            // (its height is monotonic: above at both ends is above throughout) by more than
            // rounding: then no sample hits, nor crosses a rim level (at most the top) out of
            // a hole, and what they leave is the last observed sample's level and, if holes
            // follow it, a hole entered after it.
            // The same for a whole superblock first: a ray high above the ground crosses it
            // in one step, and only a superblock with holes is searched back for its last
            // observed sample (`last_observed`).
            let q = cj / SUPER * self.ns + ci / SUPER;
            let sup = self.supers[q];
            if q != low_super && sup.clears(p.z, scale) {
                let (last, j) = self.block_end(origin, dir, dt, (s, i), steps, SUPER);
                if !sup.clears(sample(origin, dir, dt, last).z, scale) {
                    low_super = q;
                } else {
                    let seen = self.last_observed(origin, dir, dt, (s, i), (last, j), &sup);
                    self.after_skip(seen, last, dt, t, &mut level, &mut entry);
                    s = last;
                    continue;
                }
            }
            let b = cj / BLOCK * self.nb + ci / BLOCK;
            let block = self.blocks[b];
            if b != low && block.clears(p.z, scale) {
                let (last, j) = self.block_end(origin, dir, dt, (s, i), steps, BLOCK);
                if !block.clears(sample(origin, dir, dt, last).z, scale) {
                    low = b;
                } else {
                    let seen = self.last_observed(origin, dir, dt, (s, i), (last, j), &block);
                    self.after_skip(seen, last, dt, t, &mut level, &mut entry);
                    s = last;
                    continue;
                }
            }
            let z = self.z[i] as f64;
            if z.is_nan() {
                if level.is_finite() && entry.is_none() {
                    entry = Some(t - dt);
                }
                continue;
            }
            if let Some(t0) = entry.take() {
                // Out of a hole: water would lie at or below both rims.
                let l = level.min(z);
                let tl = (l - origin.z) / dir.z;
                if dir.z < 0.0 && tl >= t0 && tl <= t {
                    let q = origin + dir * tl;
                    let end = (t - dt).max(tl);
                    return Some((q, self.index_of(q.x, q.y).unwrap_or(i), Some(end)));
                }
            }
            if p.z <= z {
                return Some((p, i, None));
            }
            level = z;
        }
        // Still in a hole entered from an observed rim, with no far rim in reach (a far
        // shore beyond range or the window): the near rim's level is the best there is.
        match entry {
            Some(t0) if dir.z < 0.0 => {
                let tl = (level - origin.z) / dir.z;
                let q = origin + dir * tl;
                let i = self.index_of(q.x, q.y)?;
                (tl >= t0 && tl <= max_range && self.z[i].is_nan()).then_some((
                    q,
                    i,
                    Some(max_range),
                ))
            }
            _ => None,
        }
    }

    /// The last sample (≤ `steps`) of the march in the `size` × `size` block of sample
    /// `first` = (step, cell), and its cell. A sample's cell is monotonic in the step along
    /// both axes, so a block's samples are consecutive: the step where the ray leaves the
    /// block, checked by sampling either side.
    fn block_end(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        dt: f64,
        first: (usize, usize),
        steps: usize,
        size: usize,
    ) -> (usize, usize) {
        let (s, i) = first;
        let (bi, bj) = (i % self.n / size, i / self.n / size);
        let exit = |o: f64, d: f64, b: usize, key: i64| {
            let side = if d > 0.0 { b + 1 } else { b };
            let edge = (key + (side * size) as i64) as f64 * self.resolution;
            if d == 0.0 {
                f64::INFINITY
            } else {
                (edge - o) / d
            }
        };
        let t =
            exit(origin.x, dir.x, bi, self.origin.x).min(exit(origin.y, dir.y, bj, self.origin.y));
        let in_block = |k: usize| {
            let p = sample(origin, dir, dt, k);
            self.cell_of(p.x, p.y)
                .filter(|&(ci, cj)| ci / size == bi && cj / size == bj)
                .map(|(ci, cj)| cj * self.n + ci)
        };
        // `floor() as usize` (negative and NaN to 0), without libm's floor.
        let mut k = (floor_i64(t / dt).max(0) as usize).clamp(s, steps);
        let mut cell = in_block(k);
        while cell.is_none() && k > s {
            k -= 1;
            cell = in_block(k);
        }
        while let Some(next) = (k < steps).then(|| in_block(k + 1)).flatten() {
            k += 1;
            cell = Some(next);
        }
        (k, cell.unwrap_or(i))
    }

    /// The march's rim level and hole entry after a skip from the sample at time `t` to
    /// sample `last`, given the last of those samples on an observed cell (`seen`, from
    /// [`Self::last_observed`]): that cell's level, and a hole entered after it if it is not
    /// the last; with none, a hole entered at `t` if the march has a level and is not in
    /// one already.
    #[inline]
    fn after_skip(
        &self,
        seen: Option<(usize, usize)>,
        last: usize,
        dt: f64,
        t: f64,
        level: &mut f64,
        entry: &mut Option<f64>,
    ) {
        match seen {
            Some((k, c)) => {
                *level = self.z[c] as f64;
                *entry = (k < last).then(|| (k + 1) as f64 * dt - dt);
            }
            None if level.is_finite() && entry.is_none() => *entry = Some(t - dt),
            None => {}
        }
    }

    /// The last sample from `first` to `last` (step, cell; both in `block`) that falls
    /// on an observed cell, and that cell.
    fn last_observed(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        dt: f64,
        first: (usize, usize),
        last: (usize, usize),
        block: &Block,
    ) -> Option<(usize, usize)> {
        if block.void {
            return None;
        }
        if !block.holes || !self.z[last.1].is_nan() {
            return Some(last);
        }
        (first.0 + 1..last.0)
            .rev()
            .filter_map(|k| {
                let p = sample(origin, dir, dt, k);
                self.index_of(p.x, p.y).map(|c| (k, c))
            })
            .chain(std::iter::once(first))
            .find(|&(_, c)| !self.z[c].is_nan())
    }
}

/// Sample `k` of a march in steps of `dt` (computed the same way wherever it is taken).
#[inline]
fn sample(origin: &Point3<f64>, dir: &Vector3<f64>, dt: f64, k: usize) -> Point3<f64> {
    origin + dir * (k as f64 * dt)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::project::ElevationSurface;
    use proptest::prelude::*;

    fn grid_of(f: impl Fn(f64, f64) -> Option<f64>) -> (RollingGrid, GridSurface) {
        use crate::geom::PointCloud;
        use crate::grid::{GridConfig, RangeNoise};
        let cfg = GridConfig {
            size_cells: 200,
            resolution: 0.1,
            ..GridConfig::default()
        };
        let mut g = RollingGrid::new(cfg, 0.0, 0.0).unwrap();
        let mut pts = Vec::new();
        for j in 0..200 {
            for i in 0..200 {
                let (x, y) = (
                    -10.0 + (i as f64 + 0.5) * 0.1,
                    -10.0 + (j as f64 + 0.5) * 0.1,
                );
                if let Some(z) = f(x, y) {
                    pts.push([x as f32, y as f32, z as f32]);
                }
            }
        }
        g.ingest(&PointCloud::unorganized(pts), &RangeNoise::constant(0.02))
            .unwrap();
        let s = GridSurface::from_grid(&g);
        (g, s)
    }

    #[test]
    fn flat_ground_hit_is_the_plane_hit() {
        let (_, s) = grid_of(|_, _| Some(0.0));
        let o = Point3::new(0.0, 0.0, 1.5);
        let d = Vector3::new(1.0, 0.3, -0.2).normalize();
        let (p, _) = s.cast(&o, &d, 50.0).unwrap();
        // The plane z = 0 is hit at t = 1.5 / 0.2 (times the norm); the march is within a step.
        let t = 1.5 / -d.z;
        assert!((p - (o + d * t)).xy().norm() <= 0.05 + 1e-9, "{p}");
        // Upward or vertical rays hit nothing.
        assert!(s
            .cast(&o, &Vector3::new(1.0, 0.0, 0.1).normalize(), 50.0)
            .is_none());
        assert!(s.cast(&o, &Vector3::new(0.0, 0.0, -1.0), 50.0).is_none());
    }

    #[test]
    fn a_ridge_occludes_what_is_behind_it() {
        let (_, s) = grid_of(|x, _| Some(if (3.0..3.3).contains(&x) { 1.0 } else { 0.0 }));
        let o = Point3::new(0.0, 0.0, 1.2);
        // Aimed at x = 6 on the ground: the ridge at x = 3 (1 m high) is hit first.
        let d = Vector3::new(6.0, 0.0, -1.2).normalize();
        let (p, _) = s.cast(&o, &d, 50.0).unwrap();
        assert!((3.0..3.35).contains(&p.x), "{p}");
    }

    #[test]
    fn a_hole_takes_the_level_of_its_near_rim() {
        // Ground at 0, an unobserved pond for 4 ≤ x < 8; the far shore beyond.
        let (_, s) = grid_of(|x, _| (!(4.0..8.0).contains(&x)).then_some(0.0));
        let o = Point3::new(0.0, 0.0, 1.5);
        // Aimed at x = 6: it crosses the hole and drops to the rims' level (0) at x = 6.
        let d = Vector3::new(6.0, 0.0, -1.5).normalize();
        let (p, i) = s.cast(&o, &d, 50.0).unwrap();
        assert!((p.x - 6.0).abs() < 1e-6 && p.z.abs() < 1e-9, "{p}");
        assert_eq!(Some(i), s.index_of(p.x, p.y));
        // That hit is a hole crossing; one on the ground before the hole is not.
        assert!(s.cast_through_holes(&o, &d, 50.0).unwrap().2.is_some());
        let d2 = Vector3::new(3.0, 0.0, -1.5).normalize();
        assert!(s.cast_through_holes(&o, &d2, 50.0).unwrap().2.is_none());
        // The hole goes on to the far rim at x = 8: its last sample is within a step of it.
        let end = s.cast_through_holes(&o, &d, 50.0).unwrap().2.unwrap();
        let e = o + d * end;
        assert!((7.9..8.0).contains(&e.x), "{e}");
        assert_eq!(s.cast_through_holes(&o, &d2, 50.0).unwrap().2, None);
        // A far rim lower than the near one sets the level: far bank at −0.3 m, aimed at
        // (7, −0.3): the hit is there, not where the ray passes z = 0 (x = 6).
        let (_, s3) =
            grid_of(|x, _| (!(4.0..8.0).contains(&x)).then_some(if x >= 8.0 { -0.3 } else { 0.0 }));
        let d3 = Vector3::new(7.0, 0.0, -1.8).normalize();
        let (p3, _) = s3.cast(&o, &d3, 50.0).unwrap();
        assert!(
            (p3.x - 7.0).abs() < 1e-6 && (p3.z + 0.3).abs() < 1e-6,
            "{p3}"
        );
        // No far rim (the hole runs to the window's edge): the near rim's level.
        let (_, s4) = grid_of(|x, _| (x < 4.0).then_some(0.0));
        let (p4, _) = s4.cast(&o, &d, 50.0).unwrap();
        assert!((p4.x - 6.0).abs() < 1e-6 && p4.z.abs() < 1e-9, "{p4}");
        // ... and the water may lie anywhere down the ray within range.
        assert_eq!(s4.cast_through_holes(&o, &d, 50.0).unwrap().2, Some(50.0));
        // A ray that starts above a hole with no rim behind it passes on.
        let (_, s2) = grid_of(|x, _| (x >= 8.0).then_some(0.0));
        let (p2, _) = s2.cast(&o, &d, 50.0).unwrap();
        assert!(p2.x >= 8.0, "{p2}");
    }

    #[test]
    fn gated_surface_drops_uncertain_cells() {
        use crate::geom::PointCloud;
        use crate::grid::{GridConfig, RangeNoise};
        let cfg = GridConfig {
            size_cells: 100,
            resolution: 0.1,
            ..GridConfig::default()
        };
        let mut g = RollingGrid::new(cfg, 0.0, 0.0).unwrap();
        // One precise point at (1, 1), one noisy point at (2, 2).
        let precise = PointCloud::unorganized(vec![[1.05, 1.05, 0.0]]);
        let noisy = PointCloud::unorganized(vec![[2.05, 2.05, 0.3]]);
        g.ingest(&precise, &RangeNoise::constant(0.02)).unwrap();
        g.ingest(&noisy, &RangeNoise::constant(0.5)).unwrap();
        let all = GridSurface::from_grid(&g);
        assert!(all.elevation(1.05, 1.05).is_finite() && all.elevation(2.05, 2.05).is_finite());
        let gated = GridSurface::from_grid_gated(&g, 0.1);
        assert!(gated.elevation(1.05, 1.05).abs() < 1e-3);
        assert!(gated.elevation(2.05, 2.05).is_nan());
    }

    #[test]
    fn surface_in_used_storage_is_the_cells_elevations() {
        use crate::grid::{centre_of, DiscardSink};
        let (mut g, _) = grid_of(|x, y| ((x * 7.0 + y * 3.0).sin() > -0.3).then_some(0.1 * x));
        // The window moves, so its rows wrap around the buffer.
        g.recenter(3.37, -2.71, &mut DiscardSink).unwrap();
        let fresh = GridSurface::from_grid_gated(&g, f64::INFINITY);
        // Storage of another size holding other values changes nothing.
        let used = GridSurface::from_grid_gated_in(&g, f64::INFINITY, vec![7.0; 12345]);
        assert_eq!(format!("{fresh:?}"), format!("{used:?}"));
        let (n, o) = (g.size() as i64, g.origin());
        let (mut seen, mut holes) = (0, 0);
        for dy in 0..n {
            for dx in 0..n {
                let k = CellKey::new(o.x + dx, o.y + dy);
                let (x, y) = centre_of(g.resolution(), k);
                let z = fresh.elevation(x, y);
                match g.elevation_at(x, y) {
                    Some(e) => {
                        assert_eq!(z, e as f32, "{k:?}");
                        seen += 1;
                    }
                    None => {
                        assert!(z.is_nan(), "{k:?}");
                        holes += 1;
                    }
                }
            }
        }
        assert!(seen > 10_000 && holes > 1_000, "{seen} {holes}");
    }

    /// The ray march as first written, one sample at a time: the reference the block
    /// skipping of [`GridSurface::cast_through_holes`] must match bit for bit.
    fn reference_cast(
        s: &GridSurface,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        max_range: f64,
    ) -> Option<(Point3<f64>, usize, bool)> {
        let horiz = dir.xy().norm();
        if horiz.is_nan() || horiz <= 1e-9 || !origin.coords.iter().all(|v| v.is_finite()) {
            return None;
        }
        let dt = 0.5 * s.resolution / horiz;
        let steps = (max_range / dt).ceil() as usize;
        let mut level = f64::NAN;
        let mut entry: Option<f64> = None;
        let mut was_inside = false;
        for k in 1..=steps {
            let t = k as f64 * dt;
            let p = origin + dir * t;
            let Some(i) = s.index_of(p.x, p.y) else {
                if was_inside {
                    break;
                }
                continue;
            };
            was_inside = true;
            let z = s.z[i] as f64;
            if z.is_nan() {
                if level.is_finite() && entry.is_none() {
                    entry = Some(t - dt);
                }
                continue;
            }
            if let Some(t0) = entry.take() {
                let l = level.min(z);
                let tl = (l - origin.z) / dir.z;
                if dir.z < 0.0 && tl >= t0 && tl <= t {
                    let q = origin + dir * tl;
                    return Some((q, s.index_of(q.x, q.y).unwrap_or(i), true));
                }
            }
            if p.z <= z {
                return Some((p, i, false));
            }
            level = z;
        }
        match entry {
            Some(t0) if dir.z < 0.0 => {
                let tl = (level - origin.z) / dir.z;
                let q = origin + dir * tl;
                let i = s.index_of(q.x, q.y)?;
                (tl >= t0 && tl <= max_range && s.z[i].is_nan()).then_some((q, i, true))
            }
            _ => None,
        }
    }

    /// The random terrain and rays of one proptest case from its seed (splitmix64).
    use crate::cues::testutil::TestRng as Rng;

    /// Bits of a cast's result, so that equal means identical (also for −0 and NaN).
    fn bits(r: Option<(Point3<f64>, usize, bool)>) -> Option<([u64; 3], usize, bool)> {
        r.map(|(p, i, h)| ([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()], i, h))
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]
        /// The cast gives exactly the reference march's hit, index and hole flag, on random
        /// rasters (plateaus, slopes, bumps, spikes, rectangular and scattered holes) and
        /// rays (above and below the terrain, grazing and steep, axis-aligned, from outside
        /// the window and out of it).
        #[test]
        fn cast_matches_reference_march(
            n in prop_oneof![1usize..90, 90usize..220],
            res in prop_oneof![Just(0.1), Just(0.25), 0.02f64..0.6],
            ox in -300i64..300,
            oy in -300i64..300,
            seed in any::<u64>(),
            holes in prop::collection::vec((0.0f64..1.0, 0.0f64..1.0, 0.0f64..0.6, 0.0f64..0.6), 0..5),
            scatter in prop_oneof![Just(0.0), 0.0f64..0.05, 0.0f64..0.5],
            bump in prop_oneof![Just(0.0), 0.0f64..0.3, 0.0f64..3.0],
            tilt in (-0.2f64..0.2, -0.2f64..0.2),
            spikes in prop_oneof![Just(0.0), 0.0f64..0.02],
        ) {
            let mut rng = Rng(seed);
            let (base, quantum) = (rng.range(-2.0, 2.0), rng.range(0.0, 0.3));
            let mut z = vec![0f32; n * n];
            for (k, v) in z.iter_mut().enumerate() {
                let (i, j) = ((k % n) as f64, (k / n) as f64);
                let mut e = base + (tilt.0 * i + tilt.1 * j) * res
                    + bump * (0.3 * i).sin() * (0.17 * j + 1.0).cos();
                if quantum > 0.15 {
                    // Terraces: many cells of equal elevation, ties with the ray.
                    e = (e / quantum).round() * quantum;
                }
                if rng.chance(spikes) {
                    e += rng.range(0.0, 5.0);
                }
                let hole = rng.chance(scatter)
                    || holes.iter().any(|&(hx, hy, hw, hh)| {
                        (hx..hx + hw).contains(&(i / n as f64)) && (hy..hy + hh).contains(&(j / n as f64))
                    });
                *v = if hole { f32::NAN } else { e as f32 };
            }
            let s = GridSurface::from_raster(n, res, CellKey::new(ox, oy), z).unwrap();
            let w = n as f64 * res;
            let (x0, y0) = (ox as f64 * res, oy as f64 * res);
            for _ in 0..64 {
                let o = Point3::new(
                    x0 + rng.range(-0.2, 1.2) * w,
                    y0 + rng.range(-0.2, 1.2) * w,
                    base + rng.range(-1.0, 4.0),
                );
                let az = match rng.next_u64() % 8 {
                    0 => 0.0,
                    1 => std::f64::consts::FRAC_PI_2,
                    2 => std::f64::consts::PI,
                    3 => -std::f64::consts::FRAC_PI_2,
                    _ => rng.range(-3.2, 3.2),
                };
                let dip = match rng.next_u64() % 6 {
                    0 => 0.0,
                    1 => rng.range(-0.02, 0.02),
                    2 => rng.range(-1.5, 1.5),
                    _ => rng.range(-0.4, 0.1),
                };
                let d = Vector3::new(az.cos(), az.sin(), dip.tan()).normalize();
                let range = match rng.next_u64() % 4 {
                    0 => rng.range(0.0, 1.0),
                    _ => rng.range(0.0, 1.5 * w + 1.0),
                };
                prop_assert_eq!(
                    bits(
                        s.cast_through_holes(&o, &d, range)
                            .map(|(p, i, end)| (p, i, end.is_some()))
                    ),
                    bits(reference_cast(&s, &o, &d, range)),
                    "ray from {} along {} for {} m", o, d, range
                );
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        /// The same on rasters made of whole superblocks, each void, a rough plateau without
        /// holes, or one with scattered holes, and rays that run low over them: the
        /// skips of whole superblocks leave the march in the state (level, hole entered) the
        /// reference reaches sample by sample.
        #[test]
        fn superblock_skips_match_reference_march(
            seed in any::<u64>(),
            kinds in prop::collection::vec((0u8..3, -0.5f64..0.5), 16),
            res in prop_oneof![Just(0.1), 0.05f64..0.3],
        ) {
            let n = 4 * SUPER;
            let mut rng = Rng(seed);
            let mut z = vec![0f32; n * n];
            for (k, v) in z.iter_mut().enumerate() {
                let (i, j) = (k % n, k / n);
                let (kind, e) = kinds[(j / SUPER) * 4 + i / SUPER];
                let hole = kind == 0 || (kind == 2 && rng.chance(0.2));
                *v = if hole { f32::NAN } else { (e + rng.range(0.0, 0.05)) as f32 };
            }
            let s = GridSurface::from_raster(n, res, CellKey::new(-7, 11), z).unwrap();
            let w = n as f64 * res;
            let (x0, y0) = (-7.0 * res, 11.0 * res);
            for _ in 0..64 {
                let o = Point3::new(
                    x0 + rng.range(-0.1, 1.1) * w,
                    y0 + rng.range(-0.1, 1.1) * w,
                    rng.range(0.0, 1.5),
                );
                let az = rng.range(-3.2, 3.2);
                let d = Vector3::new(az.cos(), az.sin(), -rng.range(0.0, 0.1)).normalize();
                let range = 1.5 * w;
                prop_assert_eq!(
                    bits(
                        s.cast_through_holes(&o, &d, range)
                            .map(|(p, i, end)| (p, i, end.is_some()))
                    ),
                    bits(reference_cast(&s, &o, &d, range)),
                    "ray from {} along {}", o, d
                );
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// On a fully observed smooth surface the march and parry's height field agree to the
        /// cell (the march is piecewise constant, parry's surface piecewise linear).
        #[test]
        fn march_agrees_with_parry_heightfield(
            az in -1.2f64..1.2, dep in 0.08f64..0.6, a in -0.2f64..0.2, b in -0.2f64..0.2,
        ) {
            let (g, s) = grid_of(|x, y| Some(0.3 * (a * x).sin() + 0.2 * (b * y).cos()));
            let hf = ElevationSurface::from_grid(&g).unwrap();
            let o = Point3::new(0.0, 0.0, 1.6);
            let d = Vector3::new(az.cos(), az.sin(), -dep).normalize();
            let mine = s.cast(&o, &d, 9.0);
            let theirs = hf.cast(&o, &d, 9.0).map(|t| o + d * t);
            if let (Some((p, _)), Some(q)) = (mine, theirs) {
                // Within two cells horizontally (one for the march step, one for the
                // piecewise-constant against piecewise-linear surface).
                prop_assert!((p - q).xy().norm() < 0.2 + 0.1 / dep, "{p} {q}");
            } else {
                // Both miss only at the window's edge (9 m of range from the centre).
                prop_assert!(mine.is_none() && theirs.is_none() || (o + d * 9.0).coords.xy().norm() > 8.0);
            }
        }
    }
}
