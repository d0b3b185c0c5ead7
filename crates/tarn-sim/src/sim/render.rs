//! The sensors: a lidar (spinning or vertical scanner) with the optics of `optics` over
//! water, a stereo pair (left image + binned point cloud, mirror points on still water), and
//! SWIR and MWIR cameras. Every ray is independent; its noise is hashed from (seed, sensor,
//! frame, ray index), so results do not depend on the thread count.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::rng::{hash, normal, unit_f64};
use super::scene::{CameraSpec, IntensityKind, LidarSpec, SkyKind, StereoSpec};
use super::world::{Hit, Surface, World};
use crate::error::Result;
use crate::geom::camera::{CameraModel, Distortion};
use crate::geom::{PointCloud, Pose};
use crate::optics::{
    apparent_bottom_point, fresnel, Attenuation, LidarModelConfig, LidarWaterModel, Sensitivity,
    SolidAngleForm,
};

/// Refractive index of water used throughout the simulator.
pub const N_WATER: f64 = 1.33;
/// Nudge (m) off a surface before casting a secondary ray.
const EPS: f64 = 1e-4;

/// Pose of a sensor body in base_link from position and roll/pitch/yaw in degrees.
pub fn mount(position: [f64; 3], rpy_deg: [f64; 3]) -> Pose {
    crate::geom::pose_xyz_rpy(
        position[0],
        position[1],
        position[2],
        rpy_deg[0].to_radians(),
        rpy_deg[1].to_radians(),
        rpy_deg[2].to_radians(),
    )
}

/// Camera body (x forward, y left, z up) → optical frame (z forward, x right, y down).
pub fn body_to_optical() -> Pose {
    let m = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m)),
    )
}

/// A pinhole camera without distortion for `width` × `height` and a horizontal FOV.
pub fn pinhole(width: usize, height: usize, hfov_deg: f64, frame: &str) -> Result<CameraModel> {
    lens(width, height, hfov_deg, None, frame)
}

/// [`pinhole`] with plumb_bob lens distortion `[k1, k2, p1, p2, k3]` (none: a pinhole).
pub fn lens(
    width: usize,
    height: usize,
    hfov_deg: f64,
    distortion: Option<[f64; 5]>,
    frame: &str,
) -> Result<CameraModel> {
    let f = 0.5 * width as f64 / (0.5 * hfov_deg.to_radians()).tan();
    CameraModel::new(
        width,
        height,
        [
            f,
            f,
            0.5 * (width as f64 - 1.0),
            0.5 * (height as f64 - 1.0),
        ],
        distortion.map_or(Distortion::None, Distortion::PlumbBob),
        frame,
    )
}

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

/// Sun direction (map frame, unit, towards the sun) and its elevation (rad) at `hours`:
/// up from 6 to 18, due south (−y) at noon at 55°, rising in the east (+x).
pub fn sun(hours: f64) -> (Vector3<f64>, f64) {
    let a = (hours - 6.0) / 12.0 * std::f64::consts::PI; // 0 at dawn, π at dusk
    let el = 55f64.to_radians() * a.sin();
    // Azimuth from east (+x) through south (−y) to west (−x).
    let az = -a;
    let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
    (d, el)
}

/// Lighting of a scene at its time of day.
#[derive(Debug, Clone, Copy)]
pub struct Light {
    pub sun: Vector3<f64>,
    /// Direct irradiance scale (0 at night or overcast).
    pub direct: f64,
    /// Ambient (sky) irradiance scale.
    pub ambient: f64,
    pub kind: SkyKind,
    pub hours: f64,
}

impl Light {
    pub fn new(w: &World) -> Light {
        let s = &w.scene.sky;
        let (d, el) = sun(s.time_of_day);
        let day = (el.sin() / 55f64.to_radians().sin()).clamp(0.0, 1.0);
        let (direct, ambient) = match s.kind {
            SkyKind::Clear => (0.85 * day, 0.25 * day + 0.01),
            SkyKind::PartlyCloudy => (0.7 * day, 0.3 * day + 0.01),
            SkyKind::Overcast => (0.0, 0.55 * day + 0.01),
        };
        Light {
            sun: d,
            direct,
            ambient,
            kind: s.kind,
            hours: s.time_of_day,
        }
    }

    /// Sky radiance in a direction: visible RGB (0..1, before exposure).
    pub fn sky_rgb(&self, seed: u64, d: &Vector3<f64>) -> [f64; 3] {
        let up = d.z.clamp(0.0, 1.0);
        let b = self.ambient / 0.26;
        let clear = [0.75 - 0.45 * up, 0.82 - 0.35 * up, 0.92 - 0.1 * up].map(|c| c * b);
        match self.kind {
            SkyKind::Clear => clear,
            SkyKind::Overcast => [0.8 * b, 0.8 * b, 0.82 * b],
            SkyKind::PartlyCloudy => {
                // Clouds: thresholded noise on the sky dome.
                let (u, v) = (d.x / (d.z + 0.15), d.y / (d.z + 0.15));
                let c = cloud_noise(seed, 2.0 * u, 2.0 * v);
                let m = ((c - 0.1) / 0.3).clamp(0.0, 1.0);
                [0, 1, 2].map(|i| clear[i] * (1.0 - m) + 0.95 * b * m)
            }
        }
    }

    /// Sky radiance at 1.5 µm (0..1).
    pub fn sky_swir(&self, d: &Vector3<f64>) -> f64 {
        let b = self.ambient / 0.26;
        match self.kind {
            SkyKind::Overcast => 0.35 * b,
            _ => (0.08 + 0.25 * (1.0 - d.z.clamp(0.0, 1.0)).powi(4)) * b,
        }
    }

    /// Apparent sky temperature (K) in the mid-wave infrared.
    pub fn sky_temperature(&self, d: &Vector3<f64>) -> f64 {
        let up = d.z.clamp(0.0, 1.0);
        let horizon = 280.0;
        let zenith = match self.kind {
            SkyKind::Clear => 220.0,
            SkyKind::PartlyCloudy => 240.0,
            SkyKind::Overcast => 268.0,
        };
        horizon + (zenith - horizon) * up.sqrt()
    }

    /// Temperature (K) of a surface of mean `t`, daily half amplitude `swing`, peaking at 14 h.
    pub fn surface_temperature(&self, t: f64, swing: f64) -> f64 {
        t + swing * ((self.hours - 14.0) / 24.0 * std::f64::consts::TAU).cos()
    }
}

fn cloud_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (xi, yi) = (x.floor(), y.floor());
    let (fx, fy) = (x - xi, y - yi);
    let h = |a: f64, b: f64| unit_f64(hash(seed, &[31, a as i64 as u64, b as i64 as u64]));
    let (a, b, c, d) = (
        h(xi, yi),
        h(xi + 1.0, yi),
        h(xi, yi + 1.0),
        h(xi + 1.0, yi + 1.0),
    );
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (u, v) = (s(fx), s(fy));
    a + (b - a) * u + (c - a) * v + (a - b - c + d) * u * v
}

/// What a camera pixel sees, in all three bands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Radiance {
    pub rgb: [f64; 3],
    pub swir: f64,
    /// Apparent temperature (K).
    pub mwir: f64,
}

fn shade_solid(w: &World, light: &Light, hit: &Hit) -> Radiance {
    let m = &w.materials[hit.material].spec;
    let mut direct = 0.0;
    if light.direct > 0.0 {
        let c = hit.normal.dot(&light.sun);
        if c > 0.0
            && w.cast_solid(&(hit.point + hit.normal * 1e-3), &light.sun, 200.0)
                .is_none()
        {
            direct = light.direct * c;
        }
    }
    let e = direct + light.ambient;
    Radiance {
        rgb: m.rgb.map(|a| a * e),
        swir: m.swir * e,
        mwir: light.surface_temperature(m.temperature, m.temperature_swing),
    }
}

fn sky_radiance(w: &World, light: &Light, d: &Vector3<f64>) -> Radiance {
    Radiance {
        rgb: light.sky_rgb(w.scene.seed, d),
        swir: light.sky_swir(d),
        mwir: light.sky_temperature(d),
    }
}

/// The one bounce off water at `p` (unit normal `n`) of a ray along `d`: the cosine of
/// incidence, the reflected direction, and the solid the reflection meets within `max`
/// (`None`: the sky, or the water itself where a ripple tilts the reflection down).
fn reflect_off_water(
    w: &World,
    p: &Point3<f64>,
    d: &Vector3<f64>,
    n: &Vector3<f64>,
    max: f64,
) -> (f64, Vector3<f64>, Option<Hit>) {
    let cos_i = (-d.dot(n)).clamp(1e-6, 1.0);
    let r = d + n * (2.0 * cos_i);
    let solid = if r.z <= 0.0 {
        None
    } else {
        w.cast_solid(&(p + r * EPS), &r, max)
    };
    (cos_i, r, solid)
}

/// Radiance along a camera ray: solids shaded with sun and sky; water as a Fresnel mix of
/// the reflection (one bounce: sky or solid) and the water's body colour; ripples perturb
/// the normal.
pub fn radiance(w: &World, light: &Light, o: &Point3<f64>, d: &Vector3<f64>, max: f64) -> Radiance {
    let Some(hit) = w.cast(o, d, max) else {
        return sky_radiance(w, light, d);
    };
    match hit.surface {
        Surface::Solid { .. } => shade_solid(w, light, &hit),
        Surface::Water { body } => {
            let n = w.water_normal(body, &hit.point);
            let (cos_i, r, solid) = reflect_off_water(w, &hit.point, d, &n, max);
            let refl = match solid {
                Some(s) => shade_solid(w, light, &s),
                // A ripple may tilt the reflection into the water: it sees the water itself,
                // lit like the sky at the horizon.
                None => sky_radiance(w, light, &Vector3::new(r.x, r.y, r.z.max(0.0))),
            };
            let fr = fresnel(cos_i.acos(), N_WATER)
                .map(|f| 0.5 * (f.r_s + f.r_p))
                .unwrap_or(1.0);
            let b = &w.water[body].spec;
            let body_rgb = b
                .colour
                .map(|c| c * (light.direct * light.sun.z.max(0.0) + light.ambient));
            let t_water = light.surface_temperature(b.temperature, b.temperature_swing);
            Radiance {
                rgb: [0, 1, 2].map(|i| fr * refl.rgb[i] + (1.0 - fr) * body_rgb[i]),
                // Water absorbs 1.5 µm within millimetres: only the surface reflection.
                swir: fr * refl.swir,
                // Emission and reflection add as radiances, at the index of 3–5 µm.
                mwir: crate::optics::thermal::apparent_temperature(
                    crate::optics::thermal::water_reflectance_mwir(cos_i.acos()),
                    t_water,
                    refl.mwir,
                ),
            }
        }
    }
}

/// What a camera shows of the water: for every pixel whose ray meets water first, the
/// hit's map (x, y) and whether the water there reflects the sky (`true`) or terrain and
/// objects (`false`), by the same one-bounce reflection [`radiance`] renders. Truth for the
/// colour cue, which can see sky reflections only (paper §2.1, §2.3).
pub fn water_views(
    w: &World,
    camera: &CameraModel,
    optical_to_map: &Pose,
    max: f64,
) -> Vec<(f64, f64, bool)> {
    let o: Point3<f64> = optical_to_map.translation.vector.into();
    (0..camera.width * camera.height)
        .into_par_iter()
        .filter_map(|i| {
            let ray = camera.pixel_ray((i % camera.width) as f64, (i / camera.width) as f64)?;
            let d = optical_to_map.rotation * ray.normalize();
            let hit = w.cast(&o, &d, max)?;
            let Surface::Water { body } = hit.surface else {
                return None;
            };
            let n = w.water_normal(body, &hit.point);
            let (_, _, solid) = reflect_off_water(w, &hit.point, &d, &n, max);
            Some((hit.point.x, hit.point.y, solid.is_none()))
        })
        .collect()
}

/// The stereo pair: its left camera and where it sits.
#[derive(Debug, Clone)]
pub struct Stereo {
    pub spec: StereoSpec,
    /// The left camera as its raw image and CameraInfo show it (with the lens distortion).
    pub camera: CameraModel,
    /// The rectified left camera (the same K, no distortion): the cloud's grid.
    pub rectified: CameraModel,
    /// base_link → left optical frame.
    pub optical_mount: Pose,
}

/// Frame of the right camera of the stereo pair (its CameraInfo's header).
pub const RIGHT_CAMERA_FRAME: &str = "camera_right_optical";

impl Stereo {
    pub fn new(spec: &StereoSpec) -> Result<Stereo> {
        let frame = "camera_left_optical";
        Ok(Stereo {
            camera: lens(
                spec.width,
                spec.height,
                spec.hfov_deg,
                spec.distortion,
                frame,
            )?,
            rectified: pinhole(spec.width, spec.height, spec.hfov_deg, frame)?,
            optical_mount: mount(spec.position, spec.rpy_deg) * body_to_optical(),
            spec: spec.clone(),
        })
    }

    /// The right camera's CameraInfo as ROS stereo drivers publish it: the rectified
    /// projection `P = [f 0 cx −f·B; 0 f cy 0; 0 0 1 0]`, so that `B = −P[0][3] / P[0][0]`.
    pub fn right_info(&self, header: tarn_log::ros::Header) -> tarn_log::ros::CameraInfoMsg {
        let mut m = tarn_log::ros::camera_to_info(&self.camera, header);
        m.p[3] = -self.camera.fx * self.spec.baseline_m;
        m
    }

    /// Focal length of the disparity image (px): the camera's over the binning.
    pub fn disparity_focal_px(&self) -> f64 {
        self.rectified.fx / self.spec.bin as f64
    }

    /// Depth (along the optical axis) that stereo reports for a true depth `z` when the
    /// disparity `d = f_b·B/z` (f_b the binned focal length) is off by `e` pixels:
    /// `f_b·B/(d + e)`; `None` where the matched disparity falls below the minimum (far
    /// ground, or noise taking it there): no match.
    pub fn measured_depth(&self, z: f64, e: f64) -> Option<f64> {
        let fb = self.disparity_focal_px() * self.spec.baseline_m;
        let d = fb / z + e;
        (d >= self.spec.min_disparity_px).then(|| fb / d)
    }

    /// The point stereo reports along unit ray `d` (map frame) from `o`, before noise:
    /// the surface on solids; on still water the mirror image of what the reflected ray
    /// meets (a point on the original ray at the total path length); `None` for the sky,
    /// for a reflected sky, and on rippled water that breaks up the reflection.
    pub fn trace(&self, w: &World, o: &Point3<f64>, d: &Vector3<f64>) -> Option<(f64, usize)> {
        let max = self.spec.max_range_m;
        let hit = w.cast(o, d, max)?;
        match hit.surface {
            Surface::Solid { .. } => Some((hit.t, hit.material)),
            Surface::Water { body } => {
                if w.water[body].spec.ripple > 0.02 {
                    return None;
                }
                let n = w.water_normal(body, &hit.point);
                let r = d + n * (2.0 * -d.dot(&n));
                let s = w.cast_solid(&(hit.point + r * EPS), &r, max - hit.t)?;
                Some((hit.t + EPS + s.t, s.material))
            }
        }
    }

    /// The binned organized cloud in the left optical frame (NaN: no match), on the
    /// rectified grid. Noise is in disparity ([`Stereo::measured_depth`]): Gaussian with
    /// σ = `disparity_noise_px`, so the range error grows as z² and is skewed far; a
    /// pixel of a material without texture finds no match with probability 1 − texture.
    pub fn cloud(
        &self,
        w: &World,
        optical_to_map: &Pose,
        frame: u64,
        noise: bool,
    ) -> Result<PointCloud> {
        let k = self.spec.bin;
        let (rows, cols) = (self.spec.height / k, self.spec.width / k);
        let o: Point3<f64> = optical_to_map.translation.vector.into();
        let seed = w.scene.seed;
        let half = 0.5 * (k as f64 - 1.0);
        let xyz = (0..rows * cols)
            .into_par_iter()
            .map(|i| {
                let (r, c) = (i / cols, i % cols);
                let (u, v) = ((k * c) as f64 + half, (k * r) as f64 + half);
                let Some(ray) = self.rectified.pixel_ray(u, v) else {
                    return [f32::NAN; 3];
                };
                let ray = ray.normalize();
                let d = optical_to_map.rotation * ray;
                let Some((t, mat)) = self.trace(w, &o, &d) else {
                    return [f32::NAN; 3];
                };
                let mut e = 0.0;
                if noise {
                    let tex = w.materials[mat].spec.texture;
                    if unit_f64(hash(seed, &[41, frame, i as u64])) >= tex {
                        return [f32::NAN; 3];
                    }
                    e = self.spec.disparity_noise_px * normal(hash(seed, &[42, frame, i as u64]));
                }
                let Some(z) = self.measured_depth(t * ray.z, e) else {
                    return [f32::NAN; 3];
                };
                let p = ray * (z / ray.z);
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect();
        PointCloud::organized(rows, cols, xyz)
    }
}

/// An 8-bit value of linear radiance `v` (0..1) in `encoding`.
fn encode(v: f64, encoding: crate::project::Encoding) -> u8 {
    let e = match encoding {
        crate::project::Encoding::Linear => v,
        crate::project::Encoding::Srgb if v <= 0.003_130_8 => 12.92 * v,
        crate::project::Encoding::Srgb => 1.055 * v.powf(1.0 / 2.4) - 0.055,
    };
    (e * 255.0).round().clamp(0.0, 255.0) as u8
}

/// A rendered camera image in one band (colour in its encoding).
pub enum Band {
    Rgb(crate::project::Encoding),
    Swir,
    Mwir,
}

/// Renders `camera` at `optical_to_map`: RGB as rgb8, SWIR as mono8 (reflectance × 255
/// under full sun), MWIR as mono16 in centikelvin.
#[allow(clippy::too_many_arguments)]
pub fn render_image(
    w: &World,
    light: &Light,
    camera: &CameraModel,
    optical_to_map: &Pose,
    band: Band,
    noise_sd: f64,
    frame: u64,
    noise: bool,
) -> crate::sensor::Pixels {
    use crate::sensor::Pixels;
    let o: Point3<f64> = optical_to_map.translation.vector.into();
    let n = camera.width * camera.height;
    let seed = w.scene.seed;
    let rad: Vec<Radiance> = (0..n)
        .into_par_iter()
        .map(|i| {
            let (u, v) = ((i % camera.width) as f64, (i / camera.width) as f64);
            match camera.pixel_ray(u, v) {
                Some(ray) => radiance(
                    w,
                    light,
                    &o,
                    &(optical_to_map.rotation * ray.normalize()),
                    300.0,
                ),
                None => Radiance {
                    rgb: [0.0; 3],
                    swir: 0.0,
                    mwir: 0.0,
                },
            }
        })
        .collect();
    let jitter = |i: usize, ch: u64| {
        if noise && noise_sd > 0.0 {
            noise_sd * normal(hash(seed, &[51, ch, frame, i as u64]))
        } else {
            0.0
        }
    };
    let exposure = 255.0 / 0.75;
    match band {
        Band::Rgb(encoding) => Pixels::Rgb8(
            rad.iter()
                .enumerate()
                .map(|(i, r)| {
                    [0, 1, 2].map(|c| {
                        let v = (r.rgb[c] * exposure + jitter(i, c as u64)).clamp(0.0, 255.0);
                        encode(v / 255.0, encoding)
                    })
                })
                .collect(),
        ),
        Band::Swir => Pixels::Mono8(
            rad.iter()
                .enumerate()
                .map(|(i, r)| (r.swir * exposure + jitter(i, 3)).round().clamp(0.0, 255.0) as u8)
                .collect(),
        ),
        Band::Mwir => Pixels::Mono16(
            rad.iter()
                .enumerate()
                .map(|(i, r)| (r.mwir * 100.0 + jitter(i, 4)).round().clamp(0.0, 65535.0) as u16)
                .collect(),
        ),
    }
}

/// A single camera of the rig (SWIR or MWIR).
pub fn camera_of(spec: &CameraSpec, frame: &str) -> Result<(CameraModel, Pose)> {
    Ok((
        pinhole(spec.width, spec.height, spec.hfov_deg, frame)?,
        mount(spec.position, spec.rpy_deg) * body_to_optical(),
    ))
}
