//! A pinhole camera with lens distortion, as ROS `sensor_msgs/CameraInfo` describes it:
//! intrinsics K (fx, fy, cx, cy) and a distortion model, either `plumb_bob`
//! (Brown–Conrady: k1 k2 p1 p2 k3) or `equidistant` (fisheye: k1 k2 k3 k4).
//!
//! Coordinates are in the camera's optical frame (z forward, x right, y down); pixel
//! (0, 0) is the centre of the top-left pixel, as in OpenCV and ROS.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::error::{Error, Result};

/// Lens distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Distortion {
    /// No distortion (a pinhole camera).
    None,
    /// `plumb_bob`: [k1, k2, p1, p2, k3].
    PlumbBob([f64; 5]),
    /// `equidistant` (OpenCV fisheye): [k1, k2, k3, k4].
    Equidistant([f64; 4]),
}

/// A calibrated camera.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraModel {
    /// Image columns, pixels.
    pub width: usize,
    /// Image rows, pixels.
    pub height: usize,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Lens distortion model and coefficients.
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
        self.undistort_within(xd, yd, self.fold_radius())
    }

    /// The plumb_bob model's fold radius ([`plumb_bob_fold_radius`]); infinite for the others.
    pub(crate) fn fold_radius(&self) -> f64 {
        match self.distortion {
            Distortion::PlumbBob([k1, k2, _, _, k3]) => plumb_bob_fold_radius(k1, k2, k3),
            _ => f64::INFINITY,
        }
    }

    /// [`Self::undistort`] with the fold radius given, so that a whole image pays for it once.
    fn undistort_within(&self, xd: f64, yd: f64, r_max: f64) -> Option<[f64; 2]> {
        if !(xd.is_finite() && yd.is_finite()) {
            return None;
        }
        match self.distortion {
            // ROS drivers of undistorted cameras publish plumb_bob with zero coefficients.
            Distortion::None | Distortion::PlumbBob([0.0, 0.0, 0.0, 0.0, 0.0]) => Some([xd, yd]),
            Distortion::PlumbBob([k1, k2, p1, p2, k3]) => {
                // Strong barrel distortion folds the image: r·(1 + k1 r² + k2 r⁴ + k3 r⁶)
                // rises to a maximum at `r_max` and falls beyond it, so a distorted point has
                // a second preimage outside the lens's valid field. Start from the inverse of
                // the radial part on its rising branch and keep only solutions on it.
                let radial = |r: f64| {
                    let s = r * r;
                    r * (1.0 + s * (k1 + s * (k2 + s * k3)))
                };
                let rd = xd.hypot(yd);
                let r0 = if rd < 1e-15 {
                    0.0
                } else {
                    // radial(r) − rd is increasing on [0, hi]: Newton's steps kept inside a
                    // shrinking bracket (a bisection step where Newton would leave it).
                    let hi = if r_max.is_finite() {
                        r_max
                    } else {
                        let mut h = rd.max(1.0);
                        while radial(h) < rd && h < 1e6 {
                            h *= 2.0;
                        }
                        h
                    };
                    if radial(hi) < rd {
                        // Beyond the radial part's maximum: the tangential terms can still
                        // reach it from inside the fold (p·3r² is ~1 % of r near the fold),
                        // so start at the fold and let Newton and the final check decide.
                        hi
                    } else {
                        let (mut lo, mut hi) = (0.0, hi);
                        let mut r = rd.min(hi);
                        for _ in 0..100 {
                            let f = radial(r) - rd;
                            if f < 0.0 {
                                lo = r;
                            } else {
                                hi = r;
                            }
                            let s = r * r;
                            let df = 1.0 + s * (3.0 * k1 + s * (5.0 * k2 + s * 7.0 * k3));
                            let next = r - f / df;
                            let next = if next > lo && next < hi && df > 0.0 {
                                next
                            } else {
                                0.5 * (lo + hi)
                            };
                            if (next - r).abs() <= 1e-15 * r.max(1e-300) || hi - lo <= 1e-15 * hi {
                                r = next;
                                break;
                            }
                            r = next;
                        }
                        r
                    }
                };
                let (mut a, mut b) = if rd < 1e-15 {
                    (xd, yd)
                } else {
                    (xd * r0 / rd, yd * r0 / rd)
                };
                for _ in 0..50 {
                    let [fa, fb] = self.distort(a, b);
                    let (ea, eb) = (fa - xd, fb - yd);
                    if ea.abs() < 1e-14 && eb.abs() < 1e-14 {
                        break;
                    }
                    // The distortion's Jacobian, in closed form.
                    let s = a * a + b * b;
                    let radial = 1.0 + s * (k1 + s * (k2 + s * k3));
                    let dr = 2.0 * (k1 + s * (2.0 * k2 + s * 3.0 * k3));
                    let j11 = radial + a * a * dr + 2.0 * p1 * b + 6.0 * p2 * a;
                    let j12 = a * b * dr + 2.0 * p1 * a + 2.0 * p2 * b;
                    let j21 = j12;
                    let j22 = radial + b * b * dr + 6.0 * p1 * b + 2.0 * p2 * a;
                    let det = j11 * j22 - j12 * j21;
                    if det.abs() < 1e-12 || !det.is_finite() {
                        return None;
                    }
                    a -= (j22 * ea - j12 * eb) / det;
                    b -= (-j21 * ea + j11 * eb) / det;
                }
                let [fa, fb] = self.distort(a, b);
                ((fa - xd).hypot(fb - yd) < 1e-9 && a.hypot(b) <= r_max).then_some([a, b])
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
        self.pixel_ray_within(u, v, self.fold_radius())
    }

    fn pixel_ray_within(&self, u: f64, v: f64, r_max: f64) -> Option<Vector3<f64>> {
        let [a, b] =
            self.undistort_within((u - self.cx) / self.fx, (v - self.cy) / self.fy, r_max)?;
        Some(Vector3::new(a, b, 1.0).normalize())
    }

    /// [`Self::pixel_ray`] of every pixel, row-major (rows in parallel; the same rays
    /// whatever the thread count).
    pub fn pixel_rays(&self) -> Vec<Option<Vector3<f64>>> {
        let (w, r_max) = (self.width.max(1), self.fold_radius());
        (0..self.width * self.height)
            .into_par_iter()
            .map(|i| self.pixel_ray_within((i % w) as f64, (i / w) as f64, r_max))
            .collect()
    }
}

/// Smallest r > 0 where the plumb_bob radial map r·(1 + k1 r² + k2 r⁴ + k3 r⁶) stops rising
/// (its derivative 1 + 3k1 r² + 5k2 r⁴ + 7k3 r⁶ reaches 0); infinite when it never does.
pub(crate) fn plumb_bob_fold_radius(k1: f64, k2: f64, k3: f64) -> f64 {
    // g(s) = 1 + 3k1 s + 5k2 s² + 7k3 s³ in s = r², g(0) = 1. Split [0, ∞) at the stationary
    // points of g (roots of g' = 3k1 + 10k2 s + 21k3 s²) into monotone pieces and bisect the
    // first piece whose end is ≤ 0.
    let g = |s: f64| 1.0 + s * (3.0 * k1 + s * (5.0 * k2 + s * 7.0 * k3));
    let (qa, qb, qc) = (21.0 * k3, 10.0 * k2, 3.0 * k1);
    let mut cuts: Vec<f64> = Vec::new();
    if qa.abs() > 1e-300 {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            cuts.extend([(-qb - sq) / (2.0 * qa), (-qb + sq) / (2.0 * qa)]);
        }
    } else if qb.abs() > 1e-300 {
        cuts.push(-qc / qb);
    }
    cuts.retain(|c| c.is_finite() && *c > 0.0);
    cuts.sort_by(f64::total_cmp);
    // The last piece: far enough out that g has its leading sign.
    let mut far = cuts.last().copied().unwrap_or(0.0).max(1.0);
    for _ in 0..200 {
        if g(far) <= 0.0 {
            break;
        }
        far *= 2.0;
    }
    cuts.push(far);
    let mut lo = 0.0;
    for hi in cuts {
        if g(hi) <= 0.0 {
            let (mut a, mut b) = (lo, hi);
            for _ in 0..100 {
                let m = 0.5 * (a + b);
                if g(m) > 0.0 {
                    a = m;
                } else {
                    b = m;
                }
            }
            return (0.5 * (a + b)).sqrt();
        }
        lo = hi;
    }
    f64::INFINITY
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

    #[test]
    fn pixel_rays_are_the_pixel_ray_of_every_pixel() {
        for d in [
            Distortion::PlumbBob([-0.3, 0.1, 0.001, -0.002, 0.0]),
            Distortion::PlumbBob([0.0; 5]),
            Distortion::Equidistant([0.1, -0.01, 0.0, 0.0]),
        ] {
            let c = CameraModel::new(33, 17, [20.0, 21.0, 16.0, 8.0], d, "cam").unwrap();
            let rays = c.pixel_rays();
            assert_eq!(rays.len(), 33 * 17);
            for (i, r) in rays.iter().enumerate() {
                assert_eq!(
                    *r,
                    c.pixel_ray((i % 33) as f64, (i / 33) as f64),
                    "{d:?} {i}"
                );
            }
        }
        // A zero plumb_bob (what ROS publishes for an undistorted camera) is no distortion.
        let (z, n) = (cam(Distortion::PlumbBob([0.0; 5])), cam(Distortion::None));
        for (u, v) in [(0.0, 0.0), (319.5, 239.5), (639.0, 13.0), (-2000.0, 9000.0)] {
            assert_eq!(z.pixel_ray(u, v), n.pixel_ray(u, v));
        }
    }

    #[test]
    fn fold_radius_of_known_lenses() {
        // k1 only: 1 + 3 k1 r² = 0 → r = sqrt(−1 / 3k1).
        assert!((plumb_bob_fold_radius(-0.3, 0.0, 0.0) - (1.0f64 / 0.9).sqrt()).abs() < 1e-12);
        assert!(plumb_bob_fold_radius(0.1, 0.01, 0.0).is_infinite());
        // k2 only, negative: 1 + 5 k2 r⁴ = 0.
        assert!((plumb_bob_fold_radius(0.0, -0.2, 0.0) - 1.0).abs() < 1e-12);
    }

    proptest! {
        /// Project a point inside the lens's valid field (inside the fold radius of strong
        /// barrel distortion), then undistort its pixel: the same ray, not the fold's other
        /// branch.
        #[test]
        fn plumb_bob_project_then_undistort_strong_barrel(
            fr in 0.0f64..0.97, ang in 0.0f64..std::f64::consts::TAU,
            k1 in -0.6f64..-0.15, k2 in -0.05f64..0.15, k3 in -0.02f64..0.02,
            p1 in -0.002f64..0.002, p2 in -0.002f64..0.002,
        ) {
            let c = cam(Distortion::PlumbBob([k1, k2, p1, p2, k3]));
            let r_fold = plumb_bob_fold_radius(k1, k2, k3).min(3.0);
            let r = fr * r_fold;
            let p = Point3::new(r * ang.cos(), r * ang.sin(), 1.0);
            // The valid field is where the distortion map keeps its orientation: with the
            // tangential terms the 2-D map can fold before the radial fold radius where the
            // radial slope nearly vanishes (k1 = −0.48, k2 = 0.13: slope 0.002 at r = 1.3).
            let det = |t: f64| {
                let (a, b, h) = (t * ang.cos(), t * ang.sin(), 1e-6);
                let f = c.distort(a, b);
                let (fa, fb) = (c.distort(a + h, b), c.distort(a, b + h));
                ((fa[0] - f[0]) * (fb[1] - f[1]) - (fb[0] - f[0]) * (fa[1] - f[1])) / (h * h)
            };
            prop_assume!((0..=200).all(|i| det(r * i as f64 / 200.0) > 0.02));
            let [u, v] = c.project(&p).unwrap();
            let ray = c.pixel_ray(u, v);
            prop_assert!(ray.is_some(), "no ray for r = {r} (fold {r_fold}) at ({u}, {v})");
            let ray = ray.unwrap();
            prop_assert!((ray - p.coords.normalize()).norm() < 1e-7, "{ray} vs {p}");
        }

        /// Every pixel of a strongly distorted 640 × 480 image either has a ray that projects
        /// back to it on the valid branch, or none (beyond the fold).
        #[test]
        fn plumb_bob_pixels_round_trip_on_the_valid_branch(
            u in 0.0f64..640.0, v in 0.0f64..480.0, k1 in -0.6f64..-0.15,
        ) {
            let c = cam(Distortion::PlumbBob([k1, 0.0, 0.0, 0.0, 0.0]));
            if let Some(r) = c.pixel_ray(u, v) {
                let [pu, pv] = c.project(&Point3::from(r * 5.0)).unwrap();
                prop_assert!((pu - u).abs() < 1e-6 && (pv - v).abs() < 1e-6);
                prop_assert!((r.x / r.z).hypot(r.y / r.z) <= plumb_bob_fold_radius(k1, 0.0, 0.0) + 1e-9);
            }
        }

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
