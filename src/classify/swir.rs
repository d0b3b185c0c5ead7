//! SWIR darkness (paper section 4). At about 1.5 µm water, snow and ice absorb, so they are dark — at moderate
//! incidence. Towards grazing incidence the Fresnel reflectance of the surface rises (paper
//! Fig. 6b) and reflected sky or trees take over, so pixels whose incidence angle (from
//! [`GroundGeometry`]) exceeds `max_incidence` get no decision ([`Label::Unknown`]). The
//! terrain reference is the `reference_percentile` of the band (bright side); a pixel darker
//! than `dark_ratio` × reference is water — or snow/ice when a co-registered visible image
//! says it is bright there (snow is white in the visible and black at 1.5 µm).

use serde::{Deserialize, Serialize};

use super::horizon::GroundGeometry;
use super::thermal::{band_percentiles, check_sizes};
use super::{Label, LabelImage, MonoImage};
use crate::error::{Error, Result};

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

#[cfg(test)]
#[allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]
mod tests {
    use super::*;
    use crate::classify::thermal::tests::{noise, scene};

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
}
