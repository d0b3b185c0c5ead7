//! Damage: recording a skipped range with the log times that bound it, and finding where
//! reading goes on (the chunk index, or a forward scan for the next plausible record).

use super::{IndexedChunk, LogReader, Step};
use crate::mcap_log::records::{parse_record_checked, u32_at, u64_at};
use crate::mcap_log::DamagedRange;

impl LogReader {
    /// Records a damaged range `[start, end)`, and drops the data-section CRC (it can no
    /// longer be checked).
    pub(super) fn record_damage(&mut self, start: u64, end: u64, what: String, resumed_by: &str) {
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
    pub(super) fn resume_after(&mut self, start: u64, what: String) -> std::io::Result<Step> {
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
    pub(super) fn followed_well(&mut self, end: u64) -> std::io::Result<bool> {
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
}
