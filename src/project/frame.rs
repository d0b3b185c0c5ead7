//! Image labels of one [`Frame`] into the grid's water evidence (same pattern as
//! [`crate::cues::FrameCues`]).
//!
//! For each configured image sensor present in the frame: classify the image (colour through
//! a lookup table, pixels above the horizon — from the camera's pose — become sky; SWIR
//! water as a reflection of the sky it mirrors; MWIR thermal contrast by time of day within
//! a lookahead),
//! find each pixel's map cell (through the stereo point of the pixel where the colour camera
//! has one, else by marching the pixel ray over the grid's elevations, [`GridSurface`]),
//! tally the frame's pixels per cell (a slot per window cell into the counts of the cells
//! the frame's pixels fell in), and add **one vote
//! per cell and frame** — the majority of its pixels, water or not — to the cell's
//! [`Evidence`] (`colour_water`/`colour_dry`, `swir_dark`/`swir_lit`,
//! `mwir_water`/`mwir_dry`), with the mean of the water pixels' levels as a water level
//! sample: a hit's height, or for water placed over a hole in the map, the tightest bound on
//! the level among its neighbours in the image (`tighten_hole_levels`). Sky and unknown
//! pixels do not vote; a tie is no vote. Where the colour and the SWIR camera both vote on a
//! cell in a frame, a water vote stands only where the other votes water too
//! ([`cross_check`]).
//!
//! Only configured sensors run code; a configured sensor missing from the frame (or without
//! camera info or pose) is skipped and counted in the report.
//!
//! [`FrameLabels`] runs a frame, phase by phase, here; the parts live beside it: the
//! settings (`config`), the report (`report`), the colour checks against the sky (`sky`)
//! and against the lidar (`colour_check`), where a sampled pixel lands on the map
//! (`place`), and which cells its vote goes to (`quad`).

mod colour_check;
mod config;
mod place;
mod quad;
mod report;
mod sky;

pub use config::{Encoding, FrameLabelConfig, LabelSensor, LabelsConfig, MwirLabelConfig, Sampler};
pub use report::{FrameLabelsReport, SensorLabelStats};
pub use sky::reflection_check;

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::surface::GridSurface;
use super::zbuffer::ZBuffer;
use crate::classify::horizon::GroundGeometry;
use crate::classify::mwir::classify_mwir;
use crate::classify::swir::classify_swir;
use crate::classify::{Label, LabelImage, MonoImage};
use crate::cues::ScanSurface;
use crate::error::{Error, Result};
use crate::geom::{pose_is_finite, CameraModel, PointCloud, Pose};
use crate::grid::{CellKey, Cue, Evidence, LabelFalseAlarms, RollingGrid};
use crate::sensor::{Frame, Pixels, SensorImage};
use colour_check::{false_alarms_at, ColourCheck};
use place::{sampled_rows, tighten_hole_levels, Hit, Placer};
use quad::quad_votes;
use sky::apply_horizon;

/// The image cues, a camera each: the label stage's part of the fusion's [`Cue`]s.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ImageCue {
    Colour,
    Swir,
    Mwir,
}

impl ImageCue {
    /// The fusion cue its votes count for.
    const fn cue(self) -> Cue {
        match self {
            ImageCue::Colour => Cue::Colour,
            ImageCue::Swir => Cue::Swir,
            ImageCue::Mwir => Cue::Mwir,
        }
    }
}

/// A camera's unit pixel rays (optical frame), computed once per camera model.
#[derive(Debug, Clone)]
struct RayCache {
    camera: CameraModel,
    rays: Vec<Option<Vector3<f64>>>,
    /// The rays rotated into the map frame by the current frame's pose (reused buffer).
    in_map: Vec<Option<Vector3<f64>>>,
}

impl RayCache {
    fn new(camera: &CameraModel) -> Self {
        RayCache {
            camera: camera.clone(),
            rays: camera.pixel_rays(),
            in_map: Vec::new(),
        }
    }

    /// `camera`'s pixel rays rotated into the map frame by `cam_to_map`, from the cache in
    /// `slot` (rebuilt when the camera changed).
    fn rays_in_map<'a>(
        slot: &'a mut Option<RayCache>,
        camera: &CameraModel,
        cam_to_map: &Pose,
    ) -> &'a [Option<Vector3<f64>>] {
        if slot.as_ref().is_none_or(|c| &c.camera != camera) {
            *slot = Some(RayCache::new(camera));
        }
        let cache = slot.as_mut().expect("just set");
        cache.in_map.clear();
        cache.in_map.extend(
            cache
                .rays
                .iter()
                .map(|r| r.map(|r| cam_to_map.rotation * r)),
        );
        &cache.in_map
    }
}

/// The per-frame label runner. Keeps each camera's pixel rays, the vote raster, the
/// elevation raster and the per-pixel buffers (labels, sampled pixels' hits, per-row votes)
/// between frames, so a frame pays neither undistortion nor allocation.
#[derive(Debug, Clone)]
pub struct FrameLabels {
    /// Which sensors label, and how.
    pub cfg: FrameLabelConfig,
    caches: [Option<RayCache>; 3],
    /// The frame's pixels per cell.
    tally: Tally,
    /// The storage of the last frame's elevation raster.
    raster: Vec<f32>,
    /// What the log's range sensors said of the ground under each colour so far.
    colour_check: ColourCheck,
    /// The colour and SWIR labels' false alarms so far.
    alarms: LabelFalseAlarms,
    /// Per-pixel storage of the last frame, reused.
    bufs: PixelBuffers,
    /// The z-buffer sampler's storage ([`Sampler::Zbuffer`]).
    zbuf: ZBuffer,
    /// This frame's cell votes of the colour and the SWIR camera, held until both have
    /// run ([`cross_check`]).
    pending: [Vec<CellVote>; 2],
    /// This frame's colour and SWIR labels, each with its camera and pose, for the other
    /// camera's check of its water pixels ([`seen_check`]).
    seen: [Option<Seen>; 2],
}

/// One camera's labels in a frame, with the camera and its pose in the map frame.
type Seen = (LabelImage, CameraModel, Pose);

/// One cell's vote of one camera in one frame: its raster index, water or not, and the
/// mean level of its water pixels' hits.
#[derive(Debug, Clone, Copy, PartialEq)]
struct CellVote {
    cell: u32,
    water: bool,
    level: f64,
}

/// The label stage's per-pixel buffers, kept from frame to frame so that a frame allocates
/// nothing: their sizes follow the image, not the window.
#[derive(Debug, Clone, Default)]
struct PixelBuffers {
    /// The colour image's labels.
    labels: Vec<Label>,
    /// The sampled image rows and columns.
    rows: Vec<usize>,
    cols: Vec<usize>,
    /// Per sampled pixel, row-major: its hit.
    hits: Vec<Option<Hit>>,
    /// Per sampled row: pixels placed via a point, via a ray, not placed, beyond reach.
    counts: Vec<[u64; 4]>,
    /// Scratch of `tighten_hole_levels`.
    levels: Vec<f64>,
    /// Per sampled row: its cell votes (raster index, water, level).
    votes: Vec<Vec<(u32, bool, f32)>>,
}

/// The whole factor `k` by which a `w × h` image upsamples the organized stereo `cloud`
/// registered to it (element (row, col) is pixel block (k·row.., k·col..)); `None` when it
/// is not one.
fn stereo_factor(cloud: &PointCloud, w: usize, h: usize) -> Option<usize> {
    if !(cloud.is_organized() && cloud.cols > 0 && w % cloud.cols == 0) {
        return None;
    }
    let k = w / cloud.cols;
    (k > 0 && cloud.rows * k == h).then_some(k)
}

fn mono_of(img: &SensorImage) -> MonoImage {
    let data = match &img.image.pixels {
        Pixels::Rgb8(p) => p
            .iter()
            .map(|c| (c[0] as f32 + c[1] as f32 + c[2] as f32) / 3.0)
            .collect(),
        Pixels::Mono8(p) => p.iter().map(|&v| v as f32).collect(),
        Pixels::Mono16(p) => p.iter().map(|&v| v as f32).collect(),
    };
    MonoImage {
        width: img.image.width,
        height: img.image.height,
        data,
    }
}

impl FrameLabels {
    /// A runner of the labels `cfg` names. Fails when `cfg` does not validate.
    pub fn new(cfg: FrameLabelConfig) -> Result<Self> {
        cfg.validate()?;
        Ok(FrameLabels {
            cfg,
            caches: [None, None, None],
            tally: Tally::default(),
            raster: Vec::new(),
            colour_check: ColourCheck::default(),
            alarms: LabelFalseAlarms::default(),
            bufs: PixelBuffers::default(),
            zbuf: ZBuffer::default(),
            pending: [Vec::new(), Vec::new()],
            seen: [None, None],
        })
    }

    /// The colour and SWIR labels' false alarms on the dry ground the log's lidar sampled,
    /// over every frame so far ([`LabelFalseAlarms`]; none for the colour labels without
    /// the colour check, none for either without the lidar's samples).
    pub fn false_alarms(&self) -> LabelFalseAlarms {
        self.alarms
    }

    /// Bytes allocated per window cell between frames (capacities): the vote tally, the
    /// cells it touched and the elevation raster.
    pub fn heap_bytes(&self) -> usize {
        let t = &self.tally;
        t.slot.capacity() * std::mem::size_of::<u32>()
            + t.counts.capacity() * std::mem::size_of::<(u32, u32, f64)>()
            + t.touched.capacity() * std::mem::size_of::<u32>()
            + self.raster.capacity() * std::mem::size_of::<f32>()
            + self.zbuf.heap_bytes()
    }

    /// Classifies the frame's configured images, projects the labels and adds one vote per
    /// cell and sensor to `grid`'s evidence.
    pub fn apply(
        &mut self,
        frame: &Frame,
        grid: &mut RollingGrid,
        samples: Option<&ScanSurface>,
    ) -> Result<FrameLabelsReport> {
        let mut rep = FrameLabelsReport::default();
        let any = self.cfg.colour.is_some() || self.cfg.swir.is_some() || self.cfg.mwir.is_some();
        if !any {
            return Ok(rep);
        }
        let raster = std::mem::take(&mut self.raster);
        let surface = GridSurface::from_grid_gated_in(grid, self.cfg.surface_max_std, raster);
        let nn = surface.size() * surface.size();
        if self.tally.slot.len() != nn {
            self.tally.slot = vec![NO_SLOT; nn];
        }
        let base = frame.base_to_map.translation.vector;
        let ground_z = match surface.elevation(base.x, base.y) {
            z if z.is_finite() => z as f64,
            _ => base.z,
        };
        self.pending.iter_mut().for_each(Vec::clear);
        self.seen = [None, None];
        // The colour labels first where SWIR runs too: the SWIR water pixels are checked
        // against them, and the colour's against the SWIR labels.
        let mut pre: Option<(LabelImage, SensorLabelStats)> = None;
        if let (Some(_), Some(_), Some(img)) = (&self.cfg.colour, &self.cfg.swir, &frame.image) {
            if let Some((cam, pose)) = usable_image(img) {
                let mut st = SensorLabelStats::default();
                let stereo = frame.stereo.as_ref();
                let l = self.classify_cue(
                    ImageCue::Colour,
                    img,
                    cam,
                    &pose,
                    stereo,
                    None,
                    ground_z,
                    &surface,
                    samples,
                    &mut st,
                )?;
                self.seen[0] = Some((l.clone(), cam.clone(), pose));
                pre = Some((l, st));
            }
        }
        for cue in [ImageCue::Swir, ImageCue::Colour, ImageCue::Mwir] {
            let (configured, img) = match cue {
                ImageCue::Colour => (self.cfg.colour.is_some(), &frame.image),
                ImageCue::Swir => (self.cfg.swir.is_some(), &frame.swir),
                ImageCue::Mwir => (self.cfg.mwir.is_some(), &frame.mwir),
            };
            if !configured {
                continue;
            }
            let (labels, mut st) = match cue {
                ImageCue::Colour => pre
                    .take()
                    .map_or((None, Default::default()), |(l, st)| (Some(l), st)),
                _ => (None, SensorLabelStats::default()),
            };
            let usable = img
                .as_ref()
                .and_then(|i| usable_image(i).map(|(cam, pose)| (i, cam, pose)));
            let hour = match (cue, &self.cfg.mwir) {
                (ImageCue::Mwir, Some(m)) => m.hour_of(frame),
                _ => None,
            };
            match usable {
                None => st.frames_skipped += 1,
                Some(_) if cue == ImageCue::Mwir && hour.is_none() => st.frames_no_hour += 1,
                Some((img, cam, pose)) => {
                    if let Some(h) = hour {
                        let r = rep.mwir_hours.get_or_insert([h, h]);
                        *r = [r[0].min(h), r[1].max(h)];
                        st.frames_hour_from_stamp +=
                            u64::from(self.cfg.mwir.as_ref().is_some_and(|m| m.hour.is_none()));
                    }
                    st.frames = 1;
                    let stereo = if cue == ImageCue::Colour {
                        frame.stereo.as_ref()
                    } else {
                        None
                    };
                    let labels = match labels {
                        Some(l) => l,
                        None => self.classify_cue(
                            cue, img, cam, &pose, stereo, hour, ground_z, &surface, samples,
                            &mut st,
                        )?,
                    };
                    let px = match &img.image.pixels {
                        Pixels::Rgb8(px) => Some(&px[..]),
                        _ => None,
                    };
                    rep.dropped += self.run(
                        cue, labels, px, cam, &pose, stereo, ground_z, &surface, samples, grid,
                        &mut st,
                    )?;
                }
            }
            match cue {
                ImageCue::Colour => rep.colour = Some(st),
                ImageCue::Swir => rep.swir = Some(st),
                ImageCue::Mwir => rep.mwir = Some(st),
            }
        }
        // The colour and SWIR votes, checked against each other where both saw a cell.
        let [colour, swir] = &mut self.pending;
        let (c_out, s_out) = cross_check(colour, swir);
        for (cue, votes, out) in [
            (ImageCue::Colour, &*colour, c_out),
            (ImageCue::Swir, &*swir, s_out),
        ] {
            let st = match cue {
                ImageCue::Colour => rep.colour.as_mut(),
                _ => rep.swir.as_mut(),
            };
            if let Some(st) = st {
                st.cross_vetoed += out;
                rep.dropped += add_cell_votes(votes, cue, &surface, grid, st);
            }
        }
        self.alarms.merge(&rep.false_alarms());
        self.raster = surface.into_raster();
        Ok(rep)
    }

    /// One sensor's image in the frame: classified ([`Self::classify`]), its sampled pixels
    /// placed on the map ([`Placer`]), each pixel's votes spread over the cells its quad
    /// covers ([`quad_votes`]), tallied per cell, and one vote per cell added to `grid`
    /// ([`add_cell_votes`]). Returns the votes that fell outside the window.
    #[allow(clippy::too_many_arguments)]
    fn run(
        &mut self,
        cue: ImageCue,
        labels: LabelImage,
        px: Option<&[[u8; 3]]>,
        camera: &CameraModel,
        cam_to_map: &Pose,
        stereo: Option<&PointCloud>,
        ground_z: f64,
        surface: &GridSurface,
        samples: Option<&ScanSurface>,
        grid: &mut RollingGrid,
        st: &mut SensorLabelStats,
    ) -> Result<u64> {
        let FrameLabels {
            cfg,
            caches,
            tally,
            colour_check,
            bufs,
            zbuf,
            pending,
            seen,
            ..
        } = self;
        let map_rays = RayCache::rays_in_map(&mut caches[cue as usize], camera, cam_to_map);
        let (w, h) = (camera.width, camera.height);
        let origin = Point3::from(cam_to_map.translation.vector);
        let max_range = cfg.max_range;
        let mut buf = std::mem::take(bufs);
        buf.cols.clear();
        buf.cols.extend((0..w).step_by(cfg.ray_stride));
        if cfg.wide_rows {
            buf.rows = sampled_rows(
                map_rays,
                w,
                cfg.ray_stride,
                cam_to_map.translation.z - ground_z,
                surface.resolution(),
            );
        } else {
            buf.rows.clear();
            buf.rows.extend((0..h).step_by(cfg.ray_stride));
        }
        let (nr, nc) = (buf.rows.len(), buf.cols.len());
        let zbuf = if cfg.sampler == Sampler::Zbuffer {
            zbuf.draw(
                surface, camera, cam_to_map, map_rays, &buf.rows, &buf.cols, max_range,
            );
            Some(&*zbuf)
        } else {
            None
        };
        let placer = Placer {
            labels: &labels,
            width: w,
            stereo: stereo.and_then(|c| Some((c, stereo_factor(c, w, h)?))),
            stereo_range: cfg.stereo_max_range.min(max_range),
            origin,
            zbuf,
            map_rays,
            surface,
            max_range,
            reach: samples.and_then(|l| l.reach.as_ref()),
        };
        placer.place_all(&buf.rows, &buf.cols, &mut buf.hits, &mut buf.counts);
        // Each camera's water pixels against what the other saw at their points.
        let other = match cue {
            ImageCue::Colour => seen[1].as_ref(),
            ImageCue::Swir => seen[0].as_ref(),
            ImageCue::Mwir => None,
        };
        if let Some(other) = other {
            let n = (nr * nc).min(buf.hits.len());
            if let Some(px) = px.filter(|_| cue == ImageCue::Colour) {
                let sampled = (&buf.rows[..], &buf.cols[..]);
                colour_check.count_swir(&labels, px, &buf.hits[..n], sampled, other);
            }
            // SWIR's "other" bounds colour water physically; colour's does not bound SWIR's.
            st.cross_vetoed += seen_check(&mut buf.hits[..n], other, cue == ImageCue::Colour);
        }
        // Kept for the colour camera's check, which runs after this one.
        if cue == ImageCue::Swir && cfg.colour.is_some() {
            seen[1] = Some((labels.clone(), camera.clone(), *cam_to_map));
        }
        tighten_hole_levels(&mut buf.hits, nc, origin, &mut buf.levels);
        quad_votes(surface, &buf.hits, nr, nc, &mut buf.votes);
        for n in &buf.counts[..nr] {
            st.via_point += n[0];
            st.via_ray += n[1];
            st.no_hit += n[2];
            st.beyond_reach += n[3];
        }
        for l in &labels.data {
            match l {
                Label::Water => st.pixels_water += 1,
                Label::Other | Label::SnowIce => st.pixels_not_water += 1,
                _ => {}
            }
        }
        tally_votes(tally, &buf.votes[..nr]);
        let dropped = match cue {
            ImageCue::Colour | ImageCue::Swir => {
                cell_votes(tally, &mut pending[cue as usize]);
                0
            }
            ImageCue::Mwir => {
                let mut votes = Vec::new();
                cell_votes(tally, &mut votes);
                add_cell_votes(&votes, cue, surface, grid, st)
            }
        };
        if cue == ImageCue::Colour {
            buf.labels = labels.data;
        }
        self.bufs = buf;
        Ok(dropped)
    }

    /// The labels of one sensor's image in the frame ([`Self::classify`]).
    #[allow(clippy::too_many_arguments)]
    fn classify_cue(
        &mut self,
        cue: ImageCue,
        img: &SensorImage,
        camera: &CameraModel,
        cam_to_map: &Pose,
        stereo: Option<&PointCloud>,
        hour: Option<f64>,
        ground_z: f64,
        surface: &GridSurface,
        samples: Option<&ScanSurface>,
        st: &mut SensorLabelStats,
    ) -> Result<LabelImage> {
        let FrameLabels {
            cfg,
            caches,
            colour_check,
            bufs,
            ..
        } = self;
        let map_rays = RayCache::rays_in_map(&mut caches[cue as usize], camera, cam_to_map);
        let view = SensorView {
            cue,
            img,
            camera,
            cam_to_map,
            map_rays,
            stereo,
            hour,
            ground_z,
            samples,
            resolution: surface.resolution(),
        };
        Self::classify(cfg, &view, &mut bufs.labels, colour_check, st)
    }

    /// The labels of the view's image: colour through the lookup table
    /// ([`Self::classify_colour`]), SWIR darkness and MWIR thermal contrast over the ground
    /// geometry of the camera's rays.
    fn classify(
        cfg: &FrameLabelConfig,
        view: &SensorView<'_>,
        buf: &mut Vec<Label>,
        colour_check: &mut ColourCheck,
        st: &mut SensorLabelStats,
    ) -> Result<LabelImage> {
        let SensorView {
            img,
            camera,
            cam_to_map,
            map_rays,
            ground_z,
            ..
        } = *view;
        Ok(match view.cue {
            ImageCue::Colour => Self::classify_colour(cfg, view, buf, colour_check, st)?,
            ImageCue::Swir => {
                let g = GroundGeometry::of_rays(camera, map_rays, cam_to_map, ground_z);
                let l = classify_swir(&mono_of(img), &g, None, cfg.swir.as_ref().expect("cfg"))?;
                if let Some(samples) = view.samples {
                    let a = false_alarms_at(&l, camera, cam_to_map, &samples.dry, view.resolution);
                    st.false_alarms.merge(&a);
                }
                l
            }
            ImageCue::Mwir => {
                let m = cfg.mwir.as_ref().expect("configured");
                let g = GroundGeometry::of_rays(camera, map_rays, cam_to_map, ground_z);
                let hour = view.hour.expect("an MWIR frame without an hour is skipped");
                classify_mwir(&mono_of(img), &g, hour, &m.classifier)?
            }
        })
    }

    /// The colour image's labels, into the storage `buf` (taken): each pixel through the
    /// lookup table, the horizon rule ([`apply_horizon`]), then the checks that veto colour
    /// water: against the sky it would reflect ([`reflection_check`]) and against what the
    /// log's lidar and stereo found under its colour ([`ColourCheck`]).
    fn classify_colour(
        cfg: &FrameLabelConfig,
        view: &SensorView<'_>,
        buf: &mut Vec<Label>,
        colour_check: &mut ColourCheck,
        st: &mut SensorLabelStats,
    ) -> Result<LabelImage> {
        let SensorView {
            img,
            camera,
            cam_to_map,
            map_rays,
            ..
        } = *view;
        let (w, h) = (camera.width, camera.height);
        let lut = cfg.colour.as_ref().expect("configured");
        let Pixels::Rgb8(px) = &img.image.pixels else {
            return Err(Error::invalid(
                "colour image",
                format!("{}: not a colour image", img.image.frame_id),
            ));
        };
        if px.len() != w * h {
            return Err(Error::invalid(
                "colour image",
                format!("{} pixels for {w} × {h}", px.len()),
            ));
        }
        let mut data = std::mem::take(buf);
        data.resize(w * h, Label::Other);
        // Rows in parallel; every label is written.
        data.par_chunks_mut(w.max(1))
            .zip(px.par_chunks(w.max(1)))
            .try_for_each(|(l, p)| lut.classify_into(p.as_flattened(), l))?;
        let mut l = LabelImage {
            width: w,
            height: h,
            data,
        };
        apply_horizon(&mut l, map_rays);
        if let Some(enc) = cfg.reflection_check {
            st.reflection_vetoed += reflection_check(&mut l, px, map_rays, camera, cam_to_map, enc);
        }
        if let Some(samples) = view.samples.filter(|_| cfg.colour_check) {
            let stereo = view.stereo.and_then(|c| Some((c, stereo_factor(c, w, h)?)));
            let (vetoed, alarms) = colour_check.run(
                &mut l,
                px,
                camera,
                cam_to_map,
                samples,
                stereo,
                view.resolution,
            );
            st.colour_check_vetoed += vetoed;
            st.false_alarms.merge(&alarms);
        } else {
            // The colours the SWIR camera found on dry ground in earlier frames.
            st.colour_check_vetoed += colour_check.veto(&mut l, px);
        }
        Ok(l)
    }
}

/// The camera and pose of a sensor image that can be labelled: with camera info of its size
/// and a finite pose.
fn usable_image(i: &SensorImage) -> Option<(&CameraModel, Pose)> {
    let cam = i.camera.as_ref()?;
    let pose = i.frame_to_map.filter(pose_is_finite)?;
    (cam.width == i.image.width && cam.height == i.image.height).then_some((cam, pose))
}

/// One sensor's image in one frame, and what its labels are placed with.
struct SensorView<'a> {
    cue: ImageCue,
    img: &'a SensorImage,
    camera: &'a CameraModel,
    cam_to_map: &'a Pose,
    /// The camera's unit pixel rays in the map frame, row-major.
    map_rays: &'a [Option<Vector3<f64>>],
    /// The stereo cloud registered to the image (colour only).
    stereo: Option<&'a PointCloud>,
    /// The local solar hour (MWIR only).
    hour: Option<f64>,
    /// The ground's height under the vehicle.
    ground_z: f64,
    /// Where the frame's lidar found the surface dry or wet.
    samples: Option<&'a ScanSurface>,
    /// The map's cell size (m).
    resolution: f64,
}

/// [`Tally::slot`] of a cell no pixel of the frame fell in.
const NO_SLOT: u32 = u32::MAX;

/// A frame's pixels per cell: a slot per raster cell into the counts of the cells that got
/// any, so that the counts take 4 bytes a window cell and 20 a cell the frame's pixels
/// fell in (a dense tally took 16 a window cell).
#[derive(Debug, Clone, Default)]
struct Tally {
    /// Per raster cell: its slot in `counts` and `touched`, [`NO_SLOT`] before its first
    /// pixel of the frame.
    slot: Vec<u32>,
    /// Per touched cell: water pixels, other pixels, Σ z of the water pixels' hits.
    counts: Vec<(u32, u32, f64)>,
    /// Per touched cell: its raster index.
    touched: Vec<u32>,
}

/// Adds the rows' `votes` to the per-cell `tally` (water pixels, other pixels, Σ level of
/// the water pixels), giving each cell its slot as it gets its first vote.
fn tally_votes(tally: &mut Tally, votes: &[Vec<(u32, bool, f32)>]) {
    let Tally {
        slot,
        counts,
        touched,
    } = tally;
    for out in votes {
        for &(j, water, z) in out {
            let s = &mut slot[j as usize];
            if *s == NO_SLOT {
                *s = counts.len() as u32;
                counts.push((0, 0, 0.0));
                touched.push(j);
            }
            let t = &mut counts[*s as usize];
            if water {
                t.0 += 1;
                t.2 += z as f64;
            } else {
                t.1 += 1;
            }
        }
    }
}

/// One vote per touched cell of the `tally` (emptied), into `out`, in raster order: the
/// majority of its pixels, a tie no vote, water with the mean of its levels.
fn cell_votes(tally: &mut Tally, out: &mut Vec<CellVote>) {
    let Tally {
        slot,
        counts,
        touched,
    } = tally;
    // Cells in raster order: deterministic whatever the thread count.
    touched.sort_unstable();
    out.clear();
    for &j in touched.iter() {
        let s = std::mem::replace(&mut slot[j as usize], NO_SLOT);
        let (wn, dn, zs) = counts[s as usize];
        let water = match wn.cmp(&dn) {
            std::cmp::Ordering::Greater => true,
            std::cmp::Ordering::Less => false,
            std::cmp::Ordering::Equal => continue,
        };
        let level = if water { zs / wn as f64 } else { 0.0 };
        out.push(CellVote {
            cell: j,
            water,
            level,
        });
    }
    touched.clear();
    counts.clear();
}

/// One camera's water pixels checked against the other camera's labels of the same frame
/// (`seen`: labels, camera, pose), point by point, where the other camera labels the placed
/// point not water ([`Label::Other`], or snow/ice). Colour water that SWIR sees brighter
/// than a reflection could be is sky-coloured but no reflection of the sky (a pale slab,
/// sunlit concrete, paint, snow): SWIR's "other" is that physical bound, so the pixel
/// votes dry (`turn_dry`). SWIR water that the colour camera sees not sky-coloured is a
/// dark dry surface (asphalt, wet soil, shadow, a mud bank) or water mirroring something
/// other than the sky (the far half of a pond mirroring its far bank), which the colour
/// camera's "other" cannot tell apart: the pixel loses its vote, and the colour camera's
/// own vote there stands. Where the other camera cannot tell (unknown, sky, outside its
/// image) the pixel keeps its label. Returns the pixels turned or dropped.
fn seen_check(hits: &mut [Option<Hit>], seen: &Seen, turn_dry: bool) -> u64 {
    let (labels, camera, cam_to_map) = seen;
    let to_cam = cam_to_map.inverse();
    let mut turned = 0;
    for slot in hits.iter_mut() {
        let Some(h) = slot.as_mut().filter(|h| h.wet) else {
            continue;
        };
        let Some([u, v]) = camera.project(&(to_cam * h.p)) else {
            continue;
        };
        let (u, v) = (u.round(), v.round());
        if !(u >= 0.0 && v >= 0.0 && u < labels.width as f64 && v < labels.height as f64) {
            continue;
        }
        if matches!(
            labels.data[v as usize * labels.width + u as usize],
            Label::Other | Label::SnowIce
        ) {
            if turn_dry {
                h.wet = false;
            } else {
                *slot = None;
            }
            turned += 1;
        }
    }
    turned
}

/// The cross-spectral check of one frame's colour and SWIR cell votes (each in raster
/// order): where both cameras vote on a cell, a water vote stands only where the other
/// camera votes water too. Water that mirrors the sky is sky-coloured in colour *and* dark
/// in SWIR; a pale slab or sunlit concrete is sky-coloured but brighter in SWIR than a
/// reflection of the sky could be; asphalt, paint, wet soil and shadow are dark in SWIR
/// but not sky-coloured; snow and ice, bright in colour, are darker in SWIR than water
/// mirroring the sky at their incidence could be, or brighter in colour than the colour
/// reflection check allows. A vote against water always stands: a cue fooled into
/// "water" is vetoed by the other, and one that cannot tell casts no vote. Returns the
/// colour and the SWIR water votes dropped.
fn cross_check(colour: &mut Vec<CellVote>, swir: &mut Vec<CellVote>) -> (u64, u64) {
    let (mut i, mut j) = (0, 0);
    let (mut drop_c, mut drop_s) = (Vec::new(), Vec::new());
    while i < colour.len() && j < swir.len() {
        let (c, s) = (&colour[i], &swir[j]);
        match c.cell.cmp(&s.cell) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                if c.water && !s.water {
                    drop_c.push(i);
                } else if s.water && !c.water {
                    drop_s.push(j);
                }
                i += 1;
                j += 1;
            }
        }
    }
    let remove = |v: &mut Vec<CellVote>, idx: &[usize]| {
        let mut k = 0;
        let mut n = 0;
        v.retain(|_| {
            let keep = idx.get(k) != Some(&n);
            if !keep {
                k += 1;
            }
            n += 1;
            keep
        });
    };
    remove(colour, &drop_c);
    remove(swir, &drop_s);
    (drop_c.len() as u64, drop_s.len() as u64)
}

/// Adds one frame's cell `votes` of `cue` to `grid`'s evidence, water with its level as a
/// level sample. Returns the votes that fell outside `grid`'s window.
fn add_cell_votes(
    votes: &[CellVote],
    cue: ImageCue,
    surface: &GridSurface,
    grid: &mut RollingGrid,
    st: &mut SensorLabelStats,
) -> u64 {
    let (nw, o) = (surface.size(), surface.origin());
    let z_ref = grid.config().z_ref;
    let mut dropped = 0;
    for v in votes {
        let mut e = Evidence::default();
        e.add_image_vote(cue.cue(), v.water);
        if v.water {
            st.cells_water += 1;
            e.add_level(((v.level - z_ref) * 1000.0).round() as i32);
        } else {
            st.cells_dry += 1;
        }
        let j = v.cell as usize;
        let key = CellKey::new(o.x + (j % nw) as i64, o.y + (j / nw) as i64);
        if !grid.add_evidence(key, &e) {
            dropped += 1;
        }
    }
    dropped
}

#[cfg(test)]
mod tests;
