//! Cost of the sample interrupt in CPU cycles, measured on the box with the
//! Cortex-M4 DWT cycle counter (`DWT_CYCCNT`, a free-running 32-bit counter
//! of core clock cycles that wraps every 2³² cycles, 25 s at 170 MHz).
//!
//! The firmware reads the counter at the start and at the end of the
//! sample interrupt's body and gives both readings to
//! [`IsrCycles::record`]; the USB status reports [`IsrCycles::last`],
//! [`IsrCycles::max`] and [`IsrCycles::mean`]
//! (`protocol::StatusCounters::isr_cycles_*`). The cost of one interrupt is
//! the wrapping difference of the two readings, so a counter wrap between
//! them does not matter (an interrupt body cannot last 2³² cycles).
//!
//! On the sample path: no division, no floating point, no allocation, no
//! panic (the mean window is a power of two, so the mean is a shift).

/// log2 of [`MEAN_WINDOW`].
pub const MEAN_WINDOW_LOG2: u32 = 10;
/// Interrupts per mean window: [`IsrCycles::mean`] is the mean of the last
/// complete window of this many recorded interrupts (1 024: 20 ms at
/// 51.2 kHz, 5 ms at 200 kHz, 102 ms at 10 kHz).
pub const MEAN_WINDOW: u32 = 1 << MEAN_WINDOW_LOG2;

/// Cycle statistics of the sample interrupt's body.
///
/// * [`last`](Self::last): the most recent interrupt.
/// * [`max`](Self::max): the largest since [`new`](Self::new) /
///   [`reset`](Self::reset) (on the box: since boot, so it includes the
///   first samples after boot and after every image switch, when the
///   caches are cold and the filter state is cleared).
/// * [`mean`](Self::mean): the mean of the last complete window of
///   [`MEAN_WINDOW`] interrupts, rounded to the nearest cycle (half up);
///   0 until the first window is complete.
///
/// All three are 0 while nothing was recorded, and stay 0 if the counter
/// does not run (both readings equal): 0 means "not measured".
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IsrCycles {
    /// Sum of the current (incomplete) window; at most
    /// `MEAN_WINDOW · u32::MAX` < 2⁴², so it never overflows.
    window_sum: u64,
    /// Interrupts in the current window (`< MEAN_WINDOW`).
    window_len: u32,
    last: u32,
    max: u32,
    mean: u32,
}

impl IsrCycles {
    /// Nothing recorded yet: every figure 0.
    pub const fn new() -> Self {
        IsrCycles { window_sum: 0, window_len: 0, last: 0, max: 0, mean: 0 }
    }

    /// Record one interrupt from the cycle counter at the start and at the
    /// end of its body (wrapping difference: the counter may wrap between
    /// the two readings).
    #[inline]
    pub fn record(&mut self, start: u32, end: u32) {
        let cycles = end.wrapping_sub(start);
        self.last = cycles;
        if cycles > self.max {
            self.max = cycles;
        }
        // window_len < MEAN_WINDOW here, so the sum stays below 2⁴² and the
        // length below MEAN_WINDOW + 1: no overflow.
        self.window_sum = self.window_sum.wrapping_add(u64::from(cycles));
        self.window_len = self.window_len.wrapping_add(1);
        if self.window_len >= MEAN_WINDOW {
            // Round half up; ≤ (2¹⁰·(2³²−1) + 2⁹) >> 10 = 2³² − 1, fits.
            let half = 1u64 << (MEAN_WINDOW_LOG2 - 1);
            self.mean = u32::try_from((self.window_sum + half) >> MEAN_WINDOW_LOG2).unwrap_or(u32::MAX);
            self.window_sum = 0;
            self.window_len = 0;
        }
    }

    /// Cycles of the most recent interrupt (0 = none recorded).
    pub fn last(&self) -> u32 {
        self.last
    }

    /// Most cycles of any interrupt since [`new`](Self::new) /
    /// [`reset`](Self::reset) (0 = none recorded).
    pub fn max(&self) -> u32 {
        self.max
    }

    /// Mean cycles over the last complete window of [`MEAN_WINDOW`]
    /// interrupts (0 = no window complete yet).
    pub fn mean(&self) -> u32 {
        self.mean
    }

    /// Forget everything (all figures back to 0, a new window starts).
    pub fn reset(&mut self) {
        *self = Self::new();
    }
}
