use super::*;
use crate::classify::horizon::pixel_rays_in_map;
use crate::classify::horizon::tests::cam_pose;
use crate::classify::thermal::tests::noise;
use crate::geom::{CameraModel, Distortion};
use proptest::prelude::*;

/// The SWIR sky of a clear day in grey levels, by the elevation's sine: dim at the zenith,
/// brighter towards the horizon.
fn sky(z: f64, scale: f64) -> f32 {
    (scale * (0.25 + (1.0 - z.clamp(0.0, 1.0)).powi(4))) as f32
}

/// What a test image holds on the ground.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Ground {
    Terrain,
    /// Level water mirroring whatever its mirror pixel shows.
    Water,
    /// A dark dry surface of this radiance.
    Dark(f32),
}

impl Ground {
    /// Water where `wet`, else terrain.
    fn water_if(wet: bool) -> Ground {
        if wet {
            Ground::Water
        } else {
            Ground::Terrain
        }
    }
}

/// A 160 × 120 camera `h` m up, pitched `pitch_deg` down (hfov about 60°), its geometry,
/// its rays in the map frame.
fn camera(
    h: f64,
    pitch_deg: f64,
) -> (
    CameraModel,
    GroundGeometry,
    Vec<Option<nalgebra::Vector3<f64>>>,
) {
    let cam =
        CameraModel::new(160, 120, [138.0, 138.0, 79.5, 59.5], Distortion::None, "c").unwrap();
    let pose = cam_pose(h, pitch_deg.to_radians());
    let g = GroundGeometry::level(&cam, &pose, 0.0).unwrap();
    let rays = pixel_rays_in_map(&cam, &pose);
    (cam, g, rays)
}

/// Renders the image: the sky above the horizon (columns in `trees` hold bright trees from
/// the horizon up to 8° instead), terrain of radiance `terrain`, and on the ground whatever
/// `what` says of each pixel (water from its mirror pixel and R at its incidence, with the
/// water index of the visible, 1.33, so the rule's own index is not assumed).
fn render(
    g: &GroundGeometry,
    rays: &[Option<nalgebra::Vector3<f64>>],
    scale: f64,
    terrain: f32,
    trees: std::ops::Range<usize>,
    what: impl Fn(usize) -> Ground,
) -> MonoImage {
    let w = g.width;
    let mut data: Vec<f32> = rays
        .iter()
        .enumerate()
        .map(|(i, r)| match r {
            Some(r) if r.z >= 0.0 => {
                if trees.contains(&(i % w)) && r.z < 8f64.to_radians().sin() {
                    180.0
                } else {
                    sky(r.z, scale)
                }
            }
            _ => terrain,
        })
        .collect();
    let above = data.clone();
    for i in 0..data.len() {
        if !g.incidence[i].is_finite() {
            continue;
        }
        data[i] = match what(i) {
            Ground::Terrain => terrain,
            Ground::Dark(v) => v,
            Ground::Water => {
                let m = g.mirror[i];
                let l = if m == u32::MAX {
                    0.0
                } else {
                    above[m as usize]
                };
                let r = crate::optics::fresnel(g.incidence[i] as f64, 1.33)
                    .map_or(1.0, |f| 0.5 * (f.r_s + f.r_p));
                r as f32 * l
            }
        };
        data[i] = (data[i] + 2.0 * noise(i)).clamp(0.0, 255.0).round();
    }
    MonoImage::new(g.width, g.height, data).unwrap()
}

fn deg(g: &GroundGeometry, i: usize) -> f64 {
    (g.incidence[i] as f64).to_degrees()
}

#[test]
fn fresnel_of_water_at_1_55_um() {
    // Normal incidence: ((n − 1)/(n + 1))².
    let r0 = ((N_WATER_SWIR - 1.0) / (N_WATER_SWIR + 1.0)).powi(2);
    assert!((water_reflectance_swir(0.0) - r0).abs() < 1e-12);
    // Brewster's angle: r_p = 0, so R = r_s / 2.
    let b = N_WATER_SWIR.atan();
    let f = crate::optics::fresnel(b, N_WATER_SWIR).unwrap();
    assert!(f.r_p < 1e-12);
    assert!((water_reflectance_swir(b) - 0.5 * f.r_s).abs() < 1e-12);
    // Grazing: R → 1, finite at 89.9° and beyond (clamped), NaN taken as grazing.
    let g = water_reflectance_swir(89.9f64.to_radians());
    assert!(g > 0.98 && g <= 1.0, "{g}");
    assert_eq!(water_reflectance_swir(std::f64::consts::FRAC_PI_2), g);
    assert_eq!(water_reflectance_swir(f64::NAN), g);
    // Below the visible's index, the reflectance is a little lower.
    let vis = crate::optics::fresnel(1.2, 1.33).unwrap();
    assert!(water_reflectance_swir(1.2) < 0.5 * (vis.r_s + vis.r_p));
}

/// Water mirroring the measured sky at 80–88° incidence is water, in front of a camera
/// 1.55 m up where the band a vehicle plans in lies; the terrain around it is never water.
#[test]
fn water_mirroring_the_sky_at_grazing_incidence_is_water() {
    let (_, g, rays) = camera(1.55, 8.0);
    let pond = |i: usize| (40..120).contains(&(i % 160)) && (80.0..88.0).contains(&deg(&g, i));
    let img = render(&g, &rays, 60.0, 100.0, 0..0, |i| Ground::water_if(pond(i)));
    let l = classify_swir(&img, &g, None, &SwirConfig::default()).unwrap();
    let (mut n, mut water) = (0, 0);
    for i in 0..l.data.len() {
        if pond(i) {
            n += 1;
            water += usize::from(l.data[i] == Label::Water);
        } else {
            assert_ne!(
                l.data[i],
                Label::Water,
                "terrain pixel {i} at {:.1}°",
                deg(&g, i)
            );
        }
    }
    assert!(n > 500 && water as f64 >= 0.9 * n as f64, "{water} of {n}");
    // Terrain at moderate incidence is brighter than any reflection there: a dry vote.
    let i = 110 * 160 + 10;
    assert!(deg(&g, i) < 75.0);
    assert_eq!(l.data[i], Label::Other);
}

/// Asphalt darker than the terrain but brighter than a sky reflection is not water; nor is
/// a dark surface that matches water in one range ring and not in the next.
#[test]
fn dark_dry_surfaces_are_not_water() {
    let (_, g, rays) = camera(1.55, 8.0);
    // Asphalt at 40 over a wide strip of columns, all ranges; a pale terrain of 120.
    let asphalt = |i: usize| (30..130).contains(&(i % 160));
    let img = render(&g, &rays, 60.0, 120.0, 0..0, |i| {
        if asphalt(i) {
            Ground::Dark(40.0)
        } else {
            Ground::Terrain
        }
    });
    let l = classify_swir(&img, &g, None, &SwirConfig::default()).unwrap();
    let water = l.data.iter().filter(|&&x| x == Label::Water).count();
    assert_eq!(water, 0);
    // At 70–78° the asphalt is brighter than water could be there.
    let i = (0..l.data.len())
        .find(|&i| asphalt(i) && (70.0..78.0).contains(&deg(&g, i)))
        .unwrap();
    assert_eq!(l.data[i], Label::Other, "{:.1}°", deg(&g, i));
}

/// Water mirroring bright trees is unknown: neither water nor dry.
#[test]
fn water_mirroring_bright_trees_is_unknown() {
    let (_, g, rays) = camera(1.55, 8.0);
    let pond = |i: usize| (20..140).contains(&(i % 160)) && (82.0..88.0).contains(&deg(&g, i));
    let trees = 90..160;
    let img = render(&g, &rays, 60.0, 100.0, trees.clone(), |i| {
        Ground::water_if(pond(i))
    });
    let l = classify_swir(&img, &g, None, &SwirConfig::default()).unwrap();
    let mut under_trees = 0;
    for i in 0..l.data.len() {
        let m = g.mirror[i];
        if pond(i) && m != u32::MAX && (100..150).contains(&(m as usize % 160)) {
            // Never dry; unknown where every mirror a ripple may give is a tree.
            assert_ne!(l.data[i], Label::Other, "pixel {i} at {:.1}°", deg(&g, i));
            if deg(&g, i) > 82.0 + 2.0 * RIPPLE_TILT.to_degrees() + 0.5 {
                under_trees += 1;
                assert_eq!(l.data[i], Label::Unknown, "pixel {i} at {:.1}°", deg(&g, i));
            }
        }
    }
    assert!(under_trees > 100, "{under_trees}");
}

/// No sky in view (the mirror directions leave the image), saturated mirrors, NaN geometry:
/// no water anywhere.
#[test]
fn no_sky_saturated_or_no_geometry_decide_no_water() {
    // Pitched 45° down: the image's top ray points 22° down, no mirror pixel is in view.
    let (_, g, rays) = camera(1.55, 45.0);
    assert!(g.mirror.iter().all(|&m| m == u32::MAX));
    let img = render(&g, &rays, 60.0, 100.0, 0..0, |i| {
        if i % 160 < 80 {
            Ground::Dark(3.0)
        } else {
            Ground::Terrain
        }
    });
    let l = classify_swir(&img, &g, None, &SwirConfig::default()).unwrap();
    assert!(l.data.iter().all(|&x| x == Label::Unknown));

    // A saturated sky.
    let (_, g, rays) = camera(1.55, 8.0);
    let pond = |i: usize| (80.0..88.0).contains(&deg(&g, i));
    let img = render(&g, &rays, 600.0, 100.0, 0..0, |i| {
        if pond(i) {
            Ground::Dark(10.0)
        } else {
            Ground::Terrain
        }
    });
    let l = classify_swir(&img, &g, None, &SwirConfig::default()).unwrap();
    assert!(!l.data.contains(&Label::Water));

    // NaN geometry: unknown.
    let mut g2 = g.clone();
    g2.incidence.iter_mut().for_each(|t| *t = f32::NAN);
    let l = classify_swir(&img, &g2, None, &SwirConfig::default()).unwrap();
    assert!(l.data.iter().all(|&x| x == Label::Unknown));
    // Sizes and config are checked.
    let bad = MonoImage::new(2, 2, vec![0.0; 4]).unwrap();
    assert!(classify_swir(&bad, &g, None, &SwirConfig::default()).is_err());
    let cfg = SwirConfig {
        noise_sd: f32::NAN,
        ..SwirConfig::default()
    };
    assert!(classify_swir(&img, &g, None, &cfg).is_err());
}

/// At night there is no SWIR light: nothing is decided as water.
#[test]
fn night_decides_nothing() {
    let (_, g, rays) = camera(1.55, 8.0);
    let img = render(&g, &rays, 0.0, 1.0, 0..0, |i| {
        if i % 2 == 0 {
            Ground::Water
        } else {
            Ground::Terrain
        }
    });
    let l = classify_swir(&img, &g, None, &SwirConfig::default()).unwrap();
    assert!(!l.data.contains(&Label::Water));
}

#[test]
fn snow_needs_bright_visible() {
    let (_, g, rays) = camera(1.55, 8.0);
    let pond = |i: usize| (20..140).contains(&(i % 160)) && (80.0..86.0).contains(&deg(&g, i));
    let img = render(&g, &rays, 60.0, 100.0, 0..0, |i| Ground::water_if(pond(i)));
    let vis = MonoImage::new(
        160,
        120,
        (0..160 * 120)
            .map(|i| if i % 160 < 80 { 240.0 } else { 90.0 })
            .collect(),
    )
    .unwrap();
    let l = classify_swir(&img, &g, Some(&vis), &SwirConfig::default()).unwrap();
    let count = |lab: Label, left: bool| {
        (0..l.data.len())
            .filter(|&i| pond(i) && (i % 160 < 80) == left && l.data[i] == lab)
            .count()
    };
    assert!(count(Label::SnowIce, true) > 100);
    assert_eq!(count(Label::Water, true), 0);
    assert!(count(Label::Water, false) > 100);
    assert_eq!(count(Label::SnowIce, false), 0);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]
    /// Whatever the camera's height and pitch and the sky's brightness, water mirroring the
    /// sky at 80–88° is found and terrain of the brightness of sunlit grass is not water.
    #[test]
    fn sky_reflections_are_found_for_any_camera(
        h in 0.8f64..3.0, pitch in 3.0f64..15.0, scale in 25.0f64..90.0, terrain in 1.6f64..3.0
    ) {
        let (_, g, rays) = camera(h, pitch);
        let pond = |i: usize| (40..120).contains(&(i % 160)) && (80.0..88.0).contains(&deg(&g, i));
        let img = render(&g, &rays, scale, (terrain * scale) as f32, 0..0, |i| Ground::water_if(pond(i)));
        let l = classify_swir(&img, &g, None, &SwirConfig::default()).unwrap();
        let (mut n, mut water) = (0, 0);
        for i in 0..l.data.len() {
            if pond(i) {
                n += 1;
                water += usize::from(l.data[i] == Label::Water);
            } else {
                prop_assert_ne!(l.data[i], Label::Water, "terrain {} at {:.2}° value {}", i, deg(&g, i), img.data[i]);
            }
        }
        prop_assert!(n == 0 || water as f64 >= 0.8 * n as f64, "{} of {}", water, n);
    }
}

/// A dark Lambertian surface over a wide range of rows (an asphalt lot) is dry: its radiance
/// stays the same across rows where water would be brighter and rows where it would be
/// darker.
#[test]
fn an_asphalt_lot_is_dry() {
    let (_, g, rays) = camera(1.55, 8.0);
    let img = render(&g, &rays, 60.0, 40.0, 0..0, |_| Ground::Terrain);
    let l = classify_swir(&img, &g, None, &SwirConfig::default()).unwrap();
    assert!(!l.data.contains(&Label::Water));
    // Where water could be as dark as the asphalt (about 80–86°), the lot is dry too.
    let (mut n, mut other) = (0, 0);
    for i in 0..l.data.len() {
        if (80.0..86.0).contains(&deg(&g, i)) {
            n += 1;
            other += usize::from(l.data[i] == Label::Other);
        }
    }
    assert!(n > 500 && other as f64 > 0.9 * n as f64, "{other} of {n}");
}
