//! Robot logs of every storage tarn reads, behind one interface: an MCAP file, a rosbag2
//! directory (`metadata.yaml` beside `.mcap` or `.db3` files), a rosbag2 sqlite3 file
//! (`.db3`) and a ROS 1 bag (`.bag`). The last two need the `bags` feature (on by default).
//!
//! Every reader yields [`RawMessage`]s in file order; a message's channel names its type
//! (`sensor_msgs/msg/PointCloud2` or the ROS 1 `sensor_msgs/PointCloud2`, see
//! [`canonical_type`]) and its encoding (`cdr`, or `ros1` for a ROS 1 bag).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::mcap_log::{DamagedRange, LogReader, LogSummary, RawMessage};
use crate::ros::{schema_name, Wire};

/// The inputs tarn accepts, for error messages.
pub(crate) const SUPPORTED: &str = "supported: .mcap, .db3, rosbag2 directory, .bag, .ply, .bin";

/// Reads an input that is not a log: a point cloud ([`tarn::io::read_point_cloud`]: `.ply`,
/// `.bin`). Anything else is an error that names every input tarn reads, logs included.
pub fn read_cloud(path: &Path) -> Result<tarn::geom::PointCloud> {
    let is_cloud = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("ply") || e.eq_ignore_ascii_case("bin"));
    if !is_cloud {
        return Err(Error::format(
            path,
            "file name",
            format!("not an input tarn reads ({SUPPORTED})"),
        ));
    }
    tarn::io::read_point_cloud(path)
}

/// A stream of the messages of a log.
pub trait MessageSource: Send {
    /// The next message, `None` at the end. Damage is skipped and recorded where the
    /// storage allows ([`MessageSource::damaged`]); an `Err` ends the stream.
    fn next_message(&mut self) -> Option<Result<RawMessage>>;
    /// The log's path (a file, or a rosbag2 directory).
    fn path(&self) -> &Path;
    /// Bytes of the log consumed so far (for a progress bar).
    fn bytes_read(&self) -> u64;
    /// Size of the log in bytes.
    fn total_bytes(&self) -> u64;
    /// Messages returned so far.
    fn messages_read(&self) -> u64;
    /// The parts of the log skipped so far as damaged, in file order.
    fn damaged(&self) -> &[DamagedRange];
}

impl MessageSource for LogReader {
    fn next_message(&mut self) -> Option<Result<RawMessage>> {
        LogReader::next_message(self)
    }
    fn path(&self) -> &Path {
        LogReader::path(self)
    }
    fn bytes_read(&self) -> u64 {
        LogReader::bytes_read(self)
    }
    fn total_bytes(&self) -> u64 {
        LogReader::total_bytes(self)
    }
    fn messages_read(&self) -> u64 {
        LogReader::messages_read(self)
    }
    fn damaged(&self) -> &[DamagedRange] {
        LogReader::damaged(self)
    }
}

/// The storage of a log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogFormat {
    /// An MCAP file.
    Mcap,
    /// rosbag2 sqlite3 storage.
    Db3,
    /// A rosbag2 directory: `metadata.yaml` and its storage files.
    Rosbag2Dir,
    /// ROS 1 bag, format 2.0.
    Ros1Bag,
}

/// The log format of `path` by its extension (or, for a directory, its `metadata.yaml`);
/// `None` when it is not a log (a point cloud, or unknown).
pub fn log_format(path: &Path) -> Option<LogFormat> {
    if path.is_dir() {
        return Some(LogFormat::Rosbag2Dir);
    }
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    match ext.as_str() {
        "mcap" => Some(LogFormat::Mcap),
        "db3" => Some(LogFormat::Db3),
        "bag" => Some(LogFormat::Ros1Bag),
        _ => None,
    }
}

/// Whether `path` is read as a log ([`log_format`]).
pub fn is_log(path: &Path) -> bool {
    log_format(path).is_some()
}

/// The canonical (ROS 2) name of a message type tarn reads, from its ROS 2 name or its
/// ROS 1 name (`sensor_msgs/PointCloud2`, `tf2_msgs/TFMessage`, `tf/tfMessage`); `None`
/// for any other type.
pub fn canonical_type(name: &str) -> Option<&'static str> {
    Some(match name {
        "tf2_msgs/msg/TFMessage" | "tf2_msgs/TFMessage" | "tf/tfMessage" => schema_name::TF_MESSAGE,
        "sensor_msgs/msg/PointCloud2" | "sensor_msgs/PointCloud2" => schema_name::POINT_CLOUD2,
        "sensor_msgs/msg/Image" | "sensor_msgs/Image" => schema_name::IMAGE,
        "sensor_msgs/msg/CameraInfo" | "sensor_msgs/CameraInfo" => schema_name::CAMERA_INFO,
        "sensor_msgs/msg/NavSatFix" | "sensor_msgs/NavSatFix" => schema_name::NAV_SAT_FIX,
        _ => return None,
    })
}

/// The wire of a channel's message encoding (`cdr`, `ros1`), `None` for another one.
pub fn wire_of(message_encoding: &str) -> Option<Wire> {
    match message_encoding {
        "cdr" => Some(Wire::Cdr),
        "ros1" => Some(Wire::Ros1),
        _ => None,
    }
}

/// Opens the log at `path` for streaming, choosing the reader by [`log_format`].
pub fn open(path: impl AsRef<Path>) -> Result<Box<dyn MessageSource>> {
    let path = path.as_ref();
    match log_format(path) {
        Some(LogFormat::Mcap) => Ok(Box::new(LogReader::open(path)?)),
        Some(LogFormat::Rosbag2Dir) => Ok(Box::new(Chain::open_rosbag2(path)?)),
        Some(LogFormat::Db3) => open_db3(path),
        Some(LogFormat::Ros1Bag) => open_ros1(path),
        None => Err(Error::format(
            path,
            "file name",
            format!("not a log tarn reads ({SUPPORTED})"),
        )),
    }
}

#[cfg(feature = "bags")]
fn open_db3(path: &Path) -> Result<Box<dyn MessageSource>> {
    Ok(Box::new(crate::bags::Db3Reader::open(path)?))
}

#[cfg(feature = "bags")]
fn open_ros1(path: &Path) -> Result<Box<dyn MessageSource>> {
    Ok(Box::new(crate::bags::Ros1Reader::open(path)?))
}

#[cfg(not(feature = "bags"))]
fn without_bags(path: &Path) -> Result<Box<dyn MessageSource>> {
    Err(Error::format(
        path,
        "file name",
        "this tarn was built without the `bags` feature: it reads MCAP logs only",
    ))
}

#[cfg(not(feature = "bags"))]
fn open_db3(path: &Path) -> Result<Box<dyn MessageSource>> {
    without_bags(path)
}

#[cfg(not(feature = "bags"))]
fn open_ros1(path: &Path) -> Result<Box<dyn MessageSource>> {
    without_bags(path)
}

/// The storage files of a rosbag2 directory, in order: `relative_file_paths` of its
/// `metadata.yaml` (read as the list under that key: `- name` lines), else its `.db3` and
/// `.mcap` files by name.
pub(crate) fn rosbag2_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let meta = dir.join("metadata.yaml");
    let text = std::fs::read_to_string(&meta).map_err(|e| {
        Error::format(
            dir,
            "metadata.yaml",
            format!("not a rosbag2 directory (no readable metadata.yaml: {e}); {SUPPORTED}"),
        )
    })?;
    let mut files = Vec::new();
    let mut lines = text.lines();
    while let Some(l) = lines.next() {
        if l.trim_start().starts_with("relative_file_paths:") {
            for item in lines.by_ref() {
                let t = item.trim();
                let Some(name) = t.strip_prefix("- ") else {
                    break;
                };
                let name = name.trim().trim_matches(|c| c == '"' || c == '\'');
                if name.contains("..") || Path::new(name).is_absolute() {
                    return Err(Error::format(
                        &meta,
                        "relative_file_paths",
                        format!("{name:?} is not a file of the bag's directory"),
                    ));
                }
                files.push(dir.join(name));
            }
            break;
        }
    }
    if files.is_empty() {
        let rd = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
        for e in rd {
            let p = e.map_err(|e| Error::io(dir, e))?.path();
            if matches!(log_format(&p), Some(LogFormat::Db3 | LogFormat::Mcap)) && p.is_file() {
                files.push(p);
            }
        }
        files.sort();
    }
    if files.is_empty() {
        return Err(Error::format(
            dir,
            "metadata.yaml",
            "the rosbag2 directory names no storage file and holds no .db3 or .mcap",
        ));
    }
    for f in &files {
        if !matches!(log_format(f), Some(LogFormat::Db3 | LogFormat::Mcap)) {
            return Err(Error::format(
                f,
                "file name",
                "a rosbag2 storage file must be .db3 (sqlite3) or .mcap",
            ));
        }
        if !f.is_file() {
            return Err(Error::format(
                f,
                "metadata.yaml",
                "named by the bag's metadata.yaml but missing",
            ));
        }
    }
    Ok(files)
}

/// The files of a rosbag2 directory read one after the other.
struct Chain {
    dir: PathBuf,
    files: Vec<PathBuf>,
    next_file: usize,
    current: Option<Box<dyn MessageSource>>,
    sizes: Vec<u64>,
    done_bytes: u64,
    messages: u64,
    /// Damage of the files already read.
    done_damage: Vec<DamagedRange>,
    /// `done_damage` and the current file's.
    damage: Vec<DamagedRange>,
}

impl Chain {
    fn open_rosbag2(dir: &Path) -> Result<Self> {
        let files = rosbag2_files(dir)?;
        let sizes = files
            .iter()
            .map(|f| {
                std::fs::metadata(f)
                    .map(|m| m.len())
                    .map_err(|e| Error::io(f, e))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Chain {
            dir: dir.to_path_buf(),
            files,
            next_file: 0,
            current: None,
            sizes,
            done_bytes: 0,
            messages: 0,
            done_damage: Vec::new(),
            damage: Vec::new(),
        })
    }

    fn named(&self, d: &DamagedRange, file: &Path) -> DamagedRange {
        DamagedRange {
            what: format!("{}: {}", file.display(), d.what),
            ..d.clone()
        }
    }
}

impl MessageSource for Chain {
    fn next_message(&mut self) -> Option<Result<RawMessage>> {
        loop {
            if let Some(cur) = self.current.as_mut() {
                let m = cur.next_message();
                let file = cur.path().to_path_buf();
                if cur.damaged().len() + self.done_damage.len() != self.damage.len() {
                    let named = cur.damaged().to_vec();
                    self.damage = self.done_damage.clone();
                    for d in &named {
                        self.damage.push(self.named(d, &file));
                    }
                }
                match m {
                    Some(Ok(m)) => {
                        self.messages += 1;
                        return Some(Ok(m));
                    }
                    Some(Err(e)) => return Some(Err(e)),
                    None => {
                        self.done_bytes += self.sizes[self.next_file - 1];
                        self.done_damage = self.damage.clone();
                        self.current = None;
                    }
                }
            }
            let f = self.files.get(self.next_file)?.clone();
            self.next_file += 1;
            match open(&f) {
                Ok(r) => self.current = Some(r),
                Err(e) => return Some(Err(e)),
            }
        }
    }
    fn path(&self) -> &Path {
        &self.dir
    }
    fn bytes_read(&self) -> u64 {
        self.done_bytes + self.current.as_ref().map_or(0, |c| c.bytes_read())
    }
    fn total_bytes(&self) -> u64 {
        self.sizes.iter().sum()
    }
    fn messages_read(&self) -> u64 {
        self.messages
    }
    fn damaged(&self) -> &[DamagedRange] {
        &self.damage
    }
}

/// Counts messages per topic in one streaming pass over any log ([`open`]). A truncated
/// or damaged file gives the counts of the messages it could read and says what was
/// skipped in [`LogSummary::damaged`].
pub fn summarize(path: impl AsRef<Path>) -> Result<LogSummary> {
    count_messages(open(path)?.as_mut())
}

/// Counts the messages of a source per topic, with their time span and the damage skipped.
pub(crate) fn count_messages(r: &mut dyn MessageSource) -> Result<LogSummary> {
    let mut counts: BTreeMap<String, (String, u64)> = BTreeMap::new();
    let (mut start, mut end) = (None::<u64>, None::<u64>);
    while let Some(m) = r.next_message() {
        let m = m?;
        // A log without a summary section is counted in a pass of its own before a build.
        crate::interrupt::check("counting the log's messages")?;
        let e = counts
            .entry(m.channel.topic.clone())
            .or_insert_with(|| (m.channel.schema.clone(), 0));
        e.1 += 1;
        start = Some(start.map_or(m.log_time, |s| s.min(m.log_time)));
        end = Some(end.map_or(m.log_time, |s| s.max(m.log_time)));
    }
    Ok(LogSummary::of(counts, start, end, r.damaged().to_vec()))
}

/// [`crate::mcap_log::summarize_quick`] for an MCAP file (its summary section when it has
/// one), [`summarize`] for every other log.
pub fn summarize_quick(path: impl AsRef<Path>) -> Result<LogSummary> {
    let path = path.as_ref();
    if log_format(path) == Some(LogFormat::Mcap) {
        return crate::mcap_log::summarize_quick(path);
    }
    summarize(path)
}
