//! `tarn.Frame` and `tarn.FrameIter`: the frames of a log as `tarn build` reads them.

use std::path::PathBuf;

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2};
use pyo3::exceptions::PyStopIteration;
use pyo3::prelude::*;

use tarn::sensor::Frame as CoreFrame;
use tarn_log::frames::FrameStream;

use crate::{config_of, err, TarnError};

/// One frame of a log: the scan, the matched stereo cloud and images, with poses.
#[pyclass(module = "tarn", frozen)]
pub(crate) struct Frame {
    pub(crate) frame: CoreFrame,
}

#[pymethods]
impl Frame {
    /// The scan's stamp, log seconds.
    #[getter]
    fn stamp(&self) -> f64 {
        self.frame.stamp
    }

    /// The vehicle's position `(x, y, z)` in the map frame.
    #[getter]
    fn position(&self) -> (f64, f64, f64) {
        let t = &self.frame.base_to_map.translation.vector;
        (t.x, t.y, t.z)
    }

    /// The lidar points in the map frame, `(N, 3)` float64 (missing returns left out);
    /// `None` without a lidar scan.
    fn lidar_points<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        let c = self.frame.lidar.as_ref()?;
        let pts: Vec<[f64; 3]> = (0..c.len())
            .filter(|&i| c.xyz[i].iter().all(|v| v.is_finite()))
            .map(|i| {
                let p = c.point_in_map(i);
                [p.x, p.y, p.z]
            })
            .collect();
        let mut a = Array2::zeros((pts.len(), 3));
        for (i, p) in pts.iter().enumerate() {
            for (k, v) in p.iter().enumerate() {
                a[[i, k]] = *v;
            }
        }
        Some(a.into_pyarray(py))
    }

    fn __repr__(&self) -> String {
        let f = &self.frame;
        format!(
            "<tarn.Frame at {:.3} s: lidar {}, stereo {}, images {}>",
            f.stamp,
            f.lidar.as_ref().map_or(0, |c| c.len()),
            f.stereo.as_ref().map_or(0, |c| c.len()),
            [&f.image, &f.swir, &f.mwir]
                .iter()
                .filter(|i| i.is_some())
                .count()
        )
    }
}

/// The frames of a log, in order; frames that cannot be built are skipped (their errors
/// in `errors`).
#[pyclass(module = "tarn", unsendable)]
pub(crate) struct FrameIter {
    stream: FrameStream,
    errors: Vec<String>,
}

#[pymethods]
impl FrameIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self) -> PyResult<Frame> {
        loop {
            match self.stream.next() {
                Some(Ok(frame)) => return Ok(Frame { frame }),
                Some(Err(e)) => self.errors.push(e.to_string()),
                None => {
                    if let Some(e) = self.stream.fatal_error() {
                        return Err(TarnError::new_err(e.to_string()));
                    }
                    return Err(PyStopIteration::new_err(()));
                }
            }
        }
    }

    /// Messages or frames that could not be used so far, with why.
    #[getter]
    fn errors(&self) -> Vec<String> {
        self.errors.clone()
    }
}

/// The frames of a log as `tarn build` reads them (the config's `[log]` settings; the
/// frame topic chosen from the log unless the config names one).
#[pyfunction]
#[pyo3(signature = (path, config = None))]
pub(crate) fn read_frames(path: PathBuf, config: Option<PathBuf>) -> PyResult<FrameIter> {
    let cfg = config_of(config)?;
    let summary = tarn_log::log::summarize_quick(&path).map_err(err)?;
    let log_cfg = tarn_log::build::frame_log_config(&cfg, &summary, &path).map_err(err)?;
    let stream = FrameStream::open(&path, &log_cfg).map_err(err)?;
    Ok(FrameIter {
        stream,
        errors: Vec::new(),
    })
}
