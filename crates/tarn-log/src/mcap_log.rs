//! ROS 2 logs in MCAP: a streaming reader (chunked or not, zstd / lz4 / uncompressed, with or
//! without a summary section) and a writer that stores `ros2msg` schemas and CDR messages as
//! `ros2 bag record` does.
//!
//! The reader never loads the whole file: it feeds the `mcap` crate's sans-io linear
//! reader from a buffered file, so memory is bounded by the largest chunk and message.
//!
//! This file holds the types every part shares; [`LogReader`] and its damage handling,
//! the summary, the writer and [`recode`] each have a submodule.

use std::io::{Read, Seek};
use std::sync::Arc;

mod reader;
mod recoding;
mod records;
mod summary;
mod writer;

pub use reader::LogReader;
pub use recoding::{recode, RecodeStats};
pub use summary::{summarize, summarize_quick, LogSummary, TopicInfo};
pub use writer::{LogCompression, LogWriter, WriteOptions};

/// What a channel carries.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// Topic name.
    pub topic: String,
    /// Schema name, e.g. `sensor_msgs/msg/PointCloud2` (empty when the channel has none).
    pub schema: String,
    /// Schema encoding, e.g. `ros2msg`.
    pub schema_encoding: String,
    /// Message encoding, e.g. `cdr`.
    pub message_encoding: String,
}

/// One message as stored in the log.
#[derive(Debug, Clone)]
pub struct RawMessage {
    /// The channel the message was published on.
    pub channel: Arc<ChannelInfo>,
    /// Sequence number given by the publisher (0 when it gave none).
    pub sequence: u32,
    /// Nanoseconds.
    pub log_time: u64,
    /// Nanoseconds.
    pub publish_time: u64,
    /// The serialized message (CDR for ROS 2 logs).
    pub data: Vec<u8>,
}

/// The largest record (or decompressed chunk) the reader accepts, bytes, for a file of
/// `total_bytes`: a record outside a chunk can never be longer than the file, and a chunk
/// decompresses to at most this much. A header claiming more is damage, not an allocation.
/// Sensor messages of a few MB and chunks of a few MB (ros2 bag's default is 768 KiB) are
/// far below it.
pub fn record_length_limit(total_bytes: u64) -> usize {
    const FLOOR: u64 = 64 << 20;
    const CEIL: u64 = 2 << 30;
    total_bytes.saturating_mul(64).clamp(FLOOR, CEIL) as usize
}

/// A byte source a [`LogReader`] can read and seek in (a file, or bytes in memory).
pub trait LogSource: Read + Seek + Send {}
impl<T: Read + Seek + Send> LogSource for T {}

/// A part of a log that could not be read and was skipped: a chunk whose CRC or
/// decompression failed, a record whose framing is broken, or the cut end of a truncated
/// file. Byte offsets are exact offsets into the file.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct DamagedRange {
    /// First byte of the skipped range (the start of the damaged record).
    pub start_byte: u64,
    /// First byte after it: where reading resumed, or the file's size when it did not.
    pub end_byte: u64,
    /// What was wrong.
    pub what: String,
    /// Log times (ns) bounding the skipped messages, `[first, last]`: exact from the
    /// chunk index when the log has one (`log_time_from: "chunk index"`), else the last
    /// message read before the damage and the first one after it (`"neighbours"`; `None`
    /// where there is no such message).
    pub log_time_ns: [Option<u64>; 2],
    /// Where `log_time_ns` comes from: `"chunk index"`, `"neighbours"`, or `"unknown"` (both
    /// `None`).
    pub log_time_from: String,
    /// How reading went on: `"chunk index"`, `"record length"` (the damaged record's own
    /// framing held), `"forward scan"` (the next plausible record found by scanning),
    /// or `"end"` (nothing readable followed).
    pub resumed_by: String,
}

impl std::fmt::Display for DamagedRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "bytes {}..{} skipped: {}",
            self.start_byte, self.end_byte, self.what
        )?;
        if let [Some(a), Some(b)] = self.log_time_ns {
            write!(
                f,
                " (log time {:.9}..{:.9} s",
                a as f64 * 1e-9,
                b as f64 * 1e-9
            )?;
            write!(f, ", from the {})", self.log_time_from)?;
        }
        Ok(())
    }
}
