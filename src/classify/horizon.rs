//! The horizon, and where pixel rays meet level ground.
//!
//! A pixel whose ray (in the map frame, z up) points at or above the horizontal plane cannot
//! see water: water lies on the ground. The paper corrects sky misread as water this way.
//! The horizon is either a given image row or comes from the camera model and its pose in
//! the map frame (full distortion model, any resolution).

use nalgebra::{Matrix3, Point3, Rotation3, UnitQuaternion, Vector3};

use super::{Label, LabelImage};
use crate::error::{Error, Result};
use crate::geom::{pose_is_finite, CameraModel, Pose};

/// Unit rays of every pixel in the map frame (row-major); `None` where undistortion fails.
pub(crate) fn pixel_rays_in_map(
    camera: &CameraModel,
    cam_to_map: &Pose,
) -> Vec<Option<Vector3<f64>>> {
    camera
        .pixel_rays()
        .into_iter()
        .map(|r| r.map(|r| cam_to_map.rotation * r))
        .collect()
}

/// The pixel of `camera` (row-major index) that sees the direction in which level water at
/// the end of the map-frame ray `d` mirrors it (`d` with its vertical flipped), seen from the
/// camera: for what lies far off (the sky, a distant bank) the radiance that water reflects.
/// `None` where that direction is outside the image. `to_cam` rotates map vectors into
/// the camera's optical frame.
pub(crate) fn mirror_pixel(
    camera: &CameraModel,
    to_cam: &UnitQuaternion<f64>,
    d: &Vector3<f64>,
) -> Option<usize> {
    let m = to_cam * Vector3::new(d.x, d.y, -d.z);
    let [u, v] = camera.project(&Point3::from(m))?;
    let (u, v) = (u.round(), v.round());
    (u >= 0.0 && v >= 0.0 && (u as usize) < camera.width && (v as usize) < camera.height)
        .then(|| v as usize * camera.width + u as usize)
}

/// Rotation from a camera's optical frame (z forward, x right, y down) to its body frame
/// (REP-103: x forward, y left, z up).
pub(crate) fn optical_to_body() -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::new(
        0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0,
    )))
}

/// The optical frame's pose from a camera body pose (x forward, y left, z up) in the map
/// frame, e.g. one given as x, y, z, roll, pitch, yaw.
pub fn optical_pose(body_to_map: &Pose) -> Pose {
    Pose::from_parts(
        body_to_map.translation,
        body_to_map.rotation * optical_to_body(),
    )
}

/// Where the horizon is.
#[derive(Debug, Clone)]
pub enum Horizon {
    /// Rows above this one (y < row) are above the horizon.
    Row(usize),
    /// From the camera's intrinsics, distortion and pose (optical frame → map frame).
    Camera {
        /// The calibrated camera.
        camera: CameraModel,
        /// Pose of the camera's optical frame in the map frame.
        cam_to_map: Pose,
    },
}

/// What [`Horizon::apply`] changed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HorizonStats {
    /// Pixels above the horizon.
    pub above: usize,
    /// Water labels above the horizon turned into sky.
    pub water_to_sky: usize,
    /// Sky labels below the horizon turned into water (sky reflections).
    pub sky_to_water: usize,
}

impl Horizon {
    /// Per pixel: true above the horizon (ray z ≥ 0 in the map frame).
    pub fn above_mask(&self, width: usize, height: usize) -> Result<Vec<bool>> {
        match self {
            Horizon::Row(r) => Ok((0..width * height).map(|i| i / width.max(1) < *r).collect()),
            Horizon::Camera { camera, cam_to_map } => {
                if camera.width != width || camera.height != height {
                    return Err(Error::invalid(
                        "horizon camera",
                        format!(
                            "camera model is {} × {}, image is {width} × {height}",
                            camera.width, camera.height
                        ),
                    ));
                }
                if !pose_is_finite(cam_to_map) {
                    return Err(Error::invalid(
                        "horizon camera pose",
                        format!("{cam_to_map}"),
                    ));
                }
                // A pixel whose ray cannot be computed is treated as above the horizon
                // (it cannot be shown to see the ground).
                Ok(pixel_rays_in_map(camera, cam_to_map)
                    .into_iter()
                    .map(|r| r.is_none_or(|r| r.z >= 0.0))
                    .collect())
            }
        }
    }

    /// Labels above the horizon become sky. With `sky_below_is_water`, sky labels below the
    /// horizon become water: sky colour below the horizon is a reflection of the sky.
    pub fn apply(&self, labels: &mut LabelImage, sky_below_is_water: bool) -> Result<HorizonStats> {
        labels.validate()?;
        let above = self.above_mask(labels.width, labels.height)?;
        let mut st = HorizonStats::default();
        for (l, a) in labels.data.iter_mut().zip(above) {
            if a {
                st.above += 1;
                if *l == Label::Water {
                    st.water_to_sky += 1;
                }
                if *l != Label::Unknown {
                    *l = Label::Sky;
                }
            } else if sky_below_is_water && *l == Label::Sky {
                *l = Label::Water;
                st.sky_to_water += 1;
            }
        }
        Ok(st)
    }
}

/// Per-pixel geometry against the level plane z = `ground_z` (map frame).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct GroundGeometry {
    /// Image columns, pixels.
    pub width: usize,
    /// Image rows, pixels.
    pub height: usize,
    /// Angle between the ray and the plane's normal, radians; NaN where the ray misses.
    pub incidence: Vec<f32>,
    /// Distance along the ray to the plane, metres; NaN where the ray misses.
    pub range: Vec<f32>,
    /// Horizontal distance from the camera to the hit, metres (the lookahead); NaN on a miss.
    pub lookahead: Vec<f32>,
    /// The pixel that sees what level water at the hit mirrors ([`mirror_pixel`]);
    /// `u32::MAX` on a miss or where the mirror direction leaves the image.
    pub mirror: Vec<u32>,
}

impl GroundGeometry {
    /// Rays of `camera` at `cam_to_map` against the plane z = `ground_z` (the tests' ground;
    /// the labels cast their own rays, [`GroundGeometry::of_rays`]).
    #[cfg(test)]
    pub(crate) fn level(camera: &CameraModel, cam_to_map: &Pose, ground_z: f64) -> Result<Self> {
        if !pose_is_finite(cam_to_map) || !ground_z.is_finite() {
            return Err(Error::invalid(
                "ground geometry",
                format!("pose {cam_to_map}, ground z {ground_z} must be finite"),
            ));
        }
        let rays = pixel_rays_in_map(camera, cam_to_map);
        Ok(Self::of_rays(camera, &rays, cam_to_map, ground_z))
    }

    /// The same from the pixels' rays in the map frame (`camera`'s at `cam_to_map`), as a
    /// caller that keeps them between frames has them.
    pub(crate) fn of_rays(
        camera: &CameraModel,
        map_rays: &[Option<Vector3<f64>>],
        cam_to_map: &Pose,
        ground_z: f64,
    ) -> Self {
        let n = map_rays.len();
        let (mut incidence, mut range, mut lookahead) =
            (vec![f32::NAN; n], vec![f32::NAN; n], vec![f32::NAN; n]);
        let mut mirror = vec![u32::MAX; n];
        let to_cam = cam_to_map.rotation.inverse();
        let h = cam_to_map.translation.vector.z - ground_z;
        if h > 0.0 {
            for (i, r) in map_rays.iter().enumerate() {
                let Some(r) = r else { continue };
                if r.z < 0.0 {
                    let t = h / -r.z;
                    incidence[i] = (-r.z).clamp(0.0, 1.0).acos() as f32;
                    range[i] = t as f32;
                    lookahead[i] = (t * r.xy().norm()) as f32;
                    mirror[i] = mirror_pixel(camera, &to_cam, r)
                        .and_then(|j| u32::try_from(j).ok())
                        .unwrap_or(u32::MAX);
                }
            }
        }
        GroundGeometry {
            width: camera.width,
            height: camera.height,
            incidence,
            range,
            lookahead,
            mirror,
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geom::{pose_xyz_rpy, Distortion};
    use proptest::prelude::*;

    pub(crate) fn cam_pose(z: f64, pitch_down: f64) -> Pose {
        optical_pose(&pose_xyz_rpy(0.0, 0.0, z, 0.0, pitch_down, 0.0))
    }

    #[test]
    fn level_camera_horizon_is_the_principal_row() {
        let cam =
            CameraModel::new(64, 48, [50.0, 50.0, 31.5, 20.0], Distortion::None, "c").unwrap();
        let above = Horizon::Camera {
            camera: cam,
            cam_to_map: cam_pose(1.5, 0.0),
        }
        .above_mask(64, 48)
        .unwrap();
        for y in 0..48 {
            assert_eq!(above[y * 64 + 10], y <= 20, "row {y}");
        }
    }

    #[test]
    fn apply_moves_labels() {
        let mut l = LabelImage::filled(2, 4, Label::Water);
        l.data[6] = Label::Sky;
        let st = Horizon::Row(2).apply(&mut l, true).unwrap();
        assert_eq!(
            st,
            HorizonStats {
                above: 4,
                water_to_sky: 4,
                sky_to_water: 1
            }
        );
        assert_eq!(&l.data[..4], &[Label::Sky; 4]);
        assert_eq!(&l.data[4..], &[Label::Water; 4]);
        assert!(Horizon::Camera {
            camera: CameraModel::new(3, 3, [1.0, 1.0, 1.0, 1.0], Distortion::None, "c").unwrap(),
            cam_to_map: Pose::identity()
        }
        .apply(&mut l, false)
        .is_err());
    }

    /// A level pinhole camera sees the mirror of row v at row 2·cy − v, in the same column;
    /// above the horizon (no hit) and where the mirror leaves the image there is none.
    #[test]
    fn mirror_pixel_of_a_level_camera_is_the_row_reflected_about_the_horizon() {
        let cam =
            CameraModel::new(64, 48, [50.0, 50.0, 31.0, 30.0], Distortion::None, "c").unwrap();
        let g = GroundGeometry::level(&cam, &cam_pose(1.5, 0.0), 0.0).unwrap();
        // Row 30 looks along the horizon itself, where rounding decides.
        for v in (0..48usize).filter(|&v| v != 30) {
            for u in [0usize, 17, 63] {
                let m = g.mirror[v * 64 + u];
                if v > 30 {
                    assert_eq!(m as usize, (60 - v) * 64 + u, "row {v} column {u}");
                } else {
                    assert_eq!(m, u32::MAX, "row {v} column {u}");
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(32))]
        /// Pitching the camera down by θ moves the horizon up by fy·tan θ rows (before
        /// distortion). k1 ≥ −0.1 keeps the image inside the monotonic part of the distortion
        /// polynomial (beyond its fold `CameraModel::undistort` can converge on the wrong
        /// branch).
        #[test]
        fn pitch_moves_horizon(pitch in -0.3f64..0.3, k1 in -0.1f64..0.2) {
            let cam = CameraModel::new(40, 200, [100.0, 100.0, 19.5, 99.5], Distortion::PlumbBob([k1, 0.0, 0.0, 0.0, 0.0]), "c").unwrap();
            let above = Horizon::Camera { camera: cam.clone(), cam_to_map: cam_pose(2.0, pitch) }.above_mask(40, 200).unwrap();
            // The horizon on the central column (x = cx) is where the ray's elevation is 0:
            // undistorted y/z = −tan(pitch) → the distorted row for that point.
            let yu = -pitch.tan();
            let yd = cam.distort(0.0, yu)[1];
            let row = 100.0 * yd + 99.5;
            for y in 0..200usize {
                if (y as f64 - row).abs() > 0.51 {
                    prop_assert_eq!(above[y * 40 + 20], (y as f64) < row, "row {} horizon {}", y, row);
                }
            }
        }

        #[test]
        fn ground_geometry_range_and_incidence(pitch in 0.05f64..0.6, z in 0.5f64..4.0) {
            let cam = CameraModel::new(8, 8, [4.0, 4.0, 3.5, 3.5], Distortion::None, "c").unwrap();
            let g = GroundGeometry::level(&cam, &cam_pose(z, pitch), 0.0).unwrap();
            // The ray through the principal point points down by `pitch`: incidence = 90° − pitch.
            // (3.5, 3.5) is not a pixel centre; check every hit instead: t·(−r_z) = z.
            for i in 0..64 {
                if g.range[i].is_finite() {
                    let inc = g.incidence[i] as f64;
                    prop_assert!((g.range[i] as f64 * inc.cos() - z).abs() < 1e-3 * z);
                    prop_assert!((g.lookahead[i] as f64 - g.range[i] as f64 * inc.sin()).abs() < 1e-3 * z);
                }
            }
        }
    }
}
