//! SWIR darkness and MWIR thermal contrast (paper sections 4 and 5).
//!
//! Both compare a pixel with the *terrain at the same range*: a band of image rows around the
//! pixel's row (on level ground, a row is a range ring), restricted to pixels whose ray meets
//! the ground within the sensor's valid geometry. The terrain statistics come from the side of
//! the band's distribution water does not reach, so they hold while water covers up to
//! three quarters of a band:
//!
//! - **SWIR** (about 1.5 µm): water, snow and ice absorb, so they are dark — at moderate
//!   incidence. Towards grazing incidence the Fresnel reflectance of the surface rises (paper
//!   Fig. 6b) and reflected sky or trees take over, so pixels whose incidence angle (from
//!   [`GroundGeometry`]) exceeds `max_incidence` get no decision ([`Label::Unknown`]). The
//!   terrain reference is the `reference_percentile` of the band (bright side); a pixel darker
//!   than `dark_ratio` × reference is water — or snow/ice when a co-registered visible image
//!   says it is bright there (snow is white in the visible and black at 1.5 µm).
//! - **MWIR**: water is warmer than the terrain at night and cooler by day (paper Fig. 12:
//!   warmer from about 23:00 to 08:00). Terrain level and spread come from the cold side
//!   of the band at night (5th and 25th percentiles: σ = (q25 − q05)/0.971, μ = q25 + 0.674σ for a
//!   normal distribution), from the warm side by day (75th, 95th); a pixel more than
//!   `k_sigma`·σ and `min_contrast` beyond μ on the water side is water. Around dawn and dusk
//!   the contrast reverses and there is no decision. Beyond `max_incidence` (60°) there is
//!   no decision either: water's apparent temperature is (1 − R)·T_water + R·T_sky, and its
//!   Fresnel reflectance R (n ≈ 1.35 at 3–5 µm) rises from 6 % at 60° to 35 % at 80° and
//!   65 % at 86°, so towards grazing incidence the cold sky it reflects takes over and the
//!   water looks *colder* than the land at night (the paper saw the water darken towards
//!   the far shore). On the simulated night reservoir, seen at 83–88°, the water reads 5–7 K
//!   below the land; the cold side of such a band is water, so without the gate the land
//!   beside it passed for warm water (13 % of the dry cells called water). Nor is there a
//!   decision beyond `max_lookahead_m`.

use serde::{Deserialize, Serialize};

use super::horizon::GroundGeometry;
use super::{Label, LabelImage, MonoImage};
use crate::error::{Error, Result};

const BINS: usize = 2048;

/// Per-row percentiles over a band of rows, from histograms of the included pixels.
fn band_percentiles(
    img: &MonoImage,
    include: &[bool],
    half_band: usize,
    qs: &[f64],
) -> Vec<Option<Vec<f32>>> {
    let (w, h) = (img.width, img.height);
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for (v, &inc) in img.data.iter().zip(include) {
        if inc {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    if lo > hi {
        return vec![None; h];
    }
    let span = (hi - lo).max(1e-6);
    let bin = |v: f32| (((v - lo) / span) * (BINS - 1) as f32).round() as usize;
    let value = |b: usize| lo + span * b as f32 / (BINS - 1) as f32;
    let mut rows = vec![[0u32; BINS]; 0];
    rows.reserve(h);
    for y in 0..h {
        let mut hist = [0u32; BINS];
        for x in 0..w {
            let i = y * w + x;
            if include[i] {
                hist[bin(img.data[i])] += 1;
            }
        }
        rows.push(hist);
    }
    let mut acc = [0u64; BINS];
    let mut out = Vec::with_capacity(h);
    // Sliding window [y − half_band, y + half_band].
    for r in rows.iter().take(half_band.min(h)) {
        for (a, c) in acc.iter_mut().zip(r) {
            *a += *c as u64;
        }
    }
    for y in 0..h {
        if y + half_band < h {
            for (a, c) in acc.iter_mut().zip(&rows[y + half_band]) {
                *a += *c as u64;
            }
        }
        if y > half_band {
            for (a, c) in acc.iter_mut().zip(&rows[y - half_band - 1]) {
                *a -= *c as u64;
            }
        }
        let n: u64 = acc.iter().sum();
        if n == 0 {
            out.push(None);
            continue;
        }
        let mut res = Vec::with_capacity(qs.len());
        for &q in qs {
            let target = (q * (n - 1) as f64).round() as u64;
            let mut cum = 0u64;
            let mut b = BINS - 1;
            for (i, c) in acc.iter().enumerate() {
                cum += c;
                if cum > target {
                    b = i;
                    break;
                }
            }
            res.push(value(b));
        }
        out.push(Some(res));
    }
    out
}

fn check_sizes(img: &MonoImage, g: &GroundGeometry, what: &str) -> Result<()> {
    let n = img.width * img.height;
    if img.width != g.width
        || img.height != g.height
        || img.data.len() != n
        || g.incidence.len() != n
        || g.range.len() != n
        || g.lookahead.len() != n
    {
        return Err(Error::invalid(
            what,
            format!(
                "image is {} × {} ({} values), geometry is {} × {}",
                img.width,
                img.height,
                img.data.len(),
                g.width,
                g.height
            ),
        ));
    }
    Ok(())
}

/// SWIR classifier parameters. See the module documentation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SwirConfig {
    /// Largest incidence angle (from the surface normal) with a decision, radians. The paper
    /// concludes surface reflections limit SWIR to incidence around 60°.
    pub max_incidence: f64,
    /// A pixel darker than this × the terrain reference is water (or snow/ice).
    pub dark_ratio: f32,
    /// Percentile of the band that stands for dry terrain (bright side).
    pub reference_percentile: f64,
    /// Half-height of the row band, rows.
    pub half_band_rows: usize,
    /// With a visible image: dark-in-SWIR pixels at least this bright in the visible are
    /// snow/ice rather than water.
    pub snow_min_visible: f32,
}

impl Default for SwirConfig {
    fn default() -> Self {
        SwirConfig {
            max_incidence: 60f64.to_radians(),
            dark_ratio: 0.5,
            reference_percentile: 0.75,
            half_band_rows: 8,
            snow_min_visible: 170.0,
        }
    }
}

/// Labels a SWIR image: water / snow-ice (dark), other, or unknown (no ground, grazing).
pub(crate) fn classify_swir(
    img: &MonoImage,
    geom: &GroundGeometry,
    visible: Option<&MonoImage>,
    cfg: &SwirConfig,
) -> Result<LabelImage> {
    check_sizes(img, geom, "SWIR image")?;
    if let Some(v) = visible {
        check_sizes(v, geom, "visible image for SWIR")?;
    }
    if !(cfg.max_incidence.is_finite()
        && cfg.dark_ratio > 0.0
        && (0.0..=1.0).contains(&cfg.reference_percentile))
    {
        return Err(Error::invalid("SWIR config", format!("{cfg:?}")));
    }
    let include: Vec<bool> = img
        .data
        .iter()
        .zip(&geom.incidence)
        .map(|(v, inc)| v.is_finite() && (*inc as f64) <= cfg.max_incidence)
        .collect();
    let refs = band_percentiles(
        img,
        &include,
        cfg.half_band_rows,
        &[cfg.reference_percentile],
    );
    let mut out = LabelImage::filled(img.width, img.height, Label::Unknown);
    for (i, o) in out.data.iter_mut().enumerate() {
        if !include[i] {
            continue;
        }
        let Some(r) = &refs[i / img.width] else {
            continue;
        };
        *o = if img.data[i] < cfg.dark_ratio * r[0] {
            match visible {
                Some(v) if v.data[i] >= cfg.snow_min_visible => Label::SnowIce,
                _ => Label::Water,
            }
        } else {
            Label::Other
        };
    }
    Ok(out)
}

/// Which way the thermal contrast goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(crate) enum ThermalRegime {
    /// Water warmer than terrain.
    Night,
    /// Water cooler than terrain.
    Day,
    /// Contrast reversing: no decision.
    Transition,
}

/// MWIR classifier parameters. See the module documentation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MwirConfig {
    /// Local solar hours [start, end) of the night regime (may wrap midnight).
    pub night_hours: [f64; 2],
    /// Local solar hours [start, end) of the day regime.
    pub day_hours: [f64; 2],
    /// Standard deviations of terrain a pixel must lie beyond the terrain level.
    pub k_sigma: f32,
    /// Smallest contrast with a decision (sensor units).
    pub min_contrast: f32,
    /// No decision beyond this horizontal distance, metres.
    pub max_lookahead_m: f64,
    /// No decision beyond this incidence angle (radians): the reflected sky takes over.
    pub max_incidence: f64,
    /// Half-height of the row band, rows.
    pub half_band_rows: usize,
}

impl Default for MwirConfig {
    fn default() -> Self {
        MwirConfig {
            night_hours: [23.0, 8.0],
            day_hours: [10.0, 19.0],
            k_sigma: 3.0,
            min_contrast: 1.0,
            max_lookahead_m: 40.0,
            max_incidence: 60f64.to_radians(),
            half_band_rows: 8,
        }
    }
}

fn in_hours(h: f64, [a, b]: [f64; 2]) -> bool {
    if a <= b {
        (a..b).contains(&h)
    } else {
        h >= a || h < b
    }
}

impl MwirConfig {
    /// The regime at a local solar hour (0..24).
    pub(crate) fn regime(&self, hour: f64) -> Result<ThermalRegime> {
        if !(0.0..24.0).contains(&hour) {
            return Err(Error::invalid(
                "hour of day",
                format!("{hour} (must be 0 ≤ h < 24)"),
            ));
        }
        Ok(if in_hours(hour, self.night_hours) {
            ThermalRegime::Night
        } else if in_hours(hour, self.day_hours) {
            ThermalRegime::Day
        } else {
            ThermalRegime::Transition
        })
    }
}

/// Labels an MWIR image taken at local solar `hour`.
pub(crate) fn classify_mwir(
    img: &MonoImage,
    geom: &GroundGeometry,
    hour: f64,
    cfg: &MwirConfig,
) -> Result<LabelImage> {
    check_sizes(img, geom, "MWIR image")?;
    if !(cfg.k_sigma >= 0.0
        && cfg.min_contrast >= 0.0
        && cfg.max_lookahead_m > 0.0
        && cfg.max_incidence.is_finite())
    {
        return Err(Error::invalid("MWIR config", format!("{cfg:?}")));
    }
    let regime = cfg.regime(hour)?;
    let mut out = LabelImage::filled(img.width, img.height, Label::Unknown);
    let include: Vec<bool> = img
        .data
        .iter()
        .zip(&geom.lookahead)
        .map(|(v, d)| v.is_finite() && (*d as f64) <= cfg.max_lookahead_m)
        .collect();
    let (qs, sign) = match regime {
        ThermalRegime::Transition => return Ok(out),
        ThermalRegime::Night => ([0.05, 0.25], 1.0f32),
        ThermalRegime::Day => ([0.95, 0.75], -1.0f32),
    };
    let stats = band_percentiles(img, &include, cfg.half_band_rows, &qs);
    for (i, o) in out.data.iter_mut().enumerate() {
        // The band's statistics use grazing pixels too (cut at the gate, a band could be
        // mostly water); only the decision is gated.
        if !include[i] || geom.incidence[i] as f64 > cfg.max_incidence {
            continue;
        }
        let Some(q) = &stats[i / img.width] else {
            continue;
        };
        // Night: q[0] = q05, q[1] = q25; day: q95, q75 (mirror image).
        let sigma = (q[1] - q[0]).abs() / 0.971;
        let mu = q[1] + sign * 0.674 * sigma;
        let c = sign * (img.data[i] - mu);
        *o = if c > cfg.k_sigma * sigma && c > cfg.min_contrast {
            Label::Water
        } else {
            Label::Other
        };
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]
mod tests {
    use super::*;
    use crate::classify::horizon::tests::cam_pose;
    use crate::geom::{CameraModel, Distortion};

    /// Deterministic pseudo-noise in [−1, 1).
    fn noise(i: usize) -> f32 {
        let mut z = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        ((z >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }

    /// 80 × 60 camera 1.5 m up, pitched 20° down; a "pond" in image columns 30..50, rows 40..55.
    fn scene() -> (CameraModel, GroundGeometry, Vec<bool>) {
        let cam = CameraModel::new(
            80,
            60,
            [60.0, 60.0, 39.5, 29.5],
            Distortion::PlumbBob([-0.05, 0.01, 0.0, 0.0, 0.0]),
            "c",
        )
        .unwrap();
        let g = GroundGeometry::level(&cam, &cam_pose(1.5, 20f64.to_radians()), 0.0).unwrap();
        let water = (0..80 * 60)
            .map(|i| (30..50).contains(&(i % 80)) && (40..55).contains(&(i / 80)))
            .collect();
        (cam, g, water)
    }

    #[test]
    fn swir_dark_water_and_incidence_gate() {
        let (_, g, water) = scene();
        // Terrain 180 ± 10 %, water 40 ± 10 %: dark wherever it is.
        let data = (0..80 * 60)
            .map(|i| if water[i] { 40.0 } else { 180.0 } * (1.0 + 0.1 * noise(i)))
            .collect();
        let img = MonoImage::new(80, 60, data).unwrap();
        let l = classify_swir(&img, &g, None, &SwirConfig::default()).unwrap();
        let mut checked = 0;
        for i in 0..80 * 60 {
            let inc = g.incidence[i] as f64;
            if !(inc <= 60f64.to_radians()) {
                assert_eq!(l.data[i], Label::Unknown, "pixel {i} incidence {inc}");
            } else {
                checked += 1;
                assert_eq!(l.data[i] == Label::Water, water[i], "pixel {i}");
            }
        }
        assert!(checked > 1000, "{checked}");
        // The gate is real: rows near the horizon (grazing) have no decision.
        assert!(l.data[..80 * 25].iter().all(|&x| x == Label::Unknown));
    }

    #[test]
    fn swir_snow_needs_bright_visible() {
        let (_, g, water) = scene();
        let swir = MonoImage::new(
            80,
            60,
            (0..4800)
                .map(|i| if water[i] { 30.0 } else { 200.0 })
                .collect(),
        )
        .unwrap();
        let vis = MonoImage::new(
            80,
            60,
            (0..4800)
                .map(|i| if water[i] && i % 80 < 40 { 240.0 } else { 90.0 })
                .collect(),
        )
        .unwrap();
        let l = classify_swir(&swir, &g, Some(&vis), &SwirConfig::default()).unwrap();
        let i_snow = 45 * 80 + 35;
        let i_water = 45 * 80 + 45;
        assert_eq!(l.data[i_snow], Label::SnowIce);
        assert_eq!(l.data[i_water], Label::Water);
        assert_eq!(l.data[45 * 80 + 10], Label::Other);
        let bad = MonoImage::new(2, 2, vec![0.0; 4]).unwrap();
        assert!(classify_swir(&bad, &g, None, &SwirConfig::default()).is_err());
    }

    /// Whether the MWIR classifier decides at pixel `i` (near enough, not grazing).
    fn mwir_decides(g: &GroundGeometry, cfg: &MwirConfig, i: usize) -> bool {
        g.lookahead[i] as f64 <= cfg.max_lookahead_m && g.incidence[i] as f64 <= cfg.max_incidence
    }

    #[test]
    fn mwir_by_time_of_day() {
        let (_, g, water) = scene();
        let cfg = MwirConfig::default();
        // Terrain 280 K ± 0.5 with a gradient down the image; water +3 K at night.
        let mk = |dw: f32| {
            MonoImage::new(
                80,
                60,
                (0..4800)
                    .map(|i| {
                        280.0
                            + 0.05 * (i / 80) as f32
                            + 0.5 * noise(i)
                            + if water[i] { dw } else { 0.0 }
                    })
                    .collect(),
            )
            .unwrap()
        };
        let night = classify_mwir(&mk(3.0), &g, 3.0, &cfg).unwrap();
        let day = classify_mwir(&mk(-3.0), &g, 15.0, &cfg).unwrap();
        let wrong_way = classify_mwir(&mk(-3.0), &g, 3.0, &cfg).unwrap();
        let dusk = classify_mwir(&mk(3.0), &g, 20.5, &cfg).unwrap();
        for i in 0..4800 {
            if mwir_decides(&g, &cfg, i) {
                assert_eq!(night.data[i] == Label::Water, water[i], "night pixel {i}");
                assert_eq!(day.data[i] == Label::Water, water[i], "day pixel {i}");
                assert_ne!(
                    wrong_way.data[i],
                    Label::Water,
                    "cool water at night, pixel {i}"
                );
            } else {
                assert_eq!(night.data[i], Label::Unknown);
            }
            assert_eq!(dusk.data[i], Label::Unknown);
        }
        assert!(cfg.regime(24.0).is_err());
    }

    #[test]
    fn mwir_lookahead_limit() {
        let (_, g, water) = scene();
        let cfg = MwirConfig {
            max_lookahead_m: 5.0,
            ..Default::default()
        };
        let img = MonoImage::new(
            80,
            60,
            (0..4800)
                .map(|i| 280.0 + 0.3 * noise(i) + if water[i] { 3.0 } else { 0.0 })
                .collect(),
        )
        .unwrap();
        let l = classify_mwir(&img, &g, 2.0, &cfg).unwrap();
        for i in 0..4800 {
            assert_eq!(
                l.data[i] == Label::Unknown,
                !mwir_decides(&g, &cfg, i),
                "pixel {i}"
            );
        }
        assert!(l.data.contains(&Label::Unknown) && l.data.contains(&Label::Water));
    }

    #[test]
    fn mwir_grazing_water_reflects_the_cold_sky_and_gets_no_decision() {
        // At night a puddle near the camera, seen steeply, is 3 K warmer than the land; a
        // reservoir far off, filling three quarters of the view's width and seen beyond 60°
        // incidence, reflects the cold sky ((1 − R)·T_w + R·T_sky with the Fresnel R rising
        // towards grazing) and reads 6 K colder than the land.
        let (_, g, puddle) = scene();
        let (col, row) = (|i: usize| i % 80, |i: usize| i / 80);
        let reservoir = |i: usize| (10..70).contains(&col(i)) && row(i) < 30;
        assert!((0..4800)
            .filter(|&i| reservoir(i) && g.incidence[i].is_finite())
            .all(|i| g.incidence[i] as f64 > 70f64.to_radians()));
        let water: Vec<bool> = (0..4800).map(|i| puddle[i] || reservoir(i)).collect();
        let img = MonoImage::new(
            80,
            60,
            (0..4800)
                .map(|i| {
                    let dw = if puddle[i] {
                        3.0
                    } else if reservoir(i) {
                        -6.0
                    } else {
                        0.0
                    };
                    280.0 + 0.3 * noise(i) + dw
                })
                .collect(),
        )
        .unwrap();
        let cfg = MwirConfig::default();
        let l = classify_mwir(&img, &g, 2.0, &cfg).unwrap();
        let steep = (0..4800).filter(|&i| mwir_decides(&g, &cfg, i)).count();
        assert!(steep > 100 && steep < 4000, "{steep} pixels decided");
        for i in 0..4800 {
            if mwir_decides(&g, &cfg, i) {
                assert_eq!(l.data[i] == Label::Water, water[i], "pixel {i}");
            } else {
                assert_eq!(l.data[i], Label::Unknown, "grazing pixel {i}");
            }
        }
        // Without the gate the cold side of a grazing row is the water, and the land
        // beside it passes for warm water.
        let ungated = MwirConfig {
            max_incidence: 90f64.to_radians(),
            ..cfg
        };
        let l = classify_mwir(&img, &g, 2.0, &ungated).unwrap();
        let land_called_water = (0..4800)
            .filter(|&i| !water[i] && l.data[i] == Label::Water)
            .count();
        assert!(land_called_water > 100, "{land_called_water}");
    }
}
