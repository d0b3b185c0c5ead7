//! Water bodies: which cells are water, where the water surface is, how deep it is, and
//! what that means for a vehicle.
//!
//! The cues leave per-cell evidence in the map ([`crate::grid::Evidence`]); this stage turns
//! it into bodies of water with a surface, a depth, an area and a volume, and the hazard map
//! ([`crate::hazard::HazardMap::from_tiles`]) into one class and hazard per cell. The knobs
//! are the fields of [`WaterConfig`] and [`Vehicle`], each named below with its default in
//! parentheses. Measured results are in docs/accuracy.md and docs/limits.md.
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
//! within `vertex_median_radius_m` (1.5 m) of it ([`surface::local_medians`]; 0 keeps them
//! as measured): a triangulation carries each vertex's own error to the water around it,
//! and across a stream seen from one bank, to the whole near half of the channel. Single
//! shore cells stand well off the water: a waterline cell mostly under water, seen through
//! it at grazing incidence (low), or the top of a short stretch of bank (high). The median
//! of a one-sided neighbourhood, within the radius of a shore's end, stands off by up to
//! the slope times half the radius (2.25 cm on a 3 % stream).
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
//! closed water mesh ([`mesh`]) between the surface and the bottom, where the bottom
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

pub mod mesh;
pub mod surface;

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet, VecDeque};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::grid::{centre_of, CellKey, CellStats, Fusion, FusionLogs, TileMap};

pub use surface::{ShoreSample, Surface, SurfaceModel};

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

/// What the vehicle can drive through.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Vehicle {
    /// Deepest water the vehicle may ford (m).
    pub fording_depth_m: f64,
    /// Highest step between neighbouring cells it can climb (m).
    pub max_step_m: f64,
    /// Steepest slope it can drive (degrees).
    pub max_slope_deg: f64,
}

impl Default for Vehicle {
    fn default() -> Self {
        Vehicle {
            fording_depth_m: 0.3,
            max_step_m: 0.25,
            max_slope_deg: 25.0,
        }
    }
}

impl Vehicle {
    /// Checks that the depth and step are finite and non-negative (the step positive) and the
    /// slope strictly between 0 and 90 degrees; the error names the bad field.
    pub fn validate(&self) -> Result<()> {
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        check(
            "vehicle.fording_depth_m",
            nonneg(self.fording_depth_m),
            self.fording_depth_m,
            "must be a finite number ≥ 0",
        )?;
        check(
            "vehicle.max_step_m",
            self.max_step_m.is_finite() && self.max_step_m > 0.0,
            self.max_step_m,
            "must be a finite number > 0",
        )?;
        check(
            "vehicle.max_slope_deg",
            self.max_slope_deg > 0.0 && self.max_slope_deg < 90.0,
            self.max_slope_deg,
            "must lie strictly between 0 and 90",
        )
    }
}

/// Everything the water and hazard stage needs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct HazardConfig {
    /// The evidence fusion rule.
    pub fusion: Fusion,
    /// Water body segmentation and surface fitting.
    pub water: WaterConfig,
    /// What the vehicle can drive through.
    pub vehicle: Vehicle,
}

impl HazardConfig {
    /// Checks every part; the error names the bad field.
    pub fn validate(&self) -> Result<()> {
        self.fusion.validate()?;
        self.water.validate()?;
        self.vehicle.validate()
    }

    /// Reads a JSON config; unknown fields are errors naming the file.
    pub fn from_json_file(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let cfg: HazardConfig = serde_json::from_str(&text).map_err(|e| {
            Error::format(
                path,
                format!("line {} column {}", e.line(), e.column()),
                e.to_string(),
            )
        })?;
        cfg.validate()?;
        Ok(cfg)
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
pub fn bodies_report(bodies: &[WaterBody]) -> serde_json::Value {
    serde_json::Value::Array(bodies.iter().map(WaterBody::report).collect())
}

/// The eight neighbours of a cell, as key offsets.
pub(crate) const N8: [(i64, i64); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];
const N4: [(i64, i64); 4] = [(0, -1), (-1, 0), (1, 0), (0, 1)];

/// The key `k` moved by an offset.
pub(crate) fn add(k: CellKey, (dx, dy): (i64, i64)) -> CellKey {
    CellKey::new(k.x + dx, k.y + dy)
}

/// What the water stage reads of a cell.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Info {
    p: f64,
    /// The probability without the bottom returns' term (`p` when there are none).
    p_without_bottom: f64,
    /// Whether the bottom returns count as evidence of water (see
    /// [`WaterConfig::min_bottom_depth_m`]): until a body's surface shows they do not.
    bottom_counts: bool,
    elevation: Option<f64>,
    /// Standard deviation of the elevation estimate (m).
    std: Option<f64>,
    level: Option<f64>,
    depth: Option<Bottom>,
}

/// A cell's bottom returns: their mean depth below a water surface at `z` is `a + gain·z`
/// (see [`crate::grid::Evidence::depth_at_m`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bottom {
    a: f64,
    gain: f64,
}

impl Bottom {
    fn of(ev: &crate::grid::Evidence, z_ref: f64) -> Option<Bottom> {
        let at_ref = ev.depth_at_m(0.0)?;
        let gain = ev.depth_at_m(1000.0)? - at_ref;
        Some(Bottom {
            a: at_ref - gain * z_ref,
            gain,
        })
    }

    /// The mean depth below a surface at `z` (m), never negative: a bottom above the
    /// surface is no water at all.
    fn below(&self, z: f64) -> f64 {
        (self.a + self.gain * z).max(0.0)
    }
}

impl Info {
    /// Whether the cell's bottom returns are evidence of water.
    fn has_bottom_evidence(&self) -> bool {
        self.depth.is_some() && self.bottom_counts
    }

    /// The water probability a body grows by: without the bottom returns once they no
    /// longer count. (`p` itself stays what the evidence says: the occluder test's dry
    /// ground reads it, so that one body's fit never depends on what another's took away.)
    fn p_evidence(&self) -> f64 {
        if self.bottom_counts {
            self.p
        } else {
            self.p_without_bottom
        }
    }

    /// The cell with its bottom returns no longer evidence of water (their depth is still
    /// the cell's depth if other evidence keeps it in a body).
    fn without_bottom_evidence(self) -> Info {
        Info {
            bottom_counts: false,
            ..self
        }
    }
}

/// The cells of `inner` with the bottom evidence of the cells in `void` taken away.
pub(crate) struct WithoutBottom<'a, C> {
    inner: &'a C,
    void: &'a BTreeSet<CellKey>,
}

impl<'a, C> WithoutBottom<'a, C> {
    /// `inner`'s cells, those in `void` without their bottom evidence.
    pub(crate) fn new(inner: &'a C, void: &'a BTreeSet<CellKey>) -> Self {
        WithoutBottom { inner, void }
    }
}

impl<C: CellInfos> CellInfos for WithoutBottom<'_, C> {
    fn get(&self, k: CellKey) -> Option<Info> {
        let i = self.inner.get(k)?;
        Some(if self.void.contains(&k) {
            i.without_bottom_evidence()
        } else {
            i
        })
    }

    fn column(&self, x: i64, ys: std::ops::Range<i64>, mut f: impl FnMut(CellKey, &Info)) {
        self.inner.column(x, ys, |k, i| {
            if self.void.contains(&k) {
                f(k, &i.without_bottom_evidence())
            } else {
                f(k, i)
            }
        })
    }
}

impl Info {
    /// The cell's water probability, as its evidence gives it.
    pub(crate) fn p(&self) -> f64 {
        self.p
    }

    /// Whether a body grows over the cell: water probability (without the bottom returns
    /// once they no longer count) at least `p_low`, or bottom returns that count.
    pub(crate) fn joins(&self, cfg: &WaterConfig) -> bool {
        self.p_evidence() >= cfg.p_low || self.has_bottom_evidence()
    }

    /// The info of an observed cell `c` whose water probability under `logs` is `p`, in a
    /// map of reference height `z_ref`.
    pub(crate) fn of(c: &CellStats, p: f64, logs: &FusionLogs, z_ref: f64) -> Info {
        let p_without_bottom = if c.ev.depth_n > 0 {
            c.ev.water_probability_without_bottom_in(logs)
        } else {
            p
        };
        Info {
            p,
            p_without_bottom,
            bottom_counts: true,
            elevation: c.mean_mm().map(|m| z_ref + m * 1e-3),
            std: c.range_bound_std_m().filter(|s| s.is_finite()),
            level: c.ev.level_mm().map(|mm| z_ref + mm * 1e-3),
            depth: Bottom::of(&c.ev, z_ref),
        }
    }
}

/// Whether a cell of water probability `p` seeds a body (a NaN probability does, as it
/// always has: it is not below `p_high`).
pub(crate) fn seeds_body(p: f64, cfg: &WaterConfig) -> bool {
    p >= cfg.p_high || p.is_nan()
}

/// The cells the body search reads: the [`Info`] of observed cells by key. A tile map's
/// cells are an ordered map of them; the mapper's window reads them from its layers.
pub(crate) trait CellInfos {
    /// The info of the cell `k`, if it was observed.
    fn get(&self, k: CellKey) -> Option<Info>;

    /// Calls `f` for every observed cell of column `x` with a row in `ys`, by increasing
    /// row.
    fn column(&self, x: i64, ys: std::ops::Range<i64>, f: impl FnMut(CellKey, &Info));
}

impl CellInfos for BTreeMap<CellKey, Info> {
    fn get(&self, k: CellKey) -> Option<Info> {
        BTreeMap::get(self, &k).copied()
    }

    fn column(&self, x: i64, ys: std::ops::Range<i64>, mut f: impl FnMut(CellKey, &Info)) {
        for (&k, i) in self.range(CellKey::new(x, ys.start)..CellKey::new(x, ys.end)) {
            f(k, i);
        }
    }
}

/// Connected components with hysteresis over `p`, grown from `seeds` (every cell that
/// seeds a body, in increasing key order): deterministic. Each with the seed it grew from,
/// its smallest.
pub(crate) fn components_seeded(
    cells: &impl CellInfos,
    seeds: impl IntoIterator<Item = CellKey>,
    cfg: &WaterConfig,
) -> Vec<(CellKey, Vec<CellKey>)> {
    let mut seen: BTreeSet<CellKey> = BTreeSet::new();
    let mut out = Vec::new();
    for k in seeds {
        if seen.contains(&k) {
            continue;
        }
        let mut body = vec![k];
        seen.insert(k);
        let mut q = VecDeque::from([k]);
        while let Some(c) = q.pop_front() {
            for d in N8 {
                let n = add(c, d);
                if !seen.contains(&n) && cells.get(n).is_some_and(|i| i.joins(cfg)) {
                    seen.insert(n);
                    body.push(n);
                    q.push_back(n);
                }
            }
        }
        body.sort_unstable();
        out.push((k, body));
    }
    out
}

/// Finds the water bodies of a tile map. `previous` are the bodies of the last snapshot
/// (empty for the first): ids follow the rule in the module documentation.
pub fn find_bodies(
    tiles: &TileMap,
    cfg: &HazardConfig,
    previous: &[WaterBody],
) -> Result<Vec<WaterBody>> {
    let observed: Vec<(CellKey, CellStats)> = tiles.observed().collect();
    Ok(find_bodies_and_void(tiles, &observed, cfg, previous)?.0)
}

/// [`find_bodies`] given the tile map's observed cells, collected once by a caller that
/// reads them again (a scan of the tiles reads every cell slot, observed or not), and the
/// cells whose bottom returns the search found to be no evidence of water (see
/// [`bodies_from`]).
pub(crate) fn find_bodies_and_void(
    tiles: &TileMap,
    observed: &[(CellKey, CellStats)],
    cfg: &HazardConfig,
    previous: &[WaterBody],
) -> Result<(Vec<WaterBody>, BTreeSet<CellKey>)> {
    cfg.validate()?;
    let info = infos(tiles, observed, cfg);
    let seeds = info
        .iter()
        .filter(|(_, i)| seeds_body(i.p, &cfg.water))
        .map(|(&k, _)| k);
    Ok(bodies_from(
        &info,
        seeds,
        tiles.resolution(),
        &cfg.water,
        previous,
    ))
}

/// The [`Info`] of the `observed` cells of `tiles` that the body search reads (see
/// [`find_bodies_and_void`]): the cells within blocks of 2n + 2 cells next to the block of a
/// cell a body can grow over.
pub(crate) fn infos(
    tiles: &TileMap,
    observed: &[(CellKey, CellStats)],
    cfg: &HazardConfig,
) -> BTreeMap<CellKey, Info> {
    let res = tiles.resolution();
    // Only the neighbourhood of possible water matters: the cells a body can grow over
    // (p ≥ p_low, or with bottom returns), their shore and the ground the occluder test
    // reads around it, all within 2n + 1 cells of a body cell for n = ⌈shore_radius /
    // resolution⌉. So only cells in
    // blocks of 2n + 2 cells next to such a cell's block are looked at (most of a map is
    // dry and far from water: every frame, this skips an ordered map of all of it).
    let b = 2 * cfg.water.shore_radius_cells(res) + 2;
    let block = |k: CellKey| (k.x.div_euclid(b), k.y.div_euclid(b));
    let logs = cfg.fusion.logs();
    let p: Vec<f64> = observed
        .iter()
        .map(|(_, c)| c.ev.water_probability_in(&logs))
        .collect();
    let mut near: HashSet<(i64, i64)> = HashSet::new();
    for ((k, c), &p) in observed.iter().zip(&p) {
        if p >= cfg.water.p_low || c.ev.depth_n > 0 {
            let (bx, by) = block(*k);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    near.insert((bx + dx, by + dy));
                }
            }
        }
    }
    observed
        .iter()
        .zip(p)
        .filter(|((k, _), _)| near.contains(&block(*k)))
        .map(|(&(k, c), p)| (k, Info::of(&c, p, &logs, tiles.z_ref())))
        .collect()
}

/// The water bodies of `cells` at resolution `res`, grown from `seeds` (every observed
/// cell that [seeds a body](seeds_body), in increasing key order), with ids after the
/// `previous` bodies. Reads only cells within 2n + 1 of a cell a body can grow over, n =
/// ⌈shore_radius / resolution⌉ (see [`find_bodies_and_void`]). Also the cells whose bottom
/// returns turned out to be no evidence of water (they lie no deeper than
/// `min_bottom_depth_m` under the surface their body found): the map publishes their
/// water probability without them.
pub(crate) fn bodies_from(
    cells: &impl CellInfos,
    seeds: impl IntoIterator<Item = CellKey>,
    res: f64,
    cfg: &WaterConfig,
    previous: &[WaterBody],
) -> (Vec<WaterBody>, BTreeSet<CellKey>) {
    // Bottom returns that do not lie below the surface found by more than the lidar's
    // noise are what dry ground at the water's level gives: they are no evidence (module
    // documentation, section 1). Taking them away only shrinks or splits a component, and
    // a body's fit does not read what others took away, so each component is refined on
    // its own.
    let mut void = BTreeSet::new();
    let mut comps: Vec<(CellKey, Vec<CellKey>)> = components_seeded(cells, seeds, cfg)
        .into_iter()
        .flat_map(|(seed, comp)| refine_component(cells, seed, comp, res, cfg, &mut void))
        .collect();
    comps.sort_unstable_by_key(|&(seed, _)| seed);
    let cells = WithoutBottom {
        inner: cells,
        void: &void,
    };
    let comps: Vec<Vec<CellKey>> = comps.into_iter().map(|(_, c)| c).collect();
    let bodies = bodies_once(&cells, comps, res, cfg, previous);
    (bodies, void)
}

/// Most passes of [`refine_component`].
const MAX_BOTTOM_PASSES: usize = 8;

/// The components a first-pass component `comp` (grown from `seed`) leaves once the bottom
/// returns that lie no more than `min_bottom_depth_m` below its bodies' surfaces are taken
/// out of the evidence (added to `void`), found again until every bottom return left in a
/// body lies deeper, at most [`MAX_BOTTOM_PASSES`] times. Each with the seed it grew from.
pub(crate) fn refine_component(
    cells: &impl CellInfos,
    seed: CellKey,
    comp: Vec<CellKey>,
    res: f64,
    cfg: &WaterConfig,
    void: &mut BTreeSet<CellKey>,
) -> Vec<(CellKey, Vec<CellKey>)> {
    if !comp
        .iter()
        .any(|&k| cells.get(k).is_some_and(|i| i.depth.is_some()))
    {
        return vec![(seed, comp)];
    }
    let min_depth = cfg.min_bottom_depth();
    let cell_area = res * res;
    let all = comp.clone();
    let mut comps = vec![(seed, comp)];
    for _ in 0..MAX_BOTTOM_PASSES {
        let shallow: Vec<CellKey> = {
            let cells = WithoutBottom {
                inner: cells,
                void: &*void,
            };
            comps
                .iter()
                .filter(|(_, c)| c.len() as f64 * cell_area >= cfg.min_body_area_m2)
                .filter_map(|(_, c)| body_of(0, c.clone(), &cells, res, cfg))
                .flat_map(|b| {
                    b.cells
                        .into_iter()
                        .zip(b.cell_depth_m)
                        .filter(|(_, d)| d.is_finite() && f64::from(*d) <= min_depth)
                        .map(|(k, _)| k)
                })
                .collect()
        };
        let before = void.len();
        void.extend(shallow);
        if void.len() == before {
            break;
        }
        let cells = WithoutBottom {
            inner: cells,
            void: &*void,
        };
        let seeds = all.iter().copied().filter(|&k| {
            cells
                .get(k)
                .is_some_and(|i| seeds_body(i.p_evidence(), cfg))
        });
        comps = components_seeded(&cells, seeds, cfg);
    }
    comps
}

/// The bodies of components `comps` (in increasing order of their seeds): ids, and each
/// body's shore, surface and depth.
fn bodies_once(
    cells: &impl CellInfos,
    comps: Vec<Vec<CellKey>>,
    res: f64,
    cfg: &WaterConfig,
    previous: &[WaterBody],
) -> Vec<WaterBody> {
    let cell_area = res * res;
    let comps: Vec<Vec<CellKey>> = comps
        .into_iter()
        .filter(|b| b.len() as f64 * cell_area >= cfg.min_body_area_m2)
        .collect();
    let ids = assign_ids(&comps, previous);
    let mut bodies = Vec::with_capacity(comps.len());
    for (body, id) in comps.into_iter().zip(ids) {
        if let Some(b) = body_of(id, body, cells, res, cfg) {
            bodies.push(b);
        }
    }
    bodies
}

/// Ids for new components given the previous bodies (module documentation, "Ids").
fn assign_ids(comps: &[Vec<CellKey>], previous: &[WaterBody]) -> Vec<u32> {
    let owner: HashMap<CellKey, usize> = previous
        .iter()
        .enumerate()
        .flat_map(|(i, b)| b.cells.iter().map(move |&k| (k, i)))
        .collect();
    let mut next = previous.iter().map(|b| b.id).max().unwrap_or(0) + 1;
    // (component, ancestor, overlap) of every component that overlaps a previous body.
    let mut claims: Vec<(usize, usize, usize)> = Vec::new();
    for (ci, cells) in comps.iter().enumerate() {
        let mut overlap: BTreeMap<usize, usize> = BTreeMap::new();
        for k in cells {
            if let Some(&i) = owner.get(k) {
                *overlap.entry(i).or_default() += 1;
            }
        }
        // The largest ancestor; ties to the smaller id.
        if let Some((&a, &n)) = overlap.iter().max_by(|(a, _), (b, _)| {
            previous[**a]
                .cells
                .len()
                .cmp(&previous[**b].cells.len())
                .then(previous[**b].id.cmp(&previous[**a].id))
        }) {
            claims.push((ci, a, n));
        }
    }
    let mut ids: Vec<Option<u32>> = vec![None; comps.len()];
    // Per ancestor, the claim with the largest overlap wins (ties: first component).
    let mut best: BTreeMap<usize, (usize, usize)> = BTreeMap::new();
    for &(ci, a, n) in &claims {
        let e = best.entry(a).or_insert((ci, n));
        if n > e.1 {
            *e = (ci, n);
        }
    }
    for (a, (ci, _)) in best {
        ids[ci] = Some(previous[a].id);
    }
    ids.into_iter()
        .map(|id| {
            id.unwrap_or_else(|| {
                next += 1;
                next - 1
            })
        })
        .collect()
}

/// The body of the component `cells` (sorted) with id `id`: shore, surface, depths; `None`
/// when no surface can be fitted. Reads the cells within 2n of the component, n =
/// ⌈shore_radius / resolution⌉ (the occluder test's ground, [`ground_near`]).
pub(crate) fn body_of(
    id: u32,
    cells: Vec<CellKey>,
    info: &impl CellInfos,
    res: f64,
    cfg: &WaterConfig,
) -> Option<WaterBody> {
    let set: BTreeSet<CellKey> = cells.iter().copied().collect();
    // Shore: observed dry cells with an elevation, 4-adjacent to the body, outside its
    // small holes.
    let hole_cells = (cfg.min_body_area_m2 / (res * res)).ceil() as usize;
    let mut shore_keys: BTreeSet<CellKey> = BTreeSet::new();
    for &k in &cells {
        for d in N4 {
            let n = add(k, d);
            if !set.contains(&n)
                && info
                    .get(n)
                    .is_some_and(|i| i.elevation.is_some() && i.depth.is_none())
            {
                shore_keys.insert(n);
            }
        }
    }
    shore_keys.retain(|&k| !in_small_hole(&set, k, hole_cells));
    // Only reliably measured shore cells, when there are enough of them: a far cell seen by
    // a few stereo points has an elevation σ of decimetres to metres and would pull the
    // level with it.
    let reliable: Vec<CellKey> = shore_keys
        .iter()
        .copied()
        .filter(|&n| {
            info.get(n)
                .and_then(|i| i.std)
                .is_some_and(|s| s <= cfg.shore_max_std_m)
        })
        .collect();
    let few_reliable = reliable.len() < cfg.min_shore_samples.max(1);
    let shore_keys: Vec<CellKey> = if few_reliable {
        shore_keys.into_iter().collect()
    } else {
        reliable
    };
    let sample = |k: CellKey, z: f64| {
        let (x, y) = centre_of(res, k);
        ShoreSample { x, y, z }
    };
    let shore: Vec<ShoreSample> = shore_keys
        .iter()
        .map(|&k| {
            let z = info.get(k).and_then(|i| i.elevation).unwrap_or(f64::NAN);
            sample(k, z - bank_rise(&set, k, z, info, res, cfg))
        })
        .collect();
    let ground = ground_near(&set, &shore_keys, info, res, cfg);
    let kept = surface::reject_spilling(
        &shore,
        &surface::reject_occluders(&shore, &ground, cfg),
        cfg,
    );
    let (samples, keys, source) = if kept.len() >= cfg.min_shore_samples.max(1) {
        (
            kept.iter().map(|&i| shore[i]).collect::<Vec<_>>(),
            kept.iter().map(|&i| shore_keys[i]).collect::<Vec<_>>(),
            SurfaceSource::Shore,
        )
    } else if let Some((s, k)) = far_shore(&set, info, res, cfg) {
        (s, k, SurfaceSource::FarShore)
    } else {
        let levels: Vec<(CellKey, f64)> = cells
            .iter()
            .filter_map(|&k| info.get(k).and_then(|i| i.level).map(|z| (k, z)))
            .collect();
        if !levels.is_empty() {
            (
                levels.iter().map(|&(k, z)| sample(k, z)).collect(),
                levels.iter().map(|&(k, _)| k).collect(),
                SurfaceSource::WaterLevels,
            )
        } else if !kept.is_empty() {
            (
                kept.iter().map(|&i| shore[i]).collect(),
                kept.iter().map(|&i| shore_keys[i]).collect(),
                SurfaceSource::Shore,
            )
        } else {
            let own: Vec<(CellKey, f64)> = cells
                .iter()
                .filter_map(|&k| info.get(k).and_then(|i| i.elevation).map(|z| (k, z)))
                .collect();
            (
                own.iter().map(|&(k, z)| sample(k, z)).collect(),
                own.iter().map(|&(k, _)| k).collect(),
                SurfaceSource::CellElevations,
            )
        }
    };
    // Too few reliable shore cells: every shore cell counts, weighted by the inverse of its
    // elevation variance, so that the reliable few still decide the level; samples of σ of
    // metres make no surface, so the model is level.
    let fit = if few_reliable && source == SurfaceSource::Shore {
        let sigma: Vec<f64> = keys
            .iter()
            .map(|&k| info.get(k).and_then(|i| i.std).unwrap_or(f64::INFINITY))
            .collect();
        surface::weighted_level(&samples, &sigma)?
    } else {
        surface::fit(
            &samples,
            &shore_constraints(&keys),
            cfg,
            median_std(&keys, info),
        )?
    };
    // A shore that is neither level nor a smooth surface (the fit fell back to its lowest
    // samples), or a triangulated surface that some body cells lie more than
    // `shore_radius_m` outside of (beyond its samples' hull it is carried on level, a
    // guess), may be a stretch of a sloping stream seen in one place: the far shore, where
    // there is one, adds the rest of its length.
    let extrapolated = || {
        let ev = fit.model.evaluator();
        cells.iter().any(|&k| {
            let (x, y) = centre_of(res, k);
            ev.outside_hull_m(x, y) > cfg.shore_radius_m
        })
    };
    let undecided =
        !few_reliable && source == SurfaceSource::Shore && (!fit.decided || extrapolated());
    let far = undecided.then(|| far_shore(&set, info, res, cfg)).flatten();
    let (fit, samples, source) = match far {
        Some((far, far_keys)) => {
            let own: BTreeSet<CellKey> = keys.iter().copied().collect();
            let (mut samples, mut keys) = (samples, keys);
            for (s, k) in far.into_iter().zip(far_keys) {
                if !own.contains(&k) {
                    samples.push(s);
                    keys.push(k);
                }
            }
            let noise = median_std(&keys, info);
            let fit = surface::fit(&samples, &shore_constraints(&keys), cfg, noise)?;
            (fit, samples, SurfaceSource::ShoreAndFarShore)
        }
        None => (fit, samples, source),
    };
    // Each cell's bottom returns, moved from the levels the cue corrected them against
    // onto this body's surface.
    let surface = fit.model.evaluator();
    let cell_depth_m: Vec<f32> = cells
        .iter()
        .map(|&k| {
            info.get(k).and_then(|i| i.depth).map_or(f32::NAN, |d| {
                let (x, y) = centre_of(res, k);
                d.below(surface.at(x, y)) as f32
            })
        })
        .collect();
    let known: Vec<f64> = cell_depth_m
        .iter()
        .filter(|d| d.is_finite())
        .map(|&d| d as f64)
        .collect();
    let cell_area = res * res;
    let depth = DepthStats {
        known_cells: known.len(),
        unknown_cells: cells.len() - known.len(),
        known_area_m2: known.len() as f64 * cell_area,
        unknown_area_m2: (cells.len() - known.len()) as f64 * cell_area,
        mean_m: (!known.is_empty()).then(|| known.iter().sum::<f64>() / known.len() as f64),
        max_m: known.iter().copied().reduce(f64::max),
    };
    let mut body = WaterBody {
        id,
        area_m2: cells.len() as f64 * cell_area,
        cells,
        volume_m3: None,
        depth,
        shore_samples: shore.len(),
        shore_samples_kept: kept.len(),
        surface_samples: samples.len(),
        surface_source: source,
        surface: fit.model,
        level_residual_m: fit.level_residual_m,
        delaunay_residual_m: fit.delaunay_residual_m,
        cell_depth_m,
    };
    if body.depth.unknown_cells == 0 {
        let m = mesh::body_mesh(&body, res, &surface);
        body.volume_m3 = Some(m.volume());
    }
    Some(body)
}

/// The median elevation σ of the cells `keys` (0 when none has one).
fn median_std(keys: &[CellKey], info: &impl CellInfos) -> f64 {
    surface::median(
        keys.iter()
            .filter_map(|&k| info.get(k).and_then(|i| i.std))
            .collect(),
    )
    .unwrap_or(0.0)
}

/// Constraint edges of a surface fit: between every two 8-adjacent sample cells, each
/// pair once.
fn shore_constraints(keys: &[CellKey]) -> Vec<[usize; 2]> {
    let index: HashMap<CellKey, usize> = keys.iter().enumerate().map(|(i, &k)| (k, i)).collect();
    let mut constraints = Vec::new();
    for (i, &k) in keys.iter().enumerate() {
        for d in [(1, 0), (0, 1), (1, 1), (1, -1)] {
            if let Some(&j) = index.get(&add(k, d)) {
                constraints.push([i, j]);
            }
        }
    }
    constraints
}

/// The shore of a body seen across water no sensor measured (module documentation,
/// section 2): from each body cell, in each of the four directions, the first reliably
/// measured dry cell within `shore_radius_m` past at least one cell that is unobserved or
/// measured unreliably; kept when the occluder test keeps it, it stands no more than
/// `occluder_height_m` below the median of the others within `shore_radius_m`, and the
/// spill test keeps it. `None` when fewer than `min_shore_samples` are kept.
fn far_shore(
    set: &BTreeSet<CellKey>,
    info: &impl CellInfos,
    res: f64,
    cfg: &WaterConfig,
) -> Option<(Vec<ShoreSample>, Vec<CellKey>)> {
    let firm = |i: &Info| {
        i.elevation.is_some()
            && i.depth.is_none()
            && i.std.is_some_and(|s| s <= cfg.shore_max_std_m)
    };
    let n = cfg.shore_radius_cells(res);
    let mut keys: BTreeSet<CellKey> = BTreeSet::new();
    for &k in set {
        for d in N4 {
            for j in 1..=n {
                let c = add(k, (d.0 * j, d.1 * j));
                if set.contains(&c) {
                    break;
                }
                if let Some(i) = info.get(c) {
                    if firm(&i) {
                        if j > 1 {
                            keys.insert(c);
                        }
                        break;
                    }
                }
            }
        }
    }
    let keys: Vec<CellKey> = keys.into_iter().collect();
    let shore: Vec<ShoreSample> = keys
        .iter()
        .map(|&k| {
            let (x, y) = centre_of(res, k);
            let z = info.get(k).and_then(|i| i.elevation).unwrap_or(f64::NAN);
            ShoreSample { x, y, z }
        })
        .collect();
    let ground = ground_near(set, &keys, info, res, cfg);
    let medians = surface::local_medians(&shore, cfg.shore_radius_m);
    let not_low: Vec<usize> = surface::reject_occluders(&shore, &ground, cfg)
        .into_iter()
        .filter(|&i| medians[i].z - shore[i].z <= cfg.occluder_height_m)
        .collect();
    let kept = surface::reject_spilling(&shore, &not_low, cfg);
    (kept.len() >= cfg.min_shore_samples.max(1)).then(|| {
        (
            kept.iter().map(|&i| shore[i]).collect(),
            kept.iter().map(|&i| keys[i]).collect(),
        )
    })
}

/// Whether the dry cell `k` lies in a hole of the body `set` of at most `max_cells` cells:
/// the cells not in the body that `k` reaches through 4-neighbours are at most that many.
/// Visits at most `max_cells + 1` cells.
fn in_small_hole(set: &BTreeSet<CellKey>, k: CellKey, max_cells: usize) -> bool {
    let mut seen: BTreeSet<CellKey> = BTreeSet::from([k]);
    let mut queue = VecDeque::from([k]);
    while let Some(c) = queue.pop_front() {
        for d in N4 {
            let n = add(c, d);
            if !set.contains(&n) && seen.insert(n) {
                if seen.len() > max_cells {
                    return false;
                }
                queue.push_back(n);
            }
        }
    }
    seen.len() <= max_cells
}

/// How far the shore cell `k` (elevation `z`) stands above the water's edge beside it: half
/// a cell of the bank's rise away from the water, `g·res/2`, where `g` is the mean over the
/// directions in which `k` has water on one side and a reliably measured dry cell on the
/// other of `(z_behind − z)/res`, clamped to `0..=max_bank_slope`. 0 where no direction
/// has both. See the module documentation.
fn bank_rise(
    set: &BTreeSet<CellKey>,
    k: CellKey,
    z: f64,
    info: &impl CellInfos,
    res: f64,
    cfg: &WaterConfig,
) -> f64 {
    if !z.is_finite() {
        return 0.0;
    }
    let (mut sum, mut n) = (0.0, 0u32);
    for d in N4 {
        let behind = add(k, (-d.0, -d.1));
        if !set.contains(&add(k, d)) || set.contains(&behind) {
            continue;
        }
        let Some(i) = info.get(behind) else { continue };
        if i.depth.is_some() || !i.std.is_some_and(|s| s <= cfg.shore_max_std_m) {
            continue;
        }
        if let Some(zb) = i.elevation {
            sum += ((zb - z) / res).clamp(0.0, cfg.max_bank_slope);
            n += 1;
        }
    }
    if n == 0 {
        return 0.0;
    }
    sum / n as f64 * res / 2.0
}

/// Dry, reliably measured cells (elevation σ ≤ `shore_max_std_m`, water probability below
/// `p_low`) within about `shore_radius_m` of the shore cells: the occluder test's reference
/// for the ground beside the shore. Visits only the blocks of cells around the shore.
fn ground_near(
    body: &BTreeSet<CellKey>,
    shore: &[CellKey],
    info: &impl CellInfos,
    res: f64,
    cfg: &WaterConfig,
) -> Vec<surface::ShoreSample> {
    let n = cfg.shore_radius_cells(res);
    let blocks: BTreeSet<(i64, i64)> = shore
        .iter()
        .flat_map(|k| {
            let (bx, by) = (k.x.div_euclid(n), k.y.div_euclid(n));
            (-1..=1).flat_map(move |dx| (-1..=1).map(move |dy| (bx + dx, by + dy)))
        })
        .collect();
    let shore: BTreeSet<CellKey> = shore.iter().copied().collect();
    let mut out = Vec::new();
    for (bx, by) in blocks {
        for x in bx * n..(bx + 1) * n {
            info.column(x, by * n..(by + 1) * n, |k, i| {
                let Some(z) = i.elevation else { return };
                let reliable = i.std.is_some_and(|s| s <= cfg.shore_max_std_m);
                if reliable && i.p < cfg.p_low && !body.contains(&k) && !shore.contains(&k) {
                    let (x, y) = centre_of(res, k);
                    out.push(surface::ShoreSample { x, y, z });
                }
            });
        }
    }
    out
}

#[cfg(test)]
mod tests;
