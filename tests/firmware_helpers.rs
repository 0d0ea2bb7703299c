//! Host tests of the firmware shell's pure helpers (`dynocomp_core::shell`):
//! sample-timer divider, DMA ring bookkeeping (overrun counting) and the
//! flash-slot choice the box makes at boot.

mod common;
use common::image_with;
use dynocomp_core::image::ImageError;
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
        assert_eq!(
            d.ticks_per_period() * u64::from(fs),
            u64::from(BOX_TIMER_CLOCK_HZ)
        );
        assert_eq!(d.error_ppm(BOX_TIMER_CLOCK_HZ, fs), 0);
        assert_eq!(
            d.actual_fs_millihz(BOX_TIMER_CLOCK_HZ),
            u64::from(fs) * 1000
        );
    }
}

#[test]
fn every_box_rate_fits_a_16_bit_timer_without_prescaler() {
    // The whole supported range needs no prescaler, so the rate resolution
    // is one 170 MHz tick: at most 0.5 tick of 850 (200 kHz) = 589 ppm.
    for fs in BOX_FS_RANGE_HZ.clone().step_by(7) {
        let d = timer_divider(BOX_TIMER_CLOCK_HZ, fs, ARR_MAX_16).unwrap();
        assert_eq!(d.psc, 0, "fs {fs}");
        assert!(
            d.error_ppm(BOX_TIMER_CLOCK_HZ, fs).abs() <= 589,
            "fs {fs}: {d:?}"
        );
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
    assert_eq!(
        d,
        TimerDivider {
            psc: 0,
            arr: BOX_TIMER_CLOCK_HZ - 1
        }
    );
}

#[test]
fn impossible_rates_are_refused() {
    assert_eq!(timer_divider(BOX_TIMER_CLOCK_HZ, 0, ARR_MAX_16), None);
    assert_eq!(
        timer_divider(BOX_TIMER_CLOCK_HZ, BOX_TIMER_CLOCK_HZ, ARR_MAX_16),
        None
    );
    assert_eq!(timer_divider(0, 1000, ARR_MAX_16), None);
    // A timer without counting range.
    assert_eq!(timer_divider(BOX_TIMER_CLOCK_HZ, 1000, 0), None);
}

#[test]
fn interrupt_offset_after_the_conversion() {
    let d = timer_divider(BOX_TIMER_CLOCK_HZ, 51_200, ARR_MAX_32).unwrap();
    // 2 us at 170 MHz = 340 ticks.
    assert_eq!(
        compare_offset_ticks(&d, BOX_TIMER_CLOCK_HZ, 2_000),
        Some(340)
    );
    // Rounded up to whole ticks, never 0.
    assert_eq!(compare_offset_ticks(&d, BOX_TIMER_CLOCK_HZ, 1), Some(1));
    assert_eq!(compare_offset_ticks(&d, BOX_TIMER_CLOCK_HZ, 0), Some(1));
    // At 200 kHz (850 ticks) a 3 us delay would eat more than half the period.
    let fast = timer_divider(BOX_TIMER_CLOCK_HZ, 200_000, ARR_MAX_32).unwrap();
    assert_eq!(
        compare_offset_ticks(&fast, BOX_TIMER_CLOCK_HZ, 2_000),
        Some(340)
    );
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
    assert_eq!(
        step,
        RingStep {
            available: 3,
            newest: 2
        }
    );
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
    assert_eq!(
        step,
        RingStep {
            available: 2,
            newest: 2
        }
    );
    assert_eq!(step.missed(), 1);
}

#[test]
fn a_lagging_channel_limits_what_is_complete() {
    let len = 16;
    let mut c = RingCursor::new(len);
    // ADC1 and ADC2 transferred, ADC3's transfer not yet.
    let step = c
        .advance(&[ndtr_after(1, len), ndtr_after(1, len), ndtr_after(0, len)])
        .unwrap();
    assert_eq!(step.available, 0);
    let step = c.advance(&[ndtr_after(1, len); 3]).unwrap();
    assert_eq!(
        step,
        RingStep {
            available: 1,
            newest: 0
        }
    );
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
}

// ---------------------------------------------------------------- slots --

fn valid(fs: u32) -> dynocomp_core::image::CoeffImage {
    image_with(AxisFilter::gain(1.0).unwrap(), &[0, 1, 2], fs)
}

#[test]
fn slot_a_wins_then_slot_b() {
    let a = valid(51_200);
    let b = valid(100_000);
    let ch = choose_image(Ok(a), Ok(b));
    assert_eq!(ch.slot, Some(Slot::A));
    assert_eq!(ch.loaded, Some(Ok(a)));

    let ch = choose_image(Err(ImageError::BadMagic), Ok(b));
    assert_eq!((ch.slot, ch.loaded), (Some(Slot::B), Some(Ok(b))));

    let bad_crc = ImageError::BadCrc {
        stored: 1,
        computed: 2,
    };
    let ch = choose_image(Err(bad_crc), Ok(b));
    assert_eq!((ch.slot, ch.loaded), (Some(Slot::B), Some(Ok(b))));
}

#[test]
fn empty_slots_mean_no_image() {
    let ch = choose_image(Err(ImageError::BadMagic), Err(ImageError::BadMagic));
    assert_eq!(ch.loaded, None);
    assert_eq!(ch.slot, None);
    assert!(matches!(
        select_mode(ch.loaded.as_ref(), false),
        Mode::Bypass(BypassReason::NoImage)
    ));
}

#[test]
fn the_first_real_error_is_reported() {
    let e_a = ImageError::BadCrc {
        stored: 1,
        computed: 2,
    };
    let e_b = ImageError::UnsupportedVersion(9);
    let ch = choose_image(Err(e_a), Err(e_b));
    assert_eq!((ch.slot, ch.loaded), (Some(Slot::A), Some(Err(e_a))));
    let ch = choose_image(Err(ImageError::BadMagic), Err(e_b));
    assert_eq!((ch.slot, ch.loaded), (Some(Slot::B), Some(Err(e_b))));
    assert!(matches!(
        select_mode(ch.loaded.as_ref(), false),
        Mode::Bypass(BypassReason::InvalidImage(ImageError::UnsupportedVersion(
            9
        )))
    ));
}

#[test]
fn the_box_runs_at_the_image_rate_or_the_default() {
    let img = Ok(valid(100_000));
    let mode = select_mode(Some(&img), false);
    assert_eq!(box_sample_rate(&mode), 100_000);
    assert_eq!(box_sample_rate(&select_mode(None, false)), DEFAULT_FS_HZ);
    // A valid image at a rate the box cannot run is bypassed at the default rate.
    let slow = Ok(valid(5_000));
    let mode = select_mode(Some(&slow), false);
    assert!(matches!(
        mode,
        Mode::Bypass(BypassReason::UnsupportedSampleRate(5_000))
    ));
    assert_eq!(box_sample_rate(&mode), DEFAULT_FS_HZ);
    assert!(BOX_FS_RANGE_HZ.contains(&DEFAULT_FS_HZ));
}
