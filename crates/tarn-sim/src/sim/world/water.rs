//! The water bodies: each one's surface plane over its region, its water column's
//! attenuation, and the ripples of its surface.

use nalgebra::{Point3, Vector3};

use super::super::rng::{hash, unit_f64};
use super::super::scene::*;
use super::World;
use crate::error::{Error, Result};

/// A water body's surface plane over a region.
#[derive(Debug, Clone, PartialEq)]
pub struct WaterBody {
    pub spec: WaterSpec,
    /// A point of the surface plane and its upward unit normal.
    pub point: Point3<f64>,
    pub normal: Vector3<f64>,
    /// Attenuation of the water column (1/m).
    pub attenuation: f64,
}

impl WaterBody {
    /// Surface elevation of the plane at (x, y).
    pub fn surface_z(&self, x: f64, y: f64) -> f64 {
        let n = &self.normal;
        self.point.z - (n.x * (x - self.point.x) + n.y * (y - self.point.y)) / n.z
    }

    /// True when (x, y) lies in the body's region (before comparing with the terrain).
    pub fn in_region(&self, x: f64, y: f64) -> bool {
        let s = &self.spec;
        match s.kind {
            WaterKind::Level => {
                let c = s.centre.unwrap_or_default();
                (x - c[0]).hypot(y - c[1]) <= s.radius.unwrap_or(0.0)
            }
            WaterKind::Stream => {
                let (a, b) = (s.from.unwrap_or_default(), s.to.unwrap_or_default());
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let len = dx.hypot(dy);
                let (ux, uy) = (dx / len, dy / len);
                let (px, py) = (x - a[0], y - a[1]);
                let along = px * ux + py * uy;
                let across = (-px * uy + py * ux).abs();
                (0.0..=len).contains(&along) && across <= 0.5 * s.width.unwrap_or(0.0)
            }
        }
    }
}

/// The water bodies of `scene`: level planes and sloping stream planes, each with its
/// attenuation (pure water's at the lidar's wavelength unless the scene makes it murkier).
pub(super) fn water_bodies(scene: &Scene) -> Result<Vec<WaterBody>> {
    scene
        .water
        .iter()
        .enumerate()
        .map(|(i, w)| {
            let (point, normal) = match w.kind {
                WaterKind::Level => {
                    let c = w.centre.unwrap_or_default();
                    (
                        Point3::new(c[0], c[1], w.level.unwrap_or(0.0)),
                        Vector3::z(),
                    )
                }
                WaterKind::Stream => {
                    let (a, b) = (w.from.unwrap_or_default(), w.to.unwrap_or_default());
                    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                    let len = dx.hypot(dy);
                    let g = (b[2] - a[2]) / len;
                    let n = Vector3::new(-g * dx / len, -g * dy / len, 1.0).normalize();
                    (Point3::new(a[0], a[1], a[2]), n)
                }
            };
            // Pure water at the lidar's wavelength is the clearest water there is: a
            // scene may make its water murkier, never clearer.
            let nm = scene
                .rig
                .lidar
                .as_ref()
                .map(|l| l.wavelength_nm)
                .unwrap_or(905.0);
            let pure = crate::optics::absorption_per_m(nm)?;
            let attenuation = match w.attenuation {
                Some(a) if a < pure => {
                    return Err(Error::invalid(
                        format!("water[{i}].attenuation"),
                        format!(
                            "{a} /m is below pure water's absorption at the lidar's \
                             {nm} nm ({pure:.2} /m): no water is clearer"
                        ),
                    ))
                }
                Some(a) => a,
                None => pure,
            };
            Ok(WaterBody {
                spec: w.clone(),
                point,
                normal,
                attenuation,
            })
        })
        .collect::<Result<Vec<_>>>()
}

impl World {
    /// Ripple-perturbed normal of water body `body` at `p` (still water: the plane's).
    pub fn water_normal(&self, body: usize, p: &Point3<f64>) -> Vector3<f64> {
        let b = &self.water[body];
        if b.spec.ripple <= 0.0 {
            return b.normal;
        }
        // Three seeded wave trains; the slope field has RMS `ripple` per axis.
        let mut g = [0.0f64; 2];
        for k in 0..3u64 {
            let h = hash(self.scene.seed, &[11, body as u64, k]);
            let ang = unit_f64(h) * std::f64::consts::TAU;
            let wl = 0.3 + 0.7 * unit_f64(hash(h, &[1]));
            let ph = unit_f64(hash(h, &[2])) * std::f64::consts::TAU;
            let kx = std::f64::consts::TAU / wl * ang.cos();
            let ky = std::f64::consts::TAU / wl * ang.sin();
            let c = (kx * p.x + ky * p.y + ph).cos();
            g[0] += ang.cos() * c;
            g[1] += ang.sin() * c;
        }
        // Each train contributes variance 1/2 · cos² or sin²: scale so the per-axis RMS ≈ ripple.
        let s = b.spec.ripple * (2.0f64 / 1.5).sqrt();
        (b.normal + Vector3::new(s * g[0], s * g[1], 0.0)).normalize()
    }
}
