//! rosbag2's sqlite3 storage (`.db3`): a `topics` table (id, name, type,
//! serialization_format) and a `messages` table (id, topic_id, timestamp, data) of CDR
//! messages. The file has type names only, no schema text: tarn decodes the types it knows.
//!
//! Messages are read in the order they were recorded (`messages.id`, the table's rowid),
//! a few at a time, so memory holds a handful of messages whatever the bag's size.

use std::collections::HashMap;
use std::collections::VecDeque;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rusqlite::{Connection, OpenFlags};

use crate::error::{Error, Result};
use crate::log::MessageSource;
use crate::mcap_log::{ChannelInfo, DamagedRange, RawMessage};

/// Messages fetched per query.
const PAGE: i64 = 8;

const SQLITE_MAGIC: &[u8; 16] = b"SQLite format 3\0";

/// A streaming reader of a rosbag2 `.db3` file.
pub struct Db3Reader {
    path: PathBuf,
    conn: Connection,
    topics: HashMap<i64, Arc<ChannelInfo>>,
    /// Largest message id (for progress).
    max_id: i64,
    last_id: i64,
    total_bytes: u64,
    pending: VecDeque<RawMessage>,
    messages: u64,
    finished: bool,
}

/// Whether the file is as long as its SQLite header says: a truncated bag is named as such
/// rather than as whatever page SQLite then fails to read.
fn check_size(head: &[u8], len: u64) -> std::result::Result<(), String> {
    if head.len() < 100 {
        return Err(format!(
            "truncated: {len} bytes, shorter than the 100-byte SQLite header"
        ));
    }
    let page = match u16::from_be_bytes([head[16], head[17]]) {
        1 => 65536u64,
        p if p >= 512 && p.is_power_of_two() => p as u64,
        p => return Err(format!("SQLite header gives page size {p}: damaged")),
    };
    let be32 = |at: usize| u32::from_be_bytes([head[at], head[at + 1], head[at + 2], head[at + 3]]);
    // The page count is valid when the change counter matches "version valid for".
    let pages = be32(28) as u64;
    if be32(24) == be32(92) && pages > 0 && len < pages * page {
        return Err(format!(
            "truncated: the SQLite header says {pages} pages of {page} bytes ({} bytes), the file has {len}",
            pages * page
        ));
    }
    if len % page != 0 {
        return Err(format!(
            "truncated: {len} bytes is not a whole number of {page}-byte SQLite pages"
        ));
    }
    Ok(())
}

fn sql_err(path: &Path, what: &str, e: rusqlite::Error) -> Error {
    Error::format(path, what, format!("SQLite: {e}"))
}

impl Db3Reader {
    /// Opens `path` read-only and reads its topics. A file that is not SQLite, or an SQLite
    /// file without rosbag2's tables, is an error naming what is missing.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let mut f = std::fs::File::open(&path).map_err(|e| Error::io(&path, e))?;
        let total_bytes = f.metadata().map_err(|e| Error::io(&path, e))?.len();
        let mut head = [0u8; 100];
        let mut got = 0;
        while got < head.len() {
            let n = f.read(&mut head[got..]).map_err(|e| Error::io(&path, e))?;
            if n == 0 {
                break;
            }
            got += n;
        }
        if got < 16 || &head[..16] != SQLITE_MAGIC {
            return Err(Error::format(
                &path,
                "file header",
                "not an SQLite database (a rosbag2 .db3 starts with \"SQLite format 3\")",
            ));
        }
        drop(f);
        check_size(&head[..got], total_bytes).map_err(|e| Error::format(&path, "file size", e))?;
        let conn = Connection::open_with_flags(
            &path,
            OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
        )
        .map_err(|e| sql_err(&path, "sqlite", e))?;
        let mut topics = HashMap::new();
        {
            let mut st = conn
                .prepare("SELECT id, name, type, serialization_format FROM topics")
                .map_err(|e| sql_err(&path, "topics table", e))?;
            let rows = st
                .query_map([], |r| {
                    Ok((
                        r.get::<_, i64>(0)?,
                        r.get::<_, String>(1)?,
                        r.get::<_, String>(2)?,
                        r.get::<_, String>(3)?,
                    ))
                })
                .map_err(|e| sql_err(&path, "topics table", e))?;
            for row in rows {
                let (id, name, ty, fmt) = row.map_err(|e| sql_err(&path, "topics table", e))?;
                topics.insert(
                    id,
                    Arc::new(ChannelInfo {
                        topic: name,
                        schema: ty,
                        schema_encoding: String::new(),
                        message_encoding: fmt,
                    }),
                );
            }
        }
        let max_id: i64 = conn
            .query_row("SELECT coalesce(max(id), 0) FROM messages", [], |r| {
                r.get(0)
            })
            .map_err(|e| sql_err(&path, "messages table", e))?;
        Ok(Db3Reader {
            path,
            conn,
            topics,
            max_id,
            last_id: i64::MIN,
            total_bytes,
            pending: VecDeque::new(),
            messages: 0,
            finished: false,
        })
    }

    fn fetch(&mut self) -> Result<()> {
        let mut st = self
            .conn
            .prepare(
                "SELECT id, topic_id, timestamp, data FROM messages WHERE id > ?1 ORDER BY id LIMIT ?2",
            )
            .map_err(|e| sql_err(&self.path, "messages table", e))?;
        let rows = st
            .query_map([self.last_id, PAGE], |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    r.get::<_, i64>(1)?,
                    r.get::<_, i64>(2)?,
                    r.get::<_, Vec<u8>>(3)?,
                ))
            })
            .map_err(|e| sql_err(&self.path, "messages table", e))?;
        let mut any = false;
        for row in rows {
            let (id, topic_id, ts, data) = row.map_err(|e| {
                sql_err(
                    &self.path,
                    &format!("messages table after message id {}", self.last_id),
                    e,
                )
            })?;
            any = true;
            self.last_id = id;
            let channel = match self.topics.get(&topic_id) {
                Some(c) => c.clone(),
                None => {
                    // Counted as a message of unknown type by the frame stream.
                    let c = Arc::new(ChannelInfo {
                        topic: format!("<topic id {topic_id}, not in the topics table>"),
                        schema: String::new(),
                        schema_encoding: String::new(),
                        message_encoding: String::new(),
                    });
                    self.topics.insert(topic_id, c.clone());
                    c
                }
            };
            let t = u64::try_from(ts).map_err(|_| {
                Error::format(
                    &self.path,
                    format!("message id {id}"),
                    format!("negative timestamp {ts}"),
                )
            })?;
            self.pending.push_back(RawMessage {
                channel,
                sequence: 0,
                log_time: t,
                publish_time: t,
                data,
            });
        }
        if !any {
            self.finished = true;
        }
        Ok(())
    }
}

impl MessageSource for Db3Reader {
    fn next_message(&mut self) -> Option<Result<RawMessage>> {
        loop {
            if let Some(m) = self.pending.pop_front() {
                self.messages += 1;
                return Some(Ok(m));
            }
            if self.finished {
                return None;
            }
            if let Err(e) = self.fetch() {
                self.finished = true;
                return Some(Err(e));
            }
        }
    }
    fn path(&self) -> &Path {
        &self.path
    }
    fn bytes_read(&self) -> u64 {
        if self.finished || self.max_id <= 0 {
            return self.total_bytes;
        }
        let f = (self.last_id.max(0) as f64 / self.max_id as f64).clamp(0.0, 1.0);
        (self.total_bytes as f64 * f) as u64
    }
    fn total_bytes(&self) -> u64 {
        self.total_bytes
    }
    fn messages_read(&self) -> u64 {
        self.messages
    }
    fn damaged(&self) -> &[DamagedRange] {
        &[]
    }
}
