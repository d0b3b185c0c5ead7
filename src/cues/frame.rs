//! Driving the cues from one [`Frame`] of a log: run each configured cue on the sensor it
//! needs, fuse the *corrected* cloud (stereo reflections mirrored back above the water,
//! the lidar's specular and bottom returns taken out) into the grid instead of the raw one, and merge the evidence.
//!
//! Only configured sensors are modelled: a cue whose sensor is not configured, or absent
//! from the frame, runs no code.

use serde::Serialize;

use super::lidar::{LidarBuffers, LidarCueModel, LidarCueStats, ScanSurface};
use super::prior::WaterPrior;
use super::stereo::{stereo_reflections, GrayImage, MirrorCheck, StereoCueConfig};
use super::CueRun;
use crate::error::Result;
use crate::grid::{CellKey, Evidence, IngestStats, RangeNoise, RollingGrid};
use crate::sensor::{Frame, Image, Pixels};

/// Which cues run, and how.
#[derive(Debug, Clone, Default)]
pub struct FrameCueConfig {
    /// The lidar's cue model (`None`: no lidar cues).
    pub lidar: Option<LidarCueModel>,
    /// Range noise of the lidar points fused into the grid.
    pub lidar_noise: RangeNoise,
    /// Stereo reflection settings (`None`: no stereo cue).
    pub stereo: Option<StereoCueConfig>,
    /// Confirm stereo reflections with the frame's camera image when it has one.
    pub mirror_check: bool,
    /// Collect where the lidar found dry ground and water, and what each stereo element
    /// says of the surface ([`ScanSurface`]), for the colour labels' check; off when no
    /// label stage reads them. Stereo says less than the lidar: a point at the level may be
    /// the bed of shallow clear water, and a missing match says nothing at all (dry ground
    /// of little texture, snow and pale slabs, gives none either).
    pub surface_points: bool,
}

/// What one frame contributed.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FrameCuesReport {
    /// What the lidar cues saw (`None`: no lidar in the frame or no lidar cues).
    pub lidar: Option<LidarCueStats>,
    /// What happened to the lidar cloud's points when fused.
    pub lidar_ingest: Option<IngestStats>,
    /// Stereo reflection runs confirmed.
    pub stereo_runs: usize,
    /// Stereo points found to be reflections.
    pub stereo_reflected_points: usize,
    /// The stereo cue's water level from reflection symmetry, map z, metres.
    pub stereo_symmetry_level: Option<f64>,
    /// The stereo cue's waterline level (the level its runs took, when present).
    pub stereo_waterline_level: Option<f64>,
    /// What happened to the stereo cloud's points when fused.
    pub stereo_ingest: Option<IngestStats>,
    /// Evidence cells merged.
    pub evidence_cells: usize,
    /// Evidence cells dropped outside the window.
    pub evidence_dropped: usize,
}

/// The per-frame cue runner.
#[derive(Debug, Clone, Default)]
pub struct FrameCues {
    /// Which cues run, and how.
    pub cfg: FrameCueConfig,
    /// The water an earlier map found, read by the lidar cue ([`WaterPrior`]); `None`:
    /// the cues see this frame alone.
    pub prior: Option<WaterPrior>,
    /// The lidar cue's storage and its evidence batch, reused from frame to frame.
    lidar_bufs: LidarBuffers,
    batch: Vec<(CellKey, Evidence)>,
}

/// Intensity of a camera image as a [`GrayImage`] (mean of R, G, B for colour).
pub(crate) fn gray_of(image: &Image) -> Result<GrayImage> {
    let pixels: Vec<f32> = match &image.pixels {
        Pixels::Rgb8(p) => p
            .iter()
            .map(|c| (c[0] as f32 + c[1] as f32 + c[2] as f32) / 3.0)
            .collect(),
        Pixels::Mono8(p) => p.iter().map(|&v| v as f32).collect(),
        Pixels::Mono16(p) => p.iter().map(|&v| v as f32).collect(),
    };
    GrayImage::new(image.width, image.height, pixels)
}

/// The grey image the stereo cue's mirror check reads (`mirror_check` on and a colour
/// camera with its model in `frame`), `None` otherwise; pair it with the camera in a
/// [`MirrorCheck`] ([`mirror_check_of`]).
pub fn mirror_gray(frame: &Frame, mirror_check: bool) -> Result<Option<GrayImage>> {
    match &frame.image {
        Some(img) if mirror_check && img.camera.is_some() => Ok(Some(gray_of(&img.image)?)),
        _ => Ok(None),
    }
}

/// The mirror check of `frame` over its grey image `gray` ([`mirror_gray`]).
pub fn mirror_check_of<'a>(
    frame: &'a Frame,
    gray: Option<&'a GrayImage>,
) -> Option<MirrorCheck<'a>> {
    let camera = frame.image.as_ref()?.camera.as_ref()?;
    Some(MirrorCheck {
        camera,
        image: gray?,
    })
}

impl FrameCues {
    /// A runner of the cues `cfg` names.
    pub fn new(cfg: FrameCueConfig) -> Self {
        FrameCues {
            cfg,
            ..FrameCues::default()
        }
    }

    /// Runs the configured cues on `frame`, ingests the corrected clouds into `grid` and
    /// merges the evidence.
    pub fn apply(&mut self, frame: &Frame, grid: &mut RollingGrid) -> Result<FrameCuesReport> {
        let mut rep = FrameCuesReport::default();
        self.apply_lidar(frame, grid, &mut rep)?;
        self.apply_stereo(frame, grid, &mut rep)?;
        Ok(rep)
    }

    /// The lidar half of [`FrameCues::apply`]: runs only when a lidar cue model is
    /// configured and the frame has a lidar cloud. Returns what the scan says of the
    /// surface ([`ScanSurface`]) for the image labels that follow.
    pub(crate) fn apply_lidar(
        &mut self,
        frame: &Frame,
        grid: &mut RollingGrid,
        rep: &mut FrameCuesReport,
    ) -> Result<Option<ScanSurface>> {
        let (res, z_ref) = (grid.resolution(), grid.config().z_ref);
        if let (Some(model), Some(cloud)) = (&self.cfg.lidar, &frame.lidar) {
            let run = CueRun {
                surface_points: self.cfg.surface_points,
                prior: self.prior.as_ref(),
                ..CueRun::new(res, z_ref)
            };
            let mut out = model.run(cloud, &run, &mut self.lidar_bufs)?;
            rep.lidar_ingest = Some(grid.ingest(&out.corrected, &self.cfg.lidar_noise)?);
            rep.lidar = Some(out.stats);
            out.evidence.drain_batch_into(&mut self.batch);
            rep.evidence_cells += self.batch.len();
            rep.evidence_dropped += grid.apply_evidence(&self.batch);
            self.lidar_bufs.recycle(out.evidence, out.corrected);
            return Ok(Some(out.surface));
        }
        Ok(None)
    }

    /// The stereo half of [`FrameCues::apply`]: runs only when the stereo cue is configured
    /// and the frame has a stereo cloud. Returns what the cloud says of the surface
    /// ([`ScanSurface::stereo`]) for the image labels that follow.
    pub(crate) fn apply_stereo(
        &self,
        frame: &Frame,
        grid: &mut RollingGrid,
        rep: &mut FrameCuesReport,
    ) -> Result<Option<ScanSurface>> {
        let (res, z_ref) = (grid.resolution(), grid.config().z_ref);
        if let (Some(scfg), Some(cloud)) = (&self.cfg.stereo, &frame.stereo) {
            let gray = mirror_gray(frame, self.cfg.mirror_check)?;
            let check = mirror_check_of(frame, gray.as_ref());
            let run = CueRun {
                surface_points: self.cfg.surface_points,
                ..CueRun::new(res, z_ref)
            };
            let out = stereo_reflections(cloud, &run, check, scfg)?;
            rep.stereo_ingest = Some(grid.ingest(&out.corrected, &scfg.noise)?);
            rep.stereo_runs = out.runs;
            rep.stereo_reflected_points = out.reflected_points;
            rep.stereo_symmetry_level = out.symmetry_level;
            rep.stereo_waterline_level = out.waterline_level;
            let batch = out.evidence.into_batch();
            rep.evidence_cells += batch.len();
            rep.evidence_dropped += grid.apply_evidence(&batch);
            if self.cfg.surface_points {
                return Ok(Some(ScanSurface {
                    stereo: out.seen,
                    ..ScanSurface::default()
                }));
            }
        }
        Ok(None)
    }
}
