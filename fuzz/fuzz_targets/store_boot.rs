//! The coefficient store's boot scan (`src/store.rs`) over arbitrary flash
//! contents, on the host's simulated NOR flash (`host-tools/src/sim_flash.rs`,
//! the G474's two 8 KiB slots).
//!
//! The flash starts either from raw fuzzed bytes or from records of the
//! project's images (seq numbers fuzzed), then gets byte patches; the
//! record's descriptor CRC and image CRC can be repaired after patching, so
//! the fuzzer reaches the image checks behind them.
//!
//! Checks: never panics; boot only reads (flash unchanged, a second boot
//! gives the same result); the image boot runs is the one an independent
//! model of the record format picks (committed header, length in range, CRC
//! of the image bytes, image parses, box-runnable; newest seq wins, A on a
//! tie); with no valid slot the reason is `NoImage` exactly when no slot is
//! committed; `load_active` agrees with boot.
#![no_main]

use dynocomp::link::sim_flash::SimFlash;
use dynocomp_core::image::{BoxImage, CRC32, MAX_BOX_IMAGE_LEN};
use dynocomp_core::sample::BypassReason;
use dynocomp_core::shell::Slot;
use dynocomp_core::store::*;
use dynocomp_fuzz::{box_runnable, IMAGES};
use libfuzzer_sys::arbitrary::{self, Arbitrary};
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
enum Base {
    Raw(Vec<u8>),
    /// Per slot: (which image, seq), or erased.
    Records(Option<(u8, u32)>, Option<(u8, u32)>),
}

#[derive(Arbitrary, Debug)]
struct Input {
    base: Base,
    patches: Vec<(u16, u8)>,
    fix_descriptor_crc: bool,
    fix_image_crc: bool,
}

const SLOT: usize = SLOT_LEN as usize;

fn word(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

/// Independent model of one slot: `None` if not committed, else
/// `Some((seq, Some(image) if valid and runnable))`.
fn model_slot(slot: &[u8]) -> Option<(u32, Option<(BoxImage, u32)>)> {
    let h = &slot[..RECORD_HEADER_LEN];
    if h[..4] != SLOT_MAGIC || h[16..20] != COMMIT_MAGIC || word(h, 20) != CRC32.checksum(&h[..16]) {
        return None;
    }
    let (seq, len, crc) = (word(h, 4), word(h, 8) as usize, word(h, 12));
    if len == 0 || len > (SLOT - RECORD_HEADER_LEN).min(MAX_BOX_IMAGE_LEN) {
        return Some((seq, None));
    }
    let bytes = &slot[RECORD_HEADER_LEN..RECORD_HEADER_LEN + len];
    if CRC32.checksum(bytes) != crc {
        return Some((seq, None));
    }
    let valid = BoxImage::parse(bytes).ok().filter(box_runnable);
    Some((seq, valid.map(|img| (img, word(bytes, len - 4)))))
}

fn repair(slot: &mut [u8], fix_desc: bool, fix_img: bool) {
    if fix_img {
        let len = word(slot, 8) as usize;
        if (1..=SLOT - RECORD_HEADER_LEN).contains(&len) {
            let crc = CRC32.checksum(&slot[RECORD_HEADER_LEN..RECORD_HEADER_LEN + len]);
            slot[12..16].copy_from_slice(&crc.to_le_bytes());
        }
    }
    if fix_desc {
        let crc = CRC32.checksum(&slot[..16]);
        slot[20..24].copy_from_slice(&crc.to_le_bytes());
    }
}

fuzz_target!(|input: Input| {
    let mut flash = SimFlash::g474_slots();
    let mem = flash.bytes_mut();
    assert_eq!(mem.len(), 2 * SLOT);
    match &input.base {
        Base::Raw(bytes) => {
            let n = bytes.len().min(mem.len());
            mem[..n].copy_from_slice(&bytes[..n]);
        }
        Base::Records(a, b) => {
            for (k, rec) in [a, b].into_iter().enumerate() {
                if let Some((img, seq)) = rec {
                    let image = IMAGES[usize::from(*img) % IMAGES.len()];
                    let slot = &mut mem[k * SLOT..(k + 1) * SLOT];
                    // encode_record refuses what does not parse (the parallel image):
                    // write that one by hand, as a buggy or foreign writer would.
                    if encode_record(image, *seq, slot).is_err() {
                        let mut ok = vec![0xFFu8; RECORD_HEADER_LEN + image.len().div_ceil(16) * 16];
                        encode_record(IMAGES[0], *seq, &mut ok).unwrap();
                        slot[..RECORD_HEADER_LEN].copy_from_slice(&ok[..RECORD_HEADER_LEN]);
                        slot[8..12].copy_from_slice(&(image.len() as u32).to_le_bytes());
                        slot[RECORD_HEADER_LEN..RECORD_HEADER_LEN + image.len()].copy_from_slice(image);
                        repair(slot, true, true);
                    }
                }
            }
        }
    }
    for &(at, x) in input.patches.iter().take(64) {
        mem[usize::from(at) % mem.len()] ^= x;
    }
    for slot in mem.chunks_mut(SLOT) {
        repair(slot, input.fix_descriptor_crc, input.fix_image_crc);
    }
    let before = flash.bytes().to_vec();

    let model = [model_slot(&before[..SLOT]), model_slot(&before[SLOT..])];
    let valid = |k: usize| model[k].as_ref().and_then(|(seq, v)| v.as_ref().map(|(img, id)| (*seq, *img, *id)));
    let expected = match (valid(0), valid(1)) {
        (Some(a), Some(b)) => Some(if seq_newer(b.0, a.0) { (Slot::B, b) } else { (Slot::A, a) }),
        (Some(a), None) => Some((Slot::A, a)),
        (None, Some(b)) => Some((Slot::B, b)),
        (None, None) => None,
    };

    let mut store = Store::open(flash, Layout::STM32G474RE).expect("the G474 layout fits the simulated flash");
    let boot = store.boot();
    match expected {
        Some((slot, (seq, img, id))) => {
            assert_eq!(boot.image, Ok(img), "boot runs another image than the newest valid slot");
            assert_eq!(boot.active, Some(dynocomp_core::protocol::SlotInfo { slot, seq, image_id: id }));
            assert_eq!(store.load_active(), Ok(img));
        }
        None => {
            assert_eq!(boot.active, None);
            let reason = boot.image.expect_err("boot runs an image although no slot is valid");
            let committed = model.iter().any(Option::is_some);
            assert_eq!(reason == BypassReason::NoImage, !committed, "bypass reason {reason:?}");
            assert_eq!(store.load_active(), Err(BypassReason::NoImage));
        }
    }
    assert_eq!(store.boot(), boot, "a second boot gives another result");
    let flash = store.into_flash();
    assert!(flash.bytes() == &before[..], "boot wrote to the flash");
});
