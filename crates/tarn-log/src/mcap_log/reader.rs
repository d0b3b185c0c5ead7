//! [`LogReader`]: the streaming reader's state, its byte-source primitives, and the loop
//! that turns records into messages. Reading the summary section, recovering from damage,
//! and reading one record are in the submodules.

use std::collections::HashMap;
use std::fs::File;
use std::io::{Read, Seek};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::records::MAGIC;
use super::{record_length_limit, ChannelInfo, DamagedRange, LogSource, RawMessage};
use crate::error::{Error, Result};
use index::IndexedChunk;

mod index;
mod recovery;
mod step;

const READ_SIZE: usize = 256 * 1024;

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
    pub(crate) fn bytes_read(&self) -> u64 {
        self.pos
    }

    /// Size of the file in bytes.
    pub(crate) fn total_bytes(&self) -> u64 {
        self.total_bytes
    }

    /// Messages returned so far.
    pub(crate) fn messages_read(&self) -> u64 {
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
