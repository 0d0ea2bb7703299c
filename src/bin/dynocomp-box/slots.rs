//! The two coefficient-image flash slots, as declared in `memory.x`
//! (`COEFF_A` at 0x0807_C000, `COEFF_B` at 0x0807_E000, 8 KiB each).
//!
//! The slot addresses come from the linker symbols `__coeff_slot_{a,b}_{start,end}`
//! so this file, `memory.x` and docs/firmware.md cannot drift apart silently;
//! the expected addresses are also checked at boot.

use dynocomp_core::image::{CoeffImage, ImageError, MAX_IMAGE_LEN};
use dynocomp_core::shell::{choose_image, SlotChoice};

/// Expected start of slot A (memory.x).
pub const SLOT_A_ADDR: usize = 0x0807_C000;
/// Expected start of slot B (memory.x).
pub const SLOT_B_ADDR: usize = 0x0807_E000;
/// Size of one slot.
pub const SLOT_LEN: usize = 8 * 1024;

// A slot must hold the largest image the codec can produce.
const _: () = assert!(MAX_IMAGE_LEN <= SLOT_LEN);

extern "C" {
    static __coeff_slot_a_start: u8;
    static __coeff_slot_a_end: u8;
    static __coeff_slot_b_start: u8;
    static __coeff_slot_b_end: u8;
}

/// The bytes of a slot, from its linker symbols.
///
/// Returns `None` if the symbols disagree with [`SLOT_A_ADDR`]/[`SLOT_B_ADDR`]
/// and [`SLOT_LEN`] (memory.x edited without this file).
fn slot(start: *const u8, end: *const u8, expected: usize) -> Option<&'static [u8]> {
    let (s, e) = (start as usize, end as usize);
    if s != expected || e.wrapping_sub(s) != SLOT_LEN {
        return None;
    }
    // SAFETY: `start..end` is the COEFF_A / COEFF_B region of memory.x, inside
    // the 512 KiB on-chip flash that is always mapped and readable; it is
    // never written by the CPU while this shared slice exists (there is no
    // flash writer in this firmware yet; the future store must drop the
    // slices or copy the image out before erasing). u8 has no alignment or
    // validity requirements, so any flash content is a valid `[u8]`.
    Some(unsafe { core::slice::from_raw_parts(start, SLOT_LEN) })
}

/// Slot A's bytes (`None` if memory.x and this firmware disagree).
pub fn slot_a() -> Option<&'static [u8]> {
    // Only the addresses of the linker symbols are taken, never their values.
    let (s, e) = (
        core::ptr::addr_of!(__coeff_slot_a_start),
        core::ptr::addr_of!(__coeff_slot_a_end),
    );
    slot(s, e, SLOT_A_ADDR)
}

/// Slot B's bytes (`None` if memory.x and this firmware disagree).
pub fn slot_b() -> Option<&'static [u8]> {
    // Only the addresses of the linker symbols are taken, never their values.
    let (s, e) = (
        core::ptr::addr_of!(__coeff_slot_b_start),
        core::ptr::addr_of!(__coeff_slot_b_end),
    );
    slot(s, e, SLOT_B_ADDR)
}

fn parse(bytes: Option<&'static [u8]>) -> Result<CoeffImage, ImageError> {
    match bytes {
        Some(b) => CoeffImage::parse_prefix(b),
        // Misplaced slot: report it as "not an image" rather than reading
        // from an address nobody agreed on.
        None => {
            defmt::error!("coefficient slot symbols disagree with memory.x; slot ignored");
            Err(ImageError::BadMagic)
        }
    }
}

/// Read and validate both slots and pick the image (A, then B).
pub fn load() -> SlotChoice {
    let a = parse(slot_a());
    let b = parse(slot_b());
    match &a {
        Ok(img) => defmt::info!(
            "slot A: valid image, fs = {} Hz, id {=u32:#010x}",
            img.fs_hz,
            img.id()
        ),
        Err(e) => defmt::info!("slot A: {}", e),
    }
    match &b {
        Ok(img) => defmt::info!(
            "slot B: valid image, fs = {} Hz, id {=u32:#010x}",
            img.fs_hz,
            img.id()
        ),
        Err(e) => defmt::info!("slot B: {}", e),
    }
    choose_image(a, b)
}
