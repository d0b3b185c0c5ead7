//! Projecting pixel labels into map cells.
//!
//! A pixel with a 3-D point (stereo, or a lidar point that projects into the image) votes for
//! that point's cell. A pixel without one — sky reflections rarely match in stereo — is cast
//! as a ray against the grid's elevation surface ([`ElevationSurface`], a parry3d
//! `HeightField` built from the [`RollingGrid`]) or the current water level, and votes for the
//! cell of the first hit. Occlusion comes with the first hit: a cell hidden behind a ridge is
//! never the first thing a ray meets, so it gets no vote.
//!
//! Unobserved cells are **holes**: the height field's vertices are the grid's cell centres, and
//! every quad with an unobserved corner is removed, so a ray can only stop on a surface
//! spanned by four observed cells — no hit is ever made where nothing was observed (a ray
//! through a hole goes on, and may hit observed terrain behind it).
//!
//! The output, [`LabelVotes`], is a sparse map from [`CellKey`] to per-class `u32` counts with a
//! commutative, associative [`LabelVotes::merge`]: results do not depend on thread count or
//! frame order. Fusing votes into the map's classes is left to the mapper.
//!
//! Exports: points and rays to cells ([`label_points`], [`Projector`] with its
//! [`ProjectConfig`] and [`ProjectStats`], [`ElevationSurface`], [`RayTarget`],
//! [`LabelVotes`] of [`Counts`]); a frame's image labels into the grid's evidence
//! ([`FrameLabels`], its [`FrameLabelConfig`], [`LabelsConfig`], [`LabelSensor`],
//! [`MwirLabelConfig`], [`Sampler`], [`Encoding`], and its [`FrameLabelsReport`] of
//! [`SensorLabelStats`]; [`reflection_check`]); pixel rays marched over the fused
//! elevations ([`GridSurface`]).

mod frame;
mod surface;
mod zbuffer;

pub use frame::{
    reflection_check, Encoding, FrameLabelConfig, FrameLabels, FrameLabelsReport, LabelSensor,
    LabelsConfig, MwirLabelConfig, Sampler, SensorLabelStats,
};
pub use surface::GridSurface;

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};
use parry3d::query::{Ray, RayCast};
use parry3d::shape::{HeightField, HeightFieldCellStatus};
use rayon::prelude::*;

use crate::classify::{Label, LabelImage};
use crate::error::{Error, Result};
use crate::geom::{pose_is_finite, CameraModel, PointCloud, Pose};
use crate::grid::{key_of, CellKey, RollingGrid};

/// Votes per decided label, indexed by [`Label::index`] (other, water, sky, snow/ice).
pub type Counts = [u32; 4];

/// A sparse, mergeable map of label votes per cell.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelVotes {
    resolution: f64,
    cells: HashMap<CellKey, Counts>,
}

impl LabelVotes {
    /// An empty vote map of cells `resolution` metres wide. Fails unless the resolution is
    /// finite and positive.
    pub fn new(resolution: f64) -> Result<Self> {
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(Error::invalid(
                "vote map resolution",
                format!("{resolution} m"),
            ));
        }
        Ok(LabelVotes {
            resolution,
            cells: HashMap::new(),
        })
    }

    /// Cell edge length, metres.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// One vote of `label` for `key`; [`Label::Unknown`] is not a vote.
    pub fn add(&mut self, key: CellKey, label: Label) {
        if let Some(i) = label.index() {
            let c = self.cells.entry(key).or_insert([0; 4]);
            c[i] = c[i].saturating_add(1);
        }
    }

    /// Adds counts to a cell.
    pub(crate) fn add_counts(&mut self, key: CellKey, counts: &Counts) {
        let c = self.cells.entry(key).or_insert([0; 4]);
        for (a, b) in c.iter_mut().zip(counts) {
            *a = a.saturating_add(*b);
        }
    }

    /// Sums another vote map into this one (same resolution).
    pub fn merge(&mut self, other: &LabelVotes) -> Result<()> {
        if other.resolution != self.resolution {
            return Err(Error::invalid(
                "vote map merge",
                format!(
                    "resolutions {} m and {} m differ",
                    self.resolution, other.resolution
                ),
            ));
        }
        for (k, c) in &other.cells {
            self.add_counts(*k, c);
        }
        Ok(())
    }

    /// The votes of cell `key`, if it has any.
    pub fn get(&self, key: CellKey) -> Option<&Counts> {
        self.cells.get(&key)
    }

    /// Cells with votes.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether no cell has votes.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// All cells and counts, sorted by key.
    pub fn to_sorted_vec(&self) -> Vec<(CellKey, Counts)> {
        let mut v: Vec<_> = self.cells.iter().map(|(k, c)| (*k, *c)).collect();
        v.sort_unstable_by_key(|(k, _)| *k);
        v
    }

    /// The label with the most votes in a cell (ties: the lower index).
    pub fn majority(&self, key: CellKey) -> Option<Label> {
        let c = self.cells.get(&key)?;
        let (i, n) = c
            .iter()
            .enumerate()
            .max_by_key(|(i, n)| (**n, std::cmp::Reverse(*i)))?;
        (*n > 0).then_some(Label::DECIDED[i])
    }
}

/// The grid's elevation surface as a parry3d height field (unobserved cells are holes).
pub struct ElevationSurface {
    hf: HeightField,
    resolution: f64,
    /// Map-frame position of the height field's local origin (its centre; z of height 0).
    centre: Point3<f64>,
}

impl std::fmt::Debug for ElevationSurface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ElevationSurface")
            .field("resolution", &self.resolution)
            .field("centre", &self.centre)
            .field("vertices", &(self.hf.nrows(), self.hf.ncols()))
            .finish()
    }
}

impl ElevationSurface {
    /// Vertices at the grid's cell centres with their mean elevations. Errors when fewer than
    /// one quad of four observed cells exists.
    pub fn from_grid(grid: &RollingGrid) -> Result<Self> {
        let n = grid.size();
        let res = grid.resolution();
        let o = grid.origin();
        let z: Vec<Option<f64>> = (0..n * n)
            .map(|i| {
                let k = CellKey::new(o.x + (i % n) as i64, o.y + (i / n) as i64);
                grid.cell(k).and_then(|_| {
                    let (x, y) = grid.centre_of(k);
                    grid.elevation_at(x, y)
                })
            })
            .collect();
        let known: Vec<f64> = z.iter().flatten().copied().collect();
        if known.is_empty() {
            return Err(Error::invalid(
                "elevation surface",
                "the grid has no observed cell",
            ));
        }
        let z0 = known.iter().sum::<f64>() / known.len() as f64;
        // Row index i advances along parry z (= map y), column j along parry x (= map x);
        // parry's Array2 is column-major: element (i, j) is at i + j·n. `z` is indexed y·n + x.
        let heights: Vec<f32> = (0..n * n)
            .map(|e| {
                let (i, j) = (e % n, e / n);
                z[i * n + j].map_or(0.0, |v| (v - z0) as f32)
            })
            .collect();
        let span = (n - 1) as f64 * res;
        let scale = parry3d::math::Vector::new(span as f32, 1.0, span as f32);
        let mut hf = HeightField::new(parry3d::utils::Array2::new(n, n, heights), scale);
        let mut any = false;
        for i in 0..n - 1 {
            for j in 0..n - 1 {
                let ok = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)]
                    .iter()
                    .all(|(a, b)| z[a * n + b].is_some());
                if ok {
                    any = true;
                } else {
                    hf.set_cell_status(i, j, HeightFieldCellStatus::CELL_REMOVED);
                }
            }
        }
        if !any {
            return Err(Error::invalid(
                "elevation surface",
                "no four neighbouring observed cells: nothing a ray could hit",
            ));
        }
        let (x0, y0) = grid.centre_of(o);
        Ok(ElevationSurface {
            hf,
            resolution: res,
            centre: Point3::new(x0 + span / 2.0, y0 + span / 2.0, z0),
        })
    }

    /// Distance along the unit ray `dir` from `origin` (map frame) to the first hit, up to
    /// `max_range`.
    pub fn cast(&self, origin: &Point3<f64>, dir: &Vector3<f64>, max_range: f64) -> Option<f64> {
        let o = origin - self.centre;
        let ray = Ray::new(
            parry3d::math::Vector::new(o.x as f32, o.z as f32, o.y as f32),
            parry3d::math::Vector::new(dir.x as f32, dir.z as f32, dir.y as f32),
        );
        self.hf
            .cast_local_ray(&ray, max_range as f32, true)
            .map(|t| t as f64)
    }

    /// Cell edge length, metres.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }
}

/// What a pixel ray without a 3-D point is cast against.
#[derive(Debug, Clone, Copy)]
pub enum RayTarget<'a> {
    /// The grid's elevation surface.
    Terrain(&'a ElevationSurface),
    /// A level water surface at this height (map frame).
    WaterLevel(f64),
    /// Whichever of the two the ray meets first.
    TerrainAndWater(&'a ElevationSurface, f64),
}

impl RayTarget<'_> {
    /// Distance to the first hit along a unit ray, up to `max_range`.
    pub fn cast(&self, origin: &Point3<f64>, dir: &Vector3<f64>, max_range: f64) -> Option<f64> {
        let plane = |z: f64| {
            let t = (z - origin.z) / dir.z;
            (dir.z != 0.0 && t > 0.0 && t <= max_range).then_some(t)
        };
        match *self {
            RayTarget::Terrain(s) => s.cast(origin, dir, max_range),
            RayTarget::WaterLevel(z) => plane(z),
            RayTarget::TerrainAndWater(s, z) => match (s.cast(origin, dir, max_range), plane(z)) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            },
        }
    }
}

/// Projection parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectConfig {
    /// Rays stop after this many metres.
    pub max_range: f64,
    /// Use every `stride`-th pixel in x and y (1 = all).
    pub stride: usize,
}

impl Default for ProjectConfig {
    fn default() -> Self {
        ProjectConfig {
            max_range: 50.0,
            stride: 1,
        }
    }
}

/// Where each pixel's vote went.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ProjectStats {
    /// Pixels placed through a valid point of the stereo cloud.
    pub via_point: u64,
    /// Pixels placed by a ray march through the elevation surface.
    pub via_ray: u64,
    /// Rays that met nothing within range (sky, holes, beyond the grid).
    pub no_hit: u64,
    /// Pixels labelled unknown.
    pub unknown: u64,
}

impl ProjectStats {
    fn merge(mut self, o: ProjectStats) -> Self {
        self.via_point += o.via_point;
        self.via_ray += o.via_ray;
        self.no_hit += o.no_hit;
        self.unknown += o.unknown;
        self
    }
}

/// Projects a camera's label images into map cells; holds the camera's pixel rays so that
/// undistortion is paid once.
#[derive(Debug, Clone)]
pub struct Projector {
    camera: CameraModel,
    /// Unit rays in the optical frame, row-major.
    rays: Vec<Option<Vector3<f64>>>,
    cfg: ProjectConfig,
}

impl Projector {
    /// A projector for `camera`. Fails unless `max_range` is finite and positive and `stride`
    /// at least 1.
    pub fn new(camera: CameraModel, cfg: ProjectConfig) -> Result<Self> {
        if !(cfg.max_range.is_finite() && cfg.max_range > 0.0) || cfg.stride == 0 {
            return Err(Error::invalid("projection config", format!("{cfg:?}")));
        }
        let rays = camera.pixel_rays();
        Ok(Projector { camera, rays, cfg })
    }

    /// The camera projected.
    pub fn camera(&self) -> &CameraModel {
        &self.camera
    }

    /// Votes of one labelled image taken from `cam_to_map` (optical frame → map frame).
    ///
    /// `stereo`, if given, is an organized cloud in the camera's optical frame of the image's
    /// size or a whole-factor downsample of it (element (r, c) covers pixels k·r..k·r+k,
    /// k·c..k·c+k). Pixels whose element is a valid point vote for that point's cell; the
    /// others are cast against `target` if given, else they do not vote.
    pub fn project(
        &self,
        labels: &LabelImage,
        cam_to_map: &Pose,
        stereo: Option<&PointCloud>,
        target: Option<&RayTarget>,
        resolution: f64,
    ) -> Result<(LabelVotes, ProjectStats)> {
        let (w, h) = (self.camera.width, self.camera.height);
        labels.validate()?;
        if labels.width != w || labels.height != h {
            return Err(Error::invalid(
                "label image",
                format!(
                    "{} × {} for a {w} × {h} camera",
                    labels.width, labels.height
                ),
            ));
        }
        if !pose_is_finite(cam_to_map) {
            return Err(Error::invalid("camera pose", format!("{cam_to_map}")));
        }
        let k = match stereo {
            None => 0,
            Some(c) => {
                let k = w.checked_div(c.cols).unwrap_or(0);
                if !c.is_organized() || k == 0 || c.cols * k != w || c.rows * k != h {
                    return Err(Error::invalid(
                        "stereo cloud",
                        format!(
                            "{} × {} points is not the {w} × {h} image or a whole-factor downsample of it",
                            c.cols, c.rows
                        ),
                    ));
                }
                k
            }
        };
        let empty = LabelVotes::new(resolution)?;
        let origin = Point3::from(cam_to_map.translation.vector);
        let s = self.cfg.stride;
        let rows: Vec<usize> = (0..h).step_by(s).collect();
        let (votes, stats) = rows
            .par_chunks(8)
            .map(|ys| {
                let mut v = empty.clone();
                let mut st = ProjectStats::default();
                for &y in ys {
                    for x in (0..w).step_by(s) {
                        let i = y * w + x;
                        let l = labels.data[i];
                        if l == Label::Unknown {
                            st.unknown += 1;
                            continue;
                        }
                        if let Some(c) = stereo {
                            let e = (y / k) * c.cols + x / k;
                            if c.is_valid(e) {
                                let p = cam_to_map * point_of(c, e);
                                v.add(key_of(resolution, p.x, p.y), l);
                                st.via_point += 1;
                                continue;
                            }
                        }
                        let Some(t) = target else { continue };
                        let Some(r) = self.rays[i] else {
                            st.no_hit += 1;
                            continue;
                        };
                        let d = cam_to_map.rotation * r;
                        match t.cast(&origin, &d, self.cfg.max_range) {
                            Some(tt) => {
                                let p = origin + d * tt;
                                v.add(key_of(resolution, p.x, p.y), l);
                                st.via_ray += 1;
                            }
                            None => st.no_hit += 1,
                        }
                    }
                }
                (v, st)
            })
            .reduce(
                || (empty.clone(), ProjectStats::default()),
                |(mut a, sa), (b, sb)| {
                    a.merge(&b).expect("same resolution");
                    (a, sa.merge(sb))
                },
            );
        Ok((votes, stats))
    }
}

fn point_of(c: &PointCloud, i: usize) -> Point3<f64> {
    let p = c.xyz[i];
    Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

/// Labels 3-D points (e.g. a lidar scan) from an image: each valid point in front of the
/// camera that projects inside the image takes its pixel's label. `cloud_to_cam` maps the
/// cloud's frame to the camera's optical frame. Returns the label per point (`None`: not in
/// the image) and the votes for the points' map cells (via the cloud's `frame_to_map`).
///
/// No occlusion test is made: a point hidden from the camera by something nearer (the
/// camera and the lidar are not at the same place) still takes the label of the pixel it
/// falls on.
pub fn label_points(
    labels: &LabelImage,
    camera: &CameraModel,
    cloud: &PointCloud,
    cloud_to_cam: &Pose,
    resolution: f64,
) -> Result<(Vec<Option<Label>>, LabelVotes)> {
    labels.validate()?;
    if labels.width != camera.width || labels.height != camera.height {
        return Err(Error::invalid(
            "label image",
            format!(
                "{} × {} for a {} × {} camera",
                labels.width, labels.height, camera.width, camera.height
            ),
        ));
    }
    if !pose_is_finite(cloud_to_cam) {
        return Err(Error::invalid(
            "cloud to camera pose",
            format!("{cloud_to_cam}"),
        ));
    }
    let mut votes = LabelVotes::new(resolution)?;
    let per_point: Vec<Option<Label>> = (0..cloud.len())
        .into_par_iter()
        .map(|i| {
            if !cloud.is_valid(i) {
                return None;
            }
            let [u, v] = camera.project(&(cloud_to_cam * point_of(cloud, i)))?;
            let (x, y) = (u.round(), v.round());
            if x < 0.0 || y < 0.0 || x >= camera.width as f64 || y >= camera.height as f64 {
                return None;
            }
            Some(labels.get(x as usize, y as usize))
        })
        .collect();
    for (i, l) in per_point.iter().enumerate() {
        if let Some(l) = l {
            let p = cloud.point_in_map(i);
            votes.add(key_of(resolution, p.x, p.y), *l);
        }
    }
    Ok((per_point, votes))
}

#[cfg(test)]
mod tests;
