//! `tarn._tarn`: the Python bindings of tarn. The Python package `tarn` re-exports them
//! (see `tarn/__init__.py` and the stubs `tarn/_tarn.pyi`).
//!
//! Every long call (a build, a merge, the water stage, encoding and decoding tile sets)
//! releases the interpreter while it runs, so Python threads (a Dask worker's, say) build
//! in parallel. Errors are `tarn.TarnError` carrying tarn's own message; a file that cannot
//! be opened is an `OSError`.

use std::path::PathBuf;

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyOSError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use tarn::mapper::MapperConfig;
use tarn_log::build::LogBuildConfig;

mod frames;
mod map;
mod mapper;
mod region;
mod tiles;

use frames::{read_frames, Frame, FrameIter};
use map::{read_map, Map};
use mapper::Mapper;
use region::{finish_region, join_regions, Region};
use tiles::{build, build_many, build_tiles, finish, TileSet};

create_exception!(
    _tarn,
    TarnError,
    PyException,
    "An error from tarn: bad input, a bad setting, a damaged file. The message is tarn's."
);

fn err(e: tarn::Error) -> PyErr {
    match e {
        tarn::Error::Io { .. } => PyOSError::new_err(e.to_string()),
        e => TarnError::new_err(e.to_string()),
    }
}

/// The config of a build: `None` for what `tarn build` uses on a log without options
/// (every sensor, colour and SWIR labels), else the path of a `tarn.toml` (or JSON) file.
fn config_of(config: Option<PathBuf>) -> PyResult<LogBuildConfig> {
    match config {
        None => Ok(LogBuildConfig::of_mapper(MapperConfig::every_sensor())),
        Some(p) => LogBuildConfig::load(&p).map_err(err),
    }
}

/// What `__reduce__` gives pickle: a constructor and its arguments.
type Reduced<'py> = (Bound<'py, PyAny>, (Bound<'py, PyBytes>,));

#[pymodule]
fn _tarn(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("TarnError", m.py().get_type::<TarnError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<Map>()?;
    m.add_class::<TileSet>()?;
    m.add_class::<Region>()?;
    m.add_class::<Frame>()?;
    m.add_class::<FrameIter>()?;
    m.add_class::<Mapper>()?;
    m.add_function(wrap_pyfunction!(build, m)?)?;
    m.add_function(wrap_pyfunction!(build_many, m)?)?;
    m.add_function(wrap_pyfunction!(build_tiles, m)?)?;
    m.add_function(wrap_pyfunction!(finish, m)?)?;
    m.add_function(wrap_pyfunction!(finish_region, m)?)?;
    m.add_function(wrap_pyfunction!(join_regions, m)?)?;
    m.add_function(wrap_pyfunction!(read_map, m)?)?;
    m.add_function(wrap_pyfunction!(read_frames, m)?)?;
    Ok(())
}
