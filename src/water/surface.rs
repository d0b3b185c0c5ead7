//! Shore samples → occluder filter → water surface model (level plane or constrained
//! Delaunay interpolation). See the module documentation of [`super`] for the reasoning.

use std::collections::HashMap;

use serde::{Deserialize, Serialize};
use spade::{ConstrainedDelaunayTriangulation, Point2, PositionInTriangulation, Triangulation};

use super::WaterConfig;

/// One shore (or water-level) sample: a position in the map frame and an elevation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ShoreSample {
    /// Map x, metres.
    pub x: f64,
    /// Map y, metres.
    pub y: f64,
    /// Elevation, map z, metres.
    pub z: f64,
}

/// The fitted water surface of a body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum SurfaceModel {
    /// A horizontal plane at `z`.
    Level {
        /// Elevation of the plane, map z, metres.
        z: f64,
    },
    /// Barycentric interpolation on the constrained Delaunay triangulation of `samples`;
    /// `constraints` are index pairs into `samples` (neighbouring shore cells).
    Delaunay {
        /// The triangulation's vertices.
        samples: Vec<ShoreSample>,
        /// Edges that the triangulation keeps, as index pairs into `samples`.
        constraints: Vec<[usize; 2]>,
    },
}

impl SurfaceModel {
    /// The model's name in reports: `level` or `delaunay`.
    pub fn name(&self) -> &'static str {
        match self {
            SurfaceModel::Level { .. } => "level",
            SurfaceModel::Delaunay { .. } => "delaunay",
        }
    }

    /// An evaluator of the surface (builds the triangulation once).
    pub(crate) fn evaluator(&self) -> Surface {
        match self {
            SurfaceModel::Level { z } => Surface::Level(*z),
            SurfaceModel::Delaunay {
                samples,
                constraints,
            } => Surface::tin(samples, constraints).unwrap_or_else(|| {
                // Not triangulable (fewer than 3 distinct non-collinear samples): the
                // median, which is what `fit` would have chosen.
                Surface::Level(median(samples.iter().map(|s| s.z).collect()).unwrap_or(0.0))
            }),
        }
    }
}

/// A triangulation vertex: position and elevation.
#[derive(Debug, Clone, Copy)]
pub struct V {
    p: Point2<f64>,
    z: f64,
}

impl spade::HasPosition for V {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.p
    }
}

/// A surface ready to evaluate.
pub enum Surface {
    /// A horizontal plane at this elevation, map z, metres.
    Level(f64),
    /// Barycentric interpolation on a constrained Delaunay triangulation.
    Tin {
        /// The triangulation of the surface samples.
        cdt: ConstrainedDelaunayTriangulation<V>,
        /// The hull's edges, for points outside it.
        hull: Vec<[V; 2]>,
    },
}

impl Surface {
    /// The triangulation of `samples` with the given constraint edges; `None` when the
    /// samples do not span a triangle (all collinear, fewer than three distinct points, or
    /// non-finite). Crossing constraints are skipped, not a panic.
    fn tin(samples: &[ShoreSample], constraints: &[[usize; 2]]) -> Option<Surface> {
        let finite = |s: &ShoreSample| s.x.is_finite() && s.y.is_finite() && s.z.is_finite();
        if samples.len() < 3 || !samples.iter().all(finite) {
            return None;
        }
        let verts: Vec<V> = samples
            .iter()
            .map(|s| V {
                p: Point2::new(s.x, s.y),
                z: s.z,
            })
            .collect();
        let edges: Vec<[usize; 2]> = constraints
            .iter()
            .copied()
            .filter(|&[a, b]| a < samples.len() && b < samples.len() && a != b)
            .collect();
        // Duplicate positions are merged by spade, which renumbers vertices: constraints
        // then no longer refer to the right ones, so with duplicates load without them.
        let distinct = {
            let mut p: Vec<(u64, u64)> = samples
                .iter()
                .map(|s| (s.x.to_bits(), s.y.to_bits()))
                .collect();
            p.sort_unstable();
            p.dedup();
            p.len()
        };
        let edges = if distinct == samples.len() {
            edges
        } else {
            Vec::new()
        };
        let cdt =
            ConstrainedDelaunayTriangulation::<V>::try_bulk_load_cdt(verts, edges, |_| {}).ok()?;
        if cdt.num_inner_faces() == 0 {
            return None;
        }
        let hull = cdt
            .convex_hull()
            .map(|e| e.vertices().map(|v| *v.data()))
            .collect();
        Some(Surface::Tin { cdt, hull })
    }

    /// Surface elevation at `(x, y)`: the plane, or barycentric interpolation in the
    /// triangle containing the point; outside the triangulation's hull, the surface at the
    /// nearest point of the hull (continuous across it, level away from it).
    pub fn at(&self, x: f64, y: f64) -> f64 {
        match self {
            Surface::Level(z) => *z,
            Surface::Tin { cdt, hull } => {
                let p = Point2::new(x, y);
                let z = match cdt.locate(p) {
                    PositionInTriangulation::OnFace(f) => {
                        let f = cdt.face(f);
                        let w = f.barycentric_interpolation(p);
                        let v = f.vertices();
                        w[0] * v[0].data().z + w[1] * v[1].data().z + w[2] * v[2].data().z
                    }
                    PositionInTriangulation::OnVertex(v) => cdt.vertex(v).data().z,
                    PositionInTriangulation::OnEdge(e) => {
                        let e = cdt.directed_edge(e);
                        on_segment(e.vertices().map(|v| *v.data()), x, y).1
                    }
                    _ => f64::NAN,
                };
                // Outside the hull, or a point exactly on a hull edge for which the
                // interpolation weights degenerate: the nearest point of the hull (the first
                // edge of the hull's order among equally near ones).
                if z.is_finite() {
                    z
                } else {
                    hull.iter()
                        .map(|&e| on_segment(e, x, y))
                        .min_by(|a, b| a.0.total_cmp(&b.0))
                        .map_or(f64::NAN, |(_, z)| z)
                }
            }
        }
    }

    /// How far `(x, y)` lies outside the samples' convex hull, metres: 0 inside it, and
    /// for a level plane (which holds everywhere). Beyond the hull a triangulated surface
    /// is the hull's edge carried on level: a guess, not a fit.
    pub(crate) fn outside_hull_m(&self, x: f64, y: f64) -> f64 {
        match self {
            Surface::Level(_) => 0.0,
            Surface::Tin { cdt, hull } => match cdt.locate(Point2::new(x, y)) {
                PositionInTriangulation::OutsideOfConvexHull(_) => hull
                    .iter()
                    .map(|&e| on_segment(e, x, y).0)
                    .fold(f64::INFINITY, f64::min)
                    .sqrt(),
                _ => 0.0,
            },
        }
    }
}

/// The squared distance from `(x, y)` to the segment `[a, b]` and the linear interpolation
/// of the ends' elevations at the segment's point nearest to it.
fn on_segment([a, b]: [V; 2], x: f64, y: f64) -> (f64, f64) {
    let (dx, dy) = (b.p.x - a.p.x, b.p.y - a.p.y);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((x - a.p.x) * dx + (y - a.p.y) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (px, py) = (a.p.x + t * dx - x, a.p.y + t * dy - y);
    (px * px + py * py, a.z + t * (b.z - a.z))
}

/// The `q` quantile (0..1, nearest rank) of finite values; `None` when there are none.
pub(crate) fn quantile(mut v: Vec<f64>, q: f64) -> Option<f64> {
    v.retain(|z| z.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_unstable_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    Some(v[i])
}

/// The median of the finite values (nearest rank); `None` when there are none.
pub(crate) fn median(v: Vec<f64>) -> Option<f64> {
    quantile(v, 0.5)
}

/// Floor of a sample's elevation σ in [`weighted_level`] (m): a cell of a few returns may
/// report σ ≈ 0, and no one cell should outweigh all others by orders of magnitude.
const SIGMA_FLOOR_M: f64 = 0.01;

/// A level at the weighted median of the samples' elevations, each weighted by
/// 1 / max(σ, 1 cm)² (`sigma`, one per sample; non-finite σ weighs nothing unless no
/// sample has a finite one), with the weighted RMS about it as the residual. `None` without
/// a finite sample.
pub(crate) fn weighted_level(samples: &[ShoreSample], sigma: &[f64]) -> Option<Fit> {
    let mut v: Vec<(f64, f64)> = samples
        .iter()
        .zip(sigma)
        .filter(|(s, _)| s.z.is_finite())
        .map(|(s, &sd)| {
            let w = if sd.is_finite() {
                sd.max(SIGMA_FLOOR_M).powi(-2)
            } else {
                0.0
            };
            (s.z, w)
        })
        .collect();
    if v.is_empty() {
        return None;
    }
    if v.iter().all(|p| p.1 == 0.0) {
        v.iter_mut().for_each(|p| p.1 = 1.0);
    }
    v.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = v.iter().map(|p| p.1).sum();
    let mut acc = 0.0;
    let z = v
        .iter()
        .find(|p| {
            acc += p.1;
            acc >= 0.5 * total
        })
        .map_or(v[v.len() - 1].0, |p| p.0);
    let level_residual_m = (v.iter().map(|p| p.1 * (p.0 - z).powi(2)).sum::<f64>() / total).sqrt();
    Some(Fit {
        model: SurfaceModel::Level { z },
        level_residual_m,
        delaunay_residual_m: None,
        decided: true,
    })
}

/// Drops occluded shore samples: a sample more than `cfg.occluder_height_m` above the
/// `cfg.shore_quantile` quantile of the elevations within `cfg.shore_radius_m` of it stands
/// on something raised (a bush, a rock, a bank top seen past the edge). The elevations are
/// those of the shore samples (itself included) and of `ground`, dry cells near the shore:
/// where a bush covers a stretch of shore, every shore sample there is bush, but the ground
/// beside it is not. Returns the indices of the samples kept, in input order.
pub(crate) fn reject_occluders(
    samples: &[ShoreSample],
    ground: &[ShoreSample],
    cfg: &WaterConfig,
) -> Vec<usize> {
    local_quantiles(samples, ground, cfg.shore_radius_m, cfg.shore_quantile)
        .into_iter()
        .zip(samples)
        .enumerate()
        .filter(|(_, (reference, s))| s.z - reference.unwrap_or(s.z) <= cfg.occluder_height_m)
        .map(|(i, _)| i)
        .collect()
}

/// For each of `samples`, the `q` quantile of the elevations within `radius` (> 0) of it
/// among `samples` (itself included) and `extra`; `None` when none of them is finite.
fn local_quantiles(
    samples: &[ShoreSample],
    extra: &[ShoreSample],
    radius: f64,
    q: f64,
) -> Vec<Option<f64>> {
    let r2 = radius * radius;
    let bucket = |s: &ShoreSample| ((s.x / radius).floor() as i64, (s.y / radius).floor() as i64);
    let mut buckets: HashMap<(i64, i64), Vec<&ShoreSample>> = HashMap::new();
    for s in samples.iter().chain(extra) {
        buckets.entry(bucket(s)).or_default().push(s);
    }
    samples
        .iter()
        .map(|s| {
            let (bx, by) = bucket(s);
            let near: Vec<f64> = (-1..=1)
                .flat_map(|dx| (-1..=1).map(move |dy| (bx + dx, by + dy)))
                .filter_map(|b| buckets.get(&b))
                .flatten()
                .filter(|o| (o.x - s.x).powi(2) + (o.y - s.y).powi(2) <= r2)
                .map(|o| o.z)
                .collect();
            quantile(near, q)
        })
        .collect()
}

/// Of the samples `kept`, those not more than `occluder_height_m` above the highest the
/// water beside them can stand: `z_j + max_surface_slope · d_ij` for every other kept
/// sample j within `spill_radius_m` (module documentation, section 2). Indices into
/// `samples`, in the order of `kept`.
pub(crate) fn reject_spilling(
    samples: &[ShoreSample],
    kept: &[usize],
    cfg: &WaterConfig,
) -> Vec<usize> {
    let r = cfg.spill_radius_m;
    if r <= 0.0 {
        return kept.to_vec();
    }
    let bucket = |s: &ShoreSample| ((s.x / r).floor() as i64, (s.y / r).floor() as i64);
    let mut buckets: HashMap<(i64, i64), Vec<&ShoreSample>> = HashMap::new();
    for &i in kept {
        buckets
            .entry(bucket(&samples[i]))
            .or_default()
            .push(&samples[i]);
    }
    kept.iter()
        .copied()
        .filter(|&i| {
            let s = &samples[i];
            let (bx, by) = bucket(s);
            let bound = (-1..=1)
                .flat_map(|dx| (-1..=1).map(move |dy| (bx + dx, by + dy)))
                .filter_map(|b| buckets.get(&b))
                .flatten()
                .filter_map(|o| {
                    let d = (o.x - s.x).hypot(o.y - s.y);
                    (d <= r).then_some(o.z + cfg.max_surface_slope * d)
                })
                .fold(f64::INFINITY, f64::min);
            s.z - bound <= cfg.occluder_height_m
        })
        .collect()
}

/// Each sample with its elevation replaced by the median of the samples within `radius`
/// of it (itself included): what that stretch of shore says, for the vertices of a
/// Delaunay surface, which would otherwise carry each sample's own error to the water
/// around it (module documentation, section 3). Order and positions are kept.
pub(crate) fn local_medians(samples: &[ShoreSample], radius: f64) -> Vec<ShoreSample> {
    if radius.is_nan() || radius <= 0.0 {
        return samples.to_vec();
    }
    local_quantiles(samples, &[], radius, 0.5)
        .into_iter()
        .zip(samples)
        .map(|(m, s)| ShoreSample {
            z: m.unwrap_or(s.z),
            ..*s
        })
        .collect()
}

/// The outcome of choosing a surface model for one body.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Fit {
    /// The surface chosen.
    pub model: SurfaceModel,
    /// RMS of the kept samples about the median level.
    pub level_residual_m: f64,
    /// Hold-out RMS of the Delaunay surface (every other sample predicted from the
    /// triangulation of the rest); `None` when it was not needed or not possible.
    pub delaunay_residual_m: Option<f64>,
    /// False when the samples were neither level nor a surface a triangulation predicts
    /// (or could be triangulated at all), and the level is the lowest samples' fallback.
    pub decided: bool,
}

fn rms(it: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for v in it {
        s += v * v;
        n += 1;
    }
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

/// Chooses the surface of a body from its (occluder-filtered) samples and the constraint
/// edges between them: the level plane at the median when its RMS residual is within
/// `cfg.level_residual_m`; otherwise the constrained Delaunay surface when its hold-out
/// residual beats the level's, else still the level. The Delaunay surface's vertices are
/// the samples at their [`local_medians`] within `cfg.vertex_median_radius_m`; the
/// residuals are those of the samples as measured. `noise_m` is the samples' typical
/// elevation σ: the robust level test allows the spread that noise explains. `None`
/// without finite samples.
pub(crate) fn fit(
    samples: &[ShoreSample],
    constraints: &[[usize; 2]],
    cfg: &WaterConfig,
    noise_m: f64,
) -> Option<Fit> {
    let z = median(samples.iter().map(|s| s.z).collect())?;
    let level_residual_m = rms(samples.iter().map(|s| s.z - z));
    let level = Fit {
        model: SurfaceModel::Level { z },
        level_residual_m,
        delaunay_residual_m: None,
        decided: true,
    };
    if level_residual_m <= cfg.level_residual_m || samples.len() < 6 {
        return Some(level);
    }
    // Also level: a shore whose spread, read robustly (1.4826 × the median absolute
    // deviation: the RMS of normal noise), is as small, and whose lower quarter
    // (`shore_quantile`) stands within that residual of the level too. Then what lifts the
    // RMS is a few raised samples the occluder test kept (the foot of a bush), which do not
    // make a pond a stream; low ones would (water cannot stand above its shore).
    //
    // The samples' own noise may exceed `level_residual_m` (lidar cells at 20 m on grass
    // have σ of 3 cm): a spread within it is level too, but not decided, since a short
    // stretch of a sloping stream is level within its noise as well. The caller then adds
    // the far shore, whose length shows the slope if there is one.
    let spread = 1.4826 * median(samples.iter().map(|s| (s.z - z).abs()).collect())?;
    let low = quantile(samples.iter().map(|s| s.z).collect(), cfg.shore_quantile)?;
    let within = |t: f64| spread <= t && z - low <= t;
    if within(cfg.level_residual_m) {
        return Some(level);
    }
    if within(noise_m) {
        return Some(Fit {
            decided: false,
            ..level
        });
    }
    // Hold-out: triangulate the even samples, predict the odd ones.
    let even: Vec<ShoreSample> = samples.iter().step_by(2).copied().collect();
    let Some(half) = Surface::tin(&even, &[]) else {
        return Some(Fit {
            decided: false,
            ..level
        });
    };
    let held = rms(samples
        .iter()
        .skip(1)
        .step_by(2)
        .map(|s| half.at(s.x, s.y) - s.z));
    // The full triangulation must exist too (it does when half of it does, unless samples
    // are non-finite, which `median` and `tin` both exclude).
    if Surface::tin(samples, constraints).is_none() || held >= level_residual_m {
        // The shore is neither level nor a smooth surface: raised samples the local
        // occluder test could not see (a stretch of shore that is all bush, the top of a
        // bank where the water's edge was hidden). Water cannot stand above its lowest
        // shore, so the level is that of the lowest samples (paper 2.2): the median of
        // those within `occluder_height_m` of the `shore_quantile` quantile (`low`).
        let z = median(
            samples
                .iter()
                .map(|s| s.z)
                .filter(|&z| z <= low + cfg.occluder_height_m)
                .collect(),
        )?;
        return Some(Fit {
            model: SurfaceModel::Level { z },
            delaunay_residual_m: Some(held),
            decided: false,
            ..level
        });
    }
    Some(Fit {
        model: SurfaceModel::Delaunay {
            samples: local_medians(samples, cfg.vertex_median_radius_m),
            constraints: constraints.to_vec(),
        },
        level_residual_m,
        delaunay_residual_m: Some(held),
        decided: true,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn s(x: f64, y: f64, z: f64) -> ShoreSample {
        ShoreSample { x, y, z }
    }

    #[test]
    fn degenerate_samples_do_not_panic_and_fall_back() {
        let cfg = WaterConfig::default();
        // Collinear, sloped: no triangle. The fit stays level at the median.
        let line: Vec<_> = (0..20).map(|i| s(i as f64, 0.0, 0.1 * i as f64)).collect();
        let f = fit(&line, &[], &cfg, 0.0).unwrap();
        assert_eq!(f.model, SurfaceModel::Level { z: 1.0 });
        // Duplicates and nearly coincident points with constraints that refer to them.
        let mut dup: Vec<_> = (0..10)
            .flat_map(|i| [s(i as f64, 0.0, 0.0), s(i as f64, 5.0, 1.0)])
            .collect();
        dup.push(s(3.0, 0.0, 0.0));
        dup.push(s(3.0 + 1e-12, 1e-12, 0.0));
        let cons: Vec<[usize; 2]> = (0..dup.len() - 1).map(|i| [i, i + 1]).collect();
        let f = fit(&dup, &cons, &cfg, 0.0).unwrap();
        let e = f.model.evaluator();
        let z = e.at(4.5, 2.5);
        assert!(z.is_finite() && (-0.01..=1.01).contains(&z), "{z}");
        // Nothing finite: no fit.
        assert!(fit(&[s(f64::NAN, 0.0, f64::NAN)], &[], &cfg, 0.0).is_none());
        assert!(fit(&[], &[], &cfg, 0.0).is_none());
        // One sample.
        assert_eq!(
            fit(&[s(0.0, 0.0, 2.0)], &[], &cfg, 0.0).unwrap().model,
            SurfaceModel::Level { z: 2.0 }
        );
    }

    /// One reliable shore cell (σ 2 cm) at the water's edge among eighteen stereo cells of
    /// σ 2 m lifted 0.1–0.3 m by their noise: the reliable one sets the level. With no
    /// finite σ at all, the plain median.
    #[test]
    fn weighted_level_follows_the_reliable_samples() {
        let mut v = vec![s(0.0, 0.0, -0.35)];
        let mut sd = vec![0.02];
        for i in 0..18 {
            v.push(s(i as f64, 1.0, -0.25 + 0.2 * (i % 7) as f64 / 6.0));
            sd.push(2.0);
        }
        let f = weighted_level(&v, &sd).unwrap();
        assert_eq!(f.model, SurfaceModel::Level { z: -0.35 });
        assert!(f.level_residual_m < 0.02, "{}", f.level_residual_m);
        let none = vec![f64::NAN; v.len()];
        let m = median(v.iter().map(|p| p.z).collect()).unwrap();
        assert_eq!(
            weighted_level(&v, &none).unwrap().model,
            SurfaceModel::Level { z: m }
        );
        assert!(weighted_level(&[], &[]).is_none());
    }

    #[test]
    fn outside_the_hull_is_the_nearest_point_of_the_hull() {
        let samples = vec![s(0.0, 0.0, 0.0), s(1.0, 0.0, 1.0), s(0.0, 1.0, 2.0)];
        let e = SurfaceModel::Delaunay {
            samples,
            constraints: vec![[0, 1], [1, 2], [2, 0]],
        }
        .evaluator();
        assert!((e.at(0.25, 0.25) - 0.75).abs() < 1e-12);
        // Beyond a corner: the corner's sample.
        assert_eq!(e.at(5.0, -1.0), 1.0);
        assert_eq!(e.at(0.5, 0.0), 0.5);
        // Beside an edge: the edge's interpolation at the foot of the perpendicular, not
        // the nearest sample (0 or 1 here, 2 or 0 on the left).
        assert!((e.at(0.5, -1.0) - 0.5).abs() < 1e-12);
        assert!((e.at(-1.0, 0.5) - 1.0).abs() < 1e-12);
        assert!((e.at(1.0, 1.0) - 1.5).abs() < 1e-12);
    }

    proptest! {
        /// How far a point lies outside a triangulated surface's hull: 0 inside and on it,
        /// the distance to the nearest edge or corner outside, whatever the offset of the
        /// coordinates; a level plane reaches everywhere.
        #[test]
        fn outside_the_hull_is_the_distance_to_it(
            off in prop_oneof![Just(0.0), 1e5f64..1e6],
            u in 0.0f64..1.0, v in 0.0f64..1.0, d in 0.01f64..20.0, a in 0.0f64..std::f64::consts::TAU,
        ) {
            let samples = vec![s(off, off, 0.0), s(off + 2.0, off, 0.0), s(off + 2.0, off + 2.0, 0.0), s(off, off + 2.0, 0.0)];
            let e = SurfaceModel::Delaunay { samples, constraints: vec![] }.evaluator();
            let (x, y) = (off + 2.0 * u, off + 2.0 * v);
            prop_assert_eq!(e.outside_hull_m(x, y), 0.0);
            // Straight out from the square's bottom edge, or from a corner along any
            // direction that leaves it.
            let below = e.outside_hull_m(off + 2.0 * u, off - d);
            prop_assert!((below - d).abs() < 1e-6, "{} {}", below, d);
            let (dx, dy) = (a.cos().abs(), -a.sin().abs());
            let corner = e.outside_hull_m(off + 2.0 + d * dx, off + d * dy);
            prop_assert!((corner - d).abs() < 1e-6, "{} {}", corner, d);
            prop_assert_eq!(SurfaceModel::Level { z: 1.0 }.evaluator().outside_hull_m(x - 50.0, y), 0.0);
        }
    }

    proptest! {
        /// A level shore with one raised sample far from the others (the foot of a bush
        /// the occluder test kept): the spread is read robustly, so the body stays level
        /// at the shore's own height instead of tilting up to the raised sample, however
        /// high it stands; the RMS it reports still counts that sample.
        #[test]
        fn one_raised_sample_does_not_tilt_a_level_shore(
            level in -2.0f64..2.0,
            n in 5usize..40,
            rise in 0.1f64..2.0,
            noise in proptest::collection::vec(-0.01f64..0.01, 40),
        ) {
            let cfg = WaterConfig::default();
            let mut v: Vec<ShoreSample> = (0..n)
                .map(|i| s(f64::from(i as u32) * 0.3, 6.0, level + noise[i]))
                .collect();
            v.push(s(1.0, 0.0, level + rise));
            let f = fit(&v, &[], &cfg, 0.0).unwrap();
            let SurfaceModel::Level { z } = f.model else {
                panic!("not level: {:?}", f.model.name());
            };
            prop_assert!((z - level).abs() <= 0.01);
            prop_assert!(f.level_residual_m >= rise / ((n + 1) as f64).sqrt() - 0.011);
        }
    }

    proptest! {
        /// A level shore whose samples scatter evenly over ±4 cm (cells of σ 4 cm), with two
        /// raised ones: beyond `level_residual_m` (2 cm) however read, so without the
        /// samples' noise the fit is no decided level; with it, the level at the shore's
        /// median, undecided (the caller adds the far shore).
        #[test]
        fn a_level_shore_within_its_noise_is_level_but_undecided(
            level in -2.0f64..2.0,
            shift in 0usize..24,
        ) {
            let cfg = WaterConfig::default();
            let mut v: Vec<ShoreSample> = (0..24)
                .map(|i| {
                    let e = 0.08 * (((i * 7 + shift) % 24) as f64 / 23.0 - 0.5);
                    s(f64::from(i as u32) * 0.3, 6.0 + f64::from((i % 3) as u32), level + e)
                })
                .collect();
            v.push(s(1.0, 0.0, level + 0.35));
            v.push(s(1.3, 0.0, level + 0.30));
            let strict = fit(&v, &[], &cfg, 0.0).unwrap();
            let decided_level = matches!(strict.model, SurfaceModel::Level { .. }) && strict.decided;
            prop_assert!(!decided_level);
            let f = fit(&v, &[], &cfg, 0.04).unwrap();
            let SurfaceModel::Level { z } = f.model else {
                panic!("not level: {:?}", f.model.name());
            };
            prop_assert!(!f.decided);
            prop_assert!((z - level).abs() <= 0.01);
        }
    }

    /// A stream 2 m wide falling 3 % along x, its banks sampled every 10 cm, with a few
    /// shore cells 10 cm under the water (its bed, seen through it): the Delaunay surface
    /// is chosen and stands within a centimetre of the water over them, where one vertex
    /// per sample would put it 10 cm low. (Within the radius of the ends, the median of a
    /// one-sided neighbourhood stands up to slope × radius / 2 off: 2.25 cm here.) The
    /// residuals are the samples' own.
    #[test]
    fn a_stream_surface_is_not_pulled_down_by_single_low_samples() {
        let cfg = WaterConfig::default();
        let water = |x: f64| 0.03 * x;
        let mut v = Vec::new();
        for y in [0.0, 2.0] {
            for i in 0..200 {
                let x = f64::from(i) * 0.1;
                let low = if y == 0.0 && i % 37 == 20 { 0.10 } else { 0.0 };
                v.push(s(x, y, water(x) - low));
            }
        }
        let f = fit(&v, &[], &cfg, 0.0).unwrap();
        assert_eq!(f.model.name(), "delaunay");
        let raw = median(v.iter().map(|p| p.z).collect()).unwrap();
        let level_rms = rms(v.iter().map(|p| p.z - raw));
        assert!((f.level_residual_m - level_rms).abs() < 1e-12);
        let e = f.model.evaluator();
        for i in (20..180).step_by(37) {
            let x = f64::from(i) * 0.1;
            for y in [0.0, 0.5, 1.0] {
                let err = e.at(x, y) - water(x);
                assert!(err.abs() < 0.01, "x {x} y {y}: {err}");
            }
        }
    }

    proptest! {
        /// The local median of samples along a sloping shore, some of them isolated
        /// outliers: every sample's median lies on the shore's line within its slope over
        /// half the radius (a one-sided neighbourhood at the ends) and two spacings,
        /// however far the outliers are off.
        #[test]
        fn local_medians_ignore_isolated_outliers(
            a in -2.0f64..2.0, b in -0.05f64..0.05, n in 20usize..120,
            outliers in prop::collection::vec((0usize..120, 0.05f64..2.0, prop::bool::ANY), 0..6),
            ox in -1e5f64..1e5,
        ) {
            let (radius, spacing) = (1.5, 0.1);
            let line = |x: f64| a + b * (x - ox);
            let mut v: Vec<ShoreSample> =
                (0..n).map(|i| { let x = ox + i as f64 * spacing; s(x, 0.0, line(x)) }).collect();
            // Outliers at least 2 radii apart: one per neighbourhood.
            let mut at: Vec<usize> = Vec::new();
            for &(i, off, up) in &outliers {
                let i = i % n;
                if at.iter().all(|&j| (i as f64 - j as f64).abs() * spacing > 2.0 * radius) {
                    at.push(i);
                    v[i].z += if up { off } else { -off };
                }
            }
            let m = local_medians(&v, radius);
            prop_assert_eq!(m.len(), v.len());
            // Half the radius, a rank for the outlier, half a rank for the nearest-rank
            // median of an even count.
            let bound = b.abs() * (radius / 2.0 + 2.0 * spacing) + 1e-6;
            for (p, q) in m.iter().zip(&v) {
                prop_assert!(p.x == q.x && p.y == q.y);
                prop_assert!((p.z - line(p.x)).abs() <= bound, "{} vs {} at x {}", p.z, line(p.x), p.x);
            }
        }

        /// Samples of a plane on the integer points of a rectangle: outside it, the surface
        /// is the plane at the rectangle's nearest point (the query clamped into it), which
        /// is continuous across the hull and never beyond the samples' range.
        #[test]
        fn outside_a_rectangle_is_the_plane_at_its_nearest_point(
            a in -2.0f64..2.0, b in -1.0f64..1.0, c in -1.0f64..1.0,
            w in 1u32..5, h in 1u32..5,
            x in -6.0f64..10.0, y in -6.0f64..10.0,
        ) {
            let plane = |x: f64, y: f64| a + b * x + c * y;
            let mut samples = Vec::new();
            for i in 0..=w {
                for j in 0..=h {
                    let (sx, sy) = (f64::from(i), f64::from(j));
                    samples.push(s(sx, sy, plane(sx, sy)));
                }
            }
            let e = SurfaceModel::Delaunay { samples, constraints: vec![] }.evaluator();
            let want = plane(x.clamp(0.0, f64::from(w)), y.clamp(0.0, f64::from(h)));
            prop_assert!((e.at(x, y) - want).abs() < 1e-9, "{} vs {}", e.at(x, y), want);
        }

        /// Barycentric interpolation reproduces any plane exactly inside the hull, whatever
        /// the sample layout (duplicates included).
        #[test]
        fn a_plane_is_reproduced(
            pts in prop::collection::vec((-10.0f64..10.0, -10.0f64..10.0), 3..40),
            a in -1.0f64..1.0, b in -0.1f64..0.1, c in -0.1f64..0.1,
            qx in -1.0f64..1.0, qy in -1.0f64..1.0,
        ) {
            let mut samples: Vec<_> = pts.iter().map(|&(x, y)| s(x, y, a + b * x + c * y)).collect();
            samples.push(samples[0]);
            let cons: Vec<[usize; 2]> = (1..samples.len()).map(|i| [i - 1, i]).collect();
            let e = SurfaceModel::Delaunay { samples: samples.clone(), constraints: cons }.evaluator();
            // A point that is a convex combination of three samples lies inside the hull.
            let (p, q, r) = (samples[0], samples[1], samples[2]);
            let (u, v) = (qx.abs() * 0.5, qy.abs() * 0.5);
            let (x, y) = (p.x + u * (q.x - p.x) + v * (r.x - p.x), p.y + u * (q.y - p.y) + v * (r.y - p.y));
            let z = e.at(x, y);
            prop_assert!(z.is_finite());
            if let Surface::Tin { .. } = e {
                prop_assert!((z - (a + b * x + c * y)).abs() < 1e-6, "{} vs {}", z, a + b * x + c * y);
            }
        }
    }
}
