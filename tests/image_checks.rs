//! The loader checks what it will run, behind a valid CRC: coefficients
//! bounded, pole margin, a bound on the ℓ1 gain and the DC gain
//! (`docs/image-format.md` §8, steps 19-22). A CRC catches transport
//! errors; these catch a wrong image (a host bug, the wrong file).
//!
//! The truth the tests hold the loader to: the output of a filter driven
//! by |u| ≤ 1 can never exceed the ℓ1 norm of its impulse response, and the
//! worst input (the sign of the time-reversed impulse response) reaches it.

use dynocomp_core::image::*;
use dynocomp_core::kernel::{AxisFilter, AxisState, Section};
use proptest::prelude::*;

/// Images designed by `dynocomp design` from `data/example` (3 axes; with
/// and without latency).
const EXAMPLE: &[u8] = include_bytes!("../fuzz/images/example.dcimg");
const LAT0: &[u8] = include_bytes!("../fuzz/images/lat0.dcimg");

/// Where the f32 filter coefficients of a version-1 image are: (byte offset,
/// axis index, what) for d, every section value and every tap.
fn coefficient_offsets(img: &[u8]) -> Vec<(usize, u8, &'static str)> {
    let mut out = Vec::new();
    let mut blk = HEADER_LEN;
    for axis in 0..3u8 {
        if img[18] & (1 << axis) == 0 {
            continue;
        }
        let (n_sec, n_taps) = (usize::from(img[blk + 1]), usize::from(img[blk + 2]));
        out.push((blk + 24, axis, "d"));
        for k in 0..8 * n_sec {
            out.push((blk + AXIS_HEADER_LEN + 4 * k, axis, "section"));
        }
        for j in 0..n_taps {
            out.push((blk + AXIS_HEADER_LEN + SECTION_LEN * n_sec + 4 * j, axis, "tap"));
        }
        blk += AXIS_HEADER_LEN + SECTION_LEN * n_sec + TAP_LEN * n_taps;
    }
    out
}

/// `img` with bit `bit` of byte `at` flipped and the CRC recomputed.
fn flip_with_crc(img: &[u8], at: usize, bit: u8) -> Vec<u8> {
    let mut b = img.to_vec();
    b[at] ^= 1 << bit;
    let n = b.len() - CRC_LEN;
    let crc = CRC32.checksum(&b[..n]);
    b[n..].copy_from_slice(&crc.to_le_bytes());
    b
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

/// Samples of the impulse responses and worst-case runs: the slowest
/// pole of the fixtures (margin 4·10⁻⁴) decays by e⁻⁸ in 20 000 samples.
const N: usize = 20_000;

/// The largest |y| the f32 kernel reaches for |u| ≤ 1: the filter is run
/// on the sign of its time-reversed impulse response, whose last output is
/// the ℓ1 norm of the first N samples of the impulse response.
fn worst_output(f: &AxisFilter) -> f64 {
    let mut st = AxisState::default();
    let h: Vec<f32> = (0..N).map(|k| f.step(&mut st, if k == 0 { 1.0 } else { 0.0 })).collect();
    let mut st = AxisState::default();
    let mut worst = 0.0f64;
    for k in 0..N {
        let u = if h[N - 1 - k] < 0.0 { -1.0 } else { 1.0 };
        worst = worst.max(f64::from(f.step(&mut st, u)).abs());
    }
    worst
}

/// The valid fixtures pass, and every axis's worst output for |u| ≤ 1 is
/// within its gain bound (the bound is a true bound), which is within
/// MAX_GAIN_BOUND with orders of magnitude to spare.
#[test]
fn designed_images_pass_and_their_bounds_hold() {
    for bytes in [EXAMPLE, LAT0] {
        let img = CoeffImage::parse(bytes).unwrap();
        for a in img.axes.iter().flatten() {
            let (bound, worst, dc) = (a.filter.gain_bound(), worst_output(&a.filter), a.filter.dc_gain());
            eprintln!("axis {}: worst output {worst:.2}, gain bound {bound:.2}, DC gain {dc:.5}", a.axis);
            assert!(worst <= bound, "axis {}: worst output {worst} above the bound {bound}", a.axis);
            assert!(worst > 0.25 * bound, "axis {}: bound {bound} far above the worst output {worst}", a.axis);
            assert!(bound < MAX_GAIN_BOUND / 30.0, "axis {}: bound {bound}", a.axis);
            assert!((dc - 1.0).abs() < 0.01, "axis {}: DC gain {dc} (a calibrated compensator: 1)", a.axis);
        }
    }
}

/// The case, on these fixtures: the exponent's top bit of a
/// coefficient flipped (−2.78·10⁻⁴ became −9.5·10³⁴) behind a recomputed
/// CRC. The kernel alone accepts such a filter and would put out up to
/// 10³⁰ N for 1 N in; the loader refuses every such image. Coefficients
/// below 2⁻¹⁰⁰ (zeros among them) become small numbers, not huge ones, and
/// from 2 up the bit is cleared (a coefficient becomes tiny): both are
/// left to the bounded-output property below.
#[test]
fn a_flipped_exponent_bit_behind_a_valid_crc_is_refused() {
    let mut refused = 0;
    for bytes in [EXAMPLE, LAT0] {
        for (at, axis, what) in coefficient_offsets(bytes) {
            let v = f32_at(bytes, at);
            // Set (not cleared) top exponent bit: |v| in [2⁻¹⁰⁰, 2).
            if v.abs() < 2f32.powi(-100) || v.abs() >= 2.0 {
                continue;
            }
            let bad = flip_with_crc(bytes, at + 3, 6);
            let e = CoeffImage::parse(&bad).expect_err(&format!("{what} at byte {at} ({v} → {})", f32_at(&bad, at)));
            let named = match e {
                ImageError::CoefficientOutOfRange { axis: a, .. }
                | ImageError::TapOutOfRange { axis: a, .. }
                | ImageError::UnstableSection { axis: a, .. }
                | ImageError::PoleMarginTooSmall { axis: a, .. }
                | ImageError::GainBoundTooLarge { axis: a, .. }
                | ImageError::DcGainOutOfRange { axis: a }
                | ImageError::NotModalSection { axis: a, .. }
                | ImageError::NonFiniteCoefficient { axis: a, .. }
                | ImageError::NonFiniteTap { axis: a, .. } => a,
                other => panic!("{what} at byte {at}: unexpected {other}"),
            };
            assert_eq!(named, axis, "{e}");
            refused += 1;
        }
    }
    assert!(refused > 100, "{refused} coefficients checked");
    // Negative control: a tap of 0.0199 flipped the same way is 6.8·10³⁶,
    // which the kernel itself runs; its worst output is then far beyond
    // any bound the loader allows.
    let at = 472;
    assert_eq!(coefficient_offsets(EXAMPLE).iter().find(|c| c.0 == at).map(|c| c.2), Some("tap"));
    let bad = flip_with_crc(EXAMPLE, at + 3, 6);
    let img = CoeffImage::parse(EXAMPLE).unwrap();
    let a = img.axes[1].unwrap();
    let mut taps = a.filter.fir().to_vec();
    let j = coefficient_offsets(EXAMPLE).iter().filter(|c| c.1 == 1 && c.2 == "tap").position(|c| c.0 == at).unwrap();
    taps[j] = f32_at(&bad, at);
    let raw = AxisFilter::with_fir(a.filter.sections(), a.filter.d(), &taps).unwrap();
    assert!(worst_output(&raw) > 1e30);
    assert_eq!(CoeffImage::parse(&bad), Err(ImageError::TapOutOfRange { axis: 1, tap: j as u8 }));
    assert!(CoeffImage::parse(&bad).unwrap_err().to_string().contains("tap"));
}

/// Each check on its own, with a section at the edge of what it allows and
/// just beyond (the thresholds and the messages).
#[test]
fn each_check_refuses_just_beyond_its_limit() {
    let img = CoeffImage::parse(EXAMPLE).unwrap();
    let with = |f: AxisFilter| {
        let mut i = img;
        i.axes[0].as_mut().unwrap().filter = f;
        let mut buf = [0u8; MAX_IMAGE_LEN];
        i.encode(&mut buf).map(|_| ())
    };
    // Pole radius 1 − 2·margin passes, 1 − margin/2 does not (a real pole,
    // c·b tiny so that the gain bound does not decide).
    let real = |p: f32, c: f32| Section::first_order(p, 1.0, c);
    let ok = 1.0 - 2.0 * MIN_POLE_MARGIN as f32;
    let too_close = (1.0f64 - MIN_POLE_MARGIN / 2.0) as f32;
    assert!(too_close < 1.0);
    assert_eq!(with(AxisFilter::new(&[real(ok, 1e-5)], 1.0).unwrap()), Ok(()));
    assert_eq!(
        with(AxisFilter::new(&[real(too_close, 1e-5)], 1.0).unwrap()),
        Err(ImageError::PoleMarginTooSmall { axis: 0, section: 0 })
    );
    // Coefficient bound: d = 1e6 passes the coefficient check (and fails
    // the gain bound), 2e6 fails the coefficient check.
    assert!(matches!(
        with(AxisFilter::gain(MAX_COEFFICIENT).unwrap()),
        Err(ImageError::GainBoundTooLarge { axis: 0, .. })
    ));
    assert_eq!(
        with(AxisFilter::gain(2.0 * MAX_COEFFICIENT).unwrap()),
        Err(ImageError::CoefficientOutOfRange { axis: 0, section: 255 })
    );
    assert_eq!(
        with(AxisFilter::with_fir(&[], 1.0, &[0.0, -3e6]).unwrap()),
        Err(ImageError::TapOutOfRange { axis: 0, tap: 1 })
    );
    // Gain bound: a real pole at 0.5 with b·c = g has ℓ1 gain 2g.
    let g = (MAX_GAIN_BOUND / 2.0) as f32;
    assert_eq!(
        with(AxisFilter::new(&[real(0.5, 0.99 * g)], 0.0).unwrap()),
        Err(ImageError::DcGainOutOfRange { axis: 0 })
    );
    let c = 1.02 * g;
    assert_eq!(
        with(AxisFilter::new(&[real(0.5, c)], 0.0).unwrap()),
        Err(ImageError::GainBoundTooLarge { axis: 0, bound: (2.0 * f64::from(c)) as u32 })
    );
    // DC gain: a band-pass (DC 0) passes; DC of exactly ±MAX_DC_GAIN passes
    // (a real pole at 0.5 with b·c = 50 has DC gain 100), beyond fails.
    let dc = |d: f32| AxisFilter::new(&[real(0.5, 50.0)], d).unwrap();
    assert_eq!(with(dc(0.0)), Ok(()));
    assert_eq!(with(dc(1.0)), Err(ImageError::DcGainOutOfRange { axis: 0 }));
    assert_eq!(with(AxisFilter::new(&[real(0.5, 50.0)], -100.0).unwrap()), Ok(()));
    assert!(with(dc(1.0)).unwrap_err().to_string().contains("DC gain"));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// A random bit of a random coefficient flipped behind a recomputed CRC:
    /// the image is refused, or every axis's output for the worst input with
    /// |u| ≤ 1 stays within the axis's gain bound, hence within
    /// MAX_GAIN_BOUND.
    #[test]
    fn coefficient_bit_flips_are_refused_or_bounded(
        which in 0usize..2,
        pick in any::<prop::sample::Index>(),
        byte in 0usize..4,
        bit in 0u8..8,
    ) {
        let bytes = [EXAMPLE, LAT0][which];
        let offsets = coefficient_offsets(bytes);
        let (at, _, _) = offsets[pick.index(offsets.len())];
        let bad = flip_with_crc(bytes, at + byte, bit);
        if let Ok(img) = CoeffImage::parse(&bad) {
            for a in img.axes.iter().flatten() {
                let (bound, worst) = (a.filter.gain_bound(), worst_output(&a.filter));
                prop_assert!(bound <= MAX_GAIN_BOUND);
                prop_assert!(worst <= bound * (1.0 + 1e-4), "axis {}: worst output {} above the bound {}", a.axis, worst, bound);
                prop_assert!(a.filter.dc_gain().abs() <= MAX_DC_GAIN);
            }
        }
    }
}
