//! The built scene: the terrain heightfield and the objects as one triangle mesh (ray cast
//! with parry3d), the water bodies as analytic planes over the terrain below them, and the
//! materials of every surface. glam (parry's vector type) never leaves this file.

use std::collections::BTreeMap;

use nalgebra::{Point3, Vector3};
use parry3d::math::Vector as GVec;
use parry3d::query::{Ray, RayCast};
use parry3d::shape::TriMesh;

use super::rng::{hash, unit_f64};
use super::scene::*;
use crate::error::{Error, Result};
use crate::hazard::Class;

/// A surface material, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub name: String,
    pub spec: MaterialSpec,
}

/// What a ray hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Surface {
    /// Terrain or object triangle `tri`.
    Solid { tri: usize },
    /// Water body `body`.
    Water { body: usize },
}

/// A ray hit in the map frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    pub t: f64,
    pub point: Point3<f64>,
    /// Unit normal facing the ray's origin.
    pub normal: Vector3<f64>,
    pub surface: Surface,
    /// Material index (solids only; for water, the material under the entry point).
    pub material: usize,
}

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

/// The terrain heightfield: vertex (i, j) at origin + (i, j)·resolution; each quad split
/// along its (i, j)–(i+1, j+1) diagonal, exactly as the mesh is.
#[derive(Debug, Clone, PartialEq)]
pub struct Terrain {
    pub origin: [f64; 2],
    pub resolution: f64,
    pub nx: usize,
    pub ny: usize,
    pub z: Vec<f64>,
}

impl Terrain {
    /// Elevation of the triangulated surface at (x, y) (clamped to the edge outside).
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let fx = ((x - self.origin[0]) / self.resolution).clamp(0.0, (self.nx - 1) as f64);
        let fy = ((y - self.origin[1]) / self.resolution).clamp(0.0, (self.ny - 1) as f64);
        let i = (fx.floor() as usize).min(self.nx - 2);
        let j = (fy.floor() as usize).min(self.ny - 2);
        let (u, v) = (fx - i as f64, fy - j as f64);
        let z = |a: usize, b: usize| self.z[b * self.nx + a];
        let (z00, z10, z11, z01) = (z(i, j), z(i + 1, j), z(i + 1, j + 1), z(i, j + 1));
        if u >= v {
            z00 + u * (z10 - z00) + v * (z11 - z10)
        } else {
            z00 + v * (z01 - z00) + u * (z11 - z01)
        }
    }

    pub fn contains(&self, x: f64, y: f64) -> bool {
        let (x1, y1) = (
            self.origin[0] + (self.nx - 1) as f64 * self.resolution,
            self.origin[1] + (self.ny - 1) as f64 * self.resolution,
        );
        x >= self.origin[0] && x <= x1 && y >= self.origin[1] && y <= y1
    }
}

/// An object's footprint for the truth raster.
#[derive(Debug, Clone, PartialEq)]
struct Footprint {
    centre: [f64; 2],
    /// Half extents along the turned axes (box) or semi-axes (ellipse).
    half: [f64; 2],
    yaw: f64,
    is_box: bool,
    class: Class,
}

impl Footprint {
    fn covers(&self, x: f64, y: f64) -> bool {
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

/// The whole simulated world.
pub struct World {
    pub scene: Scene,
    pub terrain: Terrain,
    pub materials: Vec<Material>,
    pub water: Vec<WaterBody>,
    /// Mesh vertices (terrain first, then objects) and triangles, as exported.
    pub vertices: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Material of each triangle; `usize::MAX` marks terrain (material from position).
    tri_material: Vec<usize>,
    terrain_triangles: usize,
    mesh: TriMesh,
    footprints: Vec<Footprint>,
    material_index: BTreeMap<String, usize>,
}

fn smooth_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (xi, yi) = (x.floor(), y.floor());
    let (fx, fy) = (x - xi, y - yi);
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let h = |a: f64, b: f64| 2.0 * unit_f64(hash(seed, &[a as i64 as u64, b as i64 as u64])) - 1.0;
    let (a, b, c, d) = (
        h(xi, yi),
        h(xi + 1.0, yi),
        h(xi, yi + 1.0),
        h(xi + 1.0, yi + 1.0),
    );
    let (u, v) = (s(fx), s(fy));
    a + (b - a) * u + (c - a) * v + (a - b - c + d) * u * v
}

/// Profile of a depression or mound at normalized radius ρ: 1 on the flat part, a cosine
/// rim down to 0 at ρ = 1.
fn rim(rho: f64, flat: f64) -> f64 {
    if rho <= flat {
        1.0
    } else if rho >= 1.0 {
        0.0
    } else {
        let t = (rho - flat) / (1.0 - flat);
        0.5 * (1.0 + (std::f64::consts::PI * t).cos())
    }
}

/// How far the terrain's apron reaches beyond its edges (metres): farther than any sensor
/// of a scene sees the ground.
const APRON_M: f64 = 1000.0;

/// Extends the terrain mesh beyond its edges by [`APRON_M`], each edge vertex's height
/// carried straight outward (and each corner's diagonally), which is the surface
/// [`Terrain::height`] gives outside (clamped to the edge). Without it the world ended at
/// the terrain's edge: a lidar beam or camera ray past it met nothing, and the no-return
/// cue and the sky-below-the-horizon rule saw water there (on `puddles`, 53 m² of water
/// bodies outside the terrain; on `stream_slope`, 28.5 m²). The apron is terrain (its
/// material comes from position) but never water: water bodies lie inside the terrain.
fn apron(vertices: &mut Vec<[f64; 3]>, triangles: &mut Vec<[u32; 3]>, t: &Terrain) {
    let (nx, ny) = (t.nx, t.ny);
    let v = |i: usize, j: usize| j * nx + i;
    // The boundary counter-clockwise seen from above, one run per edge with both corners,
    // and each edge's outward direction.
    let edges: [(Vec<usize>, [f64; 2]); 4] = [
        ((0..nx).map(|i| v(i, 0)).collect(), [0.0, -1.0]),
        ((0..ny).map(|j| v(nx - 1, j)).collect(), [1.0, 0.0]),
        ((0..nx).rev().map(|i| v(i, ny - 1)).collect(), [0.0, 1.0]),
        ((0..ny).rev().map(|j| v(0, j)).collect(), [-1.0, 0.0]),
    ];
    let push = |vertices: &mut Vec<[f64; 3]>, k: usize, d: [f64; 2]| {
        let [x, y, z] = vertices[k];
        vertices.push([x + APRON_M * d[0], y + APRON_M * d[1], z]);
        (vertices.len() - 1) as u32
    };
    // Outer copies of each edge's vertices, in order.
    let outer: Vec<Vec<u32>> = edges
        .iter()
        .map(|(run, d)| run.iter().map(|&k| push(vertices, k, *d)).collect())
        .collect();
    for ((run, _), out) in edges.iter().zip(&outer) {
        for w in 0..run.len() - 1 {
            let (a, b) = (run[w] as u32, run[w + 1] as u32);
            let (ao, bo) = (out[w], out[w + 1]);
            triangles.push([a, ao, bo]);
            triangles.push([a, bo, b]);
        }
    }
    // Corner e: where edge e ends and edge e + 1 begins.
    for e in 0..4 {
        let n = (e + 1) % 4;
        let c = *edges[e].0.last().expect("an edge has two vertices");
        let (d1, d2) = (edges[e].1, edges[n].1);
        let diag = push(vertices, c, [d1[0] + d2[0], d1[1] + d2[1]]);
        let (o1, o2) = (*outer[e].last().expect("same length"), outer[n][0]);
        triangles.push([c as u32, o1, diag]);
        triangles.push([c as u32, diag, o2]);
    }
}

impl World {
    /// Builds the world of a validated scene.
    pub fn build(scene: &Scene) -> Result<World> {
        scene.validate()?;
        let all = scene.all_materials();
        let mut materials = Vec::new();
        let mut material_index = BTreeMap::new();
        for (k, v) in all {
            material_index.insert(k.clone(), materials.len());
            materials.push(Material { name: k, spec: v });
        }
        let t = &scene.terrain;
        let nx = (t.size[0] / t.resolution).round() as usize + 1;
        let ny = (t.size[1] / t.resolution).round() as usize + 1;
        if nx < 2 || ny < 2 {
            return Err(Error::invalid("terrain.size", "smaller than one cell"));
        }
        // A grid beyond 2^26 vertices (8,192² — e.g. 800 m square at 0.1 m) is a typo in
        // size or resolution, not a scene: refuse it instead of allocating it.
        const MAX_VERTICES: usize = 1 << 26;
        if nx.checked_mul(ny).is_none_or(|n| n > MAX_VERTICES) {
            return Err(Error::invalid(
                "terrain.size",
                format!(
                    "{} × {} m at resolution {} m is {nx} × {ny} height samples; at most {MAX_VERTICES}",
                    t.size[0], t.size[1], t.resolution
                ),
            ));
        }
        let mut z = vec![0.0; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                let x = t.origin[0] + i as f64 * t.resolution;
                let y = t.origin[1] + j as f64 * t.resolution;
                z[j * nx + i] = Self::terrain_elevation(scene, x, y);
            }
        }
        let terrain = Terrain {
            origin: t.origin,
            resolution: t.resolution,
            nx,
            ny,
            z,
        };
        let mut vertices = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                vertices.push([
                    t.origin[0] + i as f64 * t.resolution,
                    t.origin[1] + j as f64 * t.resolution,
                    terrain.z[j * nx + i],
                ]);
            }
        }
        let mut triangles = Vec::with_capacity(2 * (nx - 1) * (ny - 1));
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let v = |a: usize, b: usize| (b * nx + a) as u32;
                triangles.push([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
                triangles.push([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
            }
        }
        apron(&mut vertices, &mut triangles, &terrain);
        let terrain_triangles = triangles.len();
        let mut tri_material = vec![usize::MAX; terrain_triangles];
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
                        &mut vertices,
                        &mut triangles,
                        &mut tri_material,
                        [px, py],
                        trunk_r,
                        base - 0.3,
                        base + 0.45 * h,
                        8,
                        mat("bark"),
                    );
                    add_cone(
                        &mut vertices,
                        &mut triangles,
                        &mut tri_material,
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
                    let zmin =
                        Self::min_over_box(&terrain, [px, py], [0.5 * s[0], 0.5 * s[1]], yaw) - 0.3;
                    add_box(
                        &mut vertices,
                        &mut triangles,
                        &mut tri_material,
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
                        &mut vertices,
                        &mut triangles,
                        &mut tri_material,
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
        let gverts: Vec<GVec> = vertices
            .iter()
            .map(|v| GVec::new(v[0] as f32, v[1] as f32, v[2] as f32))
            .collect();
        let mesh = TriMesh::new(gverts, triangles.clone())
            .map_err(|e| Error::invalid("scene mesh", format!("{e:?}")))?;
        let water = scene
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
            .collect::<Result<Vec<_>>>()?;
        Ok(World {
            scene: scene.clone(),
            terrain,
            materials,
            water,
            vertices,
            triangles,
            tri_material,
            terrain_triangles,
            mesh,
            footprints,
            material_index,
        })
    }

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

    /// The analytic terrain: base plane + noise + features (before triangulation).
    pub fn terrain_elevation(scene: &Scene, x: f64, y: f64) -> f64 {
        let t = &scene.terrain;
        let mut z = t.elevation + t.slope[0] * x + t.slope[1] * y;
        if t.roughness > 0.0 {
            let mut amp = 1.0;
            let mut scale = t.roughness_scale;
            let mut sum = 0.0;
            let mut norm = 0.0;
            for o in 0..3 {
                sum += amp * smooth_noise(hash(scene.seed, &[1, o]), x / scale, y / scale);
                norm += amp;
                amp *= 0.5;
                scale *= 0.5;
            }
            z += t.roughness * sum / norm;
        }
        for f in &t.features {
            match f.kind {
                FeatureKind::Depression | FeatureKind::Mound => {
                    let c = f.centre.unwrap_or_default();
                    let r = f.radius.unwrap_or([1.0, 1.0]);
                    let rho = ((x - c[0]) / r[0]).hypot((y - c[1]) / r[1]);
                    let p = rim(rho, f.flat);
                    if f.kind == FeatureKind::Depression {
                        z -= f.depth.unwrap_or(0.0) * p;
                    } else {
                        z += f.height.unwrap_or(0.0) * p;
                    }
                }
                FeatureKind::Ditch | FeatureKind::Curb => {
                    let (a, b) = (f.from.unwrap_or_default(), f.to.unwrap_or_default());
                    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                    let l2 = dx * dx + dy * dy;
                    let s = (((x - a[0]) * dx + (y - a[1]) * dy) / l2).clamp(0.0, 1.0);
                    let d = (x - a[0] - s * dx).hypot(y - a[1] - s * dy);
                    let p = rim(d / (0.5 * f.width.unwrap_or(1.0)), f.flat);
                    z += match f.kind {
                        FeatureKind::Ditch => -f.depth.unwrap_or(0.0) * p,
                        _ => f.height.unwrap_or(0.0) * p,
                    };
                }
            }
        }
        z
    }

    /// Index of a material by name.
    pub fn material(&self, name: &str) -> Option<usize> {
        self.material_index.get(name).copied()
    }

    /// Surface material of the terrain at (x, y): the last patch covering it, else the
    /// innermost feature with a material, else the terrain's.
    pub fn terrain_material(&self, x: f64, y: f64) -> usize {
        let s = &self.scene;
        if let Some(p) = s
            .patches
            .iter()
            .rev()
            .find(|p| (x - p.centre[0]).hypot(y - p.centre[1]) <= p.radius)
        {
            return self.material_index[&p.material];
        }
        for f in s.terrain.features.iter().rev() {
            let Some(m) = &f.material else { continue };
            let inside = match f.kind {
                FeatureKind::Depression | FeatureKind::Mound => {
                    let c = f.centre.unwrap_or_default();
                    let r = f.radius.unwrap_or([1.0, 1.0]);
                    ((x - c[0]) / r[0]).hypot((y - c[1]) / r[1]) < 1.0
                }
                FeatureKind::Ditch | FeatureKind::Curb => {
                    let (a, b) = (f.from.unwrap_or_default(), f.to.unwrap_or_default());
                    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                    let l2 = dx * dx + dy * dy;
                    let t = (((x - a[0]) * dx + (y - a[1]) * dy) / l2).clamp(0.0, 1.0);
                    (x - a[0] - t * dx).hypot(y - a[1] - t * dy) < 0.5 * f.width.unwrap_or(1.0)
                }
            };
            if inside {
                return self.material_index[m];
            }
        }
        self.material_index[&s.terrain.material]
    }

    /// Water surface elevation at (x, y) when water covers it (the highest body).
    pub fn water_at(&self, x: f64, y: f64) -> Option<(usize, f64)> {
        if !self.terrain.contains(x, y) {
            return None;
        }
        let ground = self.terrain.height(x, y);
        self.water
            .iter()
            .enumerate()
            .filter(|(_, b)| b.in_region(x, y))
            .map(|(i, b)| (i, b.surface_z(x, y)))
            .filter(|(_, s)| *s > ground)
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// Whether an object of an obstacle material (a rock, a building) stands at (x, y): a
    /// geometric obstacle, unlike a flat patch of the same material.
    pub fn object_obstacle(&self, x: f64, y: f64) -> bool {
        self.footprints
            .iter()
            .any(|f| f.class == Class::Obstacle && f.covers(x, y))
    }

    /// Truth class of the dry cell at (x, y): object footprints, then the surface material.
    pub fn dry_class(&self, x: f64, y: f64) -> Class {
        if let Some(f) = self.footprints.iter().find(|f| f.covers(x, y)) {
            return f.class;
        }
        self.materials[self.terrain_material(x, y)]
            .spec
            .class
            .class()
    }

    /// First solid (terrain or object) hit along the ray within `max_t`.
    pub fn cast_solid(&self, o: &Point3<f64>, d: &Vector3<f64>, max_t: f64) -> Option<Hit> {
        let ray = Ray::new(
            GVec::new(o.x as f32, o.y as f32, o.z as f32),
            GVec::new(d.x as f32, d.y as f32, d.z as f32),
        );
        let hit = self
            .mesh
            .cast_local_ray_and_get_normal(&ray, max_t as f32, false)?;
        let tri = hit.subshape as usize;
        if tri >= self.triangles.len() {
            return None;
        }
        let t = hit.time_of_impact as f64;
        let point = o + d * t;
        let [a, b, c] = self.triangles[tri].map(|i| Vector3::from(self.vertices[i as usize]));
        let mut normal = (b - a).cross(&(c - a)).normalize();
        if normal.dot(d) > 0.0 {
            normal = -normal;
        }
        let material = match self.tri_material[tri] {
            usize::MAX => self.terrain_material(point.x, point.y),
            m => m,
        };
        Some(Hit {
            t,
            point,
            normal,
            surface: Surface::Solid { tri },
            material,
        })
    }

    /// True for terrain triangles.
    pub fn is_terrain(&self, tri: usize) -> bool {
        tri < self.terrain_triangles
    }

    /// First water surface met from above along the ray, before `max_t`.
    pub fn cast_water(&self, o: &Point3<f64>, d: &Vector3<f64>, max_t: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (i, b) in self.water.iter().enumerate() {
            let dn = d.dot(&b.normal);
            if dn >= 0.0 {
                continue;
            }
            let t = (b.point - o).dot(&b.normal) / dn;
            if !(t > 1e-9 && t < max_t && best.is_none_or(|h| t < h.t)) {
                continue;
            }
            let p = o + d * t;
            if !b.in_region(p.x, p.y) || !self.terrain.contains(p.x, p.y) {
                continue;
            }
            if self.terrain.height(p.x, p.y) >= b.surface_z(p.x, p.y) {
                continue;
            }
            best = Some(Hit {
                t,
                point: p,
                normal: b.normal,
                surface: Surface::Water { body: i },
                material: self.terrain_material(p.x, p.y),
            });
        }
        best
    }

    /// First hit of anything (solid or water) along the ray.
    pub fn cast(&self, o: &Point3<f64>, d: &Vector3<f64>, max_t: f64) -> Option<Hit> {
        let solid = self.cast_solid(o, d, max_t);
        let limit = solid.map(|h| h.t).unwrap_or(max_t);
        match self.cast_water(o, d, limit) {
            Some(w) => Some(w),
            None => solid,
        }
    }

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
