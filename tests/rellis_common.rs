//! The real RELLIS-3D frame 000104 (../shared/data, test-only licence): loading, training on
//! the left half, scoring on the right half, projecting onto the Ouster scan. Shared by
//! `tests/rellis_classify.rs` and `examples/rellis_eval.rs`.
#![allow(dead_code)]

use std::path::PathBuf;

use image::{GrayImage, RgbImage};
use nalgebra::{Matrix3, Point3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};
use tarn::classify::{ColorModel, Confusion, Horizon, Label, LabelImage, TrainConfig};
use tarn::geom::{CameraModel, Distortion, PointCloud, Pose};

pub const PUDDLE: u8 = 31;
pub const SKY: u8 = 7;

pub fn dir() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/data/rellis3d-puddle-frame"
    ))
}

pub struct Rellis {
    pub rgb: RgbImage,
    pub ids: GrayImage,
    pub camera: CameraModel,
    /// Ouster scan, point order as in 000104.label; no-returns are NaN.
    pub cloud: PointCloud,
    /// Class id per lidar point (value & 0xFFFF).
    pub lidar_ids: Vec<u16>,
    /// os1_cloud_node → camera optical frame (see [`lidar_to_camera`]).
    pub lidar_to_cam: Pose,
}

/// The transform in transforms.yaml as written: rotation q, translation t.
pub fn yaml_transform() -> Pose {
    let text = std::fs::read_to_string(dir().join("transforms.yaml")).unwrap();
    let val = |key: &str, section: &str| -> f64 {
        let s = text.split(section).nth(1).unwrap();
        let line = s
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{key}:")))
            .unwrap();
        line.split(':').nth(1).unwrap().trim().parse().unwrap()
    };
    let q = UnitQuaternion::from_quaternion(Quaternion::new(
        val("w", "q:"),
        val("x", "q:"),
        val("y", "q:"),
        val("z", "q:"),
    ));
    Pose::from_parts(
        Translation3::new(val("x", "t:"), val("y", "t:"), val("z", "t:")),
        q,
    )
}

/// The direction of transforms.yaml that maps lidar points into the camera's optical frame:
/// the inverse of the transform as written (RELLIS-3D's own utils/lidar2img.ipynb inverts it
/// too). `tests/rellis_classify.rs` checks it against the labels (sky pixels get no lidar
/// points, puddle points land on puddle pixels), and that the other direction fails.
pub fn lidar_to_camera() -> Pose {
    yaml_transform().inverse()
}

/// Lens distortion of the RELLIS-3D Basler camera (plumb_bob k1 k2 p1 p2 k3). Not in the
/// data folder's camera_info.txt; these are the coefficients RELLIS-3D's
/// utils/lidar2img.ipynb uses for this camera.
pub const DIST: [f64; 5] = [-0.134313, -0.025905, 0.002181, 0.00084, 0.0];

/// Whether the RELLIS-3D frame is beside the repository (`../shared/data`); where it is
/// not, a message says so and the test that asked skips.
pub fn available() -> bool {
    let ok = dir().join("000104.label").exists();
    if !ok {
        eprintln!(
            "skipped: {} is absent (shared test data, kept beside the repository)",
            dir().display()
        );
    }
    ok
}

pub fn load() -> Rellis {
    let d = dir();
    let rgb = image::open(d.join("frame000104-1581624663_149.jpg"))
        .unwrap()
        .to_rgb8();
    let ids = image::open(d.join("frame000104-1581624663_149.png"))
        .unwrap()
        .to_luma8();
    let k: Vec<f64> = std::fs::read_to_string(d.join("camera_info.txt"))
        .unwrap()
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    let camera = CameraModel::new(
        rgb.width() as usize,
        rgb.height() as usize,
        [k[0], k[1], k[2], k[3]],
        Distortion::PlumbBob(DIST),
        "pylon_camera_node",
    )
    .unwrap();
    let cloud = tarn::io::read_kitti(&d.join("000104.bin")).unwrap();
    let lidar_ids = std::fs::read(d.join("000104.label"))
        .unwrap()
        .chunks_exact(4)
        .map(|b| (u32::from_le_bytes([b[0], b[1], b[2], b[3]]) & 0xFFFF) as u16)
        .collect();
    Rellis {
        rgb,
        ids,
        camera,
        cloud,
        lidar_ids,
        lidar_to_cam: lidar_to_camera(),
    }
}

/// Pixels of one half: x < w/2 (left) or x ≥ w/2 (right).
pub fn in_half(x: u32, w: u32, left: bool) -> bool {
    (x < w / 2) == left
}

/// Trains water (31), sky (7) and everything else on the left half.
pub fn train(r: &Rellis, cfg: &TrainConfig) -> ColorModel {
    let (mut water, mut sky, mut other) = (Vec::new(), Vec::new(), Vec::new());
    let w = r.rgb.width();
    for (i, (p, id)) in r.rgb.pixels().zip(r.ids.pixels()).enumerate() {
        let x = (i as u32) % w;
        if !in_half(x, w, true) {
            continue;
        }
        match id.0[0] {
            PUDDLE => water.push(p.0),
            SKY => sky.push(p.0),
            _ => other.push(p.0),
        }
    }
    ColorModel::train(
        &[
            (Label::Water, &water),
            (Label::Sky, &sky),
            (Label::Other, &other),
        ],
        cfg,
    )
    .unwrap()
    .0
}

/// Puddle precision/recall/IoU of a label image on the right half.
pub fn score_right(labels: &LabelImage, ids: &GrayImage) -> Confusion {
    let w = ids.width();
    let mut c = Confusion::default();
    for (i, id) in ids.pixels().enumerate() {
        if in_half(i as u32 % w, w, false) {
            c.add(labels.data[i] == Label::Water, id.0[0] == PUDDLE);
        }
    }
    c
}

/// A level frame for the lidar: the least-squares ground plane z = a·x + b·y + c through the
/// lidar points labelled grass, concrete, mud or puddle within 20 m, rotated to horizontal.
/// Returns lidar → level frame (origin at the lidar).
pub fn lidar_level(r: &Rellis) -> Pose {
    let mut ata = Matrix3::<f64>::zeros();
    let mut atb = Vector3::<f64>::zeros();
    for (i, id) in r.lidar_ids.iter().enumerate() {
        if !matches!(id, 3 | 23 | 31 | 33) || !r.cloud.is_valid(i) {
            continue;
        }
        let p = r.cloud.xyz[i];
        let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
        if x.hypot(y) > 20.0 {
            continue;
        }
        let a = Vector3::new(x, y, 1.0);
        ata += a * a.transpose();
        atb += a * z;
    }
    let s = ata.lu().solve(&atb).unwrap();
    let n = Vector3::new(-s[0], -s[1], 1.0).normalize();
    let rot = Rotation3::rotation_between(&n, &Vector3::z()).unwrap_or_else(Rotation3::identity);
    Pose::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

/// The camera's pose in the level lidar frame: the horizon for the image.
pub fn horizon(r: &Rellis) -> Horizon {
    let cam_to_level = lidar_level(r) * r.lidar_to_cam.inverse();
    Horizon::Camera {
        camera: r.camera.clone(),
        cam_to_map: cam_to_level,
    }
}

/// Lidar points that project into the image: (point index, image id at the pixel).
pub fn lidar_pixels(r: &Rellis, lidar_to_cam: &Pose) -> Vec<(usize, u8)> {
    let (w, h) = (r.camera.width as f64, r.camera.height as f64);
    (0..r.cloud.len())
        .filter(|&i| r.cloud.is_valid(i))
        .filter_map(|i| {
            let p = r.cloud.xyz[i];
            let q = lidar_to_cam * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let [u, v] = r.camera.project(&q)?;
            let (u, v) = (u.round(), v.round());
            (u >= 0.0 && v >= 0.0 && u < w && v < h)
                .then(|| (i, r.ids.get_pixel(u as u32, v as u32).0[0]))
        })
        .collect()
}
