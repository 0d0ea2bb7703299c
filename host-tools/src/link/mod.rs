//! Link: talk to the box.
//!
//! [`serial`] frames the USB protocol, [`flash_probe`] and [`flash_serial`]
//! write an image into a slot (debug probe or USB), [`stream`] records the
//! box's sample stream, and [`sim_flash`] and [`virtual_box`] simulate the
//! box for tests. May import the leaves and the core; nothing of the design.

pub mod flash_probe;
pub mod flash_serial;
pub mod serial;
pub mod sim_flash;
pub mod stream;
pub mod virtual_box;
