//! The estimators on synthetic clouds whose noise is known: flat and tilted ground,
//! outliers, too few points, all-NaN clouds, coordinates far from the origin.

use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;

use super::lidar::{IntensityLawEstimator, LidarNoiseEstimator};
use super::stereo::{StereoMethod, StereoNoiseEstimator};
use super::*;
use crate::geom::{PointCloud, Pose};

/// A deterministic standard normal for `(seed, i)` (splitmix64 and Box–Muller).
fn normal(seed: u64, i: u64) -> f64 {
    let mix = |mut z: u64| {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let a = mix(seed.wrapping_mul(0x1000_0000_01B3) ^ i);
    let b = mix(a ^ 0xD6E8_FEB8_6659_FD93);
    let u1 = ((a >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let u2 = (b >> 11) as f64 / (1u64 << 53) as f64;
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Ground height at (x, y): a plane rising `slope` along x.
fn ground(slope: f64, x: f64) -> f64 {
    slope * x
}

/// Where `o + t·d` meets that ground, for `0 < t < max`: o.z + t·d.z = slope·(o.x + t·d.x).
fn ground_hit(o: &Vector3<f64>, d: &Vector3<f64>, slope: f64, max: f64) -> Option<f64> {
    let den = d.z - slope * d.x;
    if den >= -1e-6 {
        return None;
    }
    let t = (ground(slope, o.x) - o.z) / den;
    (t > 0.0 && t < max).then_some(t)
}

/// The left camera's optical frame in the map: at `at`, 1.6 m up, looking along +x,
/// pitched down 10°.
fn camera_pose(at: [f64; 2]) -> Pose {
    // Optical x right, y down, z forward → map −y, −z, +x.
    let r0 = Rotation3::from_matrix_unchecked(Matrix3::new(
        0.0, 0.0, 1.0, //
        -1.0, 0.0, 0.0, //
        0.0, -1.0, 0.0,
    ));
    let pitch = Rotation3::from_axis_angle(&Vector3::y_axis(), 10f64.to_radians());
    Pose::from_parts(
        Translation3::new(at[0], at[1], 1.6 + ground(0.0, at[0])),
        UnitQuaternion::from_rotation_matrix(&(pitch * r0)),
    )
}

/// An organized stereo cloud (binned focal length 200 px, 160 × 120) of the ground, its
/// inverse depth off by a Gaussian of σ `c`, matches below 1 px of disparity lost
/// (f_k·B = `fb`), and one pixel in `outlier_every`, scattered, a mixed pixel or a blade of
/// grass at a third of the depth.
fn stereo_cloud(
    seed: u64,
    c: f64,
    fb: f64,
    slope: f64,
    at: [f64; 2],
    outlier_every: usize,
) -> PointCloud {
    let (w, h, f) = (160usize, 120usize, 200.0);
    let pose = camera_pose(at);
    let o = pose.translation.vector;
    let mut xyz = vec![[f32::NAN; 3]; w * h];
    for r in 0..h {
        for col in 0..w {
            let i = r * w + col;
            let ray = Vector3::new((col as f64 - 80.0) / f, (r as f64 - 60.0) / f, 1.0);
            let Some(t) = ground_hit(&o, &(pose.rotation * ray), slope, 80.0) else {
                continue;
            };
            let mut inv = 1.0 / t + c * normal(seed, i as u64);
            if outlier_every > 0
                && (normal(seed ^ 0xA5, i as u64).abs() * 1e6) as usize % outlier_every == 0
            {
                inv = 3.0 / t;
            }
            if inv * fb < 1.0 {
                continue;
            }
            let p = ray / inv;
            xyz[i] = [p.x as f32, p.y as f32, p.z as f32];
        }
    }
    let mut cloud = PointCloud::organized(h, w, xyz).unwrap();
    cloud.frame_to_map = pose;
    cloud
}

/// An organized lidar scan of the ground from 1.8 m (32 rings, −25° … −2°, 720 columns),
/// range noise σ `sigma_r`.
fn lidar_scan(seed: u64, sigma_r: f64, slope: f64, at: [f64; 2]) -> PointCloud {
    let (rows, cols) = (32usize, 720usize);
    let o = Vector3::new(at[0], at[1], 1.8 + ground(slope, at[0]));
    let mut xyz = vec![[f32::NAN; 3]; rows * cols];
    for r in 0..rows {
        let el = (-25.0 + 23.0 * r as f64 / (rows - 1) as f64).to_radians();
        for c in 0..cols {
            let az = (c as f64 / cols as f64) * std::f64::consts::TAU;
            let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            let Some(t) = ground_hit(&o, &d, slope, 60.0) else {
                continue;
            };
            let i = r * cols + c;
            let p = d * (t + sigma_r * normal(seed ^ 0x55, i as u64));
            xyz[i] = [p.x as f32, p.y as f32, p.z as f32];
        }
    }
    let mut cloud = PointCloud::organized(rows, cols, xyz).unwrap();
    cloud.frame_to_map = Pose::from_parts(Translation3::from(o), UnitQuaternion::identity());
    cloud
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    /// Against the lidar, from flat or tilted ground with 5 % of outliers: within 15 %
    /// of the true coefficient after three frames.
    #[test]
    fn stereo_noise_against_the_lidar(c in 0.002f64..0.03, slope in -0.05f64..0.05, seed in 0u64..1000) {
        let mut est = StereoNoiseEstimator::default();
        for k in 0..3 {
            let s = stereo_cloud(seed + k, c, 30.0, slope, [0.0, 0.0], 20);
            let l = lidar_scan(seed + k, 0.02, slope, [0.0, 0.0]);
            est.observe(&s, Some(&l));
        }
        let m = est.by_lidar().expect("enough samples");
        prop_assert_eq!(m.method, StereoMethod::LidarSurface);
        prop_assert!((m.per_m2 / c - 1.0).abs() < 0.15, "measured {} for {}", m.per_m2, c);
    }

    /// Without a lidar, the cloud's own local planes, with 2.5 % of outliers (each touches
    /// three second differences, and they push the estimate up): within −10 … +20 %.
    #[test]
    fn stereo_noise_from_planes(c in 0.002f64..0.03, slope in -0.05f64..0.05, seed in 0u64..1000) {
        let mut est = StereoNoiseEstimator::default();
        for k in 0..3 {
            est.observe(&stereo_cloud(seed + k, c, 30.0, slope, [0.0, 0.0], 40), None);
        }
        prop_assert!(est.by_lidar().is_none());
        let m = est.estimate().expect("enough samples");
        prop_assert_eq!(m.method, StereoMethod::Planes);
        let rel = m.per_m2 / c - 1.0;
        prop_assert!((-0.1..0.2).contains(&rel), "measured {} for {}", m.per_m2, c);
    }

    /// A stated value never overrides a measurement that contradicts it without a
    /// warning: the measurement is used, and a warning comes exactly when the two are
    /// more than 1.5× apart.
    #[test]
    fn a_stated_value_never_silently_overrides_a_measurement(
        stated in 1e-6f64..10.0, measured in 1e-6f64..10.0, noisy in 1e-3f64..1.0,
    ) {
        let s = Sourced { value: stated, source: Source::Config };
        let r = resolve("x", Some(s), Some(measured), noisy);
        prop_assert_eq!(r.used.value, measured);
        prop_assert_eq!(r.used.source, Source::Measured);
        let ratio = (stated / measured).max(measured / stated);
        prop_assert_eq!(r.warning.is_some(), ratio > DISAGREEMENT);
        // Without a measurement the stated value stands; with neither, the noisy default.
        prop_assert_eq!(resolve("x", Some(s), None, noisy).used, s);
        let d = resolve("x", None, None, noisy).used;
        prop_assert_eq!((d.value, d.source), (noisy, Source::Default));
    }

    /// Lidar range noise from second differences along the rings: within 10 %.
    #[test]
    fn lidar_range_noise(sigma in 0.005f64..0.05, slope in -0.05f64..0.05, seed in 0u64..1000) {
        let mut est = LidarNoiseEstimator::default();
        for k in 0..2 {
            est.observe(&lidar_scan(seed + k, sigma, slope, [0.0, 0.0]));
        }
        let m = est.estimate().expect("enough samples");
        prop_assert!((m.noise.sigma(10.0) / sigma - 1.0).abs() < 0.1, "{:?} for {}", m, sigma);
    }
}

#[test]
fn far_from_the_origin_the_estimates_hold() {
    // UTM-scale map coordinates: the clouds stay in their sensors' frames.
    let at = [4.5e5, 5.2e6];
    let mut est = StereoNoiseEstimator::default();
    for k in 0..3 {
        est.observe(
            &stereo_cloud(k, 0.01, 30.0, 0.0, at, 10),
            Some(&lidar_scan(k, 0.02, 0.0, at)),
        );
    }
    let m = est.by_lidar().unwrap();
    assert!((m.per_m2 / 0.01 - 1.0).abs() < 0.15, "{m:?}");
}

#[test]
fn too_little_or_no_data_measures_nothing() {
    let mut est = StereoNoiseEstimator::default();
    let mut lidar = LidarNoiseEstimator::default();
    // Empty and all-NaN clouds.
    let empty = PointCloud::organized(0, 0, Vec::new()).unwrap();
    let nan = PointCloud::organized(10, 10, vec![[f32::NAN; 3]; 100]).unwrap();
    for c in [&empty, &nan] {
        est.observe(c, Some(c));
        lidar.observe(c);
    }
    assert_eq!(est.estimate(), None);
    assert_eq!(lidar.estimate(), None);
    // One small frame: too few samples.
    let small = stereo_cloud(1, 0.01, 30.0, 0.0, [0.0, 0.0], 0);
    let mut few = PointCloud::organized(10, 160, small.xyz[60 * 160..70 * 160].to_vec()).unwrap();
    few.frame_to_map = small.frame_to_map;
    est.observe(&few, None);
    assert_eq!(est.estimate(), None);
    // Absurd but finite values give no estimate or a finite one.
    let mut huge = PointCloud::organized(10, 10, vec![[1e30, -1e30, 1e30]; 100]).unwrap();
    huge.frame_to_map = camera_pose([0.0, 0.0]);
    est.observe(&huge, Some(&huge));
    lidar.observe(&huge);
    assert!(est.estimate().is_none_or(|m| m.per_m2.is_finite()));
    assert!(lidar.estimate().is_none_or(|m| m.noise.sigma0.is_finite()));
}

#[test]
fn the_intensity_law_tells_raw_from_range_compensated() {
    let mut e = IntensityLawEstimator::default();
    assert_eq!(e.estimate(), None);
    for x in [-3.1, -2.9, -3.0, f64::NAN] {
        e.observe(x, "reflectivity");
    }
    let law = e.estimate().unwrap();
    assert!(!law.range_compensated);
    assert!((law.incidence_exponent.unwrap() - 1.0).abs() < 1e-9);
    assert_eq!(law.scans, 3);
    let mut cal = Calibration::default();
    cal.report.lidar = Some(Default::default());
    for _ in 0..3 {
        cal.intensity_falloff(-3.0, "reflectivity");
    }
    assert!(cal
        .report()
        .warnings
        .iter()
        .any(|w| w.contains("raw intensity")));
    let mut ok = Calibration::default();
    ok.intensity_falloff(-1.05, "reflectivity");
    assert!(ok.report().warnings.is_empty());
}

#[test]
fn stereo_waits_until_the_noise_is_known() {
    // Nothing stated and nothing measurable: the noisy default, and the cue waits.
    let mut cal = Calibration::default();
    let empty = PointCloud::organized(0, 0, Vec::new()).unwrap();
    let (c, known) = cal.stereo_noise(&empty, None, StereoStated::default());
    assert!(!known);
    assert_eq!(c.source, Source::Default);
    assert_eq!(c.value, NOISY_STEREO_PER_M2);
    assert!(cal.report().waited[0].contains("no disparity noise"));
    // A frame of ground measures it; a stated value twice too small is warned about.
    let stated = StereoStated {
        focal_px: Some(400.0),
        binning: Some(2),
        baseline_m: Some(Sourced {
            value: 0.15,
            source: Source::Log,
        }),
        disparity_noise_px: Some(Sourced {
            value: 0.5,
            source: Source::Config,
        }),
    };
    let true_c = 2.0 * stated.per_m2().unwrap();
    let mut last = None;
    for k in 0..3 {
        let s = stereo_cloud(k, true_c, 30.0, 0.0, [0.0, 0.0], 20);
        last = Some(cal.stereo_noise(&s, Some(&lidar_scan(k, 0.02, 0.0, [0.0, 0.0])), stated));
    }
    let (c, known) = last.unwrap();
    assert!(known);
    assert_eq!(c.source, Source::Measured);
    assert!((c.value / true_c - 1.0).abs() < 0.15);
    let rep = cal.report();
    assert!(
        rep.warnings.iter().any(|w| w.starts_with("stereo noise")),
        "{rep:?}"
    );
    let implied = rep
        .stereo
        .as_ref()
        .unwrap()
        .implied_disparity_noise_px
        .unwrap();
    assert!((implied / 1.0 - 1.0).abs() < 0.15, "{implied}");
}
