use super::place::HOLE_LEVEL_WINDOW;
use super::quad::quad_cells;
use super::*;
use crate::classify::{optical_pose, ColorLut, Horizon, MwirConfig, RuleClassifier, SwirConfig};
use crate::cues::StereoSeen;
use crate::geom::{pose_xyz_rpy, Distortion};
use crate::grid::{FalseAlarms, Fusion, GridConfig, RangeNoise};
use crate::sensor::Image;
use nalgebra::Vector4;

const SKY: [u8; 3] = [250, 250, 252];
const GRASS: [u8; 3] = [60, 120, 40];

/// Ground at z = 0 observed on a 20 m window except a pond hole for 4 ≤ x < 6 (|y| < 2).
fn pond(x: f64, y: f64) -> bool {
    (4.0..6.0).contains(&x) && y.abs() < 2.0
}

fn ground_grid() -> RollingGrid {
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
            if !pond(x, y) {
                pts.push([x as f32, y as f32, 0.0]);
            }
        }
    }
    g.ingest(&PointCloud::unorganized(pts), &RangeNoise::constant(0.02))
        .unwrap();
    g
}

fn camera() -> (CameraModel, Pose) {
    let cam = CameraModel::new(
        96,
        64,
        [70.0, 70.0, 47.5, 31.5],
        Distortion::PlumbBob([-0.1, 0.01, 0.0, 0.0, 0.0]),
        "cam",
    )
    .unwrap();
    (
        cam,
        optical_pose(&pose_xyz_rpy(0.0, 0.0, 1.5, 0.0, 15f64.to_radians(), 0.0)),
    )
}

/// A frame whose colour image shows sky above the horizon, the sky reflected in the pond
/// and grass elsewhere (by casting each pixel ray against z = 0).
fn frame() -> Frame {
    let (cam, pose) = camera();
    let px: Vec<[u8; 3]> = (0..cam.width * cam.height)
        .map(|i| {
            let r = pose.rotation
                * cam
                    .pixel_ray((i % cam.width) as f64, (i / cam.width) as f64)
                    .unwrap();
            if r.z >= 0.0 {
                return SKY;
            }
            let t = 1.5 / -r.z;
            if pond(r.x * t, r.y * t) {
                SKY
            } else {
                GRASS
            }
        })
        .collect();
    Frame {
        stamp: 1.0,
        base_to_map: pose_xyz_rpy(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        lidar: None,
        stereo: None,
        image: Some(SensorImage {
            image: Image {
                width: cam.width,
                height: cam.height,
                pixels: Pixels::Rgb8(px),
                frame_id: "cam".into(),
                stamp: 1.0,
            },
            camera: Some(cam),
            frame_to_map: Some(pose),
        }),
        swir: None,
        mwir: None,
        stereo_baseline_m: None,
        geo: None,
    }
}

fn colour_cfg(stride: usize) -> FrameLabelConfig {
    FrameLabelConfig {
        colour: Some(ColorLut::compile(&RuleClassifier::default(), 8).unwrap()),
        ray_stride: stride,
        max_range: 30.0,
        ..FrameLabelConfig::default()
    }
}

#[test]
fn sky_reflections_vote_for_the_pond_cells() {
    for sampler in [Sampler::March, Sampler::Zbuffer] {
        sky_reflections_vote_for_the_pond_cells_with(sampler);
    }
}

fn sky_reflections_vote_for_the_pond_cells_with(sampler: Sampler) {
    let mut g = ground_grid();
    let mut fl = FrameLabels::new(FrameLabelConfig {
        sampler,
        ..colour_cfg(1)
    })
    .unwrap();
    let rep = fl.apply(&frame(), &mut g, None).unwrap();
    let st = rep.colour.unwrap();
    assert!(rep.swir.is_none() && rep.mwir.is_none());
    assert_eq!((st.frames, st.via_point), (1, 0));
    assert!(st.cells_water > 50 && st.cells_dry > 500, "{st:?}");
    let (mut water_votes, mut wrong) = (0, 0);
    for (k, c) in g.observed() {
        let (x, y) = g.centre_of(k);
        if c.ev.colour_water > 0 {
            water_votes += 1;
            // Only pond cells, give or take the cell a boundary pixel lands in.
            if !(pond(x, y) || pond(x + 0.1, y) || pond(x - 0.1, y)) {
                wrong += 1;
            }
            // The level sample is the hole's rim: z = 0.
            assert!(c.ev.level_mm().unwrap().abs() < 30.0, "{:?}", c.ev);
        }
        assert!(c.ev.colour_water + c.ev.colour_dry <= 1);
    }
    assert!(water_votes > 50 && wrong == 0, "{water_votes} {wrong}");
    // A second frame makes the pond cells water under the fusion rule.
    fl.apply(&frame(), &mut g, None).unwrap();
    let f = Fusion::default();
    let pond_water = g
        .observed()
        .filter(|(_, c)| c.ev.colour_water == 2)
        .filter(|(_, c)| c.ev.water_probability(&f) >= 0.9)
        .count();
    assert!(pond_water > 50, "{pond_water}");
}

#[test]
fn results_do_not_depend_on_threads_or_cached_rays() {
    let run = |threads: usize, sampler: Sampler| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut g = ground_grid();
            let mut fl = FrameLabels::new(FrameLabelConfig {
                sampler,
                ..colour_cfg(2)
            })
            .unwrap();
            fl.apply(&frame(), &mut g, None).unwrap();
            fl.apply(&frame(), &mut g, None).unwrap();
            g.observed().map(|(k, c)| (k, c.ev)).collect::<Vec<_>>()
        })
    };
    for sampler in [Sampler::March, Sampler::Zbuffer] {
        assert_eq!(run(1, sampler), run(3, sampler));
    }
    // The z-buffer finds where the march goes: the same votes on all but a few cells at
    // the edges of what each surface model meets.
    let (a, b) = (run(2, Sampler::March), run(2, Sampler::Zbuffer));
    let a: std::collections::HashMap<_, _> = a.into_iter().collect();
    let differ = b.iter().filter(|(k, e)| a.get(k) != Some(e)).count();
    assert!(differ * 50 <= b.len(), "{differ} of {}", b.len());
}

#[test]
fn unconfigured_or_missing_sensors_do_nothing() {
    let mut g = ground_grid();
    let before: Vec<_> = g.observed().collect();
    let mut none = FrameLabels::new(FrameLabelConfig::default()).unwrap();
    assert_eq!(
        none.apply(&frame(), &mut g, None).unwrap(),
        FrameLabelsReport::default()
    );
    // SWIR configured, but the frame has no SWIR image: skipped and counted.
    let mut swir = FrameLabels::new(FrameLabelConfig {
        swir: Some(SwirConfig::default()),
        ..FrameLabelConfig::default()
    })
    .unwrap();
    let rep = swir.apply(&frame(), &mut g, None).unwrap();
    assert_eq!(rep.swir.unwrap().frames_skipped, 1);
    assert_eq!(g.observed().collect::<Vec<_>>(), before);
    // A colour image without CameraInfo, or whose CameraInfo gives another size: skipped
    // and counted, no vote, no error.
    let mut colour = FrameLabels::new(colour_cfg(4)).unwrap();
    for spoil in [
        (|f: &mut Frame| f.image.as_mut().unwrap().camera = None) as fn(&mut Frame),
        |f: &mut Frame| {
            let cam = f.image.as_mut().unwrap().camera.as_mut().unwrap();
            cam.width += 1;
        },
    ] {
        let mut f = frame();
        spoil(&mut f);
        let rep = colour.apply(&f, &mut g, None).unwrap();
        let st = rep.colour.unwrap();
        assert_eq!((st.frames, st.frames_skipped, st.cells_water), (0, 1, 0));
        assert_eq!(g.observed().collect::<Vec<_>>(), before);
    }
    assert!(FrameLabels::new(FrameLabelConfig {
        ray_stride: 0,
        ..FrameLabelConfig::default()
    })
    .is_err());
    let bad_hour = FrameLabelConfig {
        mwir: Some(MwirLabelConfig {
            classifier: MwirConfig::default(),
            hour: Some(25.0),
            longitude_deg: None,
        }),
        ..FrameLabelConfig::default()
    };
    assert!(FrameLabels::new(bad_hour).is_err());
}

#[test]
fn cached_horizon_equals_the_classifier_horizon() {
    let (cam, pose) = camera();
    let f = frame();
    let Pixels::Rgb8(px) = &f.image.as_ref().unwrap().image.pixels else {
        unreachable!()
    };
    let lut = ColorLut::compile(&RuleClassifier::default(), 8).unwrap();
    let mut a = LabelImage::filled(cam.width, cam.height, Label::Other);
    lut.classify_into(px.as_flattened(), &mut a.data).unwrap();
    let mut b = a.clone();
    Horizon::Camera {
        camera: cam.clone(),
        cam_to_map: pose,
    }
    .apply(&mut a, true)
    .unwrap();
    let rays: Vec<_> = RayCache::new(&cam)
        .rays
        .into_iter()
        .map(|r| r.map(|r| pose.rotation * r))
        .collect();
    apply_horizon(&mut b, &rays);
    assert_eq!(a, b);
    assert!(a.data.contains(&Label::Sky) && a.data.contains(&Label::Water));
    let g1 = GroundGeometry::level(&cam, &pose, 0.0).unwrap();
    let g2 = GroundGeometry::of_rays(&cam, &rays, &pose, 0.0);
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&g1.incidence), bits(&g2.incidence));
    assert_eq!(bits(&g1.range), bits(&g2.range));
    assert_eq!(bits(&g1.lookahead), bits(&g2.lookahead));
}

/// Sampled pixels on an `nr` × `nc` grid: hole-placed water (kinds 0 and 3: upper bound
/// `level`, lower bound `floor`), other water, or no hit.
fn hole_rows(nr: usize, nc: usize, cells: &[(u8, f64, f64)]) -> Vec<Option<Hit>> {
    (0..nr * nc)
        .map(|i| {
            let (r, c) = (i / nc, i % nc);
            let (kind, upper, floor) = cells[i];
            let p = Point3::new(c as f64, r as f64, upper);
            match kind {
                0 | 3 => Some(Hit {
                    floor: Some(floor),
                    ..Hit::at(p, true)
                }),
                1 => Some(Hit::at(p, true)),
                _ => None,
            }
        })
        .collect()
}

proptest::proptest! {
    /// Tightening gives each hole-placed pixel the lowest upper bound of its window, its
    /// own floor permitting, as a direct search of the window finds it: never higher than
    /// it was, never below its floor. Other pixels keep their level. When every pixel
    /// bounds one water level `l` (floor ≤ l ≤ upper), no level goes below `l`; otherwise
    /// (another hole's water in the window) a floor may bind. The hole-placed hits move
    /// along the ray from the camera, to the height of their new level.
    #[test]
    fn hole_levels_tighten_towards_the_level_all_bounds_admit(
        nr in 1usize..24,
        nc in 1usize..24,
        l in -2.0f64..2.0,
        one_level in proptest::bool::ANY,
        cells in proptest::collection::vec((0u8..4, 0.0f64..1.0, 0.0f64..1.0), 24 * 24),
        cam in (-5.0f64..5.0, -5.0f64..5.0, 3.5f64..10.0),
    ) {
        let cells: Vec<(u8, f64, f64)> = cells
            .iter()
            .map(|&(k, a, b)| (k, l + a, if one_level { l - b } else { l + a - b }))
            .collect();
        let before = hole_rows(nr, nc, &cells);
        let mut after = before.clone();
        let origin = Point3::new(cam.0, cam.1, cam.2);
        tighten_hole_levels(&mut after, nc, origin, &mut vec![7.0; 5]);
        let k = HOLE_LEVEL_WINDOW as i64;
        for r in 0..nr {
            for c in 0..nc {
                let (b, a) = (before[r * nc + c], after[r * nc + c]);
                let (Some(b), Some(a)) = (b, a) else {
                    proptest::prop_assert!(b.is_none() && a.is_none());
                    continue;
                };
                let Some(floor) = b.floor else {
                    proptest::prop_assert_eq!(a.level, b.level);
                    proptest::prop_assert_eq!(a.p, b.p);
                    continue;
                };
                let mut low = f64::INFINITY;
                for rr in (r as i64 - k).max(0)..(r as i64 + k + 1).min(nr as i64) {
                    for cc in (c as i64 - k).max(0)..(c as i64 + k + 1).min(nc as i64) {
                        if let Some(h) = before[rr as usize * nc + cc as usize].filter(|h| h.floor.is_some()) {
                            low = low.min(h.p.z);
                        }
                    }
                }
                proptest::prop_assert_eq!(a.level, low.max(floor));
                proptest::prop_assert!(a.level <= b.level && a.level >= floor);
                proptest::prop_assert!(!one_level || a.level >= l);
                // On the ray through the old hit, at the new level.
                let (u, v) = (b.p - origin, a.p - origin);
                proptest::prop_assert!((a.p.z - a.level).abs() <= 1e-9);
                proptest::prop_assert!(u.cross(&v).norm() <= 1e-9 * (1.0 + u.norm() * v.norm()));
                proptest::prop_assert!(u.dot(&v) > 0.0 && v.norm() >= u.norm() - 1e-12);
            }
        }
    }
}

/// The polygon left of `poly` (counter-clockwise square corners) after clipping it to the
/// side of the line through `a` and `b` where `c` lies (Sutherland–Hodgman; points on the
/// line are kept).
fn clip(poly: &[(f64, f64)], a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> Vec<(f64, f64)> {
    let side = |p: (f64, f64)| (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0);
    let s = side(c).signum();
    let mut out = Vec::new();
    for i in 0..poly.len() {
        let (p, q) = (poly[i], poly[(i + 1) % poly.len()]);
        let (sp, sq) = (s * side(p), s * side(q));
        if sp >= 0.0 {
            out.push(p);
        }
        if (sp > 0.0 && sq < 0.0) || (sp < 0.0 && sq > 0.0) {
            let t = sp / (sp - sq);
            out.push((p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1)));
        }
    }
    out
}

/// Whether the square cell [x0, x0 + r] × [y0, y0 + r] meets the triangle t (clipped
/// square non-empty, with a tolerance of `eps` on the triangle's edges).
fn cell_meets_triangle(x0: f64, y0: f64, r: f64, t: [(f64, f64); 3], eps: f64) -> bool {
    let area = (t[1].0 - t[0].0) * (t[2].1 - t[0].1) - (t[2].0 - t[0].0) * (t[1].1 - t[0].1);
    if area.abs() < 1e-12 {
        return false;
    }
    let mut poly = vec![
        (x0 - eps, y0 - eps),
        (x0 + r + eps, y0 - eps),
        (x0 + r + eps, y0 + r + eps),
        (x0 - eps, y0 + r + eps),
    ];
    for i in 0..3 {
        poly = clip(&poly, t[i], t[(i + 1) % 3], t[(i + 2) % 3]);
        if poly.is_empty() {
            return false;
        }
    }
    true
}

proptest::proptest! {
    /// A quad of pixel hits votes in exactly the cells it overlaps, each once, with the
    /// level interpolated linearly: against square–triangle clipping, for convex, folded
    /// and degenerate quads anywhere (far from the origin too) and clipped by the window's
    /// edge.
    #[test]
    fn a_quad_votes_once_in_every_cell_it_overlaps(
        ox in -1000i64..1000,
        oy in -1000i64..1000,
        corners in proptest::collection::vec((-0.5f64..4.5, -0.5f64..4.5), 4),
        plane in (-1.0f64..1.0, -1.0f64..1.0, -5.0f64..5.0),
    ) {
        let (res, n) = (0.1, 40usize);
        let origin = CellKey::new(ox, oy);
        let s = GridSurface::from_raster(n, res, origin, vec![0.0; n * n]).unwrap();
        let (x0, y0) = (ox as f64 * res, oy as f64 * res);
        let level = |x: f64, y: f64| plane.0 * (x - x0) + plane.1 * (y - y0) + plane.2;
        let q: Vec<Vector4<f64>> = corners
            .iter()
            .map(|&(u, v)| {
                let (x, y) = (x0 + u, y0 + v);
                Vector4::new(x, y, 0.0, level(x, y))
            })
            .collect();
        let q = [q[0], q[1], q[2], q[3]];
        let mut got: Vec<(usize, f64)> = Vec::new();
        quad_cells(&s, q, |j, l| got.push((j, l)));
        let mut seen = std::collections::HashSet::new();
        for &(j, l) in &got {
            proptest::prop_assert!(seen.insert(j), "cell {} twice", j);
            let (cx, cy) = (
                (ox + (j % n) as i64) as f64 * res + 0.5 * res,
                (oy + (j / n) as i64) as f64 * res + 0.5 * res,
            );
            proptest::prop_assert!((l - level(cx, cy)).abs() < 1e-6, "{} {}", l, level(cx, cy));
        }
        let xy = |k: usize| (q[k].x, q[k].y);
        let tris = [[xy(0), xy(1), xy(3)], [xy(0), xy(3), xy(2)]];
        for j in 0..n * n {
            let (cx0, cy0) = (
                (ox + (j % n) as i64) as f64 * res,
                (oy + (j / n) as i64) as f64 * res,
            );
            let inner = tris.iter().any(|&t| cell_meets_triangle(cx0, cy0, res, t, -1e-7));
            let outer = tris.iter().any(|&t| cell_meets_triangle(cx0, cy0, res, t, 1e-7));
            if inner {
                proptest::prop_assert!(seen.contains(&j), "cell {} overlapped but missed", j);
            }
            if seen.contains(&j) {
                proptest::prop_assert!(outer, "cell {} voted but not overlapped", j);
            }
        }
    }
}

/// [`quad_cells`] as first written, every cell tested against each triangle from scratch:
/// the reference the precomputed triangles must match bit for bit.
fn reference_quad_cells(
    surface: &GridSurface,
    q: [Vector4<f64>; 4],
    mut f: impl FnMut(usize, f64),
) {
    if !q.iter().all(|p| p.iter().all(|v| v.is_finite())) {
        return;
    }
    let [a, b, c, d] = q;
    let res = surface.resolution();
    let half = 0.5 * res;
    let (o, n) = (surface.origin(), surface.size() as i64);
    // Barycentric coordinates of the centre (x, y) in triangle t, if the cell overlaps it.
    let bary = |t: &[Vector4<f64>; 3], x: f64, y: f64| -> Option<[f64; 3]> {
        let [p0, p1, p2] = t;
        let det = (p1.x - p0.x) * (p2.y - p0.y) - (p2.x - p0.x) * (p1.y - p0.y);
        if det.abs() <= f64::EPSILON * res * res {
            return None;
        }
        let l1 = ((x - p0.x) * (p2.y - p0.y) - (p2.x - p0.x) * (y - p0.y)) / det;
        let l2 = ((p1.x - p0.x) * (y - p0.y) - (x - p0.x) * (p1.y - p0.y)) / det;
        let l = [1.0 - l1 - l2, l1, l2];
        // l[i]·|det| / |e| is the distance of the centre inside the edge e opposite vertex
        // i; the cell reaches (|e.x| + |e.y|)·half / |e| beyond its centre along that
        // edge's normal.
        let inside = (0..3).all(|i| {
            let e = t[(i + 1) % 3] - t[(i + 2) % 3];
            l[i] * det.abs() >= -half * (e.x.abs() + e.y.abs())
        });
        inside.then_some(l)
    };
    let tris = [[a, b, d], [a, d, c]];
    // Per triangle, the cells (global keys) that overlap its bounding box (their centres
    // (i + ½)·res within half a cell of it), clipped to the window: i0, i1, j0, j1.
    let ranges = tris.map(|t| {
        let lo = |v: fn(&Vector4<f64>) -> f64| t.iter().map(v).fold(f64::INFINITY, f64::min);
        let hi = |v: fn(&Vector4<f64>) -> f64| t.iter().map(v).fold(f64::NEG_INFINITY, f64::max);
        let first = |m: f64, origin: i64| (((m - half) / res - 0.5).ceil() as i64).max(origin);
        let last =
            |m: f64, origin: i64| (((m + half) / res - 0.5).floor() as i64).min(origin + n - 1);
        [
            first(lo(|p| p.x), o.x),
            last(hi(|p| p.x), o.x),
            first(lo(|p| p.y), o.y),
            last(hi(|p| p.y), o.y),
        ]
    });
    let overlap = |k: usize, i: i64, j: i64| {
        let [i0, i1, j0, j1] = ranges[k];
        let (x, y) = ((i as f64 + 0.5) * res, (j as f64 + 0.5) * res);
        (i0..=i1)
            .contains(&i)
            .then(|| (j0..=j1).contains(&j).then(|| bary(&tris[k], x, y)))
            .flatten()
            .flatten()
    };
    for (k, t) in tris.iter().enumerate() {
        let [i0, i1, j0, j1] = ranges[k];
        for j in j0..=j1 {
            for i in i0..=i1 {
                let Some(l) = overlap(k, i, j) else { continue };
                if k == 1 && overlap(0, i, j).is_some() {
                    continue;
                }
                let level = l[0] * t[0].w + l[1] * t[1].w + l[2] * t[2].w;
                f(((j - o.y) * n + (i - o.x)) as usize, level);
            }
        }
    }
}

proptest::proptest! {
    /// The cells, their order and their levels are exactly the reference's, for quads
    /// small and large against the cell, folded and degenerate ones, anywhere, clipped by
    /// the window's edge.
    #[test]
    fn quad_cells_match_reference(
        ox in -1000i64..1000,
        oy in -1000i64..1000,
        res in proptest::prop_oneof![proptest::strategy::Just(0.1), 0.02f64..0.5],
        scale in proptest::prop_oneof![0.001f64..0.05, 0.05f64..1.0, 1.0f64..8.0],
        centre in (-0.2f64..1.2, -0.2f64..1.2),
        corners in proptest::collection::vec((-1.0f64..1.0, -1.0f64..1.0, -2.0f64..2.0), 4),
        same in 0usize..6,
    ) {
        let n = 40usize;
        let origin = CellKey::new(ox, oy);
        let s = GridSurface::from_raster(n, res, origin, vec![0.0; n * n]).unwrap();
        let w = n as f64 * res;
        let (cx, cy) = (ox as f64 * res + centre.0 * w, oy as f64 * res + centre.1 * w);
        let mut q: Vec<Vector4<f64>> = corners
            .iter()
            .map(|&(u, v, l)| Vector4::new(cx + u * scale, cy + v * scale, 0.0, l))
            .collect();
        // Coincident corners: degenerate triangles.
        if same < 4 {
            q[(same + 1) % 4] = q[same];
        }
        let q = [q[0], q[1], q[2], q[3]];
        let (mut got, mut want) = (Vec::new(), Vec::new());
        quad_cells(&s, q, |j, l| got.push((j, l.to_bits())));
        reference_quad_cells(&s, q, |j, l| want.push((j, l.to_bits())));
        proptest::prop_assert_eq!(got, want);
    }
}

/// A quad that covers no cell centre still votes in the cells it touches, and a quad with a
/// non-finite corner votes nowhere (the caller puts the pixel's own vote in its cell).
#[test]
fn small_and_broken_quads() {
    let s = GridSurface::from_raster(10, 0.1, CellKey::new(0, 0), vec![0.0; 100]).unwrap();
    let v = |x: f64, y: f64| Vector4::new(x, y, 0.0, 1.0);
    let mut got = Vec::new();
    quad_cells(
        &s,
        [v(0.21, 0.31), v(0.23, 0.31), v(0.21, 0.33), v(0.23, 0.33)],
        |j, l| got.push((j, l)),
    );
    assert_eq!(got, vec![(32, 1.0)]);
    got.clear();
    quad_cells(
        &s,
        [
            v(0.21, 0.31),
            v(f64::NAN, 0.31),
            v(0.21, 0.33),
            v(0.23, 0.33),
        ],
        |j, l| got.push((j, l)),
    );
    assert!(got.is_empty());
}

proptest::proptest! {
    /// The rows `sampled_rows` keeps: every `stride`-th, and where rows are skipped, the
    /// ground between two kept rows that both see it is at most `stride` cells wide at the
    /// first, middle and last columns (each skipped row spans at most a cell). Found by
    /// casting each kept row's rays onto level ground directly, for a pinhole camera at any
    /// height, pitch and roll (upside down, the footprint grows down the image).
    #[test]
    fn wide_rows_are_all_kept(
        stride in 1usize..6,
        height in 0.3f64..4.0,
        pitch_deg in -5.0f64..60.0,
        roll_deg in -180.0f64..180.0,
        cell in 0.02f64..0.5,
    ) {
        let cam = CameraModel::new(80, 60, [60.0, 60.0, 39.5, 29.5], Distortion::None, "cam").unwrap();
        let pose = optical_pose(&pose_xyz_rpy(
            0.0,
            0.0,
            height,
            roll_deg.to_radians(),
            pitch_deg.to_radians(),
            0.0,
        ));
        let rays: Vec<_> = RayCache::new(&cam)
            .rays
            .into_iter()
            .map(|r| r.map(|r| pose.rotation * r))
            .collect();
        let rows = sampled_rows(&rays, cam.width, stride, height, cell);
        let on_ground = |x: usize, y: usize| {
            let r = cam.pixel_ray(x as f64, y as f64).map(|r| pose.rotation * r).unwrap();
            (r.z < 0.0).then(|| height / -r.z * r.xy().norm())
        };
        for y in (0..cam.height).step_by(stride) {
            proptest::prop_assert!(rows.contains(&y));
        }
        for w in rows.windows(2) {
            proptest::prop_assert!(w[1] > w[0] && w[1] - w[0] <= stride);
            for x in [0, cam.width / 2, cam.width - 1] {
                if let (Some(a), Some(b)) = (on_ground(x, w[0]), on_ground(x, w[1])) {
                    if w[1] - w[0] > 1 {
                        proptest::prop_assert!(
                            (a - b).abs() <= (w[1] - w[0]) as f64 * cell * (1.0 + 1e-9),
                            "rows {} and {} are {} m apart at column {x}", w[0], w[1], (a - b).abs()
                        );
                    }
                }
            }
        }
    }
}

/// A level camera 2 m up looking along +x (96 × 64, no distortion), its map rays, and an
/// image whose upper half is a sky of linear radiance `sky` and lower half `ground`,
/// labelled sky above the horizon and water below.
type ReflectionScene = (
    LabelImage,
    Vec<[u8; 3]>,
    Vec<Option<Vector3<f64>>>,
    CameraModel,
    Pose,
);

fn reflection_scene(
    sky: [f64; 3],
    ground: impl Fn(f64) -> [f64; 3],
    enc: Encoding,
) -> ReflectionScene {
    let cam = CameraModel::new(96, 64, [60.0, 60.0, 47.5, 31.5], Distortion::None, "cam").unwrap();
    let pose = optical_pose(&pose_xyz_rpy(0.0, 0.0, 2.0, 0.0, 0.0, 0.0));
    let rays: Vec<Option<Vector3<f64>>> = cam
        .pixel_rays()
        .into_iter()
        .map(|r| r.map(|r| pose.rotation * r))
        .collect();
    let code = |v: f64| {
        let v = v.clamp(0.0, 1.0);
        let t = enc.table();
        (0..256)
            .min_by(|&a, &b| (t[a] - v).abs().total_cmp(&(t[b] - v).abs()))
            .unwrap() as u8
    };
    let mut labels = LabelImage::filled(96, 64, Label::Other);
    let mut px = vec![[0u8; 3]; 96 * 64];
    for (i, r) in rays.iter().enumerate() {
        let d = r.unwrap();
        let c = if d.z >= 0.0 {
            labels.data[i] = Label::Sky;
            sky
        } else {
            labels.data[i] = Label::Water;
            // The incidence on level water.
            ground((-d.z / d.norm()).acos())
        };
        px[i] = c.map(code);
    }
    (labels, px, rays, cam, pose)
}

fn fresnel_r(theta: f64) -> f64 {
    let f = crate::optics::fresnel(theta.min(89.9f64.to_radians()), 1.33).unwrap();
    0.5 * (f.r_s + f.r_p)
}

/// Sky reflections pass the check at every incidence, in either encoding; sunlit grey
/// pavement, far brighter than the reflection at steep incidence, is vetoed; an image
/// without unsaturated sky, or without sky at all, is not checked; linear data read as
/// sRGB is vetoed no more than read as linear.
#[test]
fn the_reflection_check_knows_a_sky_reflection_from_pavement() {
    let sky = [0.55, 0.62, 0.75];
    for enc in [Encoding::Linear, Encoding::Srgb] {
        // Water: R(θ)·sky plus a dark body colour.
        let (mut l, px, rays, cam, pose) = reflection_scene(
            sky,
            |t| sky.map(|s| fresnel_r(t) * s + 0.03 * (1.0 - fresnel_r(t))),
            enc,
        );
        let water = l.data.iter().filter(|x| **x == Label::Water).count();
        assert!(water > 1000);
        assert_eq!(
            reflection_check(&mut l, &px, &rays, &cam, &pose, enc),
            0,
            "{enc:?}"
        );
        // Sunlit pavement: albedo 0.5 under a bright sun. Every pixel steeper than 80° of
        // incidence is vetoed; at grazing incidence water reflects enough of the sky to be
        // as bright, and some pass.
        let (mut l, px, rays, cam, pose) = reflection_scene(sky, |_| [0.48, 0.47, 0.44], enc);
        let v = reflection_check(&mut l, &px, &rays, &cam, &pose, enc);
        assert!(
            v as usize > water * 8 / 10,
            "{enc:?}: {v} of {water} vetoed"
        );
        for (i, x) in l.data.iter().enumerate() {
            let d = rays[i].unwrap();
            if (-d.z / d.norm()).acos() < 80f64.to_radians() {
                assert_ne!(*x, Label::Water, "{enc:?}: pixel {i}");
            }
        }
    }
    // Linear data read as sRGB: no more vetoes than read as linear.
    for ground in [[0.48, 0.47, 0.44], [0.3, 0.35, 0.4], [0.1, 0.1, 0.1]] {
        let (mut a, px, rays, cam, pose) = reflection_scene(sky, |_| ground, Encoding::Linear);
        let mut b = a.clone();
        let as_lin = reflection_check(&mut a, &px, &rays, &cam, &pose, Encoding::Linear);
        let as_srgb = reflection_check(&mut b, &px, &rays, &cam, &pose, Encoding::Srgb);
        assert!(as_srgb <= as_lin, "{ground:?}: {as_srgb} > {as_lin}");
    }
    // A saturated sky bounds nothing: bright water pixels under it stay.
    let (mut l, px, rays, cam, pose) =
        reflection_scene([1.2, 1.2, 1.2], |_| [0.9, 0.9, 0.9], Encoding::Linear);
    assert_eq!(
        reflection_check(&mut l, &px, &rays, &cam, &pose, Encoding::Linear),
        0
    );
    // No sky in the image: nothing to compare with.
    let (mut l, px, rays, cam, pose) = reflection_scene(sky, |_| [0.9, 0.9, 0.9], Encoding::Linear);
    for x in l.data.iter_mut().filter(|x| **x == Label::Sky) {
        *x = Label::Unknown;
    }
    assert_eq!(
        reflection_check(&mut l, &px, &rays, &cam, &pose, Encoding::Linear),
        0
    );
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]

    /// The check honours its model: whatever the sky's colour and the water's body colour
    /// (up to a fifth of the sky in each channel), in either encoding, no pixel of a level
    /// sky-reflecting surface is vetoed.
    #[test]
    fn no_sky_reflection_is_vetoed(
        s in proptest::array::uniform3(0.05f64..0.97),
        b in proptest::array::uniform3(0.0f64..0.2),
        srgb in proptest::bool::ANY,
    ) {
        let enc = if srgb { Encoding::Srgb } else { Encoding::Linear };
        let (mut l, px, rays, cam, pose) = reflection_scene(
            s,
            |t| {
                let r = fresnel_r(t);
                [0, 1, 2].map(|c| r * s[c] + (1.0 - r) * b[c] * s[c])
            },
            enc,
        );
        proptest::prop_assert_eq!(reflection_check(&mut l, &px, &rays, &cam, &pose, enc), 0);
    }
}

#[test]
fn encodings_decode_to_linear_radiance() {
    let (lin, srgb) = (Encoding::Linear.table(), Encoding::Srgb.table());
    assert_eq!((lin[0], lin[255], srgb[0], srgb[255]), (0.0, 1.0, 0.0, 1.0));
    assert!((srgb[128] - 0.2158605).abs() < 1e-6);
    assert!(srgb.windows(2).all(|w| w[1] > w[0]));
    assert!((1..255).all(|v| srgb[v] < lin[v]));
}

/// The pond is a hole 4–6 m ahead. A lidar whose dry ground returned to 8 m along every
/// azimuth makes it a hole where dry ground would have returned: its votes stand. One whose
/// ground stopped returning at 3 m explains the hole by range alone: no vote is placed there.
#[test]
fn holes_beyond_the_lidars_dry_reach_take_no_vote() {
    use crate::cues::DryReach;
    let lines = |far: f64| (0..720).map(move |b| (b as f64 * std::f64::consts::TAU / 720.0, far));
    let mut votes = Vec::new();
    for far in [8.0, 3.0] {
        let mut g = ground_grid();
        let mut fl = FrameLabels::new(colour_cfg(1)).unwrap();
        let lidar = ScanSurface {
            reach: Some(DryReach::new([0.0, 0.0], lines(far))),
            ..ScanSurface::default()
        };
        let st = fl
            .apply(&frame(), &mut g, Some(&lidar))
            .unwrap()
            .colour
            .unwrap();
        let pond_votes = g
            .observed()
            .filter(|(k, c)| {
                let (x, y) = g.centre_of(*k);
                pond(x, y) && c.ev.colour_water > 0
            })
            .count();
        votes.push((far, pond_votes, st.beyond_reach));
    }
    assert!(votes[0].1 > 50 && votes[0].2 == 0, "{votes:?}");
    assert!(votes[1].1 == 0 && votes[1].2 > 50, "{votes:?}");
}

/// A pale colour the paper's rule calls water, as concrete or a pale slab is.
const PALE: [u8; 3] = [200, 200, 190];

/// A `w × h` image pale on its left half and sky-coloured on its right.
fn pale_left_half(w: usize, h: usize) -> Vec<[u8; 3]> {
    (0..w * h)
        .map(|i| if i % w < w / 2 { PALE } else { SKY })
        .collect()
}

/// Where pixel `(u, v)` of `cam` at `pose` sees the level ground z = 0.
fn ground_seen(cam: &CameraModel, pose: &Pose, u: usize, v: usize) -> Point3<f64> {
    let r = pose.rotation * cam.pixel_ray(u as f64, v as f64).unwrap();
    let t = pose.translation.z / -r.z;
    Point3::from(pose.translation.vector + r * t)
}

#[test]
fn colour_check_vetoes_a_colour_the_lidar_finds_on_dry_ground() {
    let (cam, pose) = camera();
    let (w, h) = (cam.width, cam.height);
    let px = pale_left_half(w, h);
    let ground_at = |u: usize, v: usize| ground_seen(&cam, &pose, u, v);
    // Ground under pale pixels near the bottom of the image, and a point behind the
    // camera, which no pixel sees.
    let on_pale: Vec<Point3<f64>> = (0..6).map(|k| ground_at(5 + k, h - 5)).collect();
    let behind = Point3::new(-5.0, 0.0, 0.0);
    let run = |dry: usize, wet: usize| -> (u64, FalseAlarms, LabelImage) {
        let mut labels = LabelImage::filled(w, h, Label::Water);
        let mut check = ColourCheck::default();
        let mut d = on_pale[..dry].to_vec();
        d.push(behind);
        let lidar = ScanSurface {
            reach: None,
            dry: d,
            wet: on_pale[..wet].to_vec(),
            stereo: Vec::new(),
        };
        let (n, alarms) = check.run(&mut labels, &px, &cam, &pose, &lidar, None, 0.1);
        (n, alarms, labels)
    };
    // Three dry samples and none wet: the sign test cannot rule yet, and the cells they
    // lie in are false alarms (the sample behind the camera is none).
    let (n, alarms, _) = run(3, 0);
    assert_eq!(n, 0);
    assert!(
        alarms.samples >= 1 && alarms.water == alarms.samples,
        "{alarms:?}"
    );
    // Four: the pale colour is not water in this log, anywhere in the image; the sky's
    // colour, which the lidar never found on dry ground, still is. The vetoed pixels vote
    // nothing: no samples, no false alarms.
    let (n, alarms, labels) = run(4, 0);
    assert_eq!(alarms, FalseAlarms::default());
    assert_eq!(n as usize, w / 2 * h);
    for (i, l) in labels.data.iter().enumerate() {
        let want = if i % w < w / 2 {
            Label::Unknown
        } else {
            Label::Water
        };
        assert_eq!(*l, want, "pixel {i}");
    }
    // Found as often on water as on dry ground: the colour keeps its votes.
    assert_eq!(run(6, 6).0, 0);
}

/// A camera's false alarms are counted per map cell and frame, the fusion rule's event:
/// each cell holding dry samples in view is one sample, called water by the majority of its
/// samples' labelled pixels; a tie, or samples on sky or unknown pixels only, is none, and
/// a sample no pixel sees is none. The same count serves the colour and the SWIR labels.
#[test]
fn false_alarms_are_counted_per_cell_by_majority() {
    let (cam, pose) = camera();
    let (w, h) = (cam.width, cam.height);
    let ground_at = |u: usize, v: usize| ground_seen(&cam, &pose, u, v);
    // Labels: water in the bottom ten rows, sky in the top four, other between.
    let mut labels = LabelImage::filled(w, h, Label::Other);
    for (i, l) in labels.data.iter_mut().enumerate() {
        if i / w < 4 {
            *l = Label::Sky;
        } else if i / w >= h - 10 {
            *l = Label::Water;
        }
    }
    // On water and on other ground, in one column: on the same side of every axis.
    let (a, b) = (ground_at(5, h - 5), ground_at(5, h - 20));
    assert!(a.x * b.x > 0.0 && a.y * b.y > 0.0);
    // Cells of 100 m hold both points: one sample whose majority decides.
    let one_cell = |pts: Vec<Point3<f64>>| false_alarms_at(&labels, &cam, &pose, &pts, 100.0);
    let alarm = |water| FalseAlarms { samples: 1, water };
    assert_eq!(one_cell(vec![a, a, b]), alarm(1));
    assert_eq!(one_cell(vec![a, b, b]), alarm(0));
    assert_eq!(one_cell(vec![a, b]), FalseAlarms::default(), "a tie");
    assert_eq!(
        one_cell(vec![Point3::new(-5.0, 0.0, 0.0)]),
        FalseAlarms::default()
    );
    // Cells of 1 cm: each point its own cell (a and b lie far apart).
    let many = false_alarms_at(&labels, &cam, &pose, &[a, b, b], 0.01);
    assert_eq!(
        many,
        FalseAlarms {
            samples: 2,
            water: 1
        }
    );
    // A point on a sky pixel is labelled neither way.
    let r = pose.rotation * cam.pixel_ray(w as f64 / 4.0, 1.0).unwrap();
    let sky = Point3::from(pose.translation.vector + r * 10.0);
    let n = false_alarms_at(&labels, &cam, &pose, &[sky], 0.01);
    assert_eq!(n, FalseAlarms::default());
}

/// A lidar point counts only where the colour water around its pixel is unbroken: four dry
/// returns on the edge column of a strip of colour water (a puddle's rim) say nothing;
/// the same four a column inside it veto the colour.
#[test]
fn colour_check_ignores_lidar_points_on_the_waters_edge() {
    let (cam, pose) = camera();
    let (w, h) = (cam.width, cam.height);
    assert!(w / 2 > 20);
    let px = pale_left_half(w, h);
    let ground_at = |u: usize, v: usize| ground_seen(&cam, &pose, u, v);
    let strip = 10..20;
    let run = |u: usize| -> u64 {
        let mut labels = LabelImage::filled(w, h, Label::Other);
        for (i, l) in labels.data.iter_mut().enumerate() {
            if strip.contains(&(i % w)) {
                *l = Label::Water;
            }
        }
        let lidar = ScanSurface {
            dry: (0..4).map(|k| ground_at(u, h - 5 - 3 * k)).collect(),
            ..ScanSurface::default()
        };
        ColourCheck::default()
            .run(&mut labels, &px, &cam, &pose, &lidar, None, 0.1)
            .0
    };
    assert_eq!(run(strip.start), 0);
    assert_eq!(run(strip.end - 1), 0);
    assert_eq!(run(strip.start + 1) as usize, strip.len() * h);
}

/// A stereo cloud registered to the image at half its resolution: elements seen as ground
/// under pale pixels count as dry samples of that colour, elements not seen as ground
/// (reflections) as samples against it.
#[test]
fn colour_check_counts_stereo_verdicts_at_their_pixels() {
    let (cam, pose) = camera();
    let (w, h) = (cam.width, cam.height);
    let px = pale_left_half(w, h);
    let (rows, cols) = (h / 2, w / 2);
    let cloud = PointCloud::organized(rows, cols, vec![[f32::NAN; 3]; rows * cols]).unwrap();
    // The check of a fresh log over `labels` with the cloud's verdicts `surface`.
    let check = |labels: &mut LabelImage, surface: &ScanSurface| {
        ColourCheck::default().run(labels, &px, &cam, &pose, surface, Some((&cloud, 2)), 0.1)
    };
    let run = |ground: usize, not_ground: usize| -> u64 {
        let mut labels = LabelImage::filled(w, h, Label::Water);
        let mut stereo = vec![StereoSeen::Nothing; rows * cols];
        // Pale pixels are the left half: element columns below cols / 2.
        // Element (0, e) for e < cols / 2 lies under pale pixels.
        assert!(ground + not_ground <= cols / 2);
        for v in stereo.iter_mut().take(ground) {
            *v = StereoSeen::Ground;
        }
        for v in stereo.iter_mut().skip(ground).take(not_ground) {
            *v = StereoSeen::NotGround;
        }
        let surface = ScanSurface {
            stereo,
            ..ScanSurface::default()
        };
        check(&mut labels, &surface).0
    };
    assert_eq!(run(3, 0), 0);
    assert_eq!(run(4, 0) as usize, w / 2 * h);
    assert_eq!(run(6, 6), 0);
    // The same four ground verdicts on the water's edge (the pixel row below theirs is not
    // colour water) say nothing.
    let mut labels = LabelImage::filled(w, h, Label::Water);
    labels.data[w..2 * w].fill(Label::Other);
    let mut stereo = vec![StereoSeen::Nothing; rows * cols];
    stereo[..4].fill(StereoSeen::Ground);
    let surface = ScanSurface {
        stereo,
        ..ScanSurface::default()
    };
    let (n, alarms) = check(&mut labels, &surface);
    assert_eq!(n, 0);
    // Stereo verdicts are no samples of the false-alarm rate.
    assert_eq!(alarms, FalseAlarms::default());
    // Verdicts for a cloud of another size are not read.
    let mut labels = LabelImage::filled(w, h, Label::Water);
    let surface = ScanSurface {
        stereo: vec![StereoSeen::Ground; 10],
        ..ScanSurface::default()
    };
    let (n, alarms) = check(&mut labels, &surface);
    assert_eq!((n, alarms), (0, FalseAlarms::default()));
}

/// Where both cameras vote on a cell, a water vote stands only where the other agrees; a
/// vote against water always stands; a cell only one camera saw keeps its vote.
#[test]
fn cross_check_keeps_water_only_where_both_agree() {
    let v = |cell: u32, water: bool| CellVote {
        cell,
        water,
        level: 0.0,
    };
    // Cells: 1 both water, 2 colour water / SWIR dry (a pale slab), 3 colour dry / SWIR
    // water (asphalt), 4 both dry, 5 colour only, 6 SWIR only.
    let mut colour = vec![v(1, true), v(2, true), v(3, false), v(4, false), v(5, true)];
    let mut swir = vec![v(1, true), v(2, false), v(3, true), v(4, false), v(6, true)];
    let (c, s) = cross_check(&mut colour, &mut swir);
    assert_eq!((c, s), (1, 1));
    assert_eq!(
        colour,
        vec![v(1, true), v(3, false), v(4, false), v(5, true)]
    );
    assert_eq!(swir, vec![v(1, true), v(2, false), v(4, false), v(6, true)]);
}

/// The point-by-point check: colour water the SWIR camera calls other (brighter than any
/// reflection) votes dry; SWIR water the colour camera calls other (not sky-coloured, which
/// water mirroring a bank is too) loses its vote; where the other camera says unknown the
/// pixel keeps its label.
#[test]
fn seen_check_turns_colour_water_dry_and_drops_swir_water() {
    let cam = CameraModel::new(8, 8, [8.0, 8.0, 3.5, 3.5], Distortion::None, "c").unwrap();
    let pose = optical_pose(&pose_xyz_rpy(0.0, 0.0, 1.5, 0.0, 0.6, 0.0));
    let mut labels = LabelImage::filled(8, 8, Label::Other);
    // The point straight ahead on the optical axis, 3 m out.
    let p = pose * Point3::new(0.0, 0.0, 3.0);
    let seen: Seen = (labels.clone(), cam.clone(), pose);
    let hit = || Some(Hit::at(p, true));
    let mut hits = vec![hit(), Some(Hit::at(p, false)), None];
    assert_eq!(seen_check(&mut hits, &seen, true), 1);
    assert!(hits[0].as_ref().is_some_and(|h| !h.wet));
    assert!(hits[1].as_ref().is_some_and(|h| !h.wet) && hits[2].is_none());
    let mut hits = vec![hit()];
    assert_eq!(seen_check(&mut hits, &seen, false), 1);
    assert!(hits[0].is_none());
    // The other camera cannot tell there: the water pixel keeps its vote either way.
    labels.data.fill(Label::Unknown);
    let seen: Seen = (labels, cam, pose);
    for dry in [true, false] {
        let mut hits = vec![hit()];
        assert_eq!(seen_check(&mut hits, &seen, dry), 0);
        assert!(hits[0].as_ref().is_some_and(|h| h.wet));
    }
}

/// The SWIR camera checks the colour labels as the lidar does: colour water placed where
/// SWIR sees brighter than any reflection is a dry sample of its colour, where SWIR sees a
/// sky reflection a wet one; a colour found dry four times and never wet is vetoed in the
/// whole image (the next frame's), as far as either camera sees.
#[test]
fn swir_verdicts_at_placed_colour_water_veto_its_colour() {
    let (cam, pose) = camera();
    let (w, h) = (cam.width, cam.height);
    let px = pale_left_half(w, h);
    let ground_at = |u: usize, v: usize| ground_seen(&cam, &pose, u, v);
    let labels = LabelImage::filled(w, h, Label::Water);
    // Sampled pixels on the pale half, one row; each placed on the ground it sees.
    let (rows, cols) = (vec![h - 5], (5..11).collect::<Vec<_>>());
    let hits: Vec<Option<Hit>> = cols
        .iter()
        .map(|&x| Some(Hit::at(ground_at(x, h - 5), true)))
        .collect();
    let run = |swir: Label, n: usize, wet_too: usize| -> LabelImage {
        let mut check = ColourCheck::default();
        let seen: Seen = (LabelImage::filled(w, h, swir), cam.clone(), pose);
        check.count_swir(&labels, &px, &hits[..n], (&rows, &cols), &seen);
        if wet_too > 0 {
            let wet: Seen = (LabelImage::filled(w, h, Label::Water), cam.clone(), pose);
            check.count_swir(&labels, &px, &hits[..wet_too], (&rows, &cols), &wet);
        }
        let mut out = labels.clone();
        check.veto(&mut out, &px);
        out
    };
    let vetoed = |l: &LabelImage| l.data.iter().filter(|&&l| l == Label::Unknown).count();
    assert_eq!(
        vetoed(&run(Label::Other, 3, 0)),
        0,
        "three samples cannot rule"
    );
    let l = run(Label::Other, 4, 0);
    assert_eq!(vetoed(&l), w / 2 * h);
    assert!((0..w * h).all(|i| (l.data[i] == Label::Unknown) == (i % w < w / 2)));
    // Seen as often a sky reflection, or unknown to SWIR: the colour keeps its votes.
    assert_eq!(vetoed(&run(Label::Other, 6, 6)), 0);
    assert_eq!(vetoed(&run(Label::Unknown, 6, 0)), 0);
    // Colour other, or placed nowhere, is no sample.
    let mut check = ColourCheck::default();
    let seen: Seen = (LabelImage::filled(w, h, Label::Other), cam.clone(), pose);
    let dry: Vec<Option<Hit>> = hits
        .iter()
        .map(|h| h.map(|h| Hit { wet: false, ..h }))
        .collect();
    check.count_swir(&labels, &px, &dry, (&rows, &cols), &seen);
    check.count_swir(&labels, &px, &[None; 6], (&rows, &cols), &seen);
    let mut out = labels.clone();
    assert_eq!(check.veto(&mut out, &px), 0);
}
