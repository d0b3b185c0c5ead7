//! Reading one record: checking its header against the file and the chunk index,
//! decoding a chunk all or nothing, applying schema, channel and message records, and
//! checking the data section's CRC at its end.

use std::sync::Arc;

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader};

use super::{LogReader, Step};
use crate::mcap_log::records::{chunk_header, parse_record_checked, u32_at, u64_at, FOOTER_LEN};
use crate::mcap_log::{ChannelInfo, RawMessage};

impl LogReader {
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
    pub(super) fn step(&mut self) -> std::io::Result<Step> {
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
            op::CHUNK => self.read_chunk(start, end, head, len),
            op::SCHEMA | op::CHANNEL | op::MESSAGE => {
                let body = self.read_vec(len as usize)?;
                if let Err(what) = self.apply(opcode, &body) {
                    self.record_damage(start, end, what, "record length");
                }
                Ok(Step::Next(end))
            }
            op::DATA_END => self.read_data_end(start, end, len, crc_before),
            op::FOOTER => Ok(Step::End),
            _ => {
                // Indexes, attachments, metadata, private records: not needed here, but
                // read (not skipped) so that the data section's CRC covers them.
                self.read_vec(len as usize)?;
                Ok(Step::Next(end))
            }
        }
    }

    /// Reads the chunk record whose 9-byte header `head` is read, `len` bytes of body
    /// ending at `end`: its messages are queued when it decodes; when it does not, it is
    /// recorded as damaged and reading goes on after it if its framing held, else where
    /// [`LogReader::resume_after`] finds.
    fn read_chunk(
        &mut self,
        start: u64,
        end: u64,
        head: Vec<u8>,
        len: u64,
    ) -> std::io::Result<Step> {
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

    /// Reads the DataEnd record at `start` and checks the data section's CRC
    /// (`crc_before`: the hash of every byte before it, when nothing was skipped); the
    /// damage found at the file's tail while reading the summary is recorded here, after
    /// the data section.
    fn read_data_end(
        &mut self,
        start: u64,
        end: u64,
        len: u64,
        crc_before: Option<crc32fast::Hasher>,
    ) -> std::io::Result<Step> {
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
            let total = self.total_bytes;
            let from = total.saturating_sub(8 + FOOTER_LEN).max(end);
            self.record_damage(from, total, what, "end");
        }
        Ok(Step::End)
    }
}
