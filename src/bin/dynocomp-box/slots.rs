//! The two coefficient-image flash slots, as declared in `memory.x`
//! (`COEFF_A` at 0x0807_C000, `COEFF_B` at 0x0807_E000, 8 KiB each).
//!
//! The coefficient store (`dynocomp_core::store`, reading and writing
//! through embassy-stm32's flash driver) has the same addresses as
//! constants; this module checks them against the linker symbols
//! `__coeff_slot_{a,b}_{start,end}` at boot, so `memory.x`, the store and
//! docs/firmware.md cannot drift apart silently. It also holds the NMI
//! handler for flash double-ECC errors (reads of a torn slot).

use core::sync::atomic::{AtomicU32, Ordering};

use dynocomp_core::store::{SLOT_A_ADDR, SLOT_B_ADDR, SLOT_LEN};
use embassy_stm32::pac;

extern "C" {
    static __coeff_slot_a_start: u8;
    static __coeff_slot_a_end: u8;
    static __coeff_slot_b_start: u8;
    static __coeff_slot_b_end: u8;
}

/// Whether the linker's slot regions are the store's (start and length of
/// both slots). Only the symbols' addresses are taken, never their values.
pub fn memory_x_matches_store() -> bool {
    let span = |s: *const u8, e: *const u8| (s as usize, (e as usize).wrapping_sub(s as usize));
    let a = span(core::ptr::addr_of!(__coeff_slot_a_start), core::ptr::addr_of!(__coeff_slot_a_end));
    let b = span(core::ptr::addr_of!(__coeff_slot_b_start), core::ptr::addr_of!(__coeff_slot_b_end));
    a == (SLOT_A_ADDR as usize, SLOT_LEN as usize) && b == (SLOT_B_ADDR as usize, SLOT_LEN as usize)
}

/// Double ECC errors the NMI handler caught on flash reads.
pub static FLASH_ECC_ERRORS: AtomicU32 = AtomicU32::new(0);

/// NMI. A read of a flash double word whose programming was cut by a power
/// loss can fail the ECC check twice over; that raises the NMI (RM0440
/// §3.3.4, `FLASH_ECCR.ECCD`). Count it, clear the flag and return: the read
/// delivers wrong data, which the store's header/CRC checks reject, so the
/// torn slot counts as invalid and the box boots the other slot or bypass
/// instead of hanging in the default handler. Any other NMI source (none is
/// enabled) resets the box.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    let eccr = pac::FLASH.eccr().read();
    if eccr.eccd() || eccr.eccd2() {
        // rc_w1 flags: writing 1 clears them.
        pac::FLASH.eccr().modify(|w| {
            w.set_eccd(true);
            w.set_eccd2(true);
        });
        FLASH_ECC_ERRORS.fetch_add(1, Ordering::Relaxed);
    } else {
        cortex_m::peripheral::SCB::sys_reset();
    }
}
