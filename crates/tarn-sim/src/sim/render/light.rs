//! Light and shading: the sun and sky of a time of day, and the radiance a camera ray
//! carries in every band, water reflecting one bounce of sky or solid.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::super::rng::{hash, unit_f64};
use super::super::scene::SkyKind;
use super::super::world::{Hit, Surface, World};
use super::{EPS, N_WATER};
use crate::geom::{CameraModel, Pose};
use crate::optics::fresnel;

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
                mwir: crate::optics::apparent_temperature(
                    crate::optics::water_reflectance_mwir(cos_i.acos()),
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
