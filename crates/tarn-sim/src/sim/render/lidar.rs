//! The lidar: its beams, the return of each (solid, water bottom, specular off water, none)
//! by the optics of `optics`, and its scans.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::super::rng::{hash, normal};
use super::super::scene::{IntensityKind, LidarSpec};
use super::super::world::{Hit, Surface, World};
use super::{mount, EPS, N_WATER};
use crate::error::Result;
use crate::geom::{PointCloud, Pose};
use crate::optics::{
    apparent_bottom_point, fresnel, Attenuation, LidarModelConfig, LidarWaterModel, Sensitivity,
    SolidAngleForm,
};

/// How a lidar beam ended. `power` is the received/emitted power ratio of the return.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LidarReturn {
    /// Dry ground or an object.
    Solid { point: Point3<f64>, power: f64 },
    /// The bottom under water: `point` is where an uncorrected lidar reports it.
    Bottom {
        point: Point3<f64>,
        bottom: Point3<f64>,
        lookahead: f64,
        depth: f64,
        power: f64,
    },
    /// A mirror bounce off water to a solid beyond: `point` lies on the original ray at the
    /// total path length.
    Specular { point: Point3<f64>, power: f64 },
    /// Nothing detectable came back.
    None,
}

impl LidarReturn {
    /// Where the lidar reports the return and its power ratio (`None`: no return).
    pub fn reported(&self) -> Option<(Point3<f64>, f64)> {
        match *self {
            LidarReturn::Solid { point, power }
            | LidarReturn::Bottom { point, power, .. }
            | LidarReturn::Specular { point, power } => Some((point, power)),
            LidarReturn::None => None,
        }
    }
}

/// The lidar as the renderer needs it.
#[derive(Debug, Clone)]
pub struct Lidar {
    pub spec: LidarSpec,
    pub mount: Pose,
    /// Smallest detectable received/emitted power ratio.
    pub min_power_ratio: f64,
}

impl Lidar {
    pub fn new(spec: &LidarSpec) -> Result<Lidar> {
        // Sensitivity from the dry-ground limit seen from the mounting height.
        let m = LidarWaterModel::new(LidarModelConfig {
            height_m: spec.position[2],
            attenuation: Attenuation::PerMetre(0.0),
            albedo: spec.reference_albedo,
            aperture_diameter_m: spec.aperture_m,
            n_water: N_WATER,
            sensitivity: Sensitivity::DryLimit(spec.dry_limit_m),
            solid_angle: SolidAngleForm::Exact,
        })?;
        Ok(Lidar {
            spec: spec.clone(),
            mount: mount(spec.position, spec.rpy_deg),
            min_power_ratio: m.min_power_ratio(),
        })
    }

    /// Unit beam direction (lidar frame) of ring `r` (0 = lowest), column `c`.
    pub fn beam(&self, r: usize, c: usize) -> Vector3<f64> {
        let s = &self.spec;
        let el = if s.rings == 1 {
            s.elevation_deg[0]
        } else {
            s.elevation_deg[0]
                + (s.elevation_deg[1] - s.elevation_deg[0]) * r as f64 / (s.rings - 1) as f64
        }
        .to_radians();
        let span = s.azimuth_deg[1] - s.azimuth_deg[0];
        let az = if s.columns == 1 {
            0.5 * (s.azimuth_deg[0] + s.azimuth_deg[1])
        } else if span >= 360.0 {
            s.azimuth_deg[0] + span * c as f64 / s.columns as f64
        } else {
            s.azimuth_deg[0] + span * c as f64 / (s.columns - 1) as f64
        }
        .to_radians();
        Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
    }

    /// Aperture area (m²).
    fn aperture_area(&self) -> f64 {
        std::f64::consts::PI * 0.25 * self.spec.aperture_m.powi(2)
    }

    /// Received/emitted power ratio from a surface of albedo ρ whose backscatter falls as
    /// cosᵐ θ (`m` = 1: Lambertian) at incidence cosine `cos`, `range` away:
    /// (ρ/π)·cosᵐθ·A_r/r².
    pub fn backscatter(&self, albedo: f64, m: f64, cos: f64, range: f64) -> f64 {
        albedo / std::f64::consts::PI * cos.max(0.0).powf(m) * self.aperture_area()
            / (range * range)
    }

    /// The per-return channel of the rig's convention for a return of power ratio `power`
    /// at measured range `range`: raw `intensity` = 10⁴·π·P/A_r (10⁴·ρ·cosᵐθ/r² on dry
    /// ground: it falls with range² and incidence); `reflectivity` = 100·π·P·r²/A_r, capped
    /// at 255 (range-corrected, not incidence-corrected: 100·ρ·cosᵐθ). `None` without one.
    pub fn intensity_of(&self, power: f64, range: f64) -> Option<f64> {
        let k = std::f64::consts::PI * power / self.aperture_area();
        match self.spec.intensity {
            IntensityKind::None => None,
            IntensityKind::Raw => Some(1e4 * k),
            IntensityKind::Reflectivity => Some((100.0 * k * range * range).min(255.0)),
        }
    }

    /// Traces one beam from `o` along unit `d` (map frame), without noise.
    pub fn trace(&self, w: &World, o: &Point3<f64>, d: &Vector3<f64>) -> Result<LidarReturn> {
        match w.cast(o, d, self.spec.max_range_m) {
            Some(hit) => self.trace_hit(w, o, d, &hit),
            None => Ok(LidarReturn::None),
        }
    }

    /// How a beam that first meets `hit` ends.
    fn trace_hit(
        &self,
        w: &World,
        o: &Point3<f64>,
        d: &Vector3<f64>,
        hit: &Hit,
    ) -> Result<LidarReturn> {
        match hit.surface {
            Surface::Solid { .. } => {
                let m = &w.materials[hit.material].spec;
                let power =
                    self.backscatter(m.lidar, m.backscatter_exponent, hit.normal.dot(&-d), hit.t);
                Ok(if power >= self.min_power_ratio {
                    LidarReturn::Solid {
                        point: hit.point,
                        power,
                    }
                } else {
                    LidarReturn::None
                })
            }
            Surface::Water { body } => self.trace_water(w, o, d, hit, body),
        }
    }

    fn trace_water(
        &self,
        w: &World,
        o: &Point3<f64>,
        d: &Vector3<f64>,
        hit: &Hit,
        body: usize,
    ) -> Result<LidarReturn> {
        let b = &w.water[body];
        let level = hit.point.z;
        let height = o.z - level;
        let lookahead = (hit.point.x - o.x).hypot(hit.point.y - o.y);
        let n = b.normal;
        let cos_i = -d.dot(&n);
        // Refracted beam (Snell, vector form).
        let eta = 1.0 / N_WATER;
        let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
        let dt = (d * eta + n * (eta * cos_i - k.sqrt())).normalize();
        let start = hit.point + dt * EPS;
        if let Some(bot) = w.cast_solid(&start, &dt, 100.0) {
            let depth = level - bot.point.z;
            if depth > 0.0 && height > 0.0 {
                let model = LidarWaterModel::new(LidarModelConfig {
                    height_m: height,
                    attenuation: Attenuation::PerMetre(b.attenuation),
                    albedo: w.materials[bot.material].spec.lidar,
                    aperture_diameter_m: self.spec.aperture_m,
                    n_water: N_WATER,
                    sensitivity: Sensitivity::MinPowerRatio(self.min_power_ratio),
                    solid_angle: SolidAngleForm::Exact,
                })?;
                let power = model.return_ratio(lookahead, depth)?;
                if power >= self.min_power_ratio {
                    let point = apparent_bottom_point(*o, bot.point, level, N_WATER)?;
                    return Ok(LidarReturn::Bottom {
                        point,
                        bottom: bot.point,
                        lookahead,
                        depth,
                        power,
                    });
                }
            }
        }
        // Specular bounce off the (mean) surface to a solid beyond.
        let r = d + n * (2.0 * cos_i);
        if let Some(s) = w.cast_solid(&(hit.point + r * EPS), &r, self.spec.max_range_m - hit.t) {
            let fr = fresnel(cos_i.clamp(0.0, 1.0).acos(), N_WATER)?;
            let refl = 0.5 * (fr.r_s + fr.r_p);
            let total = hit.t + EPS + s.t;
            let m = &w.materials[s.material].spec;
            let power =
                refl * self.backscatter(m.lidar, m.backscatter_exponent, s.normal.dot(&-r), total);
            if power >= self.min_power_ratio {
                return Ok(LidarReturn::Specular {
                    point: o + d * total,
                    power,
                });
            }
        }
        Ok(LidarReturn::None)
    }

    /// One organized scan (rings × columns, ring 0 lowest on row 0) in the lidar frame,
    /// with the rig's `intensity` or `reflectivity` channel (NaN for no return; 5 %
    /// multiplicative noise when `noise`).
    pub fn scan(
        &self,
        w: &World,
        lidar_to_map: &Pose,
        frame: u64,
        noise: bool,
    ) -> Result<PointCloud> {
        Ok(self.scan_with_water(w, lidar_to_map, frame, noise)?.0)
    }

    /// [`Lidar::scan`], and the map (x, y) of every beam that met water first.
    pub fn scan_with_water(
        &self,
        w: &World,
        lidar_to_map: &Pose,
        frame: u64,
        noise: bool,
    ) -> Result<(PointCloud, Vec<[f64; 2]>)> {
        let (rows, cols) = (self.spec.rings, self.spec.columns);
        let o = lidar_to_map.translation.vector.into();
        let map_to_lidar = lidar_to_map.inverse();
        let seed = w.scene.seed;
        let nan = ([f32::NAN; 3], f32::NAN);
        let pts = (0..rows * cols)
            .into_par_iter()
            .map(|i| -> Result<(Return, Option<[f64; 2]>)> {
                let (r, c) = (i / cols, i % cols);
                let d = lidar_to_map.rotation * self.beam(r, c);
                let Some(hit) = w.cast(&o, &d, self.spec.max_range_m) else {
                    return Ok((nan, None));
                };
                let water = matches!(hit.surface, Surface::Water { .. })
                    .then(|| [hit.point.x, hit.point.y]);
                let Some((p, power)) = self.trace_hit(w, &o, &d, &hit)?.reported() else {
                    return Ok((nan, water));
                };
                let mut q = map_to_lidar * p;
                let mut range = q.coords.norm();
                if noise && self.spec.range_noise_m > 0.0 {
                    let e = self.spec.range_noise_m * normal(hash(seed, &[21, frame, i as u64]));
                    let noisy = (range + e).max(0.0);
                    q = Point3::from(q.coords * (noisy / range));
                    range = noisy;
                }
                let mut v = self.intensity_of(power, range).unwrap_or(f64::NAN);
                if noise {
                    v *= (1.0 + 0.05 * normal(hash(seed, &[22, frame, i as u64]))).max(0.0);
                }
                if self.spec.intensity == IntensityKind::Reflectivity {
                    v = v.round().clamp(0.0, 255.0);
                }
                Ok((([q.x as f32, q.y as f32, q.z as f32], v as f32), water))
            })
            .collect::<Result<Vec<_>>>()?;
        let mut water = Vec::new();
        let mut xyz = Vec::with_capacity(pts.len());
        let mut channel = Vec::with_capacity(pts.len());
        for ((p, v), wat) in pts {
            xyz.push(p);
            channel.push(v);
            water.extend(wat);
        }
        let mut cloud = PointCloud::organized(rows, cols, xyz)?;
        match self.spec.intensity {
            IntensityKind::None => {}
            IntensityKind::Raw => cloud.intensity = Some(channel),
            IntensityKind::Reflectivity => cloud.reflectivity = Some(channel),
        }
        Ok((cloud, water))
    }
}

/// A reported point (lidar frame) and its intensity channel's value.
type Return = ([f32; 3], f32);
