//! What a log holds, by topic: from one streaming pass over the messages, or read
//! from the summary section's statistics without touching them.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Read;
use std::path::Path;

use super::records::prefixed_fields_fit;
use super::{record_length_limit, DamagedRange, LogReader};
use crate::error::Result;

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
