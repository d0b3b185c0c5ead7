//! The byte-level layout of MCAP records the reader checks itself before trusting the `mcap`
//! crate with them: the file magic, the footer length, little-endian fields, the
//! length-prefixed fields of Schema and Channel records, and a chunk record's header.

/// Whether the length-prefixed fields of a Schema or Channel record body lie inside it.
/// The `mcap` crate's parser reserves a string or map of its declared length before it
/// checks that length against the record, so a corrupted prefix inside a record of
/// plausible length would ask for gigabytes.
pub(super) fn prefixed_fields_fit(opcode: u8, body: &[u8]) -> bool {
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
pub(super) fn parse_record_checked(
    opcode: u8,
    body: &[u8],
) -> mcap::McapResult<mcap::records::Record<'_>> {
    if !prefixed_fields_fit(opcode, body) {
        return Err(mcap::McapError::UnexpectedEof);
    }
    mcap::parse_record(opcode, body)
}

pub(super) const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
pub(super) const FOOTER_LEN: u64 = 9 + 20;

pub(super) fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

pub(super) fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

/// Whether a chunk record body's header fields agree with each other and with the body's
/// length (the chunk's framing held, whatever its contents).
pub(super) fn chunk_header(body: &[u8]) -> std::result::Result<(), String> {
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

#[cfg(test)]
mod tests {
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
