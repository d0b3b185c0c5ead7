//! The sensors: a lidar (spinning or vertical scanner) with the optics of `optics` over
//! water, a stereo pair (left image + binned point cloud, mirror points on still water), and
//! SWIR and MWIR cameras. Every ray is independent; its noise is hashed from (seed, sensor,
//! frame, ray index), so results do not depend on the thread count.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion};
use rayon::prelude::*;

use super::rng::{hash, normal};
use super::scene::CameraSpec;
use super::world::World;
use crate::error::Result;
use crate::geom::{CameraModel, Distortion, Pose};

mod lidar;
mod light;
mod stereo;

pub use lidar::{Lidar, LidarReturn};
pub use light::{radiance, sun, water_views, Light, Radiance};
pub use stereo::{Stereo, RIGHT_CAMERA_FRAME};

/// Refractive index of water used throughout the simulator.
pub const N_WATER: f64 = 1.33;
/// Nudge (m) off a surface before casting a secondary ray.
const EPS: f64 = 1e-4;

/// Pose of a sensor body in base_link from position and roll/pitch/yaw in degrees.
pub fn mount(position: [f64; 3], rpy_deg: [f64; 3]) -> Pose {
    crate::geom::pose_xyz_rpy(
        position[0],
        position[1],
        position[2],
        rpy_deg[0].to_radians(),
        rpy_deg[1].to_radians(),
        rpy_deg[2].to_radians(),
    )
}

/// Camera body (x forward, y left, z up) → optical frame (z forward, x right, y down).
pub fn body_to_optical() -> Pose {
    let m = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m)),
    )
}

/// A pinhole camera without distortion for `width` × `height` and a horizontal FOV.
pub fn pinhole(width: usize, height: usize, hfov_deg: f64, frame: &str) -> Result<CameraModel> {
    lens(width, height, hfov_deg, None, frame)
}

/// [`pinhole`] with plumb_bob lens distortion `[k1, k2, p1, p2, k3]` (none: a pinhole).
pub fn lens(
    width: usize,
    height: usize,
    hfov_deg: f64,
    distortion: Option<[f64; 5]>,
    frame: &str,
) -> Result<CameraModel> {
    let f = 0.5 * width as f64 / (0.5 * hfov_deg.to_radians()).tan();
    CameraModel::new(
        width,
        height,
        [
            f,
            f,
            0.5 * (width as f64 - 1.0),
            0.5 * (height as f64 - 1.0),
        ],
        distortion.map_or(Distortion::None, Distortion::PlumbBob),
        frame,
    )
}

/// An 8-bit value of linear radiance `v` (0..1) in `encoding`.
fn encode(v: f64, encoding: crate::project::Encoding) -> u8 {
    let e = match encoding {
        crate::project::Encoding::Linear => v,
        crate::project::Encoding::Srgb if v <= 0.003_130_8 => 12.92 * v,
        crate::project::Encoding::Srgb => 1.055 * v.powf(1.0 / 2.4) - 0.055,
    };
    (e * 255.0).round().clamp(0.0, 255.0) as u8
}

/// A rendered camera image in one band (colour in its encoding).
pub enum Band {
    Rgb(crate::project::Encoding),
    Swir,
    Mwir,
}

/// Renders `camera` at `optical_to_map`: RGB as rgb8, SWIR as mono8 (reflectance × 255
/// under full sun), MWIR as mono16 in centikelvin.
#[allow(clippy::too_many_arguments)]
pub fn render_image(
    w: &World,
    light: &Light,
    camera: &CameraModel,
    optical_to_map: &Pose,
    band: Band,
    noise_sd: f64,
    frame: u64,
    noise: bool,
) -> crate::sensor::Pixels {
    use crate::sensor::Pixels;
    let o: Point3<f64> = optical_to_map.translation.vector.into();
    let n = camera.width * camera.height;
    let seed = w.scene.seed;
    let rad: Vec<Radiance> = (0..n)
        .into_par_iter()
        .map(|i| {
            let (u, v) = ((i % camera.width) as f64, (i / camera.width) as f64);
            match camera.pixel_ray(u, v) {
                Some(ray) => radiance(
                    w,
                    light,
                    &o,
                    &(optical_to_map.rotation * ray.normalize()),
                    300.0,
                ),
                None => Radiance {
                    rgb: [0.0; 3],
                    swir: 0.0,
                    mwir: 0.0,
                },
            }
        })
        .collect();
    let jitter = |i: usize, ch: u64| {
        if noise && noise_sd > 0.0 {
            noise_sd * normal(hash(seed, &[51, ch, frame, i as u64]))
        } else {
            0.0
        }
    };
    let exposure = 255.0 / 0.75;
    match band {
        Band::Rgb(encoding) => Pixels::Rgb8(
            rad.iter()
                .enumerate()
                .map(|(i, r)| {
                    [0, 1, 2].map(|c| {
                        let v = (r.rgb[c] * exposure + jitter(i, c as u64)).clamp(0.0, 255.0);
                        encode(v / 255.0, encoding)
                    })
                })
                .collect(),
        ),
        Band::Swir => Pixels::Mono8(
            rad.iter()
                .enumerate()
                .map(|(i, r)| (r.swir * exposure + jitter(i, 3)).round().clamp(0.0, 255.0) as u8)
                .collect(),
        ),
        Band::Mwir => Pixels::Mono16(
            rad.iter()
                .enumerate()
                .map(|(i, r)| (r.mwir * 100.0 + jitter(i, 4)).round().clamp(0.0, 65535.0) as u16)
                .collect(),
        ),
    }
}

/// A single camera of the rig (SWIR or MWIR).
pub fn camera_of(spec: &CameraSpec, frame: &str) -> Result<(CameraModel, Pose)> {
    Ok((
        pinhole(spec.width, spec.height, spec.hfov_deg, frame)?,
        mount(spec.position, spec.rpy_deg) * body_to_optical(),
    ))
}
