//! Frames, poses and point clouds (REP-103: x forward, y left, z up; metres, radians).
//!
//! Poses are `Isometry3<f64>`. Points are stored as `f32` *relative to their cloud's frame*
//! (a sensor frame, or a local origin chosen by a reader), never as absolute UTM-scale
//! coordinates in `f32`; [`PointCloud::frame_to_map`] carries the large part in `f64`.
//!
//! Exports: [`Pose`] and [`pose_xyz_rpy`], [`PointCloud`], the pinhole [`CameraModel`] with
//! its [`Distortion`], and the helpers [`hypot`] and [`direction`].

mod camera;

pub use camera::{CameraModel, Distortion};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::error::{Error, Result};

/// A rigid transform; `a_to_b` maps coordinates in frame `a` to frame `b`.
pub type Pose = Isometry3<f64>;

/// A pose from a translation and roll, pitch, yaw (radians, applied as yaw·pitch·roll).
pub fn pose_xyz_rpy(x: f64, y: f64, z: f64, roll: f64, pitch: f64, yaw: f64) -> Pose {
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    )
}

/// `x.hypot(y)` for the magnitudes of a map (far from overflow and underflow), as one
/// square root instead of a call into libm: the libm `hypot` was 10 % of the lidar cue's
/// profile. A proptest holds the two within two ulps of each other.
#[inline(always)]
pub fn hypot(x: f64, y: f64) -> f64 {
    (x * x + y * y).sqrt()
}

/// `v.floor() as i64`, bit for bit (NaN → 0, saturating), without a call: the x86-64
/// baseline has no rounding instruction, and `f64::floor` there is a software routine that
/// showed as 4 % of a full-frame build in the label ray march. (Inside a function built
/// with AVX2, `f64::floor` is one instruction and vectorises: keep it there.)
#[inline(always)]
pub(crate) fn floor_i64(v: f64) -> i64 {
    let t = v as i64;
    t.saturating_sub((v < t as f64) as i64)
}

/// `v.ceil() as i64`, bit for bit (NaN → 0, saturating), without a call: see
/// [`floor_i64`].
#[inline(always)]
pub(crate) fn ceil_i64(v: f64) -> i64 {
    let t = v as i64;
    t.saturating_add((v > t as f64) as i64)
}

/// `floor(v / res)` computed with a multiply by `inv = 1 / res`. The product differs from
/// the correctly rounded quotient by at most a few ulps (relative 2⁻⁵¹, under 10⁻⁶ for
/// |q| < 10⁹), so when the product's fraction is at least 10⁻⁶ from an integer both have
/// the same floor; otherwise (and for huge |q|) the division decides.
#[inline]
pub(crate) fn cell_coord(v: f64, inv: f64, res: f64) -> i64 {
    let q = v * inv;
    let f = floor_i64(q);
    let frac = q - f as f64;
    if frac > 1e-6 && frac < 1.0 - 1e-6 && q.abs() < 1e9 {
        f
    } else {
        floor_i64(v / res)
    }
}

/// True when every component of the pose is finite and the rotation is a unit quaternion.
pub(crate) fn pose_is_finite(p: &Pose) -> bool {
    let q = p.rotation.coords;
    p.translation.vector.iter().all(|v| v.is_finite())
        && q.iter().all(|v| v.is_finite())
        && (q.norm() - 1.0).abs() < 1e-6
}

/// A point cloud, organized (rows × cols, as a spinning lidar's rings × columns or a stereo
/// disparity image) or not (`rows == 1`). A missing return keeps its slot, with NaN
/// coordinates, so the beam it belongs to is still known.
#[derive(Debug, PartialEq)]
pub struct PointCloud {
    /// Rows (lidar rings, image rows); 1 for an unorganized cloud.
    pub rows: usize,
    /// Points per row.
    pub cols: usize,
    /// Coordinates in the cloud's frame; `[NaN; 3]` for a missing return.
    pub xyz: Vec<[f32; 3]>,
    /// Optional per-point intensity (sensor units).
    pub intensity: Option<Vec<f32>>,
    /// Optional per-point calibrated reflectivity (sensor units).
    pub reflectivity: Option<Vec<f32>>,
    /// Optional per-point colour.
    pub rgb: Option<Vec<[u8; 3]>>,
    /// Pose of the cloud's frame in the map frame.
    pub frame_to_map: Pose,
    /// Where the rays start (the sensor's optical centre), in the cloud's frame.
    pub sensor_origin: Point3<f64>,
    /// Acquisition time, seconds (0 when unknown).
    pub stamp: f64,
}

impl Clone for PointCloud {
    fn clone(&self) -> Self {
        let mut c = PointCloud::unorganized(Vec::new());
        c.clone_from(self);
        c
    }

    /// A copy of `source` in `self`'s storage (a scan's copy without fresh memory).
    fn clone_from(&mut self, source: &Self) {
        // Every field by name: a field added to the struct is an error here until copied.
        let PointCloud {
            rows,
            cols,
            xyz,
            intensity,
            reflectivity,
            rgb,
            frame_to_map,
            sensor_origin,
            stamp,
        } = source;
        self.rows = *rows;
        self.cols = *cols;
        self.xyz.clone_from(xyz);
        self.intensity.clone_from(intensity);
        self.reflectivity.clone_from(reflectivity);
        self.rgb.clone_from(rgb);
        self.frame_to_map = *frame_to_map;
        self.sensor_origin = *sensor_origin;
        self.stamp = *stamp;
    }
}

impl PointCloud {
    /// An unorganized cloud in the map frame, sensor at the origin of that frame.
    pub fn unorganized(xyz: Vec<[f32; 3]>) -> Self {
        let n = xyz.len();
        PointCloud {
            rows: 1,
            cols: n,
            xyz,
            intensity: None,
            reflectivity: None,
            rgb: None,
            frame_to_map: Pose::identity(),
            sensor_origin: Point3::origin(),
            stamp: 0.0,
        }
    }

    /// An organized cloud; `xyz.len()` must be `rows * cols`.
    pub fn organized(rows: usize, cols: usize, xyz: Vec<[f32; 3]>) -> Result<Self> {
        if rows.checked_mul(cols) != Some(xyz.len()) {
            return Err(Error::invalid(
                "point cloud",
                format!(
                    "{} points do not fill {rows} rows × {cols} columns",
                    xyz.len()
                ),
            ));
        }
        let mut c = Self::unorganized(xyz);
        c.rows = rows;
        c.cols = cols;
        Ok(c)
    }

    /// Number of points, missing returns included.
    pub fn len(&self) -> usize {
        self.xyz.len()
    }

    /// Whether the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.xyz.is_empty()
    }

    /// Whether the cloud has more than one row.
    pub fn is_organized(&self) -> bool {
        self.rows > 1
    }

    /// Index of (row, col) in an organized cloud.
    #[inline]
    pub fn index(&self, row: usize, col: usize) -> usize {
        row * self.cols + col
    }

    /// True when point `i` is a real return (all coordinates finite).
    #[inline]
    pub fn is_valid(&self, i: usize) -> bool {
        self.xyz[i].iter().all(|v| v.is_finite())
    }

    /// Number of real returns.
    pub fn valid_count(&self) -> usize {
        (0..self.len()).filter(|&i| self.is_valid(i)).count()
    }

    /// The sensor's optical centre in the map frame.
    pub fn sensor_origin_in_map(&self) -> Point3<f64> {
        self.frame_to_map * self.sensor_origin
    }

    /// Point `i` in the map frame (f64). Missing returns give NaN.
    #[inline]
    pub fn point_in_map(&self, i: usize) -> Point3<f64> {
        let [x, y, z] = self.xyz[i];
        self.frame_to_map * Point3::new(x as f64, y as f64, z as f64)
    }

    /// Checks internal consistency: lengths of optional channels, finite pose.
    pub fn validate(&self) -> Result<()> {
        let n = self.len();
        if self.rows.checked_mul(self.cols) != Some(n) {
            return Err(Error::invalid(
                "point cloud",
                format!("{n} points do not fill {} × {}", self.rows, self.cols),
            ));
        }
        for (name, len) in [
            ("intensity", self.intensity.as_ref().map(|v| v.len())),
            ("reflectivity", self.reflectivity.as_ref().map(|v| v.len())),
            ("rgb", self.rgb.as_ref().map(|v| v.len())),
        ] {
            if let Some(l) = len {
                if l != n {
                    return Err(Error::invalid(
                        "point cloud",
                        format!("{name} has {l} values for {n} points"),
                    ));
                }
            }
        }
        if !pose_is_finite(&self.frame_to_map) {
            return Err(Error::invalid(
                "point cloud pose",
                "frame_to_map is not finite",
            ));
        }
        if !self.sensor_origin.coords.iter().all(|v| v.is_finite()) {
            return Err(Error::invalid("point cloud", "sensor origin is not finite"));
        }
        Ok(())
    }
}

/// Unit vector helper: direction from `a` to `b`.
pub fn direction(a: &Point3<f64>, b: &Point3<f64>) -> Option<Vector3<f64>> {
    let d = b - a;
    let n = d.norm();
    (n > 0.0 && n.is_finite()).then(|| d / n)
}

#[cfg(test)]
mod tests {
    proptest::proptest! {
        /// Within two ulps of libm's `hypot` over the magnitudes a map has (1 µm to 100 km).
        #[test]
        fn hypot_is_libm_hypot(
            x in proptest::prop_oneof![-1e5f64..1e5, -1.0f64..1.0],
            y in proptest::prop_oneof![-1e5f64..1e5, -1e-6f64..1e-6],
        ) {
            let (a, b) = (super::hypot(x, y), x.hypot(y));
            proptest::prop_assert!((a - b).abs() <= 2.0 * f64::EPSILON * b, "{} vs {}", a, b);
        }

        #[test]
        fn floor_i64_is_floor_as_i64(v in proptest::num::f64::ANY) {
            proptest::prop_assert_eq!(super::floor_i64(v), v.floor() as i64);
        }

        #[test]
        fn ceil_i64_is_ceil_as_i64(v in proptest::num::f64::ANY) {
            proptest::prop_assert_eq!(super::ceil_i64(v), v.ceil() as i64);
        }
    }

    /// A copy into another cloud's storage (larger, with other optional fields) is the
    /// cloud, field for field.
    #[test]
    fn clone_from_is_a_clone() {
        let mut a = PointCloud::organized(2, 3, vec![[1.0, f32::NAN, 3.0]; 6]).unwrap();
        a.intensity = Some(vec![0.5; 6]);
        a.rgb = Some(vec![[1, 2, 3]; 6]);
        a.frame_to_map = pose_xyz_rpy(1.0, 2.0, 3.0, 0.1, 0.2, 0.3);
        a.sensor_origin = Point3::new(0.0, 0.0, 1.5);
        a.stamp = 12.5;
        let mut b = PointCloud::unorganized(vec![[9.0; 3]; 100]);
        b.reflectivity = Some(vec![7.0; 100]);
        b.clone_from(&a);
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
        assert_eq!(format!("{a:?}"), format!("{:?}", a.clone()));
    }

    #[test]
    fn floor_i64_edge_values() {
        for v in [
            0.0,
            -0.0,
            -0.5,
            0.5,
            -1.0,
            1e300,
            -1e300,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            i64::MAX as f64,
            i64::MIN as f64,
            -9.3e18,
            4503599627370495.5,
            -4503599627370495.5,
            9.3e18,
        ] {
            assert_eq!(super::floor_i64(v), v.floor() as i64, "{v}");
            assert_eq!(super::ceil_i64(v), v.ceil() as i64, "{v}");
        }
    }

    use super::*;

    #[test]
    fn organized_rejects_wrong_size() {
        assert!(PointCloud::organized(2, 3, vec![[0.0; 3]; 5]).is_err());
        assert!(PointCloud::organized(2, 3, vec![[0.0; 3]; 6]).is_ok());
    }

    #[test]
    fn missing_returns_keep_their_slot() {
        let c = PointCloud::organized(1, 3, vec![[1.0, 0.0, 0.0], [f32::NAN; 3], [2.0, 0.0, 0.0]])
            .unwrap();
        assert_eq!(c.len(), 3);
        assert_eq!(c.valid_count(), 2);
        assert!(!c.is_valid(1));
    }

    #[test]
    fn far_pose_keeps_centimetres() {
        // 5,000 km from the origin: f32 alone would have metre-level steps there.
        let mut c = PointCloud::unorganized(vec![[0.013, -0.021, 0.5]]);
        c.frame_to_map = pose_xyz_rpy(5.0e6, 4.0e6, 100.0, 0.0, 0.0, 0.0);
        let p = c.point_in_map(0);
        assert!((p.x - 5.0e6 - 0.013).abs() < 1e-6);
        assert!((p.y - 4.0e6 + 0.021).abs() < 1e-6);
    }

    #[test]
    fn nan_pose_is_rejected() {
        let mut c = PointCloud::unorganized(vec![[0.0; 3]]);
        c.frame_to_map.translation.vector.x = f64::NAN;
        assert!(c.validate().is_err());
    }
}
