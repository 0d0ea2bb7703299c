//! Helpers of the emulated-target programs: semihosting file I/O with the
//! host and the instruction counter (SysTick under `-icount shift=0`).
//!
//! Runs only under `qemu-system-arm -M mps2-an386 -semihosting-config
//! enable=on,target=native`: file names are relative to QEMU's working
//! directory.
#![no_std]

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_semihosting::{debug, hprintln, syscall};

/// Semihosting `SYS_OPEN` modes (ARM semihosting spec, table 6.1).
const MODE_RB: usize = 1;
const MODE_WB: usize = 5;

/// Stop the emulator with a failure status after printing `msg`.
pub fn fail(msg: &str) -> ! {
    hprintln!("dynocomp-qemu: {}", msg);
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}

/// Stop the emulator with status 0.
pub fn success() -> ! {
    debug::exit(debug::EXIT_SUCCESS);
    #[allow(clippy::empty_loop)]
    loop {}
}

/// An open host file (semihosting handle).
pub struct HostFile(usize);

impl HostFile {
    /// Open `name` (NUL-terminated, e.g. `b"input.bin\0"`) for binary reading.
    pub fn open_read(name: &[u8]) -> HostFile {
        Self::open(name, MODE_RB)
    }

    /// Create/truncate `name` (NUL-terminated) for binary writing.
    pub fn create(name: &[u8]) -> HostFile {
        Self::open(name, MODE_WB)
    }

    fn open(name: &[u8], mode: usize) -> HostFile {
        if name.last() != Some(&0) {
            fail("file name must be NUL-terminated");
        }
        // SAFETY: SYS_OPEN reads `len` bytes of the NUL-terminated name.
        let h = unsafe { syscall!(OPEN, name.as_ptr(), mode, name.len() - 1) };
        if h == usize::MAX {
            fail("cannot open a host file (is QEMU's working directory the test directory?)");
        }
        HostFile(h)
    }

    /// Read up to `buf.len()` bytes; returns how many were read (0 at end).
    pub fn read(&mut self, buf: &mut [u8]) -> usize {
        // SAFETY: SYS_READ writes at most `buf.len()` bytes into `buf`; it
        // returns the number of bytes NOT read.
        let not_read = unsafe { syscall!(READ, self.0, buf.as_mut_ptr(), buf.len()) };
        buf.len().saturating_sub(not_read)
    }

    /// Read until `buf` is full or the file ends; returns the byte count.
    pub fn read_full(&mut self, buf: &mut [u8]) -> usize {
        let mut n = 0;
        while n < buf.len() {
            let got = self.read(&mut buf[n..]);
            if got == 0 {
                break;
            }
            n += got;
        }
        n
    }

    /// Write all of `buf`.
    pub fn write_all(&mut self, buf: &[u8]) {
        // SAFETY: SYS_WRITE reads `buf.len()` bytes from `buf`; it returns the
        // number of bytes NOT written.
        let not_written = unsafe { syscall!(WRITE, self.0, buf.as_ptr(), buf.len()) };
        if not_written != 0 {
            fail("short write to a host file");
        }
    }
}

impl Drop for HostFile {
    fn drop(&mut self) {
        // SAFETY: closes a handle this value owns.
        unsafe { syscall!(CLOSE, self.0) };
    }
}

/// SysTick as a free-running 24-bit down-counter on the core clock.
///
/// On QEMU's mps2-an386 the SysTick core clock is the board's 25 MHz
/// SYSCLK, i.e. one tick every 40 ns of *virtual* time; under
/// `-icount shift=0` virtual time advances exactly 1 ns per executed guest
/// instruction, so one tick = 40 instructions (checked by the calibration in
/// `icount`).
pub struct Ticks {
    syst: SYST,
}

/// Reload value: the full 24-bit range.
const SYST_RELOAD: u32 = 0x00FF_FFFF;

impl Ticks {
    /// Start SysTick free-running from its reload value, no interrupt.
    pub fn start(mut syst: SYST) -> Ticks {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(SYST_RELOAD);
        syst.clear_current();
        syst.disable_interrupt();
        syst.enable_counter();
        Ticks { syst }
    }

    /// Current counter value (counts down).
    #[inline(always)]
    pub fn now(&self) -> u32 {
        let _ = &self.syst;
        SYST::get_current()
    }

    /// Ticks elapsed from `start` to `end` (one wrap at most; callers keep
    /// measured regions under 2^24 ticks = 671 ms virtual).
    pub fn elapsed(start: u32, end: u32) -> u32 {
        start.wrapping_sub(end) & SYST_RELOAD
    }
}

/// Little-endian f32 of 4 bytes.
pub fn f32_le(b: &[u8]) -> f32 {
    let mut a = [0u8; 4];
    a.copy_from_slice(&b[..4]);
    f32::from_le_bytes(a)
}

/// A panic stops the emulator with a failure status (never hangs the test).
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("dynocomp-qemu: panic: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}
