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
//! * [`box_sample_rate`]: the sample rate the box runs at. (Which flash
//!   slot's image it uses is the coefficient store's boot rule,
//!   [`crate::store`].)
//! * [`adc_oversampling`]: the ADCs' hardware oversampling ratio and the
//!   sample interrupt's delay for a sample rate (RM0440 timing arithmetic).
//! * [`AutoZero`], [`apply_adc_offsets`]: offset auto-zero on command.
//! * [`led_state`], [`led_on`]: the status LED's state and blink patterns.
//! * [`SamplePath`]: the sample interrupt's decisions (mode, filter resets,
//!   auto-zero) around [`process_sample`].
//!
//! Nothing here touches hardware, allocates or panics.

use crate::image::BoxImage;
use crate::sample::{process_sample, select_stored_mode, BypassReason, Mode, SampleFlags, SampleState};

/// The image the sample path runs, with its mode decided once, when it
/// became active (boot, upload, image switch), not on every sample.
///
/// Every way to make one runs the image checks of
/// [`select_stored_mode`] (offline-only, supported sample rate, the CPU
/// budget of [`crate::budget::check_load`]) and keeps their verdict next to
/// the image; the fields are private and the one way to change the image
/// afterwards ([`apply_adc_offsets`](Self::apply_adc_offsets)) changes
/// nothing the checks read. So an image the checks refuse can never be run through an
/// `ActiveImage`, whoever built it, and the sample interrupt pays for a
/// stored verdict and the user's bypass switch instead of the checks (the
/// budget check alone, with its 64-bit division, was ≈ 500 instructions per
/// sample for a three-axis image: BENCHMARKS.md, "Cost model of the
/// sample interrupt").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ActiveImage {
    stored: Result<BoxImage, BypassReason>,
    /// `Some(reason)` when the checks refuse the image (or there is none).
    refused: Option<BypassReason>,
}

impl ActiveImage {
    /// Check `stored` (the coefficient store's result: a verified image or
    /// why there is none) and keep the verdict.
    pub fn new(stored: Result<BoxImage, BypassReason>) -> Self {
        let refused = match select_stored_mode(&stored, false) {
            Mode::Compensate(_) => None,
            Mode::Bypass(r) => Some(r),
        };
        ActiveImage { stored, refused }
    }

    /// The image (or why there is none), as given.
    pub fn stored(&self) -> &Result<BoxImage, BypassReason> {
        &self.stored
    }

    /// The image's own verdict: `None` if it may run, else why not (the
    /// user's bypass aside).
    pub fn refused(&self) -> Option<BypassReason> {
        self.refused
    }

    /// The sample path's mode: the stored verdict, then the user's bypass
    /// switch (the same result as [`select_stored_mode`], without
    /// re-running the checks).
    #[inline(always)]
    pub fn mode(&self, user_bypass: bool) -> Mode<'_> {
        match (&self.stored, self.refused) {
            (_, Some(r)) => Mode::Bypass(r),
            (Ok(_), None) if user_bypass => Mode::Bypass(BypassReason::User),
            (Ok(img), None) => Mode::Compensate(img),
            // Unreachable: `new` refuses every `Err`; kept as bypass.
            (Err(r), None) => Mode::Bypass(*r),
        }
    }

    /// [`apply_adc_offsets`] on the image (if any); returns the mask of
    /// axes changed. The verdict stays: it changes only the ADC offsets,
    /// which none of the checks reads (offline-only flag, sample rate and
    /// the cost model's filter shapes), and it runs in the sample
    /// interrupt, where deciding again would cost the budget check's
    /// ≈ 500 instructions in that one sample (and copying the image).
    #[inline(always)]
    pub fn apply_adc_offsets(&mut self, offsets: [f32; crate::AXES]) -> u8 {
        match self.stored.as_mut() {
            Ok(img) => apply_adc_offsets(img, offsets),
            Err(_) => 0,
        }
    }
}

/// The box's CPU core clock (SYSCLK = HCLK, 170 MHz from the PLL): the
/// unit of the sample interrupt's cycle counts (DWT CYCCNT,
/// `protocol::Status::core_clock_hz`).
pub const BOX_CORE_CLOCK_HZ: u32 = 170_000_000;

/// Clock of the sample timer (TIM2 on APB1, prescaler 1) with the box's
/// 170 MHz system clock.
pub const BOX_TIMER_CLOCK_HZ: u32 = BOX_CORE_CLOCK_HZ;

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
        let q = if num >= 0 { (num + den / 2) / den } else { (num - den / 2) / den };
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
    Some(TimerDivider { psc: (psc_plus_1 - 1) as u16, arr: (arr_plus_1 - 1) as u32 })
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
    let ticks = (u64::from(delay_ns) * counter_hz).div_ceil(1_000_000_000).max(1);
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
    // 1 ≤ ndtr ≤ len, so len − ndtr < len: already the index (no division
    // on the sample path).
    Some(len - ndtr)
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
        // `next < len` always (set below), and every write index is < len,
        // so each sum below is < 2·len and "modulo len" is one conditional
        // subtraction: no division on the sample path (a `udiv` is 2-12
        // cycles on the Cortex-M4, and this ran four of them per sample).
        let wrap = |x: u32| if x >= len { x - len } else { x };
        let next = u32::from(self.next);
        let mut available = u32::MAX;
        for &n in ndtrs {
            let w = u32::from(dma_write_index(n, self.len)?);
            available = available.min(wrap(w + len - next));
        }
        // All values below are < len <= u16::MAX, so the casts are lossless.
        let next_after = wrap(next + available);
        let newest = if next_after == 0 { len - 1 } else { next_after - 1 };
        self.next = next_after as u16;
        Some(RingStep { available: available as u16, newest: newest as u16 })
    }
}

/// A coefficient-image flash slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Slot {
    /// Slot A (first 8 KiB of the last 16 KiB of flash).
    A,
    /// Slot B (last 8 KiB of flash).
    B,
}

impl core::fmt::Display for Slot {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Slot::A => "A",
            Slot::B => "B",
        })
    }
}

/// The sample rate the box runs at in `mode`: the image's rate when
/// compensating, [`DEFAULT_FS_HZ`] in bypass.
pub fn box_sample_rate(mode: &Mode<'_>) -> u32 {
    match mode {
        Mode::Compensate(img) => img.fs_hz(),
        Mode::Bypass(_) => DEFAULT_FS_HZ,
    }
}

// ------------------------------------------------------ ADC oversampling --

/// ADC kernel clock of the box: synchronous HCLK/4 (`ADCx_CCR.CKMODE = 11`)
/// at 170 MHz.
pub const BOX_ADC_CLOCK_HZ: u32 = 42_500_000;

/// Sampling time of the box's ADC channels (`ADC_SMPRx = 24.5 cycles`), in
/// half ADC clock cycles.
pub const BOX_SAMPLE_HALF_CYCLES: u32 = 49;

/// Successive-approximation time of a 12-bit conversion, 12.5 ADC clock
/// cycles (RM0440 §21.4.16, "Timing": t_CONV = t_SMPL + t_SAR, t_SAR = 12.5
/// cycles at 12 bit), in half cycles.
pub const SAR_12BIT_HALF_CYCLES: u32 = 25;

/// Largest hardware oversampling ratio (RM0440 §21.4.30, `ADC_CFGR2.OVSR` =
/// 7 → 256×).
pub const MAX_OVERSAMPLING_RATIO: u16 = 256;

/// The oversampled conversions of one trigger may take at most this fraction
/// (1/`OVERSAMPLING_WINDOW_DIVISOR`) of the sample period. It bounds the extra
/// delay of the averaged sample (its centroid lies half a window after the
/// trigger) to 1/8 of a period and leaves the rest of the period to the
/// sample interrupt.
pub const OVERSAMPLING_WINDOW_DIVISOR: u64 = 4;

/// Time from the end of the last conversion to the sample interrupt: trigger
/// latency (a few ADC cycles), the DMA transfer and margin. With one
/// conversion (0.87 µs) it gives the 2.07 µs interrupt offset.
pub const ADC_DONE_MARGIN_NS: u32 = 1_200;

/// Hardware oversampling of the sample path's ADCs (RM0440 §21.4.30,
/// "Oversampler"): on each trigger the ADC makes `ratio` conversions back to
/// back (`ADC_CFGR2.TROVS = 0`), sums them and shifts the sum right by
/// `shift` bits, so the 12-bit result is their mean (truncated). It lowers
/// the white ADC noise by √ratio at the same 12-bit code scale, so the
/// images' ADC-code → N scaling is unchanged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Oversampling {
    /// Conversions averaged per sample (1 = oversampling off, else 2..=256).
    pub ratio: u16,
    /// `ADC_CFGR2.OVSR` (ratio = 2^(ovsr + 1)); meaningless when `ratio == 1`.
    pub ovsr: u8,
    /// `ADC_CFGR2.OVSS`: right shift of the sum, log2(ratio).
    pub shift: u8,
    /// Duration of the `ratio` conversions after the trigger (ns, rounded up).
    pub window_ns: u32,
    /// Delay from the trigger to the sample interrupt (ns): window + margin.
    pub irq_delay_ns: u32,
}

impl Oversampling {
    /// Whether `ADC_CFGR2.ROVSE` must be set.
    pub fn enabled(&self) -> bool {
        self.ratio > 1
    }

    /// Delay of the averaged sample against the trigger instant (ns): the
    /// centroid of the conversions' sampling instants, (ratio − 1)/2 conversion
    /// times. A pure delay the compensator does not know about (phase lag
    /// 360° · f · delay).
    pub fn centroid_delay_ns(&self) -> u32 {
        if self.ratio <= 1 {
            return 0;
        }
        let per = u64::from(self.window_ns) / u64::from(self.ratio);
        (per * (u64::from(self.ratio) - 1) / 2) as u32
    }
}

/// Hardware oversampling for sample rate `fs_hz`: the largest power-of-two
/// ratio whose conversions (`ratio · (t_SMPL + t_SAR)` at `adc_clk_hz`, with
/// `sample_half_cycles` = t_SMPL in half cycles and the 12-bit t_SAR) fit in
/// 1/[`OVERSAMPLING_WINDOW_DIVISOR`] of the period.
///
/// With the box's numbers (42.5 MHz, 24.5 + 12.5 cycles = 870.6 ns per
/// conversion): 10 kHz → 16×, 25.6 kHz → 8×, 51.2 kHz → 4×, 100 kHz → 2×,
/// 200 kHz → 1× (off).
///
/// `None` if `fs_hz` or the clock is 0, or if even one conversion plus
/// [`ADC_DONE_MARGIN_NS`] does not fit in half a period (the rate is too high
/// for the ADC).
pub fn adc_oversampling(fs_hz: u32, adc_clk_hz: u32, sample_half_cycles: u32) -> Option<Oversampling> {
    if fs_hz == 0 || adc_clk_hz == 0 {
        return None;
    }
    let half_cycles_per_conv = u64::from(sample_half_cycles) + u64::from(SAR_12BIT_HALF_CYCLES);
    // Window of `ratio` conversions in ns, rounded up:
    // ratio · half_cycles / (2 · f_adc) · 1e9.
    let window_ns = |ratio: u64| (ratio * half_cycles_per_conv * 1_000_000_000).div_ceil(2 * u64::from(adc_clk_hz));
    // Period rounded down: the budgets below err on the safe side.
    let period_ns = 1_000_000_000 / u64::from(fs_hz);
    let budget_ns = period_ns / OVERSAMPLING_WINDOW_DIVISOR;

    let mut ratio = 1u64;
    while ratio < u64::from(MAX_OVERSAMPLING_RATIO) && window_ns(ratio * 2) <= budget_ns {
        ratio *= 2;
    }
    let window = window_ns(ratio);
    let irq_delay = window + u64::from(ADC_DONE_MARGIN_NS);
    if irq_delay * 2 > period_ns {
        return None;
    }
    let shift = ratio.trailing_zeros() as u8;
    Some(Oversampling {
        ratio: ratio as u16,
        ovsr: shift.saturating_sub(1),
        shift,
        window_ns: window as u32,
        irq_delay_ns: irq_delay as u32,
    })
}

// ------------------------------------------------------ offset auto-zero --

/// Largest number of samples one auto-zero may average (the per-axis sums of
/// 12-bit codes stay below 2^32).
pub const AUTO_ZERO_MAX_SAMPLES: u32 = 65_535;

/// Why an auto-zero was refused or gave no result.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AutoZeroError {
    /// The sample count is 0 or above [`AUTO_ZERO_MAX_SAMPLES`].
    BadCount(u32),
    /// An auto-zero is already running.
    Busy,
    /// An axis hit an ADC rail during the averaging (axis index 0..3): the
    /// mean of a clipped signal is not its offset. Unload the dynamometer
    /// and check the charge amplifier range, then retry.
    Saturated(u8),
}

impl core::fmt::Display for AutoZeroError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            AutoZeroError::BadCount(n) => write!(f, "auto-zero over {n} samples: need 1..={AUTO_ZERO_MAX_SAMPLES}"),
            AutoZeroError::Busy => f.write_str("an auto-zero is already running"),
            AutoZeroError::Saturated(a) => write!(
                f,
                "axis {}: the ADC hit a rail during the auto-zero; unload the dynamometer, check the amplifier range, retry",
                crate::AXIS_NAMES.get(usize::from(a)).copied().unwrap_or("?")
            ),
        }
    }
}

/// Offset auto-zero of the ADC inputs (the charge amplifiers' drift): on
/// command, the mean raw code of each axis over `n` samples becomes the
/// axis's new `adc_offset_code` (the code of 0 N). The gain stays the
/// image's. A pure state machine the sample interrupt feeds one sample at a
/// time; the result is applied between two samples with
/// [`apply_adc_offsets`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AutoZero {
    target: u32,
    seen: u32,
    sum: [u32; crate::AXES],
    saturated: u8,
}

impl AutoZero {
    /// An idle auto-zero.
    pub const fn new() -> Self {
        AutoZero { target: 0, seen: 0, sum: [0; crate::AXES], saturated: 0 }
    }

    /// Whether an averaging is under way.
    #[inline(always)]
    pub fn is_running(&self) -> bool {
        self.target != 0
    }

    /// Start averaging the next `n` samples.
    pub fn start(&mut self, n: u32) -> Result<(), AutoZeroError> {
        if self.is_running() {
            return Err(AutoZeroError::Busy);
        }
        if n == 0 || n > AUTO_ZERO_MAX_SAMPLES {
            return Err(AutoZeroError::BadCount(n));
        }
        *self = AutoZero { target: n, ..AutoZero::new() };
        Ok(())
    }

    /// Feed one sample's raw ADC codes. Returns `None` while idle or
    /// averaging; after the `n`-th sample, the per-axis mean code (exact
    /// integer quotient plus remainder fraction) or the first saturated
    /// axis, and goes idle.
    pub fn feed(&mut self, codes: [u16; crate::AXES]) -> Option<Result<[f32; crate::AXES], AutoZeroError>> {
        if !self.is_running() {
            return None;
        }
        for (axis, (&code, sum)) in codes.iter().zip(self.sum.iter_mut()).enumerate() {
            if code == 0 || code >= crate::sample::ADC_MAX_CODE {
                self.saturated |= 1 << axis;
            }
            *sum = sum.saturating_add(u32::from(code));
        }
        self.seen += 1;
        if self.seen < self.target {
            return None;
        }
        let n = self.target;
        let done = *self;
        *self = AutoZero::new();
        if done.saturated != 0 {
            return Some(Err(AutoZeroError::Saturated(done.saturated.trailing_zeros() as u8)));
        }
        Some(Ok(done.sum.map(|s| (s / n) as f32 + (s % n) as f32 / n as f32)))
    }
}

/// Set the ADC offset (code of 0 N) of every axis present in `img` to
/// `offsets` (from [`AutoZero`]); returns the mask of axes changed (bit i =
/// axis i). Call between two samples and reset the filter state after it:
/// the offset step would otherwise ring through the compensator.
#[inline(always)]
pub fn apply_adc_offsets(img: &mut BoxImage, offsets: [f32; crate::AXES]) -> u8 {
    img.set_adc_offsets(offsets)
}

// ------------------------------------------------------------- status LED --

/// What the status LED shows, most urgent first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LedState {
    /// The sample path is not running, or it missed deadlines, found a late
    /// conversion or a stopped DMA, or reset a runaway filter state in the
    /// last second: fast blink (5 Hz).
    Fault,
    /// An ADC input hit a rail in the last second (overload): double blink.
    Saturated,
    /// Bypass (raw forces out): long on, short off.
    Bypass,
    /// Compensating: short blink once a second.
    Running,
}

/// Ticks (100 ms each) of one LED pattern.
pub const LED_PATTERN_TICKS: u32 = 10;

/// The LED state from the last second's events (fault beats saturation
/// beats mode).
pub fn led_state(started: bool, fault: bool, saturated: bool, compensating: bool) -> LedState {
    if !started || fault {
        LedState::Fault
    } else if saturated {
        LedState::Saturated
    } else if compensating {
        LedState::Running
    } else {
        LedState::Bypass
    }
}

/// LED level at tick `tick` (taken modulo [`LED_PATTERN_TICKS`]) of `state`'s
/// pattern.
pub fn led_on(state: LedState, tick: u32) -> bool {
    let t = tick % LED_PATTERN_TICKS;
    match state {
        LedState::Running => t == 0,
        LedState::Bypass => t != 0,
        LedState::Saturated => t == 0 || t == 2,
        LedState::Fault => t.is_multiple_of(2),
    }
}

// ------------------------------------------------------- image switch --

/// How the box starts running a newly committed image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ImageSwitch {
    /// Same sample rate: hand it to the sample interrupt, which switches
    /// between two samples (`handoff::ImageHandoff`), no reboot.
    AtSampleBoundary,
    /// Different sample rate: the sample timer and the ADC oversampling are
    /// set up at boot, so the box reboots and the boot scan runs the new
    /// (newest valid) slot at its rate.
    Reboot {
        /// Rate the sample path runs at now (Hz).
        from_hz: u32,
        /// Rate of the new image (Hz).
        to_hz: u32,
    },
}

/// How to switch from the sample path running at `running_fs_hz` to `new`.
pub fn image_switch(running_fs_hz: u32, new: &BoxImage) -> ImageSwitch {
    if new.fs_hz() == running_fs_hz {
        ImageSwitch::AtSampleBoundary
    } else {
        ImageSwitch::Reboot { from_hz: running_fs_hz, to_hz: new.fs_hz() }
    }
}

/// `major.minor.patch` of a version string such as `env!("CARGO_PKG_VERSION")`
/// (each part saturates at 255; a missing or non-numeric part reads as 0,
/// a pre-release suffix is ignored), for the status message.
pub const fn parse_version(v: &str) -> [u8; 3] {
    let b = v.as_bytes();
    let mut out = [0u8; 3];
    let mut part = 0;
    let mut i = 0;
    let mut acc: u32 = 0;
    while i < b.len() && part < 3 {
        let c = b[i];
        if c == b'.' {
            out[part] = if acc > 255 { 255 } else { acc as u8 };
            part += 1;
            acc = 0;
        } else if c.is_ascii_digit() {
            acc = acc * 10 + (c - b'0') as u32;
            if acc > 255 {
                acc = 256;
            }
        } else {
            break;
        }
        i += 1;
    }
    if part < 3 {
        out[part] = if acc > 255 { 255 } else { acc as u8 };
    }
    out
}

// ------------------------------------------------- the interrupt's logic --

/// What one sample did, besides updating the state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickOutput {
    /// DAC codes to write (x, y, z).
    pub dac: [u16; crate::AXES],
    /// Flags of the sample (saturation, runaway reset, bypass).
    pub flags: SampleFlags,
    /// Whether the compensator ran.
    pub compensating: bool,
    /// An auto-zero finished with this sample: the new offsets (codes,
    /// applied to the image's axes from this sample on, with the filters
    /// reset) or why it failed.
    pub auto_zero: Option<Result<[f32; crate::AXES], AutoZeroError>>,
}

/// Everything the sample interrupt decides, as a pure state machine
/// (DESIGN.md, "Firmware": the handler is a thin shell). The firmware's TIM2
/// handler reads the three ADC codes, calls [`tick`](Self::tick) with the
/// active image buffer, writes [`TickOutput::dac`] and publishes counters.
///
/// * Leaving bypass (user or image) and switching to a new image
///   ([`on_image_switch`](Self::on_image_switch)) start the filters from
///   rest: stale state means nothing to the new mode or image.
/// * An auto-zero ([`request_auto_zero`](Self::request_auto_zero)) averages
///   the raw codes of the next `n` samples, then sets the image's ADC offsets
///   between two samples and resets the filters.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SamplePath {
    /// Filter state and counters.
    pub state: SampleState,
    auto_zero: AutoZero,
    was_compensating: bool,
}

impl SamplePath {
    /// A sample path at rest, in bypass until the first compensated sample.
    pub fn new() -> Self {
        Self::default()
    }

    /// A new image is active from the next sample on.
    pub fn on_image_switch(&mut self) {
        self.state.reset_filters();
        self.auto_zero = AutoZero::new();
    }

    /// Start an offset auto-zero over the next `n` samples.
    pub fn request_auto_zero(&mut self, n: u32) -> Result<(), AutoZeroError> {
        self.auto_zero.start(n)
    }

    /// One sample: raw ADC `codes`, the active image `stored` (its ADC
    /// offsets change when an auto-zero completes), the user's bypass
    /// switch. The image's mode was decided when it became active
    /// ([`ActiveImage`]); here only the user's switch is read.
    #[inline(always)]
    pub fn tick(&mut self, codes: [u16; crate::AXES], stored: &mut ActiveImage, user_bypass: bool) -> TickOutput {
        // Idle (almost always): one test, no call of `feed` and no
        // returned `Option<Result<…>>` through memory.
        let auto_zero = if self.auto_zero.is_running() { self.auto_zero.feed(codes) } else { None };
        if let Some(Ok(offsets)) = auto_zero {
            if stored.stored().is_ok() {
                stored.apply_adc_offsets(offsets);
                self.state.reset_filters();
            }
        }
        let mode = stored.mode(user_bypass);
        let compensating = matches!(mode, Mode::Compensate(_));
        if compensating && !self.was_compensating {
            self.state.reset_filters();
        }
        self.was_compensating = compensating;
        let (dac, flags) = process_sample(codes, mode, &mut self.state);
        TickOutput { dac, flags, compensating, auto_zero }
    }
}
