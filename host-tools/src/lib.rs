//! The `dynocomp` host tool as a library, one folder per stage of the
//! signal chain (docs/architecture.md). Imports flow one way, from the
//! leaves up to `cli`: leaves (frf, metrics, numeric, io, fit) → realize →
//! design → offline → eval → report → cli, with `link` (the box) and
//! `simulate` on the leaves alone: the simulator, the ground truth, never
//! shares code with the compensator.
//!
//! No `unsafe` anywhere in it.
#![forbid(unsafe_code)]
// `!(x < y)` is how this crate rejects NaN along with out-of-range values:
// deliberate, and clearer here than partial_cmp chains.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod fit;
pub mod frf;
pub mod io;
pub mod metrics;
pub mod numeric;

pub mod realize;

pub mod design;

pub mod offline;

pub mod eval;

pub mod report;

pub mod link;

pub mod cli;

pub mod simulate;
