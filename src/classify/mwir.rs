//! MWIR thermal contrast (paper section 5): water is warmer than the terrain at night and cooler by day (paper Fig. 12:
//! warmer from about 23:00 to 08:00). Terrain level and spread come from the cold side
//! of the band at night (5th and 25th percentiles: σ = (q25 − q05)/0.971, μ = q25 + 0.674σ for a
//! normal distribution), from the warm side by day (75th, 95th); a pixel more than
//! `k_sigma`·σ and `min_contrast` beyond μ on the water side is water. Around dawn and dusk
//! the contrast reverses and there is no decision. Beyond `max_incidence` (60°) there is
//! no decision either: water's apparent temperature is (1 − R)·T_water + R·T_sky, and its
//! Fresnel reflectance R (n ≈ 1.35 at 3–5 µm) rises from 6 % at 60° to 35 % at 80° and
//! 65 % at 86°, so towards grazing incidence the cold sky it reflects takes over and the
//! water looks *colder* than the land at night (the paper saw the water darken towards
//! the far shore). On the simulated night reservoir, seen at 83–88°, the water reads 5–7 K
//! below the land; the cold side of such a band is water, so without the gate the land
//! beside it passed for warm water (13 % of the dry cells called water). Nor is there a
//! decision beyond `max_lookahead_m`.

use serde::{Deserialize, Serialize};

use super::horizon::GroundGeometry;
use super::thermal::{band_percentiles, check_sizes};
use super::{Label, LabelImage, MonoImage};
use crate::error::{Error, Result};

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
    use crate::classify::thermal::tests::{noise, scene};

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
