//! ROS 2 logs in MCAP: a streaming reader (chunked or not, zstd / lz4 / uncompressed, with or
//! without a summary section) and a writer that stores `ros2msg` schemas and CDR messages as
//! `ros2 bag record` does.
//!
//! The reader never loads the whole file: it feeds the `mcap` crate's sans-io linear
//! reader from a buffered file, so memory is bounded by the largest chunk and message.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Read, Seek};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader};

use crate::error::{Error, Result};
use crate::geom::camera::CameraModel;
use crate::geom::PointCloud;
use crate::ros::{
    camera_to_info, cloud_to_pointcloud2, encode_image, schema_name, schema_text, Endian, Header,
    TfMessage,
};
use crate::ros::{CameraInfoMsg, ImageMsg, NavSatFixMsg, PointCloud2Msg};
use crate::sensor::Image;

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

/// Whether the length-prefixed fields of a Schema or Channel record body lie inside it.
/// The `mcap` crate's parser reserves a string or map of its declared length before it
/// checks that length against the record, so a corrupted prefix inside a record of
/// plausible length would ask for gigabytes.
fn prefixed_fields_fit(opcode: u8, body: &[u8]) -> bool {
    use mcap::records::op;
    // Reads a u32 length at `at` and returns the offset after that many bytes, if inside.
    let skip = |at: usize, within: usize| -> Option<usize> {
        let b = body.get(at..at.checked_add(4)?)?;
        let n = u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize;
        let end = (at + 4).checked_add(n)?;
        (end <= within).then_some(end)
    };
    let len = body.len();
    match opcode {
        // id u16, name, encoding, data.
        op::SCHEMA => skip(2, len)
            .and_then(|a| skip(a, len))
            .and_then(|a| skip(a, len))
            .is_some(),
        // id u16, schema id u16, topic, message encoding, metadata map of string pairs.
        op::CHANNEL => {
            let Some(map_at) = skip(4, len).and_then(|a| skip(a, len)) else {
                return false;
            };
            let Some(map_end) = skip(map_at, len) else {
                return false;
            };
            let mut a = map_at + 4;
            while a < map_end {
                match skip(a, map_end).and_then(|k| skip(k, map_end)) {
                    Some(next) => a = next,
                    None => return false,
                }
            }
            true
        }
        _ => true,
    }
}

/// [`mcap::parse_record`] after [`prefixed_fields_fit`].
fn parse_record_checked(opcode: u8, body: &[u8]) -> mcap::McapResult<mcap::records::Record<'_>> {
    if !prefixed_fields_fit(opcode, body) {
        return Err(mcap::McapError::UnexpectedEof);
    }
    mcap::parse_record(opcode, body)
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

/// A chunk as the summary section's chunk index places it.
#[derive(Debug, Clone, Copy)]
struct IndexedChunk {
    start: u64,
    end: u64,
    t0: u64,
    t1: u64,
}

/// What the summary section gives a reader.
#[derive(Default)]
struct SummaryInfo {
    chunks: Vec<IndexedChunk>,
    schemas: Vec<(u16, String, String)>,
    channels: Vec<(u16, u16, String, String)>,
    /// Where the data section ends (the summary's start).
    data_end: Option<u64>,
}

const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
const FOOTER_LEN: u64 = 9 + 20;

/// Outcome of reading one record.
enum Step {
    /// Go on at this byte.
    Next(u64),
    /// The data section is over.
    End,
}

/// A streaming reader of the messages of an MCAP file, in file order, that skips what is
/// damaged.
///
/// Every chunk's `uncompressed_crc` is checked (when it is not zero) before any of its
/// records is used, and a chunk is used whole or not at all. A damaged chunk, a record whose
/// framing is broken, or the cut end of a truncated file is recorded as a
/// [`DamagedRange`] ([`LogReader::damaged`]) and reading goes on at the next chunk of the
/// summary's chunk index, or, without one, at the next plausible record found by scanning
/// forward. The data section's CRC is checked when nothing else was found damaged. Only a
/// file that is not an MCAP log at all (no magic) or that cannot be read ends the stream
/// with an error.
///
/// Memory is bounded by the largest chunk and record ([`record_length_limit`]).
pub struct LogReader {
    path: PathBuf,
    src: std::io::BufReader<Box<dyn LogSource>>,
    /// Where `src` is positioned.
    pos: u64,
    total_bytes: u64,
    schemas: HashMap<u16, (String, String)>,
    channels: HashMap<u16, Arc<ChannelInfo>>,
    index: Vec<IndexedChunk>,
    /// Where the data section ends, when the summary says so.
    data_end: Option<u64>,
    limit: usize,
    pending: std::collections::VecDeque<RawMessage>,
    damaged: Vec<DamagedRange>,
    /// The file's end is not a footer record and the magic: recorded as damage once the
    /// data section has been read whole (a file cut short is reported as truncated instead).
    tail_damage: Option<String>,
    /// CRC of every byte read in order from the start; dropped at the first skip.
    hasher: Option<crc32fast::Hasher>,
    last_time: Option<u64>,
    /// Damaged ranges waiting for the log time of the next message read.
    open_times: Vec<usize>,
    messages: u64,
    started: bool,
    finished: bool,
}

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

/// Whether a chunk record body's header fields agree with each other and with the body's
/// length (the chunk's framing held, whatever its contents).
fn chunk_header(body: &[u8]) -> std::result::Result<(), String> {
    let short = || "chunk header is shorter than its fields".to_string();
    let (t0, t1) = (
        u64_at(body, 0).ok_or_else(short)?,
        u64_at(body, 8).ok_or_else(short)?,
    );
    let clen = u32_at(body, 28).ok_or_else(short)? as usize;
    let name = body
        .get(32..32usize.saturating_add(clen))
        .ok_or_else(short)?;
    if !matches!(name, b"" | b"zstd" | b"lz4") {
        return Err(format!(
            "unknown chunk compression {:?}",
            String::from_utf8_lossy(name)
        ));
    }
    let rlen = u64_at(body, 32 + clen).ok_or_else(short)?;
    let records = 32 + clen + 8;
    if rlen != (body.len() - records) as u64 {
        return Err(format!(
            "chunk says its records take {rlen} bytes, the record holds {}",
            body.len() - records
        ));
    }
    if t0 > t1 {
        return Err(format!("chunk message times {t0} > {t1}"));
    }
    Ok(())
}

impl LogReader {
    /// Opens the MCAP log at `path` for streaming (nothing is read yet). Fails when the file
    /// cannot be opened or its size read.
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

    /// A reader of an MCAP log from any seekable byte source of `total_bytes` (for
    /// progress, the footer and the record length limit); `name` is used in error messages
    /// only.
    pub fn from_reader(
        name: impl AsRef<Path>,
        source: Box<dyn LogSource>,
        total_bytes: u64,
    ) -> Self {
        LogReader {
            path: name.as_ref().to_path_buf(),
            src: std::io::BufReader::with_capacity(READ_SIZE, source),
            pos: 0,
            total_bytes,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            index: Vec::new(),
            data_end: None,
            limit: record_length_limit(total_bytes),
            pending: Default::default(),
            damaged: Vec::new(),
            tail_damage: None,
            hasher: Some(crc32fast::Hasher::new()),
            last_time: None,
            open_times: Vec::new(),
            messages: 0,
            started: false,
            finished: false,
        }
    }

    /// The log's path (or the name given to [`LogReader::from_bytes`] or
    /// [`LogReader::from_reader`]).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes of the file consumed so far (for a progress bar).
    pub fn bytes_read(&self) -> u64 {
        self.pos
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

    /// The parts of the log skipped so far as damaged, in file order.
    pub fn damaged(&self) -> &[DamagedRange] {
        &self.damaged
    }

    fn seek_to(&mut self, at: u64) -> std::io::Result<()> {
        if at != self.pos {
            self.src.seek(std::io::SeekFrom::Start(at))?;
            self.pos = at;
        }
        Ok(())
    }

    /// `n` bytes at the current position (`n` already checked against the file's size).
    fn read_vec(&mut self, n: usize) -> std::io::Result<Vec<u8>> {
        let mut v = vec![0u8; n];
        self.src.read_exact(&mut v)?;
        self.pos += n as u64;
        if let Some(h) = self.hasher.as_mut() {
            h.update(&v);
        }
        Ok(v)
    }

    /// Up to `n` bytes at `at`, without hashing (for the footer, the summary and scans).
    fn peek_at(&mut self, at: u64, n: usize) -> std::io::Result<Vec<u8>> {
        self.hasher = None;
        self.seek_to(at)?;
        let n = n.min(self.total_bytes.saturating_sub(at) as usize);
        let mut v = vec![0u8; n];
        self.src.read_exact(&mut v)?;
        self.pos += n as u64;
        Ok(v)
    }

    fn io_err(&mut self, e: std::io::Error) -> Error {
        self.finished = true;
        Error::io(&self.path, e)
    }

    /// Reads the footer and the summary section (its chunk index, schemas and channels),
    /// when the file has them and the summary's CRC holds. A damaged summary is recorded
    /// and not used.
    fn read_summary(&mut self) -> std::io::Result<SummaryInfo> {
        let mut info = SummaryInfo::default();
        let total = self.total_bytes;
        if total < 8 + FOOTER_LEN + 8 {
            return Ok(info);
        }
        let tail = self.peek_at(total - 8 - FOOTER_LEN, (FOOTER_LEN + 8) as usize)?;
        let footer = tail[0] == mcap::records::op::FOOTER && u64_at(&tail, 1) == Some(20);
        if &tail[FOOTER_LEN as usize..] != MAGIC || !footer {
            self.tail_damage = Some(if footer {
                "the closing magic is damaged; the summary section is not used".into()
            } else {
                "the file does not end with a footer record and the magic; the summary \
                 section is not used"
                    .into()
            });
            return Ok(info);
        }
        let start = u64_at(&tail, 9).unwrap_or(0);
        let crc = u32_at(&tail, 25).unwrap_or(0);
        let footer_at = total - 8 - FOOTER_LEN;
        if start == 0 || start < 8 || start > footer_at || footer_at - start > self.limit as u64 {
            return Ok(info);
        }
        let bytes = self.peek_at(start, (total - 8 - 4 - start) as usize)?;
        let bad = |what: String| DamagedRange {
            start_byte: start,
            end_byte: footer_at,
            what,
            log_time_ns: [None, None],
            log_time_from: "unknown".into(),
            resumed_by: "record length".into(),
        };
        if crc != 0 && crc32fast::hash(&bytes) != crc {
            self.damaged.push(bad(
                "summary section: CRC mismatch; its chunk index is not used".into(),
            ));
            return Ok(info);
        }
        let records = &bytes[..(footer_at - start) as usize];
        let mut at = 0usize;
        while at < records.len() {
            let (Some(&op), Some(len)) = (records.get(at), u64_at(records, at + 1)) else {
                self.damaged.push(bad(format!(
                    "summary section: record header cut at byte {}",
                    start + at as u64
                )));
                return Ok(SummaryInfo::default());
            };
            let body_at = at + 9;
            let Some(body) = usize::try_from(len)
                .ok()
                .and_then(|l| records.get(body_at..body_at.checked_add(l)?))
            else {
                self.damaged.push(bad(format!(
                    "summary section: record at byte {} claims {len} bytes",
                    start + at as u64
                )));
                return Ok(SummaryInfo::default());
            };
            use mcap::records::op;
            if matches!(op, op::CHUNK_INDEX | op::SCHEMA | op::CHANNEL) {
                match parse_record_checked(op, body) {
                    Ok(Record::ChunkIndex(c)) => info.chunks.push(IndexedChunk {
                        start: c.chunk_start_offset,
                        end: c.chunk_start_offset.saturating_add(c.chunk_length),
                        t0: c.message_start_time,
                        t1: c.message_end_time,
                    }),
                    Ok(Record::Schema { header, .. }) => {
                        info.schemas.push((header.id, header.name, header.encoding))
                    }
                    Ok(Record::Channel(c)) => {
                        info.channels
                            .push((c.id, c.schema_id, c.topic, c.message_encoding))
                    }
                    _ => {
                        self.damaged.push(bad(format!(
                            "summary section: bad record (opcode {op:#04x}) at byte {}",
                            start + at as u64
                        )));
                        return Ok(SummaryInfo::default());
                    }
                }
            }
            at = body_at + body.len();
        }
        info.chunks.sort_by_key(|c| c.start);
        let consistent = info
            .chunks
            .iter()
            .all(|c| c.start >= 8 && c.end <= start && c.start < c.end)
            && info.chunks.windows(2).all(|w| w[0].end <= w[1].start);
        if !consistent {
            self.damaged.push(bad(
                "summary section: the chunk index does not fit the data section; not used".into(),
            ));
            return Ok(SummaryInfo::default());
        }
        info.data_end = Some(start);
        Ok(info)
    }

    /// Records a damaged range `[start, end)`, and drops the data-section CRC (it can no
    /// longer be checked).
    fn record_damage(&mut self, start: u64, end: u64, what: String, resumed_by: &str) {
        self.hasher = None;
        // The chunk index's times when the range is (or starts with) an indexed chunk.
        let indexed: Vec<&IndexedChunk> = self
            .index
            .iter()
            .filter(|c| c.start >= start && c.start < end.max(start + 1))
            .collect();
        let (times, from) = if !indexed.is_empty() {
            let t0 = indexed.iter().map(|c| c.t0).min();
            let t1 = indexed.iter().map(|c| c.t1).max();
            ([t0, t1], "chunk index")
        } else {
            self.open_times.push(self.damaged.len());
            ([self.last_time, None], "neighbours")
        };
        self.damaged.push(DamagedRange {
            start_byte: start,
            end_byte: end,
            what,
            log_time_ns: times,
            log_time_from: from.into(),
            resumed_by: resumed_by.into(),
        });
    }

    /// Where to go on after damage at `start`, found at `seen` bytes past it: the next
    /// indexed chunk after `start`, or the next plausible record found by scanning from
    /// `start + 1`.
    fn resume_after(&mut self, start: u64, what: String) -> std::io::Result<Step> {
        if let Some(end) = self.data_end {
            let next = self.index.iter().find(|c| c.start > start).map(|c| c.start);
            let to = next.unwrap_or(end);
            self.record_damage(start, to, what, "chunk index");
            return Ok(match next {
                Some(n) => Step::Next(n),
                None => Step::End,
            });
        }
        match self.scan(start + 1)? {
            Some(p) => {
                self.record_damage(start, p, what, "forward scan");
                Ok(Step::Next(p))
            }
            None => {
                let t = self.total_bytes;
                self.record_damage(start, t, what, "end");
                Ok(Step::End)
            }
        }
    }

    /// Whether a record that ends at `end` is followed by the end of the file or by a
    /// record header that fits in it.
    fn followed_well(&mut self, end: u64) -> std::io::Result<bool> {
        if end == self.total_bytes {
            return Ok(true);
        }
        let h = self.peek_at(end, 9)?;
        Ok(h.len() == 9
            && (1..=0x0f).contains(&h[0])
            && u64_at(&h, 1).is_some_and(|l| l <= self.total_bytes - end - 9))
    }

    /// Whether a plausible record starts at `at`, given the bytes `b` from there.
    fn plausible(&mut self, b: &[u8], at: u64) -> std::io::Result<bool> {
        use mcap::records::op;
        let (Some(&opc), Some(len)) = (b.first(), u64_at(b, 1)) else {
            return Ok(false);
        };
        let room = self.total_bytes - at;
        if room < 9 || len > room - 9 || len > self.limit as u64 {
            return Ok(false);
        }
        let end = at + 9 + len;
        Ok(match opc {
            op::CHUNK => {
                let head = &b[9..b.len().min(9 + 64)];
                // Judge the header's fields against the claimed length.
                let clen = u32_at(head, 28).unwrap_or(u32::MAX) as u64;
                clen <= 4
                    && head.len() as u64 >= 40 + clen
                    && u64_at(head, 32 + clen as usize) == Some(len.wrapping_sub(40 + clen))
                    && matches!(&head[32..32 + clen as usize], b"" | b"zstd" | b"lz4")
                    && u64_at(head, 0) <= u64_at(head, 8)
            }
            op::MESSAGE => {
                len >= 22
                    && b.len() >= 11
                    && self
                        .channels
                        .contains_key(&u16::from_le_bytes([b[9], b[10]]))
                    && self.followed_well(end)?
            }
            op::SCHEMA | op::CHANNEL if len <= 1 << 20 => {
                let body = self.peek_at(at + 9, len as usize)?;
                parse_record_checked(opc, &body).is_ok() && self.followed_well(end)?
            }
            op::DATA_END => len == 4 && self.followed_well(end)?,
            op::FOOTER => len == 20 && end + 8 == self.total_bytes,
            _ => false,
        })
    }

    /// The first byte at or after `from` where a plausible record starts.
    fn scan(&mut self, from: u64) -> std::io::Result<Option<u64>> {
        const WINDOW: usize = 1 << 20;
        let mut at = from;
        while at < self.total_bytes {
            let buf = self.peek_at(at, WINDOW + 128)?;
            for i in 0..buf.len().min(WINDOW) {
                if (1..=0x0f).contains(&buf[i]) && self.plausible(&buf[i..], at + i as u64)? {
                    return Ok(Some(at + i as u64));
                }
            }
            at += WINDOW as u64;
        }
        Ok(None)
    }

    /// Decodes a chunk's records into messages (and the schemas and channels it defines),
    /// all or nothing: the CRC of the uncompressed records is checked before any is used.
    fn decode_chunk(&self, record: &[u8]) -> std::result::Result<Vec<(u8, Vec<u8>)>, String> {
        chunk_header(&record[9..])?;
        let options = mcap::sans_io::linear_reader::LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_skip_end_magic(true)
            .with_validate_chunk_crcs(true)
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(self.limit);
        let mut r = LinearReader::new_with_options(options);
        let mut fed = false;
        let mut out = Vec::new();
        while let Some(ev) = r.next_event() {
            match ev.map_err(|e| match e {
                mcap::McapError::BadChunkCrc { saved, calculated } => format!(
                    "chunk CRC mismatch (stored {saved:#010x}, computed {calculated:#010x})"
                ),
                e => format!("chunk cannot be decoded: {e}"),
            })? {
                LinearReadEvent::ReadRequest(_) => {
                    let n = if fed { 0 } else { record.len() };
                    if !fed {
                        r.insert(n).copy_from_slice(record);
                    }
                    r.notify_read(n);
                    fed = true;
                }
                LinearReadEvent::Record { data, opcode } => {
                    if matches!(
                        opcode,
                        mcap::records::op::SCHEMA
                            | mcap::records::op::CHANNEL
                            | mcap::records::op::MESSAGE
                    ) {
                        out.push((opcode, data.to_vec()));
                    }
                }
            }
        }
        Ok(out)
    }

    /// Applies one schema, channel or message record; a message is queued. `Err` names
    /// what is wrong with the record.
    fn apply(&mut self, opcode: u8, body: &[u8]) -> std::result::Result<(), String> {
        match parse_record_checked(opcode, body) {
            Ok(Record::Schema { header, .. }) => {
                self.schemas
                    .insert(header.id, (header.name, header.encoding));
            }
            Ok(Record::Channel(c)) => {
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
            Ok(Record::Message { header, data }) => {
                let Some(channel) = self.channels.get(&header.channel_id).cloned() else {
                    return Err(format!(
                        "message at log time {} ns refers to channel {} that no Channel record defined",
                        header.log_time, header.channel_id
                    ));
                };
                self.pending.push_back(RawMessage {
                    channel,
                    sequence: header.sequence,
                    log_time: header.log_time,
                    publish_time: header.publish_time,
                    data: data.into_owned(),
                });
            }
            Ok(_) => {}
            Err(e) => return Err(format!("bad record (opcode {opcode:#04x}): {e}")),
        }
        Ok(())
    }

    /// Reads the record at `self.pos`.
    fn step(&mut self) -> std::io::Result<Step> {
        use mcap::records::op;
        let start = self.pos;
        let total = self.total_bytes;
        if self.data_end.is_some_and(|e| start >= e) {
            return Ok(Step::End);
        }
        // The next chunk the index places at or after this record.
        let expect = self.index.iter().find(|c| c.start >= start).copied();
        if total - start < 9 {
            let what = if start == total {
                "the file ends without its data end and footer records (truncated)".to_string()
            } else {
                format!(
                    "file ends in the middle of a record header ({} bytes)",
                    total - start
                )
            };
            self.record_damage(start, total, what, "end");
            return Ok(Step::End);
        }
        // The data section's CRC covers the bytes before the DataEnd record.
        let crc_before = self.hasher.clone();
        let head = self.read_vec(9)?;
        let opcode = head[0];
        let len = u64_at(&head, 1).expect("9 bytes");
        let end = start.checked_add(9).and_then(|s| s.checked_add(len));
        if let Some(c) = expect {
            if c.start == start && (opcode != op::CHUNK || end != Some(c.end)) {
                let what = format!(
                    "the chunk index places a chunk of {} bytes here; the record header says opcode {opcode:#04x}, {len} bytes",
                    c.end - c.start
                );
                self.record_damage(start, c.end, what, "chunk index");
                return Ok(Step::Next(c.end));
            }
            if c.start > start && end.is_none_or(|e| e > c.start) {
                let what = format!(
                    "record (opcode {opcode:#04x}) claims {len} bytes, across the next indexed chunk at byte {}",
                    c.start
                );
                self.record_damage(start, c.start, what, "chunk index");
                return Ok(Step::Next(c.start));
            }
        }
        let known = (1..=0x0f).contains(&opcode) || opcode >= 0x80;
        let fits = end.is_some_and(|e| e <= total) && len <= self.limit as u64;
        if !known || !fits {
            let what = if !known {
                format!("no record has opcode {opcode:#04x}")
            } else if end.is_some_and(|e| e > total) {
                format!(
                    "file ends in the middle of a record (opcode {opcode:#04x} claims {len} bytes, {} remain): truncated or damaged",
                    total - start - 9
                )
            } else {
                format!("record (opcode {opcode:#04x}) claims {len} bytes, beyond the record length limit")
            };
            return self.resume_after(start, what);
        }
        let end = end.expect("checked");
        match opcode {
            op::CHUNK => {
                let body = self.read_vec(len as usize)?;
                let mut record = head;
                record.extend_from_slice(&body);
                drop(body);
                match self.decode_chunk(&record) {
                    Ok(records) => {
                        let mut bad = None;
                        for (opc, data) in records {
                            if let Err(e) = self.apply(opc, &data) {
                                bad.get_or_insert(e);
                            }
                        }
                        if let Some(e) = bad {
                            // The chunk's CRC held: keep its good messages, name the bad one.
                            self.record_damage(start, end, e, "record length");
                        }
                        Ok(Step::Next(end))
                    }
                    Err(what) => {
                        let framing_held = chunk_header(&record[9..]).is_ok();
                        if framing_held && (self.data_end.is_some() || self.followed_well(end)?) {
                            let by = if self.index.iter().any(|c| c.start == start) {
                                "chunk index"
                            } else {
                                "record length"
                            };
                            self.record_damage(start, end, what, by);
                            Ok(Step::Next(end))
                        } else {
                            self.resume_after(start, what)
                        }
                    }
                }
            }
            op::SCHEMA | op::CHANNEL | op::MESSAGE => {
                let body = self.read_vec(len as usize)?;
                if let Err(what) = self.apply(opcode, &body) {
                    self.record_damage(start, end, what, "record length");
                }
                Ok(Step::Next(end))
            }
            op::DATA_END => {
                let calculated = crc_before.map(|h| h.finalize());
                self.hasher = None;
                let body = self.read_vec(len as usize)?;
                let saved = u32_at(&body, 0).unwrap_or(0);
                if let Some(c) = calculated {
                    if saved != 0 && c != saved && self.damaged.is_empty() {
                        self.record_damage(
                            8,
                            start,
                            format!(
                                "data section CRC mismatch (stored {saved:#010x}, computed {c:#010x}): damage outside the checked chunks"
                            ),
                            "record length",
                        );
                        // Where in the data section is not known, so neither are the times.
                        self.open_times.clear();
                        if let Some(d) = self.damaged.last_mut() {
                            d.log_time_ns = [None, None];
                            d.log_time_from = "unknown".into();
                        }
                    }
                }
                if let Some(what) = self.tail_damage.take() {
                    let from = total.saturating_sub(8 + FOOTER_LEN).max(end);
                    self.record_damage(from, total, what, "end");
                }
                Ok(Step::End)
            }
            op::FOOTER => Ok(Step::End),
            _ => {
                // Indexes, attachments, metadata, private records: not needed here, but
                // read (not skipped) so that the data section's CRC covers them.
                self.read_vec(len as usize)?;
                Ok(Step::Next(end))
            }
        }
    }

    /// Checks the magic, reads the summary, and positions the reader at the first record.
    fn start(&mut self) -> Result<()> {
        self.started = true;
        if self.total_bytes < 8 {
            self.finished = true;
            let what = if self.total_bytes == 0 {
                "empty file (0 bytes)".to_string()
            } else {
                format!("{} bytes: too short for an MCAP log", self.total_bytes)
            };
            return Err(Error::format(&self.path, "byte 0", what));
        }
        let magic = self.read_vec(8).map_err(|e| self.io_err(e))?;
        if magic != MAGIC {
            self.finished = true;
            return Err(Error::format(
                &self.path,
                format!("byte 0 of {}", self.total_bytes),
                "Bad magic number: not an MCAP log",
            ));
        }
        let info = self.read_summary().map_err(|e| self.io_err(e))?;
        for (id, name, enc) in info.schemas {
            self.schemas.insert(id, (name, enc));
        }
        for (id, schema_id, topic, message_encoding) in info.channels {
            let (schema, schema_encoding) =
                self.schemas.get(&schema_id).cloned().unwrap_or_default();
            self.channels.insert(
                id,
                Arc::new(ChannelInfo {
                    topic,
                    schema,
                    schema_encoding,
                    message_encoding,
                }),
            );
        }
        self.index = info.chunks;
        self.data_end = info.data_end;
        // Reading the summary moved the file; the data-section CRC starts again from the
        // magic (hashed above only if nothing was peeked: redo it).
        self.seek_to(8).map_err(|e| self.io_err(e))?;
        let mut h = crc32fast::Hasher::new();
        h.update(MAGIC);
        self.hasher = Some(h);
        Ok(())
    }

    /// The next message, `None` at the end of the file. Damage is skipped and recorded
    /// ([`LogReader::damaged`]); an `Err` (a file that is not an MCAP log, or a read
    /// error) ends the stream.
    pub fn next_message(&mut self) -> Option<Result<RawMessage>> {
        loop {
            if let Some(m) = self.pending.pop_front() {
                self.messages += 1;
                self.last_time = Some(m.log_time);
                for i in self.open_times.drain(..) {
                    self.damaged[i].log_time_ns[1] = Some(m.log_time);
                }
                return Some(Ok(m));
            }
            if self.finished {
                return None;
            }
            if !self.started {
                if let Err(e) = self.start() {
                    return Some(Err(e));
                }
                continue;
            }
            match self.step() {
                Ok(Step::Next(at)) => {
                    if let Err(e) = self.seek_to(at) {
                        return Some(Err(self.io_err(e)));
                    }
                }
                Ok(Step::End) => self.finished = true,
                Err(e) => return Some(Err(self.io_err(e))),
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
    /// Topic name.
    pub topic: String,
    /// Schema (message type) name, `type` in JSON.
    #[serde(rename = "type")]
    pub schema: String,
    /// Messages on the topic.
    pub count: u64,
}

/// What a log holds, from one streaming pass over its messages.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LogSummary {
    /// One entry per topic.
    pub topics: Vec<TopicInfo>,
    /// Messages read.
    pub messages: u64,
    /// Earliest and latest message log time, nanoseconds (None for an empty log).
    pub start_ns: Option<u64>,
    /// Latest message log time, nanoseconds (`None` for an empty log).
    pub end_ns: Option<u64>,
    /// `end_ns − start_ns`, seconds (0 for an empty log).
    pub duration_s: f64,
    /// The damaged parts of the file, skipped (the counts are those of the messages read).
    pub damaged: Vec<DamagedRange>,
}

/// Counts messages per topic in one streaming pass. A truncated or damaged file gives the
/// counts of the messages it could read and says what was skipped in
/// [`LogSummary::damaged`]; a file that cannot be opened or read, or that is not an MCAP
/// log, is an error.
pub fn summarize(path: impl AsRef<Path>) -> Result<LogSummary> {
    crate::log::count_messages(&mut LogReader::open(path)?)
}

impl LogSummary {
    /// Whether the log has a message on `topic`.
    pub fn has_messages(&self, topic: &str) -> bool {
        self.topics.iter().any(|t| t.topic == topic && t.count > 0)
    }

    /// From the (schema, message count) of each topic and the first and last log times.
    pub(crate) fn of(
        counts: BTreeMap<String, (String, u64)>,
        start: Option<u64>,
        end: Option<u64>,
        damaged: Vec<DamagedRange>,
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
            damaged,
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
/// `Some` when every Schema and Channel record of the summary section has its
/// length-prefixed fields inside the record ([`prefixed_fields_fit`]): the `mcap` crate's
/// summary reader parses them itself and would reserve whatever a corrupted prefix claims.
/// `None` for anything unexpected (the caller then reads the log in full, checked).
fn summary_fields_fit(file: &mut File, size: u64) -> Option<()> {
    use mcap::records::op;
    use std::io::{Seek, SeekFrom};
    // Footer record (opcode, length 20, summary start, summary offset start, CRC), magic.
    const TAIL: u64 = 1 + 8 + 20 + 8;
    file.seek(SeekFrom::Start(size.checked_sub(TAIL)?)).ok()?;
    let mut tail = [0u8; TAIL as usize];
    file.read_exact(&mut tail).ok()?;
    let start = u64::from_le_bytes(tail[9..17].try_into().ok()?);
    let end = size - TAIL;
    if start == 0 {
        return Some(());
    }
    if start >= end {
        return None;
    }
    file.seek(SeekFrom::Start(start)).ok()?;
    let mut body = vec![0u8; usize::try_from(end - start).ok()?];
    file.read_exact(&mut body).ok()?;
    let mut at = 0usize;
    while at < body.len() {
        let head = body.get(at..at.checked_add(9)?)?;
        let opcode = head[0];
        let len = usize::try_from(u64::from_le_bytes(head[1..9].try_into().ok()?)).ok()?;
        let rec = body.get(at + 9..(at + 9).checked_add(len)?)?;
        if matches!(opcode, op::SCHEMA | op::CHANNEL) && !prefixed_fields_fit(opcode, rec) {
            return None;
        }
        at += 9 + len;
    }
    Some(())
}

fn summary_section(path: &Path) -> Option<LogSummary> {
    use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
    use std::io::Seek;
    let mut file = File::open(path).ok()?;
    let size = file.metadata().ok()?.len();
    summary_fields_fit(&mut file, size)?;
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
    Some(LogSummary::of(counts, start, end, Vec::new()))
}

/// Chunk compression for written logs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LogCompression {
    /// Uncompressed chunks.
    None,
    /// Zstandard.
    #[default]
    Zstd,
    /// LZ4 frames.
    Lz4,
}

/// How a log is written.
#[derive(Debug, Clone)]
pub struct WriteOptions {
    /// Chunk compression.
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
    /// Creates the log, written to a temporary file in the directory of `path` until
    /// [`LogWriter::finish`]. Fails when that file cannot be created or the MCAP header written.
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

    /// Writes a `TFMessage` on `topic` at log time `log_time_ns` (nanoseconds).
    pub fn write_tf(&mut self, topic: &str, msg: &TfMessage, log_time_ns: u64) -> Result<()> {
        let d = msg.encode(self.endian);
        self.write_known(topic, schema_name::TF_MESSAGE, log_time_ns, &d)
    }

    /// Writes a `PointCloud2` on `topic` at log time `log_time_ns` (nanoseconds).
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

    /// Writes an `Image` on `topic` at log time `log_time_ns` (nanoseconds).
    pub fn write_image_msg(&mut self, topic: &str, msg: &ImageMsg, log_time_ns: u64) -> Result<()> {
        let d = msg.encode(self.endian);
        self.write_known(topic, schema_name::IMAGE, log_time_ns, &d)
    }

    /// Writes an [`Image`] as a tightly packed `Image` message stamped with `header`.
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

    /// Writes a `CameraInfo` on `topic` at log time `log_time_ns` (nanoseconds).
    pub fn write_camera_info_msg(
        &mut self,
        topic: &str,
        msg: &CameraInfoMsg,
        log_time_ns: u64,
    ) -> Result<()> {
        let d = msg.encode(self.endian);
        self.write_known(topic, schema_name::CAMERA_INFO, log_time_ns, &d)
    }

    /// Writes a `NavSatFix` on `topic` at log time `log_time_ns` (nanoseconds).
    pub fn write_nav_sat_fix(
        &mut self,
        topic: &str,
        msg: &NavSatFixMsg,
        log_time_ns: u64,
    ) -> Result<()> {
        let d = msg.encode(self.endian);
        self.write_known(topic, schema_name::NAV_SAT_FIX, log_time_ns, &d)
    }

    /// Writes a [`CameraModel`] as a `CameraInfo` stamped with `header`.
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

#[cfg(test)]
mod field_tests {
    use super::{parse_record_checked, prefixed_fields_fit};
    use mcap::records::op;

    fn string(s: &str) -> Vec<u8> {
        let mut v = (s.len() as u32).to_le_bytes().to_vec();
        v.extend_from_slice(s.as_bytes());
        v
    }

    fn channel(topic_len: Option<u32>, map: &[(&str, &str)]) -> Vec<u8> {
        let mut b = vec![1, 0, 2, 0];
        match topic_len {
            Some(n) => b.extend_from_slice(&n.to_le_bytes()),
            None => b.extend_from_slice(&(7u32).to_le_bytes()),
        }
        b.extend_from_slice(b"/points");
        b.extend(string("cdr"));
        let pairs: Vec<u8> = map
            .iter()
            .flat_map(|(k, v)| [string(k), string(v)].concat())
            .collect();
        b.extend_from_slice(&(pairs.len() as u32).to_le_bytes());
        b.extend(pairs);
        b
    }

    #[test]
    fn length_prefixes_beyond_the_record_are_refused_before_parsing() {
        let good = channel(None, &[("k", "v")]);
        assert!(prefixed_fields_fit(op::CHANNEL, &good));
        assert!(parse_record_checked(op::CHANNEL, &good).is_ok());
        // A topic claiming 3 GB inside a 40-byte record: refused, nothing reserved.
        let bad = channel(Some(3_000_000_000), &[]);
        assert!(!prefixed_fields_fit(op::CHANNEL, &bad));
        assert!(parse_record_checked(op::CHANNEL, &bad).is_err());
        // A metadata key claiming more than its map.
        let mut m = channel(None, &[("key", "value")]);
        let at = m.len() - 3 - 4 - 5 - 4;
        m[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(!prefixed_fields_fit(op::CHANNEL, &m));
        // A schema whose data claims more than the record; one that fits.
        let mut s = vec![1, 0];
        s.extend(string("pkg/Msg"));
        s.extend(string("ros2msg"));
        s.extend_from_slice(&(1u32 << 31).to_le_bytes());
        assert!(!prefixed_fields_fit(op::SCHEMA, &s));
        let mut ok = vec![1, 0];
        ok.extend(string("pkg/Msg"));
        ok.extend(string("ros2msg"));
        ok.extend(string("int32 x"));
        assert!(prefixed_fields_fit(op::SCHEMA, &ok));
        // Truncated anywhere: refused.
        for n in 0..good.len() {
            assert!(!prefixed_fields_fit(op::CHANNEL, &good[..n]), "{n}");
        }
    }
}
