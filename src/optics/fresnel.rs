//! Snell's law and the Fresnel power coefficients at a flat interface.
//!
//! With `n = n₂/n₁` (relative index, transmitted side over incident side), `cᵢ = cos θᵢ` and
//! `cₜ = cos θₜ = √(n² − sin²θᵢ)/n`, the amplitude reflection coefficients are
//!
//! ```text
//! r_s = (cᵢ − n cₜ)/(cᵢ + n cₜ)        r_p = (n cᵢ − cₜ)/(n cᵢ + cₜ)
//! ```
//!
//! and the power transmittances (the amplitude `t` squared times the beam-area and impedance
//! factor `n cₜ/cᵢ`) are
//!
//! ```text
//! T_s = 4 n cᵢ cₜ/(cᵢ + n cₜ)²          T_p = 4 n cᵢ cₜ/(n cᵢ + cₜ)²
//! ```
//!
//! so that `R + T = 1` holds exactly in algebra ((a−b)² + 4ab = (a+b)²). These forms have no
//! 0/0 at normal incidence (unlike the sine/tangent forms) and no cancellation at grazing
//! incidence (cᵢ → 0 gives T → 0, R → 1 smoothly). "s" (senkrecht) is the paper's
//! "horizontal" polarization: the electric field is perpendicular to the plane of incidence,
//! which is vertical for a horizontal water surface; "p" is its "vertical" polarization.

use crate::error::{Error, Result};

/// Fresnel power coefficients for one angle of incidence.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Fresnel {
    /// Reflectance, s ("horizontal") polarization.
    pub r_s: f64,
    /// Reflectance, p ("vertical") polarization.
    pub r_p: f64,
    /// Transmittance, s polarization.
    pub t_s: f64,
    /// Transmittance, p polarization.
    pub t_p: f64,
}

impl Fresnel {
    /// Reflectance of an unpolarized beam: the mean of the two polarizations.
    pub fn r_unpolarized(&self) -> f64 {
        0.5 * (self.r_s + self.r_p)
    }

    /// Transmittance of an unpolarized beam: the mean of the two polarizations.
    pub fn t_unpolarized(&self) -> f64 {
        0.5 * (self.t_s + self.t_p)
    }
}

fn check_inputs(theta_i: f64, n_rel: f64) -> Result<()> {
    if !(theta_i.is_finite() && (0.0..=std::f64::consts::FRAC_PI_2).contains(&theta_i)) {
        return Err(Error::invalid(
            "angle of incidence",
            format!("{theta_i} rad is not in [0, π/2]"),
        ));
    }
    if !(n_rel.is_finite() && n_rel > 0.0) {
        return Err(Error::invalid(
            "relative refractive index",
            format!("{n_rel} is not a finite positive number"),
        ));
    }
    Ok(())
}

/// Snell's law: the angle of refraction (radians) for incidence `theta_i` (radians, 0..π/2)
/// from a medium into one whose index is `n_rel` times larger. `Ok(None)` means total internal
/// reflection (possible only when `n_rel < 1`).
pub fn snell(theta_i: f64, n_rel: f64) -> Result<Option<f64>> {
    check_inputs(theta_i, n_rel)?;
    Ok(snell_unchecked(theta_i.sin(), n_rel).map(|(s, c)| s.atan2(c)))
}

/// (sin θₜ, cos θₜ) from sin θᵢ, or None past the critical angle.
#[inline]
pub(crate) fn snell_unchecked(sin_i: f64, n_rel: f64) -> Option<(f64, f64)> {
    let q = n_rel * n_rel - sin_i * sin_i;
    if q < 0.0 {
        return None;
    }
    Some((sin_i / n_rel, q.sqrt() / n_rel))
}

/// Fresnel power coefficients for incidence `theta_i` (radians, 0..π/2) on a flat interface
/// with relative index `n_rel = n₂/n₁`. Past the critical angle (only for `n_rel < 1`)
/// everything is reflected.
pub fn fresnel(theta_i: f64, n_rel: f64) -> Result<Fresnel> {
    check_inputs(theta_i, n_rel)?;
    Ok(fresnel_unchecked(theta_i.sin(), theta_i.cos(), n_rel))
}

/// The same, from sin θᵢ and cos θᵢ (both ≥ 0) and a valid index.
#[inline]
pub(crate) fn fresnel_unchecked(sin_i: f64, cos_i: f64, n_rel: f64) -> Fresnel {
    let Some((_, cos_t)) = snell_unchecked(sin_i, n_rel) else {
        return Fresnel {
            r_s: 1.0,
            r_p: 1.0,
            t_s: 0.0,
            t_p: 0.0,
        };
    };
    let cos_i = cos_i.max(0.0);
    // s: a = cos_i, b = n cos_t; p: a = n cos_i, b = cos_t. R = ((a-b)/(a+b))², T = 4ab/(a+b)².
    let coeffs = |a: f64, b: f64| -> (f64, f64) {
        let s = a + b;
        if s <= 0.0 {
            // Only at exact grazing incidence on the critical angle: all reflected.
            return (1.0, 0.0);
        }
        let r = (a - b) / s;
        (r * r, 4.0 * a * b / (s * s))
    };
    let (r_s, t_s) = coeffs(cos_i, n_rel * cos_t);
    let (r_p, t_p) = coeffs(n_rel * cos_i, cos_t);
    Fresnel { r_s, r_p, t_s, t_p }
}

/// Brewster's angle (radians) for relative index `n_rel`: `atan(n_rel)`, where `R_p = 0`.
pub fn brewster_angle(n_rel: f64) -> Result<f64> {
    check_inputs(0.0, n_rel)?;
    Ok(n_rel.atan())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::FRAC_PI_2;

    const N: f64 = 1.33;

    #[test]
    fn normal_incidence_matches_closed_form() {
        let f = fresnel(0.0, N).unwrap();
        let r0 = ((N - 1.0) / (N + 1.0)).powi(2);
        assert!((f.r_s - r0).abs() < 1e-15);
        assert!((f.r_p - r0).abs() < 1e-15);
        assert!((f.t_unpolarized() - (1.0 - r0)).abs() < 1e-15);
        // 2.0 % for water, the textbook number.
        assert!((r0 - 0.02006).abs() < 1e-5);
    }

    #[test]
    fn p_reflectance_vanishes_at_brewster() {
        let b = brewster_angle(N).unwrap();
        assert!((b.to_degrees() - 53.06).abs() < 0.01);
        let f = fresnel(b, N).unwrap();
        assert!(f.r_p < 1e-28, "R_p at Brewster = {}", f.r_p);
        assert!(f.r_s > 0.05);
    }

    #[test]
    fn grazing_incidence_reflects_everything() {
        let f = fresnel(FRAC_PI_2, N).unwrap();
        assert!((f.r_s - 1.0).abs() < 1e-12 && (f.r_p - 1.0).abs() < 1e-12);
        assert!(f.t_s.abs() < 1e-12 && f.t_p.abs() < 1e-12);
    }

    #[test]
    fn total_internal_reflection_from_water() {
        let critical = (1.0 / N).asin();
        assert_eq!(snell(critical + 1e-6, 1.0 / N).unwrap(), None);
        let f = fresnel(critical + 1e-3, 1.0 / N).unwrap();
        assert_eq!((f.r_s, f.r_p, f.t_s, f.t_p), (1.0, 1.0, 0.0, 0.0));
        assert!(snell(critical - 1e-6, 1.0 / N).unwrap().is_some());
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        assert!(fresnel(f64::NAN, N).is_err());
        assert!(fresnel(-0.1, N).is_err());
        assert!(fresnel(2.0, N).is_err());
        assert!(fresnel(0.3, 0.0).is_err());
        assert!(fresnel(0.3, f64::INFINITY).is_err());
        assert!(snell(0.3, -1.0).is_err());
    }

    /// Independent textbook forms (Born & Wolf, sine/tangent laws), valid away from 0 and 90°.
    fn textbook(theta_i: f64, n: f64) -> (f64, f64, f64, f64) {
        let tt = (theta_i.sin() / n).asin();
        let rs = -(theta_i - tt).sin() / (theta_i + tt).sin();
        let rp = (theta_i - tt).tan() / (theta_i + tt).tan();
        let ts = 2.0 * tt.sin() * theta_i.cos() / (theta_i + tt).sin();
        let tp = 2.0 * tt.sin() * theta_i.cos() / ((theta_i + tt).sin() * (theta_i - tt).cos());
        let k = n * tt.cos() / theta_i.cos();
        (rs * rs, rp * rp, k * ts * ts, k * tp * tp)
    }

    proptest! {
        #[test]
        fn r_plus_t_is_one_and_nothing_is_nan(deg in 0.0f64..=89.999, n in 1.0001f64..3.0) {
            let f = fresnel(deg.to_radians(), n).unwrap();
            for v in [f.r_s, f.r_p, f.t_s, f.t_p] {
                prop_assert!(v.is_finite() && (0.0..=1.0).contains(&v), "{f:?}");
            }
            prop_assert!((f.r_s + f.t_s - 1.0).abs() < 1e-14);
            prop_assert!((f.r_p + f.t_p - 1.0).abs() < 1e-14);
        }

        #[test]
        fn internal_side_also_conserves_energy(deg in 0.0f64..=89.999, n in 0.3f64..0.9999) {
            let f = fresnel(deg.to_radians(), n).unwrap();
            prop_assert!((f.r_s + f.t_s - 1.0).abs() < 1e-14);
            prop_assert!((f.r_p + f.t_p - 1.0).abs() < 1e-14);
        }

        #[test]
        fn agrees_with_the_sine_tangent_forms(deg in 0.5f64..89.5, n in 1.05f64..2.5) {
            let th = deg.to_radians();
            let f = fresnel(th, n).unwrap();
            let (rs, rp, ts, tp) = textbook(th, n);
            prop_assert!((f.r_s - rs).abs() < 1e-10);
            prop_assert!((f.r_p - rp).abs() < 1e-10);
            prop_assert!((f.t_s - ts).abs() < 1e-10);
            prop_assert!((f.t_p - tp).abs() < 1e-10);
        }

        #[test]
        fn transmittance_is_reciprocal(deg in 0.0f64..=89.999, n in 1.0001f64..2.5) {
            // Air→water at θi and water→air at θt transmit the same fraction. Coming back from
            // the water side at grazing incidence with n → 1, θt sits just under the critical
            // angle, where cos θ = √(1 − n² sin² θt) loses digits (a case proptest found:
            // 89.985°, n = 1.0001): 1e-9 holds there, 1e-12 does not.
            let th = deg.to_radians();
            let tt = snell(th, n).unwrap().unwrap();
            let a = fresnel(th, n).unwrap();
            let b = fresnel(tt, 1.0 / n).unwrap();
            prop_assert!((a.t_s - b.t_s).abs() < 1e-9, "{} vs {}", a.t_s, b.t_s);
            prop_assert!((a.t_p - b.t_p).abs() < 1e-9, "{} vs {}", a.t_p, b.t_p);
        }

        #[test]
        fn unpolarized_transmittance_falls_with_incidence(a in 0.0f64..89.99, b in 0.0f64..89.99) {
            let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
            let t_lo = fresnel(lo.to_radians(), N).unwrap().t_unpolarized();
            let t_hi = fresnel(hi.to_radians(), N).unwrap().t_unpolarized();
            prop_assert!(t_hi <= t_lo + 1e-15, "T({hi}°)={t_hi} > T({lo}°)={t_lo}");
        }

        #[test]
        fn snell_holds(deg in 0.0f64..=90.0, n in 1.0001f64..3.0) {
            let th = deg.to_radians();
            let tt = snell(th, n).unwrap().unwrap();
            prop_assert!((th.sin() - n * tt.sin()).abs() < 1e-14);
        }
    }
}
