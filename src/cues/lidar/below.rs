//! Returns below the walked level: read through the water surface, each is a bottom
//! return (refraction-corrected, at a depth the optics can see), a specular return (the
//! mirror image of an object beyond the water), or ground below the level that the scan
//! line's own beams refute as a mirror image.

use nalgebra::{Point3, Vector3};

use super::walk::Event;
use super::LidarCueModel;
use crate::cues::WaterPrior;
use crate::geom::PointCloud;

impl LidarCueModel {
    /// A return under the water surface `prior` knows at its cell, by more than the
    /// line's below-level `gate` and three standard deviations of the surface together, at
    /// a depth the optics say this sensor can see there: a bottom return at that level.
    pub(super) fn under_prior(
        &self,
        prior: &WaterPrior,
        slot: usize,
        o: Point3<f64>,
        p: Point3<f64>,
        gate: impl FnOnce() -> f64,
    ) -> Option<Event> {
        let l = prior.level_at(p.x, p.y)?;
        if p.z >= o.z || o.z <= l.z || p.z >= l.z - gate().hypot(3.0 * l.sigma) {
            return None;
        }
        self.against_level(slot, o, p, l.z, true)?.1
    }

    /// A return `p` below the water level `level`, read through it: where its beam crosses
    /// the level and, when its refraction-corrected depth is one the optics say this
    /// sensor can see there, the bottom return (`prior`: the level is the prior's). `None`
    /// when the return cannot be corrected.
    pub(super) fn against_level(
        &self,
        slot: usize,
        o: Point3<f64>,
        p: Point3<f64>,
        level: f64,
        prior: bool,
    ) -> Option<(Point3<f64>, Option<Event>)> {
        let v = p - o;
        let u = v / v.norm();
        let c = o + u * ((o.z - level) / -u.z);
        let d_c = crate::geom::hypot(c.x - o.x, c.y - o.y);
        let q = self.optics.correct_bottom_return(o, p, level).ok()?;
        let depth = level - q.z;
        let visible = depth <= self.max_visible_depth(d_c) + self.cfg.depth_tolerance_m;
        let bottom = visible.then(|| Event::Bottom {
            slot,
            x: q.x,
            y: q.y,
            level,
            depth,
            gain: crate::optics::bottom_depth_gain(o, p, self.optics.config().n_water)
                .unwrap_or(0.0),
            prior,
        });
        Some((c, bottom))
    }
}

/// Beams of a scan line that must see the space above a below-level return empty before
/// it is taken for ground rather than a mirror image.
const MIRROR_FREE_BEAMS: usize = 2;

/// One scan line of an organized scan: its slots in order of lookahead, the scan, the
/// map-frame directions of its slots and the sensor's position.
#[derive(Clone, Copy)]
pub(super) struct ScanLine<'a> {
    pub(super) cloud: &'a PointCloud,
    pub(super) dirs: &'a [Option<Vector3<f64>>],
    pub(super) slots: &'a [u32],
    pub(super) o: Point3<f64>,
}

/// Whether the below-level return `p` of a scan `line` (walked level `level`, range noise
/// `sigma_r`) cannot be a mirror image. A return mirrored by water at level `w` appears at
/// the mirror image of its object about the water plane: the object stands at the
/// return's own x, y, at height `2w − z`.
/// The water lies between the return and the walked level, so the object lies somewhere on
/// the vertical segment from the return up to `2·level − z`, in the same azimuth: the scan
/// line's own higher beams cross that segment. A beam that crosses it and stops at or
/// before the crossing (within three σ of range noise) may have met the object, and keeps
/// the mirror. If none does, at least [`MIRROR_FREE_BEAMS`] cross it, and the lowest of
/// them passes within `low` (the walk's above-ground gate) of the return's height (above a
/// margin of the beam's noise, so that the far bank rising just behind the return is not
/// taken for an object), the only object it could mirror is one lower than that crossing:
/// one the walk would take for ground at the return's place anyway. The return is ground
/// below the level, the far bank of a depression. Sparse rings at range that cross only
/// high leave it a mirror.
pub(super) fn mirror_refuted(
    line: &ScanLine,
    p: Point3<f64>,
    level: f64,
    sigma_r: f64,
    low: f64,
) -> bool {
    let ScanLine {
        cloud,
        dirs,
        slots,
        o,
    } = *line;
    let d = crate::geom::hypot(p.x - o.x, p.y - o.y);
    let tol = 3.0 * sigma_r.max(0.01);
    // Above the return by a margin, so that a beam grazing the ground just behind it (the
    // far bank rising from the return) is not taken for an object.
    let (lo, hi) = (p.z + tol.max(0.1), 2.0 * level - p.z);
    let (mut free, mut lowest) = (0, f64::INFINITY);
    for &t in slots {
        let t = t as usize;
        let Some(u) = dirs.get(t).copied().flatten() else {
            continue;
        };
        let h = crate::geom::hypot(u.x, u.y);
        if h <= 1e-9 {
            continue;
        }
        // Where the beam reaches the return's horizontal distance.
        let along = d / h;
        let z = o.z + u.z * along;
        if !(lo..=hi).contains(&z) {
            continue;
        }
        if cloud.is_valid(t) && (cloud.point_in_map(t) - o).norm() <= along + tol {
            return false;
        }
        free += 1;
        lowest = lowest.min(z);
    }
    free >= MIRROR_FREE_BEAMS && lowest <= p.z + low
}
