//! Where a sampled pixel lands on the map: through its stereo point or the march over the
//! map ([`Placer`]), which image rows are sampled ([`sampled_rows`]), and the level of water
//! placed over holes ([`tighten_hole_levels`]).

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::classify::{Label, LabelImage};
use crate::cues::DryReach;
use crate::geom::PointCloud;
use crate::project::zbuffer::ZBuffer;
use crate::project::GridSurface;

/// How a sampled pixel finds its hit on the map: through its stereo point where it has
/// one within range, else by the march over the map, started where the z-buffer says its
/// ray first meets the map.
pub(super) struct Placer<'a> {
    pub(super) labels: &'a LabelImage,
    /// Image width, pixels.
    pub(super) width: usize,
    /// The stereo cloud and the factor by which the image upsamples it.
    pub(super) stereo: Option<(&'a PointCloud, usize)>,
    /// A stereo point places its pixel only up to this range (metres).
    pub(super) stereo_range: f64,
    /// The camera's position in the map.
    pub(super) origin: Point3<f64>,
    pub(super) zbuf: Option<&'a ZBuffer>,
    pub(super) map_rays: &'a [Option<Vector3<f64>>],
    pub(super) surface: &'a GridSurface,
    pub(super) max_range: f64,
    /// The lidar's dry reach: a hole beyond it is explained by range alone.
    pub(super) reach: Option<&'a DryReach>,
}

impl Placer<'_> {
    /// Per sampled pixel (`rows` × `cols`, row-major into `hits`): its hit, whether it is
    /// water (`None`: no vote), and the water level it gives (see `tighten_hole_levels`);
    /// per sampled row into `counts`: pixels placed via a point, via a ray, not placed,
    /// beyond reach. Rows in parallel, into the buffers of the last frame.
    pub(super) fn place_all(
        &self,
        rows: &[usize],
        cols: &[usize],
        hits: &mut Vec<Option<Hit>>,
        counts: &mut Vec<[u64; 4]>,
    ) {
        let (nr, nc) = (rows.len(), cols.len());
        hits.resize(nr * nc, None);
        // Zeroed here, not per row: a row without sampled columns (an image 0 pixels wide)
        // is never visited.
        counts.clear();
        counts.resize(nr, [0; 4]);
        hits.par_chunks_mut(nc.max(1))
            .zip(counts[..nr].par_iter_mut())
            .zip(rows.par_iter())
            .enumerate()
            .for_each(|(r, ((out, n), &y))| {
                for (ci, (slot, &x)) in out.iter_mut().zip(cols).enumerate() {
                    *slot = self.place(r * nc + ci, x, y, n);
                }
            });
    }

    /// The hit of pixel (x, y), sample `k` of the z-buffer, counted in `n` (via point, via
    /// ray, no hit, beyond reach); `None`: no vote.
    fn place(&self, k: usize, x: usize, y: usize, n: &mut [u64; 4]) -> Option<Hit> {
        let (origin, surface) = (self.origin, self.surface);
        let i = y * self.width + x;
        let water = match self.labels.data[i] {
            Label::Water => true,
            Label::Other | Label::SnowIce => false,
            Label::Sky | Label::Unknown => return None,
        };
        if let Some((c, f)) = self.stereo {
            let e = (y / f) * c.cols + x / f;
            if c.is_valid(e) {
                let p = c.point_in_map(e);
                if (p - origin).norm() <= self.stereo_range {
                    n[0] += 1;
                    return Some(Hit::at(p, water));
                }
            }
        }
        // With the z-buffer, the march starts where the ray first meets the drawn map; a
        // ray that meets nothing drawn meets no ground, and only water (placed in a hole at
        // its near rim's level) is marched.
        let mut after = 0.0;
        if let Some(zb) = self.zbuf {
            match zb.first(k) {
                Some(t) => after = t,
                None if water => {}
                None => {
                    n[2] += 1;
                    return None;
                }
            }
        }
        let cast = self.map_rays[i].and_then(|d| {
            surface
                .cast_through_holes_after(&origin, &d, self.max_range, after)
                .map(|h| (d, h))
        });
        // A hole beyond the dry reach is explained by range alone.
        if let (Some((_, (p, _, Some(_)))), Some(r)) = (cast, self.reach) {
            if !r.covers(p.x, p.y, 2.0 * surface.resolution()) {
                n[3] += 1;
                return None;
            }
        }
        match cast {
            // Only water is placed where the ray crosses a hole's rim level: whatever else
            // a pixel there shows (a bank the map has not seen, terrain reflected in the
            // water) is not at that level, and its vote would land on the water.
            Some((d, (p, _, hole))) if water || hole.is_none() => {
                n[1] += 1;
                let floor = hole.map(|t| origin.z + d.z * t);
                Some(Hit {
                    floor,
                    ..Hit::at(p, water)
                })
            }
            _ => {
                n[2] += 1;
                None
            }
        }
    }
}

/// One sampled pixel's hit on the map.
#[derive(Debug, Clone, Copy)]
pub(super) struct Hit {
    pub(super) p: Point3<f64>,
    /// Labelled water.
    pub(super) wet: bool,
    /// The water level its vote gives: the hit's height, or for water placed over a hole,
    /// see [`tighten_hole_levels`].
    pub(super) level: f64,
    /// For water placed where its ray drops to a hole's rim level: the ray's height at the
    /// end of the hole. The water under the pixel lies between that and the hit.
    pub(super) floor: Option<f64>,
}

impl Hit {
    pub(super) fn at(p: Point3<f64>, wet: bool) -> Self {
        Hit {
            p,
            wet,
            level: p.z,
            floor: None,
        }
    }
}

/// The image rows to label: every `stride`-th, and every row whose ground footprint on
/// either side is wider than `cell` metres, so that no skipped row spans more than a cell.
/// The footprint between two rows is how far apart their rays meet level ground `height`
/// metres below the camera, the widest of the first, middle and last columns (infinite
/// where only one of the two reaches the ground: the horizon). It grows with the square of
/// the range (r² / (h f) for focal length f): with the simulated 320 × 240 camera 1.6 m
/// up, a row spans a 0.1 m cell from about 6 m on, and 1 m at 20 m.
pub(super) fn sampled_rows(
    map_rays: &[Option<Vector3<f64>>],
    w: usize,
    stride: usize,
    height: f64,
    cell: f64,
) -> Vec<usize> {
    let h = map_rays.len() / w.max(1);
    let stride = stride.max(1);
    let ground = |r: &Option<Vector3<f64>>| match r {
        Some(r) if r.z < 0.0 && height > 0.0 => Some(height / -r.z * r.xy().norm()),
        _ => None,
    };
    let wide = |y: usize| {
        y + 1 < h
            && [0, w / 2, w.saturating_sub(1)].iter().any(|&x| {
                match (
                    ground(&map_rays[y * w + x]),
                    ground(&map_rays[(y + 1) * w + x]),
                ) {
                    (Some(a), Some(b)) => (a - b).abs() > cell,
                    (None, None) => false,
                    _ => true,
                }
            })
    };
    (0..h)
        .filter(|&y| y % stride == 0 || wide(y) || (y > 0 && wide(y - 1)))
        .collect()
}

/// Image neighbourhood (sampled pixels either side) over which water placed over holes
/// shares the tightest bound on its level.
pub(super) const HOLE_LEVEL_WINDOW: usize = 8;

/// A water pixel whose ray crosses a hole (unobserved cells) is placed where the ray drops
/// to the lower of the hole's two rims: water lies at or below both, so that height is an
/// upper bound of the level, and the ray's height where the hole ends is a lower one. Where
/// the near rim is a bank top, the bound is decimetres above the water: on the simulated
/// stream, the level samples of the water seen along the channel stood 15 to 28 cm above
/// it. Every ray across the same water bounds the same level, so each such pixel's level is
/// the lowest upper bound among the hole-placed water pixels within [`HOLE_LEVEL_WINDOW`]
/// sampled pixels of it in the image (what is near in the image is one water surface; a
/// stream's level varies along it), but never below its own lower bound.
///
/// The pixel's vote then moves along its ray to where the ray meets the tightened level.
/// Where it was placed, at its own upper bound, is only the nearest place the water can be:
/// up to 3.7 m short of a pond 0.35 m below its banks, on the near bank, where its votes
/// made a band of water on dry ground and its shore cells lifted the pond's level to the
/// bank top. A hole with no far rim in reach (as on the simulated pond in the first
/// frames) has no lower bound but the ray's end, and its pixels move as far as their
/// window's lowest upper bound.
pub(super) fn tighten_hole_levels(
    hits: &mut [Option<Hit>],
    nc: usize,
    origin: Point3<f64>,
    scratch: &mut Vec<f64>,
) {
    if nc == 0 {
        return;
    }
    let nr = hits.len() / nc;
    // Per sampled pixel its upper bound (∞: none), then the window minimum over columns.
    scratch.clear();
    scratch.extend(hits.iter().map(|h| match h {
        Some(h @ Hit { floor: Some(_), .. }) => h.p.z,
        _ => f64::INFINITY,
    }));
    if scratch.iter().all(|b| b.is_infinite()) {
        return;
    }
    let k = HOLE_LEVEL_WINDOW;
    let n = scratch.len();
    scratch.extend_from_within(..);
    let (upper, across) = scratch.split_at_mut(n);
    for (r, row) in across.chunks_mut(nc).enumerate() {
        let up = &upper[r * nc..(r + 1) * nc];
        for (c, a) in row.iter_mut().enumerate() {
            *a = up[c.saturating_sub(k)..(c + k + 1).min(nc)]
                .iter()
                .fold(f64::INFINITY, |a, &b| a.min(b));
        }
    }
    for (i, h) in hits.iter_mut().enumerate() {
        let Some(Hit {
            floor: Some(floor),
            level,
            p,
            ..
        }) = h
        else {
            continue;
        };
        let (r, c) = (i / nc, i % nc);
        let low = (r.saturating_sub(k)..(r + k + 1).min(nr))
            .map(|rr| across[rr * nc + c])
            .fold(f64::INFINITY, f64::min);
        *level = low.max(*floor).min(*level);
        if *level < p.z && p.z < origin.z {
            *p = origin + (*p - origin) * ((origin.z - *level) / (origin.z - p.z));
        }
    }
}
