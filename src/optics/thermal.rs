//! Thermal emission in the mid-wave infrared: what a radiometric thermal camera reads off
//! level water. Water emits as a body of emissivity 1 − R(θ) and mirrors, with reflectance
//! R(θ) (Fresnel), whatever lies in the mirror direction; radiances add, temperatures do
//! not, so the apparent temperature is the brightness temperature of the sum, taken at the
//! band's centre wavelength.

/// The second radiation constant h·c/k, µm·K.
const C2_UM_K: f64 = 14_387.77;

/// The wavelength the mid-wave band is taken at, µm (the middle of 3–5 µm).
pub(crate) const MWIR_UM: f64 = 4.0;

/// The refractive index of water at 3–5 µm (Hale & Querry, 1973: 1.35 at 4 µm).
pub(crate) const N_WATER_MWIR: f64 = 1.35;

/// Spectral radiance of a black body at `t_k` kelvin and `lambda_um` µm, relative: Planck's
/// law without its constant factor 2hc²/λ⁵, `1 / (exp(c₂/λT) − 1)`.
pub(crate) fn planck_rel(lambda_um: f64, t_k: f64) -> f64 {
    1.0 / (C2_UM_K / (lambda_um * t_k)).exp_m1()
}

/// The temperature whose black-body radiance at `lambda_um` is `l` ([`planck_rel`]'s
/// inverse); NaN for `l` ≤ 0.
pub(crate) fn brightness_temperature(lambda_um: f64, l: f64) -> f64 {
    if l.is_nan() || l <= 0.0 {
        return f64::NAN;
    }
    C2_UM_K / (lambda_um * (1.0 / l).ln_1p())
}

/// Unpolarised Fresnel reflectance of level water at incidence `theta` (radians from the
/// vertical) in the mid-wave infrared; 1 at and beyond grazing.
pub fn water_reflectance_mwir(theta: f64) -> f64 {
    super::fresnel(theta.clamp(0.0, std::f64::consts::FRAC_PI_2), N_WATER_MWIR)
        .map_or(1.0, |f| 0.5 * (f.r_s + f.r_p))
}

/// The apparent (brightness) temperature of water at `t_water` K seen with reflectance
/// `r`, mirroring a scene at `t_mirror` K: `B⁻¹((1 − r)·B(t_water) + r·B(t_mirror))` at
/// the band's centre, 4 µm.
pub fn apparent_temperature(r: f64, t_water: f64, t_mirror: f64) -> f64 {
    let l = (1.0 - r) * planck_rel(MWIR_UM, t_water) + r * planck_rel(MWIR_UM, t_mirror);
    brightness_temperature(MWIR_UM, l)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn reflectance_rises_from_two_per_cent_to_all_at_grazing() {
        // (n − 1)² / (n + 1)² at normal incidence.
        let r0 = ((N_WATER_MWIR - 1.0) / (N_WATER_MWIR + 1.0)).powi(2);
        assert!((water_reflectance_mwir(0.0) - r0).abs() < 1e-12);
        let r = |deg: f64| water_reflectance_mwir(deg.to_radians());
        assert!(
            r(60.0) < 0.07 && r(80.0) > 0.3 && r(86.0) > 0.6,
            "{} {} {}",
            r(60.0),
            r(80.0),
            r(86.0)
        );
        assert!((r(90.0) - 1.0).abs() < 1e-9);
    }

    /// Radiance, not temperature, mixes: half of a 290 K body and half of a 250 K sky read
    /// warmer than their mean (the warm one dominates at 4 µm).
    #[test]
    fn radiances_mix_not_temperatures() {
        let t = apparent_temperature(0.5, 290.0, 250.0);
        assert!(t > 275.0 && t < 290.0, "{t}");
        assert!(t - 270.0 > 3.0, "{t}");
        assert_eq!(apparent_temperature(0.0, 287.0, 200.0), 287.0);
        assert!((apparent_temperature(1.0, 287.0, 200.0) - 200.0).abs() < 1e-9);
        assert!(brightness_temperature(MWIR_UM, 0.0).is_nan());
        assert!(brightness_temperature(MWIR_UM, f64::NAN).is_nan());
    }

    proptest! {
        #[test]
        fn brightness_temperature_inverts_planck(t in 150.0f64..400.0) {
            let back = brightness_temperature(MWIR_UM, planck_rel(MWIR_UM, t));
            prop_assert!((back - t).abs() < 1e-9 * t, "{} {}", t, back);
        }

        /// Between the two temperatures, and monotone in each and in the reflectance
        /// toward the mirrored one.
        #[test]
        fn apparent_temperature_lies_between(r in 0.0f64..1.0, tw in 250.0f64..310.0, tm in 200.0f64..300.0) {
            let t = apparent_temperature(r, tw, tm);
            prop_assert!(t >= tw.min(tm) - 1e-9 && t <= tw.max(tm) + 1e-9);
            let more = apparent_temperature((r + 0.05).min(1.0), tw, tm);
            prop_assert!((more - tm).abs() <= (t - tm).abs() + 1e-9);
        }
    }
}
