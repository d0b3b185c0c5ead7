//! Geometric water cues: per-frame water evidence from organized clouds (paper sections 2.3
//! and 3, and beyond).
//!
//! Every mapper discards points below the ground and treats a missing lidar return as
//! nothing; for water those are the signal. Each cue walks the *scan lines* of an organized
//! cloud (a stereo image column from the bottom up, a lidar column from the steepest ring
//! out; for a single-row vertical scanner the row itself) in the order of increasing
//! lookahead, keeping the level of the last ground seen — the shore level, which is the
//! water level of a still water body — and reads what breaks the pattern:
//!
//! * stereo ([`stereo_reflections`]) — **reflections**: a run of points below the local ground, behind a gap,
//!   whose range wraps backward up the column. The ray to each reflected point crosses the
//!   water level where the water is (evidence for that cell); mirrored about the level the
//!   point is the real object, returned in place of the raw one; reflected points and their
//!   sources, paired by nearest-neighbour search (kiddo), give the level by symmetry; the
//!   intensity image, when given, confirms a run by mirror-image correlation.
//! * lidar ([`LidarCueModel`]) — **no return**: a missing beam, its direction from the organized scan or a
//!   beam model, cast against the local ground level; if it meets the ground inside the
//!   optics' diagnostic interval its cell gets no-return evidence, and returns inside the
//!   interval are counted too (so no-return is a fraction, not a raw count). **Below-level
//!   returns**: corrected for refraction and the speed of light in water, a return whose
//!   depth the optics say is visible at that lookahead is a **bottom return** (a depth
//!   sample); one deeper than that is a **specular** return from beyond the water: reflection
//!   evidence where its ray crosses the level, and no terrain (the walked level is not the
//!   water's, so its mirror image would land too high). **Reflectivity drop**: ground returns normalised for range
//!   and incidence and compared with the scan's own median.
//!
//! The cues produce sparse per-cell [`Evidence`] (see [`crate::grid::Evidence`] for the
//! fusion rule) that [`crate::grid::RollingGrid::apply_evidence`] merges exactly; nothing
//! depends on thread count or point order within a scan line.
//!
//! Exports: a run's options ([`CueRun`]) and its output ([`EvidenceMap`]); the lidar cues
//! ([`LidarCueModel`], [`LidarCueConfig`], [`BeamModel`], [`beam_directions`],
//! [`estimate_sensor_height`], [`LidarBuffers`], [`LidarCues`] with [`LidarCueStats`],
//! [`ScanSurface`], [`DryReach`]); the water an earlier map found ([`WaterPrior`]); the
//! reflectivity drop ([`ReflectivityConfig`], [`Channel`], [`ChannelLaw`],
//! [`normalised_reflectivity`]); the stereo reflections ([`stereo_reflections`],
//! [`StereoCueConfig`], [`GrayImage`], [`MirrorCheck`], [`StereoCues`], [`StereoSeen`]); and
//! a frame's cues ([`FrameCues`], [`FrameCueConfig`], [`FrameCuesReport`], [`mirror_gray`],
//! [`mirror_check_of`]).

mod frame;
mod lidar;
mod prior;
mod reflectivity;
mod stereo;

use std::collections::HashMap;

use crate::grid::{key_of, quantize_mm, BuildKeyHasher, CellKey, Evidence};

pub use frame::{mirror_check_of, mirror_gray, FrameCueConfig, FrameCues, FrameCuesReport};
pub use lidar::{
    beam_directions, estimate_sensor_height, BeamModel, DryReach, LidarBuffers, LidarCueConfig,
    LidarCueModel, LidarCueStats, LidarCues, ScanSurface,
};
pub use prior::WaterPrior;
pub use reflectivity::{normalised_reflectivity, Channel, ChannelLaw, ReflectivityConfig};
pub use stereo::{
    stereo_reflections, GrayImage, MirrorCheck, StereoCueConfig, StereoCues, StereoSeen,
};

// What the rest of the crate reads of the cues' internals: the water levels a map hands the
// next run, and the reflectivity channel the lidar calibration fits.
pub(crate) use prior::PriorLevel;
pub(crate) use reflectivity::{channel_name, channel_value};

/// The options of one run of a cue: the grid its events are keyed to, and what else it is
/// asked for.
#[derive(Debug, Clone, Copy)]
pub struct CueRun<'a> {
    /// Cell size of the grid, metres.
    pub resolution: f64,
    /// The grid's reference height (`z_ref`), metres.
    pub z_ref: f64,
    /// Also say what the run finds of the surface under each return or pixel
    /// ([`ScanSurface`], [`StereoCues::seen`]): the image labels' colour check reads it,
    /// nothing else does.
    pub surface_points: bool,
    /// The water levels an earlier map found (the lidar cue reads them: a return under one
    /// by more than the noise of both is a bottom return).
    pub prior: Option<&'a prior::WaterPrior>,
}

impl CueRun<'_> {
    /// Events keyed to a grid of `resolution` m at `z_ref`; nothing else asked for.
    pub fn new(resolution: f64, z_ref: f64) -> Self {
        CueRun {
            resolution,
            z_ref,
            surface_points: false,
            prior: None,
        }
    }
}

/// A sparse accumulator of per-cell evidence for one frame, keyed like the grid.
#[derive(Debug, Clone)]
pub struct EvidenceMap {
    resolution: f64,
    z_ref: f64,
    /// Hashed for speed; every read-out is sorted by key, so nothing depends on the
    /// hasher's order (and merging evidence is commutative).
    cells: HashMap<CellKey, Evidence, BuildKeyHasher>,
}

impl EvidenceMap {
    /// An empty map of cells `resolution` metres wide, levels relative to `z_ref` (map z, metres).
    pub fn new(resolution: f64, z_ref: f64) -> Self {
        EvidenceMap {
            resolution,
            z_ref,
            cells: HashMap::default(),
        }
    }

    /// Empties the map for cells `resolution` metres wide and levels relative to `z_ref`,
    /// keeping its storage.
    pub(crate) fn reset(&mut self, resolution: f64, z_ref: f64) {
        self.resolution = resolution;
        self.z_ref = z_ref;
        self.cells.clear();
    }

    /// The evidence of the cell under the map point `(x, y)`, created empty if needed.
    /// `None` for non-finite coordinates.
    pub fn at(&mut self, x: f64, y: f64) -> Option<&mut Evidence> {
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        Some(self.cells.entry(key_of(self.resolution, x, y)).or_default())
    }

    /// A level (map-frame metres) in the grid's fixed-point millimetres.
    pub(crate) fn level_mm(&self, z: f64) -> Option<i32> {
        quantize_mm(z - self.z_ref)
    }

    /// Adds `f`'s change to the cell under `(x, y)` together with a level sample.
    pub(crate) fn add_with_level(
        &mut self,
        x: f64,
        y: f64,
        level_z: f64,
        f: impl FnOnce(&mut Evidence),
    ) {
        let mm = self.level_mm(level_z);
        if let Some(e) = self.at(x, y) {
            f(e);
            if let Some(mm) = mm {
                e.add_level(mm);
            }
        }
    }

    /// Number of cells with evidence.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether no cell has evidence.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// The evidence of the cell `k`, if it has any.
    pub fn get(&self, k: CellKey) -> Option<&Evidence> {
        self.cells.get(&k)
    }

    /// Cells in key order.
    pub fn iter(&self) -> impl Iterator<Item = (&CellKey, &Evidence)> {
        let mut v: Vec<_> = self.cells.iter().collect();
        v.sort_unstable_by_key(|(k, _)| **k);
        v.into_iter()
    }

    /// Merges another map (same resolution and reference).
    pub fn merge(&mut self, o: &EvidenceMap) {
        for (k, e) in &o.cells {
            self.cells.entry(*k).or_default().merge(e);
        }
    }

    /// [`Self::into_batch`] into `out`'s storage (its contents replaced), leaving this map
    /// empty with its storage kept.
    pub(crate) fn drain_batch_into(&mut self, out: &mut Vec<(CellKey, Evidence)>) {
        out.clear();
        out.extend(self.cells.drain());
        out.sort_unstable_by_key(|(k, _)| *k);
    }

    /// The batch for [`crate::grid::RollingGrid::apply_evidence`], in key order.
    pub(crate) fn into_batch(self) -> Vec<(CellKey, Evidence)> {
        let mut v: Vec<_> = self.cells.into_iter().collect();
        v.sort_unstable_by_key(|(k, _)| *k);
        v
    }

    /// Sum of all cells' evidence.
    pub fn total(&self) -> Evidence {
        let mut t = Evidence::default();
        for e in self.cells.values() {
            t.merge(e);
        }
        t
    }
}

#[cfg(test)]
pub(crate) mod testutil {
    /// Deterministic test noise: splitmix64 and Box–Muller.
    pub struct TestRng(pub u64);
    impl TestRng {
        pub fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        pub fn uniform(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }
        /// Uniform in [a, b).
        pub fn range(&mut self, a: f64, b: f64) -> f64 {
            a + (b - a) * self.uniform()
        }
        pub fn chance(&mut self, p: f64) -> bool {
            self.range(0.0, 1.0) < p
        }
        pub fn normal(&mut self) -> f64 {
            let u1 = self.uniform().max(1e-300);
            let u2 = self.uniform();
            (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
        }
    }
}
