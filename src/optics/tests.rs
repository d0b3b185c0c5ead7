//! The lidar model against first principles (a brute-force ray trace) and against the
//! paper's claims (H = 1 m, ρ = 0.3, 2.54 cm aperture, dry ground lost at 11 m).

use super::*;
use nalgebra::{Point3, Vector3};
use proptest::prelude::*;

fn paper(att: Attenuation) -> LidarWaterModel {
    LidarWaterModel::new(LidarModelConfig::paper(att)).unwrap()
}

fn nm(wavelength_nm: f64) -> Attenuation {
    Attenuation::PureWater { wavelength_nm }
}

/// Solid angle, in the water, of the receiver disk seen from the bottom point, by shooting a
/// stratified fan of rays from the bottom point, refracting them at the surface and counting
/// those that cross the aperture disk (centred on the sensor, facing the return ray).
fn traced_solid_angle(h: f64, d: f64, depth: f64, n: f64, diameter: f64) -> f64 {
    let m = LidarWaterModel::new(LidarModelConfig {
        height_m: h,
        n_water: n,
        aperture_diameter_m: diameter,
        ..LidarModelConfig::paper(Attenuation::PerMetre(0.0))
    })
    .unwrap();
    let g = m.geometry(d, depth).unwrap();
    let sensor = Point3::new(0.0, 0.0, h);
    let bottom = Point3::new(g.bottom_distance, 0.0, -depth);
    let surface = Point3::new(d, 0.0, 0.0);
    let normal = (sensor - surface).normalize(); // aperture faces the return ray
    let c = (surface - bottom).normalize();
    let e1 = c.cross(&Vector3::y()).normalize();
    let e2 = c.cross(&e1);
    let r_min = g.r_sagittal.min(g.r_tangential);
    let half = (1.5 * diameter / r_min).min(0.5);
    let (nu, nphi) = (1200usize, 1200usize);
    let cos_min = half.cos();
    let radius2 = 0.25 * diameter * diameter;
    let mut hits = 0u64;
    for iu in 0..nu {
        let cos_a = 1.0 - (1.0 - cos_min) * (iu as f64 + 0.5) / nu as f64;
        let sin_a = (1.0 - cos_a * cos_a).sqrt();
        for ip in 0..nphi {
            let phi = std::f64::consts::TAU * (ip as f64 + 0.5) / nphi as f64;
            let w = c * cos_a + (e1 * phi.cos() + e2 * phi.sin()) * sin_a;
            if w.z <= 0.0 {
                continue;
            }
            let p = bottom + w * (depth / w.z);
            // Water → air: v = n w + (cos_t − n cos_i) ẑ.
            let cos_i = w.z;
            let s2 = n * n * (1.0 - cos_i * cos_i);
            if s2 >= 1.0 {
                continue;
            }
            let v = w * n + Vector3::z() * ((1.0 - s2).sqrt() - n * cos_i);
            let denom = v.dot(&normal);
            if denom <= 0.0 {
                continue;
            }
            let q = p + v * ((sensor - p).dot(&normal) / denom);
            if (q - sensor).norm_squared() <= radius2 {
                hits += 1;
            }
        }
    }
    hits as f64 / (nu * nphi) as f64 * std::f64::consts::TAU * (1.0 - cos_min)
}

#[test]
fn solid_angle_matches_a_brute_force_ray_trace() {
    for (d, depth) in [(0.0, 1.0), (0.5, 2.0), (2.0, 0.3), (4.0, 1.5), (6.0, 3.0)] {
        let traced = traced_solid_angle(1.0, d, depth, 1.33, 0.0254);
        let exact = LidarWaterModel::new(LidarModelConfig::paper(Attenuation::PerMetre(0.0)))
            .unwrap()
            .solid_angle_in_water(d, depth)
            .unwrap();
        let err = exact / traced - 1.0;
        assert!(
            err.abs() < 0.01,
            "d={d} D={depth}: exact {exact:e} traced {traced:e}"
        );
    }
}

#[test]
fn paper_solid_angle_is_optimistic_where_astigmatism_matters() {
    let exact = paper(Attenuation::PerMetre(0.0));
    let simple = LidarWaterModel::new(LidarModelConfig {
        solid_angle: SolidAngleForm::Paper,
        ..LidarModelConfig::paper(Attenuation::PerMetre(0.0))
    })
    .unwrap();
    // Straight down the two forms coincide.
    let (a, b) = (
        exact.solid_angle_in_water(0.0, 1.0).unwrap(),
        simple.solid_angle_in_water(0.0, 1.0).unwrap(),
    );
    assert!((a / b - 1.0).abs() < 1e-12);
    // Deep water seen obliquely: the single-distance form overestimates, and the ray trace
    // sides with the exact form.
    let traced = traced_solid_angle(1.0, 6.0, 3.0, 1.33, 0.0254);
    let (a, b) = (
        exact.solid_angle_in_water(6.0, 3.0).unwrap(),
        simple.solid_angle_in_water(6.0, 3.0).unwrap(),
    );
    assert!(b / a > 1.1, "paper/exact = {}", b / a);
    assert!((traced / a - 1.0).abs() < 0.01 && (traced / b - 1.0).abs() > 0.05);
}

#[test]
fn zero_depth_return_is_dry_return_times_t_squared_over_n_squared() {
    let m = paper(nm(900.0));
    for d in [0.0, 1.0, 3.0, 7.0] {
        let (ts, tp) = m.transmittance(d).unwrap();
        let t = 0.5 * (ts + tp);
        let want = m.dry_ratio(d).unwrap() * t * t / (1.33 * 1.33);
        let got = m.return_ratio(d, 0.0).unwrap();
        assert!((got / want - 1.0).abs() < 1e-12, "{d}: {got:e} vs {want:e}");
    }
}

#[test]
fn dry_limit_calibration_round_trips() {
    let m = paper(nm(900.0));
    assert!((m.dry_limit().unwrap() - 11.0).abs() < 1e-9);
    let p = m.dry_ratio(11.0).unwrap();
    assert_eq!(p, m.min_power_ratio());
    let direct = LidarWaterModel::new(LidarModelConfig {
        sensitivity: Sensitivity::MinPowerRatio(p),
        ..LidarModelConfig::paper(nm(900.0))
    })
    .unwrap();
    assert!((direct.dry_limit().unwrap() - 11.0).abs() < 1e-9);
}

#[test]
fn bad_configuration_is_an_error() {
    let base = LidarModelConfig::paper(nm(900.0));
    for cfg in [
        LidarModelConfig {
            height_m: 0.0,
            ..base
        },
        LidarModelConfig {
            height_m: f64::NAN,
            ..base
        },
        LidarModelConfig {
            albedo: 1.5,
            ..base
        },
        LidarModelConfig {
            aperture_diameter_m: -1.0,
            ..base
        },
        LidarModelConfig {
            n_water: 0.9,
            ..base
        },
        LidarModelConfig {
            attenuation: nm(5000.0),
            ..base
        },
        LidarModelConfig {
            attenuation: Attenuation::PerMetre(-1.0),
            ..base
        },
        LidarModelConfig {
            sensitivity: Sensitivity::MinPowerRatio(0.0),
            ..base
        },
        LidarModelConfig {
            sensitivity: Sensitivity::DryLimit(f64::INFINITY),
            ..base
        },
    ] {
        assert!(LidarWaterModel::new(cfg).is_err(), "{cfg:?}");
    }
    let m = LidarWaterModel::new(base).unwrap();
    assert!(m.return_ratio(-1.0, 0.1).is_err());
    assert!(m.return_ratio(1.0, f64::NAN).is_err());
    assert!(m.max_depth(f64::INFINITY).is_err());
    assert!(m.diagnostic_interval(-0.1).is_err());
}

// ---- The paper's claims --------------------------------------------------------------

#[test]
fn claim_no_return_beyond_about_6_5_m_even_at_negligible_depth() {
    for att in [nm(525.0), nm(625.0), nm(900.0), Attenuation::PerMetre(2.2)] {
        let cut = paper(att).zero_depth_cutoff().unwrap();
        assert!((cut - 6.5).abs() < 0.3, "{att:?}: {cut}");
    }
}

#[test]
fn claim_diagnostic_interval_about_6_5_to_11_m() {
    let (a, b) = paper(nm(900.0)).diagnostic_interval(0.0).unwrap().unwrap();
    assert!((a - 6.5).abs() < 0.3 && (b - 11.0).abs() < 1e-9, "{a}..{b}");
    // Deeper water starts the interval closer.
    let (a3, _) = paper(nm(900.0)).diagnostic_interval(0.3).unwrap().unwrap();
    assert!(a3 < a);
}

#[test]
fn claim_900_nm_through_30_cm_is_gone_before_2_m() {
    let m = paper(nm(900.0));
    let d = m.max_lookahead_for_depth(0.3).unwrap().unwrap_or(0.0);
    assert!(d < 2.0, "{d}");
    assert!(m.return_ratio(2.0, 0.3).unwrap() < m.min_power_ratio());
}

#[test]
fn claim_1550_nm_is_too_attenuated_even_for_1_cm() {
    let m = paper(nm(1550.0));
    assert_eq!(m.max_lookahead_for_depth(0.01).unwrap(), None);
    // Not even straight down: the best 1 cm return is far below the threshold.
    assert!(m.return_ratio(0.0, 0.01).unwrap() < 1e-3 * m.min_power_ratio());
}

#[test]
fn claim_murky_water_half_a_metre_at_about_2_m() {
    let m = paper(Attenuation::PerMetre(2.2));
    let d = m.max_lookahead_for_depth(0.5).unwrap().unwrap();
    assert!((1.5..3.0).contains(&d), "{d}");
    assert!(m.max_depth(2.0).unwrap() >= 0.5);
}

#[test]
fn claim_clear_water_over_1_5_m_out_to_over_4_m() {
    let m = paper(nm(625.0));
    assert!(m.max_depth(4.0).unwrap() > 1.5);
    assert!(m.max_lookahead_for_depth(1.5).unwrap().unwrap() > 4.0);
}

#[test]
fn figure_5_sick_at_95_cm_sees_the_bottom_further_than_the_pond_did() {
    // Paper Figure 5: 905 nm, 0.95 m above 15–20 cm of pond water, bottom seen up to ≈56°.
    // With pure-water absorption the model sees it further: the pond's total attenuation
    // must have exceeded pure water's (the paper says so about its Figure 8b too).
    for depth in [0.15, 0.20] {
        let m = LidarWaterModel::new(LidarModelConfig {
            height_m: 0.95,
            ..LidarModelConfig::paper(nm(905.0))
        })
        .unwrap();
        let th = m
            .max_incidence_for_depth(depth)
            .unwrap()
            .unwrap()
            .to_degrees();
        assert!(th > 56.0, "{depth}: {th}°");
    }
}

// ---- Properties ----------------------------------------------------------------------

fn model_strategy() -> impl Strategy<Value = LidarWaterModel> {
    (
        0.3f64..5.0,
        0.0f64..20.0,
        0.05f64..1.0,
        0.005f64..0.1,
        1.0f64..1.5,
        2.0f64..40.0,
        any::<bool>(),
    )
        .prop_map(|(h, c, rho, a, n, dry, paper_form)| {
            LidarWaterModel::new(LidarModelConfig {
                height_m: h,
                attenuation: Attenuation::PerMetre(c),
                albedo: rho,
                aperture_diameter_m: a,
                n_water: n,
                sensitivity: Sensitivity::DryLimit(dry),
                solid_angle: if paper_form {
                    SolidAngleForm::Paper
                } else {
                    SolidAngleForm::Exact
                },
            })
            .unwrap()
        })
}

proptest! {
    #[test]
    fn return_falls_with_depth(m in model_strategy(), d in 0.0f64..30.0, z1 in 0.0f64..5.0, z2 in 0.0f64..5.0) {
        let (lo, hi) = if z1 <= z2 { (z1, z2) } else { (z2, z1) };
        let a = m.return_ratio(d, lo).unwrap();
        let b = m.return_ratio(d, hi).unwrap();
        prop_assert!(b <= a * (1.0 + 1e-12), "{b:e} > {a:e}");
    }

    #[test]
    fn return_falls_with_lookahead(m in model_strategy(), z in 0.0f64..5.0, d1 in 0.0f64..30.0, d2 in 0.0f64..30.0) {
        let (lo, hi) = if d1 <= d2 { (d1, d2) } else { (d2, d1) };
        let a = m.return_ratio(lo, z).unwrap();
        let b = m.return_ratio(hi, z).unwrap();
        prop_assert!(b <= a * (1.0 + 1e-12), "{b:e} > {a:e}");
        prop_assert!(m.dry_ratio(hi).unwrap() <= m.dry_ratio(lo).unwrap());
    }

    #[test]
    fn nothing_is_nan_or_negative_from_0_to_89_999_degrees(m in model_strategy(), deg in 0.0f64..=89.999, z in 0.0f64..5.0) {
        let d = m.config().height_m * deg.to_radians().tan();
        let r = m.return_ratio(d, z).unwrap();
        let (ts, tp) = m.transmittance(d).unwrap();
        let md = m.max_depth(d).unwrap();
        for v in [r, ts, tp, md, m.dry_ratio(d).unwrap(), m.solid_angle_in_water(d, z).unwrap()] {
            prop_assert!(v.is_finite() && v >= 0.0, "{v}");
        }
    }

    #[test]
    fn water_never_returns_more_than_dry_ground(m in model_strategy(), d in 0.0f64..30.0, z in 0.0f64..5.0) {
        prop_assert!(m.return_ratio(d, z).unwrap() <= m.dry_ratio(d).unwrap());
    }

    #[test]
    fn derived_answers_agree_with_the_return_ratio(m in model_strategy(), d in 0.0f64..15.0, z in 0.0f64..3.0) {
        let p = m.min_power_ratio();
        // max_depth: the bottom at that depth returns, a bit deeper it does not.
        let md = m.max_depth(d).unwrap();
        if md > 0.0 {
            prop_assert!(m.return_ratio(d, md).unwrap() >= p);
            prop_assert!(m.return_ratio(d, md * 1.001 + 1e-9).unwrap() < p);
        } else {
            prop_assert!(m.return_ratio(d, 0.0).unwrap() < p || md == 0.0);
        }
        // max_lookahead_for_depth is consistent with max_depth.
        match m.max_lookahead_for_depth(z).unwrap() {
            Some(l) => {
                prop_assert!(m.return_ratio(l, z).unwrap() >= p);
                prop_assert!(m.return_ratio(l * 1.001 + 1e-9, z).unwrap() < p);
                prop_assert!(l <= m.zero_depth_cutoff().unwrap() + 1e-9);
                prop_assert!(m.zero_depth_cutoff().unwrap() < m.dry_limit().unwrap());
            }
            None => prop_assert!(m.return_ratio(0.0, z).unwrap() < p),
        }
    }
}
