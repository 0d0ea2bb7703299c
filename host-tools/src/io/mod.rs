//! File input/output: FRF (CSV, UFF58), signal CSV, atomic writes.
