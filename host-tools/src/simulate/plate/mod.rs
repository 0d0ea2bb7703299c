//! A physical 3x3 table dynamometer with crosstalk (DESIGN.md, "How we know
//! it works"): a rigid top plate with its workpiece on four 3-component piezo
//! sensors, a base on the machine table, and a force that acts above and off
//! the centre of the sensor plane. Every channel responds to every force
//! direction; G(0) = I plus a small static crosstalk.
//!
//! - [`body`]: rigid-body mass properties and point kinematics;
//! - [`setup`]: the set-up's parameters, their physical bounds and the
//!   12-DOF matrices M, K, B(p) and the sensor-force output Cd;
//! - [`modal`]: modes (per-mode damping), the exact FRF matrix G(j2πf) and the
//!   exact time response to a force linear between samples;
//! - [`random`]: set-ups from a seed and the presets `flat`, `offcentre`, `tall`;
//! - [`impact`]: impact tests in x, y, z recording all three channels;
//! - [`floor`]: the exact 3x3 inverse's noise floor and the per-axis one;
//! - [`run`]: a whole simulation (impact test, cut at another point, records);
//! - [`output`]: the files of `dynocomp simulate --dyno plate`.

pub mod body;
pub mod floor;
pub mod impact;
pub mod modal;
pub mod output;
pub mod random;
pub mod run;
pub mod setup;

pub use body::RigidBody;
pub use floor::{inverse_noise_floor, per_axis_noise_floor, FloorSpec};
pub use impact::impact_test_matrix;
pub use modal::{PlateModal, PlateMode};
pub use random::{check_mode_bands, MACHINE_HZ, PRESETS, SENSOR_HZ};
pub use run::{simulate_plate, PlateSim, PlateSimOutput, MAX_CUT_OFFSET_M};
pub use setup::{PlateMatrices, PlateSetup, DOF};
