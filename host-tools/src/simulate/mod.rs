//! Synthetic dynamometers, impact tests and milling forces with known truth.
