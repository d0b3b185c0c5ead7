//! ROS 1 bags (format 2.0): `#ROSBAG V2.0` then records, each a header of `name=value`
//! fields (with an `op` byte) and a data block, both length-prefixed. Messages lie in
//! chunks (uncompressed, bz2 or lz4) together with the connection records that name their
//! topic and type; the index at the end is not needed for a front-to-back read.
//!
//! The reader streams the file. Every length read from it is checked against the bytes
//! that remain before anything is allocated, and a chunk's declared uncompressed size
//! against [`record_length_limit`]. A chunk that does not decompress to its declared size,
//! or whose records do not parse, is skipped whole and recorded as damaged; a record cut
//! by the end of the file ends the read with the cut recorded. A file that does not start
//! with the 2.0 magic is an error.

use std::collections::{HashMap, VecDeque};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::error::{Error, Result};
use crate::log::MessageSource;
use crate::mcap_log::{record_length_limit, ChannelInfo, DamagedRange, RawMessage};

const MAGIC: &[u8] = b"#ROSBAG V2.0\n";

mod op {
    pub(crate) const MESSAGE: u8 = 0x02;
    pub(crate) const BAG_HEADER: u8 = 0x03;
    pub(crate) const CHUNK: u8 = 0x05;
    pub(crate) const CONNECTION: u8 = 0x07;
}

/// The `name=value` fields of a record header.
struct Fields<'a>(Vec<(&'a [u8], &'a [u8])>);

impl<'a> Fields<'a> {
    fn parse(b: &'a [u8]) -> std::result::Result<Self, String> {
        let mut out = Vec::new();
        let mut at = 0usize;
        while at < b.len() {
            let len = le_u32(b, at).ok_or("header field length cut")? as usize;
            at += 4;
            let f = at
                .checked_add(len)
                .and_then(|end| b.get(at..end))
                .ok_or_else(|| {
                    format!(
                        "header field of {len} bytes runs past its header ({} bytes)",
                        b.len()
                    )
                })?;
            at += len;
            let eq = f
                .iter()
                .position(|&c| c == b'=')
                .ok_or("header field without '='")?;
            out.push((&f[..eq], &f[eq + 1..]));
        }
        Ok(Fields(out))
    }

    fn get(&self, name: &str) -> Option<&'a [u8]> {
        self.0
            .iter()
            .find(|(n, _)| *n == name.as_bytes())
            .map(|(_, v)| *v)
    }

    fn need(&self, name: &str) -> std::result::Result<&'a [u8], String> {
        self.get(name)
            .ok_or_else(|| format!("record header lacks the {name:?} field"))
    }

    fn u32(&self, name: &str) -> std::result::Result<u32, String> {
        let v = self.need(name)?;
        le_u32(v, 0)
            .filter(|_| v.len() == 4)
            .ok_or_else(|| format!("field {name:?} is {} bytes, not 4", v.len()))
    }

    fn string(&self, name: &str) -> std::result::Result<String, String> {
        String::from_utf8(self.need(name)?.to_vec())
            .map_err(|_| format!("field {name:?} is not UTF-8"))
    }

    fn op(&self) -> std::result::Result<u8, String> {
        match self.need("op")? {
            [o] => Ok(*o),
            v => Err(format!("field \"op\" is {} bytes, not 1", v.len())),
        }
    }
}

fn le_u32(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(
        b.get(at..at.checked_add(4)?)?.try_into().ok()?,
    ))
}

/// A streaming reader of a ROS 1 bag (format 2.0).
pub struct Ros1Reader {
    path: PathBuf,
    src: BufReader<Box<dyn Read + Send>>,
    pos: u64,
    total_bytes: u64,
    limit: usize,
    conns: HashMap<u32, Arc<ChannelInfo>>,
    pending: VecDeque<RawMessage>,
    damaged: Vec<DamagedRange>,
    /// Damaged ranges waiting for the log time of the next message.
    open_times: Vec<usize>,
    last_time: Option<u64>,
    messages: u64,
    finished: bool,
}

/// One record: its header fields' bytes and data, and where it started.
struct Record {
    start: u64,
    header: Vec<u8>,
    data: Vec<u8>,
}

impl Ros1Reader {
    /// Opens `path` and checks the bag's magic: a file that is not a ROS 1 bag of format
    /// 2.0 is an error.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let file = File::open(&path).map_err(|e| Error::io(&path, e))?;
        let total_bytes = file.metadata().map_err(|e| Error::io(&path, e))?.len();
        Self::from_reader(path, Box::new(file), total_bytes)
    }

    /// A reader of a bag held in memory; `name` is used in error messages only.
    pub fn from_bytes(bytes: Vec<u8>, name: impl AsRef<Path>) -> Result<Self> {
        let total = bytes.len() as u64;
        Self::from_reader(name, Box::new(std::io::Cursor::new(bytes)), total)
    }

    /// A reader of a bag of `total_bytes` from any byte source (read front to back).
    pub fn from_reader(
        name: impl AsRef<Path>,
        source: Box<dyn Read + Send>,
        total_bytes: u64,
    ) -> Result<Self> {
        let path = name.as_ref().to_path_buf();
        let mut src = BufReader::with_capacity(256 * 1024, source);
        let mut magic = [0u8; 13];
        let mut got = 0;
        while got < magic.len() {
            let n = src
                .read(&mut magic[got..])
                .map_err(|e| Error::io(&path, e))?;
            if n == 0 {
                break;
            }
            got += n;
        }
        if &magic[..got] != MAGIC {
            let what = if magic[..got].starts_with(b"#ROSBAG V") {
                format!(
                    "ROS bag version {} is not read (format 2.0 only)",
                    String::from_utf8_lossy(&magic[9..got]).trim()
                )
            } else {
                "not a ROS 1 bag: the file does not start with \"#ROSBAG V2.0\"".to_string()
            };
            return Err(Error::format(&path, "file header", what));
        }
        Ok(Ros1Reader {
            path,
            src,
            pos: MAGIC.len() as u64,
            total_bytes,
            limit: record_length_limit(total_bytes),
            conns: HashMap::new(),
            pending: VecDeque::new(),
            damaged: Vec::new(),
            open_times: Vec::new(),
            last_time: None,
            messages: 0,
            finished: false,
        })
    }

    fn damage(&mut self, start: u64, end: u64, what: String, resumed_by: &str) {
        self.open_times.push(self.damaged.len());
        self.damaged.push(DamagedRange {
            start_byte: start,
            end_byte: end,
            what,
            log_time_ns: [self.last_time, None],
            log_time_from: "neighbours".into(),
            resumed_by: resumed_by.into(),
        });
    }

    fn read_u32(&mut self) -> std::io::Result<Option<u32>> {
        let mut b = [0u8; 4];
        let mut got = 0;
        while got < 4 {
            let n = self.src.read(&mut b[got..])?;
            if n == 0 {
                return Ok(None);
            }
            got += n;
        }
        self.pos += 4;
        Ok(Some(u32::from_le_bytes(b)))
    }

    fn read_block(&mut self, len: usize) -> std::io::Result<Vec<u8>> {
        let mut v = vec![0u8; len];
        self.src.read_exact(&mut v)?;
        self.pos += len as u64;
        Ok(v)
    }

    /// The next record, `Ok(None)` at the end of the file or after a cut record (then
    /// recorded as damaged).
    fn next_record(&mut self) -> Result<Option<Record>> {
        let start = self.pos;
        if start >= self.total_bytes {
            return Ok(None);
        }
        let io = |p: &Path, e| Error::io(p, e);
        let cut = |s: &mut Self, what: String| {
            s.damage(start, s.total_bytes, what, "end");
            Ok(None)
        };
        let Some(hlen) = self.read_u32().map_err(|e| io(&self.path, e))? else {
            return cut(self, "the file ends inside a record's header length".into());
        };
        let remain = self.total_bytes.saturating_sub(self.pos);
        if hlen as u64 > remain {
            return cut(
                self,
                format!(
                    "record header of {hlen} bytes runs past the end of the file ({remain} bytes remain)"
                ),
            );
        }
        let header = self
            .read_block(hlen as usize)
            .map_err(|e| io(&self.path, e))?;
        let Some(dlen) = self.read_u32().map_err(|e| io(&self.path, e))? else {
            return cut(self, "the file ends inside a record's data length".into());
        };
        let remain = self.total_bytes.saturating_sub(self.pos);
        if dlen as u64 > remain {
            return cut(
                self,
                format!(
                    "record data of {dlen} bytes runs past the end of the file ({remain} bytes remain)"
                ),
            );
        }
        let data = self
            .read_block(dlen as usize)
            .map_err(|e| io(&self.path, e))?;
        Ok(Some(Record {
            start,
            header,
            data,
        }))
    }

    fn connection(&mut self, f: &Fields, data: &[u8]) -> std::result::Result<(), String> {
        let id = f.u32("conn")?;
        let topic = f.string("topic")?;
        let h = Fields::parse(data).map_err(|e| format!("connection header: {e}"))?;
        let ty = h
            .string("type")
            .map_err(|e| format!("connection {id}: {e}"))?;
        self.conns.insert(
            id,
            Arc::new(ChannelInfo {
                topic,
                schema: ty,
                schema_encoding: "ros1msg".into(),
                message_encoding: "ros1".into(),
            }),
        );
        Ok(())
    }

    fn message(&mut self, f: &Fields, data: Vec<u8>) -> std::result::Result<RawMessage, String> {
        let conn = f.u32("conn")?;
        let t = f.need("time")?;
        if t.len() != 8 {
            return Err(format!("field \"time\" is {} bytes, not 8", t.len()));
        }
        let sec = le_u32(t, 0).unwrap_or(0) as u64;
        let nsec = le_u32(t, 4).unwrap_or(0) as u64;
        let channel = match self.conns.get(&conn) {
            Some(c) => c.clone(),
            None => Arc::new(ChannelInfo {
                topic: format!("<connection {conn}, no connection record before it>"),
                schema: String::new(),
                schema_encoding: String::new(),
                message_encoding: String::new(),
            }),
        };
        let ns = sec * 1_000_000_000 + nsec;
        Ok(RawMessage {
            channel,
            sequence: 0,
            log_time: ns,
            publish_time: ns,
            data,
        })
    }

    /// The chunk's records, decompressed and parsed whole: its messages in order.
    fn chunk(&mut self, f: &Fields, data: &[u8]) -> std::result::Result<Vec<RawMessage>, String> {
        let compression = f.string("compression")?;
        let size = f.u32("size")? as usize;
        if size > self.limit {
            return Err(format!(
                "chunk declares {size} bytes uncompressed, more than the {} a file of this size may hold",
                self.limit
            ));
        }
        let raw: Vec<u8> = match compression.as_str() {
            "none" => {
                if data.len() != size {
                    return Err(format!(
                        "uncompressed chunk holds {} bytes, its header says {size}",
                        data.len()
                    ));
                }
                data.to_vec()
            }
            "bz2" => inflate(bzip2::read::BzDecoder::new(data), size, "bz2")?,
            "lz4" => inflate(
                lz4::Decoder::new(data).map_err(|e| format!("lz4 chunk: {e}"))?,
                size,
                "lz4",
            )?,
            c => return Err(format!("unknown chunk compression {c:?} (none, bz2, lz4)")),
        };
        let mut out = Vec::new();
        let mut at = 0usize;
        while at < raw.len() {
            let field = |what: &str, at: usize| {
                le_u32(&raw, at).ok_or_else(|| format!("chunk byte {at}: {what} cut"))
            };
            let hlen = field("record header length", at)? as usize;
            let h0 = at + 4;
            let h1 = h0
                .checked_add(hlen)
                .filter(|&e| e <= raw.len())
                .ok_or_else(|| format!("chunk byte {at}: record header runs past the chunk"))?;
            let dlen = field("record data length", h1)? as usize;
            let d0 = h1 + 4;
            let d1 = d0
                .checked_add(dlen)
                .filter(|&e| e <= raw.len())
                .ok_or_else(|| format!("chunk byte {at}: record data runs past the chunk"))?;
            let rf = Fields::parse(&raw[h0..h1]).map_err(|e| format!("chunk byte {at}: {e}"))?;
            match rf.op().map_err(|e| format!("chunk byte {at}: {e}"))? {
                op::CONNECTION => self
                    .connection(&rf, &raw[d0..d1])
                    .map_err(|e| format!("chunk byte {at}: {e}"))?,
                op::MESSAGE => out.push(
                    self.message(&rf, raw[d0..d1].to_vec())
                        .map_err(|e| format!("chunk byte {at}: {e}"))?,
                ),
                _ => {}
            }
            at = d1;
        }
        Ok(out)
    }

    /// Reads records until messages are pending or the file ends.
    fn step(&mut self) -> Result<()> {
        let Some(rec) = self.next_record()? else {
            self.finished = true;
            return Ok(());
        };
        let end = self.pos;
        let fields = match Fields::parse(&rec.header).and_then(|f| f.op().map(|o| (f, o))) {
            Ok(x) => x,
            Err(e) => {
                self.damage(rec.start, end, e, "record length");
                return Ok(());
            }
        };
        let (f, o) = fields;
        let r = match o {
            op::CHUNK => self.chunk(&f, &rec.data).map(|ms| self.pending.extend(ms)),
            op::CONNECTION => self.connection(&f, &rec.data),
            op::MESSAGE => self
                .message(&f, rec.data)
                .map(|m| self.pending.push_back(m)),
            op::BAG_HEADER => Ok(()),
            // Index data and chunk info: the index, not needed front to back.
            _ => Ok(()),
        };
        if let Err(e) = r {
            let kind = match o {
                op::CHUNK => "chunk",
                op::CONNECTION => "connection record",
                op::MESSAGE => "message record",
                _ => "record",
            };
            self.damage(rec.start, end, format!("{kind}: {e}"), "record length");
        }
        Ok(())
    }
}

/// Decompresses exactly `size` bytes from `r`, or says why not.
fn inflate(r: impl Read, size: usize, what: &str) -> std::result::Result<Vec<u8>, String> {
    // Grown as the data decompresses: the declared size is only checked, never reserved.
    let mut out = Vec::new();
    r.take(size as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| format!("{what} chunk does not decompress: {e}"))?;
    if out.len() != size {
        return Err(format!(
            "{what} chunk decompresses to {}{} bytes, its header says {size}",
            if out.len() > size { "more than " } else { "" },
            out.len().min(size)
        ));
    }
    Ok(out)
}

impl MessageSource for Ros1Reader {
    fn next_message(&mut self) -> Option<Result<RawMessage>> {
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
            if let Err(e) = self.step() {
                self.finished = true;
                return Some(Err(e));
            }
        }
    }
    fn path(&self) -> &Path {
        &self.path
    }
    fn bytes_read(&self) -> u64 {
        self.pos
    }
    fn total_bytes(&self) -> u64 {
        self.total_bytes
    }
    fn messages_read(&self) -> u64 {
        self.messages
    }
    fn damaged(&self) -> &[DamagedRange] {
        &self.damaged
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(name: &str, value: &[u8]) -> Vec<u8> {
        let mut f = name.as_bytes().to_vec();
        f.push(b'=');
        f.extend_from_slice(value);
        let mut v = (f.len() as u32).to_le_bytes().to_vec();
        v.extend(f);
        v
    }

    fn record(header: &[Vec<u8>], data: &[u8]) -> Vec<u8> {
        let h: Vec<u8> = header.concat();
        let mut v = (h.len() as u32).to_le_bytes().to_vec();
        v.extend(h);
        v.extend((data.len() as u32).to_le_bytes());
        v.extend_from_slice(data);
        v
    }

    /// A bag of one uncompressed chunk: a connection on /x of an unread type and one
    /// message of 3 bytes at 5.5 s.
    fn bag() -> Vec<u8> {
        let conn = record(
            &[
                field("op", &[op::CONNECTION]),
                field("conn", &0u32.to_le_bytes()),
                field("topic", b"/x"),
            ],
            &[field("topic", b"/x"), field("type", b"std_msgs/String")].concat(),
        );
        let mut t = 5u32.to_le_bytes().to_vec();
        t.extend(500_000_000u32.to_le_bytes());
        let msg = record(
            &[
                field("op", &[op::MESSAGE]),
                field("conn", &0u32.to_le_bytes()),
                field("time", &t),
            ],
            b"abc",
        );
        let inner = [conn, msg].concat();
        let chunk = record(
            &[
                field("op", &[op::CHUNK]),
                field("compression", b"none"),
                field("size", &(inner.len() as u32).to_le_bytes()),
            ],
            &inner,
        );
        [MAGIC.to_vec(), chunk].concat()
    }

    fn read_all(b: Vec<u8>) -> (Vec<RawMessage>, Vec<DamagedRange>) {
        let mut r = Ros1Reader::from_bytes(b, "t.bag").unwrap();
        let mut v = Vec::new();
        while let Some(m) = r.next_message() {
            v.push(m.unwrap());
        }
        (v, r.damaged().to_vec())
    }

    #[test]
    fn reads_connections_and_messages_of_a_chunk() {
        let (m, d) = read_all(bag());
        assert!(d.is_empty());
        assert_eq!(m.len(), 1);
        assert_eq!(m[0].channel.topic, "/x");
        assert_eq!(m[0].channel.schema, "std_msgs/String");
        assert_eq!(m[0].channel.message_encoding, "ros1");
        assert_eq!(m[0].log_time, 5_500_000_000);
        assert_eq!(m[0].data, b"abc");
    }

    #[test]
    fn a_cut_bag_reports_the_cut_and_a_bad_chunk_is_skipped() {
        let b = bag();
        for cut in MAGIC.len() + 1..b.len() {
            let (m, d) = read_all(b[..cut].to_vec());
            assert!(m.is_empty());
            assert_eq!(d.len(), 1, "cut at {cut}");
            assert_eq!(d[0].end_byte, cut as u64);
            assert_eq!(d[0].resumed_by, "end");
        }
        // A chunk whose declared size disagrees with its data: skipped whole.
        let mut b = bag();
        let at = b.windows(5).position(|w| w == b"size=").unwrap() + 5;
        b[at] ^= 1;
        let (m, d) = read_all(b);
        assert!(m.is_empty());
        assert!(d[0].what.contains("chunk"), "{}", d[0].what);
    }

    #[test]
    fn not_a_bag_or_another_version_is_refused() {
        let e = Ros1Reader::from_bytes(b"#ROSBAG V1.2\n".to_vec(), "old.bag")
            .err()
            .unwrap();
        assert!(e.to_string().contains("version 1.2"), "{e}");
        let e = Ros1Reader::from_bytes(b"hello".to_vec(), "x.bag")
            .err()
            .unwrap();
        assert!(e.to_string().contains("not a ROS 1 bag"), "{e}");
    }
}
