//! The terrain: its analytic elevation (base plane, noise, features), the heightfield
//! sampled from it, and the heightfield's triangle mesh with the apron around it.

use super::super::rng::{hash, unit_f64};
use super::super::scene::*;
use super::World;
use crate::error::{Error, Result};

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

/// A terrain and its mesh: the vertices and the triangles.
pub(super) type TerrainMesh = (Terrain, Vec<[f64; 3]>, Vec<[u32; 3]>);

/// The terrain heightfield of `scene` sampled from [`World::terrain_elevation`] at its
/// resolution, and its mesh: the vertices, each quad's two triangles, then the apron's.
pub(super) fn heightfield(scene: &Scene) -> Result<TerrainMesh> {
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
            z[j * nx + i] = World::terrain_elevation(scene, x, y);
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
    Ok((terrain, vertices, triangles))
}

impl World {
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
}
