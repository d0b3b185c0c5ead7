//! The summary section as the reader uses it: its chunk index, schemas and channels, read
//! from the footer's pointer and checked (CRC, framing, an index that fits the data section).

use mcap::records::Record;

use super::LogReader;
use crate::mcap_log::records::{parse_record_checked, u32_at, u64_at, FOOTER_LEN, MAGIC};
use crate::mcap_log::DamagedRange;

/// A chunk as the summary section's chunk index places it.
#[derive(Debug, Clone, Copy)]
pub(super) struct IndexedChunk {
    pub(super) start: u64,
    pub(super) end: u64,
    pub(super) t0: u64,
    pub(super) t1: u64,
}

/// What the summary section gives a reader.
#[derive(Default)]
pub(super) struct SummaryInfo {
    pub(super) chunks: Vec<IndexedChunk>,
    pub(super) schemas: Vec<(u16, String, String)>,
    pub(super) channels: Vec<(u16, u16, String, String)>,
    /// Where the data section ends (the summary's start).
    pub(super) data_end: Option<u64>,
}

impl LogReader {
    /// Reads the footer and the summary section (its chunk index, schemas and channels),
    /// when the file has them and the summary's CRC holds. A damaged summary is recorded
    /// and not used.
    pub(super) fn read_summary(&mut self) -> std::io::Result<SummaryInfo> {
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
}
