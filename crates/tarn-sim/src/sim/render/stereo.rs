//! The stereo pair: its left camera, the right camera's info, and the binned point cloud
//! with mirror points on still water.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::super::rng::{hash, normal, unit_f64};
use super::super::scene::StereoSpec;
use super::super::world::{Surface, World};
use super::{body_to_optical, lens, mount, pinhole, EPS};
use crate::error::Result;
use crate::geom::{CameraModel, PointCloud, Pose};

/// The stereo pair: its left camera and where it sits.
#[derive(Debug, Clone)]
pub struct Stereo {
    pub spec: StereoSpec,
    /// The left camera as its raw image and CameraInfo show it (with the lens distortion).
    pub camera: CameraModel,
    /// The rectified left camera (the same K, no distortion): the cloud's grid.
    pub rectified: CameraModel,
    /// base_link → left optical frame.
    pub optical_mount: Pose,
}

/// Frame of the right camera of the stereo pair (its CameraInfo's header).
pub const RIGHT_CAMERA_FRAME: &str = "camera_right_optical";

impl Stereo {
    pub fn new(spec: &StereoSpec) -> Result<Stereo> {
        let frame = "camera_left_optical";
        Ok(Stereo {
            camera: lens(
                spec.width,
                spec.height,
                spec.hfov_deg,
                spec.distortion,
                frame,
            )?,
            rectified: pinhole(spec.width, spec.height, spec.hfov_deg, frame)?,
            optical_mount: mount(spec.position, spec.rpy_deg) * body_to_optical(),
            spec: spec.clone(),
        })
    }

    /// The right camera's CameraInfo as ROS stereo drivers publish it: the rectified
    /// projection `P = [f 0 cx −f·B; 0 f cy 0; 0 0 1 0]`, so that `B = −P[0][3] / P[0][0]`.
    pub fn right_info(&self, header: tarn_log::ros::Header) -> tarn_log::ros::CameraInfoMsg {
        let mut m = tarn_log::ros::camera_to_info(&self.camera, header);
        m.p[3] = -self.camera.fx * self.spec.baseline_m;
        m
    }

    /// Focal length of the disparity image (px): the camera's over the binning.
    pub fn disparity_focal_px(&self) -> f64 {
        self.rectified.fx / self.spec.bin as f64
    }

    /// Depth (along the optical axis) that stereo reports for a true depth `z` when the
    /// disparity `d = f_b·B/z` (f_b the binned focal length) is off by `e` pixels:
    /// `f_b·B/(d + e)`; `None` where the matched disparity falls below the minimum (far
    /// ground, or noise taking it there): no match.
    pub fn measured_depth(&self, z: f64, e: f64) -> Option<f64> {
        let fb = self.disparity_focal_px() * self.spec.baseline_m;
        let d = fb / z + e;
        (d >= self.spec.min_disparity_px).then(|| fb / d)
    }

    /// The point stereo reports along unit ray `d` (map frame) from `o`, before noise:
    /// the surface on solids; on still water the mirror image of what the reflected ray
    /// meets (a point on the original ray at the total path length); `None` for the sky,
    /// for a reflected sky, and on rippled water that breaks up the reflection.
    pub fn trace(&self, w: &World, o: &Point3<f64>, d: &Vector3<f64>) -> Option<(f64, usize)> {
        let max = self.spec.max_range_m;
        let hit = w.cast(o, d, max)?;
        match hit.surface {
            Surface::Solid { .. } => Some((hit.t, hit.material)),
            Surface::Water { body } => {
                if w.water[body].spec.ripple > 0.02 {
                    return None;
                }
                let n = w.water_normal(body, &hit.point);
                let r = d + n * (2.0 * -d.dot(&n));
                let s = w.cast_solid(&(hit.point + r * EPS), &r, max - hit.t)?;
                Some((hit.t + EPS + s.t, s.material))
            }
        }
    }

    /// The binned organized cloud in the left optical frame (NaN: no match), on the
    /// rectified grid. Noise is in disparity ([`Stereo::measured_depth`]): Gaussian with
    /// σ = `disparity_noise_px`, so the range error grows as z² and is skewed far; a
    /// pixel of a material without texture finds no match with probability 1 − texture.
    pub fn cloud(
        &self,
        w: &World,
        optical_to_map: &Pose,
        frame: u64,
        noise: bool,
    ) -> Result<PointCloud> {
        let k = self.spec.bin;
        let (rows, cols) = (self.spec.height / k, self.spec.width / k);
        let o: Point3<f64> = optical_to_map.translation.vector.into();
        let seed = w.scene.seed;
        let half = 0.5 * (k as f64 - 1.0);
        let xyz = (0..rows * cols)
            .into_par_iter()
            .map(|i| {
                let (r, c) = (i / cols, i % cols);
                let (u, v) = ((k * c) as f64 + half, (k * r) as f64 + half);
                let Some(ray) = self.rectified.pixel_ray(u, v) else {
                    return [f32::NAN; 3];
                };
                let ray = ray.normalize();
                let d = optical_to_map.rotation * ray;
                let Some((t, mat)) = self.trace(w, &o, &d) else {
                    return [f32::NAN; 3];
                };
                let mut e = 0.0;
                if noise {
                    let tex = w.materials[mat].spec.texture;
                    if unit_f64(hash(seed, &[41, frame, i as u64])) >= tex {
                        return [f32::NAN; 3];
                    }
                    e = self.spec.disparity_noise_px * normal(hash(seed, &[42, frame, i as u64]));
                }
                let Some(z) = self.measured_depth(t * ray.z, e) else {
                    return [f32::NAN; 3];
                };
                let p = ray * (z / ray.z);
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect();
        PointCloud::organized(rows, cols, xyz)
    }
}
