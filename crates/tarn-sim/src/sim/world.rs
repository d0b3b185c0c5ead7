//! The built scene: the terrain heightfield and the objects as one triangle mesh (ray cast
//! with parry3d), the water bodies as analytic planes over the terrain below them, and the
//! materials of every surface. glam (parry's vector type) never leaves this module.

use std::collections::BTreeMap;

use nalgebra::{Point3, Vector3};
use parry3d::math::Vector as GVec;
use parry3d::query::{Ray, RayCast};
use parry3d::shape::TriMesh;

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

mod objects;
mod terrain;
mod water;

use objects::Footprint;
pub use terrain::Terrain;
pub use water::WaterBody;

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

impl World {
    /// Builds the world of a validated scene: its materials, the terrain heightfield (with
    /// its apron), the objects' meshes standing on it, the one ray-cast mesh of both, and
    /// the water bodies' planes.
    pub fn build(scene: &Scene) -> Result<World> {
        scene.validate()?;
        let all = scene.all_materials();
        let mut materials = Vec::new();
        let mut material_index = BTreeMap::new();
        for (k, v) in all {
            material_index.insert(k.clone(), materials.len());
            materials.push(Material { name: k, spec: v });
        }
        let (terrain, mut vertices, mut triangles) = terrain::heightfield(scene)?;
        let terrain_triangles = triangles.len();
        let mut tri_material = vec![usize::MAX; terrain_triangles];
        let footprints = objects::add_objects(
            scene,
            &terrain,
            &materials,
            &material_index,
            &mut vertices,
            &mut triangles,
            &mut tri_material,
        );
        let gverts: Vec<GVec> = vertices
            .iter()
            .map(|v| GVec::new(v[0] as f32, v[1] as f32, v[2] as f32))
            .collect();
        let mesh = TriMesh::new(gverts, triangles.clone())
            .map_err(|e| Error::invalid("scene mesh", format!("{e:?}")))?;
        let water = water::water_bodies(scene)?;
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
}
