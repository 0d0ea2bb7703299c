//! Host tests of the firmware shell's pure helpers (`dynocomp_core::shell`):
//! sample-timer divider, DMA ring bookkeeping (overrun counting), the sample
//! rate the box runs at, and the other shell helpers.

mod common;
use common::image_with;
use dynocomp_core::kernel::AxisFilter;
use dynocomp_core::sample::{select_mode, BypassReason, Mode, SampleState, BOX_FS_RANGE_HZ};
use dynocomp_core::shell::*;
use proptest::prelude::*;

// ---------------------------------------------------------------- timer --

#[test]
fn default_rate_on_the_170_mhz_timer() {
    let d = timer_divider(BOX_TIMER_CLOCK_HZ, 51_200, ARR_MAX_32).unwrap();
    // 170e6 / 51200 = 3320.3125 -> 3320 ticks.
    assert_eq!(d, TimerDivider { psc: 0, arr: 3319 });
    assert_eq!(d.ticks_per_period(), 3320);
    assert_eq!(d.actual_fs_millihz(BOX_TIMER_CLOCK_HZ), 51_204_819);
    assert_eq!(d.error_ppm(BOX_TIMER_CLOCK_HZ, 51_200), 94);
}

#[test]
fn exact_rates_have_zero_error() {
    for fs in [10_000u32, 50_000, 100_000, 200_000] {
        let d = timer_divider(BOX_TIMER_CLOCK_HZ, fs, ARR_MAX_16).unwrap();
        assert_eq!(d.psc, 0);
        assert_eq!(d.ticks_per_period() * u64::from(fs), u64::from(BOX_TIMER_CLOCK_HZ));
        assert_eq!(d.error_ppm(BOX_TIMER_CLOCK_HZ, fs), 0);
        assert_eq!(d.actual_fs_millihz(BOX_TIMER_CLOCK_HZ), u64::from(fs) * 1000);
    }
}

#[test]
fn every_box_rate_fits_a_16_bit_timer_without_prescaler() {
    // The whole supported range needs no prescaler, so the rate resolution
    // is one 170 MHz tick: at most 0.5 tick of 850 (200 kHz) = 589 ppm.
    for fs in BOX_FS_RANGE_HZ.clone().step_by(7) {
        let d = timer_divider(BOX_TIMER_CLOCK_HZ, fs, ARR_MAX_16).unwrap();
        assert_eq!(d.psc, 0, "fs {fs}");
        assert!(d.error_ppm(BOX_TIMER_CLOCK_HZ, fs).abs() <= 589, "fs {fs}: {d:?}");
    }
}

#[test]
fn low_rates_use_the_prescaler() {
    let d = timer_divider(BOX_TIMER_CLOCK_HZ, 1, ARR_MAX_16).unwrap();
    assert_eq!(d.psc, 2593);
    assert!(d.arr <= ARR_MAX_16);
    assert!(d.error_ppm(BOX_TIMER_CLOCK_HZ, 1).abs() < 10);
    // A 32-bit timer reaches 1 Hz without a prescaler.
    let d = timer_divider(BOX_TIMER_CLOCK_HZ, 1, ARR_MAX_32).unwrap();
    assert_eq!(d, TimerDivider { psc: 0, arr: BOX_TIMER_CLOCK_HZ - 1 });
}

#[test]
fn impossible_rates_are_refused() {
    assert_eq!(timer_divider(BOX_TIMER_CLOCK_HZ, 0, ARR_MAX_16), None);
    assert_eq!(timer_divider(BOX_TIMER_CLOCK_HZ, BOX_TIMER_CLOCK_HZ, ARR_MAX_16), None);
    assert_eq!(timer_divider(0, 1000, ARR_MAX_16), None);
    // A timer without counting range.
    assert_eq!(timer_divider(BOX_TIMER_CLOCK_HZ, 1000, 0), None);
}

#[test]
fn interrupt_offset_after_the_conversion() {
    let d = timer_divider(BOX_TIMER_CLOCK_HZ, 51_200, ARR_MAX_32).unwrap();
    // 2 us at 170 MHz = 340 ticks.
    assert_eq!(compare_offset_ticks(&d, BOX_TIMER_CLOCK_HZ, 2_000), Some(340));
    // Rounded up to whole ticks, never 0.
    assert_eq!(compare_offset_ticks(&d, BOX_TIMER_CLOCK_HZ, 1), Some(1));
    assert_eq!(compare_offset_ticks(&d, BOX_TIMER_CLOCK_HZ, 0), Some(1));
    // At 200 kHz (850 ticks) a 3 us delay would eat more than half the period.
    let fast = timer_divider(BOX_TIMER_CLOCK_HZ, 200_000, ARR_MAX_32).unwrap();
    assert_eq!(compare_offset_ticks(&fast, BOX_TIMER_CLOCK_HZ, 2_000), Some(340));
    assert_eq!(compare_offset_ticks(&fast, BOX_TIMER_CLOCK_HZ, 3_000), None);
}

proptest! {
    #[test]
    fn divider_is_the_nearest_achievable(clk in 1_000_000u32..=200_000_000, fs_frac in 1u32..=1_000_000, wide in any::<bool>()) {
        let max_arr = if wide { ARR_MAX_32 } else { ARR_MAX_16 };
        let fs = (u64::from(clk) / 2 * u64::from(fs_frac) / 1_000_000).max(1) as u32;
        let d = timer_divider(clk, fs, max_arr).expect("every rate up to clk/2 is reachable");
        prop_assert!(d.arr >= 1 && d.arr <= max_arr);
        // The period is within half a counter step of clk / fs.
        let ideal = f64::from(clk) / f64::from(fs);
        let step = f64::from(d.psc) + 1.0;
        let got = d.ticks_per_period() as f64;
        prop_assert!((got - ideal).abs() <= step / 2.0 + 1e-6 * ideal + 0.5, "{d:?} ideal {ideal}");
    }
}

// ---------------------------------------------------------------- rings --

/// CNDTR of a circular channel of `len` entries after `written` transfers.
fn ndtr_after(written: u64, len: u16) -> u16 {
    len - (written % u64::from(len)) as u16
}

#[test]
fn write_index_from_remaining_count() {
    assert_eq!(dma_write_index(16, 16), Some(0));
    assert_eq!(dma_write_index(15, 16), Some(1));
    assert_eq!(dma_write_index(1, 16), Some(15));
    assert_eq!(dma_write_index(0, 16), None);
    assert_eq!(dma_write_index(17, 16), None);
    assert_eq!(dma_write_index(1, 0), None);
}

#[test]
fn one_sample_per_interrupt_is_no_overrun() {
    let len = 16;
    let mut c = RingCursor::new(len);
    for k in 1..=100u64 {
        let n = ndtr_after(k, len);
        let step = c.advance(&[n, n, n]).unwrap();
        assert_eq!(step.available, 1);
        assert_eq!(step.missed(), 0);
        assert_eq!(u64::from(step.newest), (k - 1) % 16);
    }
}

#[test]
fn skipped_samples_are_counted_and_the_newest_is_used() {
    let len = 16;
    let mut c = RingCursor::new(len);
    let mut st = SampleState::default();
    let n = ndtr_after(3, len);
    let step = c.advance(&[n, n, n]).unwrap();
    assert_eq!(step, RingStep { available: 3, newest: 2 });
    st.note_overruns(step.missed());
    assert_eq!(st.counters.overruns, 2);
    assert_eq!(c.next(), 3);
}

#[test]
fn unfinished_conversion_yields_nothing_then_catches_up() {
    let len = 16;
    let mut c = RingCursor::new(len);
    let n = ndtr_after(1, len);
    c.advance(&[n, n, n]).unwrap();
    // Interrupt ran before this period's conversions completed.
    let step = c.advance(&[n, n, n]).unwrap();
    assert_eq!(step.available, 0);
    assert_eq!(step.missed(), 0);
    assert_eq!(c.next(), 1);
    // Next interrupt: two samples, one of them missed.
    let n = ndtr_after(3, len);
    let step = c.advance(&[n, n, n]).unwrap();
    assert_eq!(step, RingStep { available: 2, newest: 2 });
    assert_eq!(step.missed(), 1);
}

#[test]
fn a_lagging_channel_limits_what_is_complete() {
    let len = 16;
    let mut c = RingCursor::new(len);
    // ADC1 and ADC2 transferred, ADC3's transfer not yet.
    let step = c.advance(&[ndtr_after(1, len), ndtr_after(1, len), ndtr_after(0, len)]).unwrap();
    assert_eq!(step.available, 0);
    let step = c.advance(&[ndtr_after(1, len); 3]).unwrap();
    assert_eq!(step, RingStep { available: 1, newest: 0 });
}

#[test]
fn impossible_counts_leave_the_cursor_alone() {
    let mut c = RingCursor::new(16);
    c.advance(&[15, 15, 15]).unwrap();
    let before = c;
    assert_eq!(c.advance(&[14, 0, 14]), None);
    assert_eq!(c.advance(&[14, 17, 14]), None);
    assert_eq!(c.advance(&[]), None);
    assert_eq!(c, before);
    assert_eq!(RingCursor::new(0).advance(&[1]), None);
    assert!(RingCursor::new(0).is_empty());
}

#[test]
fn long_rings_do_not_overflow() {
    let len = u16::MAX;
    let mut c = RingCursor::new(len);
    let mut written = 0u64;
    for burst in [1u64, 65_000, 2, 65_534, 1] {
        written += burst;
        let n = ndtr_after(written, len);
        let step = c.advance(&[n]).unwrap();
        assert_eq!(u64::from(step.available), burst);
        assert_eq!(u64::from(step.newest), (written - 1) % u64::from(len));
    }
}

proptest! {
    /// Over any schedule with fewer than `len` samples between interrupts,
    /// processed + missed = written, and the newest index is always right.
    #[test]
    fn every_written_sample_is_processed_or_counted(len in 2u16..=64, bursts in prop::collection::vec(0u16..64, 1..200)) {
        let mut c = RingCursor::new(len);
        let mut written = 0u64;
        let mut processed = 0u64;
        let mut missed = 0u64;
        for b in bursts {
            let b = u64::from(b % len);
            written += b;
            let n = ndtr_after(written, len);
            let step = c.advance(&[n, n, n]).unwrap();
            prop_assert_eq!(u64::from(step.available), b);
            if step.available > 0 {
                processed += 1;
                prop_assert_eq!(u64::from(step.newest), (written - 1) % u64::from(len));
            }
            missed += u64::from(step.missed());
        }
        prop_assert_eq!(processed + missed, written);
    }

    /// The cursor (conditional subtractions) against its definition with
    /// `%` (as first written), for any ring length, position and three
    /// channel counts, valid or not, lagging or not.
    #[test]
    fn cursor_steps_equal_the_modulo_definition(len in 1u16..=64, start in 0u16..64, n in prop::array::uniform3(0u16..=66)) {
        let mut c = RingCursor::new(len);
        // Move the cursor to `start % len` first.
        let s = start % len;
        if s > 0 {
            let n0 = len - s;
            c.advance(&[n0, n0, n0]).unwrap();
        }
        prop_assert_eq!(c.next(), s);
        let reference = || -> Option<(u16, u16, u16)> {
            let (len, next) = (u32::from(len), u32::from(s));
            let mut available = u32::MAX;
            for &k in &n {
                if k == 0 || u32::from(k) > len {
                    return None;
                }
                let w = (len - u32::from(k)) % len;
                available = available.min((w + len - next) % len);
            }
            Some((available as u16, ((next + len + available - 1) % len) as u16, ((next + available) % len) as u16))
        };
        let got = c.advance(&n).map(|st| (st.available, st.newest, c.next()));
        prop_assert_eq!(got, reference());
        if got.is_none() {
            prop_assert_eq!(c.next(), s, "a refused step does not move the cursor");
        }
    }
}

// ---------------------------------------------------------------- slots --
// Which slot's image the box runs is the coefficient store's boot rule
// (dynocomp_core::store), tested on a simulated flash in
// host-tools/tests/store_power_fail.rs.

fn valid(fs: u32) -> dynocomp_core::image::CoeffImage {
    image_with(AxisFilter::gain(1.0).unwrap(), &[0, 1, 2], fs)
}

#[test]
fn the_box_runs_at_the_image_rate_or_the_default() {
    let img = Ok(valid(100_000).into());
    let mode = select_mode(Some(&img), false);
    assert_eq!(box_sample_rate(&mode), 100_000);
    assert_eq!(box_sample_rate(&select_mode(None, false)), DEFAULT_FS_HZ);
    // A valid image at a rate the box cannot run is bypassed at the default rate.
    let slow = Ok(valid(5_000).into());
    let mode = select_mode(Some(&slow), false);
    assert!(matches!(mode, Mode::Bypass(BypassReason::UnsupportedSampleRate(5_000))));
    assert_eq!(box_sample_rate(&mode), DEFAULT_FS_HZ);
    assert!(BOX_FS_RANGE_HZ.contains(&DEFAULT_FS_HZ));
}

// ------------------------------------------------------- oversampling --

/// Independent reference in f64 from RM0440's numbers: one 12-bit conversion
/// takes 24.5 (sampling) + 12.5 (SAR) = 37 ADC cycles at 42.5 MHz; the
/// largest power-of-two ratio ≤ 256 whose conversions fit in a quarter period
/// less `margin_s` (the code works in whole nanoseconds, rounding the period
/// down and the conversion time up, so within 2 ns of a boundary it may
/// pick the smaller ratio).
fn reference_ratio_with_margin(fs: f64, margin_s: f64) -> u16 {
    let t_conv = 37.0 / 42.5e6;
    let mut ratio = 1u16;
    while ratio < 256 && f64::from(ratio * 2) * t_conv <= 0.25 / fs - margin_s {
        ratio *= 2;
    }
    ratio
}

fn reference_ratio(fs: f64) -> u16 {
    reference_ratio_with_margin(fs, 0.0)
}

#[test]
fn oversampling_ratios_of_the_box_rates() {
    let os = |fs| adc_oversampling(fs, BOX_ADC_CLOCK_HZ, BOX_SAMPLE_HALF_CYCLES).unwrap();
    // 870.588 ns per conversion; quarter periods 25 µs, 9.77 µs, 4.88 µs,
    // 2.5 µs, 1.25 µs.
    let table = [(10_000u32, 16u16), (25_600, 8), (51_200, 4), (100_000, 2), (200_000, 1)];
    for (fs, ratio) in table {
        let o = os(fs);
        assert_eq!(o.ratio, ratio, "fs {fs}");
        assert_eq!(o.ratio, reference_ratio(f64::from(fs)), "fs {fs}");
    }
    let o = os(51_200);
    // 4 × 870.588 ns = 3482.35 ns, rounded up; + 1.2 µs margin.
    assert_eq!(o.window_ns, 3_483);
    assert_eq!(o.irq_delay_ns, 4_683);
    assert_eq!((o.ovsr, o.shift), (1, 2));
    assert!(o.enabled());
    // The averaged sample lies 1.5 conversions after the trigger.
    assert_eq!(o.centroid_delay_ns(), 1_305);
    let off = os(200_000);
    assert!(!off.enabled());
    assert_eq!((off.window_ns, off.irq_delay_ns, off.centroid_delay_ns()), (871, 2_071, 0));
}

#[test]
fn oversampling_refuses_rates_the_adc_cannot_follow() {
    assert_eq!(adc_oversampling(0, BOX_ADC_CLOCK_HZ, BOX_SAMPLE_HALF_CYCLES), None);
    assert_eq!(adc_oversampling(10_000, 0, BOX_SAMPLE_HALF_CYCLES), None);
    // 0.87 µs + 1.2 µs must fit in half a period: 240 kHz (2.08 µs) does, 250 kHz does not.
    assert!(adc_oversampling(240_000, BOX_ADC_CLOCK_HZ, BOX_SAMPLE_HALF_CYCLES).is_some());
    assert_eq!(adc_oversampling(250_000, BOX_ADC_CLOCK_HZ, BOX_SAMPLE_HALF_CYCLES), None);
    // Very low rates stop at the hardware's 256×.
    let slow = adc_oversampling(100, BOX_ADC_CLOCK_HZ, BOX_SAMPLE_HALF_CYCLES).unwrap();
    assert_eq!((slow.ratio, slow.ovsr, slow.shift), (256, 7, 8));
}

proptest! {
    #[test]
    fn oversampling_fits_the_period_and_the_timer(fs in BOX_FS_RANGE_HZ) {
        let o = adc_oversampling(fs, BOX_ADC_CLOCK_HZ, BOX_SAMPLE_HALF_CYCLES).unwrap();
        let exact = reference_ratio(f64::from(fs));
        let conservative = reference_ratio_with_margin(f64::from(fs), 2e-9);
        prop_assert!(o.ratio == exact || o.ratio == conservative, "fs {} ratio {} vs {}", fs, o.ratio, exact);
        prop_assert_eq!(u32::from(o.ratio), 1u32 << o.shift);
        if o.enabled() {
            prop_assert_eq!(u32::from(o.ratio), 2u32 << o.ovsr);
        }
        // The shifted sum of `ratio` full-scale codes is still a 12-bit code.
        prop_assert!((u32::from(o.ratio) * 4095) >> o.shift <= 4095);
        // Window within a quarter period, interrupt within half a period, and
        // the sample timer can place the interrupt there.
        let period_ns = 1e9 / f64::from(fs);
        prop_assert!(f64::from(o.window_ns) <= period_ns / 4.0 + 1.0);
        let d = timer_divider(BOX_TIMER_CLOCK_HZ, fs, ARR_MAX_32).unwrap();
        let at = compare_offset_ticks(&d, BOX_TIMER_CLOCK_HZ, o.irq_delay_ns).unwrap();
        prop_assert!(f64::from(at) / f64::from(BOX_TIMER_CLOCK_HZ) * 1e9 >= f64::from(o.irq_delay_ns));
    }
}

// ---------------------------------------------------------- auto-zero --

#[test]
fn auto_zero_averages_each_axis_exactly() {
    let mut az = AutoZero::new();
    assert_eq!(az.feed([1, 2, 3]), None, "idle: no result");
    az.start(7).unwrap();
    assert!(az.is_running());
    // x constant, y alternates, z a ramp: means computed in f64.
    let mut sums = [0f64; 3];
    let mut result = None;
    for k in 0..7u16 {
        let codes = [2100, 2000 + (k % 2) * 3, 1900 + k];
        for (s, c) in sums.iter_mut().zip(codes) {
            *s += f64::from(c);
        }
        let r = az.feed(codes);
        if k < 6 {
            assert_eq!(r, None);
        } else {
            result = r;
        }
    }
    let offsets = result.unwrap().unwrap();
    for (o, s) in offsets.iter().zip(sums) {
        assert!((f64::from(*o) - s / 7.0).abs() < 2.5e-4, "{o} vs {}", s / 7.0);
    }
    assert!(!az.is_running());
    assert_eq!(az.feed([1, 2, 3]), None);
}

#[test]
fn auto_zero_refuses_bad_counts_overlap_and_clipped_inputs() {
    let mut az = AutoZero::new();
    assert_eq!(az.start(0), Err(AutoZeroError::BadCount(0)));
    assert_eq!(az.start(AUTO_ZERO_MAX_SAMPLES + 1), Err(AutoZeroError::BadCount(65_536)));
    az.start(3).unwrap();
    assert_eq!(az.start(3), Err(AutoZeroError::Busy));
    assert_eq!(az.feed([2000, 2000, 2000]), None);
    assert_eq!(az.feed([2000, 4095, 0]), None);
    // The first clipped axis is reported, and no offset comes out.
    assert_eq!(az.feed([2000, 2000, 2000]), Some(Err(AutoZeroError::Saturated(1))));
    // Idle again: a new averaging may start.
    az.start(AUTO_ZERO_MAX_SAMPLES).unwrap();
    let mut last = None;
    for _ in 0..AUTO_ZERO_MAX_SAMPLES {
        last = az.feed([4094, 1, 2048]);
    }
    assert_eq!(last, Some(Ok([4094.0, 1.0, 2048.0])), "largest window does not overflow");
}

#[test]
fn auto_zero_makes_the_resting_input_read_zero_newton() {
    use dynocomp_core::sample::process_sample;
    // Pass-through compensator (gain 1) on x and z; image scaling from
    // common::image_with: force = (code − 2048)·2.5 N, dac = 2048 + 0.4·y.
    let mut img: dynocomp_core::image::BoxImage = image_with(AxisFilter::gain(1.0).unwrap(), &[0, 2], 51_200).into();
    let rest = [2110u16, 1990, 2003];
    {
        let loaded = Ok(img);
        let mut st = SampleState::default();
        let (dac, _) = process_sample(rest, select_mode(Some(&loaded), false), &mut st);
        // Before: the drift shows as force (x: 62 codes · 2.5 N = 155 N → +62 DAC codes).
        assert_eq!(dac, [2110, 1990, 2003]);
    }
    let mut az = AutoZero::new();
    az.start(16).unwrap();
    let mut out = None;
    for _ in 0..16 {
        out = az.feed(rest);
    }
    let mask = apply_adc_offsets(&mut img, out.unwrap().unwrap());
    assert_eq!(mask, 0b101, "only axes in the image change");
    let loaded = Ok(img);
    let mut st = SampleState::default();
    let (dac, _) = process_sample(rest, select_mode(Some(&loaded), false), &mut st);
    // x, z: 0 N → DAC offset code; y is not compensated and passes through raw.
    assert_eq!(dac, [2048, 1990, 2048]);
    // Gain is the image's: 10 codes above rest = 25 N = 10 DAC codes.
    let (dac, _) = process_sample([2120, 1990, 1993], select_mode(Some(&loaded), false), &mut st);
    assert_eq!(dac, [2058, 1990, 2038]);
}

// ---------------------------------------------------------------- LED --

#[test]
fn led_state_priorities() {
    // (started, fault, saturated, compensating)
    assert_eq!(led_state(false, false, false, true), LedState::Fault);
    assert_eq!(led_state(true, true, true, true), LedState::Fault);
    assert_eq!(led_state(true, false, true, true), LedState::Saturated);
    assert_eq!(led_state(true, false, true, false), LedState::Saturated);
    assert_eq!(led_state(true, false, false, true), LedState::Running);
    assert_eq!(led_state(true, false, false, false), LedState::Bypass);
}

#[test]
fn led_patterns_are_the_documented_ones_and_distinct() {
    let pattern = |s| -> String { (0..LED_PATTERN_TICKS).map(|t| if led_on(s, t) { '#' } else { '.' }).collect() };
    // docs/firmware.md, "Status LED" (100 ms per character).
    assert_eq!(pattern(LedState::Running), "#.........");
    assert_eq!(pattern(LedState::Bypass), ".#########");
    assert_eq!(pattern(LedState::Saturated), "#.#.......");
    assert_eq!(pattern(LedState::Fault), "#.#.#.#.#.");
    // Periodic in the tick counter.
    for s in [LedState::Running, LedState::Bypass, LedState::Saturated, LedState::Fault] {
        for t in 0..3 * LED_PATTERN_TICKS {
            assert_eq!(led_on(s, t), led_on(s, t % LED_PATTERN_TICKS));
        }
    }
}

// ------------------------------------------------- image switch, version --

#[test]
fn a_new_image_at_the_running_rate_switches_without_reboot() {
    assert_eq!(image_switch(51_200, &valid(51_200).into()), ImageSwitch::AtSampleBoundary);
    assert_eq!(image_switch(51_200, &valid(100_000).into()), ImageSwitch::Reboot { from_hz: 51_200, to_hz: 100_000 });
}

#[test]
fn firmware_version_parts() {
    assert_eq!(parse_version("0.1.0"), [0, 1, 0]);
    assert_eq!(parse_version("12.34.56"), [12, 34, 56]);
    assert_eq!(parse_version("1.2.3-rc.1"), [1, 2, 3]);
    assert_eq!(parse_version("1.999.3"), [1, 255, 3]);
    assert_eq!(parse_version("7"), [7, 0, 0]);
    assert_eq!(parse_version(""), [0, 0, 0]);
    const V: [u8; 3] = parse_version(env!("CARGO_PKG_VERSION"));
    assert_eq!(V, [0, 1, 0]);
}

// ------------------------------------------------- the interrupt's logic --

use common::{kernel_filter, mode_block};
use dynocomp_core::image::CoeffImage;
use dynocomp_core::sample::{process_sample, select_stored_mode, SampleFlags};

/// An image whose x axis has memory (a 2.5 kHz mode at 51.2 kHz), so a
/// filter reset shows in the output.
fn image_with_memory(f_hz: f64) -> CoeffImage {
    let blk = mode_block(f_hz, 0.05, 51_200.0, [1.0, 0.0]);
    image_with(kernel_filter(&[blk], 0.5), &[0], 51_200)
}

fn codes(k: u16) -> [u16; 3] {
    [2048 + (k * 37) % 200, 2000, 2100]
}

/// A stored image, as the coefficient store gives it.
fn ok(img: impl Into<dynocomp_core::image::BoxImage>) -> Result<dynocomp_core::image::BoxImage, BypassReason> {
    Ok(img.into())
}

/// DAC codes of samples `ks` through `path` (compensating).
fn run(path: &mut SamplePath, stored: &mut ActiveImage, ks: std::ops::Range<u16>) -> Vec<[u16; 3]> {
    ks.map(|k| path.tick(codes(k), stored, false).dac).collect()
}

#[test]
fn leaving_bypass_starts_the_filters_from_rest() {
    let mut stored = ActiveImage::new(ok(image_with_memory(2_500.0)));
    let mut path = SamplePath::new();
    for k in 0..50 {
        assert!(path.tick(codes(k), &mut stored, false).compensating);
    }
    for k in 50..60 {
        let out = path.tick(codes(k), &mut stored, true);
        assert!(!out.compensating && out.flags.has(SampleFlags::BYPASS));
        assert_eq!(out.dac, codes(k), "bypass passes the raw codes");
    }
    let after = run(&mut path, &mut stored, 60..110);
    // Truth: the same samples through a sample path that starts at rest.
    assert_eq!(after, run(&mut SamplePath::new(), &mut stored, 60..110));
    // And it matters: carrying the state over the bypass gives other output.
    let mut st = SampleState::default();
    let loaded = Ok(stored.stored().unwrap());
    let mode = select_mode(Some(&loaded), false);
    let carried: Vec<_> = (0..110)
        .filter(|k| !(50..60).contains(k))
        .map(|k| process_sample(codes(k), mode, &mut st).0)
        .skip(50)
        .collect();
    assert_ne!(after, carried);
}

#[test]
fn a_new_image_starts_from_rest() {
    let mut stored = ActiveImage::new(ok(image_with_memory(2_500.0)));
    let mut path = SamplePath::new();
    run(&mut path, &mut stored, 0..40);
    stored = ActiveImage::new(ok(image_with_memory(3_100.0)));
    path.on_image_switch();
    let after = run(&mut path, &mut stored, 40..90);
    assert_eq!(after, run(&mut SamplePath::new(), &mut stored, 40..90));
    // The new image is the one running: the old one gives other output.
    let mut old = ActiveImage::new(ok(image_with_memory(2_500.0)));
    assert_ne!(after, run(&mut SamplePath::new(), &mut old, 40..90));
    // The counters survive the switch.
    assert_eq!(path.state.counters.samples, 90);
}

#[test]
fn auto_zero_in_the_sample_path() {
    // Pass-through gain on x and z (dac = code while the offset is 2048).
    let mut stored = ActiveImage::new(ok(image_with(AxisFilter::gain(1.0).unwrap(), &[0, 2], 51_200)));
    let rest = [2110u16, 1990, 2003];
    let mut path = SamplePath::new();
    path.request_auto_zero(8).unwrap();
    assert_eq!(path.request_auto_zero(8), Err(AutoZeroError::Busy));
    for _ in 0..7 {
        let out = path.tick(rest, &mut stored, false);
        assert_eq!(out.auto_zero, None);
        assert_eq!(out.dac, rest, "old offsets until the average is complete");
    }
    let out = path.tick(rest, &mut stored, false);
    assert_eq!(out.auto_zero, Some(Ok([2110.0, 1990.0, 2003.0])));
    // From this sample on the resting input reads 0 N on the image's axes.
    assert_eq!(out.dac, [2048, 1990, 2048]);
    let axis_x = stored.stored().as_ref().unwrap().scaling()[0].unwrap();
    assert_eq!(axis_x.adc_offset_code, 2110.0);
    assert_eq!(path.tick(rest, &mut stored, false).dac, [2048, 1990, 2048]);

    // Clipped input: refused, offsets unchanged.
    path.request_auto_zero(2).unwrap();
    path.tick([4095, 1990, 2003], &mut stored, false);
    let out = path.tick(rest, &mut stored, false);
    assert_eq!(out.auto_zero, Some(Err(AutoZeroError::Saturated(0))));
    assert_eq!(stored.stored().as_ref().unwrap().scaling()[0].unwrap().adc_offset_code, 2110.0);

    // Without an image the average is still reported; nothing to apply.
    let mut none = ActiveImage::new(Err(BypassReason::NoImage));
    path.request_auto_zero(1).unwrap();
    let out = path.tick(rest, &mut none, false);
    assert_eq!(out.auto_zero, Some(Ok([2110.0, 1990.0, 2003.0])));
    assert_eq!(out.dac, rest);
    assert_eq!(*none.stored(), Err(BypassReason::NoImage));
}

#[test]
fn an_image_switch_cancels_a_running_auto_zero() {
    let mut stored = ActiveImage::new(ok(image_with(AxisFilter::gain(1.0).unwrap(), &[0], 51_200)));
    let mut path = SamplePath::new();
    path.request_auto_zero(4).unwrap();
    path.tick([2100, 2000, 2000], &mut stored, false);
    path.on_image_switch();
    for _ in 0..4 {
        assert_eq!(path.tick([2100, 2000, 2000], &mut stored, false).auto_zero, None);
    }
    assert_eq!(stored.stored().unwrap().scaling()[0].unwrap().adc_offset_code, 2048.0);
}

/// An image over the box's CPU budget (3 × 24 pole pairs at 51.2 kHz:
/// ≈ 93 % predicted load) and the same filter where it fits (20 kHz).
fn over_and_within_budget() -> (CoeffImage, CoeffImage) {
    use common::filter_24;
    use dynocomp_core::budget::{image_load, BOX_LOAD_LIMIT_PERMILLE};
    let (blocks, d) = filter_24(51_200.0);
    let f = kernel_filter(&blocks, d);
    let over = image_with(f, &[0, 1, 2], 51_200);
    let within = image_with(f, &[0, 1, 2], 20_000);
    assert!(image_load(&over).permille > BOX_LOAD_LIMIT_PERMILLE);
    assert!(image_load(&within).permille <= BOX_LOAD_LIMIT_PERMILLE);
    (over, within)
}

/// Whether any of `n` samples through `path` ran the compensator, and
/// that every sample that did not was passed through raw.
fn runs_any(path: &mut SamplePath, stored: &mut ActiveImage, user_bypass: bool, n: u16) -> bool {
    let mut ran = false;
    for k in 0..n {
        let out = path.tick(codes(k), stored, user_bypass);
        if out.compensating {
            ran = true;
        } else {
            assert_eq!(out.dac, codes(k), "a refused image passes the raw codes");
            assert!(out.flags.has(SampleFlags::BYPASS));
        }
    }
    ran
}

#[test]
fn an_image_over_the_budget_is_refused_on_every_route_to_activation() {
    use dynocomp_core::budget::image_load;
    let (over, within) = over_and_within_budget();
    let refused = |a: &ActiveImage| matches!(a.refused(), Some(BypassReason::OverBudget(l)) if l == image_load(&over));

    // Boot: the store's result becomes the active image.
    let mut boot = ActiveImage::new(ok(over));
    assert!(refused(&boot));
    let mut path = SamplePath::new();
    assert!(!runs_any(&mut path, &mut boot, false, 20));

    // Upload / image switch: a running box is handed the image.
    let mut active = ActiveImage::new(ok(within));
    let mut path = SamplePath::new();
    assert!(runs_any(&mut path, &mut active, false, 5));
    active = ActiveImage::new(ok(over));
    path.on_image_switch();
    assert!(refused(&active));
    assert!(!runs_any(&mut path, &mut active, false, 20));

    // Bypass toggle: the user leaves bypass; the image still does not run.
    assert!(!runs_any(&mut path, &mut active, true, 5));
    assert!(!runs_any(&mut path, &mut active, false, 20));

    // Auto-zero: the image changes in place (ADC offsets, which no check
    // reads); still refused, and the same verdict as a fresh check.
    path.request_auto_zero(4).unwrap();
    assert!(!runs_any(&mut path, &mut active, false, 10));
    assert_ne!(active.stored().unwrap().scaling()[0].unwrap().adc_offset_code, 2048.0, "the auto-zero was applied");
    assert!(refused(&active));
    assert_eq!(active.refused(), ActiveImage::new(*active.stored()).refused());

    // Negative control: the same routes with the image that fits run it.
    let mut boot = ActiveImage::new(ok(within));
    assert_eq!(boot.refused(), None);
    assert!(runs_any(&mut SamplePath::new(), &mut boot, false, 5));
    let mut path = SamplePath::new();
    let mut active = ActiveImage::new(ok(over));
    assert!(!runs_any(&mut path, &mut active, false, 5));
    active = ActiveImage::new(ok(within));
    path.on_image_switch();
    assert!(runs_any(&mut path, &mut active, false, 5));
    assert!(!runs_any(&mut path, &mut active, true, 5));
    assert!(runs_any(&mut path, &mut active, false, 5));
    path.request_auto_zero(4).unwrap();
    assert!(runs_any(&mut path, &mut active, false, 10));
    assert_ne!(active.stored().unwrap().scaling()[0].unwrap().adc_offset_code, 2048.0);
    assert_eq!(active.refused(), ActiveImage::new(*active.stored()).refused());
}

#[test]
fn the_cached_mode_is_the_checked_mode() {
    // ActiveImage::mode gives what select_stored_mode decides, for every
    // reason and both positions of the user's switch.
    let (over, within) = over_and_within_budget();
    let mut offline = within;
    offline.flags = dynocomp_core::image::FLAG_OFFLINE_ONLY;
    let slow = image_with(AxisFilter::gain(1.0).unwrap(), &[0], 5_000);
    for stored in [
        ok(over),
        ok(within),
        ok(offline),
        ok(slow),
        Err(BypassReason::NoImage),
        Err(BypassReason::InvalidImage(dynocomp_core::image::ImageError::BadMagic)),
    ] {
        let active = ActiveImage::new(stored);
        for user in [false, true] {
            let (cached, checked) = (active.mode(user), select_stored_mode(&stored, user));
            match (cached, checked) {
                (Mode::Compensate(a), Mode::Compensate(b)) => assert_eq!(a, b),
                (Mode::Bypass(a), Mode::Bypass(b)) => assert_eq!(a, b),
                (a, b) => panic!("{stored:?}, user {user}: cached {a:?}, checked {b:?}"),
            }
        }
    }
}
