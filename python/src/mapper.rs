//! `tarn.Mapper`: the online mapper, one frame at a time.

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyDict;

use tarn::mapper::Mapper as CoreMapper;

use crate::frames::Frame;
use crate::map::Map;
use crate::tiles::TileSet;
use crate::{config_of, err, TarnError};

/// The online mapper: one `update(frame)` per frame; `finish()` is the map of everything.
#[pyclass(module = "tarn", unsendable)]
pub(crate) struct Mapper {
    mapper: Option<CoreMapper>,
}

impl Mapper {
    fn take(&mut self) -> PyResult<CoreMapper> {
        self.mapper
            .take()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))
    }
}

#[pymethods]
impl Mapper {
    /// `publish=True` runs the water stage after every frame (`hazard_map()` is then the
    /// window's latest map); off, as an offline build runs, only `finish()` runs it.
    #[new]
    #[pyo3(signature = (config = None, publish = false))]
    fn new(config: Option<PathBuf>, publish: bool) -> PyResult<Self> {
        let mut m = CoreMapper::new(config_of(config)?.mapper).map_err(err)?;
        m.set_publish(publish);
        Ok(Mapper { mapper: Some(m) })
    }

    /// Fuses one frame; returns its report (frame index, stamp, points, stage times).
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        frame: PyRef<'_, Frame>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let m = self
            .mapper
            .as_mut()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        let r = m.update(&frame.frame).map_err(err)?;
        let d = PyDict::new(py);
        d.set_item("frame_index", r.frame_index)?;
        d.set_item("stamp", r.stamp)?;
        d.set_item("lidar_fused", r.lidar_points().map_or(0, |s| s.fused))?;
        d.set_item("stereo_fused", r.stereo_points().map_or(0, |s| s.fused))?;
        d.set_item("warnings", r.warnings.clone())?;
        let t = PyDict::new(py);
        for (name, v) in tarn::mapper::StageTimes::NAMES
            .iter()
            .zip(r.times_s.values())
        {
            t.set_item(*name, v)?;
        }
        d.set_item("times_s", t)?;
        Ok(d)
    }

    /// Measures the sensors' noise on a frame without mapping it, as an offline build does
    /// on the log's first frames before it maps any (`calibration_settled` says when that
    /// is enough; `hold_calibration()` then keeps the values for every frame after).
    fn calibrate(&mut self, frame: PyRef<'_, Frame>) -> PyResult<()> {
        let m = self
            .mapper
            .as_mut()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        m.calibrate(&frame.frame).map_err(err)
    }

    /// Whether the sensors' noise is measured well enough to be held.
    #[getter]
    fn calibration_settled(&self) -> bool {
        self.mapper
            .as_ref()
            .is_some_and(|m| m.calibration_settled())
    }

    /// Holds the sensors' noise as measured so far, for every frame that follows.
    fn hold_calibration(&mut self) -> PyResult<()> {
        let m = self
            .mapper
            .as_mut()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        m.hold_calibration();
        Ok(())
    }

    /// Every sensor value used so far, its source and what the log measured, as JSON text.
    fn calibration(&self) -> PyResult<String> {
        let m = self
            .mapper
            .as_ref()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        serde_json::to_string(m.calibration()).map_err(|e| TarnError::new_err(e.to_string()))
    }

    /// Frames fused so far.
    #[getter]
    fn frames(&self) -> u64 {
        self.mapper.as_ref().map_or(0, |m| m.frames())
    }

    /// The latest published map of the window (empty until one was published).
    fn hazard_map(&self) -> PyResult<Map> {
        let m = self
            .mapper
            .as_ref()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        Ok(Map::new((*m.hazard_map()).clone()))
    }

    /// The cells that have left the window so far, as a `TileSet`, which the mapper then
    /// forgets: they are final, and the merge of every take and `finish_tiles()` is what
    /// `finish_tiles()` alone would have given, byte for byte.
    fn take_left_tiles(&mut self, py: Python<'_>) -> PyResult<TileSet> {
        let m = self
            .mapper
            .as_mut()
            .ok_or_else(|| TarnError::new_err("the mapper was finished"))?;
        let tiles = py.detach(|| m.take_left_tiles());
        Ok(TileSet { tiles })
    }

    /// Ends the run: the map of everything the mapper saw. The mapper cannot be used after.
    fn finish(&mut self, py: Python<'_>) -> PyResult<Map> {
        let m = self.take()?;
        let (_, map) = py.detach(|| m.finish_map()).map_err(err)?;
        Ok(Map::new(map))
    }

    /// Ends the run: everything the mapper saw as a `TileSet`, for merging with others.
    fn finish_tiles(&mut self, py: Python<'_>) -> PyResult<TileSet> {
        let m = self.take()?;
        let tiles = py.detach(|| m.finish());
        Ok(TileSet { tiles })
    }
}
