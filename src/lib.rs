//! dynocomp core: everything the compensator box and the host tool share.
//!
//! * [`kernel`]: the fixed-size, per-axis compensator in modal block-diagonal
//!   "delta" form. This is the only implementation of the filter arithmetic;
//!   the firmware, `dynocomp compensate`, the simulator and every test call it.
//! * [`image`]: the versioned, CRC-protected coefficient image (codec).
//! * [`sample`]: the body of the sample interrupt as a pure function
//!   `(ADC codes, coefficients, state) -> (DAC codes, flags)`.
//! * [`protocol`]: USB messages and framing (postcard + CRC-32 + COBS).
//! * [`link`]: the box's request handler (pure state machine over the store).
//! * [`store`]: the power-fail-safe A/B coefficient store on NOR flash.
//! * [`handoff`]: lock-free switch of the running image at a sample boundary.
//! * [`budget`]: cost model of the sample interrupt (cycles per sample from
//!   the image) and the load check that keeps over-budget images off the box.
//! * [`cycles`]: cost of the sample interrupt in CPU cycles (DWT CYCCNT
//!   readings → last, max, mean).
//! * [`stream_queue`]: the lock-free queue of streamed samples from the
//!   sample interrupt to the USB task (no panic path).
//!
//! The crate is `no_std` and allocation-free, so the same code runs on the
//! STM32G474 and under `std` in the host tests. It is free of `unsafe`
//! except, on bare-metal ARM with hardware float only, the two `asm!`
//! blocks of the Cortex-M4F's sample step, per axis (`src/kernel_m4.rs`) and
//! 3x3 (`src/mimo_m4.rs`); every other target forbids `unsafe` outright.
#![no_std]
#![cfg_attr(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")), forbid(unsafe_code))]
#![cfg_attr(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"), deny(unsafe_code))]
#![deny(missing_docs)]
// `!(x < y)` rejects NaN along with out-of-range values: deliberate.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod budget;
pub mod cycles;
pub mod handoff;
pub mod image;
pub mod kernel;
pub mod link;
pub mod mimo;
pub mod protocol;
pub mod sample;
pub mod shell;
pub mod store;
pub mod stream_queue;

/// Number of force axes the box handles (Fx, Fy, Fz).
pub const AXES: usize = 3;

/// Axis names in image/order: index 0 = x, 1 = y, 2 = z.
pub const AXIS_NAMES: [&str; AXES] = ["x", "y", "z"];
