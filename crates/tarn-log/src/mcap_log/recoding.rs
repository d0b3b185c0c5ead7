//! Rewriting a log's known messages with tarn's own encoder ([`recode`]).

use std::collections::BTreeMap;
use std::path::Path;

use super::{DamagedRange, LogWriter, WriteOptions};
use crate::error::{Error, Result};
use crate::ros::{schema_name, TfMessage};
use crate::ros::{CameraInfoMsg, ImageMsg, NavSatFixMsg, PointCloud2Msg};

/// What [`recode`] did.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct RecodeStats {
    /// Messages written.
    pub written: u64,
    /// Messages of types tarn does not read, by topic; not copied.
    pub skipped_unknown: BTreeMap<String, u64>,
    /// Damaged parts of the input, skipped: the output holds everything else.
    pub damaged: Vec<DamagedRange>,
}

/// Reads every TF, PointCloud2, Image and CameraInfo message of `input` (any log
/// [`crate::log::open`] reads, ROS 1 bags included), decodes it and
/// writes it again with tarn's encoder into `output` (with `opts`' compression, chunking
/// and byte order). Messages of other types are skipped and counted; damaged parts of the
/// input are skipped and listed in [`RecodeStats::damaged`].
pub fn recode(
    input: impl AsRef<Path>,
    output: impl AsRef<Path>,
    opts: &WriteOptions,
) -> Result<RecodeStats> {
    let mut r = crate::log::open(input)?;
    let mut w = LogWriter::create(output, opts)?;
    let mut stats = RecodeStats::default();
    while let Some(m) = r.next_message() {
        let m = m?;
        // A log without a summary section is counted in a pass of its own before a build.
        crate::interrupt::check("counting the log's messages")?;
        let ch = &m.channel;
        let loc = || {
            format!(
                "topic {} ({}), log time {} ns",
                ch.topic, ch.schema, m.log_time
            )
        };
        let bad = |e: crate::ros::CdrError| Error::format(r.path(), loc(), e.to_string());
        let (Some(kind), Some(wire)) = (
            crate::log::canonical_type(&ch.schema),
            crate::log::wire_of(&ch.message_encoding),
        ) else {
            *stats.skipped_unknown.entry(ch.topic.clone()).or_insert(0) += 1;
            continue;
        };
        match kind {
            schema_name::TF_MESSAGE => w.write_tf(
                &ch.topic,
                &TfMessage::decode_wire(&m.data, wire).map_err(bad)?,
                m.log_time,
            )?,
            schema_name::POINT_CLOUD2 => w.write_pointcloud2(
                &ch.topic,
                &PointCloud2Msg::decode_wire(&m.data, wire).map_err(bad)?,
                m.log_time,
            )?,
            schema_name::IMAGE => w.write_image_msg(
                &ch.topic,
                &ImageMsg::decode_wire(&m.data, wire).map_err(bad)?,
                m.log_time,
            )?,
            schema_name::CAMERA_INFO => w.write_camera_info_msg(
                &ch.topic,
                &CameraInfoMsg::decode_wire(&m.data, wire).map_err(bad)?,
                m.log_time,
            )?,
            schema_name::NAV_SAT_FIX => w.write_nav_sat_fix(
                &ch.topic,
                &NavSatFixMsg::decode_wire(&m.data, wire).map_err(bad)?,
                m.log_time,
            )?,
            _ => {
                *stats.skipped_unknown.entry(ch.topic.clone()).or_insert(0) += 1;
                continue;
            }
        }
        stats.written += 1;
    }
    w.finish()?;
    stats.damaged = r.damaged().to_vec();
    Ok(stats)
}
