//! `dynocomp flash --probe`: the slot/sequence plan, the record bytes at the
//! slot address, probe-rs's flash loader and dry run on its FakeProbe, and
//! refusal of bad images before any probe is touched.
#![cfg(feature = "probe")]

use crate::cli_common;
use crate::common;

use std::cell::Cell;
use std::path::PathBuf;

use dynocomp::link::flash_probe::{
    execute, fake_session, loader_for, plan, read_slots, run_with, FlashPlan, SlotArg, DEFAULT_CHIP, SLOTS_LEN,
};
use dynocomp::link::sim_flash::SimFlash;
use dynocomp_core::image::{BoxImage, CRC32};
use dynocomp_core::shell::Slot;
use dynocomp_core::store::{encode_record, Layout, Store, FLASH_BASE};
use embedded_storage::nor_flash::NorFlash;

/// Both slots' bytes, erased.
fn erased() -> Vec<u8> {
    vec![0xFF; SLOTS_LEN]
}

/// `slots` with `image` committed in `slot` under `seq` (as the box's
/// upload or an earlier probe write leaves it).
fn with_record(mut slots: Vec<u8>, slot: Slot, image: &[u8], seq: u32) -> Vec<u8> {
    let at = if slot == Slot::A { 0 } else { 8 * 1024 };
    slots[at..at + 8 * 1024].fill(0xFF);
    let n = encode_record(image, seq, &mut slots[at..at + 8 * 1024]).unwrap();
    assert!(n <= 8 * 1024);
    slots
}

fn le(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

/// The record layout from the table in src/store.rs / docs, checked field by field.
fn assert_record_layout(rec: &[u8], image: &[u8], seq: u32) {
    assert_eq!(&rec[0..4], b"DCSL");
    assert_eq!(le(rec, 4), seq);
    assert_eq!(le(rec, 8) as usize, image.len());
    assert_eq!(le(rec, 12), CRC32.checksum(image));
    assert_eq!(&rec[16..20], b"CMT1");
    assert_eq!(le(rec, 20), CRC32.checksum(&rec[0..16]));
    assert!(rec[24..32].iter().all(|&b| b == 0xFF));
    assert_eq!(&rec[32..32 + image.len()], image);
    assert!(rec[32 + image.len()..].iter().all(|&b| b == 0xFF));
    assert_eq!(rec.len() % 16, 0, "whole flash double words");
    assert!(rec.len() < 32 + image.len() + 16);
}

#[test]
fn empty_box_gets_slot_a_with_sequence_1() {
    let img = common::good(1);
    let p = plan(&img, SlotArg::Auto, &erased()).unwrap();
    assert_eq!((p.slot, p.address, p.seq), (Slot::A, 0x0807_C000, 1));
    assert_eq!(p.image_id, BoxImage::parse(&img).unwrap().id(), "the id inspect and the box show");
    assert_record_layout(&p.record, &img, 1);
}

#[test]
fn auto_writes_the_slot_that_does_not_run_and_outranks_it() {
    let img = common::good(2);
    let (x, y) = (common::good(20), common::good(21));
    let slots = with_record(erased(), Slot::A, &x, 7);
    let p = plan(&img, SlotArg::Auto, &slots).unwrap();
    assert_eq!((p.slot, p.address, p.seq), (Slot::B, 0x0807_E000, 8));
    let slots = with_record(slots, Slot::B, &y, 9);
    let p = plan(&img, SlotArg::Auto, &slots).unwrap();
    assert_eq!((p.slot, p.seq), (Slot::A, 10));
    // Wrapping sequence numbers: 1 is newer than u32::MAX, so B runs.
    let slots = with_record(with_record(erased(), Slot::A, &x, u32::MAX), Slot::B, &y, 1);
    let p = plan(&img, SlotArg::Auto, &slots).unwrap();
    assert_eq!((p.slot, p.seq), (Slot::A, 2));
    // Explicit slot B while A runs: fine, and it outranks A.
    let slots = with_record(erased(), Slot::A, &x, 3);
    let p = plan(&img, SlotArg::B, &slots).unwrap();
    assert_eq!((p.slot, p.seq), (Slot::B, 4));
    assert_record_layout(&p.record, &img, 4);
}

#[test]
fn a_newer_but_broken_record_does_not_hide_the_running_one() {
    // A runs (seq 5); B holds a committed record (seq 6) whose image was torn:
    // the box boots A, so the probe must write B, with seq 7.
    let img = common::good(3);
    let mut slots = with_record(with_record(erased(), Slot::A, &common::good(30), 5), Slot::B, &common::good(31), 6);
    slots[8 * 1024 + 100] ^= 0xFF;
    let p = plan(&img, SlotArg::Auto, &slots).unwrap();
    assert_eq!((p.slot, p.seq), (Slot::B, 7));
    let e = plan(&img, SlotArg::A, &slots).unwrap_err().to_string();
    assert!(e.contains("--slot a") && e.contains("sequence 5"), "{e}");
}

#[test]
fn the_running_slot_is_never_overwritten() {
    let img = common::good(3);
    let slots = with_record(with_record(erased(), Slot::A, &common::good(32), 5), Slot::B, &common::good(33), 4);
    let e = plan(&img, SlotArg::A, &slots).unwrap_err().to_string();
    assert!(e.contains("--slot a") && e.contains("sequence 5"), "{e}");
    let slots = with_record(erased(), Slot::B, &common::good(34), 1);
    let e = plan(&img, SlotArg::B, &slots).unwrap_err().to_string();
    assert!(e.contains("--slot b"), "{e}");
    assert!(plan(&img, SlotArg::B, &slots[..100]).is_err(), "short slot read refused");
}

/// What the box's store makes of the flash after the probe wrote.
fn box_boots(flash: SimFlash) -> (Result<BoxImage, dynocomp_core::sample::BypassReason>, Option<Slot>) {
    let mut store = Store::open(flash, Layout::STM32G474RE).unwrap();
    let boot = store.boot();
    (boot.image, boot.active.map(|a| a.slot))
}

/// The probe's write as the flash sees it: erase the slot, program the record.
fn probe_write(flash: &mut SimFlash, p: &FlashPlan) {
    let off = (p.address - u64::from(FLASH_BASE)) as u32;
    flash.erase(off, off + 8 * 1024).unwrap();
    flash.write(off, &p.record).unwrap();
}

#[test]
fn the_box_boots_what_the_probe_wrote() {
    let old = common::good(10);
    let new = common::good(11);
    let mut flash = SimFlash::g474_slots();
    let p1 = plan(&old, SlotArg::Auto, flash.bytes()).unwrap();
    probe_write(&mut flash, &p1);
    let (img, slot) = box_boots(flash.copy());
    assert_eq!(img.unwrap(), BoxImage::parse(&old).unwrap());
    assert_eq!(slot, Some(Slot::A));

    // Second flash, planned from the slots as the probe reads them.
    let p2 = plan(&new, SlotArg::Auto, flash.bytes()).unwrap();
    assert_eq!((p2.slot, p2.seq), (Slot::B, 2));
    probe_write(&mut flash, &p2);
    let (img, slot) = box_boots(flash.copy());
    assert_eq!(img.unwrap(), BoxImage::parse(&new).unwrap());
    assert_eq!(slot, Some(Slot::B));

    // A write cut short (last double word of the image missing) is not
    // booted: the box falls back to the old image in A.
    let mut torn = flash.copy();
    let off = 8 * 1024 + p2.record.len() - 16;
    torn.bytes_mut()[off..off + 16].fill(0xFF);
    let (img, slot) = box_boots(torn);
    assert_eq!(img.unwrap(), BoxImage::parse(&old).unwrap());
    assert_eq!(slot, Some(Slot::A));
}

#[test]
fn fake_probe_dry_run_plans_the_record_at_the_slot_address() {
    let img = common::good(4);
    let mut session = fake_session(DEFAULT_CHIP).expect("probe-rs knows the STM32G474RETx");
    // Reading through the probe works; the fake one has no flash contents.
    let slots = read_slots(&mut session).unwrap();
    assert_eq!(slots.len(), SLOTS_LEN);
    let p = plan(&img, SlotArg::B, &slots).unwrap();

    // The loader holds exactly the record, at slot B's address.
    let loader = loader_for(&session, &p).unwrap();
    let data: Vec<(u64, Vec<u8>)> = loader.data().map(|(a, d)| (a, d.to_vec())).collect();
    assert_eq!(data, vec![(0x0807_E000, p.record.clone())]);
    assert_record_layout(&data[0].1, &img, 1);

    // probe-rs builds its flash plan (flash algorithm of the chip covering
    // the address) without writing.
    execute(&mut session, &p, true).expect("dry run");
}

#[test]
fn fake_probe_refuses_addresses_outside_the_flash() {
    // The loader's memory-map check has teeth: the same record one slot past
    // the end of the 512 KiB flash is refused.
    let img = common::good(5);
    let session = fake_session(DEFAULT_CHIP).unwrap();
    let mut p = plan(&img, SlotArg::B, &erased()).unwrap();
    p.address = 0x0808_0000;
    let e = loader_for(&session, &p).err().expect("outside flash").to_string();
    assert!(e.contains("0x08080000"), "{e}");
}

fn temp_image(name: &str, bytes: &[u8]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    (dir, path)
}

#[test]
fn bad_images_are_refused_before_any_probe_is_opened() {
    let mut corrupt = common::good(6);
    let mid = corrupt.len() / 2;
    corrupt[mid] ^= 0x01; // CRC no longer matches
    let cases: [(&str, Vec<u8>, &str); 5] = [
        ("corrupt.dcimg", corrupt, "CRC mismatch"),
        ("offline.dcimg", common::offline_only(), "offline-only"),
        ("slow.dcimg", common::slow(), "sample rate 5000 Hz"),
        ("unstable.dcimg", common::unstable(), "outside the unit circle"),
        ("empty.dcimg", Vec::new(), "truncated"),
    ];
    for (name, bytes, why) in cases {
        let (_dir, path) = temp_image(name, &bytes);
        let opened = Cell::new(false);
        let e = run_with(&path, DEFAULT_CHIP, SlotArg::Auto, false, |_| {
            opened.set(true);
            anyhow::bail!("no probe in tests")
        })
        .unwrap_err()
        .to_string();
        assert!(!opened.get(), "{name}: probe opened for a bad image");
        assert!(e.contains(name) && e.contains("nothing was written"), "{name}: {e}");
        assert!(e.contains(why), "{name}: expected {why} in: {e}");
    }
    // A good image does reach the probe.
    let (_dir, path) = temp_image("good.dcimg", &common::good(7));
    let opened = Cell::new(false);
    let e = run_with(&path, DEFAULT_CHIP, SlotArg::Auto, false, |_| {
        opened.set(true);
        anyhow::bail!("no probe in tests")
    })
    .unwrap_err();
    assert!(opened.get());
    assert!(e.to_string().contains("no probe in tests"));
}

#[test]
fn cli_dry_run_needs_no_hardware() {
    let (_dir, path) = temp_image("good.dcimg", &common::good(8));
    run_with(&path, DEFAULT_CHIP, SlotArg::Auto, true, |_| panic!("dry run opened a real probe")).unwrap();
    // An unknown chip is a clear error, not a panic.
    let e = run_with(&path, "NOT_A_CHIP", SlotArg::Auto, true, |_| unreachable!()).unwrap_err();
    assert!(format!("{e:#}").contains("NOT_A_CHIP"), "{e:#}");
}

/// `flash --probe --dry-run` prints what it does in one line; the simulated
/// probe's register traces (about 56 lines on stdout) only with `-v`.
#[test]
fn dry_run_is_quiet_unless_verbose() {
    let image = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/images/example.dcimg");
    let run = |extra: &[&str]| {
        let args = [&["flash", image.to_str().unwrap(), "--probe", "--dry-run"], extra].concat();
        let (ok, out, err) = cli_common::dynocomp(&args);
        assert!(ok, "{err}");
        out
    };
    let quiet = run(&[]);
    assert_eq!(quiet.lines().count(), 1, "{quiet}");
    assert!(quiet.starts_with("dry run (fake probe, nothing written): would write slot"), "{quiet}");
    // Control: the traces are there with -v, and the summary still last.
    let verbose = run(&["-v"]);
    assert!(verbose.lines().count() > 10, "{verbose}");
    assert_eq!(verbose.lines().last(), quiet.lines().last());
}
