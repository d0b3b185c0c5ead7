//! tarn's simulator and evaluation: scenes rendered into logs with their ground truth
//! ([`sim`]), maps scored against that truth ([`eval`]), and the whole-pipeline entry
//! points of the fuzz targets ([`fuzzing`]).
//!
//! This crate sits beside the core library: it uses every stage of it, and nothing in the
//! core depends on it.

// The core's modules under their own names, so that paths inside the simulator read as they
// do in the core.
pub(crate) use tarn::{
    classify, error, geom, grid, hazard, io, mapper, optics, project, rig, sensor,
};

pub mod eval;
#[doc(hidden)]
pub mod fuzzing;
pub mod sim;
