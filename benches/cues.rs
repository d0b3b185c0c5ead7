//! Cost of the water cues per frame: a 64 × 2048 spinning-lidar scan and a 640 × 480
//! organized stereo cloud, over flat ground with a pond.
//!
//! `cargo bench --bench cues`

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use tarn::cues::{
    stereo_reflections, BeamModel, CueRun, GrayImage, LidarBuffers, LidarCueConfig, LidarCueModel,
    MirrorCheck, ReflectivityConfig, StereoCueConfig,
};
use tarn::geom::{CameraModel, Distortion, PointCloud, Pose};
use tarn::optics::{Attenuation, LidarModelConfig, Sensitivity, SolidAngleForm};

fn optics() -> LidarModelConfig {
    LidarModelConfig {
        height_m: 1.8,
        attenuation: Attenuation::PureWater {
            wavelength_nm: 865.0,
        },
        albedo: 0.3,
        aperture_diameter_m: 0.0254,
        n_water: 1.33,
        sensitivity: Sensitivity::DryLimit(40.0),
        solid_angle: SolidAngleForm::Exact,
    }
}

/// 64 rings (+2° to −30°) × 2048 columns, sensor 1.8 m above flat ground; beams that meet
/// a 6 m pond 15 m ahead return nothing; beams above the horizon return nothing.
fn lidar_scan() -> PointCloud {
    let (rings, cols) = (64, 2048);
    let h = 1.8;
    let mut xyz = Vec::with_capacity(rings * cols);
    let mut refl = Vec::with_capacity(rings * cols);
    for r in 0..rings {
        let el = (2.0 - 32.0 * r as f64 / (rings - 1) as f64).to_radians();
        for c in 0..cols {
            let az = -2.0 * std::f64::consts::PI * c as f64 / cols as f64;
            let u = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            if u.z >= 0.0 {
                xyz.push([f32::NAN; 3]);
                refl.push(0.0);
                continue;
            }
            let p = u * (h / -u.z);
            if (p.x - 15.0).hypot(p.y) < 6.0 || p.x.hypot(p.y) > 60.0 {
                xyz.push([f32::NAN; 3]);
                refl.push(0.0);
            } else {
                xyz.push([p.x as f32, p.y as f32, p.z as f32]);
                refl.push(1500.0 + 100.0 * ((c % 7) as f32));
            }
        }
    }
    let mut cloud = PointCloud::organized(rings, cols, xyz).unwrap();
    cloud.reflectivity = Some(refl);
    cloud.frame_to_map =
        Pose::from_parts(Translation3::new(0.0, 0.0, h), UnitQuaternion::identity());
    cloud
}

/// A 640 × 480 stereo cloud (camera 1.5 m high, pitched 8° down) of flat ground with a pond
/// from 6 to 14 m reflecting a 9 m wall at 20 m, and its intensity image.
fn stereo_cloud() -> (PointCloud, GrayImage, CameraModel) {
    let (w, h) = (640, 480);
    let cam =
        CameraModel::new(w, h, [576.0, 576.0, 319.5, 239.5], Distortion::None, "cam").unwrap();
    let pitch = 8f64.to_radians();
    let zc = Vector3::new(pitch.cos(), 0.0, -pitch.sin());
    let xc = Vector3::new(0.0, -1.0, 0.0);
    let yc = zc.cross(&xc);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[xc, yc, zc]));
    let o = Point3::new(0.0, 0.0, 1.5);
    let pose = Pose::from_parts(
        Translation3::new(0.0, 0.0, 1.5),
        UnitQuaternion::from_rotation_matrix(&rot),
    );
    let inv = pose.inverse();
    let tex = |p: &Point3<f64>| (100.0 + 60.0 * (2.1 * p.z + 1.3 * p.y).sin()) as f32;
    let (mut xyz, mut pix) = (Vec::new(), Vec::new());
    for v in 0..h {
        for u in 0..w {
            let d = pose.rotation * cam.pixel_ray(u as f64, v as f64).unwrap();
            let wall = |s: Point3<f64>, dir: Vector3<f64>| {
                let t = (20.0 - s.x) / dir.x;
                let p = s + dir * t;
                (t > 0.0 && p.z >= 0.0 && p.z <= 9.0).then_some((t, p))
            };
            let hit = if d.z < 0.0 {
                let t = o.z / -d.z;
                let g = o + d * t;
                if g.x >= 6.0 && g.x <= 14.0 {
                    let r = Vector3::new(d.x, d.y, -d.z);
                    wall(g, r).map(|(t2, real)| (g + d * t2, 0.4 * tex(&real) + 10.0))
                } else if g.x < 20.0 {
                    Some((g, tex(&g)))
                } else {
                    wall(o, d).map(|(_, p)| (p, tex(&p)))
                }
            } else {
                wall(o, d).map(|(_, p)| (p, tex(&p)))
            };
            match hit {
                Some((p, i)) => {
                    let q = inv * p;
                    xyz.push([q.x as f32, q.y as f32, q.z as f32]);
                    pix.push(i);
                }
                None => {
                    xyz.push([f32::NAN; 3]);
                    pix.push(250.0);
                }
            }
        }
    }
    let mut cloud = PointCloud::organized(h, w, xyz).unwrap();
    cloud.frame_to_map = pose;
    (cloud, GrayImage::new(w, h, pix).unwrap(), cam)
}

fn bench(c: &mut Criterion) {
    let scan = lidar_scan();
    let plain = LidarCueModel::new(
        optics(),
        BeamModel::default(),
        LidarCueConfig::default(),
        None,
    )
    .unwrap();
    let with_refl = LidarCueModel::new(
        optics(),
        BeamModel::default(),
        LidarCueConfig::default(),
        Some(ReflectivityConfig::default()),
    )
    .unwrap();
    // A scan's run as the mapper asks it (the surface points for the image labels), with
    // fresh buffers each time.
    let lidar_run = CueRun {
        surface_points: true,
        ..CueRun::new(0.1, 0.0)
    };
    let stereo_run = CueRun::new(0.1, 0.0);
    let mut g = c.benchmark_group("cues");
    g.sample_size(20);
    g.bench_function("lidar 64x2048: no-return + bottom/specular", |b| {
        b.iter(|| {
            plain
                .run(&scan, &lidar_run, &mut LidarBuffers::default())
                .unwrap()
        })
    });
    g.bench_function("lidar 64x2048: + reflectivity", |b| {
        b.iter(|| {
            with_refl
                .run(&scan, &lidar_run, &mut LidarBuffers::default())
                .unwrap()
        })
    });
    let (cloud, img, cam) = stereo_cloud();
    let cfg = StereoCueConfig::default();
    g.bench_function("stereo 640x480: reflections", |b| {
        b.iter(|| stereo_reflections(&cloud, &stereo_run, None, &cfg).unwrap())
    });
    let chk = MirrorCheck {
        camera: &cam,
        image: &img,
    };
    g.bench_function("stereo 640x480: reflections + mirror check", |b| {
        b.iter(|| stereo_reflections(&cloud, &stereo_run, Some(chk), &cfg).unwrap())
    });
    g.finish();
    let r = plain
        .run(&scan, &lidar_run, &mut LidarBuffers::default())
        .unwrap();
    let s = stereo_reflections(&cloud, &stereo_run, Some(chk), &cfg).unwrap();
    eprintln!(
        "lidar: {:?}\nstereo: {} runs, {} reflected points, {} evidence cells",
        r.stats,
        s.runs,
        s.reflected_points,
        s.evidence.len()
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
