//! The objects standing on the terrain (trees, buildings, rocks): their triangle meshes
//! and their footprints in the truth raster.

use std::collections::BTreeMap;

use super::super::rng::{hash, unit_f64};
use super::super::scene::*;
use super::{Material, Terrain};
use crate::hazard::Class;

/// An object's footprint for the truth raster.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Footprint {
    centre: [f64; 2],
    /// Half extents along the turned axes (box) or semi-axes (ellipse).
    half: [f64; 2],
    yaw: f64,
    is_box: bool,
    pub(super) class: Class,
}

impl Footprint {
    pub(super) fn covers(&self, x: f64, y: f64) -> bool {
        let (dx, dy) = (x - self.centre[0], y - self.centre[1]);
        let (c, s) = (self.yaw.cos(), self.yaw.sin());
        let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
        if self.is_box {
            u.abs() <= self.half[0] && v.abs() <= self.half[1]
        } else {
            (u / self.half[0]).powi(2) + (v / self.half[1]).powi(2) <= 1.0
        }
    }
}

/// Adds the mesh of every object of `scene` (each on the terrain under it) to the vertices,
/// triangles and triangle materials, and returns the objects' footprints.
pub(super) fn add_objects(
    scene: &Scene,
    terrain: &Terrain,
    materials: &[Material],
    material_index: &BTreeMap<String, usize>,
    vertices: &mut Vec<[f64; 3]>,
    triangles: &mut Vec<[u32; 3]>,
    tri_material: &mut Vec<usize>,
) -> Vec<Footprint> {
    let mut footprints = Vec::new();
    let mat = |name: &str| material_index[name];
    for (oi, o) in scene.objects.iter().enumerate() {
        let [px, py] = o.position;
        let base = terrain.height(px, py);
        let yaw = o.yaw_deg.to_radians();
        match o.kind {
            ObjectKind::Tree => {
                let h = o.height.unwrap_or(1.0);
                let r = o.radius.unwrap_or(1.0);
                let trunk_r = (0.08 * h).clamp(0.05, 0.4).min(0.5 * r);
                let crown = o.material.as_deref().unwrap_or("foliage");
                // Trunk: an octagonal prism from below the ground into the crown.
                add_prism(
                    vertices,
                    triangles,
                    tri_material,
                    [px, py],
                    trunk_r,
                    base - 0.3,
                    base + 0.45 * h,
                    8,
                    mat("bark"),
                );
                add_cone(
                    vertices,
                    triangles,
                    tri_material,
                    [px, py],
                    r,
                    base + 0.3 * h,
                    base + h,
                    12,
                    mat(crown),
                );
                footprints.push(Footprint {
                    centre: [px, py],
                    half: [r, r],
                    yaw: 0.0,
                    is_box: false,
                    class: Class::Vegetation,
                });
            }
            ObjectKind::Building => {
                let s = o.size.unwrap_or([1.0; 3]);
                let m = mat(o.material.as_deref().unwrap_or("concrete"));
                let zmin = min_over_box(terrain, [px, py], [0.5 * s[0], 0.5 * s[1]], yaw) - 0.3;
                add_box(
                    vertices,
                    triangles,
                    tri_material,
                    [px, py],
                    [0.5 * s[0], 0.5 * s[1]],
                    yaw,
                    zmin,
                    base + s[2],
                    m,
                );
                footprints.push(Footprint {
                    centre: [px, py],
                    half: [0.5 * s[0], 0.5 * s[1]],
                    yaw,
                    is_box: true,
                    class: materials[m].spec.class.class(),
                });
            }
            ObjectKind::Rock => {
                let s = o.size.unwrap_or([1.0; 3]);
                let m = mat(o.material.as_deref().unwrap_or("rock"));
                add_rock(
                    vertices,
                    triangles,
                    tri_material,
                    [px, py, base],
                    s,
                    yaw,
                    hash(scene.seed, &[7, oi as u64]),
                    m,
                );
                footprints.push(Footprint {
                    centre: [px, py],
                    half: [s[0], s[1]],
                    yaw,
                    is_box: false,
                    class: materials[m].spec.class.class(),
                });
            }
        }
    }
    footprints
}

/// The lowest terrain under a turned box: its corners, edge midpoints and centre.
fn min_over_box(t: &Terrain, c: [f64; 2], half: [f64; 2], yaw: f64) -> f64 {
    let (co, si) = (yaw.cos(), yaw.sin());
    let mut m = f64::INFINITY;
    for a in [-1.0, 0.0, 1.0] {
        for b in [-1.0, 0.0, 1.0] {
            let (u, v) = (a * half[0], b * half[1]);
            m = m.min(t.height(c[0] + co * u - si * v, c[1] + si * u + co * v));
        }
    }
    m
}

#[allow(clippy::too_many_arguments)]
fn add_prism(
    v: &mut Vec<[f64; 3]>,
    t: &mut Vec<[u32; 3]>,
    m: &mut Vec<usize>,
    c: [f64; 2],
    r: f64,
    z0: f64,
    z1: f64,
    n: usize,
    mat: usize,
) {
    let b = v.len() as u32;
    for k in 0..n {
        let a = k as f64 / n as f64 * std::f64::consts::TAU;
        v.push([c[0] + r * a.cos(), c[1] + r * a.sin(), z0]);
        v.push([c[0] + r * a.cos(), c[1] + r * a.sin(), z1]);
    }
    let top = v.len() as u32;
    v.push([c[0], c[1], z1]);
    for k in 0..n as u32 {
        let k1 = (k + 1) % n as u32;
        let (lo0, hi0, lo1, hi1) = (b + 2 * k, b + 2 * k + 1, b + 2 * k1, b + 2 * k1 + 1);
        t.push([lo0, lo1, hi1]);
        t.push([lo0, hi1, hi0]);
        t.push([hi0, hi1, top]);
        m.extend([mat; 3]);
    }
}

#[allow(clippy::too_many_arguments)]
fn add_cone(
    v: &mut Vec<[f64; 3]>,
    t: &mut Vec<[u32; 3]>,
    m: &mut Vec<usize>,
    c: [f64; 2],
    r: f64,
    z0: f64,
    z1: f64,
    n: usize,
    mat: usize,
) {
    let b = v.len() as u32;
    for k in 0..n {
        let a = k as f64 / n as f64 * std::f64::consts::TAU;
        v.push([c[0] + r * a.cos(), c[1] + r * a.sin(), z0]);
    }
    let apex = v.len() as u32;
    v.push([c[0], c[1], z1]);
    let bottom = v.len() as u32;
    v.push([c[0], c[1], z0]);
    for k in 0..n as u32 {
        let k1 = (k + 1) % n as u32;
        t.push([b + k, b + k1, apex]);
        t.push([b + k1, b + k, bottom]);
        m.extend([mat; 2]);
    }
}

#[allow(clippy::too_many_arguments)]
fn add_box(
    v: &mut Vec<[f64; 3]>,
    t: &mut Vec<[u32; 3]>,
    m: &mut Vec<usize>,
    c: [f64; 2],
    half: [f64; 2],
    yaw: f64,
    z0: f64,
    z1: f64,
    mat: usize,
) {
    let b = v.len() as u32;
    let (co, si) = (yaw.cos(), yaw.sin());
    for z in [z0, z1] {
        for (u, w) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let (x, y) = (u * half[0], w * half[1]);
            v.push([c[0] + co * x - si * y, c[1] + si * x + co * y, z]);
        }
    }
    let q = |a: u32, bb: u32, cc: u32, d: u32| [[b + a, b + bb, b + cc], [b + a, b + cc, b + d]];
    for f in [
        q(0, 3, 2, 1),
        q(4, 5, 6, 7),
        q(0, 1, 5, 4),
        q(1, 2, 6, 5),
        q(2, 3, 7, 6),
        q(3, 0, 4, 7),
    ] {
        t.extend(f);
        m.extend([mat; 2]);
    }
}

#[allow(clippy::too_many_arguments)]
fn add_rock(
    v: &mut Vec<[f64; 3]>,
    t: &mut Vec<[u32; 3]>,
    m: &mut Vec<usize>,
    c: [f64; 3],
    s: [f64; 3],
    yaw: f64,
    seed: u64,
    mat: usize,
) {
    // A UV sphere (8 × 12) with seeded radial jitter, its lower third buried.
    let (nr, ns) = (8usize, 12usize);
    let b = v.len() as u32;
    let (co, si) = (yaw.cos(), yaw.sin());
    for i in 0..=nr {
        let th = std::f64::consts::PI * i as f64 / nr as f64;
        for j in 0..ns {
            let ph = std::f64::consts::TAU * j as f64 / ns as f64;
            let poles = i == 0 || i == nr;
            let jit = if poles {
                1.0
            } else {
                0.85 + 0.3 * unit_f64(hash(seed, &[i as u64, j as u64]))
            };
            let (x, y, z) = (
                s[0] * jit * th.sin() * ph.cos(),
                s[1] * jit * th.sin() * ph.sin(),
                s[2] * jit * th.cos(),
            );
            v.push([
                c[0] + co * x - si * y,
                c[1] + si * x + co * y,
                c[2] + z - 0.3 * s[2],
            ]);
        }
    }
    let id = |i: usize, j: usize| b + (i * ns + j % ns) as u32;
    for i in 0..nr {
        for j in 0..ns {
            if i > 0 {
                t.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                m.push(mat);
            }
            if i + 1 < nr {
                t.push([id(i, j + 1), id(i + 1, j), id(i + 1, j + 1)]);
                m.push(mat);
            }
        }
    }
}
