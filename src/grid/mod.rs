//! The rolling elevation grid.
