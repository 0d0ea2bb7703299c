//! The `dynocomp` host tool as a library: one module per stage of the signal
//! chain, data flowing one way (io → fit → kalman → realize → quantize →
//! image → report), plus the simulator and the offline compensator.
//!
//! No `unsafe` anywhere in it (what the long fuzz campaigns without
//! AddressSanitizer rely on, `fuzz/campaign.sh`).
#![forbid(unsafe_code)]

pub mod bands;
pub mod bandsplit;
pub mod compare;
pub mod compensate;
pub mod compensate_cmd;
pub mod compensate_report;
pub mod design;
pub mod design_cmd;
pub mod discretize;
pub mod flash_serial;
pub mod force_prior;
pub mod force_spectrum;
pub mod flash_probe;
pub mod fit;
pub mod frf;
pub mod inspect;
pub mod io;
pub mod kalman;
pub mod latency;
pub mod load;
pub mod metrics;
pub mod parallel;
pub mod paper;
pub mod paper_orders;
pub mod quantize;
pub mod realize;
pub mod report;
pub mod reproduce;
pub mod sensitivity;
pub mod serial_link;
pub mod sim_flash;
pub mod simulate;
pub mod smoother;
pub mod stream;
pub mod two_state;
pub mod two_state_cmd;
pub mod two_state_joint;
pub mod virtual_box;
