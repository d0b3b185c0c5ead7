//! Tests of the simulator: scene parsing, renderer geometry against analytic answers, the
//! optics of bottom returns, determinism, logs read back, truth scored against itself.

use nalgebra::{Point3, Vector3};

use super::*;
use crate::hazard::Class;
use crate::optics::{
    apparent_bottom_point, Attenuation, LidarModelConfig, LidarWaterModel, Sensitivity,
    SolidAngleForm,
};

/// A small flat scene: a flat-bottomed pond (depth `depth` under level −0.2) 15 m ahead, a
/// building beyond it; lidar at 1.5 m, a small stereo camera.
fn scene_text(depth: f64, extra: &str) -> String {
    format!(
        r#"
name = "test"
seed = 7
[terrain]
origin = [-5.0, -30.0]
size = [40.0, 60.0]
resolution = 0.5
material = "soil"
[[terrain.features]]
kind = "depression"
centre = [12.0, 0.0]
radius = [8.0, 8.0]
depth = {d}
flat = 0.75
[[water]]
kind = "level"
level = -0.2
centre = [12.0, 0.0]
radius = 9.0
attenuation = 7.9
[[objects]]
kind = "building"
position = [30.0, 0.0]
size = [3.0, 8.0, 6.0]
[trajectory]
waypoints = [[0.0, 0.0], [2.0, 0.0]]
speed = 2.0
rate_hz = 5.0
frames = 2
[rig.lidar]
position = [0.0, 0.0, 1.5]
rings = 16
elevation_deg = [-20.0, 2.0]
columns = 64
azimuth_deg = [-30.0, 30.0]
dry_limit_m = 25.0
[rig.stereo]
position = [0.0, 0.0, 1.5]
rpy_deg = [0.0, 8.0, 0.0]
width = 64
height = 48
hfov_deg = 60.0
baseline_m = 0.12
{extra}
"#,
        d = depth + 0.0,
    )
}

fn world(depth: f64) -> World {
    World::build(&Scene::from_toml_str(&scene_text(depth, "")).unwrap()).unwrap()
}

#[test]
fn every_shipped_scene_parses_and_builds() {
    let dir = concat!(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."), "/maps");
    let mut n = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            let s = Scene::load(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            World::build(&s).unwrap();
            n += 1;
        }
    }
    assert!(n >= 1);
}

fn bad(extra_replace: (&str, &str)) -> String {
    let t = scene_text(0.5, "").replacen(extra_replace.0, extra_replace.1, 1);
    match Scene::from_toml_str(&t) {
        Ok(_) => panic!("accepted {extra_replace:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_scenes_name_the_key() {
    let cases: &[((&str, &str), &str)] = &[
        (
            ("seed = 7", "seed = 7\ncolour = 3"),
            "unknown field `colour`",
        ),
        (
            ("resolution = 0.5", "resolution = -0.5"),
            "terrain.resolution",
        ),
        (
            ("resolution = 0.5", "resolution = 0.0001"),
            "terrain.resolution",
        ),
        (
            ("material = \"soil\"", "material = \"cheese\""),
            "unknown material \"cheese\"",
        ),
        (("level = -0.2\n", ""), "water[0].level"),
        (("radius = 9.0", "radius = 0.0"), "water[0].radius"),
        (
            ("attenuation = 7.9", "attenuation = -1.0"),
            "water[0].attenuation",
        ),
        (
            ("kind = \"level\"", "kind = \"lake\""),
            "unknown variant `lake`",
        ),
        (("flat = 0.75", "flat = 1.5"), "terrain.features[0].flat"),
        (("depth = 0.5", "depth = -0.5"), "terrain.features[0].depth"),
        (
            ("size = [3.0, 8.0, 6.0]", "size = [3.0, 0.0, 6.0]"),
            "objects[0].size[1]",
        ),
        (("[2.0, 0.0]]", "[100.0, 0.0]]"), "trajectory.waypoints[1]"),
        (("speed = 2.0", "speed = 0.0"), "trajectory.speed"),
        (("rings = 16", "rings = 0"), "rig.lidar.rings"),
        (
            (
                "elevation_deg = [-20.0, 2.0]",
                "elevation_deg = [2.0, -20.0]",
            ),
            "rig.lidar.elevation_deg",
        ),
        (
            ("dry_limit_m = 25.0", "dry_limit_m = nan"),
            "rig.lidar.dry_limit_m",
        ),
        (("width = 64", "width = 63"), "rig.stereo.bin"),
        (
            ("hfov_deg = 60.0", "hfov_deg = 180.0"),
            "rig.stereo.hfov_deg",
        ),
        (
            ("baseline_m = 0.12", "baseline_m = 0.0"),
            "rig.stereo.baseline_m",
        ),
        (("name = \"test\"", "name = \"\""), "name"),
    ];
    for (rep, want) in cases {
        let e = bad(*rep);
        assert!(
            e.contains(want),
            "{rep:?}: error {e:?} does not mention {want:?}"
        );
    }
    // A rig without sensors.
    let t = scene_text(0.5, "")
        .split("[rig.lidar]")
        .next()
        .unwrap()
        .to_string();
    let e = Scene::from_toml_str(&t).unwrap_err().to_string();
    assert!(e.contains("rig"), "{e}");
}

#[test]
fn load_reports_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.toml");
    std::fs::write(
        &p,
        scene_text(0.5, "").replacen("rings = 16", "rings = \"many\"", 1),
    )
    .unwrap();
    let e = Scene::load(&p).unwrap_err().to_string();
    assert!(e.contains("s.toml") && e.contains("line"), "{e}");
}

#[test]
fn the_ground_goes_on_past_the_terrain_edge() {
    let w = world(0.5);
    // The terrain spans x −5..35 and y −30..30. Rays from 1.5 m that meet the ground 20 m
    // past the x = −5 edge, 7 m past the y = −30 edge, and past the (−5, −30) corner (the
    // corner's own triangles) hit the edge height carried outward, as terrain.
    for (o, to) in [
        ([0.0, 0.0], [-25.0, 0.0]),
        ([0.0, -25.0], [0.0, -37.0]),
        ([0.0, -25.0], [-12.0, -37.0]),
        ([0.0, 0.0], [-400.0, 7.0]),
    ] {
        let z = w.terrain.height(to[0], to[1]);
        let o = Point3::new(o[0], o[1], w.terrain.height(o[0], o[1]) + 1.5);
        let target = Point3::new(to[0], to[1], z);
        let d = (target - o).normalize();
        let h = w
            .cast_solid(&o, &d, 2000.0)
            .unwrap_or_else(|| panic!("{to:?}: no hit"));
        assert!(
            matches!(h.surface, Surface::Solid { tri } if w.is_terrain(tri)),
            "{to:?}"
        );
        assert!(
            (h.point - target).norm() < 0.02 * (target - o).norm(),
            "{to:?}: {:?}",
            h.point
        );
        assert!(
            (h.point.z - z).abs() < 1e-3,
            "{to:?}: z {} vs {z}",
            h.point.z
        );
        assert!(w.water_at(h.point.x, h.point.y).is_none());
    }
}

#[test]
fn flat_ground_range_is_height_over_sine_of_elevation() {
    let w = world(0.5);
    let l = Lidar::new(w.scene.rig.lidar.as_ref().unwrap()).unwrap();
    let h = 1.5;
    let o = Point3::new(0.0, 0.0, h);
    // Beams towards −y (away from the pond) at several depression angles.
    for deg in [5.0f64, 8.0, 12.0, 20.0, 35.0, 60.0, 89.0] {
        let e = deg.to_radians();
        let d = Vector3::new(0.0, -e.cos(), -e.sin());
        match l.trace(&w, &o, &d).unwrap() {
            LidarReturn::Solid { point, .. } => {
                let r = (point - o).norm();
                assert!(
                    (r - h / e.sin()).abs() < 2e-4,
                    "{deg}°: {r} vs {}",
                    h / e.sin()
                );
            }
            other => panic!("{deg}°: {other:?}"),
        }
    }
    // Beyond the dry-ground limit nothing returns: 25 m lookahead for albedo 0.3 from 1.5 m;
    // soil's lidar albedo is 0.30 too, so a beam meeting the ground at 30 m is lost.
    let e = (h / 30.0f64).atan();
    let d = Vector3::new(0.0, -e.cos(), -e.sin());
    assert_eq!(l.trace(&w, &o, &d).unwrap(), LidarReturn::None);
    let e = (h / 20.0f64).atan();
    let d = Vector3::new(0.0, -e.cos(), -e.sin());
    assert!(matches!(
        l.trace(&w, &o, &d).unwrap(),
        LidarReturn::Solid { .. }
    ));
}

fn model(w: &World, l: &Lidar, height: f64, depth_albedo: f64) -> LidarWaterModel {
    LidarWaterModel::new(LidarModelConfig {
        height_m: height,
        attenuation: Attenuation::PerMetre(w.water[0].attenuation),
        albedo: depth_albedo,
        aperture_diameter_m: l.spec.aperture_m,
        n_water: N_WATER,
        sensitivity: Sensitivity::MinPowerRatio(l.min_power_ratio),
        solid_angle: SolidAngleForm::Exact,
    })
    .unwrap()
}

#[test]
fn bottom_returns_exactly_where_the_optics_model_says() {
    // Water 5 and 10 cm deep (surface at −0.2): murky water (7.9 /m) returns a bottom only
    // so far.
    for depth in [0.25, 0.3] {
        let w = world(depth);
        let l = Lidar::new(w.scene.rig.lidar.as_ref().unwrap()).unwrap();
        let o = Point3::new(0.0, 0.0, 1.5);
        let level = -0.2;
        let d_true = depth - 0.2; // bottom at −depth, surface at −0.2
        let m = model(
            &w,
            &l,
            o.z - level,
            w.materials[w.material("soil").unwrap()].spec.lidar,
        );
        let limit = m
            .max_lookahead_for_depth(d_true)
            .unwrap()
            .expect("some lookahead returns");
        let (mut bottoms, mut last_bottom, mut misses) = (0, 0.0f64, 0);
        // Beams meeting the water between 9 and 21 m ahead: the flat bottom spans 9..21 m.
        for k in 0..400 {
            let look = 6.5 + 11.0 * k as f64 / 399.0;
            let e = ((o.z - level) / look).atan();
            let d = Vector3::new(e.cos(), 0.0, -e.sin());
            let r = l.trace(&w, &o, &d).unwrap();
            let expect = m.return_ratio(look, d_true).unwrap() >= l.min_power_ratio;
            match r {
                LidarReturn::Bottom {
                    point,
                    bottom,
                    lookahead,
                    depth: dd,
                    ..
                } => {
                    assert!(
                        expect,
                        "bottom return at {look} m where the model says none (limit {limit})"
                    );
                    assert!((lookahead - look).abs() < 1e-6);
                    assert!((dd - d_true).abs() < 1e-4, "depth {dd} vs {d_true}");
                    let want = apparent_bottom_point(o, bottom, level, N_WATER).unwrap();
                    assert!((point - want).norm() < 1e-9);
                    // The uncorrected point lies on the original beam, deeper than the bottom.
                    let along = (point - o).normalize();
                    assert!((along - d).norm() < 1e-4, "{along:?} vs {d:?}");
                    bottoms += 1;
                    last_bottom = last_bottom.max(look);
                }
                other => {
                    assert!(!expect, "no bottom return ({other:?}) at {look} m where the model says one (limit {limit})");
                    misses += 1;
                }
            }
        }
        assert!(
            bottoms > 0 && misses > 0,
            "depth {depth}: {bottoms} bottoms, {misses} misses, limit {limit}"
        );
        assert!(
            (last_bottom - limit).abs() < 11.0 / 399.0 + 1e-9,
            "last bottom {last_bottom} vs limit {limit}"
        );
    }
}

#[test]
fn water_clearer_than_pure_water_is_refused() {
    let t = scene_text(1.5, "").replacen("attenuation = 7.9", "attenuation = 1.0", 1);
    let e = World::build(&Scene::from_toml_str(&t).unwrap())
        .err()
        .expect("refused")
        .to_string();
    assert!(
        e.contains("water[0].attenuation") && e.contains("no water is clearer"),
        "{e}"
    );
    let t = scene_text(1.5, "").replacen("attenuation = 7.9\n", "", 1);
    let w = World::build(&Scene::from_toml_str(&t).unwrap()).unwrap();
    let nm = w.scene.rig.lidar.as_ref().unwrap().wavelength_nm;
    let pure = crate::optics::absorption_per_m(nm).unwrap();
    assert_eq!(w.water[0].attenuation, pure);
}

#[test]
fn specular_bounce_lands_on_the_original_ray_at_the_total_path() {
    // Deep murky water: no bottom return; the beam bounces off the pond to the building.
    let t = scene_text(1.5, "").replacen("attenuation = 7.9", "attenuation = 20.0", 1);
    let w = World::build(&Scene::from_toml_str(&t).unwrap()).unwrap();
    let l = Lidar::new(w.scene.rig.lidar.as_ref().unwrap()).unwrap();
    let o = Point3::new(0.0, 0.0, 1.5);
    let e = (1.7f64 / 12.0).atan();
    let d = Vector3::new(e.cos(), 0.0, -e.sin());
    match l.trace(&w, &o, &d).unwrap() {
        LidarReturn::Specular { point, .. } => {
            // Mirror the point about the water level: it lies on the building face x = 28.5.
            let mirrored = Point3::new(point.x, point.y, 2.0 * -0.2 - point.z);
            let real_dir = Vector3::new(d.x, d.y, -d.z);
            let s = w.cast_water(&o, &d, 100.0).unwrap();
            let q = s.point + real_dir * ((mirrored - s.point).norm());
            assert!((q - mirrored).norm() < 1e-3, "{q:?} vs {mirrored:?}");
            assert!((mirrored.x - 28.5).abs() < 1e-3, "{mirrored:?}");
        }
        other => panic!(
            "{other:?} {:?} {:?}",
            w.cast(&o, &d, 100.0),
            w.cast_solid(&o, &d, 100.0)
        ),
    }
}

#[test]
fn stereo_on_still_water_triangulates_the_mirror_image() {
    let w = world(0.5);
    let s = Stereo::new(w.scene.rig.stereo.as_ref().unwrap()).unwrap();
    let o = Point3::new(0.0, 0.0, 1.5);
    // Towards the building's reflection: mirror point on the original ray.
    let e = (1.7f64 / 14.0).atan();
    let d = Vector3::new(e.cos(), 0.0, -e.sin());
    let (t, _) = s.trace(&w, &o, &d).expect("the building is reflected");
    let p = o + d * t;
    let mirrored = Point3::new(p.x, p.y, -0.4 - p.z);
    assert!(
        (mirrored.x - 28.5).abs() < 1e-3 && mirrored.z > -0.2,
        "{mirrored:?}"
    );
    // A reflected sky gives no match.
    let d = Vector3::new(0.0, 1.0, 0.0);
    let e = (1.7f64 / 12.0).atan();
    let d2 = Vector3::new(e.cos() * 0.9, (1.0 - 0.81f64).sqrt() * e.cos(), -e.sin()).normalize();
    let _ = d;
    assert!(w.cast_water(&o, &d2, 100.0).is_some());
    let refl_hits = {
        let h = w.cast_water(&o, &d2, 100.0).unwrap();
        let r = d2 + Vector3::z() * (2.0 * -d2.z);
        w.cast_solid(&(h.point + r * 1e-4), &r, 100.0).is_some()
    };
    assert_eq!(s.trace(&w, &o, &d2).is_some(), refl_hits);
    // Ripples break the reflection up.
    let t = scene_text(0.5, "").replacen("attenuation = 7.9", "attenuation = 7.9\nripple = 0.1", 1);
    let w2 = World::build(&Scene::from_toml_str(&t).unwrap()).unwrap();
    assert!(s.trace(&w2, &o, &d).is_none());
}

/// The colour camera's view of the water: pixels over the pond reflecting the building are
/// terrain reflections, the rest sky; on still water that is exactly where stereo matches
/// a reflection (its independent trace), and the building's reflection lies on the far
/// part of the pond, towards it.
#[test]
fn water_views_split_sky_from_terrain_reflections() {
    let w = world(0.5);
    let s = Stereo::new(w.scene.rig.stereo.as_ref().unwrap()).unwrap();
    let opt = s.optical_mount;
    let views = water_views(&w, &s.camera, &opt, s.spec.max_range_m);
    let (sky, terrain): (Vec<_>, Vec<_>) = views.iter().partition(|v| v.2);
    assert!(
        !sky.is_empty() && !terrain.is_empty(),
        "{} sky, {} terrain",
        sky.len(),
        terrain.len()
    );
    let o: Point3<f64> = opt.translation.vector.into();
    let mut checked = 0;
    for i in 0..s.camera.width * s.camera.height {
        let ray = s
            .camera
            .pixel_ray((i % s.camera.width) as f64, (i / s.camera.width) as f64)
            .unwrap();
        let d = opt.rotation * ray.normalize();
        let Some(h) = w.cast(&o, &d, s.spec.max_range_m) else {
            continue;
        };
        if !matches!(h.surface, crate::sim::world::Surface::Water { .. }) {
            continue;
        }
        let v = views
            .iter()
            .find(|v| (v.0 - h.point.x).abs() < 1e-9 && (v.1 - h.point.y).abs() < 1e-9)
            .unwrap();
        assert_eq!(v.2, s.trace(&w, &o, &d).is_none(), "pixel {i}");
        checked += 1;
    }
    assert_eq!(checked, views.len());
    let mean_x = |v: &[&(f64, f64, bool)]| v.iter().map(|p| p.0).sum::<f64>() / v.len() as f64;
    assert!(mean_x(&terrain) > mean_x(&sky));
}

#[test]
fn truth_marks_the_pond_with_its_depth() {
    let w = world(0.5);
    let t = truth_map(&w);
    let c = t
        .cells
        .iter()
        .find(|c| (c.x - 12.1).abs() < 0.11 && (c.y - 0.1).abs() < 0.11)
        .unwrap();
    assert_eq!(c.class, Class::Water);
    assert!(
        (c.z + 0.2).abs() < 1e-12 && (c.depth - 0.3).abs() < 1e-6,
        "{c:?}"
    );
    let dry = t
        .cells
        .iter()
        .find(|c| (c.x - 0.1).abs() < 0.11 && (c.y - 0.1).abs() < 0.11)
        .unwrap();
    assert_eq!((dry.class, dry.depth), (Class::Ground, 0.0));
    let b = t
        .cells
        .iter()
        .find(|c| (c.x - 30.1).abs() < 0.11 && (c.y - 0.1).abs() < 0.11)
        .unwrap();
    assert_eq!(b.class, Class::Obstacle);
    let stats = water_stats(&w, &t);
    // Flat bottom of radius 6 m at 0.3 m depth, then the rim: area between π6² and π8².
    assert!(
        stats[0].area_m2 > std::f64::consts::PI * 36.0
            && stats[0].area_m2 < std::f64::consts::PI * 64.0
    );
    assert!((stats[0].max_depth_m - 0.3).abs() < 1e-6);
}

fn run_sim(threads: usize, noise: bool) -> (tempfile::TempDir, SimReport) {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::from_toml_str(&scene_text(
        0.5,
        "[rig.mwir]\nposition = [0.0, 0.0, 1.5]\nwidth = 32\nheight = 24\nhfov_deg = 50.0\n",
    ))
    .unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let r = pool
        .install(|| {
            simulate(
                &scene,
                dir.path(),
                SimOptions {
                    noise,
                    ..SimOptions::default()
                },
            )
        })
        .unwrap();
    (dir, r)
}

#[test]
fn same_seed_same_bytes_whatever_the_thread_count() {
    let (a, ra) = run_sim(1, true);
    let (b, _) = run_sim(3, true);
    for f in ["log.mcap", "truth.ply", "truth.json", "scene.ply"] {
        let (x, y) = (
            std::fs::read(a.path().join(f)).unwrap(),
            std::fs::read(b.path().join(f)).unwrap(),
        );
        assert!(x == y, "{f} differs between 1 and 3 threads");
    }
    assert_eq!(ra.frames, 2);
    assert!(ra.lidar_returns > 0 && ra.stereo_points > 0);
    // Noise changes the clouds.
    let (c, _) = run_sim(2, false);
    assert_ne!(
        std::fs::read(a.path().join("log.mcap")).unwrap(),
        std::fs::read(c.path().join("log.mcap")).unwrap()
    );
}

#[test]
fn the_frame_stream_reads_the_log_back() {
    let (dir, r) = run_sim(2, true);
    let mut fs =
        tarn_log::frames::FrameStream::open(dir.path().join("log.mcap"), &Default::default())
            .unwrap();
    let mut n = 0;
    let traj: TruthInfo =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("truth.json")).unwrap())
            .unwrap();
    for f in fs.by_ref() {
        let f = f.unwrap();
        let p = &traj.trajectory[n];
        assert!((f.stamp - p.stamp).abs() < 1e-6);
        assert!((f.base_to_map.translation.vector - Vector3::new(p.x, p.y, p.z)).norm() < 1e-9);
        let lidar = f.lidar.expect("lidar");
        assert_eq!((lidar.rows, lidar.cols), (16, 64));
        let st = f.stereo.expect("stereo");
        assert_eq!((st.rows, st.cols), (24, 32));
        let img = f.image.expect("image");
        assert_eq!((img.image.width, img.image.height), (64, 48));
        assert!(img.camera.is_some() && img.frame_to_map.is_some());
        assert!(f.mwir.is_some() && f.swir.is_none());
        // Lidar points in the map lie near the truth surface (dry ground within noise).
        n += 1;
    }
    assert_eq!(n, r.frames);
}

/// A rig with a GNSS receiver: its fixes put the scene's local solar time at the log's
/// stamps, and a reader of the log finds that hour from the stamps and the fix alone.
#[test]
fn the_gps_fix_and_the_stamps_give_the_scenes_solar_hour() {
    for hours in [2.0, 13.5, 23.9] {
        let dir = tempfile::tempdir().unwrap();
        let extra = format!("[rig.gps]\nlatitude_deg = -33.9\n[sky]\ntime_of_day = {hours}\n");
        let scene = Scene::from_toml_str(&scene_text(0.5, &extra)).unwrap();
        simulate(&scene, dir.path(), SimOptions::default()).unwrap();
        let fs =
            tarn_log::frames::FrameStream::open(dir.path().join("log.mcap"), &Default::default())
                .unwrap();
        let mwir = tarn::project::MwirLabelConfig {
            classifier: Default::default(),
            hour: None,
            longitude_deg: None,
        };
        let mut n = 0;
        for f in fs {
            let f = f.unwrap();
            let (lat, _) = f.geo.expect("a fix before every frame");
            assert_eq!(lat, -33.9);
            let h = mwir.hour_of(&f).unwrap();
            // Within a second of the scene's hour, over a log of seconds.
            let d = (h - hours + 12.0).rem_euclid(24.0) - 12.0;
            assert!(d.abs() < 5.0 / 3600.0, "{hours}: {h}");
            n += 1;
        }
        assert!(n > 0);
    }
    let bad = scene_text(0.5, "[rig.gps]\nlatitude_deg = 91.0\n");
    let e = Scene::from_toml_str(&bad).unwrap_err().to_string();
    assert!(e.contains("rig.gps.latitude_deg"), "{e}");
}

#[test]
fn eval_of_truth_against_itself_is_perfect_and_of_a_wrong_map_is_not() {
    let (dir, _) = run_sim(2, true);
    let truth_dir = dir.path();
    let map_dir = tempfile::tempdir().unwrap();
    std::fs::copy(truth_dir.join("truth.ply"), map_dir.path().join("map.ply")).unwrap();
    let r = crate::eval::evaluate_dirs(map_dir.path(), truth_dir).unwrap();
    assert!(r.is_perfect(), "{r:#?}");
    assert_eq!(r.all.water_recall, Some(1.0));
    assert_eq!(r.all.false_positive_rate, Some(0.0));
    assert!(r.all.water_cells > 0 && r.all.dry_cells > 0);
    assert_eq!(
        r.bins.iter().map(|b| b.observed_cells).sum::<usize>(),
        r.all.observed_cells
    );

    // Wrong: the pond's far half called ground, a dry strip called water, terrain 5 cm high
    // where the lidar returned and 20 cm high where it did not.
    let mut m = crate::io::read_map_ply(&truth_dir.join("truth.ply")).unwrap();
    let grid = crate::grid::GridConfig {
        resolution: m.resolution,
        ..Default::default()
    };
    let lidar = crate::eval::lidar_cells(&truth_dir.join("log.mcap"), &grid).unwrap();
    for c in &mut m.cells {
        if c.class == Class::Water && c.x > 12.0 {
            c.class = Class::Ground;
        } else if c.class == Class::Ground && c.y > 10.0 {
            c.class = Class::Water;
        } else if c.class == Class::Ground {
            c.z += if lidar.contains(&c.key) { 0.05 } else { 0.20 };
        }
    }
    crate::io::write_map_ply(&map_dir.path().join("map.ply"), &m).unwrap();
    let r = crate::eval::evaluate_dirs(map_dir.path(), truth_dir).unwrap();
    assert!(!r.is_perfect());
    let recall = r.all.water_recall.unwrap();
    assert!(recall > 0.3 && recall < 0.7, "{recall}");
    assert!(r.all.false_positive_rate.unwrap() > 0.0);
    let rms = r.all.terrain_rms_m.unwrap();
    assert!(rms > 0.05 + 1e-3 && rms < 0.20, "{rms}");
    let (map, truth, info) = crate::eval::read_dirs(map_dir.path(), truth_dir).unwrap();
    let bands = crate::eval::evaluate_matrix_bands(&map, &truth, &info, Some(&lidar)).unwrap();
    assert!(bands.iter().any(|b| b.terrain_lidar_cells > 0));
    for b in &bands {
        assert!(b.terrain_lidar_cells <= b.terrain_cells);
        if let Some(e) = b.terrain_lidar_rms_m {
            assert!((e - 0.05).abs() < 1e-5, "{}: {e}", b.range);
        }
    }
}

#[test]
fn trajectory_follows_the_waypoints() {
    let w = world(0.5);
    let p = trajectory(&w);
    assert_eq!(p.len(), 2);
    assert_eq!((p[0].x, p[1].x), (0.0, 0.4));
    assert!((p[1].stamp - p[0].stamp - 0.2).abs() < 1e-12);
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

    /// Over flat dry ground, from any height and in any direction that stays on the
    /// terrain, the lidar range is h / sin(depression angle).
    #[test]
    fn flat_ground_range_property(h in 0.5f64..3.0, deg in 6.0f64..89.0, az in 100.0f64..260.0) {
        let t = scene_text(0.5, "").replacen("position = [0.0, 0.0, 1.5]\nrings", &format!("position = [0.0, 0.0, {h}]\nrings"), 1);
        let w = World::build(&Scene::from_toml_str(&t).unwrap()).unwrap();
        let l = Lidar::new(w.scene.rig.lidar.as_ref().unwrap()).unwrap();
        let o = Point3::new(0.0, 0.0, h);
        let (e, a) = (deg.to_radians(), az.to_radians());
        let d = Vector3::new(e.cos() * a.cos(), e.cos() * a.sin(), -e.sin());
        let look = h / e.tan();
        let p = o + d * (h / e.sin());
        proptest::prop_assume!(w.terrain.contains(p.x, p.y) && look < l.spec.dry_limit_m);
        match l.trace(&w, &o, &d).unwrap() {
            LidarReturn::Solid { point, .. } => {
                let r = (point - o).norm();
                proptest::prop_assert!((r - h / e.sin()).abs() < 2e-4, "{} vs {}", r, h / e.sin());
            }
            other => proptest::prop_assert!(false, "{:?}", other),
        }
    }
}

/// What a camera at (x0, 0, h) sees on the pond `look` m ahead (+x) and on dry soil `look`
/// m to its right (−y).
fn water_and_ground_from(
    hours: f64,
    sky: &str,
    x0: f64,
    h: f64,
    look: f64,
) -> (Radiance, Radiance) {
    let t = scene_text(
        0.5,
        &format!("[sky]\nkind = \"{sky}\"\ntime_of_day = {hours}\n"),
    );
    let w = World::build(&Scene::from_toml_str(&t).unwrap()).unwrap();
    let light = Light::new(&w);
    let o = Point3::new(x0, 0.0, h);
    let e = ((h + 0.2) / look).atan();
    let to_water = Vector3::new(e.cos(), 0.0, -e.sin());
    let e_g = (h / look).atan();
    let to_ground = Vector3::new(0.0, -e_g.cos(), -e_g.sin());
    assert!(matches!(
        w.cast(&o, &to_water, 100.0).unwrap().surface,
        Surface::Water { .. }
    ));
    let g = w.cast(&o, &to_ground, 100.0).unwrap();
    assert!(
        matches!(g.surface, Surface::Solid { .. }) && w.water_at(g.point.x, g.point.y).is_none()
    );
    (
        radiance(&w, &light, &o, &to_water, 300.0),
        radiance(&w, &light, &o, &to_ground, 300.0),
    )
}

fn water_and_ground(hours: f64, sky: &str) -> (Radiance, Radiance) {
    water_and_ground_from(hours, sky, 0.0, 1.5, 12.0)
}

#[test]
fn mwir_water_is_warmer_than_ground_at_night_and_cooler_by_day() {
    let (w, g) = water_and_ground(2.0, "clear");
    assert!(
        w.mwir > g.mwir + 2.0,
        "night: water {} K, ground {} K",
        w.mwir,
        g.mwir
    );
    let (w, g) = water_and_ground(14.0, "clear");
    assert!(
        w.mwir < g.mwir - 2.0,
        "day: water {} K, ground {} K",
        w.mwir,
        g.mwir
    );
}

#[test]
fn swir_water_is_dark_at_moderate_incidence_and_bright_at_grazing() {
    // From 5 m up, 5 m ahead: incidence about 45°, Fresnel R about 3 %.
    let (moderate, g) = water_and_ground_from(12.0, "overcast", 6.0, 5.0, 5.0);
    assert!(
        moderate.swir < 0.2 * g.swir,
        "SWIR water {} vs soil {}",
        moderate.swir,
        g.swir
    );
    // From 1.5 m, 12 m ahead: about 82°, the surface reflection takes over.
    let (grazing, _) = water_and_ground(12.0, "overcast");
    assert!(
        grazing.swir > 3.0 * moderate.swir,
        "{} vs {}",
        grazing.swir,
        moderate.swir
    );
    // Night is darker than noon in the visible.
    let lum = |r: &Radiance| r.rgb.iter().sum::<f64>();
    let (w_noon, g_noon) = water_and_ground(12.0, "clear");
    let (w_night, g_night) = water_and_ground(0.5, "clear");
    assert!(lum(&g_night) < 0.1 * lum(&g_noon) && lum(&w_night) < lum(&w_noon));
}

/// A flat scene (no water) with a wall of `material` facing the camera `wall_x` m ahead:
/// stereo at the origin looking along +x, level.
fn wall_scene(wall_x: f64, sigma_d: f64, bin: usize) -> Scene {
    Scene::from_toml_str(&format!(
        r#"
name = "wall"
seed = 3
[terrain]
origin = [-5.0, -40.0]
size = [{size}, 80.0]
resolution = 1.0
material = "soil"
[[objects]]
kind = "building"
position = [{bx}, 0.0]
size = [2.0, 60.0, 30.0]
[trajectory]
waypoints = [[0.0, 0.0], [1.0, 0.0]]
speed = 1.0
frames = 1
[rig.stereo]
position = [0.0, 0.0, 1.5]
width = 160
height = 120
hfov_deg = 60.0
baseline_m = 0.12
disparity_noise_px = {sigma_d}
bin = {bin}
"#,
        size = wall_x + 20.0,
        bx = wall_x + 1.0,
    ))
    .unwrap()
}

/// Stereo noise is Gaussian in disparity, not in range: the depths of a flat wall at z
/// have their 15.9 % and 84.1 % quantiles at f_b·B/(d + σ_d) and f_b·B/(d − σ_d) with
/// d = f_b·B/z (f_b the binned focal length), so the far tail is longer than the near
/// one; and past the depth where d falls under the minimum disparity nothing matches.
#[test]
fn stereo_noise_is_gaussian_in_disparity() {
    for (wall, sigma_d, bin) in [(5.0, 0.25, 2), (10.0, 0.25, 1), (8.0, 0.5, 1)] {
        let scene = wall_scene(wall, sigma_d, bin);
        let w = World::build(&scene).unwrap();
        let s = Stereo::new(scene.rig.stereo.as_ref().unwrap()).unwrap();
        let pose = crate::sim::pose_of(&trajectory(&w)[0]) * s.optical_mount;
        let fb = s.disparity_focal_px() * 0.12;
        assert!((fb - s.rectified.fx / bin as f64 * 0.12).abs() < 1e-12);
        let mut z: Vec<f64> = Vec::new();
        for frame in 0..40 {
            let c = s.cloud(&w, &pose, frame, true).unwrap();
            // Points on the wall's face (the optical frame's z is the depth).
            z.extend(
                c.xyz
                    .iter()
                    .filter(|p| p[0].is_finite() && p[1] < -0.5)
                    .map(|p| p[2] as f64),
            );
        }
        assert!(z.len() > 2000, "{} wall points", z.len());
        z.sort_by(f64::total_cmp);
        let q = |p: f64| z[((z.len() - 1) as f64 * p) as usize];
        let d = fb / wall;
        let (near, far) = (fb / (d + sigma_d), fb / (d - sigma_d));
        let (q16, q50, q84) = (q(0.1587), q(0.5), q(0.8413));
        assert!((q50 / wall - 1.0).abs() < 0.01, "median {q50} for {wall}");
        assert!((q16 / near - 1.0).abs() < 0.02, "{q16} vs {near}");
        assert!((q84 / far - 1.0).abs() < 0.02, "{q84} vs {far}");
        assert!(
            q84 - q50 > q50 - q16,
            "far tail {q84} not longer than near {q16}"
        );
        // No depth beyond the minimum disparity's.
        assert!(z.iter().all(|&v| v <= fb / s.spec.min_disparity_px + 1e-6));
    }
    // A wall beyond f_b·B / d_min (8.3 m for f_b = 69.3 px, B = 0.12 m) gives no match
    // without noise.
    let scene = wall_scene(40.0, 0.0, 2);
    let w = World::build(&scene).unwrap();
    let s = Stereo::new(scene.rig.stereo.as_ref().unwrap()).unwrap();
    let fb = s.disparity_focal_px() * 0.12;
    assert!(fb / s.spec.min_disparity_px < 40.0);
    let pose = crate::sim::pose_of(&trajectory(&w)[0]) * s.optical_mount;
    let c = s.cloud(&w, &pose, 0, false).unwrap();
    assert!(c
        .xyz
        .iter()
        .filter(|p| p[0].is_finite())
        .all(|p| (p[2] as f64) <= fb / s.spec.min_disparity_px + 1e-3));
    assert!(s.measured_depth(fb, -0.01).is_none() && s.measured_depth(fb, 0.0).is_some());
}

/// A flat lot of `material` under a lidar at 2 m writing `intensity` (`raw` or
/// `reflectivity`), noise off.
fn lot(material: &str, intensity: &str) -> World {
    World::build(
        &Scene::from_toml_str(&format!(
            r#"
name = "lot"
seed = 5
[terrain]
origin = [-80.0, -80.0]
size = [160.0, 160.0]
resolution = 2.0
material = "{material}"
[trajectory]
waypoints = [[0.0, 0.0], [1.0, 0.0]]
speed = 1.0
frames = 1
[rig.lidar]
position = [0.0, 0.0, 2.0]
rings = 40
elevation_deg = [-40.0, -0.5]
columns = 8
dry_limit_m = 40.0
intensity = "{intensity}"
"#
        ))
        .unwrap(),
    )
    .unwrap()
}

/// The lidar's per-return channel follows the backscatter law (ρ/π)·cosᵐθ·A/r²: raw
/// intensity 10⁴·ρ·cosᵐθ/r² falls with range² and incidence; reflectivity 100·ρ·cosᵐθ is
/// range-corrected but still falls with incidence. Smooth pavement (m = 2.5) stops
/// returning nearer than Lambertian grass of lower albedo.
#[test]
fn lidar_intensity_conventions_follow_the_backscatter_law() {
    let mut farthest = Vec::new();
    for (material, rho, m) in [("grass", 0.35, 1.0), ("pavement", 0.40, 2.5)] {
        for conv in ["raw", "reflectivity"] {
            let w = lot(material, conv);
            let spec = w.scene.rig.lidar.as_ref().unwrap();
            assert_eq!(
                w.materials[w.material(material).unwrap()]
                    .spec
                    .backscatter_exponent,
                m
            );
            let l = Lidar::new(spec).unwrap();
            let pose = crate::sim::pose_of(&trajectory(&w)[0]) * l.mount;
            let c = l.scan(&w, &pose, 0, false).unwrap();
            let chan = if conv == "raw" {
                assert!(c.reflectivity.is_none());
                c.intensity.as_ref().unwrap()
            } else {
                assert!(c.intensity.is_none());
                c.reflectivity.as_ref().unwrap()
            };
            let mut far: f64 = 0.0;
            let mut n = 0;
            for (p, v) in c.xyz.iter().zip(chan) {
                if !p[0].is_finite() {
                    assert!(v.is_nan());
                    continue;
                }
                let r = (p[0] as f64).hypot(p[1] as f64).hypot(p[2] as f64);
                let cos = 2.0 / r; // level ground, sensor 2 m above it
                let law = rho * cos.powf(m);
                let expect = if conv == "raw" {
                    1e4 * law / (r * r)
                } else {
                    (100.0 * law).round().min(255.0)
                };
                let tol = if conv == "raw" { 1e-4 * expect } else { 1.0 };
                assert!(
                    ((*v as f64) - expect).abs() <= tol + 1e-9,
                    "{material} {conv}: {v} vs {expect} at {r} m"
                );
                far = far.max(r);
                n += 1;
            }
            assert!(n > 50, "{material}: {n} returns");
            farthest.push(far);
        }
    }
    // Grass returns out to about its dry limit; smooth pavement stops well before.
    assert!(
        farthest[0] > 30.0 && farthest[2] < 0.75 * farthest[0],
        "{farthest:?}"
    );
}

/// A rig file is datasheet values and mounts: it cannot carry a scene's water (the parser
/// refuses the keys), the mapper config comes from the rig alone, and two scenes with
/// different water, clarity and fording depth rendered with one rig give the same
/// rig.toml, and no mapper config.
#[test]
fn a_rig_cannot_carry_scene_truth() {
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("rig.toml");
    std::fs::write(
        &rig,
        "[lidar]\nposition = [0.0, 0.0, 1.5]\nrings = 8\nelevation_deg = [-20.0, 0.0]\ncolumns = 32\ndry_limit_m = 25.0\nattenuation = 0.8\n",
    )
    .unwrap();
    let e = RigSpec::load(&rig).unwrap_err().to_string();
    assert!(e.contains("attenuation"), "{e}");
    std::fs::write(
        &rig,
        "[lidar]\nposition = [0.0, 0.0, 1.5]\nrings = 8\nelevation_deg = [-20.0, 0.0]\ncolumns = 32\ndry_limit_m = 25.0\n[[water]]\nkind = \"level\"\n",
    )
    .unwrap();
    assert!(RigSpec::load(&rig).is_err());
    std::fs::write(
        &rig,
        "[lidar]\nposition = [0.0, 0.0, 1.5]\nrings = 8\nelevation_deg = [-20.0, 0.0]\ncolumns = 32\ndry_limit_m = 25.0\n[stereo]\nposition = [0.0, 0.0, 1.5]\nwidth = 32\nheight = 24\nhfov_deg = 60.0\nbaseline_m = 0.2\n",
    )
    .unwrap();
    let mut outs = Vec::new();
    for (i, (att, level, fording)) in [(7.9, -0.2, 0.3), (10.0, -0.1, 0.5)].iter().enumerate() {
        let t = scene_text(0.5, "")
            .replacen("attenuation = 7.9", &format!("attenuation = {att}"), 1)
            .replacen("level = -0.2", &format!("level = {level}"), 1)
            .replacen(
                "seed = 7",
                &format!("seed = 7\nfording_depth = {fording}"),
                1,
            );
        let p = dir.path().join(format!("scene{i}.toml"));
        std::fs::write(&p, t).unwrap();
        let scene = Scene::load_with_rig(&p, Some(&rig)).unwrap();
        let out = dir.path().join(format!("sim{i}"));
        simulate(
            &scene,
            &out,
            SimOptions {
                noise: false,
                ..SimOptions::default()
            },
        )
        .unwrap();
        assert!(!out.join("mapper.toml").exists());
        let cfg = RigSpec::load(&out.join("rig.toml"))
            .unwrap()
            .mapper_config();
        assert_eq!(cfg.lidar.as_ref().unwrap().attenuation_per_m, None);
        assert_eq!(cfg.vehicle, crate::hazard::Vehicle::default());
        outs.push((std::fs::read(out.join("rig.toml")).unwrap(), cfg));
    }
    assert!(outs[0].0 == outs[1].0, "rig.toml differs between scenes");
    assert_eq!(outs[0].1, outs[1].1);
}

/// The stereo pair's right CameraInfo carries the baseline as ROS drivers publish it
/// (P[0][3] = −f·B), and the frame reader recovers it; the left camera's lens distortion
/// reaches the log.
#[test]
fn the_log_carries_the_baseline_and_the_distortion() {
    let dir = tempfile::tempdir().unwrap();
    let t = scene_text(0.5, "").replacen(
        "baseline_m = 0.12",
        "baseline_m = 0.12\ndistortion = [-0.1, 0.02, 0.0, 0.0, 0.0]",
        1,
    );
    simulate(
        &Scene::from_toml_str(&t).unwrap(),
        dir.path(),
        SimOptions {
            noise: false,
            ..SimOptions::default()
        },
    )
    .unwrap();
    let frames: Vec<_> = tarn_log::frames::FrameStream::open(
        dir.path().join("log.mcap"),
        &tarn_log::frames::LogConfig::default(),
    )
    .unwrap()
    .map(|f| f.unwrap())
    .collect();
    assert_eq!(frames.len(), 2);
    for f in &frames {
        assert!((f.stereo_baseline_m.unwrap() - 0.12).abs() < 1e-12);
        let cam = f.image.as_ref().unwrap().camera.as_ref().unwrap();
        assert_eq!(
            cam.distortion,
            crate::geom::Distortion::PlumbBob([-0.1, 0.02, 0.0, 0.0, 0.0])
        );
        // A reader that ignored the distortion would be measurably off: at the image's
        // corner the pinhole ray of the same K is more than half a degree away.
        let pin = crate::geom::CameraModel {
            distortion: crate::geom::Distortion::None,
            ..cam.clone()
        };
        let (u, v) = (0.0, 0.0);
        let (a, b) = (cam.pixel_ray(u, v).unwrap(), pin.pixel_ray(u, v).unwrap());
        assert!(
            a.angle(&b).to_degrees() > 0.5,
            "{}",
            a.angle(&b).to_degrees()
        );
    }
}

/// Smooth pavement stops returning at grazing incidence long before the lidar's
/// configured sensitivity says (15 m against 40 m here): missing returns past where it
/// stopped are no-return evidence of water unless the cue takes its dry limit from the
/// scan itself, and then they say nothing. Grass, which returns out to the configured
/// limit, leaves no missing beam inside the interval either way.
#[test]
fn missing_returns_past_the_scans_own_dry_limit_say_nothing() {
    use tarn::cues::{BeamModel, LidarCueConfig, LidarCueModel};
    let mut noret = Vec::new();
    for material in ["pavement", "grass"] {
        let w = lot(material, "none");
        let l = Lidar::new(w.scene.rig.lidar.as_ref().unwrap()).unwrap();
        let pose = crate::sim::pose_of(&trajectory(&w)[0]) * l.mount;
        let mut cloud = l.scan(&w, &pose, 0, false).unwrap();
        cloud.frame_to_map = pose;
        // The beams' directions as a datasheet gives them (whole rings go missing here).
        let dirs: Vec<[f32; 3]> = (0..cloud.rows * cloud.cols)
            .map(|i| {
                let b = l.beam(i / cloud.cols, i % cloud.cols);
                [b.x as f32, b.y as f32, b.z as f32]
            })
            .collect();
        for scan_dry_limit in [false, true] {
            let cue = LidarCueModel::new(
                LidarModelConfig {
                    height_m: 2.0,
                    attenuation: Attenuation::PureWater {
                        wavelength_nm: 905.0,
                    },
                    albedo: 0.3,
                    aperture_diameter_m: 0.0254,
                    n_water: N_WATER,
                    sensitivity: Sensitivity::DryLimit(40.0),
                    solid_angle: SolidAngleForm::Exact,
                },
                BeamModel::Directions(dirs.clone()),
                LidarCueConfig {
                    scan_dry_limit,
                    ..LidarCueConfig::default()
                },
                None,
            )
            .unwrap();
            let out = cue
                .run(
                    &cloud,
                    &tarn::cues::CueRun::new(0.1, 0.0),
                    &mut Default::default(),
                )
                .unwrap();
            noret.push((
                material,
                scan_dry_limit,
                out.stats.noret,
                out.stats.noret_beyond_dry,
            ));
        }
    }
    assert!(noret[0].2 > 20, "{noret:?}");
    assert_eq!(noret[1].2, 0, "{noret:?}");
    assert_eq!(noret[1].3, noret[0].2, "{noret:?}");
    assert_eq!((noret[2].2, noret[3].2), (0, 0), "{noret:?}");
}
