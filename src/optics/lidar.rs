//! Lidar return power over water and dry ground (paper section 3, corrected).
//!
//! A sensor at height `H` above a flat water surface sends a beam that meets the water at
//! horizontal distance `d` (the *lookahead*), with incidence `θᵢ = atan(d/H)` and air path
//! `L_a = √(H² + d²)`. Refracted at `θₜ` (`sin θᵢ = n sin θₜ`), it crosses water of depth `D`
//! over `L_w = D / cos θₜ`, is reflected by a Lambertian bottom of albedo `ρ`, and comes back.
//! The fraction of the emitted power that reaches a receiver aperture of area `A_r` is
//!
//! ```text
//! P_r/P_0 = T(θᵢ)² · e^{−2 c L_w} · (ρ/π) cos θₜ · ΔΩ_w
//! ΔΩ_w    = A_r cos θᵢ / (n² cos θₜ · R_s · R_t)                       (exact, small aperture)
//! R_s     = L_a + L_w / n                     R_t = L_a + L_w cos²θᵢ / (n cos²θₜ)
//! ```
//!
//! `R_s`, `R_t` are the sagittal and tangential distances from the receiver to the two virtual
//! images of the bottom point seen through the flat surface (a pencil refracted at a plane is
//! astigmatic); `ΔΩ_a = A_r/(R_s R_t)` is the aperture's solid angle from those images in air
//! and Straubel's invariant (`n² cos θ dΩ dA` conserved) turns it into `ΔΩ_w`. The paper's
//! simplified single-distance form replaces `n² R_s R_t` by `(n L_a + L_w cos θᵢ/cos θₜ)²`
//! (available as [`SolidAngleForm::Paper`]); by the AM–GM inequality it is never smaller than
//! the exact one, so it never predicts less power. Dry ground at the water level returns
//! `(ρ/π) cos θᵢ A_r / L_a²`. See `docs/optics.md` for the derivation.

use nalgebra::Point3;
use serde::Serialize;

use super::absorption::absorption_per_m;
use super::fresnel::{fresnel_unchecked, snell_unchecked};
use crate::error::{Error, Result};

/// How the water column attenuates the beam.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Attenuation {
    /// Pure-water absorption at this wavelength (nm), from the embedded Segelstein table.
    PureWater {
        /// Wavelength of the beam, nanometres.
        wavelength_nm: f64,
    },
    /// A total attenuation coefficient `c = a + b` (1/m) given directly (turbid water).
    PerMetre(f64),
}

/// How the receiver's sensitivity is given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sensitivity {
    /// The smallest detectable ratio of received to emitted power.
    MinPowerRatio(f64),
    /// The lookahead (m) at which dry level ground (at the water level, same albedo) stops
    /// returning; the minimum ratio is the dry-ground ratio there.
    DryLimit(f64),
}

/// Which solid-angle expression to use for the receiver seen from the water bottom.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SolidAngleForm {
    /// Exact for a small aperture: sagittal and tangential virtual distances.
    #[default]
    Exact,
    /// The paper's single-distance form `(n L_a + L_w cos θᵢ/cos θₜ)²`.
    Paper,
}

/// Everything the model needs. [`LidarModelConfig::paper`] gives the paper's sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LidarModelConfig {
    /// Height of the sensor above the water surface (m).
    pub height_m: f64,
    /// How the water column attenuates the beam.
    pub attenuation: Attenuation,
    /// Lambertian albedo of the bottom (and of dry ground), 0..1.
    pub albedo: f64,
    /// Diameter of the receiver aperture (m), facing the return.
    pub aperture_diameter_m: f64,
    /// Refractive index of the water relative to air.
    pub n_water: f64,
    /// The receiver's sensitivity.
    pub sensitivity: Sensitivity,
    /// Solid-angle expression for the bottom return.
    pub solid_angle: SolidAngleForm,
}

impl LidarModelConfig {
    /// The paper's example: 1 m high, albedo 0.3, 1-inch aperture, n = 1.33, dry ground lost
    /// at 11 m, exact solid angle.
    pub fn paper(attenuation: Attenuation) -> Self {
        LidarModelConfig {
            height_m: 1.0,
            attenuation,
            albedo: 0.3,
            aperture_diameter_m: 0.0254,
            n_water: 1.33,
            sensitivity: Sensitivity::DryLimit(11.0),
            solid_angle: SolidAngleForm::Exact,
        }
    }
}

/// The geometry of one beam through air and water.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PathGeometry {
    /// Incidence angle on the water surface (rad).
    pub theta_i: f64,
    /// Refraction angle in the water (rad).
    pub theta_t: f64,
    /// One-way path in air (m).
    pub l_air: f64,
    /// One-way path in water (m).
    pub l_water: f64,
    /// Distance from the receiver to the sagittal virtual image of the bottom point (m).
    pub r_sagittal: f64,
    /// Distance from the receiver to the tangential virtual image of the bottom point (m).
    pub r_tangential: f64,
    /// Horizontal distance from the sensor to the bottom point (m).
    pub bottom_distance: f64,
}

/// A validated lidar-over-water propagation model.
#[derive(Debug, Clone, PartialEq)]
pub struct LidarWaterModel {
    cfg: LidarModelConfig,
    attenuation_per_m: f64,
    min_power_ratio: f64,
    /// (ρ/π)·A_r
    k_lambert: f64,
}

fn finite_positive(what: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            what,
            format!("{v} is not a finite positive number"),
        ))
    }
}

fn finite_non_negative(what: &str, v: f64) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            what,
            format!("{v} is not a finite number ≥ 0"),
        ))
    }
}

/// Bisection for the boundary of a predicate that holds on [0, x*] and fails beyond:
/// `ok(lo)` is true, `ok(hi)` false. A fixed number of halvings, so the answer does not
/// depend on anything but the inputs.
fn bisect(mut lo: f64, mut hi: f64, ok: impl Fn(f64) -> bool) -> f64 {
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if ok(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

impl LidarWaterModel {
    /// Validates the configuration and resolves attenuation and sensitivity.
    pub fn new(cfg: LidarModelConfig) -> Result<Self> {
        finite_positive("sensor height (m)", cfg.height_m)?;
        if !(cfg.albedo.is_finite() && cfg.albedo > 0.0 && cfg.albedo <= 1.0) {
            return Err(Error::invalid(
                "albedo",
                format!("{} is not in (0, 1]", cfg.albedo),
            ));
        }
        finite_positive("aperture diameter (m)", cfg.aperture_diameter_m)?;
        if !(cfg.n_water.is_finite() && cfg.n_water >= 1.0) {
            return Err(Error::invalid(
                "refractive index of water",
                format!("{} is not a finite number ≥ 1", cfg.n_water),
            ));
        }
        let attenuation_per_m = match cfg.attenuation {
            Attenuation::PureWater { wavelength_nm } => absorption_per_m(wavelength_nm)?,
            Attenuation::PerMetre(c) => {
                finite_non_negative("attenuation coefficient (1/m)", c)?;
                c
            }
        };
        let area = std::f64::consts::PI * 0.25 * cfg.aperture_diameter_m.powi(2);
        let k_lambert = cfg.albedo / std::f64::consts::PI * area;
        let mut m = LidarWaterModel {
            cfg,
            attenuation_per_m,
            min_power_ratio: f64::NAN,
            k_lambert,
        };
        m.min_power_ratio = match cfg.sensitivity {
            Sensitivity::MinPowerRatio(p) => {
                finite_positive("minimum power ratio", p)?;
                p
            }
            Sensitivity::DryLimit(l) => {
                finite_non_negative("dry-ground limit (m)", l)?;
                m.dry_ratio_unchecked(l)
            }
        };
        if !(m.min_power_ratio.is_finite() && m.min_power_ratio > 0.0) {
            return Err(Error::invalid(
                "sensitivity",
                format!(
                    "the calibrated minimum power ratio {} is not finite and positive",
                    m.min_power_ratio
                ),
            ));
        }
        Ok(m)
    }

    /// The configuration the model was built from.
    pub fn config(&self) -> &LidarModelConfig {
        &self.cfg
    }

    /// Total attenuation coefficient of the water column (1/m).
    pub fn attenuation_per_m(&self) -> f64 {
        self.attenuation_per_m
    }

    /// Smallest detectable ratio of received to emitted power.
    pub fn min_power_ratio(&self) -> f64 {
        self.min_power_ratio
    }

    /// Incidence angle (rad) of a beam meeting the water at `lookahead_m`.
    pub fn incidence(&self, lookahead_m: f64) -> Result<f64> {
        finite_non_negative("lookahead (m)", lookahead_m)?;
        Ok(lookahead_m.atan2(self.cfg.height_m))
    }

    fn check(lookahead_m: f64, depth_m: f64) -> Result<()> {
        finite_non_negative("lookahead (m)", lookahead_m)?;
        finite_non_negative("water depth (m)", depth_m)
    }

    /// The beam's path for lookahead `lookahead_m` and water depth `depth_m`.
    pub fn geometry(&self, lookahead_m: f64, depth_m: f64) -> Result<PathGeometry> {
        Self::check(lookahead_m, depth_m)?;
        Ok(self.geometry_unchecked(lookahead_m, depth_m).0)
    }

    /// Geometry plus (sin θᵢ, cos θᵢ, sin θₜ, cos θₜ).
    fn geometry_unchecked(&self, d: f64, depth: f64) -> (PathGeometry, [f64; 4]) {
        let h = self.cfg.height_m;
        let n = self.cfg.n_water;
        let l_air = h.hypot(d);
        let (sin_i, cos_i) = (d / l_air, h / l_air);
        // n ≥ 1: no total internal reflection going in.
        let (sin_t, cos_t) = snell_unchecked(sin_i, n).unwrap_or((1.0 / n, 0.0));
        let l_water = depth / cos_t;
        let r_sagittal = l_air + l_water / n;
        let r_tangential = l_air + l_water * (cos_i / cos_t).powi(2) / n;
        (
            PathGeometry {
                theta_i: sin_i.atan2(cos_i),
                theta_t: sin_t.atan2(cos_t),
                l_air,
                l_water,
                r_sagittal,
                r_tangential,
                bottom_distance: d + depth * sin_t / cos_t,
            },
            [sin_i, cos_i, sin_t, cos_t],
        )
    }

    /// Solid angle (sr), in the water, of the receiver aperture seen from the bottom point.
    pub fn solid_angle_in_water(&self, lookahead_m: f64, depth_m: f64) -> Result<f64> {
        Self::check(lookahead_m, depth_m)?;
        let (g, [_, cos_i, _, cos_t]) = self.geometry_unchecked(lookahead_m, depth_m);
        Ok(self.solid_angle_unchecked(&g, cos_i, cos_t))
    }

    fn solid_angle_unchecked(&self, g: &PathGeometry, cos_i: f64, cos_t: f64) -> f64 {
        let n = self.cfg.n_water;
        let area = std::f64::consts::PI * 0.25 * self.cfg.aperture_diameter_m.powi(2);
        match self.cfg.solid_angle {
            SolidAngleForm::Exact => area * cos_i / (n * n * cos_t * g.r_sagittal * g.r_tangential),
            SolidAngleForm::Paper => {
                let r = n * g.l_air + g.l_water * cos_i / cos_t;
                area * cos_i / (cos_t * r * r)
            }
        }
    }

    /// Ratio of power received from the bottom to power emitted, for a beam meeting water of
    /// depth `depth_m` at lookahead `lookahead_m`. Unpolarized beam.
    pub fn return_ratio(&self, lookahead_m: f64, depth_m: f64) -> Result<f64> {
        Self::check(lookahead_m, depth_m)?;
        Ok(self.return_ratio_unchecked(lookahead_m, depth_m))
    }

    fn return_ratio_unchecked(&self, d: f64, depth: f64) -> f64 {
        let (g, [sin_i, cos_i, _, cos_t]) = self.geometry_unchecked(d, depth);
        // Water→air at θₜ transmits the same fraction as air→water at θᵢ (reciprocity).
        let t = fresnel_unchecked(sin_i, cos_i, self.cfg.n_water).t_unpolarized();
        let omega_w = self.solid_angle_unchecked(&g, cos_i, cos_t);
        let lambert = self.cfg.albedo / std::f64::consts::PI * cos_t;
        let ratio = t * t * (-2.0 * self.attenuation_per_m * g.l_water).exp() * lambert * omega_w;
        if ratio.is_finite() {
            ratio.max(0.0)
        } else {
            0.0
        }
    }

    /// Fresnel transmittances (s, p) into the water at lookahead `lookahead_m`.
    pub fn transmittance(&self, lookahead_m: f64) -> Result<(f64, f64)> {
        let th = self.incidence(lookahead_m)?;
        let f = fresnel_unchecked(th.sin(), th.cos(), self.cfg.n_water);
        Ok((f.t_s, f.t_p))
    }

    /// Ratio of received to emitted power from dry level ground (at the water level, same
    /// albedo) at lookahead `lookahead_m`: `(ρ/π) cos θᵢ A_r / L_a²`.
    pub fn dry_ratio(&self, lookahead_m: f64) -> Result<f64> {
        finite_non_negative("lookahead (m)", lookahead_m)?;
        Ok(self.dry_ratio_unchecked(lookahead_m))
    }

    fn dry_ratio_unchecked(&self, d: f64) -> f64 {
        let h = self.cfg.height_m;
        let l2 = h * h + d * d;
        self.k_lambert * h / (l2 * l2.sqrt())
    }

    /// Lookahead (m) beyond which dry level ground gives no return; `None` when it gives none
    /// even straight down.
    pub fn dry_limit(&self) -> Option<f64> {
        let h = self.cfg.height_m;
        // (ρ/π) A_r H / (H² + d²)^{3/2} = P  ⇒  H² + d² = (k H / P)^{2/3}
        let l2 = (self.k_lambert * h / self.min_power_ratio).powf(2.0 / 3.0);
        if l2 < h * h {
            return None;
        }
        let d = (l2 - h * h).sqrt();
        // Guard the closed form against rounding: the returned lookahead must return.
        let d = if self.dry_ratio_unchecked(d) >= self.min_power_ratio {
            d
        } else {
            bisect(0.0, d, |x| {
                self.dry_ratio_unchecked(x) >= self.min_power_ratio
            })
        };
        Some(d)
    }

    /// Lookahead (m) beyond which even the thinnest film of water returns nothing (the
    /// zero-depth cutoff); `None` when water returns nothing at any lookahead.
    pub fn zero_depth_cutoff(&self) -> Option<f64> {
        self.max_lookahead_unchecked(0.0)
    }

    /// Incidence angle (rad) beyond which nothing returns from water of any depth.
    pub fn incidence_cutoff(&self) -> Option<f64> {
        self.zero_depth_cutoff().map(|d| d.atan2(self.cfg.height_m))
    }

    /// Largest incidence angle (rad) at which the bottom under `depth_m` of water returns.
    pub fn max_incidence_for_depth(&self, depth_m: f64) -> Result<Option<f64>> {
        Ok(self
            .max_lookahead_for_depth(depth_m)?
            .map(|d| d.atan2(self.cfg.height_m)))
    }

    /// Largest lookahead (m) at which the bottom under `depth_m` of water still returns;
    /// `None` when it does not return at any lookahead.
    pub fn max_lookahead_for_depth(&self, depth_m: f64) -> Result<Option<f64>> {
        finite_non_negative("water depth (m)", depth_m)?;
        Ok(self.max_lookahead_unchecked(depth_m))
    }

    fn max_lookahead_unchecked(&self, depth: f64) -> Option<f64> {
        let p = self.min_power_ratio;
        let ok = |d: f64| self.return_ratio_unchecked(d, depth) >= p;
        if !ok(0.0) {
            return None;
        }
        // The water return is weaker than the dry return at every lookahead, so the dry
        // limit bounds the search; grow it if rounding ever says otherwise.
        let mut hi = self.dry_limit().unwrap_or(self.cfg.height_m).max(1e-3) * 1.01;
        let mut grow = 0;
        while ok(hi) && grow < 64 {
            hi *= 2.0;
            grow += 1;
        }
        if ok(hi) {
            return Some(hi);
        }
        Some(bisect(0.0, hi, ok))
    }

    /// Greatest water depth (m) whose bottom returns at lookahead `lookahead_m`; 0 when
    /// nothing returns there.
    pub fn max_depth(&self, lookahead_m: f64) -> Result<f64> {
        finite_non_negative("lookahead (m)", lookahead_m)?;
        let p = self.min_power_ratio;
        let ok = |z: f64| self.return_ratio_unchecked(lookahead_m, z) >= p;
        if !ok(0.0) {
            return Ok(0.0);
        }
        let mut hi = 1.0;
        let mut grow = 0;
        while ok(hi) && grow < 64 {
            hi *= 2.0;
            grow += 1;
        }
        if ok(hi) {
            return Ok(hi);
        }
        Ok(bisect(0.0, hi, ok))
    }

    /// Lookaheads (m) where water `depth_m` deep returns nothing while dry ground at the same
    /// level still returns: there, no return is diagnostic of water. `None` when empty.
    pub fn diagnostic_interval(&self, depth_m: f64) -> Result<Option<(f64, f64)>> {
        let start = self.max_lookahead_for_depth(depth_m)?.unwrap_or(0.0);
        Ok(match self.dry_limit() {
            Some(end) if end > start => Some((start, end)),
            _ => None,
        })
    }

    /// Maps a raw lidar point measured through the water surface `water_level_z` (range as if
    /// the whole path were in air) to the true bottom point; see
    /// [`super::correct_bottom_return`].
    pub fn correct_bottom_return(
        &self,
        sensor_origin: Point3<f64>,
        raw_point: Point3<f64>,
        water_level_z: f64,
    ) -> Result<Point3<f64>> {
        super::correction::correct_bottom_return(
            sensor_origin,
            raw_point,
            water_level_z,
            self.cfg.n_water,
        )
    }

    /// Lookaheads for a report when none are given: every 0.5 m from 0 to 10 % past the
    /// dry-ground limit (at most 201 rows; evenly spaced beyond that).
    pub fn default_lookaheads(&self) -> Vec<f64> {
        let end = self.dry_limit().unwrap_or(self.cfg.height_m).max(1.0) * 1.1;
        let steps = (end / 0.5).ceil() as usize;
        if steps <= 200 {
            (0..=steps).map(|i| i as f64 * 0.5).collect()
        } else {
            (0..=200).map(|i| end * i as f64 / 200.0).collect()
        }
    }

    /// The `tarn lidar-model` report for these lookaheads and one water depth.
    pub fn report(&self, lookaheads_m: &[f64], depth_m: f64) -> Result<LidarModelReport> {
        finite_non_negative("water depth (m)", depth_m)?;
        let mut rows = Vec::with_capacity(lookaheads_m.len());
        for &d in lookaheads_m {
            let th = self.incidence(d)?;
            let (t_s, t_p) = self.transmittance(d)?;
            rows.push(LidarModelRow {
                lookahead_m: d,
                incidence_deg: th.to_degrees(),
                transmittance_s: t_s,
                transmittance_p: t_p,
                return_ratio: self.return_ratio(d, depth_m)?,
                dry_ratio: self.dry_ratio(d)?,
                max_depth_m: self.max_depth(d)?,
            });
        }
        let wavelength_nm = match self.cfg.attenuation {
            Attenuation::PureWater { wavelength_nm } => Some(wavelength_nm),
            Attenuation::PerMetre(_) => None,
        };
        Ok(LidarModelReport {
            height_m: self.cfg.height_m,
            depth_m,
            wavelength_nm,
            albedo: self.cfg.albedo,
            aperture_diameter_m: self.cfg.aperture_diameter_m,
            n_water: self.cfg.n_water,
            solid_angle: self.cfg.solid_angle,
            attenuation_per_m: self.attenuation_per_m,
            min_power_ratio: self.min_power_ratio,
            dry_limit_m: self.dry_limit().unwrap_or(0.0),
            zero_depth_cutoff_m: self.zero_depth_cutoff().unwrap_or(0.0),
            incidence_cutoff_deg: self.incidence_cutoff().unwrap_or(0.0).to_degrees(),
            max_lookahead_for_depth_m: self.max_lookahead_for_depth(depth_m)?.unwrap_or(0.0),
            diagnostic_interval_m: self.diagnostic_interval(depth_m)?.map(|(a, b)| [a, b]),
            rows,
        })
    }
}

/// One lookahead of the `tarn lidar-model` report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LidarModelRow {
    /// Horizontal distance from the sensor to the beam's hit on the water surface, metres.
    pub lookahead_m: f64,
    /// Incidence angle on the water surface, degrees.
    pub incidence_deg: f64,
    /// Fresnel transmittance into the water, s polarisation.
    pub transmittance_s: f64,
    /// Fresnel transmittance into the water, p polarisation.
    pub transmittance_p: f64,
    /// Bottom return ratio for the report's depth.
    pub return_ratio: f64,
    /// Return ratio from dry level ground at the water level.
    pub dry_ratio: f64,
    /// Greatest depth whose bottom returns here; 0 where nothing returns.
    pub max_depth_m: f64,
}

/// What `tarn lidar-model --json` prints. Lookaheads that "do not exist" (no return at any
/// lookahead) are reported as 0; an empty diagnostic interval as `null`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LidarModelReport {
    /// Height of the sensor above the water surface, metres.
    pub height_m: f64,
    /// Water depth of the report, metres.
    pub depth_m: f64,
    /// Wavelength when the attenuation is pure-water absorption, else `null`.
    pub wavelength_nm: Option<f64>,
    /// Lambertian albedo of the bottom and of dry ground, 0..1.
    pub albedo: f64,
    /// Diameter of the receiver aperture, metres.
    pub aperture_diameter_m: f64,
    /// Refractive index of the water relative to air.
    pub n_water: f64,
    /// Solid-angle expression used.
    pub solid_angle: SolidAngleForm,
    /// Total attenuation coefficient of the water column, 1/m.
    pub attenuation_per_m: f64,
    /// Smallest detectable ratio of received to emitted power.
    pub min_power_ratio: f64,
    /// Lookahead beyond which dry level ground gives no return, metres (0: none even straight down).
    pub dry_limit_m: f64,
    /// Lookahead beyond which the thinnest film of water returns nothing, metres.
    pub zero_depth_cutoff_m: f64,
    /// Incidence angle beyond which nothing returns from water of any depth, degrees.
    pub incidence_cutoff_deg: f64,
    /// Largest lookahead at which the bottom under `depth_m` of water still returns, metres.
    pub max_lookahead_for_depth_m: f64,
    /// Lookaheads where no return is diagnostic of water `depth_m` deep, metres; `None` when empty.
    pub diagnostic_interval_m: Option<[f64; 2]>,
    /// One row per lookahead asked for.
    pub rows: Vec<LidarModelRow>,
}
