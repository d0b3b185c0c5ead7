//! What a scan's walked lines add up to: each line's events written into the evidence map,
//! the corrected cloud, the counts, the reflectivity cue's samples and the surface points.

use nalgebra::{Point3, Vector3};

use super::walk::Event;
use super::{LidarCueStats, LidarCues, ScanSurface};
use crate::cues::reflectivity::{ChannelLaw, ReflectivityConfig, ReflectivitySample};
use crate::cues::EvidenceMap;
use crate::geom::PointCloud;

/// The scan's results as its events come in.
pub(super) struct Tally<'a> {
    cloud: &'a PointCloud,
    /// Whether the dry and wet points of [`ScanSurface`] are collected.
    surface_points: bool,
    /// Whether the reflectivity cue runs (ground returns become its samples).
    reflectivity: bool,
    ev: EvidenceMap,
    corrected: PointCloud,
    stats: LidarCueStats,
    samples: Vec<ReflectivitySample>,
    pub(super) surface: ScanSurface,
}

impl<'a> Tally<'a> {
    /// Nothing seen yet: the evidence map `ev` and the `corrected` cloud as the scan
    /// starts them, and the scan's slots, missing slots and those without a direction
    /// (`dirs`) counted.
    pub(super) fn new(
        cloud: &'a PointCloud,
        dirs: &[Option<Vector3<f64>>],
        surface_points: bool,
        reflectivity: bool,
        ev: EvidenceMap,
        corrected: PointCloud,
    ) -> Self {
        let n = cloud.len();
        let stats = LidarCueStats {
            slots: n as u64,
            missing: (n - cloud.valid_count()) as u64,
            no_direction: dirs
                .iter()
                .enumerate()
                .filter(|(i, d)| d.is_none() && !cloud.is_valid(*i))
                .count() as u64,
            ..LidarCueStats::default()
        };
        Tally {
            cloud,
            surface_points,
            reflectivity,
            ev,
            corrected,
            stats,
            samples: Vec::new(),
            surface: ScanSurface::default(),
        }
    }

    /// One event of a line whose dry ground returned from as far as `limit` (infinite
    /// when the scan's dry limit is off).
    pub(super) fn add(&mut self, e: &Event, limit: f64) {
        let stats = &mut self.stats;
        match *e {
            Event::MissingCast => stats.missing_cast += 1,
            Event::Unexplained => stats.unexplained += 1,
            Event::BelowGround => stats.below_ground += 1,
            Event::NoRet { d, .. } if d > limit => {
                stats.missing_cast += 1;
                stats.noret_beyond_dry += 1;
            }
            Event::NoRet { x, y, level, d } => self.no_return(x, y, level, d),
            Event::Ground {
                slot,
                x,
                y,
                diag,
                bright,
                cos_inc,
                range,
            } => {
                if bright && self.surface_points {
                    self.surface.dry.push(self.cloud.point_in_map(slot));
                }
                if diag {
                    stats.diag_ret += 1;
                    if let Some(e) = self.ev.at(x, y) {
                        e.diag_ret = e.diag_ret.saturating_add(1);
                    }
                }
                if self.reflectivity {
                    self.samples.push(ReflectivitySample {
                        slot,
                        x,
                        y,
                        cos_inc,
                        range,
                    });
                }
            }
            Event::Bottom {
                slot,
                x,
                y,
                level,
                depth,
                gain,
                prior,
            } => {
                stats.bottom += 1;
                stats.bottom_under_prior += prior as u64;
                let mm = self.ev.level_mm(level);
                self.ev.add_with_level(x, y, level, |e| match mm {
                    Some(mm) => e.add_bottom_return(depth, mm, gain),
                    None => e.add_depth(depth),
                });
                self.corrected.xyz[slot] = [f32::NAN; 3];
                if self.surface_points {
                    self.surface.wet.push(Point3::new(x, y, level));
                }
            }
            Event::Specular {
                slot,
                cx,
                cy,
                level,
            } => {
                stats.specular += 1;
                self.ev
                    .add_with_level(cx, cy, level, |e| e.reflect = e.reflect.saturating_add(1));
                if self.surface_points {
                    self.surface.wet.push(Point3::new(cx, cy, level));
                }
                self.corrected.xyz[slot] = [f32::NAN; 3];
            }
        }
    }

    /// A missing beam meeting the level at (x, y) inside the interval, at lookahead `d`
    /// within the line's dry limit: a no-return count there.
    fn no_return(&mut self, x: f64, y: f64, level: f64, d: f64) {
        let stats = &mut self.stats;
        stats.missing_cast += 1;
        stats.noret += 1;
        let mm = (d * 1000.0).round() as u64;
        let [lo, hi] = stats.noret_lookahead_mm.unwrap_or([mm, mm]);
        stats.noret_lookahead_mm = Some([lo.min(mm), hi.max(mm)]);
        self.ev
            .add_with_level(x, y, level, |e| e.noret = e.noret.saturating_add(1));
        if self.surface_points {
            self.surface.wet.push(Point3::new(x, y, level));
        }
    }

    /// The reflectivity cue over the scan's ground returns, with `rc` its settings: its
    /// dark threshold and the channel's law, when it ran.
    pub(super) fn reflectivity(
        &mut self,
        rc: Option<&ReflectivityConfig>,
    ) -> (Option<f64>, Option<ChannelLaw>) {
        let (mut reference, mut law) = (None, None);
        if let Some(rc) = rc {
            if let Some(r) =
                crate::cues::reflectivity::apply(self.cloud, rc, &self.samples, &mut self.ev)
            {
                self.stats.dark = r.dark;
                self.stats.lit = r.lit;
                reference = Some(r.threshold);
                law = Some(r.law);
            }
        }
        (reference, law)
    }

    /// The scan's cues, with the reflectivity cue's threshold and law.
    pub(super) fn into_cues(
        self,
        reflectivity_threshold: Option<f64>,
        reflectivity_law: Option<ChannelLaw>,
    ) -> LidarCues {
        LidarCues {
            evidence: self.ev,
            corrected: self.corrected,
            stats: self.stats,
            reflectivity_threshold,
            reflectivity_law,
            surface: self.surface,
        }
    }
}
