//! File input/output: FRF (CSV, UFF58), signal CSV, atomic writes.

pub mod atomic;
pub mod signal_csv;
pub mod image_file;
