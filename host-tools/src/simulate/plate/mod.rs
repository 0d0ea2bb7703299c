//! A physical 3x3 table dynamometer with crosstalk (DESIGN.md, "How we know
//! it works"): a rigid top plate with its workpiece on four 3-component piezo
//! sensors, a base on the machine table, and a force that acts above and off
//! the centre of the sensor plane. Every channel responds to every force
//! direction; G(0) = I plus a small static crosstalk.
//!
//! The set-up ([`body`], [`setup`], [`random`]), its modes and exact response
//! ([`modal`]), the impact tests ([`impact`]), the noise floors ([`floor`]), a
//! whole simulation ([`run`]) and its files ([`output`]).

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
