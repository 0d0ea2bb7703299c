//! Numeric helpers every stage may use: discrete LTI systems ([`lti`]) and
//! their balanced reduction ([`balanced`]), blocked dense factorizations
//! ([`dense`]),
//! one-dimensional searches ([`search`]), linear prediction ([`predict`])
//! and independent work on threads ([`parallel`]).

// `!(x < limit)` on purpose throughout: a NaN residual, condition number or
// error must fail the check, which `x >= limit` would let pass.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod balanced;
pub mod dense;
pub mod lti;
pub mod parallel;
pub mod predict;
pub mod search;
