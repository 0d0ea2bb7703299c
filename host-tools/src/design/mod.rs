//! Design: from a measured FRF to a verified compensator per axis.
//!
//! The paper's steps: fit Ĝ ([`axis`] calls `fit`), a discrete model of the
//! sampled-data relation ([`discretize`]), the disturbance Kalman filter and
//! fixed-lag smoother ([`kalman`], or the paper's own method in [`paper`]),
//! q chosen by the declared criterion ([`criterion`]), the output above the
//! band ([`above_band`]), the latency rule
//! ([`latency`]), band-fitting ([`bands`], [`parallel`]), and analyses of a
//! design ([`sensitivity`], [`force_spectrum`], [`two_state`]).
//! May import the leaves and `realize`; nothing above.

// `!(x < limit)` on purpose throughout: a NaN residual, condition number or
// error must fail the check, which `x >= limit` would let pass.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod above_band;
pub mod axis;
pub mod bands;
pub mod criterion;
pub mod discretize;
pub mod force_spectrum;
pub mod image;
pub mod kalman;
pub mod latency;
pub mod look_ahead;
pub mod mimo;
pub mod noise;
pub mod paper;
pub mod paper_orders;
pub mod parallel;
pub mod pass_through;
pub mod phase_limit;
pub mod progress;
pub mod sensitivity;
pub mod two_state;
pub mod versus_default;
