//! Water bodies: which cells are water, where the water surface is, how deep it is, and
//! what that means for a vehicle.
//!
//! The cues leave per-cell evidence in the map ([`crate::grid::Evidence`]); this stage turns
//! it into bodies of water with a surface, a depth, an area and a volume, and the hazard map
//! ([`crate::hazard::HazardMap::from_tiles`]) into one class and hazard per cell. The knobs
//! are the fields of [`WaterConfig`] and [`Vehicle`](crate::hazard::Vehicle), each named below with its default in
//! parentheses. Measured results are in docs/accuracy.md and docs/limits.md.
//!
//! Exports: [`find_bodies`] with its [`WaterConfig`]; what it finds, [`WaterBody`] (its
//! [`DepthStats`], the [`SurfaceSource`] of its level); and a body's water surface
//! ([`Surface`], of model [`SurfaceModel`], fitted to [`ShoreSample`]s; [`V`] is a vertex of
//! its triangulation).
//!
//! ## 1. Bodies: connected components with hysteresis
//!
//! Each cell's fused water probability `p = Evidence::water_probability(&Fusion)` is read.
//! Cells with `p ≥ p_high` (0.8) seed a body; a body grows through 8-connected neighbours
//! with `p ≥ p_low` (0.5). With the default fusion one cue at its cap gives
//! p = 100/119 ≈ 0.84 (prior 5 %, cap ln 100), so one well-supported cue can seed a body;
//! weakly supported cells (one reflection ray: p ≈ 0.68) only join a body that is already
//! there, so isolated weak evidence (one dark patch, one stray reflection) never becomes
//! water while the faint fringe of a real pond does. A cell with a refraction-corrected
//! bottom return also joins a neighbouring body whatever its `p`: a return from below the
//! water level is water above it, but one return gives only p ≈ 0.30, and a lidar sees
//! most of a stream's bed through one return per cell.
//!
//! But a bottom return says "water" only if it lies below the water: the cue judged it
//! against the last ground its scan line walked, which behind a kerb is the kerb's top, so
//! the pavement behind a kerb is "bed" a kerb's height under a "surface" that is not there.
//! Once a body's surface is fitted to its shore, a cell whose bottom returns lie no more
//! than `min_bottom_depth_m` below it (`None`: twice the configured lidar's range noise σ0,
//! or that of [`crate::grid::RangeNoise::LIDAR`] without one; what dry ground at the
//! water's level gives) keeps its depth but loses the bottom returns as evidence, and the
//! bodies are found again without it, until every bottom return left in a body lies deeper
//! (at most eight passes). A body that stood on such returns alone is gone; one with other
//! evidence stays, with its shallow cells. The price: bed returns at a body's edge that
//! its fitted surface does not stand above by that margin lose their evidence too. Bodies
//! smaller than `min_body_area_m2` (0.25 m², half a metre square: no wheel drops into
//! less, and single cells of false colour votes are that small) are dropped. A body is a
//! set of cells, so dry islands inside it (holes) and bays stay exactly as observed.
//!
//! **Ids** are stable as more of a body is seen: [`find_bodies`] takes the previous
//! snapshot's bodies; a new body that overlaps earlier ones keeps the id of the largest of
//! them (by area), so a body that grows, or two that merge, keep the id of their largest
//! ancestor. If a body splits, the part with the largest overlap keeps the id and the others
//! get new ones. New ids count up from the largest id seen so far.
//!
//! ## 2. Shore elevation, robust to occlusion
//!
//! The water surface of a pond is level with its shoreline. The shore samples of a body are
//! the observed dry cells 4-adjacent to it: the cells right at the water's edge, whose
//! terrain meets the water. A cell with bottom returns is never a shore sample: it is under
//! water, and its elevation is the bed's. The shore's elevations are not all trustworthy: a
//! bush, a rock or tall grass on the near shore is seen *above* the ground, and the ground
//! behind it is not seen at all (paper §2.2). Raised samples are never too low, only too
//! high, so the filter is one-sided: a sample is dropped when it stands more than
//! `occluder_height_m` (10 cm) above the `shore_quantile` (25 %) quantile of the elevations
//! within `shore_radius_m` (1.5 m) of it: the other shore samples and the dry, reliably
//! measured ground cells there. A local low quantile rather than the body's global minimum,
//! because a stream's shore legitimately descends along its course, and a local quantile
//! rather than the local minimum, because one noisy low cell must not decide. A 1 m bush
//! covering a third of the shore within 1.5 m leaves the quantile on the ground, and is
//! dropped. The ground beside the shore is in the reference because a bush seen from the
//! vehicle hides the water behind it: every shore cell along it is bush, so shore samples
//! alone put the level high.
//!
//! A second one-sided test reads the shore across the water: a water surface slopes by
//! at most `max_surface_slope` (5 %: a steep mountain stream), so the water beside a shore
//! sample cannot stand higher than another shore sample of the same body a distance d
//! away plus `max_surface_slope`·d, or it would spill there. A sample more than
//! `occluder_height_m` above that bound (over the samples within `spill_radius_m`, 4 m) is
//! not the waterline and is dropped. This is what removes the top of a bank that faces
//! away from the vehicle: the bank hides the water's edge below it, so its shore cells are
//! the bank top, and the ground around them is bank top too, which the first test reads as
//! the local level; the far bank, seen down to its waterline, bounds them.
//!
//! A shore cell's centre lies up to a cell beyond the water's edge, so on a bank rising at
//! g it stands up to g·res above the water, g·res/2 on average: 5 cm on a 45° bank with
//! 10 cm cells. Each shore sample is moved down by half a cell of the rise behind it: the
//! mean, over the directions with water on one side of the cell and a reliably measured dry
//! cell on the other, of their elevation difference per cell, clamped to
//! `0..=max_bank_slope` (1: 45°, about the angle of repose of soil and gravel; a bush
//! behind the shore rises faster, and is not a bank; 0 turns the correction off). Flat
//! ground beside the water gets no correction.
//!
//! A dry hole in a body smaller than the smallest body (`min_body_area_m2`; 25 cells of
//! 10 cm) is not shore. Clear water shows its bed: a lidar return from the bed at grazing
//! incidence appears n·d·cos θa/cos θw below the surface, inside the ground gate, and
//! a cell seen only that way is dry and *below* the water; such cells lie scattered through
//! a clear channel. An island that small says little about the level anyway: the body's
//! outer shore does.
//!
//! Only reliably measured shore cells count when there are at least `min_shore_samples`
//! (6) of them: a cell whose elevation σ bound (every point's range error taken as
//! vertical, `CellStats::range_bound_std_m`) exceeds `shore_max_std_m` (5 cm) is left out.
//! Such cells are mostly far ones seen by a few stereo points, whose range noise grows with
//! the square of the range, and they can far outnumber the reliable cells at the water's
//! edge. With fewer reliable cells than that, every shore cell counts, weighted by the
//! inverse of its elevation variance (σ floored at 1 cm): the level is their weighted
//! median, and such a shore makes no Delaunay surface. Counted equally, noisy stereo cells
//! would outvote a single lidar cell at the water's edge.
//!
//! Where the shore is poorly seen (fewer than `min_shore_samples` kept), the shore may lie
//! across water that no sensor measured: a stream seen from afar can be a sky reflection in
//! the camera along its near half, its near shore hidden by the near bank, its far half
//! giving neither returns nor labels, while the lidar measures the far bank's waterline
//! beyond. The *far shore* is, from each body cell in each of the four directions, the
//! first reliably measured dry cell within `shore_radius_m` past at least one cell that is
//! unobserved or unreliable. It passes the occluder and spill tests, and one more: a sample
//! more than `occluder_height_m` below the median of the others within `shore_radius_m` is
//! dropped, because the spill test takes the lowest sample as the truth and, across an
//! unseen channel, some cells of the far bank lie well below the water (returns placed
//! wrongly), and one of them would bound every good sample away. Without a far shore, the
//! water-level samples the cues measured with their evidence (`Evidence::level_mm`: the
//! level of the last ground a no-return beam or reflection ray was cast from) are used
//! instead, one per water cell, at the cell centre: upper bounds, as that ground stands at
//! or above the water. Without either, the body's own cell elevations.
//!
//! A shore with enough kept samples that is neither level nor a surface a triangulation
//! predicts (section 3: the fit falls back to its lowest samples), or level only within
//! its cells' own noise, or a triangulated surface that some of the body's cells lie more
//! than `shore_radius_m` outside of (beyond its samples' hull the surface is the hull's
//! edge carried on level, a guess), takes the far shore too, where there is one: such a
//! shore can be one stretch of a sloping stream, seen where the labels reached its bank,
//! and a level from that stretch is metres of stream off elsewhere
//! (`SurfaceSource::ShoreAndFarShore`).
//!
//! ## 3. Surface: level plane, or constrained Delaunay where the shore is not level
//!
//! The level plane is the median of the kept samples, and its residual is their RMS about
//! it. If that residual is at most `level_residual_m` (2 cm), the shore agrees and the body
//! is level (a pond). It is level too when the spread read robustly (1.4826 times the
//! median absolute deviation, the RMS of normal noise) is that small and the shore's lower
//! quarter (`shore_quantile`) stands within it of the median too: a few raised samples the
//! occluder test kept (the foot of a bush on the shore) do not make a pond a stream, while
//! low ones would hold the water below the median. Otherwise (a stream down a slope) the
//! surface interpolates the shore: a constrained Delaunay triangulation (spade,
//! bulk-loaded) of the samples, with a constraint edge between every two 8-adjacent shore
//! samples so that triangles follow the shoreline instead of cutting across land; crossing
//! diagonals are skipped. Water cells are given barycentric interpolation in their
//! triangle; outside the triangulation, the surface at the nearest point of its hull, so
//! that it is continuous across the hull and follows the shore along it (not the nearest
//! sample: where a stream's near bank is hidden the hull runs down the middle of the
//! channel, and the near half would take one sample's height per stretch, with steps
//! between stretches).
//!
//! The vertices are not the samples as measured but each at the median of the kept samples
//! within `vertex_median_radius_m` (1.5 m) of it (`local_medians` in `water/surface.rs`; 0
//! keeps them as measured): a triangulation carries each vertex's own error to the water
//! around it, and across a stream seen from one bank, to the whole near half of the channel.
//! Single shore cells stand well off the water: a waterline cell mostly under water, seen
//! through it at grazing incidence (low), or the top of a short stretch of bank (high). The
//! median of a one-sided neighbourhood, within the radius of a shore's end, stands off by up
//! to the slope times half the radius (2.25 cm on a 3 % stream).
//!
//! The Delaunay model must earn its place: its hold-out residual (every other sample
//! predicted from the triangulation of the others) must beat the level's, or the body
//! stays level. Both residuals are reported per body. Degenerate samples (collinear,
//! duplicates, fewer than three) cannot be triangulated and keep the level. A body kept
//! level this way (its shore neither level nor smooth) takes the level of its lowest
//! samples, the median of those within `occluder_height_m` of the `shore_quantile`
//! quantile, not the median of all: water cannot stand above its lowest shore, and what
//! raises the others (a shore that is all bush for a metre, a bank top where the water's
//! edge was hidden) only ever raises them. (spade's natural-neighbour interpolation exists
//! only for unconstrained triangulations; the constraints were worth more than the
//! smoother interpolant.)
//!
//! ## 4. Depth, area, volume
//!
//! A water cell's depth is the mean of its refraction-corrected bottom returns below the
//! body's surface at the cell; without any it is **unknown** (NaN in the map), never a
//! guess. The lidar cue corrected each return against the level it knew then (the local
//! ground it was cast from, often a bank top well above the water), and at grazing
//! incidence the depth moves by `cos θₜ/(n cos θᵢ)` (up to 4 and more) per metre of level
//! error. The correction is linear in the level ([`crate::optics::bottom_depth_gain`]), so
//! the evidence keeps the gain-weighted sums that move a depth exactly onto any level, and
//! this stage evaluates it at the fitted surface; what error remains in a depth is the
//! surface's own error times the gain. Area is the number of cells times the cell area.
//! The volume is given only when every cell's depth is known (`volume_m3: None`
//! otherwise, with the known and unknown-depth areas reported): it is the volume of the
//! closed water mesh (`water/mesh.rs`) between the surface and the bottom, where the bottom
//! interpolates the measured depths at the cell centres and comes up to depth zero at the
//! shoreline, as real water does.
//!
//! ## 5. Hazards
//!
//! Water with every bottom return's depth known and at most `fording_depth_m` (0.3 m) is
//! shallow (hazard 1); deeper, or unknown, is deep (hazard 2): unknown is not safe. Dry
//! cells are geometric obstacles (hazard 3) when the step to an 8-neighbour exceeds
//! `max_step_m` (0.25 m; the upper side of the step is class obstacle) or the slope of the
//! local 3 × 3 fit exceeds `max_slope_deg` (25°).

mod body;
mod mesh;
mod search;
mod surface;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::grid::CellKey;

pub use search::find_bodies;
// The water stage's seam for other map stores (the rolling window, a region of tiles):
// what it reads of a cell, and the searches over those cells.
pub(crate) use search::{
    bodies_from, bodies_in_part, find_bodies_and_void, seeds_body, CellInfos, Info,
};
pub use surface::{ShoreSample, Surface, SurfaceModel, V};
// A body's closed water mesh, which `water.ply` writes.
pub(crate) use mesh::body_mesh;

/// Parameters of body extraction and surface fitting (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WaterConfig {
    /// A cell with water probability at least this seeds a body.
    pub p_high: f64,
    /// A cell with water probability at least this joins a neighbouring body.
    pub p_low: f64,
    /// Bodies smaller than this are dropped (m²).
    pub min_body_area_m2: f64,
    /// Neighbourhood of the occluder test on shore samples (m).
    pub shore_radius_m: f64,
    /// Quantile of the neighbourhood taken as the local shore level (0..1).
    pub shore_quantile: f64,
    /// A shore sample this far above the local shore level is an occluder (m).
    pub occluder_height_m: f64,
    /// Steepest water surface (rise over run) the spill test allows between shore samples.
    pub max_surface_slope: f64,
    /// Shore samples the spill test compares within this distance (m).
    pub spill_radius_m: f64,
    /// Shore cells whose elevation σ bound ([`crate::grid::CellStats::range_bound_std_m`])
    /// exceeds this are left out when enough others remain (m).
    pub shore_max_std_m: f64,
    /// Fewer kept shore samples than this: use the cues' water-level samples.
    pub min_shore_samples: usize,
    /// Largest RMS of the shore about its median for a level surface (m); also the largest
    /// robust spread (1.4826 × the median absolute deviation) of a shore with a few raised
    /// samples (see the module documentation, section 3).
    pub level_residual_m: f64,
    /// Steepest bank (rise over run) whose slope moves a shore sample down to the water's
    /// edge; 0 turns the correction off.
    pub max_bank_slope: f64,
    /// A Delaunay surface's vertices are its samples at the median of the samples within
    /// this distance (m); 0 keeps them as measured.
    pub vertex_median_radius_m: f64,
    /// A cell's bottom returns are evidence of water only where they lie more than this
    /// below the surface of the body found (m): a return within the lidar's noise of the
    /// water level is what dry ground at that level gives. `None`: twice the configured
    /// lidar's range noise (`σ0`), or of [`crate::grid::RangeNoise::LIDAR`] without one.
    pub min_bottom_depth_m: Option<f64>,
}

impl Default for WaterConfig {
    fn default() -> Self {
        WaterConfig {
            p_high: 0.8,
            p_low: 0.5,
            min_body_area_m2: 0.25,
            shore_radius_m: 1.5,
            shore_quantile: 0.25,
            occluder_height_m: 0.10,
            max_surface_slope: 0.05,
            spill_radius_m: 4.0,
            shore_max_std_m: 0.05,
            min_shore_samples: 6,
            level_residual_m: 0.02,
            max_bank_slope: 1.0,
            vertex_median_radius_m: 1.5,
            min_bottom_depth_m: None,
        }
    }
}

fn check(what: &str, ok: bool, v: impl std::fmt::Display, must: &str) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(Error::invalid(what, format!("{v} {must}")))
    }
}

impl WaterConfig {
    /// `shore_radius_m` in whole cells of size `resolution` (at least 1).
    pub(crate) fn shore_radius_cells(&self, resolution: f64) -> i64 {
        (self.shore_radius_m / resolution).ceil().max(1.0) as i64
    }

    /// Checks every threshold's range; the error names the bad field.
    pub fn validate(&self) -> Result<()> {
        let prob = |p: f64| p > 0.0 && p < 1.0;
        check(
            "water.p_high",
            prob(self.p_high),
            self.p_high,
            "must lie strictly between 0 and 1",
        )?;
        check(
            "water.p_low",
            prob(self.p_low) && self.p_low <= self.p_high,
            self.p_low,
            "must lie strictly between 0 and 1 and not above p_high",
        )?;
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        let pos = |v: f64| v.is_finite() && v > 0.0;
        check(
            "water.min_body_area_m2",
            nonneg(self.min_body_area_m2),
            self.min_body_area_m2,
            "must be a finite number ≥ 0",
        )?;
        check(
            "water.shore_radius_m",
            pos(self.shore_radius_m),
            self.shore_radius_m,
            "must be a finite number > 0",
        )?;
        check(
            "water.shore_quantile",
            (0.0..=1.0).contains(&self.shore_quantile),
            self.shore_quantile,
            "must lie in 0..1",
        )?;
        check(
            "water.occluder_height_m",
            pos(self.occluder_height_m),
            self.occluder_height_m,
            "must be a finite number > 0",
        )?;
        check(
            "water.max_surface_slope",
            nonneg(self.max_surface_slope),
            self.max_surface_slope,
            "must be a finite number ≥ 0",
        )?;
        check(
            "water.spill_radius_m",
            nonneg(self.spill_radius_m),
            self.spill_radius_m,
            "must be a finite number ≥ 0",
        )?;
        check(
            "water.shore_max_std_m",
            pos(self.shore_max_std_m),
            self.shore_max_std_m,
            "must be a finite number > 0",
        )?;
        check(
            "water.level_residual_m",
            nonneg(self.level_residual_m),
            self.level_residual_m,
            "must be a finite number ≥ 0",
        )?;
        check(
            "water.max_bank_slope",
            nonneg(self.max_bank_slope),
            self.max_bank_slope,
            "must be a finite number ≥ 0",
        )?;
        check(
            "water.vertex_median_radius_m",
            nonneg(self.vertex_median_radius_m),
            self.vertex_median_radius_m,
            "must be a finite number ≥ 0",
        )?;
        let d = self.min_bottom_depth_m;
        check(
            "water.min_bottom_depth_m",
            d.is_none_or(nonneg),
            d.map_or("none".to_string(), |d| d.to_string()),
            "must be a finite number ≥ 0",
        )
    }

    /// [`Self::min_bottom_depth_m`], or its default without a lidar's noise.
    fn min_bottom_depth(&self) -> f64 {
        self.min_bottom_depth_m
            .unwrap_or(2.0 * crate::grid::RangeNoise::LIDAR.sigma0)
    }
}

/// Where a body's surface samples came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SurfaceSource {
    /// Dry cells along the water's edge.
    Shore,
    /// Dry cells across unobserved water from the body (its own shore was poorly seen).
    FarShore,
    /// Both: a shore that was neither level nor a smooth surface, with the far shore
    /// added (a stretch of a sloping stream seen in one place).
    ShoreAndFarShore,
    /// The cues' water-level samples (the shore was poorly seen).
    WaterLevels,
    /// The body's own cell elevations (nothing better).
    CellElevations,
}

/// Depth knowledge of a body.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DepthStats {
    /// Cells with at least one bottom return, and without.
    pub known_cells: usize,
    /// Cells with no bottom return.
    pub unknown_cells: usize,
    /// Area of the cells with a bottom return, square metres.
    pub known_area_m2: f64,
    /// Area of the cells without, square metres.
    pub unknown_area_m2: f64,
    /// Mean and greatest of the known cell depths (m).
    pub mean_m: Option<f64>,
    /// Greatest known cell depth, metres.
    pub max_m: Option<f64>,
}

/// One water body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WaterBody {
    /// Identifier, kept from frame to frame for the body that inherits most of a previous
    /// body's cells (see the module documentation, "Ids").
    pub id: u32,
    /// Its cells, sorted.
    pub cells: Vec<CellKey>,
    /// Area of its cells, square metres.
    pub area_m2: f64,
    /// Volume of the closed water mesh; `None` when any cell's depth is unknown.
    pub volume_m3: Option<f64>,
    /// What is known of its depth.
    pub depth: DepthStats,
    /// Dry shore cells found, and those kept after the occluder test.
    pub shore_samples: usize,
    /// Shore cells kept after the occluder test.
    pub shore_samples_kept: usize,
    /// Samples the surface was fitted to, and where they came from.
    pub surface_samples: usize,
    /// Where the surface samples came from.
    pub surface_source: SurfaceSource,
    /// The fitted water surface (map z, metres).
    pub surface: SurfaceModel,
    /// RMS of the samples about the level plane (m).
    pub level_residual_m: f64,
    /// Hold-out RMS of the Delaunay surface, when it was tried (m).
    pub delaunay_residual_m: Option<f64>,
    /// Per-cell depth, parallel to `cells` (m; NaN unknown).
    pub cell_depth_m: Vec<f32>,
}

impl WaterBody {
    /// The `report.json` record of the body (everything but the per-cell lists).
    pub fn report(&self) -> serde_json::Value {
        let (surface_z, vertices) = match &self.surface {
            SurfaceModel::Level { z } => (Some(*z), None),
            SurfaceModel::Delaunay { samples, .. } => (None, Some(samples.len())),
        };
        serde_json::json!({
            "id": self.id,
            "cells": self.cells.len(),
            "area_m2": self.area_m2,
            "volume_m3": self.volume_m3,
            "depth": self.depth,
            "shore_samples": self.shore_samples,
            "shore_samples_kept": self.shore_samples_kept,
            "surface_samples": self.surface_samples,
            "surface_source": self.surface_source,
            "surface_model": self.surface.name(),
            "surface_z": surface_z,
            "delaunay_vertices": vertices,
            "level_residual_m": self.level_residual_m,
            "delaunay_residual_m": self.delaunay_residual_m,
        })
    }
}

/// The `report.json` record of all bodies.
pub(crate) fn bodies_report(bodies: &[WaterBody]) -> serde_json::Value {
    serde_json::Value::Array(bodies.iter().map(WaterBody::report).collect())
}

#[cfg(test)]
mod tests;
