//! Pure helpers of the box firmware's hardware shell (DESIGN.md,
//! "Firmware"): the arithmetic the interrupt and boot code need, kept here so
//! host tests exercise it and the firmware binary holds only register access.
//!
//! * [`timer_divider`], [`compare_offset_ticks`]: prescaler/auto-reload of the
//!   sample timer for a requested rate, the rate actually obtained and its
//!   error, and where in the period the sample interrupt fires.
//! * [`dma_write_index`], [`RingCursor`]: bookkeeping of the circular DMA
//!   rings the ADCs write into: which sample is the newest complete one and
//!   how many were skipped (overruns), from the DMA channels' remaining-count
//!   registers alone.
//! * [`choose_image`], [`box_sample_rate`]: which flash slot's coefficient
//!   image the box uses, and the sample rate it runs at.
//!
//! Nothing here touches hardware, allocates or panics.

use crate::image::{CoeffImage, ImageError};
use crate::sample::Mode;

/// Clock of the sample timer (TIM2 on APB1, prescaler 1) with the box's
/// 170 MHz system clock.
pub const BOX_TIMER_CLOCK_HZ: u32 = 170_000_000;

/// Sample rate of the box when no image can run (bypass), Hz.
pub const DEFAULT_FS_HZ: u32 = 51_200;

/// Largest auto-reload value of a 16-bit timer.
pub const ARR_MAX_16: u32 = 0xFFFF;
/// Largest auto-reload value of a 32-bit timer (TIM2, TIM5).
pub const ARR_MAX_32: u32 = 0xFFFF_FFFF;

/// Prescaler and auto-reload of a timer that overflows at the sample rate.
///
/// One period lasts `(psc + 1) · (arr + 1)` timer-clock ticks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TimerDivider {
    /// Prescaler register value (`TIMx_PSC`): the counter runs at clk / (psc + 1).
    pub psc: u16,
    /// Auto-reload register value (`TIMx_ARR`): the counter wraps after arr + 1 counts.
    pub arr: u32,
}

impl TimerDivider {
    /// Timer-clock ticks per period, `(psc + 1) · (arr + 1)`.
    pub fn ticks_per_period(&self) -> u64 {
        (u64::from(self.psc) + 1) * (u64::from(self.arr) + 1)
    }

    /// Sample rate actually obtained, in millihertz (exact integer rounding
    /// of `clk / ticks_per_period`).
    pub fn actual_fs_millihz(&self, clk_hz: u32) -> u64 {
        let t = self.ticks_per_period();
        (u64::from(clk_hz) * 1000 + t / 2) / t
    }

    /// Relative error of the obtained rate against `fs_hz`, in parts per
    /// million, rounded to the nearest integer (positive = faster).
    pub fn error_ppm(&self, clk_hz: u32, fs_hz: u32) -> i64 {
        if fs_hz == 0 {
            return 0;
        }
        // (clk / t - fs) / fs · 1e6 = (clk - fs·t) · 1e6 / (fs·t)
        let t = self.ticks_per_period() as i128;
        let num = (i128::from(clk_hz) - i128::from(fs_hz) * t) * 1_000_000;
        let den = i128::from(fs_hz) * t;
        let q = if num >= 0 {
            (num + den / 2) / den
        } else {
            (num - den / 2) / den
        };
        q as i64
    }
}

/// Prescaler and auto-reload for a timer clocked at `clk_hz` to overflow at
/// (as close as possible to) `fs_hz`; `max_arr` is [`ARR_MAX_16`] or
/// [`ARR_MAX_32`].
///
/// The total division `clk / fs` is rounded to the nearest integer; the
/// prescaler is the smallest that lets the auto-reload fit (0 whenever
/// possible, for the finest rate resolution). `None` if `fs_hz` is 0, above
/// `clk_hz / 2` or too low for a 16-bit prescaler.
pub fn timer_divider(clk_hz: u32, fs_hz: u32, max_arr: u32) -> Option<TimerDivider> {
    if fs_hz == 0 || clk_hz == 0 || max_arr == 0 {
        return None;
    }
    let clk = u64::from(clk_hz);
    let fs = u64::from(fs_hz);
    let total = (clk + fs / 2) / fs;
    if total < 2 {
        return None;
    }
    let arr_span = u64::from(max_arr) + 1;
    let psc_plus_1 = total.div_ceil(arr_span);
    if psc_plus_1 > 1 << 16 {
        return None;
    }
    let step = fs * psc_plus_1;
    let arr_plus_1 = ((clk + step / 2) / step).clamp(2, arr_span);
    Some(TimerDivider {
        psc: (psc_plus_1 - 1) as u16,
        arr: (arr_plus_1 - 1) as u32,
    })
}

/// Counter value at which the sample interrupt fires (`TIMx_CCR1`): `delay_ns`
/// after the update event that triggered the conversions (rounded up to the
/// next counter tick), so the three conversions and their DMA transfers are
/// complete when the interrupt reads the rings.
///
/// `None` if the delay does not leave at least half of the period for the
/// sample path (the rate is too high for this conversion time).
pub fn compare_offset_ticks(div: &TimerDivider, clk_hz: u32, delay_ns: u32) -> Option<u32> {
    let counter_hz = u64::from(clk_hz) / (u64::from(div.psc) + 1);
    let ticks = (u64::from(delay_ns) * counter_hz)
        .div_ceil(1_000_000_000)
        .max(1);
    let period = u64::from(div.arr) + 1;
    if ticks * 2 > period {
        return None;
    }
    Some(ticks as u32)
}

/// Index a circular DMA channel writes next, from its remaining-transfers
/// register (`DMA_CNDTRx`, counts down from `len` to 1, then reloads `len`).
///
/// `None` for a value a running circular channel of length `len` cannot
/// show (0, above `len`, or `len == 0`): the DMA is stopped or misconfigured.
pub fn dma_write_index(ndtr: u16, len: u16) -> Option<u16> {
    if len == 0 || ndtr == 0 || ndtr > len {
        return None;
    }
    Some((len - ndtr) % len)
}

/// What arrived in the rings since the previous sample interrupt.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RingStep {
    /// Complete samples (all channels) not yet consumed. 1 in steady state;
    /// 0 if the conversions were not finished when the interrupt ran.
    pub available: u16,
    /// Ring index of the newest complete sample (meaningful if `available > 0`).
    pub newest: u16,
}

impl RingStep {
    /// Samples that arrived but will never be processed (all but the newest):
    /// missed deadlines for [`SampleState::note_overruns`](crate::sample::SampleState::note_overruns).
    pub fn missed(&self) -> u32 {
        u32::from(self.available.saturating_sub(1))
    }
}

/// Read position in a set of equally long circular DMA rings written in
/// lockstep (one per ADC, all triggered by the same timer event).
///
/// Counting is modulo the ring length: if the interrupt is held off for a
/// whole ring (`len` samples) or more, whole laps are invisible, so the ring
/// must be longer than the longest interrupt blackout at the highest rate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RingCursor {
    next: u16,
    len: u16,
}

impl RingCursor {
    /// A cursor at index 0 of rings of `len` entries (the DMA channels must
    /// have been started with `CNDTR = len`, i.e. write index 0).
    pub const fn new(len: u16) -> Self {
        RingCursor { next: 0, len }
    }

    /// Index of the next sample the cursor expects.
    pub fn next(&self) -> u16 {
        self.next
    }

    /// Ring length.
    pub fn len(&self) -> u16 {
        self.len
    }

    /// Whether the rings have no entries (an unusable cursor).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Advance over every sample complete in *all* rings, given each DMA
    /// channel's `CNDTR`. A channel lagging behind the others limits what
    /// counts as complete. Returns `None` (and does not move) if any count is
    /// impossible for a running channel or `ndtrs` is empty.
    pub fn advance(&mut self, ndtrs: &[u16]) -> Option<RingStep> {
        if ndtrs.is_empty() || self.len == 0 {
            return None;
        }
        let len = u32::from(self.len);
        let next = u32::from(self.next);
        let mut available = u32::MAX;
        for &n in ndtrs {
            let w = u32::from(dma_write_index(n, self.len)?);
            available = available.min((w + len - next) % len);
        }
        // All values below are < len <= u16::MAX, so the casts are lossless.
        let newest = (next + len + available - 1) % len;
        self.next = ((next + available) % len) as u16;
        Some(RingStep {
            available: available as u16,
            newest: newest as u16,
        })
    }
}

/// A coefficient-image flash slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Slot {
    /// Slot A (first 8 KiB of the last 16 KiB of flash).
    A,
    /// Slot B (last 8 KiB of flash).
    B,
}

/// The image the box loads and where it came from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlotChoice {
    /// Input to [`select_mode`](crate::sample::select_mode): `None` if both
    /// slots are empty, the first valid image, or the error to report.
    pub loaded: Option<Result<CoeffImage, ImageError>>,
    /// Slot the image (or the reported error) belongs to.
    pub slot: Option<Slot>,
}

/// Pick the coefficient image from the parse results of slots A and B
/// (`CoeffImage::parse_prefix` on each slot's bytes).
///
/// Interim policy until the sequence-numbered store exists: a valid A wins,
/// then a valid B. A slot that is not an image at all ([`ImageError::BadMagic`],
/// e.g. erased flash) counts as empty; if both are empty the result is `None`
/// (bypass, "no image"). Otherwise the error of the first non-empty slot is
/// reported (bypass, "invalid image").
pub fn choose_image(
    a: Result<CoeffImage, ImageError>,
    b: Result<CoeffImage, ImageError>,
) -> SlotChoice {
    match (a, b) {
        (Ok(img), _) => SlotChoice {
            loaded: Some(Ok(img)),
            slot: Some(Slot::A),
        },
        (_, Ok(img)) => SlotChoice {
            loaded: Some(Ok(img)),
            slot: Some(Slot::B),
        },
        (Err(ImageError::BadMagic), Err(ImageError::BadMagic)) => SlotChoice {
            loaded: None,
            slot: None,
        },
        (Err(ImageError::BadMagic), Err(e)) => SlotChoice {
            loaded: Some(Err(e)),
            slot: Some(Slot::B),
        },
        (Err(e), _) => SlotChoice {
            loaded: Some(Err(e)),
            slot: Some(Slot::A),
        },
    }
}

/// The sample rate the box runs at in `mode`: the image's rate when
/// compensating, [`DEFAULT_FS_HZ`] in bypass.
pub fn box_sample_rate(mode: &Mode<'_>) -> u32 {
    match mode {
        Mode::Compensate(img) => img.fs_hz,
        Mode::Bypass(_) => DEFAULT_FS_HZ,
    }
}
