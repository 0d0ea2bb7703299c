//! Report: what people read.
//!
//! Plot helpers ([`plot`]) and the HTML page ([`page`]) know nothing of the
//! design; one module per report or figure draws a design ([`design`],
//! [`sensitivity`], [`force_spectrum`], [`two_state`], [`summary`]), a 3x3
//! design ([`matrix`]), a compensated record ([`compensation`]), an image
//! ([`inspect`]) or a comparison ([`compare`]). May import every stage below the command line
//! except the box link.

pub mod compare;
pub mod compensation;
pub mod design;
pub mod force_spectrum;
pub mod inspect;
pub mod look_ahead;
pub mod matrix;
pub mod page;
pub mod plot;
pub mod sensitivity;
pub mod summary;
pub mod two_state;
