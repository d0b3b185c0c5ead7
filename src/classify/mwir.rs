//! MWIR thermal labels (paper section 5), from the physics of what a thermal camera sees
//! of level water rather than from a fixed incidence gate.
//!
//! **Units.** The rule works in brightness temperature (kelvin), converted to relative
//! in-band radiance at 4 µm (Planck) wherever radiances mix. An image value `v` is
//! `kelvin_per_count·v + kelvin_offset` kelvin; the defaults read mono16 centikelvin, what a
//! radiometric camera (and the simulator) writes. A camera whose counts are linear in
//! temperature states its calibration through `labels.mwir_kelvin_per_count` and
//! `labels.mwir_kelvin_offset`. Where over half the ground reads outside
//! [`MIN_PLAUSIBLE_K`, `MAX_PLAUSIBLE_K`] after the conversion, the values are taken as raw
//! detector counts (0–65535), linear in in-band radiance with an unknown gain and offset
//! (a photon detector integrates the flux): emission and reflection then mix as the counts
//! do, since their weights 1 − R and R sum to one, and every threshold is in units of the
//! noise measured from the image (the kelvin ones, `min_contrast` and [`MIN_NOISE_K`], do
//! not apply; counts rise with radiance).
//!
//! **Water.** At incidence θ level water reads `L = (1 − R(θ))·B(T_w) + R(θ)·L_m`: it emits
//! with emissivity 1 − R (Fresnel, n = 1.35 at 3–5 µm) and mirrors the radiance `L_m` of
//! what its mirror ray meets, which the same image shows at the mirror pixel
//! (`GroundGeometry::mirror`). From a pixel's reading and its mirror's, the temperature
//! the surface would have *if it were water* follows: `T_e = B⁻¹((L − R·L_m)/(1 − R))`.
//! Over a water body `T_e` is one temperature, whatever the incidence; over a solid (land,
//! rock, asphalt, emissivity near 1) it is the reading `T_a` that stays put, and `T_e`
//! climbs with R as the sky term is removed from a surface that does not mirror it.
//!
//! **Land.** The land's level and spread come from the side of the scene's ground pixels
//! water does not reach: the cold side at night (5th and 25th percentiles, σ = (q25 −
//! q05)/0.971, μ = q25 + 0.674σ), the warm side by day; the same for the whole lookahead
//! (land's emissivity is near 1 and 40 m of air absorb little, so its reading does not
//! depend on range). The regime comes from the local solar hour (water warmer than land
//! at night, cooler by day, paper Fig. 12); around dawn and dusk there is no decision.
//!
//! **Decision.** Ground pixels that differ from the land by `k_sigma`·σ and `min_contrast`
//! (either way: far water mirroring a cold sky reads colder than land even at night) form
//! 4-connected regions of one sign. Each region is fitted both ways: water (one `T_e`) and
//! solid (one `T_a`), each residual in units of its own noise. A region is water where
//! the water fit is the better one, its temperature is on the water side of the land for
//! the regime, and the reading water of that temperature would give varies over the
//! region by [`SEPARABLE_K`] noise σ (else the two fits cannot be told apart: Unknown).
//! In a water region a pixel is water where its `T_e` matches the region's, dry where it
//! does not (a warm shore), Unknown where the reflection it shows is too weak to tell
//! (mirroring terrain as warm as the water). A warm rock, asphalt or concrete reads one
//! temperature at every incidence: its region is fitted better as a solid and is dry.
//! Land-like pixels are dry, except where water at a temperature found in the image would
//! read like land there (Unknown). Pixels whose mirror ray leaves the image, whose water
//! would emit less than [`MIN_EMISSIVITY`] (R > 0.9, beyond about 88°), beyond
//! `max_lookahead_m`, or whose ray misses the ground are Unknown. The image's noise is
//! measured from neighbouring pixels (at least [`MIN_NOISE_K`]).

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use super::horizon::GroundGeometry;
use super::thermal::check_sizes;
use super::{Label, LabelImage, MonoImage};
use crate::error::{Error, Result};
use crate::optics::{brightness_temperature, planck_rel, water_reflectance_mwir, MWIR_UM};

/// Brightness temperatures (K) a terrestrial scene and its sky show in 3–5 µm: a clear
/// zenith reads above 180 K, sunlit ground below 350 K. Pixels outside are not trusted;
/// an image whose ground median is outside is not in kelvin as configured.
pub const MIN_PLAUSIBLE_K: f64 = 150.0;
/// See [`MIN_PLAUSIBLE_K`].
pub const MAX_PLAUSIBLE_K: f64 = 400.0;
/// The least noise (K) assumed: the NETD of the best cooled MWIR cameras is about 20 mK,
/// and a flat image measures none.
pub const MIN_NOISE_K: f64 = 0.02;
/// In raw counts, the least noise assumed: the rounding of a count (σ = 1/√12 ≈ 0.3).
pub const MIN_NOISE_COUNTS: f64 = 0.5;
/// The largest raw count (16 bits).
const MAX_COUNT: f64 = 65535.0;
/// Water emitting less than this fraction (Fresnel R > 0.9, beyond about 88° at
/// n = 1.35) shows almost only what it mirrors: its temperature cannot be inferred.
pub const MIN_EMISSIVITY: f64 = 0.1;
/// A region is decided only where water of its fitted temperature would read over a span
/// (10th to 90th percentile) of this many noise σ across it: the reflection signature.
pub const SEPARABLE_K: f64 = 3.0;
/// A pixel of a water region is water within this many of its σ of the region's
/// temperature; its reflection must show by as many noise σ.
pub const WATER_K: f64 = 3.0;
/// Regions of fewer pixels are not fitted (Unknown).
pub const MIN_REGION_PIXELS: usize = 12;

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
    /// Land spreads (σ) a pixel must differ from the land's level by to be a candidate.
    pub k_sigma: f32,
    /// Smallest difference from the land's level (K) for a candidate, and for a water
    /// region's temperature on the water side of the land.
    pub min_contrast: f32,
    /// No decision beyond this horizontal distance, metres.
    pub max_lookahead_m: f64,
    /// Kelvin per image count (0.01: centikelvin).
    pub kelvin_per_count: f64,
    /// Kelvin at count 0.
    pub kelvin_offset: f64,
}

impl Default for MwirConfig {
    fn default() -> Self {
        MwirConfig {
            night_hours: [23.0, 8.0],
            day_hours: [10.0, 19.0],
            k_sigma: 3.0,
            min_contrast: 0.5,
            max_lookahead_m: 40.0,
            kelvin_per_count: 0.01,
            kelvin_offset: 0.0,
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

    fn validate(&self) -> Result<()> {
        if !(self.k_sigma >= 0.0
            && self.min_contrast >= 0.0
            && self.max_lookahead_m > 0.0
            && self.kelvin_per_count.is_finite()
            && self.kelvin_per_count > 0.0
            && self.kelvin_offset.is_finite())
        {
            return Err(Error::invalid("MWIR config", format!("{self:?}")));
        }
        Ok(())
    }
}

/// What the image's values are: kelvin, or raw counts linear in in-band radiance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scale {
    /// Brightness temperature; radiances mix through Planck at 4 µm.
    Kelvin,
    /// Raw detector counts, an unknown gain and offset from the radiance: radiances mix
    /// as the counts do, since the weights (1 − R and R) sum to one.
    Counts,
}

impl Scale {
    /// The radiance of a reading (relative; for counts the counts themselves).
    fn radiance(self, t: f64) -> f64 {
        match self {
            Scale::Kelvin => planck_rel(MWIR_UM, t),
            Scale::Counts => t,
        }
    }

    /// The reading of a radiance ([`Self::radiance`]'s inverse; NaN for none in kelvin).
    fn reading(self, l: f64) -> f64 {
        match self {
            Scale::Kelvin => brightness_temperature(MWIR_UM, l),
            Scale::Counts => l,
        }
    }

    /// What level water at `t_w` reads with reflectance `r`, mirroring radiance `l_m`.
    fn water_reading(self, t_w: f64, r: f64, l_m: f64) -> f64 {
        self.reading((1.0 - r) * self.radiance(t_w) + r * l_m)
    }

    /// Radiance per unit of reading at `t`.
    fn slope(self, t: f64) -> f64 {
        (self.radiance(t + 0.05) - self.radiance(t - 0.05)) / 0.1
    }
}

/// The `q` quantile (0..1) of `v` (sorted in place); NaN when empty.
fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// The midpoint and σ of the shortest interval that holds half of `v` (Rousseeuw's
/// shorth; ±0.674σ for a normal population): the land's level and spread, whichever side
/// of it the rest lies.
fn shorth(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    let half = v.len() / 2;
    let (mut best, mut at) = (f64::INFINITY, 0);
    for i in 0..v.len() - half {
        let width = v[i + half] - v[i];
        if width < best {
            (best, at) = (width, i);
        }
    }
    (0.5 * (v[at] + v[at + half]), 0.5 * best / 0.674)
}

/// One ground pixel the rule can decide: its reading, reflectance, mirrored radiance and
/// the water temperature it implies.
#[derive(Debug, Clone, Copy)]
struct Px {
    t_a: f64,
    r: f64,
    l_m: f64,
    /// `B⁻¹((B(t_a) − r·l_m)/(1 − r))`; NaN where the mirror outshines the reading.
    t_e: f64,
    /// σ of `t_e` from the image noise.
    sd_e: f64,
}

/// Labels an MWIR image taken at local solar `hour`. See the module documentation.
pub(crate) fn classify_mwir(
    img: &MonoImage,
    geom: &GroundGeometry,
    hour: f64,
    cfg: &MwirConfig,
) -> Result<LabelImage> {
    check_sizes(img, geom, "MWIR image")?;
    cfg.validate()?;
    let regime = cfg.regime(hour)?;
    let (w, h) = (img.width, img.height);
    let mut out = LabelImage::filled(w, h, Label::Unknown);
    let sign = match regime {
        ThermalRegime::Transition => return Ok(out),
        ThermalRegime::Night => 1.0,
        ThermalRegime::Day => -1.0,
    };
    let on_ground: Vec<bool> = (0..w * h)
        .map(|i| geom.incidence[i].is_finite() && (geom.lookahead[i] as f64) <= cfg.max_lookahead_m)
        .collect();
    let n_on_ground = on_ground.iter().filter(|&&g| g).count();
    let as_kelvin: Vec<f64> = img
        .data
        .iter()
        .map(|&v| {
            let t = cfg.kelvin_per_count * v as f64 + cfg.kelvin_offset;
            if (MIN_PLAUSIBLE_K..=MAX_PLAUSIBLE_K).contains(&t) {
                t
            } else {
                f64::NAN
            }
        })
        .collect();
    let count = |v: &[f64]| {
        (0..w * h)
            .filter(|&i| on_ground[i] && v[i].is_finite())
            .count()
    };
    // Most of the ground outside the plausible temperatures: not kelvin as configured, so
    // raw counts (within 16 bits), linear in radiance.
    let (scale, kelvin) = if 2 * count(&as_kelvin) >= n_on_ground {
        (Scale::Kelvin, as_kelvin)
    } else {
        let counts: Vec<f64> = img
            .data
            .iter()
            .map(|&v| {
                let v = v as f64;
                if (0.0..=MAX_COUNT).contains(&v) {
                    v
                } else {
                    f64::NAN
                }
            })
            .collect();
        (Scale::Counts, counts)
    };
    let ground: Vec<bool> = (0..w * h)
        .map(|i| on_ground[i] && kelvin[i].is_finite())
        .collect();
    let n_ground = ground.iter().filter(|&&g| g).count();
    if n_ground < MIN_REGION_PIXELS || 2 * n_ground < n_on_ground {
        return Ok(out);
    }
    // Kelvin thresholds apply to kelvin; counts are judged against their noise alone.
    let (min_noise, min_contrast) = match scale {
        Scale::Kelvin => (MIN_NOISE_K, cfg.min_contrast as f64),
        Scale::Counts => (MIN_NOISE_COUNTS, 0.0),
    };

    // The image's noise: horizontal neighbours on the ground differ by √2·σ.
    let mut diffs: Vec<f64> = (0..w * h)
        .filter(|&i| i % w + 1 < w && ground[i] && ground[i + 1])
        .map(|i| (kelvin[i + 1] - kelvin[i]).abs())
        .collect();
    let noise = (1.4826 * quantile(&mut diffs, 0.5) / std::f64::consts::SQRT_2).max(min_noise);
    // The land: the densest half of the ground's readings (the shorth: water's readings
    // spread with its reflectance, on either side of the land's).
    let mut vals: Vec<f64> = (0..w * h)
        .filter(|&i| ground[i])
        .map(|i| kelvin[i])
        .collect();
    let (land, land_sd) = shorth(&mut vals);
    let land_sd = land_sd.max(noise);
    let margin = (cfg.k_sigma as f64 * land_sd).max(min_contrast);

    // Per ground pixel with a mirror in view and water there emitting enough.
    let px: Vec<Option<Px>> = (0..w * h)
        .map(|i| {
            if !ground[i] {
                return None;
            }
            let j = geom.mirror[i] as usize;
            let t_m = *kelvin.get(j)?;
            let r = water_reflectance_mwir(geom.incidence[i] as f64);
            if !t_m.is_finite() || 1.0 - r < MIN_EMISSIVITY {
                return None;
            }
            let (t_a, l_m) = (kelvin[i], scale.radiance(t_m));
            let t_e = scale.reading((scale.radiance(t_a) - r * l_m) / (1.0 - r));
            Some(Px {
                t_a,
                r,
                l_m,
                t_e,
                sd_e: noise * (1.0 + r * r).sqrt() / (1.0 - r),
            })
        })
        .collect();
    // Candidates: −1 colder, +1 warmer than the land; 0 land-like.
    let side = |i: usize| -> i8 {
        let d = kelvin[i] - land;
        if d > margin {
            1
        } else if d < -margin {
            -1
        } else {
            0
        }
    };
    let mut region = vec![u32::MAX; w * h];
    let mut waters: Vec<f64> = Vec::new();
    let mut next = 0u32;
    for start in 0..w * h {
        if px[start].is_none() || region[start] != u32::MAX || side(start) == 0 {
            continue;
        }
        let s = side(start);
        let mut members = vec![start];
        region[start] = next;
        let mut queue = VecDeque::from([start]);
        while let Some(i) = queue.pop_front() {
            let (x, y) = (i % w, i / w);
            let nbrs = [
                (x > 0).then(|| i - 1),
                (x + 1 < w).then(|| i + 1),
                (y > 0).then(|| i - w),
                (y + 1 < h).then(|| i + w),
            ];
            for j in nbrs.into_iter().flatten() {
                if px[j].is_some() && region[j] == u32::MAX && side(j) == s {
                    region[j] = next;
                    members.push(j);
                    queue.push_back(j);
                }
            }
        }
        next += 1;
        let ps: Vec<Px> = members.iter().map(|&i| px[i].expect("member")).collect();
        // How far water must lie on its side of the land: the kelvin contrast, or for counts
        // the candidates' margin.
        let premise = match scale {
            Scale::Kelvin => min_contrast,
            Scale::Counts => margin,
        };
        let verdict = judge(scale, &ps, noise, land, premise, sign);
        for (&i, p) in members.iter().zip(&ps) {
            out.data[i] = match verdict {
                Verdict::Unknown => Label::Unknown,
                Verdict::Solid => Label::Other,
                Verdict::Water { t_w, tol } => {
                    let shown = p.r * (scale.radiance(t_w) - p.l_m).abs() / scale.slope(t_w);
                    if shown < WATER_K * noise {
                        Label::Unknown
                    } else if (p.t_e - t_w).abs() <= WATER_K * p.sd_e.max(tol) {
                        Label::Water
                    } else {
                        Label::Other
                    }
                }
            };
        }
        if let Verdict::Water { t_w, .. } = verdict {
            waters.push(t_w);
        }
    }
    // Land-like pixels: dry, unless water found in the image would read like land there.
    for (i, p) in px.iter().enumerate() {
        let Some(p) = p else { continue };
        if side(i) != 0 {
            continue;
        }
        let hidden = waters
            .iter()
            .any(|&t_w| (scale.water_reading(t_w, p.r, p.l_m) - land).abs() <= margin);
        out.data[i] = if hidden { Label::Unknown } else { Label::Other };
    }
    Ok(out)
}

/// What a candidate region is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Verdict {
    /// The two fits cannot be told apart, or too few pixels.
    Unknown,
    /// One temperature at every incidence: land, rock, asphalt.
    Solid,
    /// One water temperature `t_w` (K), its pixels' spread `tol` about it.
    Water { t_w: f64, tol: f64 },
}

/// Fits a region as water (one `t_e`) and as a solid (one `t_a`). See the module docs.
fn judge(scale: Scale, ps: &[Px], noise: f64, land: f64, premise: f64, sign: f64) -> Verdict {
    if ps.len() < MIN_REGION_PIXELS {
        return Verdict::Unknown;
    }
    let mut te: Vec<f64> = ps.iter().map(|p| p.t_e).filter(|t| t.is_finite()).collect();
    if 2 * te.len() < ps.len() {
        // Most of the region reads darker than what it would mirror: not water.
        return Verdict::Solid;
    }
    let t_w = quantile(&mut te, 0.5);
    let mut ta: Vec<f64> = ps.iter().map(|p| p.t_a).collect();
    let t_s = quantile(&mut ta, 0.5);
    let mut res_w: Vec<f64> = ps
        .iter()
        .map(|p| {
            let r = (p.t_e - t_w).abs() / p.sd_e;
            if r.is_nan() {
                f64::INFINITY
            } else {
                r
            }
        })
        .collect();
    let mut res_s: Vec<f64> = ps.iter().map(|p| (p.t_a - t_s).abs() / noise).collect();
    let mut pred: Vec<f64> = ps
        .iter()
        .map(|p| scale.water_reading(t_w, p.r, p.l_m))
        .collect();
    let span = quantile(&mut pred, 0.9) - quantile(&mut pred, 0.1);
    if span.is_nan() || span < SEPARABLE_K * noise {
        return Verdict::Unknown;
    }
    let (rw, rs) = (quantile(&mut res_w, 0.5), quantile(&mut res_s, 0.5));
    if rw < rs && sign * (t_w - land) > premise {
        let mut dev: Vec<f64> = te.iter().map(|t| (t - t_w).abs()).collect();
        Verdict::Water {
            t_w,
            tol: 1.4826 * quantile(&mut dev, 0.5),
        }
    } else {
        Verdict::Solid
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;
    use crate::classify::horizon::tests::cam_pose;
    use crate::classify::thermal::tests::noise;
    use crate::geom::{CameraModel, Distortion};
    use crate::optics::apparent_temperature;
    use proptest::prelude::*;

    const W: usize = 80;
    const H: usize = 60;
    const NIGHT: f64 = 3.0;
    const DAY: f64 = 14.0;

    /// 80 × 60 camera 1.5 m up, pitched 10° down, 73° vertical field: the horizon at row
    /// 22, the sky up to 26° elevation, so water out to 70° incidence mirrors the sky in
    /// view.
    fn geometry(pitch_deg: f64) -> GroundGeometry {
        let cam = CameraModel::new(W, H, [40.0, 40.0, 39.5, 29.5], Distortion::None, "c").unwrap();
        GroundGeometry::level(&cam, &cam_pose(1.5, pitch_deg.to_radians()), 0.0).unwrap()
    }

    fn deg(g: &GroundGeometry, i: usize) -> f64 {
        (g.incidence[i] as f64).to_degrees()
    }

    /// The pond: columns 20..60, incidence 70–88°, within the lookahead.
    fn pond(g: &GroundGeometry, i: usize) -> bool {
        (20..60).contains(&(i % W)) && (70.0..88.0).contains(&deg(g, i)) && g.lookahead[i] <= 40.0
    }

    /// The warm rock: columns 2..14, rows 28..40.
    fn rock(i: usize) -> bool {
        (2..14).contains(&(i % W)) && (28..40).contains(&(i / W))
    }

    /// A bank above the horizon, columns 45..60, as warm as the water.
    fn bank(g: &GroundGeometry, i: usize) -> bool {
        (45..60).contains(&(i % W)) && !g.incidence[i].is_finite()
    }

    struct Scene {
        land: f64,
        water: f64,
        rock: f64,
        bank: Option<f64>,
        noise_k: f64,
    }

    /// Kelvin per pixel: a sky from 282 K at the horizon to 232 K at the zenith, land,
    /// a rock, the pond mirroring whatever its mirror pixel shows (the sky, or the bank).
    fn render(g: &GroundGeometry, s: &Scene) -> Vec<f64> {
        let mut t = vec![0.0; W * H];
        for i in 0..W * H {
            if !g.incidence[i].is_finite() {
                // Elevation from the row: the camera's optical axis is 10° down.
                let el = (10f64.to_radians() - ((i / W) as f64 - 29.5).atan2(40.0)).max(0.0);
                t[i] = match s.bank {
                    Some(b) if bank(g, i) => b,
                    _ => 282.0 - 50.0 * el.sin().sqrt(),
                };
            }
        }
        for i in 0..W * H {
            if g.incidence[i].is_finite() {
                t[i] = if rock(i) {
                    s.rock
                } else if pond(g, i) {
                    let m = g.mirror[i] as usize;
                    let r = water_reflectance_mwir(g.incidence[i] as f64);
                    apparent_temperature(r, s.water, t[m])
                } else {
                    s.land
                };
            }
        }
        for (i, v) in t.iter_mut().enumerate() {
            *v += s.noise_k * noise(i) as f64 * 1.7;
        }
        t
    }

    fn centikelvin(t: &[f64]) -> MonoImage {
        MonoImage::new(W, H, t.iter().map(|v| (v * 100.0) as f32).collect()).unwrap()
    }

    fn night() -> Scene {
        Scene {
            land: 280.0,
            water: 282.0,
            rock: 282.0,
            bank: Some(282.0),
            noise_k: 0.05,
        }
    }

    fn count(l: &LabelImage, f: impl Fn(usize) -> bool, label: Label) -> usize {
        (0..W * H).filter(|&i| f(i) && l.data[i] == label).count()
    }

    #[test]
    fn night_pond_mirroring_the_measured_sky_is_water_and_a_warm_rock_is_not() {
        let g = geometry(10.0);
        let s = night();
        let l = classify_mwir(
            &centikelvin(&render(&g, &s)),
            &g,
            NIGHT,
            &MwirConfig::default(),
        )
        .unwrap();
        let mirrors_bank = |i: usize| bank(&g, g.mirror[i] as usize);
        let open = |i: usize| pond(&g, i) && !mirrors_bank(i);
        let n = (0..W * H).filter(|&i| open(i)).count();
        let water = count(&l, open, Label::Water);
        assert!(n > 300, "{n}");
        assert!(
            water as f64 >= 0.7 * n as f64,
            "{water} of {n} pond pixels water"
        );
        assert!(count(&l, open, Label::Other) * 20 <= n, "pond called dry");
        // Water mirroring a bank as warm as itself shows no reflection: Unknown.
        let banked = (0..W * H)
            .filter(|&i| pond(&g, i) && mirrors_bank(i))
            .count();
        assert!(banked > 20, "{banked}");
        assert_eq!(
            count(&l, |i| pond(&g, i) && mirrors_bank(i), Label::Water),
            0
        );
        // The rock, as warm as the water, reads one temperature at every incidence.
        assert_eq!(count(&l, rock, Label::Water), 0);
        assert!(count(&l, rock, Label::Other) > 50);
        // The land is never water, and mostly dry.
        let land = |i: usize| g.incidence[i].is_finite() && !pond(&g, i) && !rock(i);
        assert_eq!(count(&l, land, Label::Water), 0);
        assert!(count(&l, land, Label::Other) > 500);
        // Above the horizon nothing is decided.
        assert_eq!(
            count(&l, |i| !g.incidence[i].is_finite(), Label::Unknown),
            (0..W * H).filter(|&i| !g.incidence[i].is_finite()).count()
        );
    }

    #[test]
    fn day_pond_cooler_than_the_land_is_water() {
        let g = geometry(10.0);
        let s = Scene {
            land: 300.0,
            water: 293.0,
            rock: 296.0,
            bank: None,
            noise_k: 0.05,
        };
        let t = render(&g, &s);
        let l = classify_mwir(&centikelvin(&t), &g, DAY, &MwirConfig::default()).unwrap();
        let n = (0..W * H).filter(|&i| pond(&g, i)).count();
        let water = count(&l, |i| pond(&g, i), Label::Water);
        assert!(water as f64 >= 0.7 * n as f64, "{water} of {n}");
        assert_eq!(count(&l, |i| !pond(&g, i), Label::Water), 0);
        // The same image at night: water cooler than land is not night water.
        let l = classify_mwir(&centikelvin(&t), &g, NIGHT, &MwirConfig::default()).unwrap();
        assert_eq!(count(&l, |_| true, Label::Water), 0);
        // At dusk, no decision.
        let l = classify_mwir(&centikelvin(&t), &g, 20.5, &MwirConfig::default()).unwrap();
        assert_eq!(count(&l, |_| true, Label::Unknown), W * H);
    }

    #[test]
    fn dry_night_with_warm_decoys_has_no_water() {
        // Warm rock and a warm paved strip across the view (asphalt holding the day's
        // heat), no water.
        let g = geometry(10.0);
        let s = Scene {
            water: 280.0,
            ..night()
        };
        let mut t = render(&g, &s);
        for i in 0..W * H {
            if g.incidence[i].is_finite() && (30..50).contains(&(i % W)) {
                t[i] = 283.5 + 0.05 * noise(i + 7) as f64;
            }
        }
        let l = classify_mwir(&centikelvin(&t), &g, NIGHT, &MwirConfig::default()).unwrap();
        assert_eq!(count(&l, |_| true, Label::Water), 0);
    }

    #[test]
    fn without_sky_in_view_or_geometry_nothing_is_decided() {
        // Pitched 60° down: no mirror ray stays in the image.
        let g = geometry(60.0);
        assert!(g.mirror.iter().all(|&m| m == u32::MAX));
        let img = centikelvin(&vec![281.0; W * H]);
        let l = classify_mwir(&img, &g, NIGHT, &MwirConfig::default()).unwrap();
        assert_eq!(count(&l, |_| true, Label::Unknown), W * H);
        // NaN geometry everywhere.
        let mut g = geometry(10.0);
        g.incidence.iter_mut().for_each(|v| *v = f32::NAN);
        g.lookahead.iter_mut().for_each(|v| *v = f32::NAN);
        let t = render(&geometry(10.0), &night());
        let l = classify_mwir(&centikelvin(&t), &g, NIGHT, &MwirConfig::default()).unwrap();
        assert_eq!(count(&l, |_| true, Label::Unknown), W * H);
    }

    #[test]
    fn grazing_water_emits_too_little_to_tell() {
        let mut g = geometry(10.0);
        let s = night();
        let t = render(&g, &s);
        for i in 0..W * H {
            if pond(&g, i) {
                g.incidence[i] = 89.9f32.to_radians();
            }
        }
        let l = classify_mwir(&centikelvin(&t), &g, NIGHT, &MwirConfig::default()).unwrap();
        assert_eq!(
            count(&l, |i| pond(&geometry(10.0), i), Label::Unknown),
            (0..W * H).filter(|&i| pond(&geometry(10.0), i)).count()
        );
    }

    #[test]
    fn one_value_and_absurd_values() {
        let g = geometry(10.0);
        let l = classify_mwir(
            &centikelvin(&vec![281.0; W * H]),
            &g,
            NIGHT,
            &MwirConfig::default(),
        )
        .unwrap();
        assert_eq!(count(&l, |_| true, Label::Water), 0);
        assert!(count(&l, |_| true, Label::Other) > 1000);
        // Absurd but finite values: those pixels are not trusted, the rest still decided.
        let mut t = render(&g, &night());
        for i in (0..W * H).step_by(7) {
            t[i] = if i % 2 == 0 { 1e30 } else { -1e30 };
        }
        let img = MonoImage::new(W, H, t.iter().map(|v| (v * 100.0) as f32).collect()).unwrap();
        let l = classify_mwir(&img, &g, NIGHT, &MwirConfig::default()).unwrap();
        for i in (0..W * H).step_by(7) {
            assert_eq!(l.data[i], Label::Unknown, "pixel {i}");
        }
        assert_eq!(count(&l, |i| !pond(&g, i), Label::Water), 0);
        assert!(count(&l, |i| pond(&g, i), Label::Water) > 100);
    }

    #[test]
    fn counts_linear_in_temperature_with_their_calibration() {
        let g = geometry(10.0);
        let t = render(&g, &night());
        // A camera whose counts are 20 mK each above 200 K, its calibration stated.
        let counts = MonoImage::new(
            W,
            H,
            t.iter().map(|v| ((v - 200.0) / 0.02) as f32).collect(),
        )
        .unwrap();
        let cfg = MwirConfig {
            kelvin_per_count: 0.02,
            kelvin_offset: 200.0,
            ..Default::default()
        };
        let raw = classify_mwir(&counts, &g, NIGHT, &cfg).unwrap();
        let ck = classify_mwir(&centikelvin(&t), &g, NIGHT, &MwirConfig::default()).unwrap();
        let same = (0..W * H).filter(|&i| raw.data[i] == ck.data[i]).count();
        assert!(same as f64 > 0.99 * (W * H) as f64, "{same}");
    }

    #[test]
    fn raw_counts_linear_in_radiance_without_a_calibration() {
        let g = geometry(10.0);
        let t = render(&g, &night());
        // Counts = gain·radiance + offset (3,600–5,100 here): read as centikelvin they are
        // 36–51 K, not a scene's temperatures, so the rule mixes them as radiances.
        let counts: Vec<f32> = t
            .iter()
            .map(|&v| (1e9 * planck_rel(MWIR_UM, v) + 1000.0).round() as f32)
            .collect();
        let l = classify_mwir(
            &MonoImage::new(W, H, counts).unwrap(),
            &g,
            NIGHT,
            &MwirConfig::default(),
        )
        .unwrap();
        let n = (0..W * H).filter(|&i| pond(&g, i)).count();
        let water = count(&l, |i| pond(&g, i), Label::Water);
        assert!(water as f64 >= 0.6 * n as f64, "{water} of {n}");
        assert_eq!(count(&l, |i| !pond(&g, i), Label::Water), 0);
        assert!(count(&l, rock, Label::Other) > 50);
        // Counts beyond 16 bits are no image at all: nothing decided.
        let l = classify_mwir(
            &centikelvin(&vec![1e4; W * H]),
            &g,
            NIGHT,
            &MwirConfig::default(),
        )
        .unwrap();
        assert_eq!(count(&l, |_| true, Label::Unknown), W * H);
    }

    #[test]
    fn bad_config_and_sizes_are_errors() {
        let g = geometry(10.0);
        let img = centikelvin(&vec![281.0; W * H]);
        let bad = MwirConfig {
            kelvin_per_count: 0.0,
            ..Default::default()
        };
        assert!(classify_mwir(&img, &g, NIGHT, &bad).is_err());
        assert!(classify_mwir(&img, &g, 24.0, &MwirConfig::default()).is_err());
        let small = MonoImage::new(2, 2, vec![0.0; 4]).unwrap();
        assert!(classify_mwir(&small, &g, NIGHT, &MwirConfig::default()).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// Water 1–4 K warmer than land at night, land 260–300 K, 20–100 mK noise: the
        /// land and a rock as warm as the water are never water, and most of the pond is.
        #[test]
        fn night_water_over_a_range_of_scenes(
            land in 260.0f64..300.0,
            dw in 1.0f64..4.0,
            noise_k in 0.02f64..0.1,
        ) {
            let g = geometry(10.0);
            let s = Scene { land, water: land + dw, rock: land + dw, bank: None, noise_k };
            let l = classify_mwir(&centikelvin(&render(&g, &s)), &g, NIGHT, &MwirConfig::default())
                .unwrap();
            prop_assert_eq!(count(&l, |i| !pond(&g, i), Label::Water), 0);
            let n = (0..W * H).filter(|&i| pond(&g, i)).count();
            let water = count(&l, |i| pond(&g, i), Label::Water);
            prop_assert!(water as f64 >= 0.6 * n as f64, "{} of {}", water, n);
        }

        /// Any finite image: labels only on the ground within the lookahead, no panic.
        #[test]
        fn any_image_is_labelled_on_the_ground_only(
            vals in proptest::collection::vec(-1e6f32..1e6, W * H),
        ) {
            let g = geometry(10.0);
            let img = MonoImage::new(W, H, vals).unwrap();
            let l = classify_mwir(&img, &g, NIGHT, &MwirConfig::default()).unwrap();
            for i in 0..W * H {
                if !(g.incidence[i].is_finite() && g.lookahead[i] <= 40.0) {
                    prop_assert_eq!(l.data[i], Label::Unknown);
                }
            }
        }
    }
}
