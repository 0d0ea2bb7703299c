//! The interrupt body as a pure function: bypass decisions, scaling,
//! saturation and the runaway guard.

mod common;
use common::*;
use dynocomp_core::image::{BoxImage, CoeffImage, ImageError, FLAG_OFFLINE_ONLY, MAX_IMAGE_LEN};
use dynocomp_core::kernel::AxisFilter;
use dynocomp_core::sample::*;

fn encoded(img: &CoeffImage) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_IMAGE_LEN];
    let n = img.encode(&mut buf).unwrap();
    buf.truncate(n);
    buf
}

#[test]
fn absent_image_leaves_the_box_in_bypass_with_raw_codes_out() {
    let mode = select_mode(None, false);
    assert!(matches!(mode, Mode::Bypass(BypassReason::NoImage)));
    let mut st = SampleState::default();
    for codes in [[0u16, 2048, 4095], [1, 2, 3], [4000, 100, 2047]] {
        let (dac, flags) = process_sample(codes, mode, &mut st);
        assert_eq!(dac, codes);
        assert!(flags.has(SampleFlags::BYPASS));
    }
}

#[test]
fn corrupted_image_leaves_the_box_in_bypass() {
    let (blocks, d) = filter_24(51_200.0);
    let bytes = encoded(&image_with(kernel_filter(&blocks, d), &[0, 1, 2], 51_200));
    // flash slot holding the image with one flipped bit, as the firmware reads it
    let mut slot = vec![0xFFu8; 8192];
    slot[..bytes.len()].copy_from_slice(&bytes);
    slot[200] ^= 0x10;
    let loaded = BoxImage::parse_prefix(&slot);
    assert!(matches!(loaded, Err(ImageError::BadCrc { .. })));
    let mode = select_mode(Some(&loaded), false);
    assert!(matches!(mode, Mode::Bypass(BypassReason::InvalidImage(ImageError::BadCrc { .. }))));
    let mut st = SampleState::default();
    let (dac, flags) = process_sample([1234, 2345, 3456], mode, &mut st);
    assert_eq!(dac, [1234, 2345, 3456]);
    assert!(flags.has(SampleFlags::BYPASS));
    // an erased slot reads as "no image" in spirit: bad magic, bypass
    let erased = BoxImage::parse_prefix(&vec![0xFFu8; 8192]);
    assert!(matches!(
        select_mode(Some(&erased), false),
        Mode::Bypass(BypassReason::InvalidImage(ImageError::BadMagic))
    ));
}

#[test]
fn offline_only_unsupported_rate_and_user_bypass_are_never_run() {
    let f = AxisFilter::gain(2.0).unwrap();
    let mut img = image_with(f, &[0], 51_200);
    img.flags = FLAG_OFFLINE_ONLY;
    assert!(matches!(select_mode(Some(&Ok(img.into())), false), Mode::Bypass(BypassReason::OfflineOnly)));
    let img = image_with(f, &[0], 5_000);
    assert!(matches!(
        select_mode(Some(&Ok(img.into())), false),
        Mode::Bypass(BypassReason::UnsupportedSampleRate(5_000))
    ));
    let img = image_with(f, &[0], 51_200);
    assert!(matches!(select_mode(Some(&Ok(img.into())), true), Mode::Bypass(BypassReason::User)));
    assert!(matches!(select_mode(Some(&Ok(img.into())), false), Mode::Compensate(_)));
}

#[test]
fn compensation_scales_codes_to_newtons_and_back() {
    // gain-2 "compensator" on x only; scaling from common::image_with:
    // force = (code − 2048)·2.5 N, dac = 2048 + 0.4·y
    let img = image_with(AxisFilter::gain(2.0).unwrap(), &[0], 51_200);
    let loaded = Ok(img.into());
    let mode = select_mode(Some(&loaded), false);
    let mut st = SampleState::default();
    let (dac, flags) = process_sample([2148, 1000, 3000], mode, &mut st);
    // x: force = 100·2.5 = 250 N, y = 500 N, dac = 2048 + 200 = 2248
    assert_eq!(dac[0], 2248);
    // y and z are not in the image: raw codes pass through
    assert_eq!(&dac[1..], &[1000, 3000]);
    assert_eq!(flags, SampleFlags(0));
    // output clamps at the DAC rails instead of wrapping
    let (dac, _) = process_sample([4000, 2048, 2048], mode, &mut st);
    assert_eq!(dac[0], DAC_MAX_CODE);
    let (dac, _) = process_sample([100, 2048, 2048], mode, &mut st);
    assert_eq!(dac[0], 0);
    assert_eq!(st.counters.samples, 3);
}

#[test]
fn compensated_output_follows_the_kernel_response() {
    // The sample path applies the kernel: a unit step of 100 codes (250 N) on
    // a filter with a known DC gain converges to that gain times 250 N.
    let blk = mode_block(2_500.0, 0.05, 51_200.0, [1.0, 0.0]);
    // DC gain of the block: c (I − A)^-1 b, computed in f64
    let (a, b) = (blk.a, blk.b);
    let det = (1.0 - a[0][0]) * (1.0 - a[1][1]) - a[0][1] * a[1][0];
    let x1 = ((1.0 - a[1][1]) * b[0] + a[0][1] * b[1]) / det;
    let dc = blk.c[0] * x1;
    let img = image_with(kernel_filter(&[blk], 0.0), &[2], 51_200);
    let loaded = Ok(img.into());
    let mode = select_mode(Some(&loaded), false);
    let mut st = SampleState::default();
    let mut last = [0u16; 3];
    for _ in 0..20_000 {
        last = process_sample([2048, 2048, 2148], mode, &mut st).0;
    }
    let expected = 2048.0 + 0.4 * dc * 250.0;
    assert!((f64::from(last[2]) - expected).abs() <= 0.5 + 1e-9, "dac {} expected {expected}", last[2]);
}

#[test]
fn saturation_is_flagged_and_counted_in_both_modes() {
    let img = image_with(AxisFilter::gain(1.0).unwrap(), &[0, 1, 2], 51_200);
    let loaded = Ok(img.into());
    for mode in [select_mode(Some(&loaded), false), select_mode(None, false)] {
        let mut st = SampleState::default();
        let (_, flags) = process_sample([0, ADC_MAX_CODE, 2000], mode, &mut st);
        assert!(flags.has(SampleFlags::saturated(0)));
        assert!(flags.has(SampleFlags::saturated(1)));
        assert!(!flags.has(SampleFlags::saturated(2)));
        assert_eq!(st.counters.saturated, [1, 1, 0]);
    }
}

#[test]
fn runaway_state_is_reset_flagged_counted_and_raw_force_output() {
    let (blocks, d) = filter_24(51_200.0);
    // 3 × 24 pairs exceed the box's CPU budget at 51.2 kHz (see
    // `images_over_the_cpu_budget_are_never_run`); at 20 kHz they fit.
    let img = image_with(kernel_filter(&blocks, d), &[0, 1, 2], 20_000);
    let loaded = Ok(img.into());
    let mode = select_mode(Some(&loaded), false);
    let mut st = SampleState::default();
    st.axes[1].x[5][0] = f32::INFINITY;
    let (dac, flags) = process_sample([2048, 2148, 2048], mode, &mut st);
    assert!(flags.has(SampleFlags::reset(1)));
    assert!(!flags.has(SampleFlags::reset(0)));
    assert_eq!(st.axes[1].nonfinite_resets, 1);
    // raw force 250 N → dac 2048 + 0.4·250 = 2148
    assert_eq!(dac[1], 2148);
    st.note_overruns(2);
    assert_eq!(st.counters.overruns, 2);
}

#[test]
fn dac_rounding_is_total() {
    assert_eq!(to_dac_code(f32::NAN), 0);
    assert_eq!(to_dac_code(-3.0), 0);
    assert_eq!(to_dac_code(1e30), DAC_MAX_CODE);
    assert_eq!(to_dac_code(f32::INFINITY), DAC_MAX_CODE);
    assert_eq!(to_dac_code(1.49), 1);
    assert_eq!(to_dac_code(1.5), 2);
}

/// The DAC rounding as first written (float comparisons, then a cast): the
/// specification the integer-clamp version must keep.
#[allow(clippy::neg_cmp_op_on_partial_ord)] // `!(v >= 0.0)` is also true for NaN, on purpose
fn dac_code_reference(value: f32) -> u16 {
    let v = value + 0.5;
    if !(v >= 0.0) {
        0
    } else if v >= f32::from(DAC_MAX_CODE) {
        DAC_MAX_CODE
    } else {
        v as u16
    }
}

#[test]
fn dac_rounding_equals_its_reference_on_every_float_near_the_range() {
    // Every f32 from -2 to 4 100 (all codes, both rails and each rounding
    // boundary, ≈ 1.1e9 values would be too many: every 97th bit pattern,
    // plus every pattern within 4 ulps of each half-integer), and a sweep
    // of the whole bit space for NaNs, infinities and huge values.
    let mut checked = 0u64;
    let mut check = |v: f32| {
        assert_eq!(to_dac_code(v), dac_code_reference(v), "value {v:e} ({:#010x})", v.to_bits());
        checked += 1;
    };
    let (lo, hi) = ((-2.0f32).to_bits(), 4_100.0f32.to_bits());
    for b in (0..=hi).step_by(97).chain((0x8000_0000..=lo).step_by(97)) {
        check(f32::from_bits(b));
    }
    for k in -4..=8_200 {
        let half = k as f32 * 0.5;
        for d in -4i32..=4 {
            check(f32::from_bits(half.to_bits().wrapping_add_signed(d)));
        }
    }
    for b in (0..=u32::MAX).step_by(65_537) {
        check(f32::from_bits(b));
    }
    assert!(checked > 10_000_000, "{checked}");
    // Negative control: a version that rounds by truncation alone differs.
    let truncating = |v: f32| (v as u32).min(u32::from(DAC_MAX_CODE)) as u16;
    assert!((0..100).map(|k| k as f32 + 0.7).any(|v| truncating(v) != dac_code_reference(v)));
}

#[test]
fn the_box_rate_range_is_10_to_200_khz_inclusive() {
    let f = AxisFilter::gain(1.0).unwrap();
    for (fs, in_range) in [(9_999u32, false), (10_000, true), (51_200, true), (200_000, true), (200_001, false)] {
        let img = Ok(image_with(f, &[0], fs).into());
        let mode = select_mode(Some(&img), false);
        let rate_refused = matches!(mode, Mode::Bypass(BypassReason::UnsupportedSampleRate(r)) if r == fs);
        assert_eq!(rate_refused, !in_range, "fs {fs}: {mode:?}");
        // In range, only the CPU budget can refuse it: at 200 kHz (850
        // cycles per sample) the interrupt shell and one axis call alone are
        // predicted above 60 % of the period (dynocomp_core::budget).
        let runs = matches!(mode, Mode::Compensate(_));
        let over_budget = matches!(mode, Mode::Bypass(BypassReason::OverBudget(_)));
        if in_range {
            assert_eq!((runs, over_budget), (fs < 200_000, fs == 200_000), "fs {fs}: {mode:?}");
        }
    }
}

#[test]
fn stored_results_select_the_same_modes() {
    // The store's boot result: a reason is passed through, an image gets the
    // same checks as a parsed slot.
    let f = AxisFilter::gain(2.0).unwrap();
    let none: Result<BoxImage, BypassReason> = Err(BypassReason::NoImage);
    assert!(matches!(select_stored_mode(&none, false), Mode::Bypass(BypassReason::NoImage)));
    let bad = Err(BypassReason::InvalidImage(ImageError::BadMagic));
    assert!(matches!(select_stored_mode(&bad, true), Mode::Bypass(BypassReason::InvalidImage(ImageError::BadMagic))));
    let mut offline = image_with(f, &[0], 51_200);
    offline.flags = FLAG_OFFLINE_ONLY;
    assert!(matches!(select_stored_mode(&Ok(offline.into()), false), Mode::Bypass(BypassReason::OfflineOnly)));
    let slow = Ok(image_with(f, &[0], 5_000).into());
    assert!(matches!(select_stored_mode(&slow, false), Mode::Bypass(BypassReason::UnsupportedSampleRate(5_000))));
    let good: Result<BoxImage, BypassReason> = Ok(image_with(f, &[0], 51_200).into());
    assert!(matches!(select_stored_mode(&good, true), Mode::Bypass(BypassReason::User)));
    match select_stored_mode(&good, false) {
        Mode::Compensate(img) => assert_eq!(Ok(*img), good),
        m => panic!("expected compensate, got {m:?}"),
    }
}

#[test]
fn images_over_the_cpu_budget_are_never_run() {
    use dynocomp_core::budget::{image_load, period_cycles, BOX_LOAD_LIMIT_PERMILLE};
    // 3 × 24 pole pairs: ≈ 3 100 cycles per sample (high estimate), 93 %
    // of the 3 320-cycle period at 51.2 kHz; 36 % at 20 kHz.
    let (blocks, d) = filter_24(51_200.0);
    let f = kernel_filter(&blocks, d);
    let fast = image_with(f, &[0, 1, 2], 51_200);
    let load = image_load(&fast);
    assert!(load.permille > BOX_LOAD_LIMIT_PERMILLE, "{load:?}");
    assert!(load.cycles > period_cycles(51_200) / 2, "{load:?}");
    for mode in [select_mode(Some(&Ok(fast.into())), false), select_stored_mode(&Ok(fast.into()), false)] {
        assert!(matches!(mode, Mode::Bypass(BypassReason::OverBudget(l)) if l == load), "{mode:?}");
        let mut st = SampleState::default();
        let (dac, flags) = process_sample([100, 2048, 4000], mode, &mut st);
        assert_eq!(dac, [100, 2048, 4000]);
        assert!(flags.has(SampleFlags::BYPASS));
    }
    // Negative control: the same filter at 20 kHz, and one axis of it at
    // 51.2 kHz, fit and run.
    let slow = image_with(f, &[0, 1, 2], 20_000);
    assert!(matches!(select_mode(Some(&Ok(slow.into())), false), Mode::Compensate(_)));
    let one = image_with(f, &[1], 51_200);
    assert!(matches!(select_mode(Some(&Ok(one.into())), false), Mode::Compensate(_)), "{:?}", image_load(&one));
}
