//! `dynocomp flash IMAGE --probe [--chip CHIP] [--slot a|b|auto] [--dry-run]`:
//! write a coefficient image into one of the box's two flash slots through a
//! debug probe, with the probe-rs library, and verify it ([`run`]).
//!
//! What is written is a complete slot *record* of the coefficient store
//! (`dynocomp_core::store::encode_record`: header with sequence number and
//! CRC, commit word, the image, 0xFF padding), exactly what a USB upload
//! leaves in a slot, so the box's boot scan (newest valid slot wins) accepts
//! it; the written slot is never the active one, so a power cut during the
//! write leaves the box booting the other slot (or bypass), never a mix.

use std::path::Path;

use anyhow::{bail, Context, Result};
use dynocomp_core::image::{BoxImage, CRC32};
use dynocomp_core::protocol::SlotInfo;
use dynocomp_core::shell::Slot;
use dynocomp_core::store::{
    encode_record, other, parse_header, seq_newer, trailing_id, verify_image, Header, Layout, Store, RECORD_HEADER_LEN,
    SLOT_A_ADDR, SLOT_B_ADDR, SLOT_LEN,
};
#[cfg(feature = "probe")]
use probe_rs::flashing::{DownloadOptions, FlashLoader};
#[cfg(feature = "probe")]
use probe_rs::probe::fake_probe::FakeProbe;
#[cfg(feature = "probe")]
use probe_rs::probe::list::Lister;
#[cfg(feature = "probe")]
use probe_rs::probe::Probe;
#[cfg(feature = "probe")]
use probe_rs::{MemoryInterface, Permissions, Session};

use crate::link::sim_flash::SimFlash;

/// Default chip of `--chip`: the box's STM32G474RE (probe-rs target name).
pub const DEFAULT_CHIP: &str = "STM32G474RETx";

/// Which slot to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotArg {
    /// Slot A (0x0807_C000).
    A,
    /// Slot B (0x0807_E000).
    B,
    /// The slot that does not hold the newest valid record.
    Auto,
}

/// What will be written where.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FlashPlan {
    /// The slot written.
    pub slot: Slot,
    /// Its start address in the chip's memory map.
    pub address: u64,
    /// Sequence number of the new record.
    pub seq: u32,
    /// The record bytes (header + image + 0xFF padding).
    pub record: Vec<u8>,
    /// The image id as `inspect` and the box's status show it (`BoxImage::id`,
    /// the image's trailing CRC).
    pub image_id: u32,
}

/// Start address of `slot` (memory.x).
pub fn slot_address(slot: Slot) -> u64 {
    u64::from(match slot {
        Slot::A => SLOT_A_ADDR,
        Slot::B => SLOT_B_ADDR,
    })
}

/// Read and verify an image file for the box; the error names the file.
pub fn read_box_image(path: &Path) -> Result<(Vec<u8>, BoxImage)> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    use dynocomp_core::protocol::LinkError;
    use dynocomp_core::sample::BypassReason;
    let img = verify_image(&bytes, CRC32.checksum(&bytes)).map_err(|e| match e {
        LinkError::NotRunnable(BypassReason::OfflineOnly) => anyhow::anyhow!(
            "{}: offline-only image (OfflineOnly: over the box's CPU budget at its sample rate, or parallel elaboration; see `dynocomp inspect`): the box never runs it, nothing was written — use it with `dynocomp compensate`, or re-run `dynocomp design` at a lower --fs",
            path.display()
        ),
        LinkError::NotRunnable(BypassReason::OverBudget(l)) => anyhow::anyhow!(
            "{}: predicted box CPU load {:.1} % ({} cycles per sample) at its sample rate exceeds the box's limit of {} %: the box would stay in bypass, nothing was written",
            path.display(),
            f64::from(l.permille) / 10.0,
            l.cycles,
            dynocomp_core::budget::BOX_LOAD_LIMIT_PERMILLE / 10
        ),
        e => anyhow::anyhow!(
            "{}: not a valid coefficient image for the box ({e}); nothing was written — re-run `dynocomp design` or check the file",
            path.display()
        ),
    })?;
    Ok((bytes, img))
}

/// Bytes of both slots as read from the chip: slot A then slot B.
pub const SLOTS_LEN: usize = 2 * SLOT_LEN as usize;

/// What the box would boot from `slots` (both slots' bytes, A then B): the
/// store's own boot scan (`Store::boot`: newest committed record whose image
/// verifies) run on a simulated flash holding those bytes.
pub fn running_slot(slots: &[u8]) -> Result<Option<SlotInfo>> {
    if slots.len() != SLOTS_LEN {
        bail!("slot contents: {} bytes, expected {SLOTS_LEN}", slots.len());
    }
    let mut flash = SimFlash::g474_slots();
    flash.bytes_mut().copy_from_slice(slots);
    let mut store =
        Store::open(flash, Layout::STM32G474RE).map_err(|e| anyhow::anyhow!("store layout refused: {e}"))?;
    Ok(store.boot().active)
}

/// Decide slot and sequence number from the contents of both slots
/// (`slots`, A then B, [`SLOTS_LEN`] bytes) and build the record. Pure.
///
/// * The slot the box runs (newest valid record, as its boot scan decides)
///   is never written: `auto` picks the other one (A if none runs), an
///   explicit `--slot` naming it is refused.
/// * The sequence number is one past the newest *committed* record of
///   either slot (valid or not), so the new record wins the boot scan.
pub fn plan(image: &[u8], slot: SlotArg, slots: &[u8]) -> Result<FlashPlan> {
    let running = running_slot(slots)?;
    let header = |i: usize| {
        let mut h = [0u8; RECORD_HEADER_LEN];
        let at = i * SLOT_LEN as usize;
        h.copy_from_slice(&slots[at..at + RECORD_HEADER_LEN]);
        parse_header(&h)
    };
    let newest_seq = [header(0), header(1)]
        .iter()
        .filter_map(|h| match *h {
            Header::Committed { seq, .. } => Some(seq),
            _ => None,
        })
        .reduce(|x, y| if seq_newer(y, x) { y } else { x });
    let target = match (slot, running) {
        (SlotArg::A, _) => Slot::A,
        (SlotArg::B, _) => Slot::B,
        (SlotArg::Auto, Some(info)) => other(info.slot),
        (SlotArg::Auto, None) => Slot::A,
    };
    if let Some(info) = running {
        if info.slot == target {
            bail!(
                "--slot {}: the box runs that slot (sequence {}, image {:#010x}); overwriting it would leave no fallback if this write is interrupted — use --slot auto or the other slot",
                if target == Slot::A { "a" } else { "b" },
                info.seq,
                info.image_id
            );
        }
    }
    let seq = newest_seq.map_or(1, |s| s.wrapping_add(1));
    let mut record = vec![0xFF; SLOT_LEN as usize];
    let n =
        encode_record(image, seq, &mut record).map_err(|e| anyhow::anyhow!("image does not fit a slot record: {e}"))?;
    record.truncate(n);
    Ok(FlashPlan { slot: target, address: slot_address(target), seq, record, image_id: trailing_id(image) })
}

#[cfg(feature = "probe")]
/// Read both slots (A then B) through an attached session.
pub fn read_slots(session: &mut Session) -> Result<Vec<u8>> {
    let mut core = session.core(0).context("probe: cannot access core 0")?;
    let mut out = vec![0u8; SLOTS_LEN];
    core.read(u64::from(SLOT_A_ADDR), &mut out)
        .with_context(|| format!("probe: cannot read the coefficient slots at {SLOT_A_ADDR:#010x}"))?;
    Ok(out)
}

#[cfg(feature = "probe")]
/// The probe-rs flash loader holding `plan`'s record at its address
/// (checked against the chip's memory map).
pub fn loader_for(session: &Session, plan: &FlashPlan) -> Result<FlashLoader> {
    let mut loader = session.target().flash_loader();
    loader
        .add_data(plan.address, &plan.record)
        .with_context(|| format!("probe: {:#010x} is not flash of {}", plan.address, session.target().name))?;
    Ok(loader)
}

#[cfg(feature = "probe")]
/// Erase, program and verify `plan` (or, with `dry_run`, only let probe-rs
/// build its flash plan).
pub fn execute(session: &mut Session, plan: &FlashPlan, dry_run: bool) -> Result<()> {
    let loader = loader_for(session, plan)?;
    let mut options = DownloadOptions::default();
    options.verify = true;
    options.dry_run = dry_run;
    // Keep the rest of the erased sectors as they were (the slot is 4 pages;
    // a record is shorter).
    options.keep_unwritten_bytes = true;
    loader.commit(session, options).with_context(|| format!("probe: writing slot at {:#010x} failed", plan.address))?;
    Ok(())
}

#[cfg(feature = "probe")]
/// A session on probe-rs's fake probe (mocked Cortex-M core), for dry runs.
pub fn fake_session(chip: &str) -> Result<Session> {
    FakeProbe::with_mocked_core()
        .into_probe()
        .attach(chip, Permissions::default())
        .with_context(|| format!("dry run: probe-rs has no usable target description for chip {chip:?}"))
}

#[cfg(feature = "probe")]
fn real_session(chip: &str) -> Result<Session> {
    let probes = Lister::new().list_all();
    let Some(info) = probes.first() else {
        bail!("no debug probe found (connect the ST-LINK of the Nucleo, or use --dry-run)");
    };
    if probes.len() > 1 {
        eprintln!("{} probes found; using the first: {info}", probes.len());
    }
    let probe: Probe = info.open().with_context(|| format!("cannot open probe {info}"))?;
    probe.attach(chip, Permissions::default()).with_context(|| format!("cannot attach to {chip} through {info}"))
}

/// One-line description of a plan.
pub fn describe(plan: &FlashPlan) -> String {
    format!(
        "slot {} at {:#010x}: record of {} bytes (image id {:#010x}, sequence {})",
        plan.slot,
        plan.address,
        plan.record.len(),
        plan.image_id,
        plan.seq
    )
}

#[cfg(feature = "probe")]
/// `dynocomp flash IMAGE --probe`, in this order:
///
/// 1. Read and verify the image file (CRC, version, ranges, stability,
///    runnable on the box). A bad image is refused here, before any probe is
///    opened.
/// 2. Open the probe, attach to the chip, read both slots.
/// 3. [`plan`]: run the box's own boot scan on those bytes to see which slot
///    it runs; pick the other one (`auto`; an explicit slot that holds the
///    running image is refused) and the sequence number (newest committed +
///    1, so the new record wins at boot).
/// 4. probe-rs `FlashLoader`: the record at the slot address, erase/program
///    with `verify` (read back), then reset the core so the box boots with
///    the new image.
///
/// `dry_run` needs no hardware: it runs steps 1, 3 and 4 against probe-rs's
/// `FakeProbe` (a mock debug probe with a mocked Cortex-M core) and
/// `DownloadOptions::dry_run` — the loader checks the data against the chip's
/// memory map and builds its flash plan (flash algorithm, sectors) — and
/// prints the plan (after the fake probe's own log of register accesses,
/// which probe-rs prints on stdout). The slots are not read in a dry run (the
/// fake probe has no flash contents): both count as erased, so `auto` = slot
/// A, sequence 1. A power cut or a pulled cable during step 4 leaves a record
/// whose CRC or commit word does not check out; the box then boots the other
/// slot (or bypass).
pub fn run(image: &Path, chip: &str, slot: SlotArg, dry_run: bool, verbose: bool) -> Result<()> {
    // probe-rs's fake probe prints every register access on stdout (about 56
    // lines): shown only with --verbose.
    let quiet = (dry_run && !verbose).then(StdoutSilenced::new);
    let result = run_with(image, chip, slot, dry_run, real_session);
    drop(quiet);
    let summary = result?;
    println!("{summary}");
    Ok(())
}

/// Stdout sent to /dev/null while it lives (the process's file descriptor
/// 1, which a library's `println!` writes to), restored on drop. Does
/// nothing where that is not possible.
struct StdoutSilenced {
    #[cfg(unix)]
    saved: Option<std::os::fd::OwnedFd>,
}

impl StdoutSilenced {
    fn new() -> Self {
        use std::io::Write;
        let _ = std::io::stdout().flush();
        #[cfg(unix)]
        {
            use std::os::fd::AsFd;
            let null = std::fs::OpenOptions::new().write(true).open("/dev/null").ok();
            let saved = null.and_then(|null| {
                let saved = nix::unistd::dup(std::io::stdout().as_fd()).ok()?;
                nix::unistd::dup2_stdout(&null).ok().map(|()| saved)
            });
            StdoutSilenced { saved }
        }
        #[cfg(not(unix))]
        StdoutSilenced {}
    }
}

impl Drop for StdoutSilenced {
    fn drop(&mut self) {
        use std::io::Write;
        let _ = std::io::stdout().flush();
        #[cfg(unix)]
        if let Some(saved) = &self.saved {
            let _ = nix::unistd::dup2_stdout(saved);
        }
    }
}

#[cfg(feature = "probe")]
/// [`run`] with the session opener for real (non-dry) runs given, so tests
/// can check that a bad image never reaches it.
pub fn run_with(
    image: &Path,
    chip: &str,
    slot: SlotArg,
    dry_run: bool,
    open: impl FnOnce(&str) -> Result<Session>,
) -> Result<String> {
    let (bytes, img) = read_box_image(image)?;
    let mut session = if dry_run { fake_session(chip)? } else { open(chip)? };
    // The fake probe has no flash contents (it reads zeros and logs every
    // byte): a dry run plans against erased slots.
    let slots = if dry_run { vec![0xFF; SLOTS_LEN] } else { read_slots(&mut session)? };
    let plan = plan(&bytes, slot, &slots)?;
    execute(&mut session, &plan, dry_run)?;
    if dry_run {
        // probe-rs's fake probe logs its register accesses on stdout, also
        // when the session closes: close it first so the plan comes last.
        drop(session);
        Ok(format!(
            "dry run (fake probe, nothing written): would write {} to {chip}, fs = {} Hz; the slots were not read (erased assumed)",
            describe(&plan),
            img.fs_hz()
        ))
    } else {
        session
            .core(0)
            .and_then(|mut core| core.reset())
            .context("written and verified, but the reset failed: reset the box by hand")?;
        Ok(format!("wrote and verified {} on {chip}; box reset, it boots the newest valid slot", describe(&plan)))
    }
}
