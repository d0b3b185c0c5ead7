//! Writing ROS 2 MCAP logs: the compression and chunking options and [`LogWriter`].

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::geom::{CameraModel, PointCloud};
use crate::ros::{
    camera_to_info, cloud_to_pointcloud2, encode_image, schema_name, schema_text, Endian, Header,
    TfMessage,
};
use crate::ros::{CameraInfoMsg, ImageMsg, NavSatFixMsg, PointCloud2Msg};
use crate::sensor::Image;

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
