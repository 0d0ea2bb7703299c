//! A set-up in two states: the FRF measured before and after machining
//! ([`model`]: the paired models and the one in between; [`joint`]: the
//! sensor modes above the band fitted to both FRFs at once; [`range`]: the
//! box design for the whole range). The smoother that follows the change
//! during a record is offline (`crate::offline::drift`).

pub mod joint;
pub mod model;
pub mod range;
