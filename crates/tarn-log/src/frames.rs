//! A time-synchronized stream of [`Frame`]s from a ROS 2 log: each scan of the frame topic
//! (the lidar by default, or the stereo cloud) with the vehicle pose at its own stamp, and
//! the other clouds and images nearest in time within a tolerance.
//!
//! The stream reads the log once, front to back. It holds back a scan only until the log
//! has moved `tolerance + lookahead` seconds past it (so that transforms and images stamped
//! after it have arrived), then emits it and forgets what is older: memory depends on the
//! message rate and those two durations, never on the length of the log.
//!
//! What the stream reads (topics, frames, timing) is [`LogConfig`], in its own submodule.

use std::collections::{BTreeMap, VecDeque};
use std::path::Path;

use nalgebra::{Point3, Vector3};

use crate::error::{Error, Result};
use crate::geom::{CameraModel, PointCloud, Pose};
use crate::log::{canonical_type, wire_of, MessageSource};
use crate::mcap_log::{DamagedRange, LogReader, RawMessage};
use crate::ros::{
    camera_from_info, decode_image, pointcloud2_to_cloud, schema_name, CameraInfoMsg, ImageMsg,
    NavSatFixMsg, PointCloud2Msg, TfMessage,
};
use crate::sensor::{Frame, Image, SensorImage};
use crate::tf::TfBuffer;

mod config;

pub use config::{LogConfig, NamedTopics, POSE_JUMP_CONFIRM, POSE_JUMP_SLACK_M};

/// The baseline (m) of a stereo pair from its right camera's rectified projection:
/// ROS stereo drivers publish `P[0][3] = −f·B` (`f = P[0][0]`).
pub(crate) fn stereo_baseline(right: &CameraInfoMsg) -> std::result::Result<f64, String> {
    let (f, tx) = (right.p[0], right.p[3]);
    let b = -tx / f;
    if f.is_finite() && f > 0.0 && b.is_finite() && b > 0.0 {
        Ok(b)
    } else {
        Err(format!(
            "right camera P[0][0] = {f}, P[0][3] = {tx}: no baseline (P[0][3] must be −f·B, B > 0)"
        ))
    }
}

/// What happened while streaming.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameStats {
    /// Messages read from the log.
    pub messages: u64,
    /// Frames emitted.
    pub frames_built: u64,
    /// Frames whose scan had no transform to the map at its stamp.
    pub frames_skipped_no_tf: u64,
    /// Reasons for the first skipped frames (up to 20).
    pub skip_reasons: Vec<String>,
    /// Matched clouds or images dropped for want of a transform.
    pub secondary_dropped_no_tf: u64,
    /// Messages whose type tarn does not read, by `topic (type)`.
    pub unknown_type: BTreeMap<String, u64>,
    /// Messages of known type that could not be decoded (each also yielded as an error).
    pub decode_errors: u64,
    /// Frames refused because their pose jumped farther than `max_speed_mps` allows (each
    /// named in `skip_reasons` while there is room).
    #[serde(default)]
    pub frames_refused_pose_jump: u64,
}

impl FrameStats {
    /// Messages of types tarn does not read, all topics together.
    pub fn unknown_type_total(&self) -> u64 {
        self.unknown_type.values().sum()
    }
}

const MAX_REASONS: usize = 20;

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Slot {
    Lidar,
    Stereo,
    Image,
    Swir,
    Mwir,
}

struct Pending<T> {
    ns: i64,
    item: T,
}

/// The frame stream. Iterate for `Result<Frame>`; an `Err` for one bad message does not
/// end the stream. Damaged parts of the file are skipped by the reader and listed in
/// [`FrameStream::damaged`]; only a file that is not a log or cannot be read ends the
/// stream with an `Err` (after the frames of everything before it).
pub struct FrameStream {
    cfg: LogConfig,
    reader: Box<dyn MessageSource>,
    tf: TfBuffer,
    /// Scans of the frame topic waiting for the log to move past them.
    scans: VecDeque<Pending<(PointCloud, String)>>,
    other_clouds: VecDeque<Pending<(PointCloud, String)>>,
    images: [VecDeque<Pending<Image>>; 3],
    infos: [Option<CameraModel>; 3],
    baseline_m: Option<f64>,
    geo: Option<(f64, f64)>,
    /// Latest log time seen, ns.
    now_ns: i64,
    stats: FrameStats,
    /// The read error that ended the stream (not a log, or the file could not be read).
    fatal: Option<String>,
    /// Stamp (ns) and position of the last accepted frame's `base_frame`.
    last_pose: Option<(i64, Vector3<f64>)>,
    /// Refused frames in a row that agree with each other: the last one and how many.
    jump_run: Option<(i64, Vector3<f64>, u32)>,
    ended: bool,
    out: VecDeque<Result<Frame>>,
}

fn secs(ns: i64) -> f64 {
    ns as f64 * 1e-9
}

impl FrameStream {
    /// The frame stream of the log at `path`: any storage [`crate::log::open`] reads.
    pub fn open(path: impl AsRef<Path>, cfg: &LogConfig) -> Result<Self> {
        cfg.validate()?;
        Self::from_source(crate::log::open(path)?, cfg)
    }

    /// The frame stream of an already opened MCAP log (e.g. [`LogReader::from_bytes`]).
    pub fn from_reader(reader: LogReader, cfg: &LogConfig) -> Result<Self> {
        Self::from_source(Box::new(reader), cfg)
    }

    /// The frame stream of any opened log.
    pub fn from_source(reader: Box<dyn MessageSource>, cfg: &LogConfig) -> Result<Self> {
        cfg.validate()?;
        Ok(FrameStream {
            cfg: cfg.clone(),
            reader,
            tf: TfBuffer::new(),
            scans: VecDeque::new(),
            other_clouds: VecDeque::new(),
            images: Default::default(),
            infos: Default::default(),
            baseline_m: None,
            geo: None,
            now_ns: i64::MIN,
            stats: FrameStats::default(),
            fatal: None,
            last_pose: None,
            jump_run: None,
            ended: false,
            out: VecDeque::new(),
        })
    }

    /// What happened so far.
    pub fn stats(&self) -> &FrameStats {
        &self.stats
    }

    /// The parts of the log skipped as damaged so far, in file order.
    pub fn damaged(&self) -> &[DamagedRange] {
        self.reader.damaged()
    }

    /// The error that ended the stream early, if one did: the file is not an MCAP log or
    /// could not be read (damage inside a log is skipped, not fatal: [`Self::damaged`]).
    pub fn fatal_error(&self) -> Option<&str> {
        self.fatal.as_deref()
    }

    /// Bytes read of the log, and its size in bytes.
    pub fn progress(&self) -> (u64, u64) {
        (self.reader.bytes_read(), self.reader.total_bytes())
    }

    /// Messages held in memory waiting to be matched (for memory checks).
    pub fn buffered(&self) -> usize {
        self.scans.len()
            + self.other_clouds.len()
            + self.images.iter().map(|q| q.len()).sum::<usize>()
            + self.tf.len()
    }

    fn slot(&self, topic: &str) -> Option<Slot> {
        let c = &self.cfg;
        if topic == c.lidar_topic {
            Some(Slot::Lidar)
        } else if topic == c.stereo_topic {
            Some(Slot::Stereo)
        } else if topic == c.image_topic {
            Some(Slot::Image)
        } else if topic == c.swir_topic {
            Some(Slot::Swir)
        } else if topic == c.mwir_topic {
            Some(Slot::Mwir)
        } else {
            None
        }
    }

    fn bad(&mut self, m: &RawMessage, e: impl std::fmt::Display) -> Error {
        self.stats.decode_errors += 1;
        Error::format(
            self.reader.path(),
            format!(
                "topic {} ({}), message {} at log time {:.9} s",
                m.channel.topic,
                m.channel.schema,
                self.reader.messages_read() - 1,
                m.log_time as f64 * 1e-9
            ),
            e.to_string(),
        )
    }

    /// Takes one message in; returns an error for a message that cannot be decoded.
    fn ingest(&mut self, m: RawMessage) -> Result<()> {
        self.stats.messages += 1;
        self.now_ns = self.now_ns.max(m.log_time as i64);
        let ch = m.channel.clone();
        let (Some(kind), Some(wire)) = (canonical_type(&ch.schema), wire_of(&ch.message_encoding))
        else {
            *self
                .stats
                .unknown_type
                .entry(format!(
                    "{} ({})",
                    ch.topic,
                    if ch.schema.is_empty() {
                        &ch.message_encoding
                    } else {
                        &ch.schema
                    }
                ))
                .or_insert(0) += 1;
            return Ok(());
        };
        let stamp_or_log = |ns: i64| if ns == 0 { m.log_time as i64 } else { ns };
        match kind {
            schema_name::TF_MESSAGE => {
                let is_static = ch.topic == self.cfg.tf_static_topic;
                if is_static || ch.topic == self.cfg.tf_topic {
                    let tf = TfMessage::decode_wire(&m.data, wire).map_err(|e| self.bad(&m, e))?;
                    for t in &tf.transforms {
                        self.tf.insert(t, is_static);
                    }
                }
            }
            schema_name::CAMERA_INFO => {
                if ch.topic == self.cfg.right_camera_info_topic {
                    let info =
                        CameraInfoMsg::decode_wire(&m.data, wire).map_err(|e| self.bad(&m, e))?;
                    self.baseline_m = Some(stereo_baseline(&info).map_err(|e| self.bad(&m, e))?);
                    return Ok(());
                }
                let k = if ch.topic == self.cfg.camera_info_topic {
                    0
                } else if ch.topic == self.cfg.swir_info_topic {
                    1
                } else if ch.topic == self.cfg.mwir_info_topic {
                    2
                } else {
                    return Ok(());
                };
                let info =
                    CameraInfoMsg::decode_wire(&m.data, wire).map_err(|e| self.bad(&m, e))?;
                self.infos[k] = Some(camera_from_info(&info).map_err(|e| self.bad(&m, e))?);
            }
            schema_name::NAV_SAT_FIX => {
                if ch.topic == self.cfg.gps_topic {
                    let fix =
                        NavSatFixMsg::decode_wire(&m.data, wire).map_err(|e| self.bad(&m, e))?;
                    // A receiver without a fix says so every message: not an error, and
                    // the last good fix stands.
                    match fix.position() {
                        Ok(p) => self.geo = Some(p),
                        Err(_) if fix.status < 0 => {}
                        Err(why) => return Err(self.bad(&m, why)),
                    }
                }
            }
            schema_name::POINT_CLOUD2 => {
                if !matches!(self.slot(&ch.topic), Some(Slot::Lidar | Slot::Stereo)) {
                    return Ok(());
                }
                let msg =
                    PointCloud2Msg::decode_wire(&m.data, wire).map_err(|e| self.bad(&m, e))?;
                let mut cloud = pointcloud2_to_cloud(&msg).map_err(|e| self.bad(&m, e))?;
                let ns = stamp_or_log(msg.header.stamp.to_nanos());
                cloud.stamp = secs(ns);
                cloud.sensor_origin = Point3::origin();
                let entry = Pending {
                    ns,
                    item: (cloud, msg.header.frame_id),
                };
                if ch.topic == self.cfg.frame_topic {
                    self.scans.push_back(entry);
                } else {
                    self.other_clouds.push_back(entry);
                }
            }
            _ => {
                let k = match self.slot(&ch.topic) {
                    Some(Slot::Image) => 0,
                    Some(Slot::Swir) => 1,
                    Some(Slot::Mwir) => 2,
                    _ => return Ok(()),
                };
                let msg = ImageMsg::decode_wire(&m.data, wire).map_err(|e| self.bad(&m, e))?;
                let img = decode_image(&msg).map_err(|e| self.bad(&m, e))?;
                let ns = stamp_or_log(msg.header.stamp.to_nanos());
                self.images[k].push_back(Pending {
                    ns,
                    item: Image {
                        stamp: secs(ns),
                        ..img
                    },
                });
            }
        }
        Ok(())
    }
}

impl FrameStream {
    fn horizon_ns(&self) -> i64 {
        ((self.cfg.tolerance_s + self.cfg.lookahead_s) * 1e9) as i64
    }

    fn tol_ns(&self) -> i64 {
        (self.cfg.tolerance_s * 1e9) as i64
    }

    /// Pose of `frame` in the map at `ns`.
    fn to_map(&self, frame: &str, ns: i64) -> std::result::Result<Pose, String> {
        self.tf
            .lookup(&self.cfg.map_frame, frame, ns)
            .map_err(|e| e.to_string())
    }

    fn nearest<T: Clone>(q: &VecDeque<Pending<T>>, ns: i64, tol: i64) -> Option<&Pending<T>> {
        q.iter()
            .filter(|p| (p.ns - ns).abs() <= tol)
            .min_by_key(|p| ((p.ns - ns).abs(), p.ns))
    }

    fn matched_image(&mut self, k: usize, ns: i64) -> Option<SensorImage> {
        let p = Self::nearest(&self.images[k], ns, self.tol_ns())?;
        let image = p.item.clone();
        let pose = self.to_map(&image.frame_id, p.ns);
        if pose.is_err() {
            self.stats.secondary_dropped_no_tf += 1;
        }
        Some(SensorImage {
            camera: self.infos[k].clone(),
            frame_to_map: pose.ok(),
            image,
        })
    }

    fn build(&mut self, scan: Pending<(PointCloud, String)>) -> Option<Frame> {
        let ns = scan.ns;
        let (mut cloud, frame_id) = scan.item;
        let poses = self
            .to_map(&self.cfg.base_frame, ns)
            .and_then(|b| self.to_map(&frame_id, ns).map(|c| (b, c)));
        let (base_to_map, cloud_to_map) = match poses {
            Ok(p) => p,
            Err(e) => {
                self.stats.frames_skipped_no_tf += 1;
                if self.stats.skip_reasons.len() < MAX_REASONS {
                    self.stats.skip_reasons.push(format!(
                        "{} at {:.9} s (frame {frame_id:?}): {e}",
                        self.cfg.frame_topic,
                        secs(ns)
                    ));
                }
                return None;
            }
        };
        if let Err(why) = self.check_speed(ns, &base_to_map) {
            self.stats.frames_refused_pose_jump += 1;
            if self.stats.skip_reasons.len() < MAX_REASONS {
                self.stats.skip_reasons.push(format!(
                    "{} at {:.9} s (frame {frame_id:?}): {why}; frame refused",
                    self.cfg.frame_topic,
                    secs(ns)
                ));
            }
            return None;
        }
        cloud.frame_to_map = cloud_to_map;
        let other =
            Self::nearest(&self.other_clouds, ns, self.tol_ns()).map(|p| (p.ns, p.item.clone()));
        let other = other.and_then(|(ons, (mut c, f))| match self.to_map(&f, ons) {
            Ok(p) => {
                c.frame_to_map = p;
                Some(c)
            }
            Err(_) => {
                self.stats.secondary_dropped_no_tf += 1;
                None
            }
        });
        let (lidar, stereo) = if self.cfg.frame_topic == self.cfg.lidar_topic {
            (Some(cloud), other)
        } else {
            (other, Some(cloud))
        };
        self.stats.frames_built += 1;
        Some(Frame {
            stamp: secs(ns),
            base_to_map,
            lidar,
            stereo,
            image: self.matched_image(0, ns),
            swir: self.matched_image(1, ns),
            mwir: self.matched_image(2, ns),
            stereo_baseline_m: self.baseline_m,
            geo: self.geo,
        })
    }

    /// The speed gate: `Err` (what jumped, how far, how fast) when the vehicle at `ns`
    /// is farther from the last accepted frame than `max_speed_mps` allows. An accepted
    /// pose becomes the reference; so does the last of [`POSE_JUMP_CONFIRM`] refused ones
    /// that agree with each other.
    fn check_speed(&mut self, ns: i64, pose: &Pose) -> std::result::Result<(), String> {
        let p = pose.translation.vector;
        let allowed = |from_ns: i64, from: &Vector3<f64>| {
            let dt = (ns as f64 - from_ns as f64).abs() * 1e-9;
            let d = (p - from).norm();
            (d <= self.cfg.max_speed_mps * dt + POSE_JUMP_SLACK_M, d, dt)
        };
        let Some((last_ns, last)) = self.last_pose else {
            self.last_pose = Some((ns, p));
            return Ok(());
        };
        let (ok, d, dt) = allowed(last_ns, &last);
        if ok {
            self.last_pose = Some((ns, p));
            self.jump_run = None;
            return Ok(());
        }
        let run = match self.jump_run {
            Some((rns, r, k)) if allowed(rns, &r).0 => k + 1,
            _ => 1,
        };
        if run >= POSE_JUMP_CONFIRM {
            self.last_pose = Some((ns, p));
            self.jump_run = None;
            return Ok(());
        }
        self.jump_run = Some((ns, p, run));
        Err(format!(
            "{} → {} moved {d:.3} m in {dt:.3} s since the frame at {:.9} s ({:.1} m/s, \
             beyond log.max_speed_mps {} m/s), to ({:.3}, {:.3}, {:.3})",
            self.cfg.map_frame,
            self.cfg.base_frame,
            secs(last_ns),
            d / dt.max(1e-9),
            self.cfg.max_speed_mps,
            p.x,
            p.y,
            p.z
        ))
    }

    /// Emits scans the log has moved far enough past (all of them when `flush`), then
    /// forgets what no future scan can match.
    fn emit_ready(&mut self, flush: bool) {
        let horizon = self.horizon_ns();
        while let Some(front) = self.scans.front() {
            if !flush && self.now_ns < front.ns.saturating_add(horizon) {
                break;
            }
            let scan = self.scans.pop_front().expect("front exists");
            if let Some(f) = self.build(scan) {
                self.out.push_back(Ok(f));
            }
        }
        // A future scan has a stamp ≥ min(oldest pending scan, now − horizon) (older ones
        // are emitted at once); it matches nothing older than that minus the tolerance.
        let oldest = self.scans.front().map_or(i64::MAX, |p| p.ns);
        let keep_from = oldest
            .min(self.now_ns.saturating_sub(horizon))
            .saturating_sub(self.tol_ns());
        while self.other_clouds.front().is_some_and(|p| p.ns < keep_from) {
            self.other_clouds.pop_front();
        }
        for q in self.images.iter_mut() {
            while q.front().is_some_and(|p| p.ns < keep_from) {
                q.pop_front();
            }
        }
        self.tf.prune_before(keep_from);
    }
}

impl Iterator for FrameStream {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Result<Frame>> {
        loop {
            if let Some(f) = self.out.pop_front() {
                return Some(f);
            }
            if self.ended {
                return None;
            }
            match self.reader.next_message() {
                None => {
                    self.emit_ready(true);
                    self.ended = true;
                }
                Some(Err(e)) => {
                    // Everything before the error still makes frames; then the error.
                    self.emit_ready(true);
                    self.fatal = Some(e.to_string());
                    self.out.push_back(Err(e));
                    self.ended = true;
                }
                Some(Ok(m)) => {
                    if let Err(e) = self.ingest(m) {
                        self.out.push_back(Err(e));
                    }
                    self.emit_ready(false);
                }
            }
        }
    }
}
