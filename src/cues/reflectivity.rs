//! The reflectivity-drop cue (beyond the paper): wet ground and shallow water return less
//! of the beam than dry ground, with returns still present.
//!
//! A Lambertian surface of albedo ρ at range `r` and incidence `θ` returns power
//! `∝ ρ cos θ / r²`. The *normalised reflectivity* of a ground return is therefore
//! `intensity · r² / cos θ` for a raw intensity channel, or `reflectivity / cos θ` for a
//! sensor-calibrated reflectivity channel (already range-compensated, as the Ouster's),
//! with `cos θ` the incidence on level ground. Each scan is its own reference: a ground
//! return is *dark* when its normalised value is below the `dark_quantile` quantile of the
//! scan's ground returns in the range band, else *lit*. Most ground in a scan is dry, so
//! about `dark_quantile` of dry ground reads dark by construction: that is the fusion's
//! `p_dark_dry`, not a tuned number. Both counts go to the cell
//! ([`crate::grid::Evidence::dark`], `lit`); the fusion rule turns them into weak evidence.

use serde::{Deserialize, Serialize};

use super::EvidenceMap;
use crate::error::{Error, Result};
use crate::geom::PointCloud;

/// Which per-point channel carries the return strength.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Channel {
    /// `reflectivity` when the cloud has it, else `intensity`.
    #[default]
    Auto,
    /// Calibrated (range-compensated) reflectivity.
    Reflectivity,
    /// Raw intensity (falls as 1/r²).
    Intensity,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReflectivityConfig {
    pub channel: Channel,
    /// A return is dark below this quantile of the scan's ground returns (0..1); keep it
    /// equal to the fusion's `p_dark_dry`.
    pub dark_quantile: f64,
    /// Range band of the returns used (m): close returns saturate, far ones are noisy.
    pub min_range_m: f64,
    pub max_range_m: f64,
    /// Returns at a grazing incidence (cos θ below this) are not used.
    pub min_cos_incidence: f64,
    /// Fewest ground returns a scan needs to set its reference.
    pub min_samples: usize,
}

impl Default for ReflectivityConfig {
    fn default() -> Self {
        ReflectivityConfig {
            channel: Channel::Auto,
            dark_quantile: 0.15,
            min_range_m: 2.0,
            max_range_m: 40.0,
            min_cos_incidence: 0.05,
            min_samples: 50,
        }
    }
}

impl ReflectivityConfig {
    pub fn validate(&self) -> Result<()> {
        let ok = self.dark_quantile > 0.0
            && self.dark_quantile < 1.0
            && self.min_range_m.is_finite()
            && self.min_range_m >= 0.0
            && self.max_range_m > self.min_range_m
            && self.min_cos_incidence > 0.0
            && self.min_cos_incidence <= 1.0;
        if ok {
            Ok(())
        } else {
            Err(Error::invalid(
                "reflectivity cue",
                format!(
                    "dark_quantile {} must be in (0, 1), ranges {}..{} m increasing and ≥ 0, \
                     min_cos_incidence {} in (0, 1]",
                    self.dark_quantile, self.min_range_m, self.max_range_m, self.min_cos_incidence
                ),
            ))
        }
    }
}

/// A ground return offered to the cue.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ReflectivitySample {
    pub slot: usize,
    pub x: f64,
    pub y: f64,
    pub cos_inc: f64,
    pub range: f64,
}

pub(crate) struct Applied {
    pub dark: u64,
    pub lit: u64,
    /// The scan's dark threshold (normalised units).
    pub threshold: f64,
}

/// Normalised reflectivity of slot `slot` (see the module documentation); `None` without a
/// usable channel value or outside the configured band.
pub fn normalised_reflectivity(
    cloud: &PointCloud,
    slot: usize,
    cos_inc: f64,
    range: f64,
    cfg: &ReflectivityConfig,
) -> Option<f64> {
    if !(range >= cfg.min_range_m && range <= cfg.max_range_m && cos_inc >= cfg.min_cos_incidence) {
        return None;
    }
    let (v, calibrated) = match cfg.channel {
        Channel::Reflectivity => (cloud.reflectivity.as_ref()?[slot], true),
        Channel::Intensity => (cloud.intensity.as_ref()?[slot], false),
        Channel::Auto => match (&cloud.reflectivity, &cloud.intensity) {
            (Some(r), _) => (r[slot], true),
            (None, Some(i)) => (i[slot], false),
            (None, None) => return None,
        },
    };
    let v = v as f64;
    if !(v.is_finite() && v > 0.0) {
        return None;
    }
    Some(if calibrated {
        v / cos_inc
    } else {
        v * range * range / cos_inc
    })
}

/// Sets the scan's reference and adds dark/lit counts to the cells.
pub(crate) fn apply(
    cloud: &PointCloud,
    cfg: &ReflectivityConfig,
    samples: &[ReflectivitySample],
    ev: &mut EvidenceMap,
) -> Option<Applied> {
    let vals: Vec<(usize, f64)> = samples
        .iter()
        .enumerate()
        .filter_map(|(k, s)| {
            normalised_reflectivity(cloud, s.slot, s.cos_inc, s.range, cfg).map(|v| (k, v))
        })
        .collect();
    if vals.len() < cfg.min_samples.max(1) {
        return None;
    }
    let mut sorted: Vec<f64> = vals.iter().map(|v| v.1).collect();
    let q = ((sorted.len() as f64 * cfg.dark_quantile) as usize).min(sorted.len() - 1);
    sorted.select_nth_unstable_by(q, |a, b| a.total_cmp(b));
    let threshold = sorted[q];
    let (mut dark, mut lit) = (0, 0);
    for (k, v) in vals {
        let s = &samples[k];
        if let Some(e) = ev.at(s.x, s.y) {
            if v < threshold {
                e.dark = e.dark.saturating_add(1);
                dark += 1;
            } else {
                e.lit = e.lit.saturating_add(1);
                lit += 1;
            }
        }
    }
    Some(Applied {
        dark,
        lit,
        threshold,
    })
}
