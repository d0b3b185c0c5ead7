//! Bottom returns through a known flat water surface (the paper's Figure 5 red triangles).
//!
//! A lidar reports a range `r = c·t/2` as if the whole path were in air, along the direction
//! it fired. Through water the beam bends at the surface (Snell) and travels `n` times slower,
//! so the true bottom point lies on the refracted ray, at `L_w = (r − L_a)/n` past the
//! surface point. `n` is used both for refraction and for the speed of light (the group index
//! of water, ≈1.34 in the near infrared, differs from the phase index by under 1 %).

use nalgebra::{Point3, Vector3};

use crate::error::{Error, Result};

fn check_point(what: &str, p: &Point3<f64>) -> Result<()> {
    if p.coords.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(Error::invalid(what, format!("{p:?} is not finite")))
    }
}

fn check_common(sensor: &Point3<f64>, water_level_z: f64, n_water: f64) -> Result<()> {
    check_point("sensor origin", sensor)?;
    if !water_level_z.is_finite() {
        return Err(Error::invalid(
            "water level",
            format!("{water_level_z} is not finite"),
        ));
    }
    if !(n_water.is_finite() && n_water >= 1.0) {
        return Err(Error::invalid(
            "refractive index of water",
            format!("{n_water} is not a finite number ≥ 1"),
        ));
    }
    if sensor.z <= water_level_z {
        return Err(Error::invalid(
            "sensor origin",
            format!(
                "z = {} is not above the water level {water_level_z}",
                sensor.z
            ),
        ));
    }
    Ok(())
}

/// Maps a raw lidar point (measured as if through air) to the true point under a horizontal
/// water surface at height `water_level_z` (z up, same frame as both points). Points whose
/// range ends before the surface, or whose ray never descends to it, are returned unchanged.
pub fn correct_bottom_return(
    sensor_origin: Point3<f64>,
    raw_point: Point3<f64>,
    water_level_z: f64,
    n_water: f64,
) -> Result<Point3<f64>> {
    check_common(&sensor_origin, water_level_z, n_water)?;
    check_point("raw lidar point", &raw_point)?;
    let v = raw_point - sensor_origin;
    let range = v.norm();
    if range <= 0.0 {
        return Err(Error::invalid(
            "raw lidar point",
            "coincides with the sensor origin (zero range)",
        ));
    }
    let u = v / range;
    if u.z >= 0.0 {
        return Ok(raw_point);
    }
    let cos_i = -u.z;
    let l_air = (sensor_origin.z - water_level_z) / cos_i;
    if range <= l_air {
        return Ok(raw_point);
    }
    let l_water = (range - l_air) / n_water;
    let surface = sensor_origin + u * l_air;
    let cos_t = (1.0 - (1.0 - cos_i * cos_i) / (n_water * n_water)).sqrt();
    let t = u / n_water + Vector3::z() * (cos_i / n_water - cos_t);
    Ok(surface + t * l_water)
}

/// How the depth of a corrected bottom return changes with the water level assumed:
/// d(depth)/d(level) for the beam from `sensor_origin` through `raw_point`.
///
/// With the beam's incidence cos θᵢ = −u_z and cos θₜ from Snell, the corrected depth below a
/// level L is `depth(L) = cos θₜ·(r − (z_s − L)/cos θᵢ)/n`: linear in L, with slope
/// `cos θₜ/(n·cos θᵢ)` (1/n straight down, growing without bound toward grazing). A depth
/// measured against a provisional level L₀ is therefore exactly
/// `depth(L) = depth(L₀) + gain·(L − L₀)` against any other level the beam still crosses
/// before its range ends. `None` for a beam that does not descend.
pub fn bottom_depth_gain(
    sensor_origin: Point3<f64>,
    raw_point: Point3<f64>,
    n_water: f64,
) -> Option<f64> {
    let v = raw_point - sensor_origin;
    let range = v.norm();
    let cos_i = -v.z / range;
    if !(range > 0.0 && cos_i > 0.0 && n_water >= 1.0) {
        return None;
    }
    let cos_t = (1.0 - (1.0 - cos_i * cos_i) / (n_water * n_water)).sqrt();
    Some(cos_t / (n_water * cos_i))
}

/// The inverse of [`correct_bottom_return`]: where a lidar at `sensor_origin` reports a true
/// point `bottom` under the water surface at `water_level_z` (found by Fermat's principle).
/// Points at or above the water level are returned unchanged.
pub fn apparent_bottom_point(
    sensor_origin: Point3<f64>,
    bottom: Point3<f64>,
    water_level_z: f64,
    n_water: f64,
) -> Result<Point3<f64>> {
    check_common(&sensor_origin, water_level_z, n_water)?;
    check_point("bottom point", &bottom)?;
    if bottom.z >= water_level_z {
        return Ok(bottom);
    }
    let a = sensor_origin.z - water_level_z;
    let b = water_level_z - bottom.z;
    let dxy = Vector3::new(bottom.x - sensor_origin.x, bottom.y - sensor_origin.y, 0.0);
    let big_x = dxy.norm();
    // f(x) = sin θᵢ − n sin θₜ rises from ≤ 0 at x = 0 to ≥ 0 at x = X.
    let f = |x: f64| x / a.hypot(x) - n_water * (big_x - x) / b.hypot(big_x - x);
    let (mut lo, mut hi) = (0.0, big_x);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if f(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let x = 0.5 * (lo + hi);
    let dir_xy = if big_x > 0.0 { dxy / big_x } else { dxy };
    let surface = Point3::new(
        sensor_origin.x + dir_xy.x * x,
        sensor_origin.y + dir_xy.y * x,
        water_level_z,
    );
    let l_air = (surface - sensor_origin).norm();
    let l_water = (bottom - surface).norm();
    let u = (surface - sensor_origin) / l_air;
    Ok(sensor_origin + u * (l_air + n_water * l_water))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn straight_down_only_rescales_the_water_part() {
        let s = Point3::new(0.0, 0.0, 1.0);
        // 1 m of air, then 0.3 m of water reads as 0.3·1.33 m.
        let raw = Point3::new(0.0, 0.0, 1.0 - 1.0 - 0.3 * 1.33);
        let b = correct_bottom_return(s, raw, 0.0, 1.33).unwrap();
        assert!((b - Point3::new(0.0, 0.0, -0.3)).norm() < 1e-12, "{b:?}");
    }

    #[test]
    fn refracted_ray_obeys_snell_and_stays_in_plane() {
        let s = Point3::new(0.0, 0.0, 0.95);
        let raw = Point3::new(1.2, 0.4, -0.5);
        let b = correct_bottom_return(s, raw, 0.0, 1.33).unwrap();
        let u = (raw - s).normalize();
        let l_air = 0.95 / -u.z;
        let w = s + u * l_air;
        let t = (b - w).normalize();
        let sin_i = (1.0 - u.z * u.z).sqrt();
        let sin_t = (1.0 - t.z * t.z).sqrt();
        assert!((sin_i - 1.33 * sin_t).abs() < 1e-12);
        // Same azimuth.
        assert!((u.y * t.x - u.x * t.y).abs() < 1e-12);
        // The bottom is above the raw point: refraction bends toward the normal and light is slower.
        assert!(b.z > raw.z);
        // Path length: air + n · water = measured range.
        let r = (raw - s).norm();
        assert!((l_air + 1.33 * (b - w).norm() - r).abs() < 1e-12);
    }

    #[test]
    fn points_above_water_are_unchanged() {
        let s = Point3::new(0.0, 0.0, 1.0);
        let p = Point3::new(3.0, 0.0, 0.5);
        assert_eq!(correct_bottom_return(s, p, 0.0, 1.33).unwrap(), p);
        let up = Point3::new(3.0, 0.0, 2.0);
        assert_eq!(correct_bottom_return(s, up, 0.0, 1.33).unwrap(), up);
    }

    #[test]
    fn bad_input_is_an_error() {
        let s = Point3::new(0.0, 0.0, 1.0);
        let p = Point3::new(1.0, 0.0, -1.0);
        assert!(correct_bottom_return(s, s, 0.0, 1.33).is_err());
        assert!(correct_bottom_return(s, p, 2.0, 1.33).is_err());
        assert!(correct_bottom_return(s, p, f64::NAN, 1.33).is_err());
        assert!(correct_bottom_return(s, p, 0.0, 0.5).is_err());
        assert!(correct_bottom_return(Point3::new(f64::NAN, 0.0, 1.0), p, 0.0, 1.33).is_err());
        assert!(
            apparent_bottom_point(s, Point3::new(f64::INFINITY, 0.0, -1.0), 0.0, 1.33).is_err()
        );
    }

    #[test]
    fn depth_gain_is_one_over_n_straight_down_and_grows_toward_grazing() {
        let s = Point3::new(0.0, 0.0, 1.0);
        let down = bottom_depth_gain(s, Point3::new(0.0, 0.0, -1.0), 1.33).unwrap();
        assert!((down - 1.0 / 1.33).abs() < 1e-12);
        // 1.2 m down over 10 m: cos θᵢ = 1.2/√101.44, sin θₜ = sin θᵢ/1.33.
        let oblique = bottom_depth_gain(s, Point3::new(10.0, 0.0, -0.2), 1.33).unwrap();
        let cos_i = 1.2 / 101.44f64.sqrt();
        let sin_t = (1.0 - cos_i * cos_i).sqrt() / 1.33;
        let expected = (1.0 - sin_t * sin_t).sqrt() / (1.33 * cos_i);
        assert!(
            (oblique - expected).abs() < 1e-12,
            "{oblique} vs {expected}"
        );
        assert!(
            oblique > 5.0 * down,
            "grazing beams must amplify level errors: {oblique}"
        );
        assert!(bottom_depth_gain(s, Point3::new(3.0, 0.0, 1.0), 1.33).is_none());
        assert!(bottom_depth_gain(s, s, 1.33).is_none());
    }

    proptest! {
        #[test]
        fn correction_inverts_the_forward_model(
            sx in -5.0f64..5.0, sy in -5.0f64..5.0, h in 0.2f64..3.0,
            bx in -20.0f64..20.0, by in -20.0f64..20.0, depth in 0.001f64..3.0,
            level in -2.0f64..2.0, n in 1.0f64..1.6,
        ) {
            let s = Point3::new(sx, sy, level + h);
            let bottom = Point3::new(bx, by, level - depth);
            let raw = apparent_bottom_point(s, bottom, level, n).unwrap();
            let back = correct_bottom_return(s, raw, level, n).unwrap();
            prop_assert!((back - bottom).norm() < 1e-8 * (1.0 + (bottom - s).norm()),
                "{bottom:?} -> {raw:?} -> {back:?}");
        }

        /// The depth of one raw return against two different levels differs by exactly the
        /// gain times the difference of the levels (the water stage relies on this to move
        /// a cue's depth onto the body's surface).
        #[test]
        fn depth_is_linear_in_the_level_with_the_gain(
            h in 0.3f64..3.0, bx in 0.5f64..20.0, by in -5.0f64..5.0, depth in 0.01f64..2.0,
            level in -2.0f64..2.0, shift in -0.25f64..0.25, n in 1.0f64..1.6,
        ) {
            let s = Point3::new(0.0, 0.0, level + h);
            let raw = apparent_bottom_point(s, Point3::new(bx, by, level - depth), level, n)
                .unwrap();
            let other = level + shift;
            // Only levels the beam crosses before its range ends, below the sensor.
            prop_assume!(other < s.z && other > raw.z);
            let d0 = level - correct_bottom_return(s, raw, level, n).unwrap().z;
            let d1 = other - correct_bottom_return(s, raw, other, n).unwrap().z;
            let g = bottom_depth_gain(s, raw, n).unwrap();
            prop_assert!((d1 - (d0 + g * shift)).abs() < 1e-9 * (1.0 + g),
                "{d0} {d1} {g} {shift}");
        }
    }
}
