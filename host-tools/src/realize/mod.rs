//! Realize: turn a linear filter into the box's f32 modal form and prove it.
//!
//! [`modal`] realizes a state-space compensator as 2x2 "delta" blocks plus
//! an FIR tail, [`quantize`] rounds it to f32 and verifies it against the
//! f64 filter, [`load`] predicts the box's CPU load of an image.
//! May import only the leaves (frf, metrics, numeric, io, fit) and the core.

// `!(x < limit)` on purpose throughout: a NaN residual, condition number or
// error must fail the check, which `x >= limit` would let pass.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod choose;
pub mod image;
pub mod load;
pub mod mimo;
pub mod modal;
pub mod quantize;
