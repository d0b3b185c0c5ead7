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

/// Settings of the reflectivity cue (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReflectivityConfig {
    /// Which per-point channel to read.
    pub channel: Channel,
    /// A return is dark below this quantile of the scan's ground returns (0..1); keep it
    /// equal to the fusion's `p_dark_dry`.
    pub dark_quantile: f64,
    /// Range band of the returns used (m): close returns saturate, far ones are noisy.
    pub min_range_m: f64,
    /// Upper end of that band, metres.
    pub max_range_m: f64,
    /// Returns at a grazing incidence (cos θ below this) are not used.
    pub min_cos_incidence: f64,
    /// Fewest ground returns a scan needs to set its reference.
    pub min_samples: usize,
    /// Whether the channel read is range-compensated. Absent: by its name (`reflectivity`
    /// is, `intensity` is not). The mapper sets it from how the channel falls with range
    /// over the log's ground ([`crate::calib::IntensityLaw`]), whatever its name says.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range_compensated: Option<bool>,
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
            range_compensated: None,
        }
    }
}

impl ReflectivityConfig {
    /// Checks the quantile, range band and incidence limit; an `Error::Invalid` says which
    /// value is out of range.
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
    /// The scan's dark threshold (a residual from `law`, natural log).
    pub threshold: f64,
    /// The channel's law over this scan's ground.
    pub law: ChannelLaw,
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
    let (v, calibrated) = channel_value(cloud, slot, cfg)?;
    Some(if calibrated {
        v / cos_inc
    } else {
        v * range * range / cos_inc
    })
}

/// How a channel's value falls along one scan's ground: ln v = `offset` + `exponent`·ln r,
/// fitted by least squares to the scan's ground returns (those beyond 3 median absolute
/// deviations of the first fit, water among them, dropped and the fit repeated).
///
/// Range and incidence cannot be told apart on level ground from one sensor height:
/// cos θ = h / r, so ρ·cosᵐθ·rᵏ = ρ·hᵐ·r^(k−m). What a scan determines is the combined
/// falloff: −3 for raw intensity of Lambertian ground (cos θ / r²), −1 for a range-corrected
/// reflectivity of it, steeper for smooth ground whose backscatter falls faster with
/// incidence. The fit takes whichever convention and surface the scan has, so a drop is
/// measured against the scan's own law, not an assumed one.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ChannelLaw {
    /// `ln v` at a range of 1 m (natural log of the channel's units).
    pub offset: f64,
    /// Slope of `ln v` against `ln r`.
    pub exponent: f64,
    /// Returns the fit used.
    pub samples: usize,
}

impl ChannelLaw {
    /// The law physics gives level Lambertian ground: v ∝ cos θ / r² ∝ r⁻³ for raw
    /// intensity, v ∝ cos θ ∝ r⁻¹ for a range-corrected reflectivity.
    pub(crate) fn lambertian(calibrated: bool) -> Self {
        ChannelLaw {
            offset: 0.0,
            exponent: if calibrated { -1.0 } else { -3.0 },
            samples: 0,
        }
    }

    /// ln of the value relative to the law at that range (0 = on the law).
    pub fn residual(&self, v: f64, range: f64) -> f64 {
        v.ln() - self.offset - self.exponent * range.ln()
    }

    /// Least-squares fit to (value, range) samples with positive finite values; `None` when
    /// fewer than `min_samples` remain or the ranges do not spread enough to fit a slope.
    pub fn fit(samples: &[(f64, f64)], min_samples: usize) -> Option<ChannelLaw> {
        let rows: Vec<[f64; 2]> = samples
            .iter()
            .filter(|(v, r)| *v > 0.0 && *r > 0.0 && v.is_finite() && r.is_finite())
            .map(|(v, r)| [r.ln(), v.ln()])
            .filter(|[x, y]| x.is_finite() && y.is_finite())
            .collect();
        let line = |keep: &dyn Fn(&[f64; 2]) -> bool| -> Option<(f64, f64, usize)> {
            let kept = rows.iter().filter(|r| keep(r));
            let (n, sx, sy) = kept.clone().fold((0usize, 0.0, 0.0), |(n, sx, sy), r| {
                (n + 1, sx + r[0], sy + r[1])
            });
            if n < min_samples.max(3) {
                return None;
            }
            let (mx, my) = (sx / n as f64, sy / n as f64);
            let (sxx, sxy) = kept.fold((0.0, 0.0), |(a, b), r| {
                (a + (r[0] - mx) * (r[0] - mx), b + (r[0] - mx) * (r[1] - my))
            });
            // ln r must spread: a scan at one range has no slope.
            if sxx.is_nan() || sxx / n as f64 <= 1e-6 {
                return None;
            }
            let e = sxy / sxx;
            (e.is_finite() && my.is_finite()).then_some((my - e * mx, e, n))
        };
        let (a0, e0, _) = line(&|_| true)?;
        let resid = |r: &[f64; 2]| (r[1] - a0 - e0 * r[0]).abs();
        let mut dev: Vec<f64> = rows.iter().map(resid).collect();
        let mid = dev.len() / 2;
        dev.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        let cut = 3.0 * dev[mid].max(1e-12);
        let (offset, exponent, samples) = line(&|r| resid(r) <= cut)?;
        Some(ChannelLaw {
            offset,
            exponent,
            samples,
        })
    }
}

/// The value of `slot`'s strength channel and whether it is range-corrected (the config's
/// `range_compensated`, else by the channel's name); `None` without a usable value.
pub(crate) fn channel_value(
    cloud: &PointCloud,
    slot: usize,
    cfg: &ReflectivityConfig,
) -> Option<(f64, bool)> {
    let (v, by_name) = match cfg.channel {
        Channel::Reflectivity => (cloud.reflectivity.as_ref()?[slot], true),
        Channel::Intensity => (cloud.intensity.as_ref()?[slot], false),
        Channel::Auto => match (&cloud.reflectivity, &cloud.intensity) {
            (Some(r), _) => (r[slot], true),
            (None, Some(i)) => (i[slot], false),
            (None, None) => return None,
        },
    };
    let v = v as f64;
    (v.is_finite() && v > 0.0).then_some((v, cfg.range_compensated.unwrap_or(by_name)))
}

/// The name of the channel `cfg` reads from `cloud`, when it has one.
pub(crate) fn channel_name(cloud: &PointCloud, cfg: &ReflectivityConfig) -> Option<&'static str> {
    match (cfg.channel, &cloud.reflectivity, &cloud.intensity) {
        (Channel::Reflectivity | Channel::Auto, Some(_), _) => Some("reflectivity"),
        (Channel::Intensity, _, Some(_)) | (Channel::Auto, None, Some(_)) => Some("intensity"),
        _ => None,
    }
}

/// Sets the scan's reference and adds dark/lit counts to the cells: a return is dark when
/// its residual from the scan's fitted [`ChannelLaw`] (the Lambertian law when the scan
/// cannot be fitted) lies below the `dark_quantile` of the residuals.
pub(crate) fn apply(
    cloud: &PointCloud,
    cfg: &ReflectivityConfig,
    samples: &[ReflectivitySample],
    ev: &mut EvidenceMap,
) -> Option<Applied> {
    let in_band = |s: &ReflectivitySample| {
        s.range >= cfg.min_range_m
            && s.range <= cfg.max_range_m
            && s.cos_inc >= cfg.min_cos_incidence
    };
    let raw: Vec<(usize, f64, bool)> = samples
        .iter()
        .enumerate()
        .filter(|(_, s)| in_band(s))
        .filter_map(|(k, s)| channel_value(cloud, s.slot, cfg).map(|(v, c)| (k, v, c)))
        .collect();
    if raw.len() < cfg.min_samples.max(1) {
        return None;
    }
    let fit_input: Vec<(f64, f64)> = raw.iter().map(|&(k, v, _)| (v, samples[k].range)).collect();
    let law = ChannelLaw::fit(&fit_input, cfg.min_samples)
        .unwrap_or_else(|| ChannelLaw::lambertian(raw[0].2));
    let vals: Vec<(usize, f64)> = raw
        .iter()
        .map(|&(k, v, _)| (k, law.residual(v, samples[k].range)))
        .collect();
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
        law,
    })
}

#[cfg(test)]
mod tests {
    use super::ChannelLaw;
    use proptest::prelude::*;

    /// Level ground seen from 1.8 m whose channel follows v = k · cosᵐθ · rᵇ (2–40 m), with
    /// ±2 % texture and one return in 40 dark as water (a tenth), which the refit leaves out.
    fn scan(k: f64, b: f64, m: f64) -> Vec<(f64, f64)> {
        (0..400)
            .map(|i| {
                let d = 2.0 + 38.0 * (i as f64 / 400.0);
                let r = (d * d + 1.8f64 * 1.8).sqrt();
                let cos = 1.8 / r;
                let ripple = 1.0 + 0.02 * ((i * 7919 % 13) as f64 / 6.0 - 1.0);
                let dark = if i % 40 == 0 { 0.1 } else { 1.0 };
                (k * r.powf(b) * cos.powf(m) * ripple * dark, r)
            })
            .collect()
    }

    proptest! {
        /// The fit recovers the combined falloff b − m of either convention and any
        /// backscatter exponent; a return on the law has residual ~0, a water-dark one
        /// (a tenth) about ln 0.1.
        #[test]
        fn fit_recovers_the_channel_law(k in 1.0f64..1e4, b in -2.5f64..0.5, m in 0.5f64..3.5) {
            let law = ChannelLaw::fit(&scan(k, b, m), 50).unwrap();
            prop_assert!((law.exponent - (b - m)).abs() < 0.05, "{law:?}");
            let r = 10.0f64;
            let on = k * r.powf(b) * (1.8 / r).powf(m);
            prop_assert!(law.residual(on, r).abs() < 0.05, "{law:?}");
            prop_assert!((law.residual(0.1 * on, r) - 0.1f64.ln()).abs() < 0.05);
        }
    }

    #[test]
    fn degenerate_scans_have_no_law() {
        // One range: no slope.
        let one: Vec<_> = (0..100).map(|i| (1.0 + i as f64 * 0.01, 10.0)).collect();
        assert_eq!(ChannelLaw::fit(&one, 50), None);
        // Too few samples, no positive values, nothing at all.
        assert_eq!(ChannelLaw::fit(&scan(1.0, -2.0, 1.0)[..20], 50), None);
        assert_eq!(ChannelLaw::fit(&[(0.0, 10.0); 100], 50), None);
        assert_eq!(ChannelLaw::fit(&[], 50), None);
        // Absurd but finite values give a finite law or none.
        let huge: Vec<_> = (0..100)
            .map(|i| (1e300 / (i + 1) as f64, 1e-300 * (i + 1) as f64))
            .collect();
        assert!(ChannelLaw::fit(&huge, 50)
            .is_none_or(|l| l.exponent.is_finite() && l.offset.is_finite()));
    }
}
