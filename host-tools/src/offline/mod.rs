//! Offline: compensate recorded data on the host.
//!
//! [`compensate`] runs the box's own kernel over a record (bit-exact with
//! the box), [`smoother`] the zero-lag fixed-interval smoother, with its
//! model sidecar, [`matrix_smoother`] the same for the 3x3 model, [`drift`] the one that follows a drifting set-up,
//! [`force_prior`] the harmonic force prior, [`bandsplit`] the zero-phase
//! band split of parallel elaboration, and [`record`] any of them from file
//! to file. May import the leaves, `realize` and `design`.

// `!(x < limit)` on purpose throughout: a NaN residual, condition number or
// error must fail the check, which `x >= limit` would let pass.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bandsplit;
pub mod compensate;
pub mod drift;
pub mod force_prior;
pub mod matrix_model;
pub mod matrix_smoother;
pub mod record;
pub mod sidecar;
pub mod smoother;
