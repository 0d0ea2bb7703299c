//! A simulated NOR flash with the STM32G4's geometry and semantics
//! ([`SimFlash`]), for the coefficient store's tests and the virtual box. The
//! window `base..base + len` of the device's address space is simulated; the
//! rest is out of bounds. With `base = 0x7C000` and `len = 16 KiB` the
//! store's [`Layout::STM32G474RE`](dynocomp_core::store::Layout::STM32G474RE)
//! offsets are used unchanged.

use std::fs::File;
use std::io::{Read, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};

/// Page (erase unit) of the STM32G474RE in dual-bank mode, bytes.
pub const PAGE: usize = 2048;
/// Programming unit (double word), bytes.
pub const DWORD: usize = 8;
/// Capacity of the whole device: 512 KiB.
pub const DEVICE_LEN: u32 = 512 * 1024;

/// How the operation hit by a power cut is left.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CutMode {
    /// The operation did not start.
    Before,
    /// The operation completed, but nothing after it.
    After,
    /// The operation was torn: a write cleared only some of its bits, an
    /// erase set only some of the page's bytes to 0xFF. Deterministic from
    /// the seed.
    Torn(u64),
}

/// Simulated flash errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimError {
    /// Offset or length not aligned to the page / double word.
    NotAligned,
    /// Outside the simulated window.
    OutOfBounds,
    /// Programming a double word that is not erased (PROGERR).
    NotErased,
    /// The power was cut; nothing works until the flash is reopened.
    PowerLost,
}

impl NorFlashError for SimError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            SimError::NotAligned => NorFlashErrorKind::NotAligned,
            SimError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// The simulated flash.
///
/// * Erase works on 2 KiB pages and sets them to 0xFF.
/// * Writes are whole, 8-byte aligned double words, and a double word can
///   only be programmed while fully erased (RM0440 §3.3.7: programming a
///   non-erased double word sets PROGERR). Bits can only go 1 → 0.
/// * A power cut can be scheduled at any operation boundary: operation
///   number `n` (each page erase and each double-word write is one
///   operation) is torn ([`CutMode`]) and every later operation fails with
///   [`SimError::PowerLost`], as if the MCU had lost power there.
/// * Optionally the contents live in a file, written through on every
///   operation, so a "reboot" can be a new process.
#[derive(Debug)]
pub struct SimFlash {
    base: u32,
    mem: Vec<u8>,
    /// Operations performed so far (erased pages + written double words).
    ops: u64,
    cut_at: Option<(u64, CutMode)>,
    dead: bool,
    file: Option<(PathBuf, File)>,
}

/// splitmix64: a tiny deterministic bit source for torn operations.
fn mix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl SimFlash {
    /// An erased window of `len` bytes (a multiple of [`PAGE`]) at `base`.
    pub fn new(base: u32, len: usize) -> Self {
        SimFlash { base, mem: vec![0xFF; len], ops: 0, cut_at: None, dead: false, file: None }
    }

    /// The window of the STM32G474RE's two coefficient slots
    /// (0x0807_C000..0x0808_0000 as offsets 0x7C000..0x80000).
    pub fn g474_slots() -> Self {
        Self::new(dynocomp_core::store::Layout::STM32G474RE.a, 2 * dynocomp_core::store::SLOT_LEN as usize)
    }

    /// Like [`g474_slots`](Self::g474_slots), with the contents in `path`
    /// (created erased if missing), written through on every operation.
    pub fn g474_slots_file(path: &Path) -> Result<Self> {
        let mut f = Self::g474_slots();
        if path.exists() {
            let mut file = File::open(path).with_context(|| format!("{}: cannot open flash file", path.display()))?;
            let mut bytes = Vec::new();
            file.read_to_end(&mut bytes).with_context(|| format!("{}: cannot read flash file", path.display()))?;
            anyhow::ensure!(
                bytes.len() == f.mem.len(),
                "{}: flash file has {} bytes, expected {}",
                path.display(),
                bytes.len(),
                f.mem.len()
            );
            f.mem = bytes;
        } else {
            let mut file =
                File::create(path).with_context(|| format!("{}: cannot create flash file", path.display()))?;
            file.write_all(&f.mem).with_context(|| format!("{}: cannot write flash file", path.display()))?;
        }
        let file = std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .with_context(|| format!("{}: cannot open flash file for writing", path.display()))?;
        f.file = Some((path.to_path_buf(), file));
        Ok(f)
    }

    /// Schedule a power cut at operation number `op` (0-based, counted from
    /// now on the running total [`ops`](Self::ops)).
    pub fn cut_power_at(&mut self, op: u64, mode: CutMode) {
        self.cut_at = Some((op, mode));
    }

    /// Operations performed so far.
    pub fn ops(&self) -> u64 {
        self.ops
    }

    /// Whether a power cut happened.
    pub fn is_dead(&self) -> bool {
        self.dead
    }

    /// "Reboot": power is back, no cut scheduled, contents kept.
    pub fn reboot(mut self) -> Self {
        self.dead = false;
        self.cut_at = None;
        self
    }

    /// A copy of the contents, powered, without a file or a scheduled cut
    /// (the operation counter restarts at 0).
    pub fn copy(&self) -> Self {
        SimFlash { base: self.base, mem: self.mem.clone(), ops: 0, cut_at: None, dead: false, file: None }
    }

    /// The simulated bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.mem
    }

    /// Mutable bytes (tests: bit rot).
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        &mut self.mem
    }

    fn range(&self, offset: u32, len: usize) -> Result<std::ops::Range<usize>, SimError> {
        let start = offset.checked_sub(self.base).ok_or(SimError::OutOfBounds)? as usize;
        let end = start.checked_add(len).ok_or(SimError::OutOfBounds)?;
        if end > self.mem.len() {
            return Err(SimError::OutOfBounds);
        }
        Ok(start..end)
    }

    /// Decide the fate of the next operation: `Ok(None)` run it fully,
    /// `Ok(Some(mode))` the cut hits it, `Err` power already lost.
    fn next_op(&mut self) -> Result<Option<CutMode>, SimError> {
        if self.dead {
            return Err(SimError::PowerLost);
        }
        let n = self.ops;
        self.ops += 1;
        match self.cut_at {
            Some((at, mode)) if at == n => {
                self.dead = true;
                Ok(Some(mode))
            }
            _ => Ok(None),
        }
    }

    fn persist(&mut self, r: std::ops::Range<usize>) {
        if let Some((path, file)) = &self.file {
            // A failed write-through is a test-environment failure, not a
            // flash behaviour: make it loud.
            if let Err(e) = file.write_all_at(&self.mem[r.clone()], r.start as u64) {
                panic!("{}: cannot write through simulated flash: {e}", path.display());
            }
        }
    }
}

impl ErrorType for SimFlash {
    type Error = SimError;
}

impl ReadNorFlash for SimFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), SimError> {
        if self.dead {
            return Err(SimError::PowerLost);
        }
        let r = self.range(offset, bytes.len())?;
        bytes.copy_from_slice(&self.mem[r]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        DEVICE_LEN as usize
    }
}

impl NorFlash for SimFlash {
    const WRITE_SIZE: usize = DWORD;
    const ERASE_SIZE: usize = PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), SimError> {
        if from > to || !(from as usize).is_multiple_of(PAGE) || !(to as usize).is_multiple_of(PAGE) {
            return Err(SimError::NotAligned);
        }
        self.range(from, (to - from) as usize)?;
        for page in (from..to).step_by(PAGE) {
            let r = self.range(page, PAGE)?;
            match self.next_op()? {
                None | Some(CutMode::After) => self.mem[r.clone()].fill(0xFF),
                Some(CutMode::Before) => {}
                Some(CutMode::Torn(seed)) => {
                    for (i, b) in self.mem[r.clone()].iter_mut().enumerate() {
                        if mix(seed ^ i as u64) & 1 == 1 {
                            *b = 0xFF;
                        }
                    }
                }
            }
            self.persist(r);
            if self.dead {
                return Err(SimError::PowerLost);
            }
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), SimError> {
        if !(offset as usize).is_multiple_of(DWORD) || !bytes.len().is_multiple_of(DWORD) {
            return Err(SimError::NotAligned);
        }
        self.range(offset, bytes.len())?;
        for (k, unit) in bytes.chunks(DWORD).enumerate() {
            let r = self.range(offset + (k * DWORD) as u32, DWORD)?;
            if self.mem[r.clone()].iter().any(|&b| b != 0xFF) {
                return Err(if self.dead { SimError::PowerLost } else { SimError::NotErased });
            }
            match self.next_op()? {
                None | Some(CutMode::After) => {
                    for (m, &b) in self.mem[r.clone()].iter_mut().zip(unit) {
                        *m &= b;
                    }
                }
                Some(CutMode::Before) => {}
                Some(CutMode::Torn(seed)) => {
                    // Clear only some of the bits the write would clear.
                    for (i, (m, &b)) in self.mem[r.clone()].iter_mut().zip(unit).enumerate() {
                        let keep = mix(seed ^ (i as u64) << 8) as u8;
                        *m &= b | keep;
                    }
                }
            }
            self.persist(r);
            if self.dead {
                return Err(SimError::PowerLost);
            }
        }
        Ok(())
    }
}
