//! The sample interrupt's cycle statistics (src/cycles.rs): wrapping
//! differences of a free-running 32-bit counter, last / max / window mean,
//! against known sequences and an independent reference.

use dynocomp_core::cycles::{IsrCycles, MEAN_WINDOW, MEAN_WINDOW_LOG2};
use proptest::prelude::*;

/// Record `costs` as interrupts whose bodies start `period` cycles apart on
/// a counter that starts at `t0` (wrapping like CYCCNT).
fn run(c: &mut IsrCycles, t0: u32, period: u32, costs: impl IntoIterator<Item = u32>) -> u32 {
    let mut t = t0;
    for cost in costs {
        c.record(t, t.wrapping_add(cost));
        t = t.wrapping_add(period);
    }
    t
}

#[test]
fn nothing_recorded_reads_zero_not_measured() {
    let c = IsrCycles::new();
    assert_eq!((c.last(), c.max(), c.mean()), (0, 0, 0));
    assert_eq!(c, IsrCycles::default());
    assert_eq!(MEAN_WINDOW, 1 << MEAN_WINDOW_LOG2);
    assert_eq!(MEAN_WINDOW, 1024);
}

#[test]
fn a_counter_wrap_inside_one_interrupt_is_its_true_cost() {
    let mut c = IsrCycles::new();
    // Starts 100 cycles before the wrap, ends 1 234 after it.
    c.record(u32::MAX - 99, 1_234);
    assert_eq!(c.last(), 1_334);
    assert_eq!(c.max(), 1_334);
    // Exactly at the wrap.
    c.record(u32::MAX, 0);
    assert_eq!(c.last(), 1);
    assert_eq!(c.max(), 1_334);
    c.record(0xFFFF_F000, 0x0000_0FFF);
    assert_eq!(c.last(), 0x1FFF);
    assert_eq!(c.max(), 0x1FFF);
}

#[test]
fn a_stopped_counter_reads_zero_not_measured() {
    // DWT not enabled: CYCCNT stays put, both readings are equal.
    let mut c = IsrCycles::new();
    for _ in 0..3 * MEAN_WINDOW {
        c.record(0, 0);
    }
    assert_eq!((c.last(), c.max(), c.mean()), (0, 0, 0));
}

#[test]
fn the_mean_is_published_per_complete_window_and_rounded() {
    let mut c = IsrCycles::new();
    // 1 000 and 2 001 alternating, across the counter's wrap (170 MHz at
    // 51.2 kHz: 3 320 cycles per period; start 10 periods before the wrap).
    let period = 3_320;
    let t0 = 0u32.wrapping_sub(10 * period);
    let costs = |n: u32| (0..n).map(|k| if k % 2 == 0 { 1_000 } else { 2_001 });
    let t = run(&mut c, t0, period, costs(MEAN_WINDOW - 1));
    assert_eq!(c.mean(), 0, "no window complete yet");
    assert_eq!((c.last(), c.max()), (1_000, 2_001));
    run(&mut c, t, period, [2_001]);
    // (512 · 1 000 + 512 · 2 001) / 1 024 = 1 500.5 → 1 501 (half up).
    assert_eq!(c.mean(), 1_501);
    assert_eq!(c.last(), 2_001);

    // The next window: the mean stays until it is complete, then it is
    // that window's alone.
    let t = run(&mut c, t + period, period, (0..MEAN_WINDOW - 1).map(|_| 900));
    assert_eq!(c.mean(), 1_501);
    run(&mut c, t, period, [900 + 1_023]);
    // (1 023 · 900 + 1 923) / 1 024 = 900.999 → 901.
    assert_eq!(c.mean(), 901);
    assert_eq!(c.last(), 1_923);
    // Max since new(): the first window's 2 001 is still the largest.
    assert_eq!(c.max(), 2_001);
}

#[test]
fn the_mean_rounds_down_below_one_half() {
    let mut c = IsrCycles::new();
    // 511 extra cycles over the window: mean 100 + 511/1024 = 100.499 → 100.
    run(&mut c, 5, 4_000, (0..MEAN_WINDOW).map(|k| if k == 0 { 100 + 511 } else { 100 }));
    assert_eq!(c.mean(), 100);
    // 512 extra: 100.5 → 101.
    run(&mut c, 5, 4_000, (0..MEAN_WINDOW).map(|k| if k == 7 { 100 + 512 } else { 100 }));
    assert_eq!(c.mean(), 101);
}

#[test]
fn max_keeps_a_single_spike_and_reset_forgets_everything() {
    let mut c = IsrCycles::new();
    // A slow first sample (image switch: cold cache, state cleared), then
    // steady samples.
    run(&mut c, 123_456, 3_320, std::iter::once(2_900).chain((0..2 * MEAN_WINDOW).map(|_| 1_200)));
    assert_eq!(c.max(), 2_900);
    assert_eq!(c.last(), 1_200);
    // The second window holds only steady samples.
    assert_eq!(c.mean(), 1_200);
    c.reset();
    assert_eq!((c.last(), c.max(), c.mean()), (0, 0, 0));
    // Every new largest cost is the max, however small the step.
    for k in 1..=5 {
        c.record(u32::MAX, k - 1);
        assert_eq!((c.last(), c.max()), (k, k));
    }
    c.record(7, 7);
    assert_eq!((c.last(), c.max()), (0, 5));
    c.reset();
    // After a reset the window starts again from its first interrupt.
    run(&mut c, 0, 3_320, (0..MEAN_WINDOW - 1).map(|_| 700));
    assert_eq!((c.last(), c.max(), c.mean()), (700, 700, 0));
    run(&mut c, 0, 3_320, [700]);
    assert_eq!(c.mean(), 700);
}

#[test]
fn extreme_costs_neither_overflow_nor_panic() {
    let mut c = IsrCycles::new();
    // The largest difference the counter can show, a whole window of it.
    for _ in 0..MEAN_WINDOW {
        c.record(1, 0);
    }
    assert_eq!((c.last(), c.max(), c.mean()), (u32::MAX, u32::MAX, u32::MAX));
    // And the window after it is independent.
    for _ in 0..MEAN_WINDOW {
        c.record(0, 1);
    }
    assert_eq!((c.last(), c.max(), c.mean()), (1, u32::MAX, 1));
}

proptest! {
    /// Against an independent reference: any start of the counter, any costs.
    #[test]
    fn matches_a_reference_model(
        t0 in any::<u32>(),
        period in 0u32..1_000_000,
        costs in proptest::collection::vec(prop_oneof![0u32..20_000, any::<u32>()], 0..3_000),
    ) {
        let mut c = IsrCycles::new();
        run(&mut c, t0, period, costs.iter().copied());
        let last = costs.last().copied().unwrap_or(0);
        let max = costs.iter().copied().max().unwrap_or(0);
        let n = MEAN_WINDOW as usize;
        let complete = costs.len() / n;
        let mean = if complete == 0 {
            0
        } else {
            let w = &costs[(complete - 1) * n..complete * n];
            let sum: u128 = w.iter().map(|&x| u128::from(x)).sum();
            // Nearest, half up.
            ((2 * sum + n as u128) / (2 * n as u128)) as u32
        };
        prop_assert_eq!((c.last(), c.max(), c.mean()), (last, max, mean));
    }
}
