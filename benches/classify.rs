//! Classifying a 640 × 480 frame with the colour lookup table on one core (the paper: 40 ms
//! on a 433 MHz PowerPC; target here ≤ 1 ms), direct mixture evaluation for comparison,
//! every table size (its RELLIS accuracy is printed by `examples/rellis_eval.rs`), and the
//! projection of a 640 × 480 label image onto a 400 × 400 grid by stereo points and by rays,
//! and the undistorted ray of every pixel of a 640 × 480 camera.
//!
//! The model is trained on the left half of the RELLIS-3D frame in ../shared/data; the frame
//! is the 640 × 480 centre-bottom crop of that image (puddles, track, grass, some sky).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use image::RgbImage;
use nalgebra::Point3;
use tarn::classify::{
    optical_pose, ColorLut, ColorModel, Label, LabelImage, PixelClassifier, TrainConfig,
};
use tarn::geom::{pose_xyz_rpy, CameraModel, Distortion, PointCloud};
use tarn::grid::{GridConfig, RangeNoise, RollingGrid};
use tarn::project::{ElevationSurface, ProjectConfig, Projector, RayTarget};

const DIR: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/rellis3d-puddle-frame"
);

fn setup() -> (ColorModel, RgbImage) {
    let rgb = image::open(format!("{DIR}/frame000104-1581624663_149.jpg"))
        .unwrap()
        .to_rgb8();
    let ids = image::open(format!("{DIR}/frame000104-1581624663_149.png"))
        .unwrap()
        .to_luma8();
    let w = rgb.width();
    let (mut water, mut sky, mut other) = (Vec::new(), Vec::new(), Vec::new());
    for (i, (p, id)) in rgb.pixels().zip(ids.pixels()).enumerate() {
        if (i as u32 % w) >= w / 2 {
            continue;
        }
        match id.0[0] {
            31 => water.push(p.0),
            7 => sky.push(p.0),
            _ => other.push(p.0),
        }
    }
    let (m, _) = ColorModel::train(
        &[
            (Label::Water, &water),
            (Label::Sky, &sky),
            (Label::Other, &other),
        ],
        &TrainConfig::default(),
    )
    .unwrap();
    let frame = image::imageops::crop_imm(&rgb, 640, 700, 640, 480).to_image();
    (m, frame)
}

fn classify(c: &mut Criterion) {
    let (model, frame) = setup();
    let mut g = c.benchmark_group("classify_640x480");
    g.throughput(Throughput::Elements(640 * 480));
    let mut out = vec![Label::Other; 640 * 480];
    for bits in [4u8, 5, 6, 7, 8] {
        let lut = ColorLut::compile(&model, bits).unwrap();
        g.bench_with_input(BenchmarkId::new("lut_one_core", bits), &lut, |b, lut| {
            b.iter(|| lut.classify_into(frame.as_raw(), &mut out).unwrap())
        });
    }
    g.sample_size(10);
    g.bench_function("gmm_direct_one_core", |b| {
        b.iter(|| {
            for (o, p) in out.iter_mut().zip(frame.pixels()) {
                *o = model.classify_pixel(p.0);
            }
        })
    });
    g.finish();
    let mut g = c.benchmark_group("lut_compile");
    g.sample_size(10);
    for bits in [5u8, 6] {
        g.bench_with_input(BenchmarkId::from_parameter(bits), &bits, |b, &bits| {
            b.iter(|| ColorLut::compile(&model, bits).unwrap())
        });
    }
    g.finish();
}

fn project(c: &mut Criterion) {
    // 40 m × 40 m grid at 0.1 m (400 × 400) of rolling ground; camera 1.5 m up, 15° down.
    let cfg = GridConfig {
        resolution: 0.1,
        size_cells: 400,
        ..Default::default()
    };
    let mut grid = RollingGrid::new(cfg, 18.0, 0.0).unwrap();
    let mut xyz = Vec::new();
    for i in -20..380 {
        for j in -200..200 {
            let (x, y) = ((i as f64 + 0.5) * 0.1, (j as f64 + 0.5) * 0.1);
            xyz.push([
                x as f32,
                y as f32,
                (0.2 * (0.3 * x).sin() + 0.1 * (0.5 * y).cos()) as f32,
            ]);
        }
    }
    let mut cloud = PointCloud::unorganized(xyz);
    cloud.sensor_origin = Point3::new(0.0, 0.0, 10.0);
    grid.ingest(&cloud, &RangeNoise::constant(0.01)).unwrap();
    let surface = ElevationSurface::from_grid(&grid).unwrap();
    let cam = CameraModel::new(
        640,
        480,
        [500.0, 500.0, 319.5, 239.5],
        Distortion::PlumbBob([-0.2, 0.05, 0.0, 0.0, 0.0]),
        "cam",
    )
    .unwrap();
    let pose = optical_pose(&pose_xyz_rpy(0.0, 0.0, 1.5, 0.0, 15f64.to_radians(), 0.0));
    let p = Projector::new(cam.clone(), ProjectConfig::default()).unwrap();
    let mut labels = LabelImage::filled(640, 480, Label::Other);
    for (i, l) in labels.data.iter_mut().enumerate() {
        if (i / 640) > 300 && (i % 640) / 40 % 2 == 0 {
            *l = Label::Water;
        }
    }
    // Stereo at 2 × 2 binning: 320 × 240 points on the ray of each block, where rays hit.
    let t = RayTarget::Terrain(&surface);
    let origin = Point3::from(pose.translation.vector);
    let mut sxyz = vec![[f32::NAN; 3]; 320 * 240];
    for r in 0..240 {
        for col in 0..320 {
            if let Some(ray) = cam.pixel_ray(2.0 * col as f64 + 0.5, 2.0 * r as f64 + 0.5) {
                if let Some(tt) = t.cast(&origin, &(pose.rotation * ray), 50.0) {
                    let q = ray * tt;
                    sxyz[r * 320 + col] = [q.x as f32, q.y as f32, q.z as f32];
                }
            }
        }
    }
    let stereo = PointCloud::organized(240, 320, sxyz).unwrap();
    let mut g = c.benchmark_group("project_640x480_onto_400x400");
    g.sample_size(10);
    g.bench_function("heightfield_build", |b| {
        b.iter(|| ElevationSurface::from_grid(&grid).unwrap())
    });
    g.bench_function("stereo_votes", |b| {
        b.iter(|| p.project(&labels, &pose, Some(&stereo), None, 0.1).unwrap())
    });
    g.bench_function("ray_cast_terrain", |b| {
        b.iter(|| p.project(&labels, &pose, None, Some(&t), 0.1).unwrap())
    });
    g.bench_function("ray_cast_water_level", |b| {
        b.iter(|| {
            p.project(
                &labels,
                &pose,
                None,
                Some(&RayTarget::WaterLevel(-0.1)),
                0.1,
            )
            .unwrap()
        })
    });
    g.finish();
}

/// Every pixel's ray of a 640 × 480 camera (what a label stage computes once per camera):
/// the simulated rigs' plumb_bob lens, and a fisheye.
fn pixel_rays(c: &mut Criterion) {
    let mut g = c.benchmark_group("pixel_rays_640x480");
    g.throughput(Throughput::Elements(640 * 480));
    for (name, d) in [
        (
            "plumb_bob",
            Distortion::PlumbBob([-0.12, 0.03, 0.0005, -0.0003, 0.0]),
        ),
        (
            "equidistant",
            Distortion::Equidistant([0.1, -0.02, 0.003, 0.0]),
        ),
    ] {
        let cam = CameraModel::new(640, 480, [457.0, 457.0, 319.5, 239.5], d, "cam").unwrap();
        g.bench_function(name, |b| b.iter(|| cam.pixel_rays()));
    }
    g.finish();
}

criterion_group!(benches, classify, project, pixel_rays);
criterion_main!(benches);
