//! Numeric helpers every stage may use: discrete LTI systems ([`lti`]) and
//! one-dimensional searches ([`search`]). Leaves: they import nothing of the crate.

pub mod lti;
pub mod search;
