//! Ground truth: the `truth.ply` raster (the `map.ply` contract schema) and `truth.json`.

use serde::{Deserialize, Serialize};

use super::world::World;
use crate::grid::CellKey;
use crate::hazard::{Class, Hazard, HazardMap, MapCell};

/// One vehicle pose of the trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthPose {
    pub stamp: f64,
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub yaw: f64,
}

/// A water body as the truth describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthWater {
    /// "level" or "stream".
    pub kind: String,
    /// A point of the surface plane and its upward unit normal (map frame).
    pub surface_point: [f64; 3],
    pub surface_normal: [f64; 3],
    /// Elevation of a level surface; `null` for a stream.
    pub level: Option<f64>,
    /// Truth cells covered, their area (m²), the water volume (m³) and greatest depth (m).
    pub cells: usize,
    pub area_m2: f64,
    pub volume_m3: f64,
    pub max_depth_m: f64,
    pub ripple_rad: f64,
    pub attenuation_per_m: f64,
}

/// `truth.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthInfo {
    pub scene: String,
    pub description: String,
    pub seed: u64,
    /// Cell size of `truth.ply`; cell key k has its centre at (k + 0.5) · resolution.
    pub resolution: f64,
    /// Water at most this deep is hazard 1 (shallow), deeper is hazard 2.
    pub fording_depth_m: f64,
    /// Terrain extent: lower-left corner and size (m).
    pub origin: [f64; 2],
    pub size: [f64; 2],
    /// The vehicle (base_link) at every frame.
    pub trajectory: Vec<TruthPose>,
    pub water_bodies: Vec<TruthWater>,
    /// Truth cells of each class code (0..=5).
    pub class_counts: [usize; 6],
    /// Sensors the log carries, by topic.
    pub topics: Vec<String>,
    /// What the colour camera saw of the water over the whole log, when the rig has one.
    #[serde(default)]
    pub colour_view: Option<ColourView>,
    /// Truth cells of water (keys at `resolution`) that some sensor ray (a lidar beam, a
    /// stereo or camera pixel) met first at the water's surface in some frame: the water
    /// the sensors could see. `None` in truth written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seen_water: Option<Vec<[i64; 2]>>,
}

/// Truth cells of water (keys at `resolution`) as the colour camera saw them: in some frame
/// reflecting the sky (what a colour classifier can call water), or only ever reflecting
/// terrain and objects (paper §2.3: hard to recognise by colour alone). Water cells in
/// neither list were never seen by the camera (hidden behind a bank, out of view).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ColourView {
    pub sky: Vec<[i64; 2]>,
    pub terrain: Vec<[i64; 2]>,
}

/// The truth raster over every whole cell of the terrain: z is the terrain elevation, or
/// the water surface for water cells; depth is the water depth (0 when dry); class from
/// water, object footprints and surface materials; hazard from the fording depth (objects
/// of an obstacle material are hazard 3; a flat patch of such a material is not: `tarn
/// eval` adds the obstacles of the terrain's own steps and slopes).
pub fn truth_map(w: &World) -> HazardMap {
    let res = w.scene.truth_resolution;
    let t = &w.terrain;
    let x1 = t.origin[0] + (t.nx - 1) as f64 * t.resolution;
    let y1 = t.origin[1] + (t.ny - 1) as f64 * t.resolution;
    let (kx0, kx1) = ((t.origin[0] / res).ceil() as i64, (x1 / res).floor() as i64);
    let (ky0, ky1) = ((t.origin[1] / res).ceil() as i64, (y1 / res).floor() as i64);
    let mut cells = Vec::new();
    for ky in ky0..ky1 {
        for kx in kx0..kx1 {
            let (x, y) = ((kx as f64 + 0.5) * res, (ky as f64 + 0.5) * res);
            let ground = t.height(x, y);
            let (z, depth, class, hazard, water) = match w.water_at(x, y) {
                Some((_, s)) => {
                    let d = s - ground;
                    let hz = if d <= w.scene.fording_depth {
                        Hazard::ShallowWater
                    } else {
                        Hazard::DeepWater
                    };
                    (s, d as f32, Class::Water, hz, 1.0)
                }
                None => {
                    let c = w.dry_class(x, y);
                    let hz = if w.object_obstacle(x, y) {
                        Hazard::Obstacle
                    } else {
                        Hazard::Free
                    };
                    (ground, 0.0, c, hz, 0.0)
                }
            };
            cells.push(MapCell {
                key: CellKey::new(kx, ky),
                x,
                y,
                z,
                elevation_std: 0.0,
                water,
                depth,
                class,
                hazard,
                hits: 0,
                below: 0,
            });
        }
    }
    HazardMap::new(res, cells)
}

/// Statistics of each water body over the truth raster.
pub fn water_stats(w: &World, map: &HazardMap) -> Vec<TruthWater> {
    let a = map.resolution * map.resolution;
    w.water
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let (mut n, mut vol, mut maxd) = (0usize, 0.0, 0.0f64);
            for c in map.cells.iter().filter(|c| c.class == Class::Water) {
                if w.water_at(c.x, c.y).map(|(j, _)| j) == Some(i) {
                    n += 1;
                    vol += c.depth as f64 * a;
                    maxd = maxd.max(c.depth as f64);
                }
            }
            TruthWater {
                kind: format!("{:?}", b.spec.kind).to_lowercase(),
                surface_point: b.point.coords.into(),
                surface_normal: b.normal.into(),
                level: b.spec.level,
                cells: n,
                area_m2: n as f64 * a,
                volume_m3: vol,
                max_depth_m: maxd,
                ripple_rad: b.spec.ripple,
                attenuation_per_m: b.attenuation,
            }
        })
        .collect()
}
