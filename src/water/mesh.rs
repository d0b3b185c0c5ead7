//! The triangle mesh of a water body (`water.ply`).
//!
//! Every cell is four triangles around its centre. The top follows the fitted surface, with
//! vertices at cell corners shared between neighbouring cells, so the top is one connected
//! sheet. When every cell's depth is known the body is closed: the bottom lies at surface −
//! depth, with the measured depth at each cell centre, the mean depth of the four cells
//! around an interior corner, the mean of the two cells at the midpoint of an edge between
//! two water cells, and depth zero at the shoreline, where the bottom meets the top in the
//! same vertex. Every edge then belongs to exactly two triangles, all wound
//! counter-clockwise seen from outside: a watertight, consistently wound solid whose volume
//! is the water's. A body with any unknown depth is the open top sheet only.

use std::collections::{BTreeSet, HashMap};

use super::{Surface, WaterBody};
use crate::grid::CellKey;

/// A body's mesh in the map frame (f64).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct BodyMesh {
    /// Vertex positions, map frame, metres.
    pub vertices: Vec<[f64; 3]>,
    /// Depth below the surface at each vertex (0 on the top sheet).
    pub vertex_depth: Vec<f64>,
    /// Top triangles (normals up).
    pub top: Vec<[u32; 3]>,
    /// Bottom triangles (normals down).
    pub bottom: Vec<[u32; 3]>,
    /// Whether every cell's depth is known, so the mesh is closed.
    pub closed: bool,
}

impl BodyMesh {
    /// Signed volume by the divergence theorem (positive for a closed, outward-wound mesh),
    /// about the first vertex to keep the sums small.
    pub(crate) fn volume(&self) -> f64 {
        let Some(&o) = self.vertices.first() else {
            return 0.0;
        };
        let p = |i: u32| {
            let v = self.vertices[i as usize];
            nalgebra::Vector3::new(v[0] - o[0], v[1] - o[1], v[2] - o[2])
        };
        self.top
            .iter()
            .chain(&self.bottom)
            .map(|t| p(t[0]).dot(&p(t[1]).cross(&p(t[2]))) / 6.0)
            .sum()
    }

    /// Area of the top sheet projected on the horizontal plane (the tests check the mesh
    /// by it).
    #[cfg(test)]
    pub(crate) fn top_plan_area(&self) -> f64 {
        self.top
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
            })
            .sum()
    }
}

/// Builds the mesh of `body` on a grid of resolution `res` with its surface evaluator.
pub(crate) fn body_mesh(body: &WaterBody, res: f64, surface: &Surface) -> BodyMesh {
    let closed = !body.cells.is_empty() && body.cell_depth_m.iter().all(|d| d.is_finite());
    let set: BTreeSet<CellKey> = body.cells.iter().copied().collect();
    let depth: HashMap<CellKey, f64> = body
        .cells
        .iter()
        .zip(&body.cell_depth_m)
        .map(|(&k, &d)| (k, d as f64))
        .collect();
    let mut m = BodyMesh {
        closed,
        ..BodyMesh::default()
    };
    let push = |m: &mut BodyMesh, x: f64, y: f64, z: f64, d: f64| {
        m.vertices.push([x, y, z]);
        m.vertex_depth.push(d);
        (m.vertices.len() - 1) as u32
    };
    // Corner (i, j) is at (i·res, j·res); cell (kx, ky) spans corners kx..kx+1, ky..ky+1.
    let mut top_corner: HashMap<(i64, i64), u32> = HashMap::new();
    let mut bottom_corner: HashMap<(i64, i64), u32> = HashMap::new();
    let mut bottom_mid: HashMap<(i64, i64), u32> = HashMap::new();
    for &k in &body.cells {
        let corners = [
            (k.x, k.y),
            (k.x + 1, k.y),
            (k.x + 1, k.y + 1),
            (k.x, k.y + 1),
        ];
        let mut t = [0u32; 4];
        let mut b = [0u32; 4];
        for (n, &(i, j)) in corners.iter().enumerate() {
            let (x, y) = (i as f64 * res, j as f64 * res);
            let around =
                [(i - 1, j - 1), (i, j - 1), (i - 1, j), (i, j)].map(|(a, c)| CellKey::new(a, c));
            let interior = around.iter().all(|c| set.contains(c));
            t[n] = match top_corner.get(&(i, j)) {
                Some(&v) => v,
                None => {
                    let v = push(&mut m, x, y, surface.at(x, y), 0.0);
                    top_corner.insert((i, j), v);
                    v
                }
            };
            b[n] = if !closed || !interior {
                t[n]
            } else {
                match bottom_corner.get(&(i, j)) {
                    Some(&v) => v,
                    None => {
                        let d = around.iter().map(|c| depth[c]).sum::<f64>() / 4.0;
                        let top = m.vertices[t[n] as usize][2];
                        let v = push(&mut m, x, y, top - d, d);
                        bottom_corner.insert((i, j), v);
                        v
                    }
                }
            };
        }
        let (cx, cy) = ((k.x as f64 + 0.5) * res, (k.y as f64 + 0.5) * res);
        let zc = surface.at(cx, cy);
        let ct = push(&mut m, cx, cy, zc, 0.0);
        for n in 0..4 {
            m.top.push([ct, t[n], t[(n + 1) % 4]]);
        }
        if closed {
            let d = depth[&k];
            let cb = push(&mut m, cx, cy, zc - d, d);
            // The bottom polygon: corners, and the midpoint of every edge shared with
            // another cell of the body. Without the midpoint, an edge between two shoreline
            // corners inside a one-cell-wide strip would be shared by four triangles.
            let mut ring: Vec<u32> = Vec::with_capacity(8);
            for n in 0..4 {
                ring.push(b[n]);
                let (p, q) = (corners[n], corners[(n + 1) % 4]);
                // The neighbour across edge p–q (counter-clockwise: below, right, above, left).
                let across = [(0, -1), (1, 0), (0, 1), (-1, 0)][n];
                let nb = CellKey::new(k.x + across.0, k.y + across.1);
                if set.contains(&nb) {
                    let key = (p.0 + q.0, p.1 + q.1); // twice the midpoint: unique per edge
                    let v = match bottom_mid.get(&key) {
                        Some(&v) => v,
                        None => {
                            let (x, y) = (key.0 as f64 * res / 2.0, key.1 as f64 * res / 2.0);
                            let dm = (d + depth[&nb]) / 2.0;
                            let v = push(&mut m, x, y, surface.at(x, y) - dm, dm);
                            bottom_mid.insert(key, v);
                            v
                        }
                    };
                    ring.push(v);
                }
            }
            for n in 0..ring.len() {
                m.bottom.push([cb, ring[(n + 1) % ring.len()], ring[n]]);
            }
        }
    }
    m
}
