//! A pinhole camera with lens distortion, as ROS `sensor_msgs/CameraInfo` describes it:
//! intrinsics K (fx, fy, cx, cy) and a distortion model, either `plumb_bob`
//! (Brown–Conrady: k1 k2 p1 p2 k3) or `equidistant` (fisheye: k1 k2 k3 k4).
//!
//! Coordinates are in the camera's optical frame (z forward, x right, y down); pixel
//! (0, 0) is the centre of the top-left pixel, as in OpenCV and ROS.

use nalgebra::{Point3, Vector3};

use crate::error::{Error, Result};

/// Lens distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Distortion {
    None,
    /// `plumb_bob`: [k1, k2, p1, p2, k3].
    PlumbBob([f64; 5]),
    /// `equidistant` (OpenCV fisheye): [k1, k2, k3, k4].
    Equidistant([f64; 4]),
}

/// A calibrated camera.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraModel {
    pub width: usize,
    pub height: usize,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub distortion: Distortion,
    /// The optical frame the model lives in.
    pub frame_id: String,
}

impl CameraModel {
    /// Checks that focal lengths are positive and everything is finite.
    pub fn new(
        width: usize,
        height: usize,
        [fx, fy, cx, cy]: [f64; 4],
        distortion: Distortion,
        frame_id: impl Into<String>,
    ) -> Result<Self> {
        let coeffs: &[f64] = match &distortion {
            Distortion::None => &[],
            Distortion::PlumbBob(c) => c,
            Distortion::Equidistant(c) => c,
        };
        let ok = fx > 0.0
            && fy > 0.0
            && [fx, fy, cx, cy].iter().all(|v| v.is_finite())
            && coeffs.iter().all(|v| v.is_finite());
        if !ok {
            return Err(Error::invalid(
                "camera model",
                format!("fx {fx}, fy {fy} must be positive and finite; cx {cx}, cy {cy} and distortion {coeffs:?} finite"),
            ));
        }
        Ok(CameraModel {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            distortion,
            frame_id: frame_id.into(),
        })
    }

    /// [fx, fy, cx, cy].
    pub fn intrinsics(&self) -> [f64; 4] {
        [self.fx, self.fy, self.cx, self.cy]
    }

    /// Normalized undistorted image coordinates (x/z, y/z) → distorted normalized ones.
    pub fn distort(&self, a: f64, b: f64) -> [f64; 2] {
        match self.distortion {
            Distortion::None => [a, b],
            Distortion::PlumbBob([k1, k2, p1, p2, k3]) => {
                let r2 = a * a + b * b;
                let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
                [
                    a * radial + 2.0 * p1 * a * b + p2 * (r2 + 2.0 * a * a),
                    b * radial + p1 * (r2 + 2.0 * b * b) + 2.0 * p2 * a * b,
                ]
            }
            Distortion::Equidistant(k) => {
                let r = (a * a + b * b).sqrt();
                if r < 1e-12 {
                    return [a, b];
                }
                let th = r.atan();
                let s = r_of_theta(th, &k) / r;
                [a * s, b * s]
            }
        }
    }

    /// Inverse of [`Self::distort`], by Newton iteration; `None` where it does not converge
    /// (far outside the calibrated field of view).
    pub fn undistort(&self, xd: f64, yd: f64) -> Option<[f64; 2]> {
        if !(xd.is_finite() && yd.is_finite()) {
            return None;
        }
        match self.distortion {
            Distortion::None => Some([xd, yd]),
            Distortion::PlumbBob(_) => {
                let (mut a, mut b) = (xd, yd);
                for _ in 0..50 {
                    let [fa, fb] = self.distort(a, b);
                    let (ea, eb) = (fa - xd, fb - yd);
                    if ea.abs() < 1e-14 && eb.abs() < 1e-14 {
                        return Some([a, b]);
                    }
                    // Numerical Jacobian (the function is a smooth polynomial).
                    let h = 1e-7;
                    let [aa, ab] = self.distort(a + h, b);
                    let [ba, bb] = self.distort(a, b + h);
                    let (j11, j21, j12, j22) =
                        ((aa - fa) / h, (ab - fb) / h, (ba - fa) / h, (bb - fb) / h);
                    let det = j11 * j22 - j12 * j21;
                    if det.abs() < 1e-12 || !det.is_finite() {
                        return None;
                    }
                    a -= (j22 * ea - j12 * eb) / det;
                    b -= (-j21 * ea + j11 * eb) / det;
                }
                let [fa, fb] = self.distort(a, b);
                ((fa - xd).hypot(fb - yd) < 1e-9).then_some([a, b])
            }
            Distortion::Equidistant(k) => {
                let rd = (xd * xd + yd * yd).sqrt();
                if rd < 1e-12 {
                    return Some([xd, yd]);
                }
                let mut th = rd.min(1.5);
                for _ in 0..50 {
                    let f = r_of_theta(th, &k) - rd;
                    let t2 = th * th;
                    let df = 1.0
                        + t2 * (3.0 * k[0]
                            + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])));
                    if df <= 0.0 || !df.is_finite() {
                        return None;
                    }
                    let step = f / df;
                    th -= step;
                    if step.abs() < 1e-15 {
                        break;
                    }
                }
                if !(0.0..std::f64::consts::FRAC_PI_2).contains(&th)
                    || (r_of_theta(th, &k) - rd).abs() > 1e-9
                {
                    return None;
                }
                let s = th.tan() / rd;
                Some([xd * s, yd * s])
            }
        }
    }

    /// Pixel of a point in the optical frame; `None` behind the camera (z ≤ 0).
    pub fn project(&self, p: &Point3<f64>) -> Option<[f64; 2]> {
        if p.z.is_nan() || p.z <= 0.0 {
            return None;
        }
        let [xd, yd] = self.distort(p.x / p.z, p.y / p.z);
        Some([self.fx * xd + self.cx, self.fy * yd + self.cy])
    }

    /// Unit ray (optical frame) through pixel (u, v); `None` where undistortion fails.
    pub fn pixel_ray(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        let [a, b] = self.undistort((u - self.cx) / self.fx, (v - self.cy) / self.fy)?;
        Some(Vector3::new(a, b, 1.0).normalize())
    }
}

/// Equidistant model: distorted radius θ_d(θ) = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸).
fn r_of_theta(th: f64, k: &[f64; 4]) -> f64 {
    let t2 = th * th;
    th * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cam(d: Distortion) -> CameraModel {
        CameraModel::new(640, 480, [500.0, 510.0, 319.5, 239.5], d, "cam").unwrap()
    }

    #[test]
    fn centre_pixel_looks_forward() {
        let c = cam(Distortion::PlumbBob([-0.3, 0.1, 0.001, -0.002, 0.0]));
        let r = c.pixel_ray(319.5, 239.5).unwrap();
        assert!((r - Vector3::z()).norm() < 1e-12);
    }

    #[test]
    fn known_plumb_bob_value() {
        // Radial only, k1 = 0.1: x = 0.2, y = 0 → r² = 0.04, x_d = 0.2·1.004 = 0.2008.
        let c = cam(Distortion::PlumbBob([0.1, 0.0, 0.0, 0.0, 0.0]));
        let [u, v] = c.project(&Point3::new(0.2, 0.0, 1.0)).unwrap();
        assert!((u - (500.0 * 0.2008 + 319.5)).abs() < 1e-9);
        assert!((v - 239.5).abs() < 1e-12);
    }

    #[test]
    fn known_equidistant_value() {
        // No coefficients: x_d = atan(r) along the ray direction.
        let c = cam(Distortion::Equidistant([0.0; 4]));
        let [u, _] = c.project(&Point3::new(1.0, 0.0, 1.0)).unwrap();
        assert!((u - (500.0 * std::f64::consts::FRAC_PI_4 + 319.5)).abs() < 1e-9);
    }

    #[test]
    fn behind_camera_does_not_project() {
        assert!(cam(Distortion::None)
            .project(&Point3::new(0.0, 0.0, -1.0))
            .is_none());
    }

    #[test]
    fn rejects_bad_intrinsics() {
        assert!(CameraModel::new(1, 1, [0.0, 1.0, 0.0, 0.0], Distortion::None, "c").is_err());
        assert!(CameraModel::new(1, 1, [1.0, 1.0, f64::NAN, 0.0], Distortion::None, "c").is_err());
    }

    proptest! {
        #[test]
        fn plumb_bob_round_trip(
            u in 0.0f64..640.0, v in 0.0f64..480.0,
            k1 in -0.3f64..0.3, k2 in -0.1f64..0.1, p1 in -0.005f64..0.005,
            p2 in -0.005f64..0.005, k3 in -0.02f64..0.02,
        ) {
            let c = cam(Distortion::PlumbBob([k1, k2, p1, p2, k3]));
            if let Some(r) = c.pixel_ray(u, v) {
                let [pu, pv] = c.project(&Point3::from(r * 7.0)).unwrap();
                prop_assert!((pu - u).abs() < 1e-6 && (pv - v).abs() < 1e-6, "{pu} {pv}");
            } else {
                // Undistortion may only fail for strong barrel distortion near the corners.
                prop_assert!(k1 < 0.0 || k2 < 0.0 || k3 < 0.0);
            }
        }

        #[test]
        fn equidistant_round_trip(
            x in -1.5f64..1.5, y in -1.0f64..1.0,
            k1 in -0.05f64..0.05, k2 in -0.01f64..0.01, k3 in -0.005f64..0.005, k4 in -0.001f64..0.001,
        ) {
            let c = cam(Distortion::Equidistant([k1, k2, k3, k4]));
            let p = Point3::new(x, y, 1.0);
            let [u, v] = c.project(&p).unwrap();
            let r = c.pixel_ray(u, v).unwrap();
            prop_assert!((r - p.coords.normalize()).norm() < 1e-9);
        }
    }
}
