//! Evaluation: the method against the paper and against known truth.
//!
//! [`compare`] runs the paper's method beside the default on one FRF,
//! [`reproduce`] the paper's experiments on the simulator's presets, and
//! [`rates`] the multi-rate accuracy harness, [`sweep`] its random set-ups and
//! [`drift_sweep`] random two-state drifts. May import the leaves,
//! realize, design, offline and the simulator; `report` draws its results.

pub mod compare;
pub mod drift_sweep;
pub mod rates;
pub mod reproduce;
pub mod sweep;
