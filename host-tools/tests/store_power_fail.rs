//! The A/B coefficient store (dynocomp_core::store) on a simulated NOR
//! flash with STM32G4 semantics: power cut injected at every erase and
//! double-word write of an upload (before, after and torn in the middle),
//! then a reboot must run a complete verified image (old or new) or bypass,
//! never a mix. Also: consecutive uploads, sequence-number wrap, bit rot,
//! rejected images, out-of-order chunks.

use crate::common;

use dynocomp::link::sim_flash::{CutMode, SimFlash};
use dynocomp_core::image::{BoxImage, CRC32};
use dynocomp_core::protocol::{LinkError, MAX_CHUNK};
use dynocomp_core::sample::BypassReason;
use dynocomp_core::shell::Slot;
use dynocomp_core::store::{encode_record, Layout, SlotState, Store, RECORD_HEADER_LEN, SLOT_LEN};

fn open(flash: SimFlash) -> Store<SimFlash> {
    Store::open(flash, Layout::STM32G474RE).expect("layout fits the simulated flash")
}

/// Upload `bytes` through the store's upload API in protocol-sized chunks.
fn upload(store: &mut Store<SimFlash>, bytes: &[u8]) -> Result<(), LinkError> {
    store.begin_upload(bytes.len() as u32, CRC32.checksum(bytes))?;
    for (i, c) in bytes.chunks(MAX_CHUNK).enumerate() {
        store.write_chunk((i * MAX_CHUNK) as u32, c)?;
    }
    store.commit().map(|_| ())
}

fn parsed(b: &[u8]) -> BoxImage {
    BoxImage::parse(b).expect("fixture parses")
}

/// A flash holding the given images, uploaded in order.
fn flash_with(images: &[&[u8]]) -> SimFlash {
    let mut s = open(SimFlash::g474_slots());
    for b in images {
        upload(&mut s, b).expect("fixture upload");
    }
    s.into_flash()
}

/// For every operation of an upload of `new` onto `initial`, and every way
/// the power can fail there, reboot and check the outcome. `old` is the
/// image that must survive (None: the box must be in bypass).
fn cut_everywhere(initial: &SimFlash, old: Option<&[u8]>, new: &[u8]) {
    // Count the operations of an uninterrupted upload.
    let mut s = open(initial.copy());
    upload(&mut s, new).expect("uninterrupted upload");
    let total = s.into_flash().ops();
    // 4 page erases + image double words + 2 descriptor + 1 commit word.
    assert_eq!(total, 4 + new.len().div_ceil(8) as u64 + 3);
    let old_img = old.map(parsed);
    let new_img = parsed(new);
    let mut seen_new = 0;
    for op in 0..total {
        for mode in [CutMode::Before, CutMode::After, CutMode::Torn(op * 31 + 7), CutMode::Torn(op * 17 + 3)] {
            let mut flash = initial.copy();
            flash.cut_power_at(op, mode);
            let mut s = open(flash);
            let r = upload(&mut s, new);
            let flash = s.into_flash();
            assert!(flash.is_dead(), "op {op} {mode:?}: the cut did not happen");
            assert!(
                r.is_err() || (op == total - 1 && mode == CutMode::After),
                "op {op} {mode:?}: upload reported success"
            );

            let mut s = open(flash.reboot());
            let boot = s.boot();
            let last = op == total - 1;
            let is_new = boot.image == Ok(new_img);
            match (&boot.image, old_img) {
                (Ok(img), _) if *img == new_img => {
                    // Only a completed (or torn-but-complete) commit word may
                    // make the new image win.
                    assert!(
                        last && mode != CutMode::Before,
                        "op {op}/{total} {mode:?}: new image before its commit word"
                    );
                    assert_eq!(boot.active.map(|a| a.image_id), Some(common::id(new)));
                }
                (Ok(img), Some(o)) => assert_eq!(*img, o, "op {op} {mode:?}: neither old nor new image"),
                (Err(BypassReason::NoImage), None) => {}
                (other, _) => panic!("op {op} {mode:?}: unexpected boot result {other:?}"),
            }
            if last && mode == CutMode::After {
                assert!(is_new, "commit word written, but the new image does not run");
            }
            seen_new += usize::from(is_new);
            // The store is usable after the reboot: the upload now succeeds.
            upload(&mut s, new).unwrap_or_else(|e| panic!("op {op} {mode:?}: upload after reboot failed: {e:?}"));
            assert_eq!(s.boot().image, Ok(new_img));
        }
    }
    assert!(seen_new >= 1);
}

#[test]
fn power_cut_at_every_boundary_of_first_upload_leaves_bypass_or_new() {
    cut_everywhere(&SimFlash::g474_slots(), None, &common::good(1));
}

#[test]
fn power_cut_at_every_boundary_keeps_old_image_or_takes_new() {
    let old = common::good(1);
    cut_everywhere(&flash_with(&[&old]), Some(&old), &common::good(2));
}

#[test]
fn power_cut_while_overwriting_the_older_of_two_slots() {
    // A = image 1 (seq 1), B = image 2 (seq 2): the upload erases A.
    let (one, two) = (common::good(1), common::good(2));
    cut_everywhere(&flash_with(&[&one, &two]), Some(&two), &common::good(3));
}

#[test]
fn consecutive_uploads_alternate_slots_and_count_up() {
    let mut s = open(SimFlash::g474_slots());
    let mut expect = vec![];
    for v in 1..=5u32 {
        let b = common::good(v);
        upload(&mut s, &b).unwrap();
        let a = s.active().unwrap();
        expect.push((a.slot, a.seq));
        assert_eq!(a.image_id, common::id(&b));
        // A fresh boot agrees with the running store.
        let mut again = open(s.into_flash().copy());
        assert_eq!(again.boot().image, Ok(parsed(&b)));
        s = again;
    }
    assert_eq!(expect, vec![(Slot::A, 1), (Slot::B, 2), (Slot::A, 3), (Slot::B, 4), (Slot::A, 5)]);
}

/// Write a committed record directly (what `flash --probe` writes).
fn put_record(flash: &mut SimFlash, slot: Slot, image: &[u8], seq: u32) {
    let mut rec = vec![0u8; SLOT_LEN as usize];
    let n = encode_record(image, seq, &mut rec).unwrap();
    let at = (Layout::STM32G474RE.offset(slot) - Layout::STM32G474RE.a) as usize;
    flash.bytes_mut()[at..at + n].copy_from_slice(&rec[..n]);
}

#[test]
fn sequence_numbers_wrap() {
    let (one, two, three) = (common::good(1), common::good(2), common::good(3));
    let mut f = SimFlash::g474_slots();
    put_record(&mut f, Slot::A, &one, u32::MAX);
    put_record(&mut f, Slot::B, &two, u32::MAX - 1);
    let mut s = open(f);
    // u32::MAX is newer than u32::MAX − 1.
    assert_eq!(s.boot().image, Ok(parsed(&one)));
    // The next upload goes to B with seq 0, which is newer than u32::MAX.
    upload(&mut s, &three).unwrap();
    let a = s.active().unwrap();
    assert_eq!((a.slot, a.seq), (Slot::B, 0));
    let mut s = open(s.into_flash().copy());
    assert_eq!(s.boot().image, Ok(parsed(&three)));
    assert_eq!(s.active().unwrap().seq, 0);
}

#[test]
fn bit_rot_in_newest_slot_falls_back_to_older_then_bypass() {
    let (one, two) = (common::good(1), common::good(2));
    let mut f = flash_with(&[&one, &two]);
    // Flip one bit in the middle of B's image (B = newest, seq 2).
    let b_img = SLOT_LEN as usize + RECORD_HEADER_LEN + two.len() / 2;
    f.bytes_mut()[b_img] ^= 0x10;
    let mut s = open(f);
    assert!(matches!(s.check(Slot::B), SlotState::Invalid(_)));
    assert_eq!(s.boot().image, Ok(parsed(&one)));
    assert_eq!(s.active().unwrap().slot, Slot::A);
    // Rot in A's descriptor too: nothing valid, bypass with a reason.
    let mut f = s.into_flash();
    f.bytes_mut()[5] ^= 0x01; // A's sequence number: the commit CRC no longer matches.
    let mut s = open(f);
    assert_eq!(s.check(Slot::A), SlotState::Empty);
    match s.boot().image {
        Err(BypassReason::InvalidImage(_)) => {}
        other => panic!("expected bypass for an invalid image, got {other:?}"),
    }
    assert_eq!(s.active(), None);
}

#[test]
fn bad_images_are_rejected_and_the_old_one_keeps_running() {
    let old = common::good(1);
    type Check = fn(&LinkError) -> bool;
    let cases: Vec<(&str, Vec<u8>, Check)> = vec![
        ("offline-only", common::offline_only(), |e| matches!(e, LinkError::NotRunnable(BypassReason::OfflineOnly))),
        ("5 kHz", common::slow(), |e| matches!(e, LinkError::NotRunnable(BypassReason::UnsupportedSampleRate(5_000)))),
        ("unstable", common::unstable(), |e| {
            matches!(e, LinkError::Image(dynocomp_core::image::ImageError::UnstableSection { axis: 0, section: 0 }))
        }),
    ];
    for (name, bad, ok) in cases {
        let mut s = open(flash_with(&[&old]));
        let err = upload(&mut s, &bad).expect_err(name);
        assert!(ok(&err), "{name}: wrong error {err:?}");
        assert_eq!(s.active().unwrap().image_id, common::id(&old), "{name}");
        let mut s = open(s.into_flash().copy());
        assert_eq!(s.boot().image, Ok(parsed(&old)), "{name}: reboot");
    }
    // Declared CRC disagrees with the bytes sent.
    let mut s = open(flash_with(&[&old]));
    let new = common::good(2);
    s.begin_upload(new.len() as u32, CRC32.checksum(&new) ^ 1).unwrap();
    for (i, c) in new.chunks(MAX_CHUNK).enumerate() {
        s.write_chunk((i * MAX_CHUNK) as u32, c).unwrap();
    }
    assert!(matches!(s.commit(), Err(LinkError::CrcMismatch { .. })));
    assert_eq!(open(s.into_flash().copy()).boot().image, Ok(parsed(&old)));
}

#[test]
fn chunks_out_of_order_too_long_or_without_upload_are_refused() {
    let new = common::good(2);
    let mut s = open(SimFlash::g474_slots());
    assert_eq!(s.write_chunk(0, &new[..8]), Err(LinkError::NoUpload));
    assert_eq!(s.commit(), Err(LinkError::NoUpload));
    s.begin_upload(new.len() as u32, CRC32.checksum(&new)).unwrap();
    s.write_chunk(0, &new[..100]).unwrap();
    assert_eq!(s.write_chunk(0, &new[..100]), Err(LinkError::OutOfOrder { expected: 100, got: 0 }));
    assert_eq!(s.write_chunk(108, &new[108..120]), Err(LinkError::OutOfOrder { expected: 100, got: 108 }));
    assert_eq!(s.commit(), Err(LinkError::Incomplete { received: 100, len: new.len() as u32 }));
    // The refused commit ended nothing: the upload goes on (Incomplete keeps it).
    let mut at = 100;
    for c in new[100..].chunks(MAX_CHUNK) {
        s.write_chunk(at as u32, c).unwrap();
        at += c.len();
    }
    assert_eq!(s.write_chunk(at as u32, &[0]), Err(LinkError::ChunkTooLong { len: new.len() as u32 }));
    s.commit().unwrap();
    assert_eq!(s.boot().image, Ok(parsed(&new)));
    // Too large a declared length.
    assert!(matches!(s.begin_upload(100_000, 0), Err(LinkError::UploadTooLarge { len: 100_000, .. })));
    assert!(matches!(s.begin_upload(0, 0), Err(LinkError::UploadTooLarge { len: 0, .. })));
}

#[test]
fn encode_record_matches_what_an_upload_leaves_in_the_slot() {
    let img = common::good(4);
    let f = flash_with(&[&img]);
    let mut rec = vec![0u8; SLOT_LEN as usize];
    let n = encode_record(&img, 1, &mut rec).unwrap();
    assert_eq!(&f.bytes()[..n], &rec[..n]);
    assert!(f.bytes()[n..SLOT_LEN as usize].iter().all(|&b| b == 0xFF));
}
