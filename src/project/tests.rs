use super::*;
use crate::classify::horizon::tests::cam_pose;
use crate::geom::Distortion;
use crate::grid::{GridConfig, RangeNoise};
use proptest::prelude::*;

const RES: f64 = 0.1;

/// A 20 m × 20 m grid around (5, 0) with ground z = f(x, y) sampled at every cell centre
/// (skipping cells where f is None).
fn grid(f: impl Fn(f64, f64) -> Option<f64>) -> RollingGrid {
    let cfg = GridConfig {
        resolution: RES,
        size_cells: 200,
        ..Default::default()
    };
    let mut g = RollingGrid::new(cfg, 5.0, 0.0).unwrap();
    let mut xyz = Vec::new();
    for i in -50..150 {
        for j in -100..100 {
            let (x, y) = ((i as f64 + 0.5) * RES, (j as f64 + 0.5) * RES);
            if let Some(z) = f(x, y) {
                xyz.push([x as f32, y as f32, z as f32]);
            }
        }
    }
    let mut c = PointCloud::unorganized(xyz);
    c.sensor_origin = Point3::new(0.0, 0.0, 10.0);
    g.ingest(&c, &RangeNoise::constant(0.01)).unwrap();
    g
}

fn camera(d: Distortion) -> CameraModel {
    CameraModel::new(64, 48, [40.0, 40.0, 31.5, 23.5], d, "cam").unwrap()
}

#[test]
fn rays_on_flat_ground_hit_where_the_plane_says() {
    let g = grid(|_, _| Some(0.0));
    let s = ElevationSurface::from_grid(&g).unwrap();
    let cam = camera(Distortion::PlumbBob([-0.1, 0.01, 0.001, 0.0, 0.0]));
    let pose = cam_pose(1.5, 0.35);
    let p = Projector::new(cam.clone(), ProjectConfig::default()).unwrap();
    let origin = Point3::from(pose.translation.vector);
    let mut checked = 0;
    for (i, r) in p.rays.iter().enumerate() {
        let Some(r) = r else { continue };
        let d = pose.rotation * r;
        if d.z >= -0.05 {
            continue;
        }
        let t_plane = 1.5 / -d.z;
        let hit = origin + d * t_plane;
        if !(0.5..14.0).contains(&hit.x) || hit.y.abs() > 9.0 {
            continue;
        }
        let t = s
            .cast(&origin, &d, 100.0)
            .unwrap_or_else(|| panic!("pixel {i} missed"));
        assert!(
            (t - t_plane).abs() < 1e-3 * t_plane.max(1.0),
            "pixel {i}: {t} vs {t_plane}"
        );
        checked += 1;
    }
    assert!(checked > 1000, "{checked}");
    // Whole image: every vote lands in the grid and water votes equal pixels that hit.
    let labels = LabelImage::filled(64, 48, Label::Water);
    let (v, st) = p
        .project(&labels, &pose, None, Some(&RayTarget::Terrain(&s)), RES)
        .unwrap();
    let total: u64 = v.to_sorted_vec().iter().map(|(_, c)| c[1] as u64).sum();
    assert_eq!(total, st.via_ray);
    assert_eq!(st.via_ray + st.no_hit, 64 * 48);
    assert!(st.via_ray > 1000);
}

#[test]
fn ridge_occludes_the_cells_behind_it() {
    // A 1 m ridge at 4.0 ≤ x < 4.4; camera 1 m up: the ground from the ridge to well beyond
    // it is hidden (the ray over the ridge top falls to z = 0 at x = 4.4 · 1/(1 − 1) → never
    // from a 1 m high camera: everything behind is hidden up to the grid's end).
    let g = grid(|x, _| Some(if (4.0..4.4).contains(&x) { 1.0 } else { 0.0 }));
    let s = ElevationSurface::from_grid(&g).unwrap();
    let p = Projector::new(camera(Distortion::None), ProjectConfig::default()).unwrap();
    let labels = LabelImage::filled(64, 48, Label::Water);
    let (v, st) = p
        .project(
            &labels,
            &cam_pose(0.95, 0.3),
            None,
            Some(&RayTarget::Terrain(&s)),
            RES,
        )
        .unwrap();
    assert!(st.via_ray > 0);
    let mut front = 0;
    for (k, _) in v.to_sorted_vec() {
        let (x, _) = crate::grid::centre_of(RES, k);
        assert!(x < 4.5, "hidden cell {k:?} at x = {x} got a vote");
        front += (x < 3.9) as usize;
    }
    assert!(front > 50, "{front}");
    // Without the ridge the same camera sees cells beyond 4.5 m.
    let flat = ElevationSurface::from_grid(&grid(|_, _| Some(0.0))).unwrap();
    let (v2, _) = p
        .project(
            &labels,
            &cam_pose(0.95, 0.3),
            None,
            Some(&RayTarget::Terrain(&flat)),
            RES,
        )
        .unwrap();
    assert!(v2
        .to_sorted_vec()
        .iter()
        .any(|(k, _)| crate::grid::centre_of(RES, *k).0 > 4.5));
}

#[test]
fn holes_are_never_hit() {
    // Nothing observed for 3 ≤ x < 5.
    let g = grid(|x, _| (!(3.0..5.0).contains(&x)).then_some(0.0));
    let s = ElevationSurface::from_grid(&g).unwrap();
    let p = Projector::new(camera(Distortion::None), ProjectConfig::default()).unwrap();
    let labels = LabelImage::filled(64, 48, Label::Other);
    let (v, _) = p
        .project(
            &labels,
            &cam_pose(1.5, 0.3),
            None,
            Some(&RayTarget::Terrain(&s)),
            RES,
        )
        .unwrap();
    let mut near = 0;
    for (k, _) in v.to_sorted_vec() {
        let (x, _) = crate::grid::centre_of(RES, k);
        assert!(
            !(2.95..5.05).contains(&x),
            "cell {k:?} in the hole got a vote"
        );
        near += (x < 2.9) as usize;
    }
    assert!(near > 50);
    // An empty grid is refused.
    assert!(ElevationSurface::from_grid(&grid(|_, _| None)).is_err());
}

#[test]
fn water_level_and_stereo_paths() {
    let cam = camera(Distortion::Equidistant([0.01, 0.0, 0.0, 0.0]));
    let pose = cam_pose(2.0, 0.4);
    let p = Projector::new(cam.clone(), ProjectConfig::default()).unwrap();
    let labels = LabelImage::filled(64, 48, Label::Water);
    // Water level 0.5 m: the hit of the centre pixel.
    let (v, st) = p
        .project(&labels, &pose, None, Some(&RayTarget::WaterLevel(0.5)), RES)
        .unwrap();
    let d = pose.rotation * cam.pixel_ray(32.0, 40.0).unwrap();
    let hit = Point3::from(pose.translation.vector) + d * (1.5 / -d.z);
    assert!(v.get(key_of(RES, hit.x, hit.y)).is_some_and(|c| c[1] > 0));
    assert!(st.via_ray > 0 && st.via_point == 0);

    // Stereo at half resolution: 32 × 24 points, one valid at element (10, 5) 3 m ahead.
    let mut xyz = vec![[f32::NAN; 3]; 32 * 24];
    xyz[10 * 32 + 5] = [0.23, 0.47, 3.04];
    let cloud = PointCloud::organized(24, 32, xyz).unwrap();
    let (v, st) = p.project(&labels, &pose, Some(&cloud), None, RES).unwrap();
    assert_eq!(st.via_point, 4, "a 2 × 2 block of pixels");
    let q = pose * Point3::new(0.23f32 as f64, 0.47f32 as f64, 3.04f32 as f64);
    assert_eq!(v.get(key_of(RES, q.x, q.y)), Some(&[0, 4, 0, 0]));
    assert_eq!(v.len(), 1);
    // Wrong stereo size is refused.
    let bad = PointCloud::organized(5, 7, vec![[0.0; 3]; 35]).unwrap();
    assert!(p.project(&labels, &pose, Some(&bad), None, RES).is_err());
}

#[test]
fn projection_is_thread_independent() {
    let g = grid(|x, y| Some(0.1 * (x * 0.7).sin() + 0.05 * y));
    let s = ElevationSurface::from_grid(&g).unwrap();
    let p = Projector::new(camera(Distortion::None), ProjectConfig::default()).unwrap();
    let mut labels = LabelImage::filled(64, 48, Label::Other);
    for (i, l) in labels.data.iter_mut().enumerate() {
        if i % 7 < 3 {
            *l = Label::Water;
        }
    }
    let run = |t| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap()
            .install(|| {
                p.project(
                    &labels,
                    &cam_pose(1.5, 0.3),
                    None,
                    Some(&RayTarget::Terrain(&s)),
                    RES,
                )
                .unwrap()
            })
    };
    let (a, sa) = run(1);
    let (b, sb) = run(3);
    assert_eq!(a.to_sorted_vec(), b.to_sorted_vec());
    assert_eq!(sa, sb);
}

fn votes_strategy() -> impl Strategy<Value = Vec<(i64, i64, u8)>> {
    proptest::collection::vec((-5i64..5, -5i64..5, 0u8..5), 0..40)
}

fn build(v: &[(i64, i64, u8)]) -> LabelVotes {
    let mut m = LabelVotes::new(RES).unwrap();
    for &(x, y, l) in v {
        m.add(
            CellKey::new(x, y),
            if l == 4 {
                Label::Unknown
            } else {
                Label::DECIDED[l as usize]
            },
        );
    }
    m
}

proptest! {
    #[test]
    fn merge_is_commutative_and_associative(a in votes_strategy(), b in votes_strategy(), c in votes_strategy()) {
        let (ma, mb, mc) = (build(&a), build(&b), build(&c));
        let mut ab = ma.clone(); ab.merge(&mb).unwrap();
        let mut ba = mb.clone(); ba.merge(&ma).unwrap();
        prop_assert_eq!(ab.to_sorted_vec(), ba.to_sorted_vec());
        let mut ab_c = ab.clone(); ab_c.merge(&mc).unwrap();
        let mut bc = mb.clone(); bc.merge(&mc).unwrap();
        let mut a_bc = ma.clone(); a_bc.merge(&bc).unwrap();
        prop_assert_eq!(ab_c.to_sorted_vec(), a_bc.to_sorted_vec());
        // Merging equals adding everything to one map.
        let all: Vec<_> = a.iter().chain(&b).chain(&c).copied().collect();
        prop_assert_eq!(build(&all).to_sorted_vec(), ab_c.to_sorted_vec());
    }
}

#[test]
fn merge_refuses_other_resolution() {
    let mut a = LabelVotes::new(0.1).unwrap();
    assert!(a.merge(&LabelVotes::new(0.2).unwrap()).is_err());
    assert!(LabelVotes::new(0.0).is_err());
    a.add(CellKey::new(0, 0), Label::Water);
    a.add(CellKey::new(0, 0), Label::Water);
    a.add(CellKey::new(0, 0), Label::Other);
    assert_eq!(a.majority(CellKey::new(0, 0)), Some(Label::Water));
}
