//! Reading and writing the outside world's files: point clouds, logs, exports.
pub mod frames;
pub mod mcap_log;
pub mod ros;
pub mod tf;
