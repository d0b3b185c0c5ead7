//! Reading and writing the outside world's files: point clouds, logs, exports.
pub mod ros;
