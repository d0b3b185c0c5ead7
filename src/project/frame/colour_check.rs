//! The colour classifier checked by the log's lidar and stereo ([`ColourCheck`]).

use nalgebra::Point3;

use super::place::Hit;
use super::Seen;
use crate::classify::{Label, LabelImage};
use crate::cues::{ScanSurface, StereoSeen};
use crate::geom::{CameraModel, PointCloud, Pose};
use crate::grid::FalseAlarms;

/// Bits per channel of the colour bins the [`ColourCheck`] counts in.
const CHECK_BITS: u32 = 4;
/// One-sided 5 % point of the standard normal: the [`ColourCheck`]'s sign test.
const CHECK_Z: f64 = 1.645;

/// Whether pixel `(u, v)` and the eight around it (those inside the image) are all colour
/// water: only there does a sample tell which side of the water's edge it lies on. A lidar
/// point's projection is rounded to the nearest pixel, a stereo element's disparity is
/// matched over a window of pixels, and the label's edge is itself a pixel wide: a return
/// from the dry rim of a puddle lands on the puddle's edge pixels as often as on the rim's,
/// and a stereo match there may be the rim's texture.
fn inside_water(labels: &LabelImage, u: usize, v: usize) -> bool {
    let (w, h) = (labels.width, labels.height);
    (v.saturating_sub(1)..(v + 2).min(h)).all(|y| {
        (u.saturating_sub(1)..(u + 2).min(w)).all(|x| labels.data[y * w + x] == Label::Water)
    })
}

/// The colour classifier checked by the lidar, over a log. The paper's rule calls whatever
/// is bright and weakly saturated water, which pale concrete, a pale slab and snow are too:
/// the cue's false-alarm rate is then not the few per cent the fusion rule assumes but a
/// property of the scene. The lidar measures it. Each frame, the points where the scan
/// found dry ground (returns water would not give) and water (missing beams inside the
/// diagnostic interval, bottom and specular returns where their beams cross the water) are
/// projected into the colour image; a water pixel there, inside the water's edge
/// ([`inside_water`]), counts for its colour bin (4 bits a channel) as seen on dry ground
/// or on water. A colour the lidar finds on dry ground
/// more often than on water, by a one-sided sign test at 5 % (`dry − wet ≥ 1.645
/// √(dry + wet + 1)`, the normal form: four dry samples and none wet suffice), is not
/// evidence of water in this log: its pixels become `Unknown` and place no vote, near or
/// beyond the lidar's reach. The counts
/// go on whether a colour is vetoed or not, so a verdict follows the log. On a rig with
/// stereo the stereo elements registered to the image are samples too ([`StereoSeen`]): a
/// point at the local ground level within its own vertical noise is a dry one, a
/// reflection (the mirror image well below the level) one against. A missing
/// match counts for neither: still water mirroring the sky gives none, and neither do snow
/// and pale concrete without texture, the colours the check is for. A SWIR camera's
/// verdicts at the placed colour water pixels count too ([`ColourCheck::count_swir`]), one
/// frame late, with or without range sensors. Without any of these sensors nothing is
/// counted and nothing vetoed: the check says nothing where it cannot tell.
///
/// The lidar's dry samples also measure the labels' false-alarm rate after the veto
/// ([`FalseAlarms`]), which the fusion rule reads in place of a stated one. A sample is
/// what the rule's event is, a map cell in a frame: the cells holding dry samples, each
/// called water or not by the majority of its samples' labelled pixels (a tie is no
/// sample, as it is no vote). The points of one cell are one patch of ground, not
/// independent draws. The stereo's do not: stereo
/// matches textured ground, which the colour rule gets right, and finds no match on the
/// pale, smooth surfaces it calls water, so its samples would measure a rate far below
/// the one the labels' votes have there.
#[derive(Debug, Clone, Default)]
pub(super) struct ColourCheck {
    /// Per bin: lidar samples on dry ground and on water whose pixel is colour water.
    dry: Vec<u32>,
    wet: Vec<u32>,
}

impl ColourCheck {
    fn bin([r, g, b]: [u8; 3]) -> usize {
        let k = 8 - CHECK_BITS;
        ((r as usize >> k) << (2 * CHECK_BITS))
            | ((g as usize >> k) << CHECK_BITS)
            | (b as usize >> k)
    }

    /// One more dry (or wet) sample of `colour`.
    fn count(&mut self, colour: [u8; 3], dry: bool) {
        let b = Self::bin(colour);
        let n = if dry {
            &mut self.dry[b]
        } else {
            &mut self.wet[b]
        };
        *n = n.saturating_add(1);
    }

    fn vetoed(&self, bin: usize) -> bool {
        let (d, w) = (f64::from(self.dry[bin]), f64::from(self.wet[bin]));
        d - w >= CHECK_Z * (d + w + 1.0).sqrt()
    }

    /// Counts the frame's lidar `samples`, and the verdicts of the stereo `(cloud, k)`
    /// registered to the image at `1/k` of its resolution, that land on colour water, then
    /// takes the water label from pixels of vetoed colours ([`Self::veto`]). Returns the
    /// pixels vetoed and the frame's false alarms, after the veto, over the map cells
    /// (`resolution` m) its lidar dry samples lie in.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn run(
        &mut self,
        labels: &mut LabelImage,
        px: &[[u8; 3]],
        camera: &CameraModel,
        cam_to_map: &Pose,
        samples: &ScanSurface,
        stereo: Option<(&PointCloud, usize)>,
        resolution: f64,
    ) -> (u64, FalseAlarms) {
        self.bins();
        let (w, h) = (labels.width, labels.height);
        if let Some((cloud, k)) = stereo.filter(|(c, _)| c.len() == samples.stereo.len()) {
            let half = (k - 1) / 2;
            for (e, seen) in samples.stereo.iter().enumerate() {
                let dry = match seen {
                    StereoSeen::Nothing => continue,
                    StereoSeen::Ground => true,
                    StereoSeen::NotGround => false,
                };
                let (u, v) = (k * (e % cloud.cols) + half, k * (e / cloud.cols) + half);
                if u >= w || v >= h || !inside_water(labels, u, v) {
                    continue;
                }
                self.count(px[v * w + u], dry);
            }
        }
        let to_cam = cam_to_map.inverse();
        for (points, dry) in [(&samples.dry, true), (&samples.wet, false)] {
            for p in points {
                let Some([u, v]) = camera.project(&(to_cam * p)) else {
                    continue;
                };
                let (u, v) = (u.round(), v.round());
                if !(u >= 0.0 && v >= 0.0 && u < w as f64 && v < h as f64) {
                    continue;
                }
                let (u, v) = (u as usize, v as usize);
                if !inside_water(labels, u, v) {
                    continue;
                }
                self.count(px[v * w + u], dry);
            }
        }
        let vetoed = self.veto(labels, px);
        let alarms = false_alarms_at(labels, camera, cam_to_map, &samples.dry, resolution);
        (vetoed, alarms)
    }

    /// Counts what the SWIR camera of the same frame (`swir`: its labels, camera and pose)
    /// says at the colour water pixels placed on the map (`hits` of the sampled `rows` ×
    /// `cols`, row-major), inside the water's edge: brighter than any reflection (SWIR
    /// "other", a physical bound) is a dry sample of the pixel's colour, a sky reflection
    /// (SWIR water) a wet one. So a colour that SWIR sees on dry ground more often than on
    /// water is vetoed from the next frame on, in the whole image: on a rig without range
    /// sensors, where the SWIR camera does not see as well as where it does.
    pub(super) fn count_swir(
        &mut self,
        labels: &LabelImage,
        px: &[[u8; 3]],
        hits: &[Option<Hit>],
        (rows, cols): (&[usize], &[usize]),
        swir: &Seen,
    ) {
        self.bins();
        let (sl, camera, cam_to_map) = swir;
        let to_cam = cam_to_map.inverse();
        let w = labels.width;
        for (k, h) in hits.iter().enumerate() {
            let Some(h) = h.filter(|h| h.wet) else {
                continue;
            };
            let (x, y) = (cols[k % cols.len()], rows[k / cols.len()]);
            if !inside_water(labels, x, y) {
                continue;
            }
            let Some([u, v]) = camera.project(&(to_cam * h.p)) else {
                continue;
            };
            let (u, v) = (u.round(), v.round());
            if !(u >= 0.0 && v >= 0.0 && u < sl.width as f64 && v < sl.height as f64) {
                continue;
            }
            match sl.data[v as usize * sl.width + u as usize] {
                Label::Other | Label::SnowIce => self.count(px[y * w + x], true),
                Label::Water => self.count(px[y * w + x], false),
                Label::Sky | Label::Unknown => {}
            }
        }
    }

    /// Takes the water label from pixels of vetoed colours: those found on dry ground more
    /// often than on water so far. Returns the pixels vetoed.
    pub(super) fn veto(&self, labels: &mut LabelImage, px: &[[u8; 3]]) -> u64 {
        if self.dry.is_empty() {
            return 0;
        }
        let mut vetoed = 0;
        for (l, &c) in labels.data.iter_mut().zip(px) {
            if *l == Label::Water && self.vetoed(Self::bin(c)) {
                *l = Label::Unknown;
                vetoed += 1;
            }
        }
        vetoed
    }

    fn bins(&mut self) {
        let bins = 1 << (3 * CHECK_BITS);
        self.dry.resize(bins, 0);
        self.wet.resize(bins, 0);
    }
}

/// A camera's false alarms on the lidar's dry samples `dry` (map frame) of one frame: the
/// map cells (`resolution` m) holding samples that project into the image, each called
/// water or not by the majority of its samples' labelled pixels (a tie is no sample, as it
/// is no vote). The event is the fusion rule's, a map cell in a frame: the points of one
/// cell are one patch of ground, not independent draws.
pub(super) fn false_alarms_at(
    labels: &LabelImage,
    camera: &CameraModel,
    cam_to_map: &Pose,
    dry: &[Point3<f64>],
    resolution: f64,
) -> FalseAlarms {
    let (w, h) = (labels.width, labels.height);
    let to_cam = cam_to_map.inverse();
    let cell = |c: f64| (c / resolution).floor() as i64;
    let mut px: Vec<((i64, i64), usize)> = dry
        .iter()
        .filter_map(|p| {
            let [u, v] = camera.project(&(to_cam * p))?;
            let (u, v) = (u.round(), v.round());
            (u >= 0.0 && v >= 0.0 && u < w as f64 && v < h as f64)
                .then(|| ((cell(p.x), cell(p.y)), v as usize * w + u as usize))
        })
        .collect();
    px.sort_unstable();
    let mut alarms = FalseAlarms::default();
    for cell in px.chunk_by(|a, b| a.0 == b.0) {
        let (mut water, mut dry) = (0u32, 0u32);
        for &(_, i) in cell {
            match labels.data[i] {
                Label::Water => water += 1,
                Label::Other | Label::SnowIce => dry += 1,
                _ => {}
            }
        }
        if water != dry {
            alarms.samples += 1;
            alarms.water += u64::from(water > dry);
        }
    }
    alarms
}
