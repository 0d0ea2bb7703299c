//! The power-fail-safe A/B coefficient store: two flash slots (`memory.x`:
//! `COEFF_A` at 0x0807_C000, `COEFF_B` at 0x0807_E000, 8 KiB each), each
//! holding a sequence-numbered, CRC-protected record around a coefficient
//! image. Generic over the `embedded-storage` NOR-flash traits, so the same
//! code runs on embassy-stm32's flash driver and on the host's simulated
//! flash. The full argument is in `docs/store.md`.
//!
//! # Slot record (offsets inside the slot, little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `DCSL` |
//! | 4 | 4 | sequence number |
//! | 8 | 4 | image length `len` |
//! | 12 | 4 | CRC-32 of all `len` image bytes |
//! | 16 | 4 | commit magic `CMT1` |
//! | 20 | 4 | CRC-32 of bytes 0..16 |
//! | 24 | 8 | 0xFF (unused) |
//! | 32 | len | the image, padded with 0xFF to the write size |
//!
//! Write order of an upload: erase the inactive slot (header page first) →
//! image bytes → descriptor (0..16) → read back and verify everything →
//! commit word (16..24) **last**. A slot counts only if its commit word is
//! present and matches its descriptor, the image CRC matches and the image
//! parses and is runnable. Boot takes the valid slot with the newest
//! sequence number (wrapping comparison); none valid → bypass.
//!
//! # How the firmware calls this (API note for the box)
//!
//! * **Boot (main, before the sample path starts):** `Store::open(flash,
//!   Layout::STM32G474RE)`, then [`Store::boot`] gives the image to run (or
//!   the bypass reason) and the active slot.
//! * **USB task only:** all upload calls ([`Store::begin_upload`],
//!   [`Store::write_chunk`], [`Store::commit`]) run through
//!   [`crate::link::BoxLink`]. They block while the flash erases/writes
//!   (bank 2; the CPU keeps executing from bank 1, so the sample interrupt
//!   is not stalled; RM0440 §3.3.8 read-while-write).
//! * **Sample interrupt:** never touches the store or the flash. After a
//!   commit, the USB task loads the new image with [`Store::load_active`]
//!   into the spare image buffer and hands it to the interrupt through
//!   [`crate::handoff::ImageHandoff`]; the interrupt switches at a sample
//!   boundary.

use embedded_storage::nor_flash::{NorFlash, NorFlashError, NorFlashErrorKind};

use crate::image::{BoxImage, ImageError, CRC32, MAX_BOX_IMAGE_LEN};
use crate::protocol::{FlashFault, LinkError, SlotInfo};
use crate::sample::{select_mode, BypassReason, Mode};
use crate::shell::Slot;

/// Start of slot A in the STM32G474RE memory map (`memory.x`).
pub const SLOT_A_ADDR: u32 = 0x0807_C000;
/// Start of slot B (`memory.x`).
pub const SLOT_B_ADDR: u32 = 0x0807_E000;
/// Size of one slot, bytes.
pub const SLOT_LEN: u32 = 8 * 1024;
/// Start of the on-chip flash; embassy-stm32's `NorFlash` offsets count
/// from here.
pub const FLASH_BASE: u32 = 0x0800_0000;
/// Bytes before the image in a slot.
pub const RECORD_HEADER_LEN: usize = 32;
/// Slot magic (offset 0).
pub const SLOT_MAGIC: [u8; 4] = *b"DCSL";
/// Commit magic (offset 16).
pub const COMMIT_MAGIC: [u8; 4] = *b"CMT1";
/// Largest write size the store supports (the descriptor and the commit word
/// must be separate writes).
pub const MAX_WRITE_SIZE: usize = 16;
/// Read-back buffer: the largest image rounded up to [`MAX_WRITE_SIZE`].
const BUF_LEN: usize = MAX_BOX_IMAGE_LEN.div_ceil(MAX_WRITE_SIZE) * MAX_WRITE_SIZE;

// A slot must hold the largest image plus the record header.
const _: () = assert!(RECORD_HEADER_LEN + BUF_LEN <= SLOT_LEN as usize);

/// Where the two slots are, as offsets in the `NorFlash` device's address
/// space.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Layout {
    /// Offset of slot A.
    pub a: u32,
    /// Offset of slot B.
    pub b: u32,
    /// Length of each slot.
    pub len: u32,
}

impl Layout {
    /// The box: offsets from [`FLASH_BASE`] (embassy-stm32's convention).
    pub const STM32G474RE: Layout = Layout { a: SLOT_A_ADDR - FLASH_BASE, b: SLOT_B_ADDR - FLASH_BASE, len: SLOT_LEN };

    /// Offset of `slot`.
    pub fn offset(&self, slot: Slot) -> u32 {
        match slot {
            Slot::A => self.a,
            Slot::B => self.b,
        }
    }

    /// Largest image a slot holds.
    pub fn max_image_len(&self) -> u32 {
        (self.len as usize).saturating_sub(RECORD_HEADER_LEN).min(MAX_BOX_IMAGE_LEN) as u32
    }
}

/// The other slot.
pub fn other(slot: Slot) -> Slot {
    match slot {
        Slot::A => Slot::B,
        Slot::B => Slot::A,
    }
}

/// Whether sequence number `a` is newer than `b` (serial-number arithmetic:
/// `a − b` as a signed 32-bit value is positive), so the counter may wrap.
pub fn seq_newer(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

/// What the header of a slot says (before the image is checked).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Header {
    /// All header bytes 0xFF: erased, never written.
    Erased,
    /// Descriptor present but no valid commit word (an upload that did not
    /// finish, or a torn write): never used.
    Uncommitted,
    /// A committed record.
    Committed {
        /// Sequence number.
        seq: u32,
        /// Image length.
        len: u32,
        /// CRC-32 of the image.
        image_crc: u32,
    },
}

/// Decode a slot's 32 header bytes (pure; used by boot and by the host to
/// show what a slot holds).
pub fn parse_header(h: &[u8; RECORD_HEADER_LEN]) -> Header {
    if h.iter().all(|&b| b == 0xFF) {
        return Header::Erased;
    }
    let word = |i: usize| u32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
    let desc_crc = CRC32.checksum(&h[..16]);
    if h[..4] != SLOT_MAGIC || h[16..20] != COMMIT_MAGIC || word(20) != desc_crc {
        return Header::Uncommitted;
    }
    Header::Committed { seq: word(4), len: word(8), image_crc: word(12) }
}

/// The 16-byte descriptor and 8-byte commit word of a record.
fn record_words(seq: u32, len: u32, image_crc: u32) -> ([u8; 16], [u8; 8]) {
    let mut d = [0u8; 16];
    d[..4].copy_from_slice(&SLOT_MAGIC);
    d[4..8].copy_from_slice(&seq.to_le_bytes());
    d[8..12].copy_from_slice(&len.to_le_bytes());
    d[12..16].copy_from_slice(&image_crc.to_le_bytes());
    let mut c = [0u8; 8];
    c[..4].copy_from_slice(&COMMIT_MAGIC);
    c[4..8].copy_from_slice(&CRC32.checksum(&d).to_le_bytes());
    (d, c)
}

/// A complete slot record (header + image + 0xFF padding) for writing a slot
/// in one go, e.g. by `dynocomp flash --probe` at the slot's address.
/// Returns the record's length (a multiple of [`MAX_WRITE_SIZE`]).
///
/// The image must parse ([`BoxImage::parse`]: version 1 or 3); the record is then exactly
/// what an upload leaves in the slot with sequence number `seq`.
pub fn encode_record(image: &[u8], seq: u32, out: &mut [u8]) -> Result<usize, ImageError> {
    BoxImage::parse(image)?;
    let total = RECORD_HEADER_LEN + image.len().div_ceil(MAX_WRITE_SIZE) * MAX_WRITE_SIZE;
    let dst = out.get_mut(..total).ok_or(ImageError::BufferTooSmall { needed: total as u32 })?;
    dst.fill(0xFF);
    let (d, c) = record_words(seq, image.len() as u32, CRC32.checksum(image));
    dst[..16].copy_from_slice(&d);
    dst[16..24].copy_from_slice(&c);
    dst[RECORD_HEADER_LEN..RECORD_HEADER_LEN + image.len()].copy_from_slice(image);
    Ok(total)
}

/// Verify image bytes for the box: CRC against `crc`, full parse (version 1
/// or 3,
/// ranges, finiteness, section stability), and runnable on the box (not
/// offline-only, sample rate in [`crate::sample::BOX_FS_RANGE_HZ`], predicted
/// interrupt load within [`crate::budget::BOX_LOAD_LIMIT_PERMILLE`]).
pub fn verify_image(bytes: &[u8], crc: u32) -> Result<BoxImage, LinkError> {
    let computed = CRC32.checksum(bytes);
    if computed != crc {
        return Err(LinkError::CrcMismatch { declared: crc, computed });
    }
    let img = BoxImage::parse(bytes).map_err(LinkError::Image)?;
    match select_mode(Some(&Ok(img)), false) {
        Mode::Compensate(_) => Ok(img),
        Mode::Bypass(r) => Err(LinkError::NotRunnable(r)),
    }
}

/// Result of checking one slot completely.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SlotState {
    /// Erased or uncommitted: holds nothing.
    Empty,
    /// Committed record whose image fails verification (bit rot, …).
    Invalid(VerifyFailure),
    /// Committed, verified record.
    Valid(SlotInfo),
}

/// Why a committed slot failed verification (for [`SlotState`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum VerifyFailure {
    /// The header's length is out of range.
    BadLength(u32),
    /// Image CRC mismatch.
    Crc {
        /// CRC in the slot header.
        stored: u32,
        /// CRC of the image bytes.
        computed: u32,
    },
    /// The image does not parse.
    Image(ImageError),
    /// The image is not runnable on the box.
    NotRunnable(BypassReason),
    /// Flash read failed.
    Flash,
}

impl core::fmt::Display for VerifyFailure {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            VerifyFailure::BadLength(l) => write!(f, "slot record length {l} out of range"),
            VerifyFailure::Crc { stored, computed } => {
                write!(f, "slot image CRC mismatch: stored {stored:#010x}, computed {computed:#010x}")
            }
            VerifyFailure::Image(e) => write!(f, "slot image invalid: {e}"),
            VerifyFailure::NotRunnable(r) => write!(f, "slot image not runnable: {r}"),
            VerifyFailure::Flash => f.write_str("flash read failed"),
        }
    }
}

/// What boot found: the image to run or why not, and the slot it is in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Boot {
    /// The verified image of the newest valid slot, or the bypass reason:
    /// [`BypassReason::NoImage`] if both slots are empty, else the
    /// verification error of the newest committed slot.
    pub image: Result<BoxImage, BypassReason>,
    /// The active slot (None if no slot is valid).
    pub active: Option<SlotInfo>,
}

/// An upload under way.
#[derive(Clone, Copy, Debug)]
struct Upload {
    slot: Slot,
    len: u32,
    crc: u32,
    /// Bytes received so far.
    received: u32,
    /// Received bytes not yet written (fewer than the write size).
    carry: [u8; MAX_WRITE_SIZE],
    carry_len: usize,
    /// A flash error happened: refuse further chunks and the commit.
    failed: bool,
}

/// The A/B store over a NOR flash `F`.
pub struct Store<F> {
    flash: F,
    layout: Layout,
    active: Option<SlotInfo>,
    upload: Option<Upload>,
    buf: [u8; BUF_LEN],
}

/// Why [`Store::open`] refused a flash/layout combination.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LayoutError {
    /// The flash's write size is above [`MAX_WRITE_SIZE`] or does not divide it.
    WriteSize,
    /// The flash's read size does not divide [`MAX_WRITE_SIZE`].
    ReadSize,
    /// A slot is not aligned to / a multiple of the erase size, the slots
    /// overlap, or a slot lies outside the flash.
    Slots,
}

impl core::fmt::Display for LayoutError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            LayoutError::WriteSize => "the flash's write size does not divide the store's write unit",
            LayoutError::ReadSize => "the flash's read size does not divide the store's write unit",
            LayoutError::Slots => "slots misaligned to the erase size, overlapping, or outside the flash",
        })
    }
}

fn fault<E: NorFlashError>(e: E) -> LinkError {
    LinkError::Flash(match e.kind() {
        NorFlashErrorKind::NotAligned => FlashFault::NotAligned,
        NorFlashErrorKind::OutOfBounds => FlashFault::OutOfBounds,
        _ => FlashFault::Other,
    })
}

impl<F: NorFlash> Store<F> {
    /// Check the layout against the flash's geometry and scan both slots.
    pub fn open(flash: F, layout: Layout) -> Result<Self, LayoutError> {
        let (w, r, e) = (F::WRITE_SIZE, F::READ_SIZE, F::ERASE_SIZE as u32);
        if w == 0 || w > MAX_WRITE_SIZE || !MAX_WRITE_SIZE.is_multiple_of(w) {
            return Err(LayoutError::WriteSize);
        }
        if r == 0 || !MAX_WRITE_SIZE.is_multiple_of(r) {
            return Err(LayoutError::ReadSize);
        }
        let cap = flash.capacity() as u64;
        let ok_slot = |o: u32| e != 0 && o.is_multiple_of(e) && u64::from(o) + u64::from(layout.len) <= cap;
        let disjoint = layout.a.abs_diff(layout.b) >= layout.len;
        if layout.len == 0
            || e == 0
            || !layout.len.is_multiple_of(e)
            || !ok_slot(layout.a)
            || !ok_slot(layout.b)
            || !disjoint
        {
            return Err(LayoutError::Slots);
        }
        let mut s = Store { flash, layout, active: None, upload: None, buf: [0; BUF_LEN] };
        s.active = s.boot().active;
        Ok(s)
    }

    /// The slot layout.
    pub fn layout(&self) -> Layout {
        self.layout
    }

    /// The active (newest valid) slot.
    pub fn active(&self) -> Option<SlotInfo> {
        self.active
    }

    /// Give the flash back (tests: "power cut" = drop the store, reopen).
    pub fn into_flash(self) -> F {
        self.flash
    }

    /// The flash (tests: inspect or corrupt it).
    pub fn flash_mut(&mut self) -> &mut F {
        &mut self.flash
    }

    /// Read `len` image bytes of `slot` into the buffer (rounded up to the
    /// read size); returns the image bytes.
    fn read_image(&mut self, slot: Slot, len: u32) -> Result<&[u8], LinkError> {
        let n = len as usize;
        let padded = n.div_ceil(MAX_WRITE_SIZE) * MAX_WRITE_SIZE;
        let off = self.layout.offset(slot) + RECORD_HEADER_LEN as u32;
        let dst = self.buf.get_mut(..padded).ok_or(LinkError::UploadTooLarge { len, max: MAX_BOX_IMAGE_LEN as u32 })?;
        self.flash.read(off, dst).map_err(fault)?;
        self.buf.get(..n).ok_or(LinkError::Flash(FlashFault::Other))
    }

    fn read_header(&mut self, slot: Slot) -> Result<Header, LinkError> {
        let mut h = [0u8; RECORD_HEADER_LEN];
        self.flash.read(self.layout.offset(slot), &mut h).map_err(fault)?;
        Ok(parse_header(&h))
    }

    /// Check `slot` completely (header, CRC, parse, runnable).
    pub fn check(&mut self, slot: Slot) -> SlotState {
        self.check_image(slot).1
    }

    fn check_image(&mut self, slot: Slot) -> (Option<BoxImage>, SlotState) {
        let (seq, len, image_crc) = match self.read_header(slot) {
            Err(_) => return (None, SlotState::Invalid(VerifyFailure::Flash)),
            Ok(Header::Erased | Header::Uncommitted) => return (None, SlotState::Empty),
            Ok(Header::Committed { seq, len, image_crc }) => (seq, len, image_crc),
        };
        if len == 0 || len > self.layout.max_image_len() {
            return (None, SlotState::Invalid(VerifyFailure::BadLength(len)));
        }
        let bytes = match self.read_image(slot, len) {
            Ok(b) => b,
            Err(_) => return (None, SlotState::Invalid(VerifyFailure::Flash)),
        };
        let image_id = trailing_id(bytes);
        match verify_image(bytes, image_crc) {
            Ok(img) => (Some(img), SlotState::Valid(SlotInfo { slot, seq, image_id })),
            Err(e) => (None, SlotState::Invalid(kind(e))),
        }
    }

    /// Scan both slots: the newest valid slot wins. Also refreshes
    /// [`active`](Self::active).
    pub fn boot(&mut self) -> Boot {
        let (img_a, a) = self.check_image(Slot::A);
        let (img_b, b) = self.check_image(Slot::B);
        let pick_b = match (a, b) {
            (SlotState::Valid(x), SlotState::Valid(y)) => seq_newer(y.seq, x.seq),
            (_, SlotState::Valid(_)) => true,
            _ => false,
        };
        let (img, state, other_state) = if pick_b { (img_b, b, a) } else { (img_a, a, b) };
        let boot = match (img, state) {
            (Some(img), SlotState::Valid(info)) => Boot { image: Ok(img), active: Some(info) },
            _ => {
                // No valid slot: report the first committed-but-invalid one.
                let reason = [state, other_state]
                    .iter()
                    .find_map(|s| match s {
                        SlotState::Invalid(k) => Some(bypass_reason(*k)),
                        _ => None,
                    })
                    .unwrap_or(BypassReason::NoImage);
                Boot { image: Err(reason), active: None }
            }
        };
        self.active = boot.active;
        boot
    }

    /// Load and verify the active slot's image (after a commit: the image
    /// to hand to the sample path).
    pub fn load_active(&mut self) -> Result<BoxImage, BypassReason> {
        let Some(info) = self.active else { return Err(BypassReason::NoImage) };
        match self.check_image(info.slot) {
            (Some(img), SlotState::Valid(_)) => Ok(img),
            (_, SlotState::Invalid(k)) => Err(bypass_reason(k)),
            _ => Err(BypassReason::NoImage),
        }
    }

    /// The slot an upload writes: the one that is not active.
    pub fn inactive(&self) -> Slot {
        match self.active {
            Some(info) => other(info.slot),
            None => Slot::A,
        }
    }

    /// Start an upload of `len` bytes with CRC `crc`: erases the inactive
    /// slot (header page first). Abandons any upload under way.
    pub fn begin_upload(&mut self, len: u32, crc: u32) -> Result<(), LinkError> {
        self.upload = None;
        let max = self.layout.max_image_len();
        if len == 0 || len > max {
            return Err(LinkError::UploadTooLarge { len, max });
        }
        let slot = self.inactive();
        let start = self.layout.offset(slot);
        let page = F::ERASE_SIZE as u32;
        let mut off = start;
        while off < start + self.layout.len {
            self.flash.erase(off, off + page).map_err(fault)?;
            off += page;
        }
        self.upload =
            Some(Upload { slot, len, crc, received: 0, carry: [0xFF; MAX_WRITE_SIZE], carry_len: 0, failed: false });
        Ok(())
    }

    /// Bytes received by the upload under way (None: no upload).
    pub fn upload_received(&self) -> Option<u32> {
        self.upload.map(|u| u.received)
    }

    /// Write the next chunk of the upload. `offset` must equal the bytes
    /// received so far; nothing is written on any error.
    pub fn write_chunk(&mut self, offset: u32, bytes: &[u8]) -> Result<(), LinkError> {
        let w = F::WRITE_SIZE;
        let base = |u: &Upload, layout: &Layout| layout.offset(u.slot) + RECORD_HEADER_LEN as u32;
        let Some(mut u) = self.upload else { return Err(LinkError::NoUpload) };
        if u.failed {
            return Err(LinkError::UploadAborted);
        }
        if offset != u.received {
            return Err(LinkError::OutOfOrder { expected: u.received, got: offset });
        }
        if bytes.len() > crate::protocol::MAX_CHUNK || u64::from(u.received) + bytes.len() as u64 > u64::from(u.len) {
            return Err(LinkError::ChunkTooLong { len: u.len });
        }
        let mut result = Ok(());
        for &byte in bytes {
            u.carry[u.carry_len] = byte;
            u.carry_len += 1;
            u.received += 1;
            let last = u.received == u.len;
            if u.carry_len == w || last {
                // Units are aligned: `received - carry_len` is a multiple of w.
                let addr = base(&u, &self.layout) + u.received - u.carry_len as u32;
                if let Err(e) = self.flash.write(addr, &u.carry[..w]) {
                    u.failed = true;
                    result = Err(fault(e));
                    break;
                }
                u.carry = [0xFF; MAX_WRITE_SIZE];
                u.carry_len = 0;
            }
        }
        self.upload = Some(u);
        result
    }

    /// Finish the upload: read the image back and verify it
    /// ([`verify_image`]), write the descriptor, write the commit word last,
    /// then re-check the slot as boot would. On success the new slot is
    /// active and its [`SlotInfo`] is returned; on any error the previously
    /// active slot stays active (the new slot is left uncommitted or is
    /// older than it).
    pub fn commit(&mut self) -> Result<SlotInfo, LinkError> {
        let Some(u) = self.upload else { return Err(LinkError::NoUpload) };
        if u.failed {
            return Err(LinkError::UploadAborted);
        }
        if u.received != u.len {
            return Err(LinkError::Incomplete { received: u.received, len: u.len });
        }
        // The upload ends here whatever the outcome.
        self.upload = None;
        let bytes = self.read_image(u.slot, u.len)?;
        verify_image(bytes, u.crc)?;
        let seq = self.active.map_or(1, |a| a.seq.wrapping_add(1));
        let (d, c) = record_words(seq, u.len, u.crc);
        let start = self.layout.offset(u.slot);
        let w = F::WRITE_SIZE;
        for (i, unit) in d.chunks(w).enumerate() {
            self.flash.write(start + (i * w) as u32, unit).map_err(fault)?;
        }
        for (i, unit) in c.chunks(w).enumerate() {
            self.flash.write(start + 16 + (i * w) as u32, unit).map_err(fault)?;
        }
        match self.check(u.slot) {
            SlotState::Valid(info) if info.seq == seq => {
                self.active = Some(info);
                Ok(info)
            }
            _ => Err(LinkError::Flash(FlashFault::Verify)),
        }
    }
}

/// The image id ([`BoxImage::id`]) of encoded image bytes: the image's
/// own trailing CRC-32 (valid once the image has parsed). Not to be confused
/// with the record's `image_crc`, the CRC-32 of all the image bytes, which
/// protects the transfer and the slot.
pub fn trailing_id(bytes: &[u8]) -> u32 {
    match bytes.len().checked_sub(4).and_then(|n| bytes.get(n..)) {
        Some(&[a, b, c, d]) => u32::from_le_bytes([a, b, c, d]),
        _ => 0,
    }
}

fn kind(e: LinkError) -> VerifyFailure {
    match e {
        LinkError::CrcMismatch { declared, computed } => VerifyFailure::Crc { stored: declared, computed },
        LinkError::Image(i) => VerifyFailure::Image(i),
        LinkError::NotRunnable(r) => VerifyFailure::NotRunnable(r),
        LinkError::Flash(_) => VerifyFailure::Flash,
        _ => VerifyFailure::BadLength(0),
    }
}

fn bypass_reason(k: VerifyFailure) -> BypassReason {
    match k {
        VerifyFailure::Image(e) => BypassReason::InvalidImage(e),
        VerifyFailure::NotRunnable(r) => r,
        VerifyFailure::Crc { stored, computed } => BypassReason::InvalidImage(ImageError::BadCrc { stored, computed }),
        VerifyFailure::BadLength(len) => BypassReason::InvalidImage(ImageError::BadLength(len)),
        // A failed read of memory-mapped flash: report it as an unreadable image.
        VerifyFailure::Flash => BypassReason::InvalidImage(ImageError::Truncated { needed: 1, have: 0 }),
    }
}
