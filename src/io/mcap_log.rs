//! ROS 2 logs in MCAP: a streaming reader (chunked or not, zstd / lz4 / uncompressed, with or
//! without a summary section) and a writer that stores `ros2msg` schemas and CDR messages as
//! `ros2 bag record` does.
//!
//! The reader never loads the whole file: it feeds the `mcap` crate's sans-io linear
//! reader from a buffered file, so memory is bounded by the largest chunk and message.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader};

use super::ros::{
    camera_to_info, cloud_to_pointcloud2, encode_image, schema_name, schema_text, Endian, Header,
    Image, TfMessage,
};
use super::ros::{CameraInfoMsg, ImageMsg, PointCloud2Msg};
use crate::error::{Error, Result};
use crate::geom::camera::CameraModel;
use crate::geom::PointCloud;

/// What a channel carries.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
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
    pub channel: Arc<ChannelInfo>,
    pub sequence: u32,
    /// Nanoseconds.
    pub log_time: u64,
    /// Nanoseconds.
    pub publish_time: u64,
    pub data: Vec<u8>,
}

const READ_SIZE: usize = 256 * 1024;

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

/// A streaming reader of the messages of an MCAP file, in file order.
pub struct LogReader {
    path: PathBuf,
    source: Box<dyn Read + Send>,
    reader: LinearReader,
    schemas: HashMap<u16, (String, String)>,
    channels: HashMap<u16, Arc<ChannelInfo>>,
    bytes_read: u64,
    total_bytes: u64,
    messages: u64,
    finished: bool,
}

impl LogReader {
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let file = File::open(&path).map_err(|e| Error::io(&path, e))?;
        let total_bytes = file.metadata().map_err(|e| Error::io(&path, e))?.len();
        Ok(Self::from_reader(path, Box::new(file), total_bytes))
    }

    /// A reader of an MCAP log held in memory; `name` is used in error messages only.
    pub fn from_bytes(bytes: Vec<u8>, name: impl AsRef<Path>) -> Self {
        let total = bytes.len() as u64;
        Self::from_reader(name.as_ref(), Box::new(std::io::Cursor::new(bytes)), total)
    }

    /// A reader of an MCAP log from any byte source of `total_bytes` (for progress and
    /// for the record length limit); `name` is used in error messages only.
    pub fn from_reader(
        name: impl AsRef<Path>,
        source: Box<dyn Read + Send>,
        total_bytes: u64,
    ) -> Self {
        let options = mcap::sans_io::linear_reader::LinearReaderOptions::default()
            .with_record_length_limit(record_length_limit(total_bytes));
        LogReader {
            path: name.as_ref().to_path_buf(),
            source,
            reader: LinearReader::new_with_options(options),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            bytes_read: 0,
            total_bytes,
            messages: 0,
            finished: false,
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes of the file consumed so far (for a progress bar).
    pub fn bytes_read(&self) -> u64 {
        self.bytes_read
    }

    /// Size of the file in bytes.
    pub fn total_bytes(&self) -> u64 {
        self.total_bytes
    }

    /// Messages returned so far.
    pub fn messages_read(&self) -> u64 {
        self.messages
    }

    /// Channels seen so far.
    pub fn channels(&self) -> impl Iterator<Item = &Arc<ChannelInfo>> {
        self.channels.values()
    }

    fn damaged(&mut self, what: String) -> Error {
        self.finished = true;
        Error::format(
            &self.path,
            format!("byte {} of {}", self.bytes_read, self.total_bytes),
            format!(
                "{what}; the log is truncated or damaged here ({} messages before this point were read)",
                self.messages
            ),
        )
    }

    /// The next message, `None` at the end of a well-formed file. After an error (a
    /// truncated or damaged file) the reader is finished.
    pub fn next_message(&mut self) -> Option<Result<RawMessage>> {
        if self.finished {
            return None;
        }
        loop {
            let event = match self.reader.next_event() {
                None => {
                    self.finished = true;
                    return None;
                }
                Some(Err(e)) => {
                    let what = match e {
                        mcap::McapError::UnexpectedEof => {
                            "file ends in the middle of a record".to_string()
                        }
                        e => e.to_string(),
                    };
                    return Some(Err(self.damaged(what)));
                }
                Some(Ok(ev)) => ev,
            };
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    let want = need.max(READ_SIZE);
                    let buf = self.reader.insert(want);
                    match self.source.read(buf) {
                        Ok(n) => {
                            self.bytes_read += n as u64;
                            self.reader.notify_read(n);
                        }
                        Err(e) => {
                            self.finished = true;
                            return Some(Err(Error::io(&self.path, e)));
                        }
                    }
                }
                LinearReadEvent::Record { data, opcode } => {
                    // Only schemas, channels and messages matter here. Other records are
                    // not parsed at all: mcap 0.26's attachment parser panics on a record
                    // shorter than its own header (found by fuzzing, kept in
                    // fuzz/regressions/mcap/attachment-shorter-than-header.mcap).
                    if !matches!(
                        opcode,
                        mcap::records::op::SCHEMA
                            | mcap::records::op::CHANNEL
                            | mcap::records::op::MESSAGE
                    ) {
                        continue;
                    }
                    let rec = match mcap::parse_record(opcode, data) {
                        Ok(r) => r,
                        Err(e) => {
                            let what = format!("bad record (opcode {opcode:#04x}): {e}");
                            return Some(Err(self.damaged(what)));
                        }
                    };
                    match rec {
                        Record::Schema { header, .. } => {
                            self.schemas
                                .insert(header.id, (header.name, header.encoding));
                        }
                        Record::Channel(c) => {
                            let (schema, schema_encoding) =
                                self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                            self.channels.insert(
                                c.id,
                                Arc::new(ChannelInfo {
                                    topic: c.topic,
                                    schema,
                                    schema_encoding,
                                    message_encoding: c.message_encoding,
                                }),
                            );
                        }
                        Record::Message { header, data } => {
                            let Some(channel) = self.channels.get(&header.channel_id).cloned()
                            else {
                                let what = format!(
                                    "message {} refers to channel {} that no Channel record defined",
                                    self.messages, header.channel_id
                                );
                                return Some(Err(self.damaged(what)));
                            };
                            self.messages += 1;
                            return Some(Ok(RawMessage {
                                channel,
                                sequence: header.sequence,
                                log_time: header.log_time,
                                publish_time: header.publish_time,
                                data: data.into_owned(),
                            }));
                        }
                        _ => {}
                    }
                }
            }
        }
    }
}

impl Iterator for LogReader {
    type Item = Result<RawMessage>;
    fn next(&mut self) -> Option<Self::Item> {
        self.next_message()
    }
}

/// Per-topic summary of a log.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct TopicInfo {
    pub topic: String,
    #[serde(rename = "type")]
    pub schema: String,
    pub count: u64,
}

/// What a log holds, from one streaming pass over its messages.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LogSummary {
    pub topics: Vec<TopicInfo>,
    pub messages: u64,
    /// Earliest and latest message log time, nanoseconds (None for an empty log).
    pub start_ns: Option<u64>,
    pub end_ns: Option<u64>,
    pub duration_s: f64,
    /// Where and why reading stopped early (a truncated or damaged file); the counts are
    /// those of the messages before that point.
    pub damage: Option<String>,
}

/// Counts messages per topic in one streaming pass. A truncated or damaged file gives the
/// counts up to the damage and says where it is in [`LogSummary::damage`]; only a file that
/// cannot be opened is an error.
pub fn summarize(path: impl AsRef<Path>) -> Result<LogSummary> {
    let mut r = LogReader::open(path)?;
    let mut counts: BTreeMap<String, (String, u64)> = BTreeMap::new();
    let (mut start, mut end) = (None::<u64>, None::<u64>);
    let mut damage = None;
    while let Some(m) = r.next_message() {
        let m = match m {
            Ok(m) => m,
            Err(e) => {
                damage = Some(e.to_string());
                break;
            }
        };
        let e = counts
            .entry(m.channel.topic.clone())
            .or_insert_with(|| (m.channel.schema.clone(), 0));
        e.1 += 1;
        start = Some(start.map_or(m.log_time, |s| s.min(m.log_time)));
        end = Some(end.map_or(m.log_time, |s| s.max(m.log_time)));
    }
    Ok(LogSummary::of(counts, start, end, damage))
}

impl LogSummary {
    /// From the (schema, message count) of each topic and the first and last log times.
    fn of(
        counts: BTreeMap<String, (String, u64)>,
        start: Option<u64>,
        end: Option<u64>,
        damage: Option<String>,
    ) -> Self {
        LogSummary {
            messages: counts.values().map(|v| v.1).sum(),
            topics: counts
                .into_iter()
                .map(|(topic, (schema, count))| TopicInfo {
                    topic,
                    schema,
                    count,
                })
                .collect(),
            duration_s: match (start, end) {
                (Some(s), Some(e)) => e.saturating_sub(s) as f64 * 1e-9,
                _ => 0.0,
            },
            start_ns: start,
            end_ns: end,
            damage,
        }
    }
}

/// What a log holds, from its summary section (the statistics and channels a chunked
/// writer such as `ros2 bag` appends) when it has one, read without touching the messages;
/// else [`summarize`]'s streaming pass. A log with a summary reports no damage here: a
/// reader of its messages finds any.
pub fn summarize_quick(path: impl AsRef<Path>) -> Result<LogSummary> {
    let path = path.as_ref();
    match summary_section(path) {
        Some(s) => Ok(s),
        None => summarize(path),
    }
}

/// [`LogSummary`] from the summary section's statistics record, if the file has a valid
/// footer, a summary and statistics (`None` on any error: the caller streams instead).
fn summary_section(path: &Path) -> Option<LogSummary> {
    use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
    use std::io::Seek;
    let mut file = File::open(path).ok()?;
    let size = file.metadata().ok()?.len();
    let mut reader = SummaryReader::new_with_options(
        SummaryReaderOptions::default()
            .with_file_size(size)
            .with_record_length_limit(record_length_limit(size)),
    );
    while let Some(event) = reader.next_event() {
        match event.ok()? {
            SummaryReadEvent::ReadRequest(need) => {
                let n = file.read(reader.insert(need)).ok()?;
                reader.notify_read(n);
            }
            SummaryReadEvent::SeekRequest(to) => reader.notify_seeked(file.seek(to).ok()?),
        }
    }
    let summary = reader.finish()?;
    let stats = summary.stats.as_ref()?;
    let mut counts: BTreeMap<String, (String, u64)> = BTreeMap::new();
    for (id, &n) in &stats.channel_message_counts {
        let ch = summary.channels.get(id)?;
        let schema = ch.schema.as_ref().map_or(String::new(), |s| s.name.clone());
        counts.entry(ch.topic.clone()).or_insert((schema, 0)).1 += n;
    }
    let messages: u64 = counts.values().map(|v| v.1).sum();
    if messages != stats.message_count {
        return None;
    }
    let (start, end) = (messages > 0)
        .then_some((stats.message_start_time, stats.message_end_time))
        .unzip();
    Some(LogSummary::of(counts, start, end, None))
}

/// Chunk compression for written logs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LogCompression {
    None,
    #[default]
    Zstd,
    Lz4,
}

/// How a log is written.
#[derive(Debug, Clone)]
pub struct WriteOptions {
    pub compression: LogCompression,
    /// Chunked (with message indexes and a summary) as `ros2 bag` writes; unchunked otherwise.
    pub chunked: bool,
    /// Uncompressed bytes per chunk (`None`: 768 KiB, the `ros2 bag record` default).
    pub chunk_size: Option<u64>,
    /// CDR byte order of the payloads (ROS 2 writes little endian).
    pub endian: Endian,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            compression: LogCompression::Zstd,
            chunked: true,
            chunk_size: None,
            endian: Endian::Little,
        }
    }
}

/// Writes a ROS 2 MCAP log (profile `ros2`, `ros2msg` schemas, `cdr` messages). The file
/// appears at its path only when [`LogWriter::finish`] succeeds.
pub struct LogWriter {
    path: PathBuf,
    tmp: Option<tempfile::TempPath>,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    schemas: HashMap<String, u16>,
    channels: HashMap<String, (u16, String)>,
    sequence: u32,
    endian: Endian,
}

impl LogWriter {
    pub fn create(path: impl AsRef<Path>, opts: &WriteOptions) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let tmp = tempfile::Builder::new()
            .prefix(".tarn-log-")
            .suffix(".mcap.tmp")
            .tempfile_in(&dir)
            .map_err(|e| Error::io(&dir, e))?;
        let (file, tmp) = tmp.into_parts();
        let compression = match opts.compression {
            LogCompression::None => None,
            LogCompression::Zstd => Some(mcap::Compression::Zstd),
            LogCompression::Lz4 => Some(mcap::Compression::Lz4),
        };
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("tarn/", env!("CARGO_PKG_VERSION")))
            .compression(compression)
            .use_chunks(opts.chunked)
            .chunk_size(opts.chunk_size.or(Some(1024 * 768)))
            .create(BufWriter::new(file))
            .map_err(|e| Error::format(&path, "header", e.to_string()))?;
        Ok(LogWriter {
            path,
            tmp: Some(tmp),
            writer: Some(writer),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            sequence: 0,
            endian: opts.endian,
        })
    }

    fn err(&self, topic: &str, e: impl std::fmt::Display) -> Error {
        Error::format(&self.path, format!("topic {topic}"), e.to_string())
    }

    /// Writes an already encoded CDR message under `schema` (whose `ros2msg` text is given).
    pub fn write_raw(
        &mut self,
        topic: &str,
        schema: &str,
        schema_text: &str,
        log_time_ns: u64,
        data: &[u8],
    ) -> Result<()> {
        let Some(w) = self.writer.as_mut() else {
            return Err(Error::invalid("log writer", "already finished"));
        };
        let channel_id = match self.channels.get(topic) {
            Some((id, s)) if s == schema => *id,
            Some((_, s)) => {
                let s = s.clone();
                return Err(self.err(topic, format!("already carries {s}, not {schema}")));
            }
            None => {
                let schema_id = match self.schemas.get(schema) {
                    Some(id) => *id,
                    None => {
                        let id = w
                            .add_schema(schema, "ros2msg", schema_text.as_bytes())
                            .map_err(|e| {
                                Error::format(&self.path, format!("schema {schema}"), e.to_string())
                            })?;
                        self.schemas.insert(schema.to_string(), id);
                        id
                    }
                };
                let id = w
                    .add_channel(schema_id, topic, "cdr", &BTreeMap::new())
                    .map_err(|e| {
                        Error::format(&self.path, format!("topic {topic}"), e.to_string())
                    })?;
                self.channels
                    .insert(topic.to_string(), (id, schema.to_string()));
                id
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.sequence = self.sequence.wrapping_add(1);
        let w = self.writer.as_mut().expect("checked above");
        w.write_to_known_channel(&header, data)
            .map_err(|e| Error::format(&self.path, format!("topic {topic}"), e.to_string()))
    }

    fn write_known(
        &mut self,
        topic: &str,
        schema: &str,
        log_time_ns: u64,
        data: &[u8],
    ) -> Result<()> {
        let text = schema_text(schema).expect("known schema");
        self.write_raw(topic, schema, &text, log_time_ns, data)
    }

    pub fn write_tf(&mut self, topic: &str, msg: &TfMessage, log_time_ns: u64) -> Result<()> {
        let d = msg.encode(self.endian);
        self.write_known(topic, schema_name::TF_MESSAGE, log_time_ns, &d)
    }

    pub fn write_pointcloud2(
        &mut self,
        topic: &str,
        msg: &PointCloud2Msg,
        log_time_ns: u64,
    ) -> Result<()> {
        let d = msg.encode(self.endian);
        self.write_known(topic, schema_name::POINT_CLOUD2, log_time_ns, &d)
    }

    /// Writes a [`PointCloud`] (in its own frame `frame_id`) stamped with `header`.
    pub fn write_cloud(
        &mut self,
        topic: &str,
        cloud: &PointCloud,
        header: Header,
        log_time_ns: u64,
    ) -> Result<()> {
        let m = cloud_to_pointcloud2(cloud, header);
        self.write_pointcloud2(topic, &m, log_time_ns)
    }

    pub fn write_image_msg(&mut self, topic: &str, msg: &ImageMsg, log_time_ns: u64) -> Result<()> {
        let d = msg.encode(self.endian);
        self.write_known(topic, schema_name::IMAGE, log_time_ns, &d)
    }

    pub fn write_image(
        &mut self,
        topic: &str,
        img: &Image,
        header: Header,
        log_time_ns: u64,
    ) -> Result<()> {
        let m = encode_image(img, header);
        self.write_image_msg(topic, &m, log_time_ns)
    }

    pub fn write_camera_info_msg(
        &mut self,
        topic: &str,
        msg: &CameraInfoMsg,
        log_time_ns: u64,
    ) -> Result<()> {
        let d = msg.encode(self.endian);
        self.write_known(topic, schema_name::CAMERA_INFO, log_time_ns, &d)
    }

    pub fn write_camera(
        &mut self,
        topic: &str,
        cam: &CameraModel,
        header: Header,
        log_time_ns: u64,
    ) -> Result<()> {
        let m = camera_to_info(cam, header);
        self.write_camera_info_msg(topic, &m, log_time_ns)
    }

    /// Writes the summary and footer and moves the file into place.
    pub fn finish(mut self) -> Result<()> {
        let mut w = self.writer.take().expect("finish consumes the writer");
        w.finish()
            .map_err(|e| Error::format(&self.path, "summary", e.to_string()))?;
        let buf = w.into_inner();
        let file = buf
            .into_inner()
            .map_err(|e| Error::io(&self.path, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(&self.path, e))?;
        let tmp = self.tmp.take().expect("finish runs once");
        tmp.persist(&self.path)
            .map_err(|e| Error::io(&self.path, e.error))?;
        Ok(())
    }
}

/// What [`recode`] did.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct RecodeStats {
    pub written: u64,
    /// Messages of types tarn does not read, by topic; not copied.
    pub skipped_unknown: BTreeMap<String, u64>,
}

/// Reads every TF, PointCloud2, Image and CameraInfo message of `input`, decodes it and
/// writes it again with tarn's encoder into `output` (with `opts`' compression, chunking
/// and byte order). Messages of other types are skipped and counted.
pub fn recode(
    input: impl AsRef<Path>,
    output: impl AsRef<Path>,
    opts: &WriteOptions,
) -> Result<RecodeStats> {
    let mut r = LogReader::open(input)?;
    let mut w = LogWriter::create(output, opts)?;
    let mut stats = RecodeStats::default();
    while let Some(m) = r.next_message() {
        let m = m?;
        let ch = &m.channel;
        let loc = || {
            format!(
                "topic {} ({}), log time {} ns",
                ch.topic, ch.schema, m.log_time
            )
        };
        let bad = |e: super::ros::CdrError| Error::format(r.path(), loc(), e.to_string());
        if ch.message_encoding != "cdr" {
            *stats.skipped_unknown.entry(ch.topic.clone()).or_insert(0) += 1;
            continue;
        }
        match ch.schema.as_str() {
            schema_name::TF_MESSAGE => w.write_tf(
                &ch.topic,
                &TfMessage::decode(&m.data).map_err(bad)?,
                m.log_time,
            )?,
            schema_name::POINT_CLOUD2 => w.write_pointcloud2(
                &ch.topic,
                &PointCloud2Msg::decode(&m.data).map_err(bad)?,
                m.log_time,
            )?,
            schema_name::IMAGE => w.write_image_msg(
                &ch.topic,
                &ImageMsg::decode(&m.data).map_err(bad)?,
                m.log_time,
            )?,
            schema_name::CAMERA_INFO => w.write_camera_info_msg(
                &ch.topic,
                &CameraInfoMsg::decode(&m.data).map_err(bad)?,
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
    Ok(stats)
}
