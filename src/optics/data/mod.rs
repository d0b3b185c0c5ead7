//! Embedded measured tables (CC0), see `tables.rs` for their source.
pub(crate) mod tables;
