//! [`LogConfig`]: which topics and frames a log is read with, its timing limits, and how
//! the sensor topics are found in a log ([`LogConfig::with_topics_of`]).

use std::path::Path;

use crate::error::{Error, Result};
use crate::log::canonical_type;
use crate::ros::schema_name;

/// Topic names, frame names and timing for reading a log. Defaults follow DESIGN.md.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LogConfig {
    /// Topic of `tf2_msgs/TFMessage` transforms.
    pub tf_topic: String,
    /// Topic of static transforms.
    pub tf_static_topic: String,
    /// Lidar `PointCloud2` topic.
    pub lidar_topic: String,
    /// Stereo `PointCloud2` topic (points in the camera frame).
    pub stereo_topic: String,
    /// Colour camera `Image` topic.
    pub image_topic: String,
    /// `CameraInfo` topic of the colour camera.
    pub camera_info_topic: String,
    /// The right camera of the stereo pair: its projection gives the baseline
    /// (`P[0][3] = −f·B`).
    pub right_camera_info_topic: String,
    /// Short-wave infrared `Image` topic.
    pub swir_topic: String,
    /// `CameraInfo` topic of the short-wave infrared camera.
    pub swir_info_topic: String,
    /// Mid-wave infrared `Image` topic.
    pub mwir_topic: String,
    /// `CameraInfo` topic of the mid-wave infrared camera.
    pub mwir_info_topic: String,
    /// `sensor_msgs/NavSatFix` topic: where the vehicle is on the globe (its longitude and
    /// the stamps give the local solar time the thermal labels need).
    pub gps_topic: String,
    /// Which cloud topic makes a frame: the lidar (default) or the stereo topic.
    pub frame_topic: String,
    /// Name of the map frame, the frame of the built map.
    pub map_frame: String,
    /// Name of the vehicle frame.
    pub base_frame: String,
    /// Largest time difference between a frame's scan and a matched cloud or image, s.
    pub tolerance_s: f64,
    /// How far past a scan's stamp the log must have advanced before the scan is
    /// emitted (waiting for late transforms and images), s.
    pub lookahead_s: f64,
    /// Fastest the vehicle moves, m/s: a frame whose `base_frame` lies farther from the
    /// last accepted frame's than this speed allows (plus [`POSE_JUMP_SLACK_M`]) is refused
    /// and named in `skip_reasons`, unless [`POSE_JUMP_CONFIRM`] frames in a row agree
    /// with it (the localisation really moved).
    pub max_speed_mps: f64,
}

/// Distance a pose may move between two frames beyond `max_speed_mps` times their time
/// difference (localisation corrections), m.
pub const POSE_JUMP_SLACK_M: f64 = 1.0;

/// Consecutive refused frames, each within the speed limit of the one before, after which
/// the last of them is accepted and becomes the reference.
pub const POSE_JUMP_CONFIRM: u32 = 3;

impl Default for LogConfig {
    fn default() -> Self {
        LogConfig {
            tf_topic: "/tf".into(),
            tf_static_topic: "/tf_static".into(),
            lidar_topic: "/lidar/points".into(),
            stereo_topic: "/stereo/points".into(),
            image_topic: "/camera/image".into(),
            camera_info_topic: "/camera/camera_info".into(),
            right_camera_info_topic: "/camera_right/camera_info".into(),
            swir_topic: "/swir/image".into(),
            swir_info_topic: "/swir/camera_info".into(),
            mwir_topic: "/mwir/image".into(),
            mwir_info_topic: "/mwir/camera_info".into(),
            gps_topic: "/gps/fix".into(),
            frame_topic: "/lidar/points".into(),
            map_frame: "map".into(),
            base_frame: "base_link".into(),
            tolerance_s: 0.05,
            lookahead_s: 0.5,
            max_speed_mps: 30.0,
        }
    }
}

impl LogConfig {
    /// Checks the tolerances and speed limit and that `frame_topic` is the lidar or the stereo
    /// topic; an `Error::Invalid` names the offending setting.
    pub fn validate(&self) -> Result<()> {
        if !(self.tolerance_s >= 0.0 && self.tolerance_s.is_finite()) {
            return Err(Error::invalid(
                "log config",
                format!("tolerance_s {} must be ≥ 0", self.tolerance_s),
            ));
        }
        if !(self.lookahead_s >= 0.0 && self.lookahead_s.is_finite()) {
            return Err(Error::invalid(
                "log config",
                format!("lookahead_s {} must be ≥ 0", self.lookahead_s),
            ));
        }
        if self.max_speed_mps.is_nan() || self.max_speed_mps <= 0.0 {
            return Err(Error::invalid(
                "log config",
                format!("max_speed_mps {} must be > 0", self.max_speed_mps),
            ));
        }
        if self.frame_topic != self.lidar_topic && self.frame_topic != self.stereo_topic {
            return Err(Error::invalid(
                "log config",
                format!(
                    "frame_topic {:?} must be the lidar or the stereo topic",
                    self.frame_topic
                ),
            ));
        }
        Ok(())
    }
}

/// Topics named by the user (`--lidar-topic`, `--stereo-topic`, `--camera-topic`,
/// `--frame-topic`): each must be in the log with the right type.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NamedTopics {
    /// Lidar `PointCloud2` topic.
    pub lidar: Option<String>,
    /// Stereo `PointCloud2` topic.
    pub stereo: Option<String>,
    /// Colour camera `Image` topic.
    pub camera: Option<String>,
    /// Which cloud topic makes frames; a point cloud topic that is not the stereo topic
    /// is taken as the lidar.
    pub frame: Option<String>,
}

impl LogConfig {
    /// The config with its sensor topics set for `summary`'s log, and the frame topic.
    ///
    /// A named topic is used as it is (it must be in the log with its type). Otherwise a
    /// topic of the config (the defaults of DESIGN.md, or a log config's) is kept when the
    /// log has it, and else found by message type: the stereo cloud is the one
    /// `PointCloud2` topic with `stereo` in its name; the lidar is the one `PointCloud2`
    /// topic that is not the stereo cloud; the colour camera the one `Image` topic that is
    /// not the SWIR or MWIR one, with the `camera_info` beside it. More than one candidate
    /// is an error naming them and the option that chooses. Frames come from the lidar,
    /// or from the stereo cloud when the log has no lidar.
    pub fn with_topics_of(
        &self,
        summary: &crate::mcap_log::LogSummary,
        named: &NamedTopics,
        log: &Path,
    ) -> Result<LogConfig> {
        let of_type = |ty: &str| -> Vec<String> {
            summary
                .topics
                .iter()
                .filter(|t| t.count > 0 && canonical_type(&t.schema) == Some(ty))
                .map(|t| t.topic.clone())
                .collect()
        };
        let clouds = of_type(schema_name::POINT_CLOUD2);
        let images = of_type(schema_name::IMAGE);
        let infos = of_type(schema_name::CAMERA_INFO);
        let fixes = of_type(schema_name::NAV_SAT_FIX);
        let has = |list: &[String], t: &str| list.iter().any(|x| x == t);
        let err = |msg: String| Error::format(log, "topics", msg);
        let check = |t: &Option<String>, list: &[String], opt: &str, ty: &str| -> Result<()> {
            match t {
                Some(t) if !has(list, t) => Err(err(format!(
                    "{opt} {t}: the log has no {ty} messages on it (its {ty} topics: {})",
                    list_or_none(list)
                ))),
                _ => Ok(()),
            }
        };
        check(&named.lidar, &clouds, "--lidar-topic", "PointCloud2")?;
        check(&named.stereo, &clouds, "--stereo-topic", "PointCloud2")?;
        check(&named.camera, &images, "--camera-topic", "Image")?;
        check(&named.frame, &clouds, "--frame-topic", "PointCloud2")?;
        let mut c = self.clone();
        let one_of = |cands: Vec<String>, what: &str, opt: &str| -> Result<Option<String>> {
            match cands.len() {
                0 => Ok(None),
                1 => Ok(cands.into_iter().next()),
                _ => Err(err(format!(
                    "the log has {} topics that may be the {what}: {}; choose one with {opt}",
                    cands.len(),
                    cands.join(", ")
                ))),
            }
        };
        // Stereo.
        if let Some(t) = &named.stereo {
            c.stereo_topic = t.clone();
        } else if !has(&clouds, &c.stereo_topic) {
            let cands: Vec<String> = clouds
                .iter()
                .filter(|t| t.contains("stereo") && Some(*t) != named.lidar.as_ref())
                .cloned()
                .collect();
            if let Some(t) = one_of(cands, "stereo cloud", "--stereo-topic")? {
                c.stereo_topic = t;
            }
        }
        // Lidar.
        let frame_as_lidar = named
            .frame
            .as_ref()
            .filter(|f| **f != c.stereo_topic && named.lidar.is_none());
        if let Some(t) = named.lidar.as_ref().or(frame_as_lidar) {
            c.lidar_topic = t.clone();
        } else if !has(&clouds, &c.lidar_topic) {
            let cands: Vec<String> = clouds
                .iter()
                .filter(|t| **t != c.stereo_topic)
                .cloned()
                .collect();
            let what = "lidar (--stereo-topic names the stereo cloud)";
            if let Some(t) = one_of(cands, what, "--lidar-topic")? {
                c.lidar_topic = t;
            }
        }
        if c.lidar_topic == c.stereo_topic {
            return Err(err(format!(
                "{} cannot be both the lidar and the stereo topic",
                c.lidar_topic
            )));
        }
        // Colour camera and its CameraInfo.
        let camera = if let Some(t) = &named.camera {
            Some(t.clone())
        } else if !has(&images, &c.image_topic) {
            let cands: Vec<String> = images
                .iter()
                .filter(|t| **t != c.swir_topic && **t != c.mwir_topic)
                .cloned()
                .collect();
            one_of(cands, "colour camera", "--camera-topic")?
        } else {
            None
        };
        if let Some(t) = camera {
            if t != c.image_topic {
                c.image_topic = t;
                let ns = c.image_topic.rsplit_once('/').map_or("", |(a, _)| a);
                let beside = format!("{ns}/camera_info");
                if has(&infos, &beside) {
                    c.camera_info_topic = beside;
                } else if !has(&infos, &c.camera_info_topic) {
                    let others = [
                        &c.right_camera_info_topic,
                        &c.swir_info_topic,
                        &c.mwir_info_topic,
                    ];
                    let cands: Vec<String> = infos
                        .iter()
                        .filter(|t| !others.contains(t))
                        .cloned()
                        .collect();
                    if cands.len() == 1 {
                        c.camera_info_topic = cands[0].clone();
                    }
                }
            }
        }
        // The GNSS fix: the configured topic, else the log's one NavSatFix topic.
        if !has(&fixes, &c.gps_topic) && fixes.len() == 1 {
            c.gps_topic = fixes[0].clone();
        }
        c.frame_topic = match &named.frame {
            Some(f) => f.clone(),
            None if !has(&clouds, &c.lidar_topic) && has(&clouds, &c.stereo_topic) => {
                c.stereo_topic.clone()
            }
            None => c.lidar_topic.clone(),
        };
        c.validate()?;
        Ok(c)
    }
}

fn list_or_none(list: &[String]) -> String {
    if list.is_empty() {
        "none".into()
    } else {
        list.join(", ")
    }
}
